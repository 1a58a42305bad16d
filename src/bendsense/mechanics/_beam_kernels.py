"""Compiled kernels of the spectral beam solver (one frame each; batches loop over them).

The equations are those of :mod:`bendsense.mechanics.beam` (paper eq. 13–17 in the base frame of
DESIGN section 2): with σ = s/L, ``g = G L²/EI`` and the unknowns φ at the Chebyshev–
Lobatto nodes 1..n-1 (φ_0 = φ_base), the collocation equations are

    φ''(σ_j) − λ (sin φ_j g_y(σ_j) − cos φ_j g_x(σ_j)) = 0   at the interior nodes,
    φ'(1) = K0 L                                              at the tip,

A point force at σ_c = s_c/L < 1 (``g = f [σ < σ_c] + w (1 − σ)``) splits [0, 1] into two
Chebyshev domains [0, σ_c] and [σ_c, 1] (:func:`contact_grid`): the interface node is
shared (φ continuous), its equation is φ'(σ_c−) = φ'(σ_c+) (φ'' jumps there) and the
collocation rows of each domain are scaled by its length squared. A tip load is σ_c = 1,
one domain: the operators (:class:`_KernelOperators`) hold the rows of
either (``C``, ``h2``, ``on``, ...), and every kernel below runs the same code on both.

solved by Newton's method (dense (n-1)² Jacobian, LU with partial pivoting), with load
continuation in λ from the unloaded arc where the load is beyond the convexity bound.
The Jacobian at the solution also gives the Jacobi field (stability) and ∂φ/∂g
(sensitivities). Every function here is ``numba.njit(cache=True)`` and works on one
frame; :func:`solve_frames` is the ``prange`` loop over a batch.

Measured (one core, n = 20, under load from other jobs): a convex frame from the free
arc ~4 µs, a warm-started re-solve ~2 µs, a continuation over ~6 steps ~20 µs.
"""

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numba.experimental import structref

from bendsense import _jit
from bendsense.status import Status

# flags to compiled callees go through bool(): one compiled version for both values, not one per literal
YES, NO = True, False

STABLE_BOUND = math.pi**2 / 4  # first eigenvalue of -d²/dσ² with η(0)=0, η'(1)=0
WEIGHT_BOUND = 7.83  # Greenhill: first eigenvalue b of -η'' = b (1 - σ) η, 7.8373 (rounded down)
QUAD = 1e-4  # Newton's quadratic-regime early stop (see _newton)
QUAD_SENS = 1e-8  # ... with sensitivities, which come from the last Jacobian
NEWTON_TOL = 1e-11  # rad: the Newton tolerance of the beam solver and the force estimate
LOCATE = 1e-3  # load-factor step within which a loss of stability is accepted as real
WARM_MOVE = 0.1  # [rad] a non-convex warm start moving farther is re-solved from the arc
FIRST_STEP = 1.0  # first continuation step, in units of the convexity bound
STEP_ITER = 10  # Newton iterations of an intermediate continuation step
MIN_DOMAIN = 7  # Chebyshev nodes of the shorter domain of a contact (contact_grid)

_RUNNING = int(Status.RUNNING)
_OK = int(Status.OK)
_UNSTABLE = int(Status.UNSTABLE)
_LOST = int(Status.LOST_BRANCH)
_WARM_UNSTABLE = int(Status.WARM_UNSTABLE)


class _KernelOperators(NamedTuple):
    """The collocation operators of one contact point σ_c as the compiled kernels take them (n nodes, m = n − 1).

    Row r of the system belongs to node r + 1 (:func:`newton`). A tip load (σ_c = 1): one
    Chebyshev domain, built once per n by :func:`bendsense.mechanics.beam._operators`; a contact
    (σ_c < 1): two, built per frame by :func:`contact_grid`.
    """

    sigma: np.ndarray  # (n,) nodes on [0, 1], sigma[0] = 0 (base), sigma[-1] = 1 (tip)
    C: np.ndarray  # (m, n) the rows' linear part: h² d²/dσ² (collocation), the φ' jump (interface), d/dσ (tip)
    h2: np.ndarray  # (m,) factor of the load term of each row: its domain's length squared; 0: no load term
    on: np.ndarray  # (m,) 1 where the point force acts (σ < σ_c), else 0
    tail: np.ndarray  # (m,) 1 − σ at the rows' nodes
    J0: np.ndarray  # (m, m) Jacobian at zero load; unknowns are φ_1..φ_{n-1}
    J0inv: np.ndarray  # (m, m)
    D0: np.ndarray  # (m,) first row of d/dσ without its first column (times the first domain's length)
    kscale: float  # the tip row's K0 L factor (the last domain's length)
    jrow: int  # the row of the contact node (the interface, or the tip for a tip load)
    jscale: float  # the contact row's scale: the ∂φ/∂σ_c source is −jscale × the jump of φ'


