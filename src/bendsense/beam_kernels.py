"""Compiled kernels of the spectral beam solver (one frame each; batches loop over them).

The equations are those of :mod:`bendsense.beam` (paper eq. 13–17 in the base frame of
DESIGN section 2): with σ = s/L, ``g = G L²/EI`` and the unknowns φ at the Chebyshev–
Lobatto nodes 1..n-1 (φ_0 = φ_base), the collocation equations are

    φ''(σ_j) − λ (sin φ_j g_y(σ_j) − cos φ_j g_x(σ_j)) = 0   at the interior nodes,
    φ'(1) = K0 L                                              at the tip,

solved by Newton's method (dense (n-1)² Jacobian, LU with partial pivoting), with load
continuation in λ from the unloaded arc where the load is beyond the convexity bound.
The Jacobian at the solution also gives the Jacobi field (stability) and ∂φ/∂g
(sensitivities). Every function here is ``numba.njit(cache=True)`` and works on one
frame; :func:`solve_frames` is the ``prange`` loop over a batch.

Measured (one core, n = 20, under load from other jobs): a convex frame from the free
arc ~4 µs, a warm-started re-solve ~2 µs, a continuation over ~6 steps ~20 µs.
"""

import math

import numpy as np
from numba import njit, prange

from bendsense import _jit
from bendsense.status import Status

# flags to compiled callees go through bool(): one compiled version for both values, not one per literal
YES, NO = True, False

STABLE_BOUND = math.pi**2 / 4  # first eigenvalue of -d²/dσ² with η(0)=0, η'(1)=0
WEIGHT_BOUND = 7.83  # Greenhill: first eigenvalue b of -η'' = b (1 - σ) η, 7.8373 (rounded down)
QUAD = 1e-4  # Newton's quadratic-regime early stop (see _newton)
QUAD_SENS = 1e-8  # ... with sensitivities, which come from the last Jacobian
LOCATE = 1e-3  # load-factor step within which a loss of stability is accepted as real
WARM_MOVE = 0.1  # [rad] a non-convex warm start moving farther is re-solved from the arc
FIRST_STEP = 1.0  # first continuation step, in units of the convexity bound
STEP_ITER = 10  # Newton iterations of an intermediate continuation step

_RUNNING = int(Status.RUNNING)
_OK = int(Status.OK)
_UNSTABLE = int(Status.UNSTABLE)
_LOST = int(Status.LOST_BRANCH)
_WARM_UNSTABLE = int(Status.WARM_UNSTABLE)


@njit(cache=True)
def load_ratio(fx, fy, wx, wy):
    """Load measure ρ ≥ 0; ρ < 1 proves the energy strictly convex (unique, stable equilibrium).

    ``f`` = F L²/EI, ``w`` = w L³/EI. The second variation ∫ η'² + (g·t) η² dσ is
    positive if max |g| < π²/4 (|g| is linear in σ: its maximum sits at an end), or by
    Dunkerley |f|/(π²/4) + |w|/7.837 < 1 (the lowest eigenvalue is concave in the loads).
    """
    fn = math.hypot(fx, fy)
    gmax = max(fn, math.hypot(fx + wx, fy + wy))
    return min(gmax / STABLE_BOUND, fn / STABLE_BOUND + math.hypot(wx, wy) / WEIGHT_BOUND)


@njit(cache=True)
def lu_factor(A, piv):
    """LU factorisation of A (m, m) in place with partial pivoting (row swaps in ``piv``).

    The multipliers are kept below the diagonal. Returns False for a singular (or
    non-finite) matrix. For the 19×19 collocation Jacobian: ~1 µs.
    """
    m = A.shape[0]
    for k in range(m):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, m):
            v = abs(A[i, k])
            if v > big:
                big = v
                p = i
        if not big > 0.0:  # zero or NaN
            return False
        piv[k] = p
        if p != k:  # the multipliers left of k stay where they were made: lu_apply replays the steps in order
            for j in range(k, m):
                t = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = t
        inv = 1.0 / A[k, k]
        for i in range(k + 1, m):
            f = A[i, k] * inv
            A[i, k] = f
            if f != 0.0:
                for j in range(k + 1, m):
                    A[i, j] -= f * A[k, j]
    return True


