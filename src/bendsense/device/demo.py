"""Moved to :mod:`bendsense.apps.demo`; this import path keeps working."""

from bendsense.apps.demo import DEFAULT_DIR, DemoResult, run_demo, write_figure

__all__ = ["DemoResult", "run_demo", "DEFAULT_DIR", "write_figure"]