@structref.register
class _OperatorsRefType(_jit.StructType):
    pass


class OperatorsRef(structref.StructRefProxy):
    """:class:`_KernelOperators` as the kernels hold them: one object, not a tuple of 8 arrays.

    (:class:`bendsense.estimation.problem.ProblemRef` says why.) Made from their fields,
    ``OperatorsRef(*ops)``; :func:`contact_grid` gives a ``_KernelOperators``. The
    estimator's kernels and the simulator's (:func:`solve_sample`) pass them alike, so
    that a process running both compiles :func:`solve_frame` once.
    """


structref.define_proxy(OperatorsRef, _OperatorsRefType, list(_KernelOperators._fields))


class _SplitOperators(NamedTuple):
    """Chebyshev operators on [0, 1] of every domain size k = MIN_DOMAIN..n − MIN_DOMAIN + 1 (:func:`contact_grid`).

    Entry k holds the k-node operators in its leading k × k block (the rest is unused).
    """

    sig: np.ndarray  # (n + 1, n) nodes on [0, 1]
    D: np.ndarray  # (n + 1, n, n) d/dτ
    D2: np.ndarray  # (n + 1, n, n) d²/dτ²
    Q: np.ndarray  # (n + 1, n, n) ∫_0^τ_j


@njit(cache=True)
def split_nodes(sc, n):
    """Nodes (na, nb) of the domains [0, σ_c] and [σ_c, 1], na + nb − 1 = n: in proportion to their lengths.

    Each domain gets at least ``MIN_DOMAIN`` nodes; the state keeps its size n.
    """
    na = int(round(sc * (n - 1))) + 1
    na = min(max(na, MIN_DOMAIN), n + 1 - MIN_DOMAIN)
    return na, n + 1 - na


