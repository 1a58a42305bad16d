"""Compiled per-frame kernels of the force estimate (paper eq. 18 and 21).

One frame: the moment-balance start (:func:`moment_guess`), the projected Gauss–Newton
iteration with a trust region on the constraint parameters ``u`` (:func:`gauss_newton`,
``F = F_fixed + D u``, ``u ≥ lower``) around the spectral beam solver of
:mod:`bendsense.mechanics._beam_kernels`, and the uncertainty propagation
(:mod:`bendsense.estimation.uncertainty`). :func:`estimate_frames` is the batch: a
``prange`` loop over blocks of consecutive frames, each block run in order so that a
frame's start is corrected by its predecessor's offset from its own moment-balance start
(warm start along a time series).

The residual is pluggable: :func:`objective` evaluates the weighted residual vector of
the model shape against the measured one and its Jacobian by F; the positions objective
(paper eq. 18) compares points of the beam with the PCC shape at quadrature nodes.

The stages of a frame that one kernel calls (``setup``, ``moment_guess``,
``gauss_newton`` and its ``first_solve``, ``finish`` and the covariances it calls) are
inlined into their caller (``inline="always"``): numba builds every compiled function
with its callees' code and optimises and generates the whole again, so each level of a
deep tree pays for the levels below it, and the shallower tree compiles faster on the
first run (docs/performance.md); the beam solve, called from several places, stays a
function of its own.
"""

import math

import numpy as np
from numba import njit, prange
from numba.typed import List

from bendsense import _jit
from bendsense.calibration._kernels import shift_covariance
from bendsense.calibration.shift_errors import ShiftErrorModel
from bendsense.estimation import problem as prob
from bendsense.estimation import uncertainty as unc
from bendsense.estimation.problem import BuffersRef, Outputs, Target, WorkspaceRef
from bendsense.mechanics import _beam_kernels as bk
from bendsense.status import MISFIT_P, Status

_RUNNING = int(Status.RUNNING)
_OK = int(Status.OK)
_BEAM_FAILED = int(Status.BEAM_FAILED)
_NOT_CONVERGED = int(Status.NOT_CONVERGED)
_NOT_IDENTIFIABLE = int(Status.NOT_IDENTIFIABLE)
_NO_STABLE_MATCH = int(Status.NO_STABLE_MATCH)
_MODEL_MISFIT = int(Status.MODEL_MISFIT)

# flags to compiled callees go through bool()/int(): numba compiles a callee once per literal
# value it is called with, and once for all non-literal values (compile time)
YES, NO = bk.YES, bk.NO
NEWTON_TOL = bk.NEWTON_TOL

POSITIONS, ANGLES = prob.POSITIONS, prob.ANGLES

FORCE_SENS, CONTACT_SENS = 1, 2  # the beam's sensitivity levels (bendsense.mechanics._beam_kernels.solve_frame)
MAX_JUMPS = 8  # trial steps off the stable branch before stopping at the boundary
BOUNDARY_MISFIT = 0.05  # RMS residual / L beyond which a shape is no bending of the model actuator
SIGMA_STEP = 1e-3  # an error left below this many σ (a whitened cost) changes nothing a user can see: converged
FLAT = 2.0  # σ beyond FLAT · EI/L² (the force that bends the actuator a radian): the data do not determine it
NEWTON_MAX_ITER = 30


@njit(cache=True)
def force_of(D, ffix, u, out):
    """F = F_fixed + D u."""
    for a in range(2):
        acc = ffix[a]
        for c in range(u.size):
            acc += D[a, c] * u[c]
        out[a] = acc


@njit(cache=True, inline="always")
def moment_guess(p0, s, w, L, ei, k0, wload, D, ffix, lower, phi_end, kappa_s, group, s_c, u):
    """Starting force from the moment balance ``EI (κ(s) − K0) = −M_z(s)`` (linear in F).

    With the reference shape's curvature and points, the moment of the force at ``s_c``
    (the tip: L) about ``r(s)``, ``(r(s_c) − r(s)) × F`` for s < s_c, and of the
    distributed load are known: a small
    weighted linear least-squares problem in ``u``. The balance is integrated over each
    group of comparison nodes (``group`` (M,), ascending): over a PCC segment, where the
    sensor measures the integral of the curvature ``κ_i l_i`` exactly and not its course,
    the integrated balance has no PCC bias; a shape given by points has one node per
    group (exact for a beam-model shape). A ridge keeps directions it hardly sees near
    zero; beyond 3 EI/L² the guess is scaled down.
    """
    M = s.size
    k = u.size
    if s_c >= s[M - 1]:  # beyond the last point: along its tangent
        tx = p0[M - 1, 0] + (s_c - s[M - 1]) * math.sin(phi_end)
        ty = p0[M - 1, 1] + (s_c - s[M - 1]) * math.cos(phi_end)
    else:  # between two points (the base and the first): the chord
        j = 0
        while s[j] <= s_c:
            j += 1
        s0, x0, y0 = (s[j - 1], p0[j - 1, 0], p0[j - 1, 1]) if j > 0 else (0.0, 0.0, 0.0)
        t = (s_c - s0) / (s[j] - s0)
        tx = x0 + t * (p0[j, 0] - x0)
        ty = y0 + t * (p0[j, 1] - y0)
    H = np.zeros((k, k))
    g = np.zeros(k)
    A = np.zeros(k)  # the group's ∫ (moment arm · D) ds, ∫ (the known moments) ds and length
    C = 0.0
    W = 0.0
    tail_x = 0.0  # ∫_{s_j}^{L} r dσ, accumulated from the tip
    tail_y = 0.0
    nx, ny = tx, ty  # the next point out
    ns = L
    for j in range(M - 1, -1, -1):
        tail_x += 0.5 * (nx + p0[j, 0]) * (ns - s[j])
        tail_y += 0.5 * (ny + p0[j, 1]) * (ns - s[j])
        nx, ny, ns = p0[j, 0], p0[j, 1], s[j]
        arm_x = tail_x - (L - s[j]) * p0[j, 0]
        arm_y = tail_y - (L - s[j]) * p0[j, 1]
        ax = -(ty - p0[j, 1]) if s[j] < s_c else 0.0  # M_F = a · F
        ay = tx - p0[j, 0] if s[j] < s_c else 0.0
        c = ei * (kappa_s[j] - k0) + arm_x * wload[1] - arm_y * wload[0] + ax * ffix[0] + ay * ffix[1]
        for q in range(k):
            A[q] += w[j] * (ax * D[0, q] + ay * D[1, q])
        C += w[j] * c
        W += w[j]
        if j == 0 or group[j - 1] != group[j]:  # the group is complete: its balance into the normal equations
            for q in range(k):
                g[q] += A[q] * C / W
                for r in range(k):
                    H[q, r] += A[q] * A[r] / W
                A[q] = 0.0
            C = 0.0
            W = 0.0
    tr = 0.0
    for q in range(k):
        tr += H[q, q]
    for q in range(k):
        H[q, q] += 1e-6 * tr / k
    unc.lm_step(H, g, u)
    norm = 0.0
    for q in range(k):
        norm += u[q] * u[q]
    norm = math.sqrt(norm)
    f = min(1.0, 3.0 * ei / (L * L) / max(norm, 1e-300))
    for q in range(k):
        v = u[q] * f
        u[q] = max(v if math.isfinite(v) else 0.0, lower[q])


