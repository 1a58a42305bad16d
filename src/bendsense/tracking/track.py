"""Tracking the force over time: :func:`track` (offline, filter or smoother) and :class:`Tracker` (streaming).

The per-frame estimates are the measurements of a Kalman filter whose state is the force
(:mod:`bendsense.tracking._kalman_kernels`). Only each frame's **sensor-noise** covariance enters
the filter; the calibration and model-parameter parts of the frame's covariance are one
bias shared by neighbouring frames, which no averaging removes: they are added back whole
to the filtered or smoothed covariance, so that a tracked σ is never below that floor
(docs/theory.md, "Time: tracking and window checks").
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from bendsense import _jit
from bendsense._batched import brief_repr, quick_init
from bendsense.choices import TRACK_MODES
from bendsense.errors import ArgumentError, DataWarning
from bendsense.estimation.result import ForceEstimate
from bendsense.results import TRACK_COLUMNS, estimate_codes
from bendsense.status import MISFIT_P, Status, words
from bendsense.tracking import _kalman_kernels as _kalman
from bendsense.tracking import _stream_kernels as _stream
from bendsense.tracking import windows as _windows
from bendsense.validation import short

__all__ = ["Track", "Tracker", "track", "DEFAULT_BANDWIDTH_HZ", "ML_STEP_DECADES", "TRACK_COLUMNS"]

#: Bandwidth of the causal filter when none is given and none can be chosen from the data (live) [Hz].
DEFAULT_BANDWIDTH_HZ = 5.0
#: Longer series: the search runs on about this many frames (every m-th), then refines on the whole series.
ML_SUBSAMPLE_FRAMES = 1000
#: The half-width of the maximum-likelihood bandwidth's parabolas in log10 B (12 %).
ML_STEP_DECADES = 0.05
ML_REFINE_PASSES = 6  # at most this many more passes over the whole series after its first three
LOWEST_BANDWIDTH_HZ = 0.01  # the grid's lower end [Hz]; its upper end is a quarter of the frame rate


@quick_init
@dataclass(frozen=True, eq=False)
class Track:
    """The force tracked over a time series of frames (B,).

    Attributes
    ----------
    force_n : ndarray, shape (B, 2)
        Tracked force (Fx, Fy) in the base frame [N]; NaN for a component no frame of
        its segment has observed (yet, for the filter).
    std_n : ndarray, shape (B, 2)
        Its standard deviation [N]: the filtered or smoothed noise part plus the frame's
        calibration and parameter parts, whole (never below them); inf where unobserved.
    covariance_n2 : ndarray, shape (B, 2, 2)
        Covariance of ``force_n`` [N²].
    window_p_value : ndarray, shape (B,)
        The window test's p-value (:func:`bendsense.check_windows`): the frame's window
        (offline), or the latest completed window when the frame arrived (:class:`Tracker`);
        NaN where no test is available.
    status : ndarray of int8, shape (B,)
        Status codes (:class:`bendsense.status.Status`): ``OK``, ``MODEL_MISFIT`` (a
        window test below 0.001), ``NO_FORCE`` (no finite track) or the frame's own
        (``NOT_CONVERGED``, ``NOT_IDENTIFIABLE``, ...): never ``OK`` for a frame whose own
        status is not. Its words are results.csv's ``track_status``.
    bandwidth_hz : float
        The bandwidth of the filter used [Hz] (:func:`bendsense.tracking.track.intensity`).
    mode : str
        ``"smooth"`` (RTS smoother) or ``"filter"`` (causal Kalman filter).
    t_s : ndarray, shape (B,)
        Time of each frame [s].
    frame_force_n : ndarray, shape (B, 2)
        The per-frame estimates tracked [N].
    """

    __repr__ = brief_repr  # a line or two, not every value of every frame

    force_n: np.ndarray
    std_n: np.ndarray
    covariance_n2: np.ndarray
    window_p_value: np.ndarray
    status: np.ndarray
    bandwidth_hz: float
    mode: str
    t_s: np.ndarray | None = field(default=None, repr=False)
    frame_force_n: np.ndarray | None = field(default=None, repr=False)

    def to_columns(self) -> dict:
        """The results.csv columns ``fx_track_n, fy_track_n, fx_track_std_n, fy_track_std_n, track_status``."""
        f, s = np.asarray(self.force_n), np.asarray(self.std_n)
        return dict(zip(TRACK_COLUMNS, (f[:, 0], f[:, 1], s[:, 0], s[:, 1], words(self.status))))

    def plot(self, ax=None):
        """Fx and Fy against time: the tracked force with its ±2σ band over the per-frame points; returns the axes.

        As the force panel of :func:`bendsense.plots.plot_time_series`: the frames whose
        track is not ``ok`` are ticked and left out of the line and band (a smoother carried
        through frames that do not determine the force swings there, with σ of newtons),
        and the limits follow the forces, not a band far wider than them.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw (default: a new figure).
        """
        from bendsense.plots import _force_panel, _new_axes

        ax = _new_axes(ax, figsize=(7, 3.5))
        t = np.arange(len(self.force_n), dtype=float) if self.t_s is None else np.asarray(self.t_s, dtype=float)
        if self.frame_force_n is None:  # the track alone
            _force_panel(ax, t, self.force_n, self.std_n, status=words(self.status))
        else:
            _force_panel(ax, t, self.frame_force_n, np.zeros_like(self.std_n), status=words(self.status),
                         tracked=(self.force_n, self.std_n))
        ax.set_xlabel("t [s]" if self.t_s is not None else "frame")
        ax.set_title(f"{self.mode}, {self.bandwidth_hz:.3g} Hz", loc="left", fontsize="small")
        return ax

def track(estimate, t_s, *, mode: str = "smooth", bandwidth_hz: float | None = None, window_s: float = 0.05,
          pressure_pa=None) -> Track:
    """The force tracked over a time series: Kalman filter (causal) or Rauch–Tung–Striebel smoother (offline).

    Runs the window model check first (:func:`bendsense.check_windows`), then the filter
    over the per-frame estimates with only their sensor-noise covariance; the frames'
    calibration and parameter parts are added back whole. A gap or a pressure step
    restarts the state (diffuse prior); a failed frame (NaN force) is predicted only; a
    ``not_identifiable`` component (σ inf) is not observed, the other one is.

    Parameters
    ----------
    estimate : ForceEstimate
        Per-frame estimates (B,) of a time series (``estimate_force``). Without a noise
        model (``uncertainty="none"``: no noise covariance) nothing is observed and the
        tracked force is NaN.
    t_s : array_like, shape (B,)
        Time of each frame [s], not decreasing.
    mode : {"smooth", "filter"}
        RTS smoother (each frame uses the whole session) or the causal filter.
    bandwidth_hz : float, optional
        −3 dB bandwidth of the steady-state filter at each frame's noise [Hz]; None: the
        maximum likelihood of the innovations over a log grid from 0.01 Hz to a quarter
        of the frame rate.
    window_s : float
        Window of the model check and the longest interval inside a segment [s].
    pressure_pa : array_like, shape (B,), optional
        Pressure of each frame [Pa]: a step over 1 kPa restarts the state.

    Returns
    -------
    Track
    """
    if not isinstance(mode, str) or mode not in TRACK_MODES:
        raise ArgumentError(f"mode: must be one of {', '.join(TRACK_MODES)}, got {short(mode)}")
    bandwidth_hz = _check_bandwidth(bandwidth_hz, allow_none=True)
    t, P, window_s = _windows.series_inputs(estimate, t_s, window_s, pressure_pa)
    starts = _windows.segment_starts(t, P, window_s, _windows.reference_interval(t))
    bounds = _windows.window_bounds(t, starts, window_s)
    p, n = _windows.window_p_values(estimate, bounds)
    if estimate.window_p_value is None:  # check_windows has said it of a checked estimate
        _windows.warn_untested(estimate, t, bounds, window_s, 3, P)
    checked = _windows.flag(estimate, bounds, p, n, window_s)
    z, Rn, floor = measurements(checked)
    dt = np.diff(t, prepend=t[0])
    dt_ref = _windows.reference_interval(t)
    if bandwidth_hz is None:
        bandwidth_hz = ml_bandwidth(z, Rn, dt, starts, dt_ref)
    B = t.size
    xp, Pp, xf, Pf = np.empty((B, 4)), np.empty((B, 4, 4)), np.empty((B, 4)), np.empty((B, 4, 4))
    _jit.call(_kalman.kalman_filter, z, Rn, dt, starts, intensity(bandwidth_hz, dt_ref), new_state(), xp, Pp, xf, Pf,
              True)
    if mode == "smooth":
        xs, Ps = np.empty((B, 4)), np.empty((B, 4, 4))
        _jit.call(_kalman.rts_smoother, dt, starts, xp, Pp, xf, Pf, xs, Ps)
        floor = fill_floor(floor, starts, backward=True)
    else:
        xs, Ps = xf, Pf
        floor = fill_floor(floor, starts, backward=False)
    return result(xs, Ps, floor, checked.window_p_value, checked, float(bandwidth_hz), mode, t, z)


def intensity(bandwidth_hz, dt_ref_s):
    """The process intensity q [1/s³] of a bandwidth at the reference interval; 0 without one.

    :func:`bendsense.tracking._kalman_kernels.process_intensity`.
    """
    if not (math.isfinite(dt_ref_s) and dt_ref_s > 0):
        return 0.0  # fewer than two frames: nothing moves between them
    return float(_jit.call(_kalman.process_intensity, float(bandwidth_hz), float(dt_ref_s)))


def measurements(estimate):
    """The filter's measurements of an estimate: the force (B, 2), its noise covariance (B, 2, 2) and the floor.

    A component with an infinite σ (``not_identifiable``) gets a NaN force (not observed);
    the floor (B, 2, 2) is the covariance's calibration and parameter parts
    (:func:`bendsense.tracking._stream_kernels.measure`).
    """
    force = np.asarray(estimate.force_n, dtype=float).reshape(-1, 2)
    B = force.shape[0]
    z, Rn, floor = np.empty((B, 2)), np.empty((B, 2, 2)), np.empty((B, 2, 2))
    parts = estimate.covariance_parts_n2
    parts = np.full((B, 3, 2, 2), np.nan) if parts is None else np.asarray(parts, dtype=float).reshape(B, 3, 2, 2)
    _jit.call(_stream.measure, force, np.asarray(estimate.std_n, dtype=float).reshape(B, 2), parts, z, Rn, floor)
    return z, Rn, floor


def fill_floor(floor, starts, backward):
    """The floor (B, 2, 2) of a frame without one: the last one of its segment (and the next, ``backward``).

    :func:`bendsense.tracking._stream_kernels.fill_floor`.
    """
    out = np.empty_like(floor)
    _jit.call(_stream.fill_floor, np.ascontiguousarray(floor), starts, backward, out)
    return out


def ml_bandwidth(z, Rn, dt, starts, dt_ref_s):
    """The maximum-likelihood bandwidth [Hz] of the innovations.

    A grid of one point per decade from :data:`LOWEST_BANDWIDTH_HZ` to a quarter of the
    frame rate, then parabolas in log B from its best point (:func:`_ml_refine`): on the
    whole series up to twice :data:`ML_SUBSAMPLE_FRAMES` frames; on a longer one, that
    search runs on every m-th frame (~ML_SUBSAMPLE_FRAMES of them: the force-and-rate
    model sampled at m Δt is the same model with Q(m Δt), so this is the exact likelihood
    of those frames, spread over the whole series), then :func:`_ml_refine` on the whole
    series from there: 4–6 passes over the series in all. A likelihood that does not
    choose (flat: no segment with three observed frames) gives :data:`DEFAULT_BANDWIDTH_HZ`
    and a :class:`~bendsense.errors.DataWarning` when any frame was observed.
    """
    B = z.shape[0]
    if B > 2 * ML_SUBSAMPLE_FRAMES:
        m = B // ML_SUBSAMPLE_FRAMES
        idx = np.arange(0, B, m)
        cs, cdt = np.cumsum(starts), np.cumsum(dt)
        sub_starts = np.ones(idx.size, dtype=bool)
        sub_starts[1:] = np.diff(cs[idx]) > 0  # a restart between two kept frames restarts the kept one
        sub_dt = np.diff(cdt[idx], prepend=0.0)
        x = _ml_search(np.ascontiguousarray(z[idx]), np.ascontiguousarray(Rn[idx]), sub_dt, sub_starts, dt_ref_s)
        if x is not None:
            return _ml_refine(z, Rn, dt, starts, dt_ref_s, x)
    x = _ml_search(z, Rn, dt, starts, dt_ref_s)
    if x is not None:
        return float(10.0 ** x)
    if (np.isfinite(z) & np.isfinite(np.diagonal(Rn, axis1=1, axis2=2))).any():  # without any: nothing to track
        warnings.warn(f"track: the likelihood is flat over the bandwidth (no segment has three frames with a force "
                      f"and a noise covariance): tracking at {DEFAULT_BANDWIDTH_HZ:g} Hz; give bandwidth_hz "
                      f"(--bandwidth-hz) to choose", DataWarning, stacklevel=3)
    return DEFAULT_BANDWIDTH_HZ


def _ml_search(z, Rn, dt, starts, dt_ref_s):
    """log10 of the maximum-likelihood bandwidth: the grid, then :func:`_ml_refine` from its best; None without data."""
    top = 0.25 / dt_ref_s if math.isfinite(dt_ref_s) and dt_ref_s > 0 else 1.0
    lo_log, hi_log = math.log10(LOWEST_BANDWIDTH_HZ), max(math.log10(top), math.log10(LOWEST_BANDWIDTH_HZ) + 0.5)
    grid = np.linspace(lo_log, hi_log, int(math.ceil(hi_log - lo_log)) + 1)
    ll = _log_likelihoods(z, Rn, dt, starts, 10.0 ** grid, dt_ref_s)
    if not np.isfinite(ll).any() or np.ptp(ll[np.isfinite(ll)]) == 0.0:
        return None  # nothing to choose from (no observations)
    i = int(np.nanargmax(ll))
    return math.log10(_ml_refine(z, Rn, dt, starts, dt_ref_s, float(grid[i]), (grid[0], grid[-1])))


def _ml_refine(z, Rn, dt, starts, dt_ref_s, x, bounds=(-np.inf, np.inf)):
    """B [Hz] at the vertex of a parabola in log B through the whole series' likelihood around ``x`` (log10 B).

    Three points x, x ± h; while the best is at an end, a Newton step of the parabola
    through the end's three points (at least h, at most 8h beyond it; not beyond
    ``bounds``, log10 B); while the best's neighbours are more than 2.5h apart, the vertex
    is evaluated; then the vertex.
    """
    h = ML_STEP_DECADES
    xs = [x - h, x, x + h]
    fs = [f if math.isfinite(f) else -np.inf for f in _log_likelihoods(z, Rn, dt, starts, 10.0 ** np.array(xs),
                                                                        dt_ref_s)]
    for _ in range(ML_REFINE_PASSES):
        j = int(np.argmax(fs))
        k = min(max(j, 1), len(xs) - 2)
        (x0, x1, x2), (f0, f1, f2) = xs[k - 1:k + 2], fs[k - 1:k + 2]
        den = (x1 - x0) * (f1 - f2) - (x1 - x2) * (f1 - f0)
        v = x1 - 0.5 * ((x1 - x0) ** 2 * (f1 - f2) - (x1 - x2) ** 2 * (f1 - f0)) / den if den > 0.0 else np.nan
        if j == 0 or j == len(xs) - 1:  # at an end: beyond it
            end, sign = (xs[0], -1.0) if j == 0 else (xs[-1], 1.0)
            v = end + sign * min(max(sign * (v - end), h), 8 * h) if math.isfinite(v) else end + sign * 4 * h
            if not bounds[0] <= v <= bounds[1]:
                return float(10.0 ** xs[j])  # the best is at an end of the search range: that end
        elif not math.isfinite(v) or not x0 < v < x2:
            return float(10.0 ** xs[j])
        elif x2 - x0 <= 2.5 * h or min(abs(v - x0), abs(v - x1), abs(v - x2)) < 0.1 * h:
            return float(10.0 ** v)
        f = _log_likelihoods(z, Rn, dt, starts, np.array([10.0 ** v]), dt_ref_s)[0]
        i = int(np.searchsorted(xs, v))
        xs.insert(i, v)
        fs.insert(i, f if math.isfinite(f) else -np.inf)
    return float(10.0 ** xs[int(np.argmax(fs))])


def _log_likelihoods(z, Rn, dt, starts, bandwidths_hz, dt_ref_s):
    q = np.array([intensity(b, dt_ref_s) for b in bandwidths_hz])
    out = np.empty(q.size)
    _jit.call(_kalman.log_likelihoods, z, Rn, dt, starts, q, out)
    return out


def result(x, P, floor, window_p, est, bandwidth_hz, mode, t, z):
    """The :class:`Track` of the states ``x`` (B, 4), ``P`` (B, 4, 4) (force and rate) with the floor added back."""
    B = x.shape[0]
    frame_z = np.asarray(est.force_n, dtype=float).reshape(B, 2)
    force, std, cov = np.empty((B, 2)), np.empty((B, 2)), np.empty((B, 2, 2))
    _jit.call(_kalman.finish, x, P, np.ascontiguousarray(floor), force, std, cov)
    window_p = np.asarray(window_p, dtype=float)
    return Track(force_n=force, std_n=std, covariance_n2=cov, window_p_value=window_p,
                 status=track_status(est, frame_z, window_p, force, std), bandwidth_hz=bandwidth_hz, mode=mode, t_s=t,
                 frame_force_n=z)


def new_state():
    """A filter's state before its first frame: x (4,), P (4, 4), the latest noise covariance, [has it, Fx, Fy seen]."""
    return np.zeros(4), np.zeros((4, 4)), np.zeros((2, 2)), np.zeros(3)