@njit(cache=True)
def load_ratio(fx, fy, wx, wy, beyond):
    """Load measure ρ ≥ 0; ρ < 1 proves the energy strictly convex (unique, stable equilibrium).

    ``f`` = F L²/EI at σ_c, ``w`` = w L³/EI, ``beyond`` = 1 − σ_c (0 for a tip load). The
    second variation ∫ η'² + (g·t) η² dσ is positive if max |g| < π²/4 (|g| is linear in σ
    on each side of σ_c: its maximum sits at 0, σ_c or 1), or by Dunkerley |f|/(π²/4) +
    |w|/7.837 < 1 (the lowest eigenvalue is concave in the loads; a force at σ_c < 1
    buckles the beam later than at the tip).
    """
    fn = math.hypot(fx, fy)
    gc = math.hypot(fx + wx * beyond, fy + wy * beyond)
    gmax = max(gc, math.hypot(fx + wx, fy + wy), math.hypot(wx, wy) * beyond)
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
def newton(p, lam, k0n, gi, f, ops, tol, limit, sens, tangent, x, work):
    """Newton on the collocation equations at load factor λ; ``p`` (n,) updated in place.

    ``gi`` (n-1, 2): g at the nodes 1..n-1 (the rows' nodes), ``f`` (2,) the point force
    f = F L²/EI, ``ops`` the frame's operators (:func:`contact_grid`). Row r of the system
    belongs to node r + 1: ``C[r]·φ − h2[r] λ (sin φ g_y − cos φ g_x) = 0`` (collocation
    rows; the interface and tip rows have h2 = 0), the tip row equals ``kscale`` K0 L.
    Stops when the angle step is below ``tol`` or, in the quadratic regime, when the
    error left (~ step³/previous step²) is; at most ``limit`` iterations; steps longer
    than 1 rad are shortened to 1 rad. On convergence ``x`` (n-1, ncol-1) holds
    J⁻¹ [e_tip kscale, -∂R/∂g_x, -∂R/∂g_y (sens ≥ 1), -∂R/∂σ_c (sens 2), -∂R/∂λ (tangent)]
    at the last iterate: column 0 is the discrete Jacobi field ψ = ∂φ/∂(K0 L); ∂φ/∂σ_c (at
    fixed σ) has one source, the jump λ (sin φ_c f_y − cos φ_c f_x) of φ' at σ_c, in the
    interface row (the tip row for a tip load: the one-sided derivative). Returns
    (converged, iterations).
    """
    n = p.size
    m = n - 1
    ncol = 2 + 2 * (sens > 0) + (sens > 1) + tangent
    quad = QUAD_SENS if sens > 0 else QUAD
    C, h2, on, J0 = ops.C, ops.h2, ops.on, ops.J0
    J, rhs, piv = work[0], work[1], work[2]  # rhs's first ncol columns
    prev = np.inf
    it = 0
    while it < limit:
        for i in range(m):
            acc = 0.0
            for j in range(n):
                acc += C[i, j] * p[j]
            for j in range(m):
                J[i, j] = J0[i, j]
            for c_ in range(1, ncol):
                rhs[i, c_] = 0.0
            h = h2[i]
            if h == 0.0:  # the interface and tip rows: linear, no load term
                rhs[i, 0] = -acc
                continue
            s = math.sin(p[i + 1])
            c = math.cos(p[i + 1])
            gx = gi[i, 0] * lam
            gy = gi[i, 1] * lam
            rhs[i, 0] = h * (s * gy - c * gx) - acc
            if sens > 0:
                hf = h * on[i]
                rhs[i, 2] = -c * lam * hf
                rhs[i, 3] = s * lam * hf
            if tangent:
                rhs[i, ncol - 1] = h * (s * gi[i, 1] - c * gi[i, 0])
            J[i, i] -= h * (c * gy + s * gx)
        rhs[m - 1, 0] += ops.kscale * k0n
        rhs[m - 1, 1] = ops.kscale
        if sens > 1:
            r = ops.jrow
            rhs[r, 4] = -ops.jscale * lam * (math.sin(p[r + 1]) * f[1] - math.cos(p[r + 1]) * f[0])
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
def arc_tangent(phi, gi, ops, out):
    """dφ/dλ at λ = 0, where the Jacobian is the constant J0: a product, not a solve."""
    m = out.size
    J0inv = ops.J0inv
    for r in range(m):
        out[r] = 0.0
    for i in range(m):
        if ops.h2[i] == 0.0:
            continue
        v = ops.h2[i] * (math.sin(phi[i + 1]) * gi[i, 1] - math.cos(phi[i + 1]) * gi[i, 0])
        for r in range(m):
            out[r] += J0inv[r, i] * v


@njit(cache=True, inline="always")
def continuation(phi, k0n, gi, f, ratio, ops, tol, max_iter, sens, extra, work):
    """Follow the branch from the unloaded arc ``phi`` (λ = 0) to the full load (λ = 1).

    Euler–Newton continuation with the tangent dφ/dλ as predictor. A step is accepted
    when Newton converges close to the prediction (no jump to a distant branch); the
    Jacobi condition at each accepted step detects a loss of stability, and an unstable
    frame is carried on to λ = 1 and reported. Returns (status, load factor where it
    failed, Newton iterations); ``phi`` and ``extra`` hold the last accepted step.
    """
    n = phi.size
    m = n - 1
    ncol = 2 + 2 * (sens > 0) + (sens > 1) + 1
    lam = 0.0
    dlam = min(1.0, FIRST_STEP / max(ratio, 1e-300))
    status = _RUNNING
    where = 0.0
    iters = 0
    tan, pred, start, x = work[5], work[6], work[7], work[8]  # x's first ncol - 1 columns
    arc_tangent(phi, gi, ops, tan)
    for _ in range(1000):
        lt = min(1.0, lam + dlam)
        pred[0] = phi[0]
        pstep = 0.0
        for i in range(m):
            d = (lt - lam) * tan[i]
            pred[i + 1] = phi[i + 1] + d
            pstep = max(pstep, abs(d))
        copy_into(pred, start)
        last = lt >= 1.0
        conv, it = newton(pred, lt, k0n, gi, f, ops, tol if last else 1e-6,
                          max_iter if last else min(STEP_ITER, max_iter), sens, bool(YES), x, work)
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
            copy_into(pred, phi)
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
def copy_into(src, dst):
    """``dst[...] = src`` for two arrays of one shape (the kernels' own buffers), element by element.

    An array's slice assignment compiles numba's shape check and its error message for
    every signature (~1 s each on the first run); these copies are alike by construction.
    """
    for i in np.ndindex(src.shape):
        dst[i] = src[i]