@njit(cache=True)
def workspace(M, n, R):
    """Buffers of one beam evaluation (:class:`Workspace`): M comparison nodes, n state nodes, R fitted values."""
    return WorkspaceRef(np.empty((M, 2)), np.empty((M, 2, 2)), np.empty(n), np.empty(6), np.empty((n, 5)), np.empty(R),
                        np.empty((R, 2)), np.empty((R, 3)), np.empty((n - 1, bk.extra_columns(FORCE_SENS))),
                        bk.solver_work(n))


@njit(cache=True)
def beam_eval(L, ei, k0, F, wload, state, has_state, allow_continuation, ops, fit, ws):
    """The beam at force ``F`` and its fitted response with ∂y/∂F, into the workspace ``ws``; True if stable.

    ``ops``: the frame's beam operators, of its contact point (the force acts there;
    :func:`bendsense.mechanics._beam_kernels.contact_grid`); ``fit``: what it reads of the
    point's problem (:func:`fitted`; :func:`~bendsense.estimation.problem.contact_problem`).
    The positions objective samples the positions at the comparison nodes (rows of
    ``PQ_fit``), the angles objective interpolates the tangent angle at the coils (rows
    of ``PA``): ``φ(L_i)``, what the sensor measures as ``S_i / d``.
    """
    pos, dpos, st, tip, dst, y, dy, extra = ws.pos, ws.dpos, ws.state, ws.tip, ws.dphi, ws.y, ws.dy, ws.extra
    objective, PQ_fit, q, PA = fit
    n = st.size
    status, _, _ = bk.solve_frame(L, ei, k0, 0.0, F[0], F[1], wload[0], wload[1], state, has_state, ops, NEWTON_TOL,
                                  int(NEWTON_MAX_ITER), int(FORCE_SENS), allow_continuation, st, extra, ws.solver)
    bk.node_sensitivity(extra, L, ei, dst)
    # the model inputs: ∂φ/∂K0 = L ψ (ψ = ∂φ/∂(K0 L), the Jacobi field); EI scales the
    # load factor, λ ∝ 1/EI: ∂φ/∂EI = −(dφ/dλ)/EI at λ = 1 (∂φ/∂s_c: contact_jacobian)
    dst[0, 2] = 0.0
    dst[0, 3] = 0.0
    for i in range(n - 1):
        dst[i + 1, 2] = extra[i, 0] * L
        dst[i + 1, 3] = -extra[i, 3] / ei
    bk.sample(st, dst, L, PQ_fit, q, bool(YES), pos, dpos, tip)
    if objective == ANGLES:
        for i in range(y.size):
            a = 0.0
            d0 = 0.0
            d1 = 0.0
            for j in range(n):
                a += PA[i, j] * st[j]
                d0 += PA[i, j] * dst[j, 0]
                d1 += PA[i, j] * dst[j, 1]
            y[i] = a
            dy[i, 0] = d0
            dy[i, 1] = d1
    else:
        for j in range(pos.shape[0]):
            for a in range(2):
                y[2 * j + a] = pos[j, a]
                dy[2 * j + a, 0] = dpos[j, a, 0]
                dy[2 * j + a, 1] = dpos[j, a, 1]
    return status == _OK


@njit(cache=True, inline="always")
def fitted(pb):
    """What :func:`beam_eval` needs of the problem ``pb``: (objective, PQ_fit, q, PA).

    A compiled call takes a reference to every array it is given, at its start and end:
    the problem's ~25 arrays at each beam solve cost more than its lines.
    """
    return pb.objective, pb.PQ_fit, pb.q, pb.PA


@njit(cache=True)
def whitened(ws, tg):
    """The whitened residual e (R,) and its Jacobian ∂e/∂F (R, 2) of the target ``tg``, into ``ws.e`` (R, 3).

    ``tg``: the :class:`Target` (y⁰, √w, L_w, whiten): e = √w (y − y⁰) with per-row weights (positions,
    paper eq. 18's quadrature), or e = L_w⁻¹ (y − y⁰) with L_w the Cholesky factor of the
    measured angles' covariance (angles objective: weights Σ_θ⁻¹).
    """
    y, dy, e = ws.y, ws.dy, ws.e
    y0, sw, Lw, whiten = tg
    R = y.size
    for i in range(R):
        e[i, 0] = (y[i] - y0[i]) * sw[i]
        e[i, 1] = dy[i, 0] * sw[i]
        e[i, 2] = dy[i, 1] * sw[i]
    if whiten:
        unc.forward(Lw, e)
    return e


