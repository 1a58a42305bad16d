"""The live step: a block of one finger's frames in one compiled call (DESIGN.md section 2c).

:func:`live_block` runs the chain of :func:`bendsense.pipeline.process` on a block, in the
order a frame flows, on the processor's state:

readings → ΔA → shifts → PCC shape (:func:`bendsense.shape._kernels.reconstruct_block`) →
the beam's inputs at the pressure, clipped to the actuator's range (θ(P) from the
free-bending table, EI(P), the covariance of (K0, EI) from the parameters',
:func:`bendsense.mechanics._actuator_kernels.model_inputs`) → force and σ
(:func:`bendsense.estimation._kernels.estimate_block`, warm-started from the previous
block's last good frame, a failed frame retried cold) →
the plausibility marks (a force beyond what the actuator carries, a pressure outside its
range) → the causal track and the streaming window check
(:mod:`bendsense.tracking._stream_kernels`) → the statuses (:mod:`bendsense.results._kernels`,
the rules of the offline outputs).

Every stage is the offline chain's own kernel; this module only strings them together so
that Python touches a block once (``tests/pipeline/test_live_step.py`` compares the two
frame by frame).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit
from bendsense.estimation import _kernels as est_kernels
from bendsense.mechanics import _actuator_kernels as act
from bendsense.results._kernels import estimate_code, frame_code, track_code
from bendsense.shape import _kernels as shape_kernels
from bendsense.status import MISFIT_P, Status
from bendsense.tracking import _stream_kernels as stream

_NO_SHAPE = int(Status.NO_SHAPE)
_IMPLAUSIBLE_FORCE = int(Status.IMPLAUSIBLE_FORCE)
_OUT_OF_RANGE = int(Status.PRESSURE_OUT_OF_RANGE)
_NO_PRESSURE = int(Status.NO_PRESSURE)
_RUNNING = int(Status.RUNNING)


@njit(cache=True)
def clear(out):
    """The estimate's outputs ``out`` (:class:`bendsense.estimation.problem.Outputs`) as for a frame not estimated."""
    out[0][...] = np.nan
    out[1][...] = np.nan
    out[2][...] = _RUNNING
    out[3][...] = 0
    out[4][...] = np.nan
    out[5][...] = np.nan
    out[6][...] = np.nan
    out[7][...] = np.nan
    out[8][...] = np.nan
    out[9][...] = np.nan
    out[10][...] = 0.0
    out[11][...] = np.nan
    out[12][...] = np.nan
    out[13][...] = False
    out[14][...] = np.nan
    out[15][...] = np.nan


@njit(cache=True)
def outputs(n, N, R, nodes):
    """The estimate's outputs of ``n`` frames (:class:`bendsense.estimation.problem.Outputs`), as not estimated."""
    out = (np.empty((n, 2)), np.empty((n, 2, 2)), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64),
           np.empty(n), np.empty(n), np.empty(n), np.empty((n, 2)), np.empty((n, nodes)), np.empty((n, 2)),
           np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 3, 2, 2)), np.empty(n, dtype=np.bool_),
           np.empty((n, R, 6)), np.empty((n, N)))
    clear(out)
    return out


@njit(cache=True)
def scatter(part, rows, out):
    """The estimate's outputs ``part`` of the frames ``rows`` into those of the whole block ``out``."""
    for k in range(rows.size):
        i = rows[k]
        out[0][i] = part[0][k]
        out[1][i] = part[1][k]
        out[2][i] = part[2][k]
        out[3][i] = part[3][k]
        out[4][i] = part[4][k]
        out[5][i] = part[5][k]
        out[6][i] = part[6][k]
        out[7][i] = part[7][k]
        out[8][i] = part[8][k]
        out[9][i] = part[9][k]
        out[10][i] = part[10][k]
        out[11][i] = part[11][k]
        out[12][i] = part[12][k]
        out[13][i] = part[13][k]
        out[14][i] = part[14][k]
        out[15][i] = part[15][k]


