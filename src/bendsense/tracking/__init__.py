"""The force over time: tracking (a Kalman filter and an RTS smoother) and the model check over windows.

- :mod:`~bendsense.tracking.windows`: the window test of the mean residual
  (:func:`check_windows`);
- :mod:`~bendsense.tracking.track`: :func:`track` (offline), :class:`Tracker`
  (streaming) and their result :class:`Track`.

Their compiled kernels are private: the window test (``_window_kernels``), the Kalman
filter and RTS smoother over the frames, the force and its rate (``_kalman_kernels``),
and the streaming tracker's block kernels (``_stream_kernels``).

docs/theory.md ("Time: tracking and window checks") derives both.
"""

from bendsense.tracking.track import DEFAULT_BANDWIDTH_HZ, TRACK_COLUMNS, Track, Tracker, track
from bendsense.tracking.windows import WINDOW_S, check_windows

__all__ = ["track", "Track", "Tracker", "check_windows", "DEFAULT_BANDWIDTH_HZ", "TRACK_COLUMNS", "WINDOW_S"]