@njit(cache=True)
def solver_work(n):
    """The buffers of :func:`solve_frame` for n nodes: kept by a caller that solves often (the estimator's workspace).

    With m = n - 1: Newton's matrix (m, m), right-hand sides (m, 6) and pivots (m,), the load
    g (m, 2) and f (2,), continuation's tangent (m,), prediction and start (n,) and solutions (m, 5).
    """
    m = n - 1
    return (np.empty((m, m)), np.empty((m, 6)), np.empty(m, dtype=np.int64), np.empty((m, 2)), np.empty(2),
            np.empty(m), np.empty(n), np.empty(n), np.empty((m, 5)))


@njit(cache=True)
def extra_columns(sens):
    """Columns of :func:`solve_frame`'s ``extra`` at a sensitivity level ``sens`` (0, 1 or 2)."""
    return 1 + 3 * (sens > 0) + (sens > 1)


@njit(cache=True)
def solve_frame(L, ei, k0, base, fx, fy, wx, wy, state, has_state, ops, tol, max_iter, sens, allow_continuation,
                phi, extra, work):
    """One frame of the fast solver: φ at the nodes into ``phi`` (n,), J⁻¹ columns into ``extra``.

    ``state`` (n,) with ``has_state``: Newton starts there (warm start); accepted if the
    load is provably convex, or if the equilibrium is stable and near the start;
    ``allow_continuation=False`` reports a converged unstable warm landing beyond the
    convexity bound as ``WARM_UNSTABLE`` instead of continuing from the arc. Without a
    state, convex loads start from the arc plus its first-order change. Everything else
    follows the branch from the unloaded arc (:func:`continuation`). ``ops``: the frame's
    operators, of its contact point σ_c (:func:`contact_grid`; the force ``(fx, fy)``
    acts there). ``sens`` 0, 1 or 2: ``extra`` (n-1, :func:`extra_columns`) holds the
    Jacobi field ψ = ∂φ/∂(K0 L) and, with ``sens`` ≥ 1, ∂φ/∂g (g = F L²/EI), with ``sens``
    2 ∂φ/∂σ_c at fixed σ, and last the load tangent dφ/dλ (= −EI ∂φ/∂EI at λ = 1). ``work``:
    the solver's buffers (:func:`solver_work`). Returns (status, load factor of a failure,
    Newton iterations).
    """
    n = phi.size
    m = n - 1
    scale = L * L / ei
    k0n = k0 * L
    gi, f = work[3], work[4]
    f0, f1 = fx * scale, fy * scale
    f[0], f[1] = f0, f1
    w0, w1 = wx * scale * L, wy * scale * L
    for i in range(m):
        gi[i, 0] = f0 * ops.on[i] + w0 * ops.tail[i]
        gi[i, 1] = f1 * ops.on[i] + w1 * ops.tail[i]
    ratio = load_ratio(f0, f1, w0, w1, ops.tail[ops.jrow])
    convex = ratio < 1.0
    status = _RUNNING
    iters = 0
    extra[:, :] = np.nan  # where a solve leaves a column unset
    if has_state:
        copy_into(state, phi)
        phi[0] = base
        conv, iters = newton(phi, 1.0, k0n, gi, f, ops, tol, max_iter, sens, sens > 0, extra, work)
        if conv:
            near = True
            for i in range(1, n):
                if abs(phi[i] - state[i]) > WARM_MOVE:
                    near = False
            st = stable(extra[:, 0], ops.D0)
            if convex or (st and near):
                status = _OK
            elif not allow_continuation and not st:
                status = _WARM_UNSTABLE
    elif convex:
        for i in range(n):
            phi[i] = base + k0n * ops.sigma[i]
        tan = work[5]
        arc_tangent(phi, gi, ops, tan)
        for i in range(m):
            phi[i + 1] += tan[i]
        conv, iters = newton(phi, 1.0, k0n, gi, f, ops, tol, max_iter, sens, sens > 0, extra, work)
        if conv:
            status = _OK
    where = 1.0
    if status == _RUNNING:
        for i in range(n):
            phi[i] = base + k0n * ops.sigma[i]
        status, where, it = continuation(phi, k0n, gi, f, ratio, ops, tol, max_iter, sens, extra, work)
        iters += it
    return status, where, iters


