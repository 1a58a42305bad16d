"""The model check over windows of frames: the test of a window's mean residual (docs/theory.md, "Time").

A frame's χ² has little power against a persistent model error at realistic noise: the
error is a fraction of a noise σ per frame. Over a window of n frames the noise of the
mean residual falls as 1/√n while a persistent error stays, so a test of the mean
residual against its covariance gains power as n (its statistic grows as n × the error²);
a sum of the frames' χ² gains it only as √n. Per window of frames ``a:b``, over its usable
frames (a finite residual):

- the means r̄ (R,) of the residuals (measured − model coil angle), Ā (R, 2) of the
  Jacobians by the fitted parameters u, M̄ (R, 2) of the model factors, S̄ of the shifts;
- ``Σ_θ = Σ_S(S̄)_(coils) / d²`` (:func:`bendsense.calibration._kernels.shift_covariance`) with its
  noise diagonal ``nv``: ``Σ_cal = Σ_θ − diag(nv)`` is the calibration's part;
- ``C = P̄ (diag(nv)/n + Σ_cal + M̄ M̄ᵀ) P̄ᵀ``, ``P̄ = I − Ā (ĀᵀWĀ)⁺ ĀᵀW``, ``W = Σ_θ⁻¹``
  (the estimator's own weights): the noise averages down, the calibration and parameter
  parts are one bias shared by the window's frames and count whole;
- ``T = r̄ᵀ C⁺ r̄`` with rank(C) = R − k degrees of freedom: whitened by the Cholesky
  factor of Σ_θ, the fitted directions projected out by an orthonormal complement of the
  whitened Ā, then solved; ``p = P(χ²_(R−k) > T)``.

The compiled kernels (:mod:`bendsense.tracking._window_kernels`) run the test over the
windows; ``check_windows`` costs ~0.5 µs per frame in all (benchmarks/bench_track.py).
"""

import dataclasses
import math
import warnings

import numpy as np

from bendsense import _jit
from bendsense.errors import ArgumentError, DataWarning
from bendsense.estimation.result import ForceEstimate
from bendsense.status import MISFIT_P, Status
from bendsense.tracking import _window_kernels
from bendsense.tracking._window_kernels import MIN_FRAMES
from bendsense.tracking.gaps import GAP_FACTOR, reference_interval
from bendsense.validation import short

__all__ = ["check_windows", "WINDOW_S", "PRESSURE_STEP_PA", "MIN_FRAMES"]

WINDOW_S = 0.05  # default window [s]: 100 frames at 2 kHz
WINDOW_SLIP_S = 10.0  # a window this long is a window in milliseconds given as seconds (50 for 0.05 s)
PRESSURE_STEP_PA = 1000.0  # a pressure change between two frames beyond this is a step [Pa]


def segment_starts(t_s, pressure_pa, window_s, dt_ref_s):
    """Whether each frame (B,) starts a segment: the first, and after a gap or a pressure step.

    A gap is an interval over ``GAP_FACTOR`` × ``dt_ref_s`` (the median interval) or over
    ``window_s``; a step is a pressure change over ``PRESSURE_STEP_PA`` between two frames.
    """
    starts = np.ones(t_s.size, dtype=bool)
    dt = np.diff(t_s)
    brk = (dt > GAP_FACTOR * dt_ref_s) | (dt > window_s)
    if pressure_pa is not None:
        brk |= np.abs(np.diff(pressure_pa)) > PRESSURE_STEP_PA
    starts[1:] = brk
    return starts


def window_index(t_s, starts, window_s, t0_s=None):
    """Each frame's segment and window ``floor((t − t_segment) / window_s)`` in it; and the segments' start times.

    ``t0_s``: the start time of the segment the first frame continues (streaming), if it starts none.
    """
    seg = np.cumsum(starts) - 1
    first = np.flatnonzero(starts)
    t_first = t_s[first]
    if not starts[0]:  # frames before the first start continue an open segment (streaming)
        seg = seg + 1
        t_first = np.concatenate(([t0_s], t_first))
    t_seg = t_first[seg]
    return seg, np.floor((t_s - t_seg) / window_s + 1e-9).astype(np.int64), t_first