@njit(cache=True)
def lu_apply(A, piv, B, lo, hi):
    """Solve A X = B for the columns ``lo:hi`` of B in place, with A factored by :func:`lu_factor`.

    Column by column the same operations as an elimination of A and B together: a
    column solved later is bit for bit the column solved with the others.
    """
    m = A.shape[0]
    for k in range(m):
        p = piv[k]
        if p != k:
            for j in range(lo, hi):
                t = B[k, j]
                B[k, j] = B[p, j]
                B[p, j] = t
        for i in range(k + 1, m):
            f = A[i, k]
            if f != 0.0:
                for j in range(lo, hi):
                    B[i, j] -= f * B[k, j]
    for k in range(m - 1, -1, -1):
        inv = 1.0 / A[k, k]
        for j in range(lo, hi):
            acc = B[k, j]
            for i in range(k + 1, m):
                acc -= A[k, i] * B[i, j]
            B[k, j] = acc * inv


@njit(cache=True)
def lu_solve(A, B):
    """Solve A X = B in place (X in B) by Gaussian elimination with partial pivoting; False if A is singular."""
    piv = np.empty(A.shape[0], dtype=np.int64)
    if not lu_factor(A, piv):
        return False
    lu_apply(A, piv, B, 0, B.shape[1])
    return True


@njit(cache=True)
def newton(p, lam, k0n, gi, J0, D2i, Dtip, tol, limit, sens, tangent, x):
    """Newton on the collocation equations at load factor λ; ``p`` (n,) updated in place.

    ``gi`` (n-2, 2): g at the interior nodes. Stops when the angle step is below
    ``tol`` or, in the quadratic regime, when the error left (~ step³/previous step²)
    is; at most ``limit`` iterations; steps longer than 1 rad are shortened to 1 rad.
    On convergence ``x`` (n-1, ncol-1) holds J⁻¹ [e_tip, -∂R/∂g_x, -∂R/∂g_y (sens),
    -∂R/∂λ (tangent)] at the last iterate: column 0 is the discrete Jacobi field ψ with
    ψ'(1) = 1. Returns (converged, iterations).
    """
    n = p.size
    m = n - 1
    ncol = 2 + 2 * sens + tangent
    quad = QUAD_SENS if sens else QUAD
    J = np.empty((m, m))
    rhs = np.empty((m, ncol))
    piv = np.empty(m, dtype=np.int64)
    prev = np.inf
    it = 0
    while it < limit:
        for i in range(m - 1):
            s = math.sin(p[i + 1])
            c = math.cos(p[i + 1])
            gx = gi[i, 0] * lam
            gy = gi[i, 1] * lam
            acc = 0.0
            for j in range(n):
                acc += D2i[i, j] * p[j]
            rhs[i, 0] = s * gy - c * gx - acc
            rhs[i, 1] = 0.0
            if sens:
                rhs[i, 2] = -c * lam
                rhs[i, 3] = s * lam
            if tangent:
                rhs[i, ncol - 1] = s * gi[i, 1] - c * gi[i, 0]
            for j in range(m):
                J[i, j] = J0[i, j]
            J[i, i] -= c * gy + s * gx
        acc = 0.0
        for j in range(n):
            acc += Dtip[j] * p[j]
        rhs[m - 1, 0] = k0n - acc
        rhs[m - 1, 1] = 1.0
        for c_ in range(2, ncol):
            rhs[m - 1, c_] = 0.0
        for j in range(m):
            J[m - 1, j] = J0[m - 1, j]
        # the step now; the other columns (Jacobi field, sensitivities) only at the last iterate
        good = lu_factor(J, piv)
        if good:
            lu_apply(J, piv, rhs, 0, 1)
        size = 0.0
        for i in range(m):
            size = max(size, abs(rhs[i, 0]))
        it += 1
        if not good or not math.isfinite(size):
            return False, it
        done = size <= tol or (size <= quad and size <= 0.1 * prev and size**3 <= tol * prev * prev)
        damp = 1.0 / max(size, 1.0)
        for i in range(m):
            p[i + 1] += rhs[i, 0] * damp
        prev = size
        if done:
            lu_apply(J, piv, rhs, 1, ncol)
            for i in range(m):
                for c_ in range(ncol - 1):
                    x[i, c_] = rhs[i, c_ + 1]
            return True, it
    return False, it