@njit(cache=True)
def objective(ws, tg, gF, GF):
    """The cost ‖e‖² of the whitened residual (:func:`whitened`), its force gradient and Gram matrix.

    Writes ``gF`` (2,) = (∂e/∂F)ᵀ e and ``GF`` (2, 2) = (∂e/∂F)ᵀ ∂e/∂F; returns the cost.
    For the positions objective the cost is Σ w ‖p − p⁰‖² (paper eq. 18).
    """
    e = whitened(ws, tg)
    cost = 0.0
    gF[:] = 0.0
    GF[:, :] = 0.0
    for i in range(e.shape[0]):
        cost += e[i, 0] * e[i, 0]
        for b in range(2):
            gF[b] += e[i, 1 + b] * e[i, 0]
            for c in range(2):
                GF[b, c] += e[i, 1 + b] * e[i, 1 + c]
    return cost


@njit(cache=True)
def project(D, gF, GF, g, H):
    """Reduced gradient Dᵀ g_F and Gauss–Newton matrix Dᵀ G_F D."""
    k = g.size
    for q in range(k):
        g[q] = D[0, q] * gF[0] + D[1, q] * gF[1]
        for r in range(k):
            acc = 0.0
            for a in range(2):
                for b in range(2):
                    acc += D[a, q] * GF[a, b] * D[b, r]
            H[q, r] = acc


@njit(cache=True)
def convex_start(L, ei, wload, D, ffix, lower, beyond, u, out):
    """``u`` scaled toward the fixed force (1, 0.8, …, 0) while the load stays provably convex (ρ < 0.9)."""
    scale = L * L / ei
    k = u.size
    best = 0.0
    F = np.empty(2)
    ut = np.empty(k)
    for t in (0.2, 0.4, 0.6, 0.8, 1.0):
        for c in range(k):
            ut[c] = max(u[c] * t, lower[c])
        force_of(D, ffix, ut, F)
        if bk.load_ratio(F[0] * scale, F[1] * scale, wload[0] * L * scale, wload[1] * L * scale, beyond) < 0.9:
            best = t
    for c in range(k):
        out[c] = max(u[c] * best, lower[c])


@njit(cache=True, inline="always")
def first_solve(L, ei, k0, wload, tg, D, ffix, lower, u, state0, ops, fit, ws, trial, buf):
    """The iteration's first beam at ``u`` (into ``ws``); returns (stable, beam solves, ws, trial).

    Newton starts from the reference shape ``state0`` where the load is provably convex,
    else by continuation from the unloaded arc; a start that fails restarts at zero force;
    a start beyond the convexity bound competes with the same start scaled into the convex
    region (the lower cost wins; ``trial`` is scratch: the two trade places when it wins).
    """
    k = u.size
    for c in range(k):
        u[c] = max(u[c], lower[c])
    F = buf.gram[0, 0]
    force_of(D, ffix, u, F)
    scale = L * L / ei
    wx, wy = wload[0] * L, wload[1] * L
    beyond = ops.tail[ops.jrow]  # 1 − σ_c: the weight beyond the contact point
    unique = bk.load_ratio(F[0] * scale, F[1] * scale, wx * scale, wy * scale, beyond) < 1.0
    gmax = max(math.hypot(F[0] + wx * beyond, F[1] + wy * beyond), math.hypot(F[0] + wx, F[1] + wy),
               math.hypot(wx, wy) * beyond)
    convex = gmax * scale < 0.9 * bk.STABLE_BOUND
    iters = 1
    ok = beam_eval(L, ei, k0, F, wload, state0, unique, bool(YES), ops, fit, ws)
    if not ok:
        # the start may buckle the beam or lead Newton astray: start over from the unloaded
        # arc by continuation at the constraint's zero force
        for c in range(k):
            u[c] = max(0.0, lower[c])
        force_of(D, ffix, u, F)
        ok = beam_eval(L, ei, k0, F, wload, state0, bool(NO), bool(YES), ops, fit, ws)
        iters += 1
    if not convex and ok:
        gF, GF, uc = buf.gram[1, 0], buf.gram[2], buf.guess[10]
        convex_start(L, ei, wload, D, ffix, lower, beyond, u, uc)
        moved = False
        for c in range(k):
            moved |= uc[c] != u[c]
        if moved:
            force_of(D, ffix, uc, F)
            okc = beam_eval(L, ei, k0, F, wload, state0, bool(YES), bool(YES), ops, fit, trial)
            iters += 1
            if okc and objective(trial, tg, gF, GF) < objective(ws, tg, gF, GF):
                bk.copy_into(uc, u)
                ws, trial = trial, ws
    return ok, iters, ws, trial


@njit(cache=True)
def converged(dstep, size, last, H, chi2, xtol):
    """Whether the iteration stops with the step ``dstep`` (k,) of largest component ``size`` [N].

    It stops when the step, or the error left by a contraction at the rate observed
    against the previous step ``last``, is below ``xtol``; or, when the cost is a χ²
    (``chi2``: ``H⁻¹`` the covariance of u), when that error is below ``SIGMA_STEP``
    standard deviations (a flat, poorly determined direction); or when the steps stall at
    the round-off floor of the beam solutions.
    """
    seen = math.isfinite(last)
    rate = size / last if seen else size
    left = size * rate / (1.0 - rate) if seen and rate < 0.5 else size
    small = False
    if chi2 and size > 0.0:
        q = 0.0
        for c in range(dstep.size):
            for r in range(dstep.size):
                q += dstep[c] * H[c, r] * dstep[r]
        small = q * (left / size) ** 2 <= SIGMA_STEP * SIGMA_STEP
    return left <= xtol or small or (seen and size <= 1e3 * xtol and rate > 0.5)