@njit(cache=True)
def contact_grid(sc, ops, ref):
    """The operators of a point force at σ_c = s_c/L: ``ops`` (one domain) for σ_c ≥ 1, else two domains.

    The domains [0, σ_c] (``na`` nodes) and [σ_c, 1] (``nb``, :func:`split_nodes`) of
    ``ref`` (:class:`_SplitOperators`) share the node at σ_c; n = na + nb − 1 nodes in all
    (the size of the tip load's grid: the state keeps its shape). Their rows: collocation
    ``D2 φ − h² λ (...)`` with h = σ_c or 1 − σ_c; the interface ``h_b D_a φ_a − h_a D_b
    φ_b = h_a h_b (φ'(σ_c−) − φ'(σ_c+)) = 0``; the tip ``D_b φ_b = h_b K0 L``. ~2 µs
    (n = 16), once per frame.
    """
    if sc >= 1.0:  # a _KernelOperators of any form of ops (an OperatorsRef's fields)
        return _KernelOperators(ops.sigma, ops.C, ops.h2, ops.on, ops.tail, ops.J0, ops.J0inv, ops.D0, ops.kscale,
                                ops.jrow, ops.jscale)
    n = ops.sigma.size
    m = n - 1
    na, nb = split_nodes(sc, n)
    sig_a, D_a, D2_a = ref.sig[na, :na], ref.D[na, :na, :na], ref.D2[na, :na, :na]
    sig_b, D_b, D2_b = ref.sig[nb, :nb], ref.D[nb, :nb, :nb], ref.D2[nb, :nb, :nb]
    ha = sc
    hb = 1.0 - sc
    sigma = np.empty(n)
    for j in range(na):
        sigma[j] = ha * sig_a[j]
    for j in range(1, nb):
        sigma[na - 1 + j] = sc + hb * sig_b[j]
    sigma[na - 1] = sc
    sigma[n - 1] = 1.0
    C = np.zeros((m, n))
    h2 = np.zeros(m)
    on = np.zeros(m)
    for r in range(na - 2):  # the first domain's interior: node r + 1
        for j in range(na):
            C[r, j] = D2_a[r + 1, j]
        h2[r] = ha * ha
        on[r] = 1.0
    r = na - 2  # the interface: φ' continuous
    for j in range(na):
        C[r, j] = hb * D_a[na - 1, j]
    for j in range(nb):
        C[r, na - 1 + j] -= ha * D_b[0, j]
    for k in range(1, nb - 1):  # the second domain's interior: node na − 1 + k
        for j in range(nb):
            C[na - 2 + k, na - 1 + j] = D2_b[k, j]
        h2[na - 2 + k] = hb * hb
    for j in range(nb):
        C[m - 1, na - 1 + j] = D_b[nb - 1, j]
    tail = np.empty(m)
    for r in range(m):
        tail[r] = 1.0 - sigma[r + 1]
    J0 = np.ascontiguousarray(C[:, 1:])
    J0inv = np.eye(m)
    lu_solve(J0.copy(), J0inv)
    D0 = np.zeros(m)
    for j in range(1, na):
        D0[j - 1] = D_a[0, j]
    return _KernelOperators(sigma, C, h2, on, tail, J0, J0inv, D0, hb, na - 2, ha * hb)