@njit(cache=True)
def stable(psi, D0):
    """Jacobi condition on the discrete Jacobi field ψ (ψ(0) = 0, ψ'(1) = 1).

    Stable iff ψ stays positive on (0, 1] and ψ'(0) > 0 (Prüfer angle below π/2).
    """
    d = 0.0
    for i in range(psi.size):
        if not psi[i] > 0.0:
            return False
        d += psi[i] * D0[i]
    return d > 0.0


@njit(cache=True)
def arc_tangent(phi, gi, J0inv, out):
    """dφ/dλ at λ = 0, where the Jacobian is the constant J0: a product, not a solve."""
    m = out.size
    for r in range(m):
        out[r] = 0.0
    for i in range(m - 1):
        v = math.sin(phi[i + 1]) * gi[i, 1] - math.cos(phi[i + 1]) * gi[i, 0]
        for r in range(m):
            out[r] += J0inv[r, i] * v


@njit(cache=True)
def continuation(phi, k0n, gi, ratio, ops, tol, max_iter, sens, extra):
    """Follow the branch from the unloaded arc ``phi`` (λ = 0) to the full load (λ = 1).

    Euler–Newton continuation with the tangent dφ/dλ as predictor. A step is accepted
    when Newton converges close to the prediction (no jump to a distant branch); the
    Jacobi condition at each accepted step detects a loss of stability, and an unstable
    frame is carried on to λ = 1 and reported. Returns (status, load factor where it
    failed, Newton iterations); ``phi`` and ``extra`` hold the last accepted step.
    """
    n = phi.size
    m = n - 1
    ncol = 2 + 2 * sens + 1
    lam = 0.0
    dlam = min(1.0, FIRST_STEP / max(ratio, 1e-300))
    status = _RUNNING
    where = 0.0
    iters = 0
    tan = np.empty(m)
    arc_tangent(phi, gi, ops.J0inv, tan)
    pred = np.empty(n)
    x = np.empty((m, ncol - 1))
    for _ in range(1000):
        lt = min(1.0, lam + dlam)
        pred[0] = phi[0]
        pstep = 0.0
        for i in range(m):
            d = (lt - lam) * tan[i]
            pred[i + 1] = phi[i + 1] + d
            pstep = max(pstep, abs(d))
        start = pred.copy()
        last = lt >= 1.0
        conv, it = newton(pred, lt, k0n, gi, ops.J0, ops.D2i, ops.Dtip, tol if last else 1e-6,
                          max_iter if last else min(STEP_ITER, max_iter), sens, bool(YES), x)
        iters += it
        move = 0.0
        for i in range(n):
            move = max(move, abs(pred[i] - start[i]))
        ok = conv and move <= max(0.5 * pstep, 0.05)
        if ok and status == _RUNNING and not stable(x[:, 0], ops.D0):
            if lt - lam > LOCATE:
                ok = False  # an unstable landing after a long step may be a jump: refine
            else:
                status = _UNSTABLE
                where = lam
        if ok:
            phi[:] = pred
            lam = lt
            for i in range(m):
                tan[i] = x[i, ncol - 2]
                for c in range(extra.shape[1]):  # with sens the tangent dφ/dλ too
                    extra[i, c] = x[i, c]
            dlam = min(1.0, 1.5 * dlam)
            if lam >= 1.0:
                return (_UNSTABLE if status == _UNSTABLE else _OK), where, iters
        else:
            dlam *= 0.25
            if dlam < 1e-4:
                if status == _RUNNING:
                    return _LOST, lam, iters
                return status, where, iters
    if status == _RUNNING:
        return _LOST, lam, iters
    return status, where, iters