def _check_bandwidth(value, allow_none):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not (
            math.isfinite(value) and value > 0):
        raise ArgumentError(f"bandwidth_hz: expected a frequency > 0 [Hz], got {short(value)}")
    return float(value)


class Tracker:
    """The causal filter over blocks of frames as they arrive (``record --estimate``, ``live``).

    ``update`` gives the same numbers block by block as :func:`track` with
    ``mode="filter"`` on the whole series (the same kernel, its state kept across blocks;
    the gaps are judged against the median interval of the first frames seen). The window
    check runs as windows close: each frame reports its filtered force at once and the
    p-value of the latest completed window (a window closes when a frame of the next one
    arrives, or at a gap or pressure step); while that p is below 0.001 the frames are
    ``model_misfit``.

    Parameters
    ----------
    mode : {"filter"}
        Only the causal filter streams.
    bandwidth_hz : float, optional
        Bandwidth [Hz]; default :data:`DEFAULT_BANDWIDTH_HZ`.
    window_s : float
        Window of the model check and the longest interval inside a segment [s].
    """

    def __init__(self, mode: str = "filter", bandwidth_hz: float | None = None, window_s: float = 0.05):
        if mode != "filter":
            raise ArgumentError(f"mode: a Tracker filters causally: only 'filter', got {short(mode)}")
        self.bandwidth_hz = _check_bandwidth(DEFAULT_BANDWIDTH_HZ if bandwidth_hz is None else bandwidth_hz, False)
        self.window_s = _windows.checked_window_s(window_s)
        self.mode = mode
        self._state = new_state()
        self._dt_ref = None  # the median interval of the first frames
        self._q = None  # the process intensity of the bandwidth at that interval [1/s³]
        self._fs = np.zeros(_stream.N_SCALARS)  # the carried scalars of the stream kernels
        self._fs[_stream.LATEST_P] = np.nan
        self._carry = np.full((2, 2), np.nan)  # the segment's latest floor
        self._sums = None  # the open window's sums (r, A, M, shifts)
        self._model = None  # (the shift error model, as a plain tuple, the coils) of the latest block

    def update(self, estimate_block, t_s_block, pressure_pa_block=None) -> Track:
        """Filter a block of frames; returns their :class:`Track`.

        Parameters
        ----------
        estimate_block : ForceEstimate
            The block's per-frame estimates (b,), or one frame's (batch shape ``()``).
        t_s_block : array_like, shape (b,)
            Their times [s], after the previous block's.
        pressure_pa_block : array_like, shape (b,), optional
            Their pressures [Pa].
        """
        est, t, P = self._inputs(estimate_block, t_s_block, pressure_pa_block)
        b = t.size
        fs = self._fs
        learning = self._learn(t)
        force, std, cov = np.empty((b, 2)), np.empty((b, 2)), np.empty((b, 2, 2))
        starts = np.empty(b, dtype=np.bool_)
        parts = est.covariance_parts_n2
        parts = np.full((b, 3, 2, 2), np.nan) if parts is None else _c(parts, (b, 3, 2, 2))
        z = _c(est.force_n, (b, 2))
        missing = _jit.call(_stream.stream_filter, t, P, z, _c(est.std_n, (b, 2)), parts, *self._filter_state(),
                            starts, force, std, cov)
        if missing < 0:  # nothing filtered: the times are checked first
            if learning:
                self._dt_ref = self._q = None  # nor the interval learnt from these times kept
            i = -1 - missing
            before = float(t[i - 1] if i else fs[_stream.LAST_T])
            raise ArgumentError(f"t_s_block: expected finite times [s], got {float(t[i])!r} at frame {i}" if not
                                math.isfinite(t[i]) else f"t_s_block: must not decrease, got {float(t[i])!r} s "
                                f"after {before!r} s")
        window_p, misfit = self._windows(est, t, starts, b)
        return Track(force_n=force, std_n=std, covariance_n2=cov, window_p_value=window_p,
                     status=track_status(est, z, window_p, force, std, missing > 0 or misfit),
                     bandwidth_hz=self.bandwidth_hz,
                     mode=self.mode, t_s=t, frame_force_n=z)

    def stream_state(self, t, coils: int, channels: int) -> tuple:
        """The filter's state as the live step takes it (``pipeline._kernels.track``), for frames at ``t``.

        Learns the reference interval from the first frames, as :meth:`update` does; the
        arrays are the Tracker's own, so the step carries them on.

        Parameters
        ----------
        t : ndarray, shape (b,)
            The block's frame times [s].
        coils, channels : int
            The sizes of the window test's sums (the coils fitted, the sensor's channels).
        """
        self._learn(t)
        return (*self._filter_state(), *self._window_sums(coils, channels))

    def _learn(self, t) -> bool:
        """Learn the reference interval (the median of the first frames seen) at times ``t``; whether it was unknown."""
        if self._dt_ref is not None:
            return False
        fs = self._fs
        tt = t if fs[_stream.HAS_LAST] == 0.0 else np.concatenate(([fs[_stream.LAST_T]], t))
        if tt.size > 1:
            self._dt_ref = _windows.reference_interval(tt)
            self._q = intensity(self.bandwidth_hz, self._dt_ref)
        return True

    def _filter_state(self) -> tuple:
        """:func:`~bendsense.tracking._stream_kernels.stream_filter`'s constants and carried state, in its order."""
        return (self._q or 0.0, self.window_s, self._dt_ref or np.inf, _windows.GAP_FACTOR, _windows.PRESSURE_STEP_PA,
                self._fs, *self._state, self._carry)

    def _window_sums(self, coils: int, channels: int) -> tuple:
        """The open window's sums (r, A, M, shifts), made at the first block."""
        if self._sums is None:
            self._sums = (np.zeros(coils), np.zeros((coils, 2)), np.zeros((coils, 2)), np.zeros(channels))
        return self._sums

    def _inputs(self, est, t_s, pressure_pa):
        """The checked block: (estimate, t (b,), pressure (b,) NaN where not given)."""
        if not isinstance(est, ForceEstimate):
            raise ArgumentError(f"estimate_block: expected a ForceEstimate (estimate_force), got {type(est).__name__}")
        shape = est.batch_shape
        if len(shape) > 1:
            raise ArgumentError(f"estimate_block: expected the estimates of a block of frames (one batch axis), got "
                                f"batch shape {shape}")
        b = shape[0] if shape else 1
        try:
            t = _c(t_s, -1)
        except (TypeError, ValueError):
            raise ArgumentError(f"t_s_block: expected times [s], got {short(t_s)}") from None
        if t.size != b:
            raise ArgumentError(f"t_s_block: expected {b} times (one per frame), got {short(t_s)}")
        if pressure_pa is None:
            return est, t, np.full(b, np.nan)
        try:
            P = np.array(np.broadcast_to(np.asarray(pressure_pa, dtype=float).reshape(-1), (b,)))
        except (TypeError, ValueError):
            raise ArgumentError(f"pressure_pa_block: expected {b} pressures [Pa] (one per frame), got "
                                f"{short(pressure_pa)}") from None
        return est, t, P

    def _windows(self, est, t, starts, b):
        """The latest completed window's p at each frame (b,), and whether any is below MISFIT_P (stream kernels)."""
        resid, jac, mfac, shifts = (est.residual_rad, est.jacobian_rad_per_n, est.model_factor_rad, est.shifts_m)
        p = np.full(b, np.nan)
        if resid is None or jac is None or mfac is None or shifts is None or est.shift_errors is None \
                or est.uncertainty != "propagated":
            return p, False
        R, N = resid.shape[-1], shifts.shape[-1]
        resid, shifts, jac, mfac = _c(resid, (b, R)), _c(shifts, (b, N)), _c(jac, (b, R, 2)), _c(mfac, (b, R, 2))
        sums = self._window_sums(R, N)
        if self._model is None or self._model[0] is not est.shift_errors:  # the same calibration: converted once
            self._model = (est.shift_errors, tuple(est.shift_errors), np.asarray(est.coils, dtype=np.int64))
        misfit = _jit.call(_stream.stream_windows, t, starts, resid, jac, mfac, shifts, self._model[1],
                           self._model[2], float(est.strip_gap_m), self.window_s, self._fs, *sums, p)
        return p, misfit