@njit(cache=True)
def advance(ws, dF):
    """The beam in ``ws`` moved by the force step ``dF`` to first order: the last step, taken without a solve.

    The state, the fitted response, the positions and the tip, off by O(``dF``²): the
    frame's residual, χ² and shape are the estimate's, not the last solve's. Their
    sensitivities (and so σ) stay the last solve's, O(``dF``) off.
    """
    st, dst, y, dy, pos, dpos, tip = ws.state, ws.dphi, ws.y, ws.dy, ws.pos, ws.dpos, ws.tip
    for i in range(st.size):
        st[i] += dst[i, 0] * dF[0] + dst[i, 1] * dF[1]
    for i in range(y.size):
        y[i] += dy[i, 0] * dF[0] + dy[i, 1] * dF[1]
    for j in range(pos.shape[0]):
        for a in range(2):
            pos[j, a] += dpos[j, a, 0] * dF[0] + dpos[j, a, 1] * dF[1]
    tip[0] += tip[2] * dF[0] + tip[3] * dF[1]
    tip[1] += tip[4] * dF[0] + tip[5] * dF[1]


@njit(cache=True)
def decrease(g, H, step):
    """The cost decrease −(2 gᵀ step + stepᵀ H step) that the Gauss–Newton model predicts for ``step``."""
    predicted = 0.0
    for c in range(step.size):
        predicted -= 2.0 * g[c] * step[c]
        for r in range(step.size):
            predicted -= step[c] * H[c, r] * step[r]
    return predicted


@njit(cache=True)
def jumped(y, dy, y_trial, dF, floor):
    """Whether the trial response ``y_trial`` lies far from its linear prediction ``y + dy dF``.

    A shape that far has jumped to another branch of equilibria: more than half the
    predicted change, plus ``floor`` (the round-off of the response) [m or rad].
    """
    jump = 0.0
    lin_max = 0.0
    for i in range(y.size):
        lin = dy[i, 0] * dF[0] + dy[i, 1] * dF[1]
        lin_max = max(lin_max, abs(lin))
        jump = max(jump, abs(y_trial[i] - y[i] - lin))
    return not jump <= 0.5 * lin_max + floor  # NaN: jumped


@njit(cache=True, inline="always")
def gauss_newton(L, ei, k0, wload, tg, D, ffix, lower, u, state0, xtol, max_iter, ops, pb, ws, trial, blocked, buf):
    """Projected Gauss–Newton with a trust region on ``u`` (k,) for one frame; ``u`` updated in place.

    The first beam comes from :func:`first_solve`. Each trial solve starts from the
    first-order prediction of the state and may not leave its linear prediction (a jump
    to another branch). Stops by :func:`converged`. Returns (status, beam solves, cost, ws,
    trial): the workspace holding the beam at the last accepted ``u``, and the other
    (``ws`` and the scratch ``trial`` trade places at each accepted step); ``blocked`` the
    last step that left the stable branch (status NOT_IDENTIFIABLE).
    """
    k = u.size
    n = state0.size
    fit = fitted(pb)
    ok, iters, ws, trial = first_solve(L, ei, k0, wload, tg, D, ffix, lower, u, state0, ops, fit, ws, trial, buf)
    if not ok:
        return _BEAM_FAILED, iters, np.nan, ws, trial
    F, gF, GF, dF, gFn, GFn, zero = buf.gram[0, 0], buf.gram[1, 0], buf.gram[2], buf.gram[3, 0], buf.gram[4, 0], \
        buf.gram[5], buf.gram[6, 0]
    cost = objective(ws, tg, gF, GF)
    g, step, dstep, un, H = buf.guess[6], buf.guess[7], buf.guess[8], buf.guess[9], buf.H
    project(D, gF, GF, g, H)
    radius = 0.5 * ei / (L * L)  # trust region in units of the natural force scale EI/L²
    last = np.inf
    jumps = 0
    status = _RUNNING
    guess = buf.state_guess
    weak = False
    for _ in range(max_iter):
        # a χ² cost that does not determine the load along ``blocked`` here: the step keeps
        # to the determined direction; where the iteration ends so (the cost's shape at the
        # optimum, not at the iterates on the way there), the frame is not identifiable along it
        weak = tg.whiten and unc.flat_direction(H, (FLAT * ei / (L * L)) ** -2, blocked)
        if weak:
            unc.restricted_step(H, g, blocked, step)
        else:
            unc.lm_step(H, g, step)
        size = 0.0
        for c in range(k):
            dstep[c] = max(u[c] + step[c], lower[c]) - u[c]
            size = max(size, abs(dstep[c]))
        if converged(dstep, size, last, H, tg.whiten, xtol):
            for c in range(k):
                u[c] += dstep[c]
            force_of(D, zero, dstep, dF)
            advance(ws, dF)
            status = _OK
            break
        last = size
        norm = 0.0
        for c in range(k):
            norm += dstep[c] * dstep[c]
        norm = math.sqrt(norm)
        shrink = min(1.0, radius / norm)
        norm *= shrink
        for c in range(k):
            un[c] = max(u[c] + dstep[c] * shrink, lower[c])
            dstep[c] = un[c] - u[c]
        predicted = decrease(g, H, dstep)
        force_of(D, zero, dstep, dF)
        force_of(D, ffix, un, F)
        st, dst = ws.state, ws.dphi
        for i in range(n):  # first-order prediction of the new state
            guess[i] = st[i] + dst[i, 0] * dF[0] + dst[i, 1] * dF[1]
        okn = beam_eval(L, ei, k0, F, wload, guess, bool(YES), bool(NO), ops, fit, trial)
        iters += 1
        okn = okn and not jumped(ws.y, ws.dy, trial.y, dF, pb.jump_floor)
        cn = objective(trial, tg, gFn, GFn)
        rho = (cost - cn) / (predicted if predicted > 0 else np.inf)
        # below ~1e-6 N the cost change is lost in the beam's round-off: the step is trusted
        acc = okn and (rho > 1e-4 or norm < 1e-6)
        if acc:
            bk.copy_into(un, u)
            ws, trial = trial, ws
            cost = cn
            bk.copy_into(gFn, gF)
            bk.copy_into(GFn, GF)
            project(D, gF, GF, g, H)
            if rho > 0.75 and shrink < 1.0:
                radius *= 4.0
        if not acc or rho < 0.25:
            radius = 0.25 * norm
        if not acc:
            last = np.inf
        if radius < 1e-12:
            status = _NOT_CONVERGED
        if not okn:
            # trials leave the stable branch again and again: the optimum lies at the
            # stability boundary; stop at the best stable point
            jumps += 1
            bk.copy_into(dstep, blocked)
            if jumps >= MAX_JUMPS and status == _RUNNING:
                status = _NOT_IDENTIFIABLE
        if status != _RUNNING:
            break
    if status == _RUNNING:
        status = _NOT_CONVERGED
    if status == _OK and weak:
        status = _NOT_IDENTIFIABLE
    return status, iters, cost, ws, trial