@njit(cache=True, inline="always")
def estimate(kappa, p, rows, model, problem, previous, out):
    """Force and σ of the frames ``rows`` (those with a pressure), into ``out``.

    Their frames are one chain (:func:`~bendsense.estimation._kernels.estimate_block`),
    as :func:`bendsense.estimation.estimate_force` runs a series: the first starts at its
    moment-balance guess corrected by ``previous`` (2,), the offset of the last good frame
    before it from its own guess (zero at the start), each next one by its predecessor's;
    a frame that fails from a warm start is retried cold. ``previous`` becomes the last
    good frame's offset. Then the marks of :func:`~bendsense.estimation.estimate_force`: a
    force beyond ``force_scale · EI(P)`` is ``IMPLAUSIBLE_FORCE`` (kept), a pressure
    outside the range ``PRESSURE_OUT_OF_RANGE`` (estimated at the range's end, no force).
    Returns (frames estimated, frames failed, frames marked).
    """
    p_lo, p_hi, table, prebend, length, ei0, ei1, cov, has_cov, mu, mu_s, c_a, force_scale, contact = model
    held, R, nodes, at = problem
    m = rows.size
    whole = m == p.size
    part = out if whole else outputs(m, kappa.shape[1], R, nodes)
    pm = p if whole else p[rows]
    pc = np.minimum(np.maximum(pm, p_lo), p_hi)
    theta, ei, k0, model_cov = np.empty(m), np.empty(m), np.empty(m), np.empty((m, 2, 2))
    act.model_inputs(pc, table, prebend, length, ei0, ei1, cov, has_cov, mu, mu_s, c_a, theta, ei, k0, model_cov)
    none = np.empty((0, 1))
    YES, NO = bool(est_kernels.YES), bool(est_kernels.NO)  # not literals: the signature estimate_force compiled
    fr = (kappa if whole else kappa[rows], np.empty((0, 1, 2)), np.empty(0), none, none, np.empty(0), ei, k0, theta,
          model_cov, np.full(m, contact))
    force, cov_f, status, _, residual, chi2, pval, guess, _, _, _, std, parts, success, pay, _ = part
    start = np.empty((m, 2))
    start[:, 0] = previous[0]
    start[:, 1] = previous[1]
    est_kernels.estimate_block(0, m, YES, YES, fr, held, start, part, 0, at)
    failed = 0
    marked = 0
    for i in range(m):
        if not success[i] and (i > 0 or previous[0] != 0.0 or previous[1] != 0.0):
            start[i, :] = 0.0  # a start far from the frame (a fast change): its own start may converge
            est_kernels.estimate_block(i, i + 1, YES, NO, fr, held, start, part, 0, at)
        failed += not success[i]
        magnitude = math.hypot(force[i, 0], force[i, 1])
        if success[i] and math.isfinite(magnitude) and magnitude > force_scale * ei[i]:
            success[i] = False
            status[i] = _IMPLAUSIBLE_FORCE
            marked += 1
        if pm[i] < p_lo or pm[i] > p_hi:
            force[i, :] = np.nan
            std[i, :] = np.nan
            cov_f[i, :, :] = np.nan
            residual[i] = np.nan
            chi2[i] = np.nan
            pval[i] = np.nan
            parts[i, :, :, :] = np.nan
            pay[i, :, 0] = np.nan
            success[i] = False
            status[i] = _OUT_OF_RANGE
            marked += 1
        if success[i]:  # the next start: the last good frame's offset from its guess
            previous[0] = force[i, 0] - guess[i, 0]
            previous[1] = force[i, 1] - guess[i, 1]
    if not whole:
        scatter(part, rows, out)
    return m, failed, marked