def _c(a, shape):
    """``a`` as the stream kernels take it: float64, C-contiguous, of ``shape`` (a copy only if it is not).

    One layout for every block, whatever view an estimate holds (a strided slice of the
    estimator's output, a copy after a frame was taken out or put back): numba compiles a
    kernel once per layout, and a second layout met in a control loop compiled there
    (~1 µs a block for the copies).
    """
    return np.ascontiguousarray(a, dtype=float).reshape(shape)


def track_status(est, z, window_p, force, std, flagged=None):
    """The tracked status codes (b,): the frame's own, ``MODEL_MISFIT`` where its window's p < MISFIT_P and it was ok.

    The frame's own: :func:`bendsense.results.estimate_codes`, looked up only where a frame
    is not ok; ``NO_FORCE`` where it was ok but the tracked force or its σ is not finite
    (an estimate without a noise model has nothing to weigh: a NaN track is never ok).
    ``flagged``: whether any frame's force is missing or its window p below MISFIT_P, when
    the caller knows (the stream kernels count them).
    """
    b = z.shape[0]
    if flagged is None:
        flagged = not np.isfinite(z).all() or (window_p < MISFIT_P).any()
    flagged = flagged or not (np.isfinite(force).all() and np.isfinite(std).all())
    if not flagged and bool(np.all(est.success)) and bool(np.all(est.status == Status.OK)):
        return np.full(b, Status.OK, dtype=np.int8)  # every frame ok (the live path's usual block)
    from bendsense.results import _kernels

    status = np.empty(b, dtype=np.int8)
    force, std = (np.ascontiguousarray(x, dtype=float).reshape(b, 2) for x in (force, std))
    _jit.call(_kernels.track_codes_into, estimate_codes(est, b), np.ascontiguousarray(window_p, dtype=float), force,
              std, status)
    return status
