"""Pieces shared by the command modules: the command class and common options."""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["InterspersedCommand", "config_option", "overwrite_option"]


class InterspersedCommand(click.Command):
    """A command whose options may follow its arguments, also inside a chained group.

    click parses the subcommands of a chained group with
    ``allow_interspersed_args=False``, so ``calibrate MANIFEST.yaml -o cal.yaml`` would
    stop at ``MANIFEST.yaml``. Here the arguments are cut at the first sibling command
    name (the next step of the chain) and everything before it is parsed with options
    allowed anywhere.
    """

    def make_context(self, info_name, args, parent=None, **extra):
        """Make the context with interspersed options allowed."""
        extra["allow_interspersed_args"] = True
        return super().make_context(info_name, args, parent=parent, **extra)

    def parse_args(self, ctx, args):
        """Parse up to the next chained command; leave the rest for the group."""
        group = ctx.parent.command if ctx.parent is not None else None
        siblings = set(group.commands) if isinstance(group, click.Group) else set()
        takes_value = {name for p in self.params if isinstance(p, click.Option) and not p.is_flag for name in p.opts}
        cut = len(args)
        for i, token in enumerate(args):
            if token in siblings and (i == 0 or args[i - 1] not in takes_value):
                cut = i
                break
        super().parse_args(ctx, args[:cut])
        ctx.args = [*ctx.args, *args[cut:]]
        return ctx.args


config_option = click.option(
    "--config",
    "config_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Config YAML (default: the paper's prototype, built in).",
)
overwrite_option = click.option("--overwrite", is_flag=True, help="Replace existing output.")