@njit(cache=True, inline="always")
def finish(status, pb, p0, tg, D, dD, u, ws, blocked, frame_cov, cov_s, noise_var, model_cov, kappa, force, cov,
           parts, direction, pay):
    """Status, force, covariance and χ² of a frame after the iteration; returns (status, residual, χ²/dof, p-value).

    A converged fit is ``model_misfit`` (force kept) when its model shape stays over
    ``BOUNDARY_MISFIT`` of the length from the measured one, or when its χ² is beyond
    chance under the stated covariance (p < ``MISFIT_P``). ``pay`` (R, 5): the frame's
    window test payload (:func:`payload`), NaN unless the fit of the coil angles has a force.
    """
    pos, L, w = ws.pos, pb.L, pb.w
    if pb.objective == ANGLES:  # the positions at the comparison nodes, for the residual (no sensitivities)
        bk.sample(ws.state, ws.dphi, L, pb.PQ, pb.q, bool(NO), pos, ws.dpos, ws.tip)
    num = 0.0
    den = 0.0
    for j in range(p0.shape[0]):
        dx = pos[j, 0] - p0[j, 0]
        dy = pos[j, 1] - p0[j, 1]
        num += w[j] * (dx * dx + dy * dy)
        den += w[j]
    residual = math.sqrt(num / den)
    ratio = np.nan
    p = np.nan
    parts[:, :, :] = np.nan
    pay[:, :] = np.nan
    if status == _OK or status == _NOT_IDENTIFIABLE:
        # a covariance with a zero diagonal is zero: no parameter term (the config has no parameter_covariance)
        dym = model_response(pb, ws) if model_cov[0, 0] > 0.0 or model_cov[1, 1] > 0.0 else np.zeros((ws.y.size, 2))
        if pb.objective == ANGLES:
            payload(tg, ws, D, dym, model_cov, pay)
            ratio, p = unc.covariance_angles(whitened(ws, tg), tg, D, dD, pb.shape_angle, u, frame_cov, cov_s, pb.coils,
                                             pb.gap, pb.dphi_ds, ws.dy, cov, noise_var, dym, model_cov, parts)
        else:
            ratio, p = unc.covariance(L, p0, w, D, dD, pb.shape_angle, u, ws.pos, ws.dpos, frame_cov, cov_s, kappa,
                                      pb.lengths, pb.gap, pb.seg, pb.sigma, pb.dphi_ds, cov, noise_var, dym, model_cov,
                                      parts)
    if status == _NOT_IDENTIFIABLE:
        v = np.empty(2)
        force_of(D, np.zeros(2), blocked, v)
        nv = max(math.hypot(v[0], v[1]), 1e-300)
        direction[0] = v[0] / nv
        direction[1] = v[1] / nv
        for a in range(2):
            for b in range(2):
                if abs(direction[a] * direction[b]) > 1e-12:
                    cov[a, b] = np.inf
        if residual > BOUNDARY_MISFIT * L:
            status = _NO_STABLE_MATCH
    if status == _OK or status == _NOT_IDENTIFIABLE:
        force_of(D, pb.ffix, u, force)
        if not (math.isfinite(force[0]) and math.isfinite(force[1])):
            status = _NOT_CONVERGED  # a NaN force is never a success
        elif status == _OK and (residual > BOUNDARY_MISFIT * L or p < MISFIT_P):
            status = _MODEL_MISFIT  # the force is kept, flagged
    if status != _OK and status != _NOT_IDENTIFIABLE and status != _MODEL_MISFIT:
        force[:] = np.nan
        cov[:, :] = np.nan
        parts[:, :, :] = np.nan
        pay[:, :] = np.nan
        ratio = np.nan
        p = np.nan
    return status, residual, ratio, p


@njit(cache=True)
def payload(tg, ws, D, dym, model_cov, pay):
    """What a window test needs of a frame fitted to the coil angles, in raw angle units [rad], into ``pay`` (R, 6).

    Column 0: measured − model angle at the optimum; 1–2: ∂(model angle)/∂u = (∂y/∂F) D,
    its unused columns 0 (k < 2); 3–4: ∂y/∂(K0, EI) · chol(Σ_m), whose outer product is
    the angles' covariance from the model parameters (zero without a parameter
    covariance); 5: NaN, ∂y/∂s_c of a contact (:func:`contact_jacobian`). Copies of what
    the fit has.
    """
    y, dy, y0 = ws.y, ws.dy, tg.y0
    k = D.shape[1]
    l00 = math.sqrt(max(model_cov[0, 0], 0.0))
    l10 = model_cov[1, 0] / l00 if l00 > 0.0 else 0.0
    l11 = math.sqrt(max(model_cov[1, 1] - l10 * l10, 0.0))
    for i in range(y.size):
        pay[i, 0] = y0[i] - y[i]
        for c in range(2):
            pay[i, 1 + c] = dy[i, 0] * D[0, c] + dy[i, 1] * D[1, c] if c < k else 0.0
        pay[i, 3] = dym[i, 0] * l00 + dym[i, 1] * l10
        pay[i, 4] = dym[i, 1] * l11
        pay[i, 5] = np.nan


