"""Moved to :mod:`bendsense.apps.live_view`; this import path keeps working."""

from bendsense.apps.live_view import LiveStats, LiveView, run_live, status_line
from bendsense.pipeline import LIVE_MAX_ITER, LiveFrame, LiveProcessor

__all__ = ["LiveFrame", "LiveProcessor", "LiveView", "LiveStats", "run_live", "status_line", "LIVE_MAX_ITER"]
