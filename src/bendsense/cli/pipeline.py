"""Chained processing steps: load, reconstruct, estimate, save, plot, export."""

import click

COMMANDS = []


class PipelineGroup(click.Group):
    """A chained group (filled in with the pipeline)."""