@njit(cache=True, inline="always")
def contact_jacobian(L, ei, k0, F, wload, ops, pb, ws, out):
    """∂y/∂s_c (R,) [rad/m] of the coil angles at the beam in ``ws``, the force ``F`` fixed, into ``out``.

    The beam's Jacobian at the converged state with one more right-hand side, the jump
    of φ' at s_c (:func:`bendsense.mechanics._beam_kernels.newton`): a Newton iteration from the
    solution. Only for a contact load (the tip load's frames are not slowed by it).
    """
    n = ws.state.size
    st = ws.state.copy()
    extra = np.empty((n - 1, bk.extra_columns(CONTACT_SENS)))
    status, _, _ = bk.solve_frame(L, ei, k0, 0.0, F[0], F[1], wload[0], wload[1], ws.state, bool(YES), ops, NEWTON_TOL,
                                  int(NEWTON_MAX_ITER), int(CONTACT_SENS), bool(NO), st, extra, ws.solver)
    for a in range(out.size):
        acc = 0.0
        for j in range(n - 1):
            acc += pb.PA[a, j + 1] * extra[j, 3]
        out[a] = acc / L if status == _OK else np.nan


@njit(cache=True, inline="always")
def model_response(pb, ws):
    """∂y/∂(K0, EI) (R, 2) of the fitted response at the beam in ``ws`` (:func:`beam_eval`)."""
    dphi = ws.dphi[:, 2:4].copy()
    R = ws.y.size
    out = np.empty((R, 2))
    if pb.objective == ANGLES:
        for i in range(R):
            for c in range(2):
                acc = 0.0
                for j in range(dphi.shape[0]):
                    acc += pb.PA[i, j] * dphi[j, c]
                out[i, c] = acc
    else:
        M = pb.PQ_fit.shape[0]
        pos, dpos, tip = np.empty((M, 2)), np.empty((M, 2, 2)), np.empty(6)
        bk.sample(ws.state, dphi, pb.L, pb.PQ_fit, pb.q, bool(YES), pos, dpos, tip)
        for j in range(M):
            for a in range(2):
                out[2 * j + a, 0] = dpos[j, a, 0]
                out[2 * j + a, 1] = dpos[j, a, 1]
    return out


@njit(cache=True)
def buffers(pb, n):
    """Per-thread buffers of :func:`setup` (:class:`Buffers`)."""
    m = pb.seg_fk.size
    N = pb.lengths.size
    k = pb.lower.size
    R = pb.sw.size
    Rw = R if pb.objective == ANGLES else 1
    return BuffersRef(np.empty((m, 2)), np.empty(m), np.empty(pb.s.size), np.empty(n), np.empty((2, k)),
                      np.empty((2, k)), np.empty((N, N)), np.zeros(N), np.empty(R), np.empty((Rw, Rw)), np.zeros(N),
                      np.empty(N), np.empty(n), np.empty((11, k)), np.zeros((7, 2, 2)), np.empty(n), np.empty((k, k)))


@njit(cache=True)
def scratch(pb, n):
    """What one frame's estimate works in (:func:`buffers`, two :func:`workspace`): kept with its constants."""
    return buffers(pb, n), workspace(pb.s.size, n, pb.sw.size), workspace(pb.s.size, n, pb.sw.size)


@njit(cache=True, inline="always")
def setup(i, fr, pb, err, buf):
    """Frame ``i``'s reference shape, fit target, constraint basis and shift covariance (the kernels' inputs).

    A PCC frame's reference comes from its curvatures
    (:func:`~bendsense.estimation.problem.pcc_reference`); a shape given by points
    brings its own (``fr``: :class:`~bendsense.estimation.problem.Frames`). The target
    (:func:`whitened`) is the reference's positions with the quadrature weights, or the
    measured angles ``S_i / d = Σ_{j ≤ i} κ_j l_j`` at the coils weighted by the inverse
    of their covariance ``Σ_S / d²`` (unweighted without a noise model). Returns (p⁰, φ
    at the last node, κ at the nodes, beam start, target, D, ∂D/∂φ_L, whether Σ_S is
    known, Σ_S, its noise variances, κ) of the frame; the arrays live in ``buf`` (:func:`buffers`).
    """
    pos, ang, ks, st, D, dD, cov_s = buf.pos, buf.ang, buf.ks, buf.state, buf.D, buf.dD, buf.cov_s
    no_kappa, y0, Lw, noise_var, shifts = buf.no_kappa, buf.y0, buf.Lw, buf.noise_var, buf.shifts
    M = ks.size
    if pb.pcc:
        tip = prob.pcc_reference(fr.kappa[i], pb.lengths, pb.seg_fk, pb.sigma_fk, pb.beyond, pb.tip_weights, pos, ang,
                                 ks, st)
        p0, phi_end, kappa_s, state0, kappa = pos[:M], ang[M - 1], ks, st, fr.kappa[i]
    else:
        tip = fr.tip_shape[i]
        p0, phi_end, kappa_s, state0, kappa = fr.p0[i], fr.phi_end[i], fr.kappa_s[i], fr.state[i], no_kappa
    # the constraints at the force's point: the shape's angle there (pb.tip_weights), or the free arc's, K0 s_c
    prob.basis(pb.kind, tip if pb.shape_angle else fr.theta[i] * fr.contact[i], pb.direction, pb.follower_angle, D, dD)
    if pb.pcc:  # φ(L_j) = S_j / d = Σ_{i ≤ j} κ_i l_i (paper eq. 3–4), the angles objective's target
        acc = 0.0
        c = 0
        for j in range(pb.lengths.size):
            acc += kappa[j] * pb.lengths[j]
            shifts[j] = pb.gap * acc
            if c < pb.coils.size and pb.coils[c] == j:
                y0[c] = acc
                c += 1
    frame_cov = pb.pcc and pb.noise and shift_covariance(err, shifts, cov_s, noise_var) > 0
    whiten = False
    if pb.objective == ANGLES:
        if frame_cov:
            inv_d2 = 1.0 / (pb.gap * pb.gap)
            for a in range(pb.coils.size):
                for b in range(pb.coils.size):
                    Lw[a, b] = cov_s[pb.coils[a], pb.coils[b]] * inv_d2
            whiten = unc.cholesky(Lw) > 0
    else:
        for j in range(M):
            y0[2 * j] = p0[j, 0]
            y0[2 * j + 1] = p0[j, 1]
    return p0, phi_end, kappa_s, state0, Target(y0, pb.sw, Lw, whiten), D, dD, frame_cov, cov_s, noise_var, kappa


