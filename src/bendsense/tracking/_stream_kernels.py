"""The compiled kernels of the streaming tracker (:class:`~bendsense.tracking.Tracker`): a block of frames per call.

:func:`stream_filter` cuts the segments (a gap, a pressure step), runs the filter's
frames (:func:`bendsense.tracking._kalman_kernels.advance` and ``observe``, the steps of
``track``'s filter), carries the calibration and parameter floor within a segment and
writes the tracked force; :func:`stream_windows` keeps the open window's sums across
blocks and reports, at each frame, the p-value of the latest completed window
(:func:`bendsense.tracking._window_kernels.window_statistic`, the statistic of
``check_windows``).
Their state lives in arrays the Tracker owns, so a call costs the frames and one
dispatch each, not a chain of numpy calls: ``Tracker.update`` ~17 µs for a single frame,
~1.5 µs per frame in blocks of 20 (benchmarks/bench_track.py).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit
from bendsense.calibration.shift_errors import ShiftErrorModel
from bendsense.status import MISFIT_P
from bendsense.tracking import _kalman_kernels as K
from bendsense.tracking import _window_kernels as W

# the carried scalars (a float array the Tracker owns)
HAS_LAST, LAST_T, LAST_P, SEG_T0, WIN_J, HAS_OPEN, LATEST_P, WIN_N = range(8)
N_SCALARS = 8


@njit(cache=True)
def measure_frame(force, std, parts, z, Rn, floor):
    """A frame's measurement: the force (NaN where σ is not finite), the noise covariance, the floor (parts 1 + 2)."""
    for a in range(2):
        z[a] = force[a] if math.isfinite(std[a]) else np.nan
        for b in range(2):
            Rn[a, b] = parts[0, a, b]
            floor[a, b] = parts[1, a, b] + parts[2, a, b]


@njit(cache=True)
def measure(force, std, parts, z, Rn, floor):
    """:func:`measure_frame` over frames (B,)."""
    for k in range(force.shape[0]):
        measure_frame(force[k], std[k], parts[k], z[k], Rn[k], floor[k])


@njit(cache=True)
def fill_floor(floor, starts, backward, out):
    """The floor (B, 2, 2) of a frame without a finite one: the latest of its segment (else the next, ``backward``).

    A frame whose floor no frame of its segment gives (before it, or after it with
    ``backward``) gets NaN: nothing is added to its covariance.
    """
    B = floor.shape[0]
    take = np.empty(B, dtype=np.int64)
    last = -1
    for k in range(B):
        if starts[k]:
            last = -1
        if math.isfinite(floor[k, 0, 0] + floor[k, 0, 1] + floor[k, 1, 0] + floor[k, 1, 1]):
            last = k
        take[k] = last
    if backward:
        nxt = -1
        for k in range(B - 1, -1, -1):
            if math.isfinite(floor[k, 0, 0] + floor[k, 0, 1] + floor[k, 1, 0] + floor[k, 1, 1]):
                nxt = k
            if take[k] < 0:
                take[k] = nxt
            if starts[k]:
                nxt = -1
    for k in range(B):
        for a in range(2):
            for b in range(2):
                out[k, a, b] = floor[take[k], a, b] if take[k] >= 0 else np.nan


@njit(cache=True)
def stream_filter(t, pressure, force_in, std_in, parts, q, window_s, dt_ref, gap_factor, step_pa, fs, x, P, Rbar,
                  has, carry, starts, force, std, cov):
    """The causal filter over a block (b,), its state carried in ``fs``, ``x``, ``P``, ``R̄``, ``has``, ``carry``.

    ``pressure`` (b,) NaN where unknown; a frame starts a segment (``starts``) when it is the
    first ever, or after an interval over ``gap_factor × dt_ref`` or ``window_s``, or a
    pressure change over ``step_pa``. ``carry`` (2, 2) is the segment's latest finite floor.

    Returns the number of frames whose force is not finite (0: every frame has one), or,
    before touching the state, ``−1 − i`` when frame i's time is not finite or goes back.
    """
    last = fs[LAST_T] if fs[HAS_LAST] > 0.0 else -np.inf
    for i in range(t.size):
        if not (math.isfinite(t[i]) and t[i] >= last):
            return -1 - i
        last = t[i]
    missing = 0
    S, Kg, T = np.empty((2, 2)), np.empty((4, 2)), np.empty((4, 4))
    z, Rn, floor = np.empty(2), np.empty((1, 2, 2)), np.empty((2, 2))
    for i in range(t.size):
        if fs[HAS_LAST] > 0.0:
            dt = t[i] - fs[LAST_T]
            brk = dt > gap_factor * dt_ref or dt > window_s or abs(pressure[i] - fs[LAST_P]) > step_pa
        else:
            dt, brk = 0.0, True
        starts[i] = brk
        measure_frame(force_in[i], std_in[i], parts[i], z, Rn[0], floor)
        if not (math.isfinite(force_in[i, 0]) and math.isfinite(force_in[i, 1])):
            missing += 1
        K.advance(x, P, Rbar, has, dt, brk, q)
        K.observe(x, P, Rbar, has, Rn, 0, z[0], z[1], S, Kg, T)
        full = math.isfinite(floor[0, 0] + floor[0, 1] + floor[1, 0] + floor[1, 1])
        if full:
            carry[:, :] = floor
        elif brk:
            carry[:, :] = np.nan
        K.finish_frame(x, P, carry, force[i], std[i], cov[i])
        fs[HAS_LAST], fs[LAST_T], fs[LAST_P] = 1.0, t[i], pressure[i]
    return missing


@njit(cache=True)
def stream_windows(t, starts, resid, jac, mfac, shifts, err, coils, gap, window_s, fs, rsum, Asum, Msum, Ssum, p_out):
    """Each frame's p-value of the latest completed window (b,); the open window's sums carried across blocks.

    A window ``floor((t − t_segment) / window_s)`` closes when a frame of the next one or
    of a new segment arrives; its p-value (NaN under MIN_FRAMES usable frames) holds from
    that frame on. Returns whether any frame's p is below MISFIT_P.
    """
    model = ShiftErrorModel(*err)
    misfit = False
    for i in range(t.size):
        if starts[i]:
            fs[SEG_T0] = t[i]
        j = math.floor((t[i] - fs[SEG_T0]) / window_s + 1e-9)
        if fs[HAS_OPEN] > 0.0 and (starts[i] or j != fs[WIN_J]):
            fs[LATEST_P] = W.window_statistic(rsum, Asum, Msum, Ssum, int(fs[WIN_N]), model, coils, gap)
            rsum[:] = 0.0
            Asum[:, :] = 0.0
            Msum[:, :] = 0.0
            Ssum[:] = 0.0
            fs[WIN_N] = 0.0
        fs[WIN_N] += W.window_sums(i, i + 1, resid, jac, mfac, shifts, rsum, Asum, Msum, Ssum)
        fs[WIN_J] = j
        fs[HAS_OPEN] = 1.0
        p_out[i] = fs[LATEST_P]
        misfit = misfit or p_out[i] < MISFIT_P
    return misfit


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