@njit(cache=True)
def solve_frame(L, ei, k0, base, fx, fy, wx, wy, state, has_state, ops, tol, max_iter, sens, allow_continuation,
                phi, extra):
    """One frame of the fast solver: φ at the nodes into ``phi`` (n,), J⁻¹ columns into ``extra``.

    ``state`` (n,) with ``has_state``: Newton starts there (warm start); accepted if the
    load is provably convex, or if the equilibrium is stable and near the start;
    ``allow_continuation=False`` reports a converged unstable warm landing beyond the
    convexity bound as ``WARM_UNSTABLE`` instead of continuing from the arc. Without a
    state, convex loads start from the arc plus its first-order change. Everything else
    follows the branch from the unloaded arc (:func:`continuation`). ``extra`` (n-1,
    1 + 3 sens): the Jacobi field ψ = ∂φ/∂(K0 L) and, with ``sens``, ∂φ/∂g and the load
    tangent dφ/dλ (= −EI ∂φ/∂EI at λ = 1). Returns (status, load factor of a failure,
    Newton iterations).
    """
    n = phi.size
    m = n - 1
    scale = L * L / ei
    k0n = k0 * L
    f0, f1 = fx * scale, fy * scale
    w0, w1 = wx * scale * L, wy * scale * L
    gi = np.empty((n - 2, 2))
    for i in range(n - 2):
        gi[i, 0] = f0 + w0 * ops.tail[i]
        gi[i, 1] = f1 + w1 * ops.tail[i]
    ratio = load_ratio(f0, f1, w0, w1)
    convex = ratio < 1.0
    status = _RUNNING
    iters = 0
    x = np.full((m, 1 + 3 * sens), np.nan)
    if has_state:
        phi[:] = state
        phi[0] = base
        conv, iters = newton(phi, 1.0, k0n, gi, ops.J0, ops.D2i, ops.Dtip, tol, max_iter, sens, sens, x)
        if conv:
            near = True
            for i in range(1, n):
                if abs(phi[i] - state[i]) > WARM_MOVE:
                    near = False
            st = stable(x[:, 0], ops.D0)
            if convex or (st and near):
                status = _OK
            elif not allow_continuation and not st:
                status = _WARM_UNSTABLE
    elif convex:
        for i in range(n):
            phi[i] = base + k0n * ops.sigma[i]
        tan = np.empty(m)
        arc_tangent(phi, gi, ops.J0inv, tan)
        for i in range(m):
            phi[i + 1] += tan[i]
        conv, iters = newton(phi, 1.0, k0n, gi, ops.J0, ops.D2i, ops.Dtip, tol, max_iter, sens, sens, x)
        if conv:
            status = _OK
    where = 1.0
    if status == _RUNNING:
        for i in range(n):
            phi[i] = base + k0n * ops.sigma[i]
        status, where, it = continuation(phi, k0n, gi, ratio, ops, tol, max_iter, sens, x)
        iters += it
    extra[:, :] = x
    return status, where, iters