@njit(cache=True)
def near(u0, prev_u0, prev_u):
    """Whether the start ``u0`` lies closer to the previous start than the previous estimate did."""
    d = 0.0
    off = 0.0
    for c in range(u0.size):
        d += (u0[c] - prev_u0[c]) ** 2
        off += (prev_u[c] - prev_u0[c]) ** 2
    return d <= off


@njit(cache=True, inline="always")
def typed(fr, held):
    """The kernels' structures from the frames' plain tuple and the constants ``held`` (:func:`hold_estimate`).

    numba types a named tuple given from Python slowly (~3 µs a call): the entry points take plain tuples.
    """
    pb, err, ops, ref, sc = held[0]
    return prob.FramesRef(*fr), pb, err, ops, ref, sc


def plain(*structures):
    """The structures (NamedTuples: frames, problem, shift error model, operators) as plain tuples (:func:`typed`)."""
    return tuple(tuple(s) for s in structures)


@njit(cache=True)
def hold(constants):
    """The tuple ``constants`` in a typed list of one, which a call from Python takes as one object.

    Not each of its arrays (~0.1 µs each; an estimate's constants are ~40, a live step's ~150, the same at every call).
    """
    held = List()
    held.append(constants)
    return held


@njit(cache=True)
def hold_estimate(constants):
    """:func:`hold` of an estimate's constants as the kernels take them: StructRefs, made once (~140 counts a call).

    ``constants``: the plain tuples (:func:`plain`) of its Problem, shift error model, beam operators and a contact's.
    With them the buffers of :func:`scratch`, one set a ``slot`` of :func:`estimate_block` (:func:`estimate_frames`
    adds its threads'): calls with the same constants must not overlap (bendsense's calls hold ``_jit``'s lock).
    """
    pb, err, ops, ref = constants
    pb, ops = prob.ProblemRef(*pb), bk.OperatorsRef(*ops)
    scratch_of = List()
    scratch_of.append(scratch(pb, ops.sigma.size))
    return hold((pb, ShiftErrorModel(*err), ops, bk._SplitOperators(*ref), scratch_of))


@njit(cache=True)
def contact_at(pb, ops, ref, sc):
    """The problem and the beam's operators of a force at σ_c = ``sc`` (< 1), as :func:`estimate_block`'s ``at``.

    ``pb``, ``ops``, ``ref``: the plain tuples of :func:`plain`. A live stream at a known
    contact makes them once, not per frame (~10 µs a frame).
    """
    pb, ops, ref = prob.ProblemRef(*pb), bk.OperatorsRef(*ops), bk._SplitOperators(*ref)
    return prob.contact_problem(pb, sc, ref), bk.contact_grid(sc, ops, ref)


@njit(cache=True)
def estimate_block(lo, hi, use_guess, chained, fr, held, start, out, slot, at=None):
    """The whole estimate of frames ``lo:hi`` in order (:func:`estimate_frames`).

    ``fr``: the frames' plain tuple, ``held``: the constants (:func:`typed`). A
    frame's force point gets its problem and operators once for a run of frames at the
    same point; ``at`` (optional): those of the point σ_c = ``at[2]``, made ahead (:func:`contact_at`, plain
    tuples). ``slot``: which buffers of ``held`` it works in (:func:`hold_estimate`; 0 but in a batch's threads).
    """
    fr, pb0, err, ops0, ref, scratch_of = typed(fr, held)
    buf, ws, trial = scratch_of[slot]
    force, cov, status, iters, residual, chi2, pval, guess_n, state, tip, direction, std, parts, success, pay, \
        shifts = Outputs(*out)
    k = pb0.lower.size
    on_grid = buf.on_grid  # the reference's angles on a contact's nodes
    u, u0, prev_u, prev_u0, blocked, g = buf.guess[0], buf.guess[1], buf.guess[2], buf.guess[3], buf.guess[4], \
        buf.guess[5]
    prev_ok = False
    ops_c, pb_c, sc_c = ops0, pb0, 1.0  # the latest contact point's
    if at is not None:
        ops_c, pb_c, sc_c = bk.OperatorsRef(*at[1]), prob.ProblemRef(*at[0]), at[2]
    for i in range(lo, hi):
        # the beam's operators and the problem of the frame's force point: the tip's, or a contact's
        # (bendsense.mechanics._beam_kernels.contact_grid, problem.contact_problem: one code path for every point)
        ops, pb = ops0, pb0
        if fr.contact[i] < 1.0:
            if fr.contact[i] != sc_c:
                sc_c = fr.contact[i]
                ops_c = bk.OperatorsRef(*bk.contact_grid(sc_c, ops0, ref))
                pb_c = prob.ProblemRef(*prob.contact_problem(pb0, sc_c, ref))
            ops, pb = ops_c, pb_c
        p0, phi_end, kappa_s, state0, tg, D, dD, frame_cov, cov_s, noise_var, kappa = setup(i, fr, pb, err, buf)
        if fr.contact[i] < 1.0:
            prob.contact_state(state0, ops0.sigma, ops.sigma, on_grid)
            state0 = on_grid
        ei, k0 = fr.ei[i], fr.k0[i]
        moment_guess(p0, pb.s, pb.w, pb.L, ei, k0, pb.wload, D, pb.ffix, pb.lower, phi_end, kappa_s, pb.seg,
                     fr.contact[i] * pb.L, g)
        force_of(D, pb.ffix, g, guess_n[i])
        for c in range(k):
            if use_guess:  # the guess corrected by a previous estimate's offset from its own guess
                proj = g[c] + D[0, c] * start[i, 0] + D[1, c] * start[i, 1]
            else:  # a given force
                proj = D[0, c] * (start[i, 0] - pb.ffix[0]) + D[1, c] * (start[i, 1] - pb.ffix[1])
            u0[c] = max(proj, pb.lower[c])
            u[c] = u0[c]
        # the previous frame's offset corrects this frame's start where the two frames are
        # near (their starts closer than that offset): along a time series, not across a shuffle
        if prev_ok and near(u0, prev_u0, prev_u):
            for c in range(k):
                u[c] = max(u0[c] + prev_u[c] - prev_u0[c], pb.lower[c])
        blocked[:] = 0.0
        st, it, _, ws, trial = gauss_newton(pb.L, ei, k0, pb.wload, tg, D, pb.ffix, pb.lower, u, state0, pb.xtol,
                                            pb.max_iter, ops, pb, ws, trial, blocked, buf)
        prev_ok = chained and st == _OK
        bk.copy_into(u, prev_u)
        bk.copy_into(u0, prev_u0)
        direction[i, :] = 0.0
        status[i], residual[i], chi2[i], pval[i] = finish(st, pb, p0, tg, D, dD, u, ws, blocked, frame_cov, cov_s,
                                                          noise_var, fr.model_cov[i], kappa, force[i], cov[i],
                                                          parts[i], direction[i], pay[i])
        if pb.contact and pb.objective == ANGLES and math.isfinite(pay[i, 0, 0]):
            contact_jacobian(pb.L, ei, k0, force[i], pb.wload, ops, pb, ws, pay[i, :, 5])
        if pb.pcc:
            bk.copy_into(buf.shifts, shifts[i])
        else:
            shifts[i] = np.nan
        iters[i] = it
        success[i] = status[i] == _OK or status[i] == _NOT_IDENTIFIABLE  # never with a NaN force (finish)
        std[i, 0] = math.sqrt(cov[i, 0, 0])
        std[i, 1] = math.sqrt(cov[i, 1, 1])
        bk.copy_into(ws.state, state[i])
        tip[i, 0] = ws.tip[0]
        tip[i, 1] = ws.tip[1]