@njit(cache=True, inline="always")
def track(t, p, out, tracker, windows, window_model, tforce, tstd, tcov, window_p):
    """The causal track of the block and its window check (:class:`bendsense.tracking.Tracker`'s kernels).

    ``tracker``: (q, window_s, dt_ref, gap factor, pressure step, carried scalars, x, P,
    R̄, has, carry, the open window's sums (r, A, M, shifts)); ``window_model``: the shift
    error model and the coils of the window test. Returns the frames without a force (or
    ``−1 − i`` for a time that goes back, nothing done).
    """
    force, _, _, _, _, _, _, _, _, _, _, std, parts, _, pay, shifts = out
    q, window_s, dt_ref, gap_factor, step_pa, fs, x, P, Rbar, has, carry, rsum, Asum, Msum, Ssum = tracker
    n = t.size
    starts = np.empty(n, dtype=np.bool_)
    missing = stream.stream_filter(t, p, force, std, parts, q, window_s, dt_ref, gap_factor, step_pa, fs, x, P, Rbar,
                                   has, carry, starts, tforce, tstd, tcov)
    if missing < 0 or not windows:
        return missing
    err, coils, gap = window_model
    resid = np.ascontiguousarray(pay[:, :, 0])
    jac = np.ascontiguousarray(pay[:, :, 1:3])
    mfac = np.ascontiguousarray(pay[:, :, 3:5])
    stream.stream_windows(t, starts, resid, jac, mfac, shifts, err, coils, gap, window_s, fs, rsum, Asum, Msum, Ssum,
                          window_p)
    return missing


@njit(cache=True, inline="always")
def _run(f, o, shape):
    """The values of ``f`` from offset ``o`` as a view of ``shape`` (a tuple), and the offset after them."""
    size = 1
    for d in shape:
        size *= d
    return f[o:o + size].reshape(shape), o + size


@njit(cache=True, inline="always")
def carve(n, e, N, M, R, nodes, f, ints, bools, codes):
    """The step's outputs of ``n`` frames as views of its four buffers, each output one run of a buffer.

    ``e``: the frames estimated (``n``, or 0 without estimating); ``N`` channels, ``M``
    points of a shape, ``R`` coils fitted, ``nodes`` of the beam. ``f`` float64, ``ints``
    int64 (the counts (5,), then the estimate's codes), ``bools`` bool, ``codes`` int8.
    Returns (shapes, the estimate's, the track's, the frames' status, counts), as
    :func:`live_block` documents them. The order is that of
    :func:`bendsense.pipeline.live._fields`, which sizes the buffers and makes a block's
    arrays as views at the same offsets (one array per buffer crosses the call, not 30);
    ``tests/pipeline/test_live_step.py`` checks that the two agree.
    """
    kappa, o = _run(f, 0, (n, N))
    pos, o = _run(f, o, (n, M, 2))
    ang, o = _run(f, o, (n, M))
    tip, o = _run(f, o, (n, 2))
    tip_ang, o = _run(f, o, (n,))
    force, o = _run(f, o, (e, 2))
    cov, o = _run(f, o, (e, 2, 2))
    residual, o = _run(f, o, (e,))
    chi2, o = _run(f, o, (e,))
    pval, o = _run(f, o, (e,))
    guess, o = _run(f, o, (e, 2))
    state, o = _run(f, o, (e, nodes))
    etip, o = _run(f, o, (e, 2))
    direction, o = _run(f, o, (e, 2))
    std, o = _run(f, o, (e, 2))
    parts, o = _run(f, o, (e, 3, 2, 2))
    pay, o = _run(f, o, (e, R, 6))
    shifts, o = _run(f, o, (e, N))
    tforce, o = _run(f, o, (n, 2))
    tstd, o = _run(f, o, (n, 2))
    tcov, o = _run(f, o, (n, 2, 2))
    window_p, _ = _run(f, o, (n,))
    out = (force, cov, ints[5:5 + e], ints[5 + e:5 + 2 * e], residual, chi2, pval, guess, state, etip, direction, std,
           parts, bools[n:n + e], pay, shifts)
    return ((kappa, pos, ang, tip, tip_ang, bools[:n]), out, (tforce, tstd, tcov, window_p, codes[:n]), codes[n:],
            ints[:5])