def window_bounds(t_s, starts, window_s):
    """Boundaries (W + 1,) of consecutive windows of ``window_s`` within the segments ``starts``.

    A segment's last window shorter than half a window joins the previous one of its segment.
    """
    seg, j, t_first = window_index(t_s, starts, window_s)
    new = np.ones(t_s.size, dtype=bool)
    new[1:] = (seg[1:] != seg[:-1]) | (j[1:] != j[:-1])
    bounds = np.flatnonzero(new)
    ends = np.append(bounds[1:], t_s.size)
    last = ~starts[bounds] & np.append(seg[bounds[1:]] != seg[bounds[:-1]], True)  # a segment's last, not its first
    short_ = last & (t_s[ends - 1] - (t_first[seg[bounds]] + j[bounds] * window_s) < 0.5 * window_s)
    return np.append(bounds[~short_], t_s.size).astype(np.int64)


PAYLOAD = ("residual_rad", "jacobian_rad_per_n", "model_factor_rad", "shifts_m")  # a window test's per-frame inputs


def window_p_values(estimate, bounds, payload=None):
    """The p-value (W,) and the usable frames (W,) of the window test over ``bounds`` of a 1-D estimate.

    ``payload``: the frames' :data:`PAYLOAD` arrays, if not the estimate's own (streaming).
    """
    W = bounds.size - 1
    p = np.full(W, np.nan)
    n = np.zeros(W, dtype=np.int64)
    payload = tuple(getattr(estimate, name) for name in PAYLOAD) if payload is None else payload
    if any(a is None for a in payload) or estimate.shift_errors is None or estimate.uncertainty != "propagated" \
            or W < 1:
        return p, n
    c = np.ascontiguousarray
    _jit.call(_window_kernels.window_tests, c(bounds, dtype=np.int64), *(c(a, dtype=float) for a in payload),
              tuple(estimate.shift_errors), np.asarray(estimate.coils, dtype=np.int64), float(estimate.strip_gap_m), p,
              n)
    return p, n


def compile_kernels(calibration, config) -> None:
    """Compile (or load from the cache) the window test's kernel for a session of ``calibration``: no window tested.

    The types of every later call (the shift error model of the calibration's noise, the
    payload's arrays); ``bendsense demo`` compiles it while the estimation kernels compile
    in a second process.

    Parameters
    ----------
    calibration : Calibration
        The session's calibration.
    config : Config
        Its ``estimation.signal_noise_std``, where the calibration has no noise.
    """
    from bendsense.estimation.uncertainty import noise_std

    err = calibration.error_model(noise_std(None, calibration, config.estimation))
    none = np.empty(0)
    _jit.call(_window_kernels.window_tests, np.zeros(1, dtype=np.int64), np.empty((0, 1)), np.empty((0, 1, 2)),
              np.empty((0, 1, 2)), np.empty((0, 1)), tuple(err), np.zeros(1, dtype=np.int64), 0.0, none,
              np.empty(0, dtype=np.int64))