@njit(cache=True)
def barycentric(nodes, t, out):
    """Weights (k,) of the polynomial through the Chebyshev–Lobatto ``nodes`` (k,) at ``t``, into ``out``."""
    k = nodes.size
    for j in range(k):
        if t == nodes[j]:
            out[:] = 0.0
            out[j] = 1.0
            return
    total = 0.0
    for j in range(k):
        wj = (1.0 if j % 2 == 0 else -1.0) * (0.5 if j == 0 or j == k - 1 else 1.0)
        out[j] = wj / (t - nodes[j])
        total += out[j]
    for j in range(k):
        out[j] /= total


@njit(cache=True)
def contact_sampling(sc, ref, sig, P, PQ, q):
    """Interpolation ``P`` (M, n), integration ``PQ`` (M, n), ``q`` (n,) at the points ``sig`` (M,) of a contact grid.

    The contact counterpart of the tip grid's constant matrices (:func:`sample`): a
    point of [0, σ_c] interpolates the first domain, r(σ) = σ_c ∫_0^τ; a point beyond
    the second, r(σ) = r(σ_c) + (1 − σ_c) ∫_0^τ (``contact_grid``, σ_c < 1).
    """
    na, nb = split_nodes(sc, q.size)
    sig_a, Q_a = ref.sig[na, :na], ref.Q[na, :na, :na]
    sig_b, Q_b = ref.sig[nb, :nb], ref.Q[nb, :nb, :nb]
    ha = sc
    hb = 1.0 - sc
    la = np.empty(na)
    lb = np.empty(nb)
    P[:, :] = 0.0
    PQ[:, :] = 0.0
    for r in range(sig.size):
        if sig[r] <= sc:
            barycentric(sig_a, min(sig[r] / sc, 1.0), la)
            for j in range(na):
                P[r, j] = la[j]
                acc = 0.0
                for i in range(na):
                    acc += la[i] * Q_a[i, j]
                PQ[r, j] = ha * acc
        else:
            barycentric(sig_b, min((sig[r] - sc) / hb, 1.0), lb)
            for j in range(nb):
                P[r, na - 1 + j] = lb[j]
            for j in range(na):
                PQ[r, j] = ha * Q_a[na - 1, j]
            for j in range(nb):
                acc = 0.0
                for i in range(nb):
                    acc += lb[i] * Q_b[i, j]
                PQ[r, na - 1 + j] += hb * acc
    q[:] = 0.0
    for j in range(na):
        q[j] = ha * Q_a[na - 1, j]
    for j in range(nb):
        q[na - 1 + j] += hb * Q_b[nb - 1, j]