@njit(cache=True, nogil=True)
def live_block(a, p, t, constants, previous, tracker, f, ints, bools, codes):
    """One block of frames (n,) of one finger, readings to statuses (module docstring), into the outputs given.

    ``a`` (n, N) raw signals, ``p`` (n,) pressures (NaN: none), ``t`` (n,) times;
    ``constants``: the step's, :func:`~bendsense.estimation._kernels.hold` of (shape, model, problem, flags,
    window_model): ``shape`` the calibration and the PCC grid (offset, coefficients, ΔA
    range, lengths, strip gap, the points' segments and arc lengths within them);
    ``model`` and ``problem`` :class:`bendsense.estimation.Compiled`'s (the problem's
    first item, the estimate's constants, held); ``flags`` whether
    to estimate, track and check windows; ``window_model`` the shift error model, the
    coils and the strip gap of the window test. ``previous`` (2,): the warm start,
    carried; ``tracker``: :meth:`bendsense.tracking.Tracker.stream_state`. Outputs: the
    shapes (κ, positions, angles, tip, tip angle, extrapolated), the estimate's (n frames
    when estimating, else none; :class:`~bendsense.estimation.problem.Outputs`), the
    track's (force, σ, covariance, window p, status), the frames' status (n,) and
    ``counts`` (frames estimated, failed, marked, without a force in the track, tracked
    while the latest window failed the test).

    The outputs are the caller's (no array is returned): a compiled call that returns
    arrays runs Python code as it hands them over, where a stop signal's handler would
    raise into numba's own code. The call releases the GIL (``nogil``): the driver's
    reader thread takes in the next frames while a control loop's block is computed.
    """
    shape, model, problem, flags, window_model = constants[0]
    estimating, tracking, windows = flags
    offset, coef, lo, hi, lengths, gap, seg, sigma = shape
    n, N = a.shape[0], lengths.size
    out_shape, out, out_track, status, counts = carve(n, n if estimating else 0, N, seg.size, problem[1], problem[2],
                                                      f, ints, bools, codes)
    kappa, pos, ang, tip, tip_ang, extrapolated = out_shape
    tforce, tstd, tcov, window_p, tstatus = out_track
    shape_kernels.reconstruct_block(0, n, a, offset, coef, lo, hi, lengths, gap, np.zeros(n), seg, sigma, kappa, pos,
                                    ang, tip, tip_ang, extrapolated)
    has_p = np.empty(n, dtype=np.bool_)
    finite = np.empty(n, dtype=np.bool_)
    for i in range(n):
        has_p[i] = math.isfinite(p[i])
        finite[i] = True
        for j in range(N):
            finite[i] = finite[i] and math.isfinite(kappa[i, j])
    rows = np.flatnonzero(has_p & finite)  # the frames with a force to estimate
    counts[:] = 0
    tforce[...] = np.nan
    tstd[...] = np.nan
    tcov[...] = np.nan
    window_p[...] = np.nan
    tstatus[...] = _RUNNING
    if estimating:
        clear(out)
    estimating = estimating and rows.size > 0
    if estimating:
        counts[0], counts[1], counts[2] = estimate(kappa, p, rows, model, problem, previous, out)
    if estimating and tracking:
        counts[3] = track(t, p, out, tracker, windows, window_model, tforce, tstd, tcov, window_p)
        for i in range(n):
            counts[4] += window_p[i] < MISFIT_P
    force, success, est_status = out[0], out[13], out[2]
    for i in range(n):
        own = _RUNNING
        if estimating:
            if not has_p[i]:
                est_status[i] = _NO_PRESSURE
            elif not finite[i]:
                est_status[i] = _NO_SHAPE
            own = estimate_code(est_status[i], success[i], force[i, 0], force[i, 1], False)
            tstatus[i] = track_code(own, window_p[i], tforce[i, 0], tforce[i, 1], tstd[i, 0], tstd[i, 1])
        status[i] = frame_code(extrapolated[i], finite[i], tip_ang[i], estimating, own, success[i] if estimating
                               else False)
        if not has_p[i]:
            status[i] = _NO_PRESSURE


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