def check_windows(estimate, t_s, *, window_s: float = WINDOW_S, pressure_pa=None) -> ForceEstimate:
    """The model check over windows of frames: ``estimate`` with ``window_p_value`` and the misfits flagged.

    The frames are cut into segments at gaps (an interval over 3× the median one or over
    ``window_s``) and at pressure steps (over 1 kPa between two frames), then into
    consecutive windows of ``window_s`` (a remainder shorter than half a window joins the
    previous one). Each window's mean residual is tested against its covariance (the
    sensor noise divided by the frames, the calibration and parameter parts whole; module
    docstring). Where p < 0.001 (:data:`~bendsense.status.MISFIT_P`), the
    window's converged frames become ``model_misfit`` (``success=False``, the force kept,
    a message naming the window test).

    Parameters
    ----------
    estimate : ForceEstimate
        Per-frame estimates (B,) of a time series, from ``estimate_force`` with the fast
        method fitting the coil angles (``objective="angles"``) and a noise model; else
        no test is available and ``window_p_value`` is NaN.
    t_s : array_like, shape (B,)
        Time of each frame [s], not decreasing.
    window_s : float
        Window length [s] (default 0.05).
    pressure_pa : array_like, shape (B,), optional
        Pressure of each frame [Pa]: a step starts a new segment.

    Returns
    -------
    ForceEstimate
        The same estimate with ``window_p_value`` (B,) (NaN for frames in a window of
        fewer than 5 usable frames) and the flagged frames' ``success`` and ``message``.
        Windows too short for any test at the session's frame rate give a
        :class:`~bendsense.errors.DataWarning` naming the ``window_s`` that would test them.
    """
    t, P, window_s = series_inputs(estimate, t_s, window_s, pressure_pa)
    starts = segment_starts(t, P, window_s, reference_interval(t))
    bounds = window_bounds(t, starts, window_s)
    p, n = window_p_values(estimate, bounds)
    warn_untested(estimate, t, bounds, window_s, 3, P)
    return flag(estimate, bounds, p, n, window_s)


def warn_untested(estimate, t_s, bounds, window_s, stacklevel, pressure_pa=None):
    """A :class:`~bendsense.errors.DataWarning` when a test is available but no window holds MIN_FRAMES frames.

    A session of at least MIN_FRAMES frames whose rate puts fewer in a window of
    ``window_s`` (35 Hz and 50 ms: one to three) is never tested; the message names the
    window (a frame to spare, whole ms) that would hold enough, and says when pressure
    steps cut the session into pieces shorter than that.
    """
    tested = all(getattr(estimate, name) is not None for name in PAYLOAD) and estimate.shift_errors is not None \
        and estimate.uncertainty == "propagated"
    most = int(np.diff(bounds).max())
    dt = reference_interval(t_s)
    if not tested or t_s.size < MIN_FRAMES or most >= MIN_FRAMES or not window_s < MIN_FRAMES * dt:
        return  # (windows the rate fills, cut short by gaps or pressure steps: no longer window helps)
    need = math.ceil((MIN_FRAMES + 1) * dt * 1e3) / 1e3
    steps = pressure_pa is not None and bool((np.abs(np.diff(pressure_pa)) > PRESSURE_STEP_PA).any())
    cut = f" (frames between pressure steps over {PRESSURE_STEP_PA / 1e3:g} kPa stay untested)" if steps else ""
    warnings.warn(f"window check: {window_s * 1e3:g} ms windows hold at most {most} frames at {1.0 / dt:.3g} Hz, "
                  f"fewer than the {MIN_FRAMES} a test needs: no window is tested (window_p_value NaN); "
                  f"window_s={need:g} (--window-s {need:g}) holds {MIN_FRAMES + 1}{cut}", DataWarning,
                  stacklevel=stacklevel)


def flag(estimate, bounds, p, n, window_s):
    """``estimate`` with its windows' p-values per frame, the converged frames of a window with p < MISFIT_P flagged."""
    B = estimate.batch_shape[0]
    counts = np.diff(bounds)
    frame_p = np.repeat(p, counts)
    frame_n = np.repeat(n, counts)
    message = np.array(np.broadcast_to(np.asarray(estimate.message, dtype=object), (B,)), dtype=object)
    bad = (frame_p < MISFIT_P) & (np.asarray(estimate.status) == Status.OK) & np.asarray(estimate.success, dtype=bool)
    for i in np.flatnonzero(bad):
        message[i] = (f"model_misfit: window test over {window_s * 1e3:g} ms ({frame_n[i]} frames): p = "
                      f"{frame_p[i]:.2g} < {MISFIT_P:g}: the model does not explain the window's mean residual within "
                      "the stated noise, calibration and parameter errors (a load not at the tip, contact along the "
                      "body, or a mis-identified actuator)")
    return dataclasses.replace(estimate, window_p_value=frame_p, success=np.where(bad, False, estimate.success),
                               status=np.where(bad, Status.MODEL_MISFIT, estimate.status).astype(np.int8),
                               message=message.astype(str))