@njit(cache=True)
def sample(phi, dphi, L, PQ, q, sens, pos, dpos, tip):
    """Positions r = L ∫ (sin φ, cos φ) dσ at the rows of ``PQ`` (and the tip, row ``q``).

    With ``sens``, ∂r/∂p_c for the first k = ``dpos.shape[2]`` (2 or 3) columns of ``dphi``
    (n, ≥k) = ∂φ/∂p_c at the nodes: ∂r/∂p = L ∫ (cos φ, −sin φ) ∂φ/∂p dσ, into ``dpos``
    (M, 2, k) and ``tip[2:]`` (2 × k, row-major). Scalar accumulators: the estimate's
    residual samples 41 rows a frame.
    """
    n = phi.size
    M = PQ.shape[0]
    k = dpos.shape[2]
    third = k > 2
    sn = np.empty(n)
    cs = np.empty(n)
    for j in range(n):
        sn[j] = math.sin(phi[j])
        cs[j] = math.cos(phi[j])
    for r in range(M + 1):
        x = 0.0
        y = 0.0
        a00 = a01 = a02 = a10 = a11 = a12 = 0.0
        for j in range(n):
            wgt = PQ[r, j] if r < M else q[j]
            x += wgt * sn[j]
            y += wgt * cs[j]
            if sens:
                a00 += wgt * cs[j] * dphi[j, 0]
                a01 += wgt * cs[j] * dphi[j, 1]
                a10 -= wgt * sn[j] * dphi[j, 0]
                a11 -= wgt * sn[j] * dphi[j, 1]
                if third:
                    a02 += wgt * cs[j] * dphi[j, 2]
                    a12 -= wgt * sn[j] * dphi[j, 2]
        if r < M:
            pos[r, 0] = L * x
            pos[r, 1] = L * y
            if sens:
                dpos[r, 0, 0] = L * a00
                dpos[r, 0, 1] = L * a01
                dpos[r, 1, 0] = L * a10
                dpos[r, 1, 1] = L * a11
                if third:
                    dpos[r, 0, 2] = L * a02
                    dpos[r, 1, 2] = L * a12
        else:
            tip[0] = L * x
            tip[1] = L * y
            if sens:
                tip[2] = L * a00
                tip[3] = L * a01
                tip[2 + k] = L * a10
                tip[3 + k] = L * a11
                if third:
                    tip[4] = L * a02
                    tip[4 + k] = L * a12


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
def solve_sample(b, L, ei, k0, base, F, w, sc, state, has_state, ops, ref, tol, max_iter, sens, allow_continuation,
                 sig, P, PQ, q, out):
    """:func:`solve_frame` and :func:`sample` of frame ``b`` of a batch (:func:`solve_frames`)."""
    phi, status, where, iters, angle, pos, dpos, dang, tip = out
    n = ops.sigma.size
    M = P.shape[0]
    grid = OperatorsRef(*contact_grid(sc[b], OperatorsRef(*ops), ref))  # as the estimator holds them: one compile
    if sc[b] < 1.0:  # the contact grid's sampling (the tip grid's is a constant)
        P, PQ, q = np.empty((M, n)), np.empty((M, n)), np.empty(n)
        contact_sampling(sc[b], ref, sig, P, PQ, q)
    level = 2 if sens else 0  # with the force's sensitivities, the contact point's
    extra = np.empty((n - 1, extra_columns(level)))
    st, wh, it = solve_frame(L, ei[b], k0[b], base[b], F[b, 0], F[b, 1], w[b, 0], w[b, 1], state[b], has_state, grid,
                             tol, max_iter, level, allow_continuation, phi[b], extra, solver_work(n))
    status[b] = st
    where[b] = wh
    iters[b] = it
    dphi = np.zeros((n, 3))
    if sens:
        node_sensitivity(extra, L, ei[b], dphi)
        for i in range(n - 1):
            dphi[i + 1, 2] = extra[i, 3] / L  # ∂φ/∂s_c = ∂φ/∂σ_c / L
        for r in range(M):
            for c in range(3):
                a = 0.0
                for j in range(n):
                    a += P[r, j] * dphi[j, c]
                dang[b, r, c] = a
    for r in range(M):
        a = 0.0
        for j in range(n):
            a += P[r, j] * phi[b, j]
        angle[b, r] = a
    sample(phi[b], dphi, L, PQ, q, sens, pos[b], dpos[b], tip[b])


@njit(cache=True, parallel=True)
def solve_frames(L, ei, k0, base, F, w, sc, state, has_state, ops, ref, tol, max_iter, sens, allow_continuation, sig,
                 P, PQ, q, out):
    """:func:`solve_frame` and :func:`sample` over a batch (B,) of frames, in parallel.

    ``sc`` (B,): the force's point σ_c = s_c/L (1: the tip), ``ops`` the tip grid's
    operators and ``ref`` a contact's (:func:`contact_grid`); ``sig`` (M,) the output
    points, where ``P`` (M, n) interpolates angles, ``PQ`` (M, n) and ``q`` (n,) positions
    (times L) on the tip grid. ``out``: ``phi`` (B, n), ``status``, ``where``, ``iters``
    (B,), ``angle`` (B, M), ``pos`` (B, M, 2), and with ``sens`` ``dpos`` (B, M, 2, 3),
    ``dang`` (B, M, 3) (by Fx, Fy and s_c), ``tip`` (B, 8) (the tip and ∂tip/∂(Fx, Fy, s_c)
    row-major).
    """
    for b in prange(ei.size):  # prange's index is unsigned, the loop's typed before it is not: one compile as int64
        solve_sample(np.int64(b), L, ei, k0, base, F, w, sc, state, has_state, ops, ref, tol, max_iter, sens,
                     allow_continuation, sig, P, PQ, q, out)


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
