"""The ``bendsense`` command line: a thin shell over the library.

Commands live in one module per area (``pipeline``, ``batch``, ``calibrate``,
``identify``, ``sim``, ``reproduce``, ``device``, ``live``, ``control``); each exposes ``COMMANDS``,
a list of click commands added here.
Heavy imports happen inside the commands, so ``bendsense --help`` is fast.
"""

from __future__ import annotations

import logging
import os

# bendsense's linear algebra is many small matrices, which a threaded BLAS slows down
# by an order of magnitude; parallelism comes from processes instead. This must be set
# before numpy is first imported (the commands import it lazily).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import click  # noqa: E402 (after the BLAS settings above)

from bendsense import __version__  # noqa: E402
from bendsense.cli import batch, calibrate, control, device, identify, live, pipeline, reproduce, sim  # noqa: E402


@click.group(
    cls=pipeline.PipelineGroup,
    chain=True,
    context_settings={"help_option_names": ["-h", "--help"]},
)
@click.option("-v", "--verbose", count=True, help="More log output (repeat for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.version_option(__version__, prog_name="bendsense")
@click.pass_context
def main(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """Shape and tip force of soft bending actuators from an inductive curvature sensor.

    Processing steps chain on one command line, for example:

        bendsense load run.csv --calibration cal.yaml reconstruct estimate save out/
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s")
    ctx.ensure_object(dict)
    ctx.obj["quiet"] = quiet


@main.result_callback()
def _run_pipeline(steps, **_options) -> None:
    pipeline.run_steps(steps)


for _module in (pipeline, batch, calibrate, identify, sim, reproduce, device, live, control):
    for _command in _module.COMMANDS:
        main.add_command(_command)


def run() -> None:
    """The ``bendsense`` console script: :func:`main`; once it is done, a late stop signal keeps its exit status.

    (:func:`bendsense.cli._signals.exit_quietly`: a second Ctrl-C while the interpreter
    exits ends it at once with the command's status, instead of killing it by the signal.)
    """
    from bendsense.cli import _signals

    try:
        main()
    except SystemExit as done:
        _signals.exit_quietly(done.code)
        raise