def as_series(estimate):
    """A one-frame estimate (batch shape ``()``) as a series of one frame (1,); any other estimate as it is."""
    if not isinstance(estimate, ForceEstimate) or estimate.batch_shape != ():
        return estimate
    changes = {f.name: getattr(estimate, f.name)[None] for f in dataclasses.fields(estimate)
               if isinstance(getattr(estimate, f.name), np.ndarray)}
    return dataclasses.replace(estimate, message=np.array([str(estimate.message)]), **changes)


def series_inputs(estimate, t_s, window_s, pressure_pa):
    """The checked time series inputs of :func:`check_windows` and :func:`bendsense.track`: (t (B,), P (B,) or None, W).

    ``estimate`` must be a series (one batch axis; :func:`as_series` makes one of a single frame).
    """
    if not isinstance(estimate, ForceEstimate):
        raise ArgumentError(f"estimate: expected a ForceEstimate (estimate_force), got {type(estimate).__name__}")
    if len(estimate.batch_shape) != 1:
        raise ArgumentError(f"estimate: expected the estimates of a time series (one batch axis of frames), got batch "
                            f"shape {estimate.batch_shape}")
    return time_inputs(estimate.batch_shape[0], t_s, window_s, pressure_pa)


def checked_window_s(window_s) -> float:
    """``window_s`` [s] checked: a duration > 0, below :data:`WINDOW_SLIP_S` (beyond: milliseconds given)."""
    if isinstance(window_s, bool) or not isinstance(window_s, (int, float, np.integer, np.floating)) or not (
            math.isfinite(window_s) and window_s > 0):
        raise ArgumentError(f"window_s: expected a duration > 0 [s], got {short(window_s)}")
    if window_s >= WINDOW_SLIP_S:
        raise ArgumentError(f"window_s: {float(window_s):g} s looks like milliseconds (a window holds one load: tens "
                            f"to hundreds of ms; give seconds, e.g. {WINDOW_S:g})")
    return float(window_s)


def time_inputs(B, t_s, window_s, pressure_pa):
    """The checked times (B,), pressures (B,) or None and window length of a series of ``B`` frames."""
    try:
        t = np.asarray(t_s, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"t_s: expected times [s], got {short(t_s)}") from None
    if t.shape != (B,):
        raise ArgumentError(f"t_s: expected {B} times (one per frame), got shape {t.shape}")
    if not np.isfinite(t).all():
        raise ArgumentError(f"t_s: must be finite, got {short(t[~np.isfinite(t)][0])} at frame "
                            f"{int(np.flatnonzero(~np.isfinite(t))[0])}")
    back = np.flatnonzero(~(np.diff(t) > 0))  # equal times too: no interval to filter over (t + 1e15: all equal)
    if back.size:
        raise ArgumentError(f"t_s: must increase, got {short(t[back[0] + 1])} s after {short(t[back[0]])} s "
                            f"at frame {int(back[0]) + 1}")
    window_s = checked_window_s(window_s)
    P = None
    if pressure_pa is not None:
        try:
            P = np.array(np.broadcast_to(np.asarray(pressure_pa, dtype=float), (B,)))
        except (TypeError, ValueError):
            raise ArgumentError(f"pressure_pa: expected {B} pressures [Pa] (one per frame), got "
                                f"{short(pressure_pa)}") from None
        if not np.isfinite(P).all():  # a step in it restarts the series: NaN would hide every step
            bad = int(np.flatnonzero(~np.isfinite(P))[0])
            raise ArgumentError(f"pressure_pa: must be finite, got {short(P[bad])} at frame {bad} (or give None)")
    return t, P, float(window_s)