@njit(cache=True, parallel=True)
def estimate_frames(block, use_guess, fr, held, start, out, threads):
    """The whole estimate of every frame (B,), in parallel over blocks of ``block`` consecutive frames.

    ``use_guess``: start at the moment-balance guess plus the force offset ``start`` (B, 2)
    (projected on the constraint), else at the force ``start``. Within a block (``block`` >
    1, a time series) a frame's start is corrected by the previous frame's offset from its
    own guess when that converged. ``fr``: the plain tuple (:func:`plain`) of
    :class:`~bendsense.estimation.problem.Frames`; ``held``: the constants (:func:`hold_estimate`;
    each frame's force acts at its ``Frames.contact``). ``out``: force (B, 2), cov (B, 2, 2), status,
    iterations, residual, χ²/dof, its p-value, guess (B, 2), state (B, n), tip (B, 2), the unidentifiable
    direction of a boundary stop (B, 2), σ (B, 2), the covariance's parts (B, 3, 2, 2), success (B,)
    (converged or not identifiable), and the window test's payload (:func:`payload`): residual, Jacobian
    by u and model factor (B, R, 5), and the measured shifts (B, N). ``threads``: the caller's numba thread
    count (asked in Python: compiled in, it puts an address in the code, and numba caches no such code).
    """
    B = prob.Frames(*fr).ei.size
    nblocks = (B + block - 1) // block
    pb, _, ops, _, scratch_of = held[0]
    slots = min(nblocks, threads)
    while len(scratch_of) < slots:
        scratch_of.append(scratch(pb, ops.sigma.size))
    for s in prange(slots):  # slot s runs the blocks s, s + slots, ...: its buffers in one thread at a time
        slot = np.int64(s)  # prange's index is unsigned: one compiled estimate_block for every caller
        for blk in range(slot, nblocks, slots):
            estimate_block(blk * block, min(B, (blk + 1) * block), use_guess, block > 1, fr, held, start, out, slot)


@njit(cache=True)
def evaluate_frames(fr, held, u, run_status, out):
    """Shape, covariance and status of every frame at given parameters ``u`` (B, k) (the paper's optimum)."""
    fr, pb, err, ops, ref, scratch_of = typed(fr, held)
    buf, ws, _ = scratch_of[0]
    force, cov, status, iters, residual, chi2, pval, guess_n, state, tip, direction, std, parts, success, pay, \
        shifts = Outputs(*out)
    F = buf.gram[0, 0]
    blocked = buf.guess[4]
    blocked[:] = 0.0
    for i in range(fr.ei.size):
        p0, _, _, state0, tg, D, dD, frame_cov, cov_s, noise_var, kappa = setup(i, fr, pb, err, buf)
        force_of(D, pb.ffix, u[i], F)
        ok = beam_eval(pb.L, fr.ei[i], fr.k0[i], F, pb.wload, state0, bool(YES), bool(YES), ops, fitted(pb), ws)
        st = run_status[i] if ok else _BEAM_FAILED
        status[i], residual[i], chi2[i], pval[i] = finish(st, pb, p0, tg, D, dD, u[i], ws, blocked, frame_cov, cov_s,
                                                          noise_var, fr.model_cov[i], kappa, force[i], cov[i],
                                                          parts[i], direction[i], pay[i])
        if pb.pcc:
            bk.copy_into(buf.shifts, shifts[i])
        else:
            shifts[i] = np.nan
        success[i] = status[i] == _OK or status[i] == _NOT_IDENTIFIABLE
        std[i, 0] = math.sqrt(cov[i, 0, 0])
        std[i, 1] = math.sqrt(cov[i, 1, 1])
        bk.copy_into(ws.state, state[i])
        tip[i, 0] = ws.tip[0]
        tip[i, 1] = ws.tip[1]


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