@njit(cache=True)
def sample(phi, dphi, L, PQ, q, sens, pos, dpos, tip):
    """Positions r = L ∫ (sin φ, cos φ) dσ at the rows of ``PQ`` (and the tip, row ``q``).

    With ``sens``, ∂r/∂F from ``dphi`` (n, 2) = ∂φ/∂F at the nodes:
    ∂r/∂F = L ∫ (cos φ, −sin φ) ∂φ/∂F dσ.
    """
    n = phi.size
    M = PQ.shape[0]
    sn = np.empty(n)
    cs = np.empty(n)
    for j in range(n):
        sn[j] = math.sin(phi[j])
        cs[j] = math.cos(phi[j])
    for r in range(M + 1):
        x = 0.0
        y = 0.0
        a00 = a01 = a10 = a11 = 0.0
        for j in range(n):
            wgt = PQ[r, j] if r < M else q[j]
            x += wgt * sn[j]
            y += wgt * cs[j]
            if sens:
                a00 += wgt * cs[j] * dphi[j, 0]
                a01 += wgt * cs[j] * dphi[j, 1]
                a10 -= wgt * sn[j] * dphi[j, 0]
                a11 -= wgt * sn[j] * dphi[j, 1]
        if r < M:
            pos[r, 0] = L * x
            pos[r, 1] = L * y
            if sens:
                dpos[r, 0, 0] = L * a00
                dpos[r, 0, 1] = L * a01
                dpos[r, 1, 0] = L * a10
                dpos[r, 1, 1] = L * a11
        else:
            tip[0] = L * x
            tip[1] = L * y
            if sens:
                tip[2] = L * a00
                tip[3] = L * a01
                tip[4] = L * a10
                tip[5] = L * a11


@njit(cache=True)
def node_sensitivity(extra, L, ei, dphi):
    """∂φ/∂F (n, 2) at the nodes from the J⁻¹ columns: ∂φ/∂g times ∂g/∂F = L²/EI."""
    scale = L * L / ei
    dphi[0, 0] = 0.0
    dphi[0, 1] = 0.0
    for i in range(extra.shape[0]):
        dphi[i + 1, 0] = extra[i, 1] * scale
        dphi[i + 1, 1] = extra[i, 2] * scale


@njit(cache=True)
def solve_sample(b, L, ei, k0, base, F, w, state, has_state, ops, tol, max_iter, sens, allow_continuation, P, PQ, q,
                 out):
    """:func:`solve_frame` and :func:`sample` of frame ``b`` of a batch (:func:`solve_frames`)."""
    phi, status, where, iters, angle, pos, dpos, dang, tip = out
    n = ops.sigma.size
    M = P.shape[0]
    extra = np.empty((n - 1, 1 + 3 * sens))
    st, wh, it = solve_frame(L, ei[b], k0[b], base[b], F[b, 0], F[b, 1], w[b, 0], w[b, 1], state[b], has_state, ops,
                             tol, max_iter, sens, allow_continuation, phi[b], extra)
    status[b] = st
    where[b] = wh
    iters[b] = it
    dphi = np.zeros((n, 2))
    if sens:
        node_sensitivity(extra, L, ei[b], dphi)
        for r in range(M):
            a0 = 0.0
            a1 = 0.0
            for j in range(n):
                a0 += P[r, j] * dphi[j, 0]
                a1 += P[r, j] * dphi[j, 1]
            dang[b, r, 0] = a0
            dang[b, r, 1] = a1
    for r in range(M):
        a = 0.0
        for j in range(n):
            a += P[r, j] * phi[b, j]
        angle[b, r] = a
    sample(phi[b], dphi, L, PQ, q, sens, pos[b], dpos[b], tip[b])


@njit(cache=True, parallel=True)
def solve_frames(L, ei, k0, base, F, w, state, has_state, ops, tol, max_iter, sens, allow_continuation, P, PQ, q, out):
    """:func:`solve_frame` and :func:`sample` over a batch (B,) of frames, in parallel.

    ``P`` (M, n) interpolates angles, ``PQ`` (M, n) and ``q`` (n,) positions (times L).
    ``out``: ``phi`` (B, n), ``status``, ``where``, ``iters`` (B,), ``angle`` (B, M),
    ``pos`` (B, M, 2), and with ``sens`` ``dpos`` (B, M, 2, 2), ``dang`` (B, M, 2), ``tip``
    (B, 6) (the tip and ∂tip/∂F row-major).
    """
    for b in prange(ei.size):
        solve_sample(b, L, ei, k0, base, F, w, state, has_state, ops, tol, max_iter, sens, allow_continuation, P, PQ, q,
                     out)


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
