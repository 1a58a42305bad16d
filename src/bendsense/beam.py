"""Curved cantilever beam under a tip force and a distributed load (paper eq. 13–17).

The actuator is a planar, inextensible, unshearable (Euler–Bernoulli) cantilever with
natural curvature ``K0`` set by the pressure (free-bending model). In the base frame of
DESIGN section 2 (``+y`` the base tangent, ``φ`` measured from ``+y`` toward ``+x``,
tangent ``t = (sin φ, cos φ)``, ``κ = dφ/ds``), with ``G(s) = F + w (L − s)`` the total
external force beyond ``s``::

    EI φ''(s) = sin φ · G_y(s) − cos φ · G_x(s),   φ(0) = φ_base,   φ'(L) = K0,
    r(s) = ∫₀ˢ (sin φ, cos φ) dσ.

This is the paper's eq. 13–14 and 16 with ``s = L − s_t``; the paper's ``F_y`` and
gravity ``q`` point the other way (its "downward tip load" ``F_y`` is ``−F_y`` here for
the upright rig), and its position integral (eq. 17) runs from the tip. The equilibrium
is a stationary point of the energy ``Π[φ] = ∫ EI/2 (φ' − K0)² − G·t(φ) ds``; it is
stable when the second variation ``∫ EI η'² + (G·t) η² ds`` is positive for every
``η`` with ``η(0) = 0``. A compressive load (``G·t < 0``) softens the beam and can buckle it.

Two solvers:

``"fast"`` (default)
    Chebyshev collocation of ``φ`` on ``n_nodes`` Chebyshev–Lobatto points, Newton's
    method with the dense Jacobian solved for the whole batch at once, positions by
    spectral integration and values at ``s_m`` by barycentric interpolation. Loads for
    which the energy is provably convex (``max_s |G(s)| L²/EI < π²/4``, so that the
    equilibrium is unique and stable) are solved by Newton from the free arc directly;
    larger loads follow the branch connected to the unloaded arc by load continuation,
    and the sign of the Jacobian's determinant at every step flags a loss of stability.
``"shooting"`` (alias ``"paper"``)
    The paper's method, kept as the reference: ``scipy.integrate.solve_ivp`` from the
    base with the unknown ``φ'(0)``, Newton on ``φ'(L) = K0`` with the variational
    equation, load continuation; stability by the Jacobi condition on the variational
    solution. A Python loop over frames.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dgesv as _dgesv

from bendsense.errors import ArgumentError, ConvergenceError, ConvergenceWarning

__all__ = [
    "BeamSolution",
    "BeamConvergenceWarning",
    "solve_beam",
    "solve",
    "free_arc",
    "DEFAULT_NODES",
    "DEFAULT_POINTS",
]

#: Chebyshev nodes of the fast method; enough for ~1e-10 L tip accuracy at
#: F L²/EI up to 10 (see tests and ``benchmarks/bench_beam.py``).
DEFAULT_NODES = 20
#: Number of output points of the default ``s_m`` grid (both ends included).
DEFAULT_POINTS = 101

_STABLE_BOUND = math.pi**2 / 4  # first eigenvalue of -d²/dσ² with η(0)=0, η'(1)=0
_WEIGHT_BOUND = 7.83  # Greenhill: first eigenvalue b of -η'' = b (1 - σ) η, 7.8373 (rounded down)


def _load_ratio(f, wn):
    """Return a load measure ρ ≥ 0 such that ρ < 1 proves the energy strictly convex.

    The second variation ∫ η'² + (g·t) η² dσ is bounded below by using
    g·t ≥ -|g(σ)|. Two sufficient conditions for positivity: max |g| < π²/4 (|g| is
    linear in σ, so its maximum sits at an end), and, since the lowest eigenvalue is
    concave in the loads, Dunkerley's |f|/(π²/4) + |w|/7.837 < 1 (tip load and
    uniform load toward the base at their separate buckling values). Below 1 the
    equilibrium is unique and stable.
    """
    fn = np.hypot(f[..., 0], f[..., 1])
    gmax = np.maximum(fn, np.hypot(f[..., 0] + wn[..., 0], f[..., 1] + wn[..., 1]))
    return np.minimum(gmax / _STABLE_BOUND, fn / _STABLE_BOUND + np.hypot(wn[..., 0], wn[..., 1]) / _WEIGHT_BOUND)


_OK = "converged"
NEWTON_TOL = 1e-11  # rad: default Newton tolerance of :func:`solve`
NEWTON_MAX_ITER = 30
# Newton stops early once in its quadratic regime (step below _QUAD and shrinking fast):
# the error left is ~ step³/previous step². Sensitivities come from the Jacobian at the
# last iterate, so they ask for a smaller last step.
_QUAD = 1e-4
_LOCATE = 1e-3  # load-factor step within which a loss of stability is accepted as real
# a warm start on a non-convex problem that moves farther than this [rad] is re-solved
# from the unloaded shape, in case it slid onto another branch
_WARM_MOVE = 0.1
_FIRST_STEP = 1.0  # first continuation step, in units of the convexity bound
_STEP_ITER = 10  # Newton iterations of an intermediate continuation step
_QUAD_SENS = 1e-8


class BeamConvergenceWarning(ConvergenceWarning):
    """Some frames of a beam solve did not converge or are unstable (``success=False``)."""


@dataclass(frozen=True)
class BeamSolution:
    """Shape of the loaded cantilever (paper eq. 16–17), batched over leading axes ``...``.

    Attributes
    ----------
    s_m : ndarray, shape (M,)
        Arc length of the output points, from the base [m].
    angle_rad : ndarray, shape (..., M)
        Tangent angle φ(s) from ``+y`` toward ``+x`` [rad].
    positions_m : ndarray, shape (..., M, 2)
        Points r(s) in the base frame [m].
    tip_position_m : ndarray, shape (..., 2)
        r(L) [m].
    tip_angle_rad : ndarray, shape (...)
        φ(L) [rad].
    success : ndarray of bool, shape (...)
        Converged to a stable equilibrium on the branch connected to the unloaded shape.
    message : str or ndarray of str, shape (...)
        ``"converged"`` or the reason for ``success=False``, per frame.
    iterations : ndarray of int, shape (...)
        Newton iterations (fast) or IVP solves (shooting) spent on each frame.
    method : str
        ``"fast"`` or ``"shooting"``.
    state : ndarray, shape (..., n_nodes) or None
        φ at the Chebyshev nodes (fast method); pass the solution back as
        ``initial=`` to warm-start a nearby solve.
    dpositions_dforce : ndarray, shape (..., M, 2, 2) or None
        ∂r_a(s_j)/∂F_b [m/N], with ``sensitivities=True``.
    dangle_dforce : ndarray, shape (..., M, 2) or None
        ∂φ(s_j)/∂F_b [rad/N], with ``sensitivities=True``.
    dtip_position_dforce : ndarray, shape (..., 2, 2) or None
        ∂r_a(L)/∂F_b [m/N], with ``sensitivities=True``.
    """

    s_m: np.ndarray
    angle_rad: np.ndarray
    positions_m: np.ndarray
    tip_position_m: np.ndarray
    tip_angle_rad: np.ndarray
    success: np.ndarray
    message: object
    iterations: np.ndarray
    method: str
    state: np.ndarray | None = None
    dpositions_dforce: np.ndarray | None = None
    dangle_dforce: np.ndarray | None = None
    dtip_position_dforce: np.ndarray | None = None

    @property
    def length_m(self) -> float:
        """Beam length L [m]."""
        return float(self.s_m[-1]) if self.s_m.size else 0.0

    def plot(self, ax=None, **kwargs):
        """Draw the shape(s) in the base frame; returns the matplotlib axes.

        Frames with ``success=False`` are drawn dashed. Keyword arguments go to
        ``ax.plot``.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        pos = self.positions_m.reshape(-1, self.s_m.size, 2)
        ok = np.asarray(self.success).reshape(-1)
        for p, good in zip(pos, ok, strict=True):
            ax.plot(p[:, 0], p[:, 1], "-" if good else "--", **kwargs)
        ax.plot([0.0], [0.0], "ks", markersize=4)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_aspect("equal", adjustable="datalim")
        return ax


# --------------------------------------------------------------------------- operators


@dataclass(frozen=True)
class _Operators:
    n: int
    sigma: np.ndarray  # nodes on [0, 1], sigma[0] = 0 (base), sigma[-1] = 1 (tip)
    D: np.ndarray  # d/dσ at the nodes
    D2i: np.ndarray  # rows 1..n-2 of d²/dσ², all columns
    Dtip: np.ndarray  # last row of d/dσ
    Q: np.ndarray  # (Q f)_j = ∫_0^{σ_j} f dσ
    D0: np.ndarray  # first row of d/dσ without its first column: ψ'(0) when ψ(0) = 0
    J0: np.ndarray  # Jacobian at zero load, (n-1, n-1); unknowns are φ_1..φ_{n-1}
    J0inv: np.ndarray
    J0T: np.ndarray  # J0ᵀ, C-contiguous: its transpose is J0 in Fortran order, as LAPACK takes it
    rhs_one: np.ndarray  # (4, n-1): the constant entries of one frame's Newton right-hand sides, transposed
    Dall: np.ndarray  # D2i and then Dtip: the rows of the collocation equations
    diag: np.ndarray  # flat indices of the diagonal entries that carry the load term
    tail: np.ndarray  # 1 − σ at the interior nodes


@functools.lru_cache(maxsize=16)
def _operators(n: int) -> _Operators:
    N = n - 1
    x = np.cos(np.pi * np.arange(n) / N)
    c = np.ones(n)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** np.arange(n)
    dx = x[:, None] - x[None, :]
    Dx = np.outer(c, 1.0 / c) / (dx + np.eye(n))
    Dx -= np.diag(Dx.sum(axis=1))  # negative-sum trick: exact derivative of constants
    D = -2.0 * Dx  # σ = (1 − x)/2
    D2 = D @ D
    sigma = (1.0 - x) / 2.0
    sigma[0], sigma[-1] = 0.0, 1.0
    # integration matrix through Chebyshev coefficients: ∫_0^σ f dσ' = ½ ∫_x^1 f dx'
    V = np.polynomial.chebyshev.chebvander(x, N)
    coeffs = np.linalg.solve(V, np.eye(n))
    anti = np.polynomial.chebyshev.chebint(coeffs, lbnd=1.0, axis=0)
    Q = -0.5 * np.polynomial.chebyshev.chebvander(x, N + 1) @ anti
    Q[0] = 0.0
    J0 = np.vstack([D2[1:-1, 1:], D[-1:, 1:]])
    m = n - 1
    diag = np.arange(m - 1) * (m + 1)
    rhs_one = np.zeros((4, m))
    rhs_one[1, -1] = 1.0  # e_tip: the Jacobi field's column
    return _Operators(
        n, sigma, D, D2[1:-1].copy(), D[-1].copy(), Q, D[0, 1:].copy(), J0, np.linalg.inv(J0), J0.T.copy(), rhs_one,
        np.vstack([D2[1:-1], D[-1:]]), diag,
        1.0 - sigma[1:-1],
    )


@functools.lru_cache(maxsize=64)
def _sampling(n: int, sigma_m_bytes: bytes):
    """Interpolation matrix P (M, n) and interpolated integration matrix P Q (M, n)."""
    ops = _operators(n)
    sm = np.frombuffer(sigma_m_bytes, dtype=float)
    w = (-1.0) ** np.arange(n)
    w[0] *= 0.5
    w[-1] *= 0.5
    diff = sm[:, None] - ops.sigma[None, :]
    exact = diff == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        P = w / diff
    hit = exact.any(axis=1)
    P[hit] = exact[hit].astype(float)
    P[~hit] /= P[~hit].sum(axis=1, keepdims=True)
    PQ = P @ ops.Q
    return P, PQ


# --------------------------------------------------------------------------- inputs


def _as_float(name: str, value, *, positive: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{name}: expected numbers, got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise ArgumentError(f"{name}: must be finite, got {value!r}")
    if positive and not np.all(arr > 0):
        raise ArgumentError(f"{name}: must be > 0, got {value!r}")
    return arr


def _as_vector(name: str, value) -> np.ndarray:
    arr = _as_float(name, value)
    if arr.ndim == 0 or arr.shape[-1] != 2:
        raise ArgumentError(f"{name}: expected shape (..., 2), got shape {arr.shape}")
    return arr


@functools.lru_cache(maxsize=16)
def _default_grid(length_m: float) -> np.ndarray:
    s = np.linspace(0.0, length_m, DEFAULT_POINTS)
    s.flags.writeable = False
    return s


def _grid(length_m: float, s_m) -> np.ndarray:
    if s_m is None:
        return _default_grid(length_m)
    s = _as_float("s_m", s_m)
    if s.ndim != 1 or s.size == 0:
        raise ArgumentError(f"s_m: expected a non-empty 1-D array of arc lengths [m], got shape {s.shape}")
    tol = 1e-12 * length_m
    if s.min() < -tol or s.max() > length_m + tol:
        raise ArgumentError(f"s_m: must lie in [0, length_m] = [0, {length_m!r}], got [{s.min()!r}, {s.max()!r}]")
    return np.clip(s, 0.0, length_m)


def free_arc(length_m, tip_curvature_per_m, base_angle_rad=0.0, s_m=None):
    """Unloaded shape: an arc of constant curvature ``K0`` (paper eq. 5–7).

    Parameters
    ----------
    length_m : float
        Beam length L [m].
    tip_curvature_per_m : array_like, shape (...)
        Natural curvature K0 [1/m].
    base_angle_rad : array_like, shape (...)
        Tangent angle at the base [rad].
    s_m : array_like, shape (M,), optional
        Arc length of the output points [m]; default ``DEFAULT_POINTS`` points on [0, L].

    Returns
    -------
    angle_rad : ndarray, shape (..., M)
    positions_m : ndarray, shape (..., M, 2)
    """
    s = _grid(float(length_m), s_m)
    k = np.asarray(tip_curvature_per_m, dtype=float)[..., None]
    b = np.asarray(base_angle_rad, dtype=float)[..., None]
    k, b = np.broadcast_arrays(k, b)
    phi = b + k * s
    # sin(ks)/k and (1 − cos ks)/k without cancellation for small k
    half = 0.5 * k * s
    sinc = s * np.sinc(half / np.pi)
    chord_x = sinc * np.sin(b + half)
    chord_y = sinc * np.cos(b + half)
    return phi, np.stack([chord_x, chord_y], axis=-1)


# --------------------------------------------------------------------------- fast core


def _linsolve(J, rhs):
    """Solve the stacked systems; singular ones give NaN instead of raising."""
    if J.shape[0] == 1:
        # LAPACK directly: a third of np.linalg.solve's overhead for one small system
        _, _, x, info = _dgesv(J[0], rhs[0], overwrite_a=True, overwrite_b=False)
        return x[None] if info == 0 else np.full(rhs.shape, np.nan)
    try:
        return np.linalg.solve(J, rhs)
    except np.linalg.LinAlgError:
        out = np.full(rhs.shape, np.nan)
        for_ok = np.abs(np.linalg.det(J)) > 0.0
        if for_ok.any():
            out[for_ok] = np.linalg.solve(J[for_ok], rhs[for_ok])
        return out


def _newton(phi, lam, k0, gi, ops, tol, max_iter, *, sens=False, tangent=False, limit=None):
    """Batched Newton on the collocation equations (the unknowns are φ at nodes 1..n-1).

    Parameters
    ----------
    phi : ndarray, shape (b, n)
        Initial iterate; ``phi[:, 0]`` is the base angle and stays fixed.
    lam : ndarray, shape (b,)
        Load factor λ (continuation); the loads are λ G.
    k0 : ndarray, shape (b,)
        K0 L.
    gi : ndarray, shape (b, n-2, 2)
        G L²/EI at the interior nodes.
    tol : float or ndarray, shape (b,)
        Tolerance on the largest angle update [rad].
    sens, tangent : bool
        Also solve for -∂R/∂g (2 columns) and -∂R/∂λ (1 column) with the last Jacobian.
    limit : ndarray of int, shape (b,), optional
        Iterations per frame, at most ``max_iter``; a frame not converged within its
        limit stops (``converged`` False).

    Returns
    -------
    phi, converged, iterations, extra
        ``extra`` (b, n-1, k): J⁻¹ applied to [e_tip, -∂R/∂g..., -∂R/∂λ] at the last
        iterate. Column 0 is the discrete Jacobi field ψ normalised to ψ'(1) = 1: the
        null vector of the interior rows, whose sign pattern decides stability.
    """
    b, n = phi.shape
    m = n - 1
    ncol = 2 + 2 * sens + tangent
    quad = _QUAD_SENS if sens else _QUAD
    phi = phi.copy()
    conv = np.zeros(b, dtype=bool)
    iters = np.zeros(b, dtype=int)
    extra = np.full((b, m, ncol - 1), np.nan)
    tol = np.broadcast_to(np.asarray(tol, dtype=float), (b,))
    idx = np.arange(b)
    p, g, kk, lm, tl = phi, gi, k0, lam, tol
    prev = np.full(b, np.inf)
    cap = None if limit is None else np.minimum(limit, max_iter)
    for _ in range(max_iter):
        a = idx.size
        s, c = np.sin(p), np.cos(p)
        si, ci = s[:, 1:-1], c[:, 1:-1]
        gx = g[..., 0] * lm[:, None]
        gy = g[..., 1] * lm[:, None]
        rhs = np.zeros((a, m, ncol))
        rhs[:, :-1, 0] = si * gy - ci * gx - p @ ops.D2i.T
        rhs[:, -1, 0] = kk - p @ ops.Dtip
        rhs[:, -1, 1] = 1.0
        if sens:
            rhs[:, :-1, 2] = -ci * lm[:, None]
            rhs[:, :-1, 3] = si * lm[:, None]
        if tangent:
            rhs[:, :-1, -1] = si * g[..., 1] - ci * g[..., 0]
        J = np.empty((a, m, m))
        J[:] = ops.J0
        J.reshape(a, m * m)[:, ops.diag] -= ci * gy + si * gx
        sol = _linsolve(J, rhs)
        step = sol[..., 0]
        size = np.abs(step).max(axis=1)
        good = np.isfinite(size)
        # quadratic convergence: the error left after this step is ~ size³ / prev²
        done = good & ((size <= tl) | ((size <= quad) & (size <= 0.1 * prev) & (size**3 <= tl * prev**2)))
        # damping: a Newton step of more than ~1 rad from a poor guess overshoots
        step *= (1.0 / np.maximum(size, 1.0))[:, None]
        p = p.copy() if p is phi else p
        p[:, 1:] += step
        iters[idx] += 1
        prev = size
        if done.all():
            phi[idx] = p
            conv[idx] = True
            extra[idx] = sol[..., 1:]
            break
        over = None if cap is None else iters[idx] >= cap[idx]
        if done.any() or not good.all() or (over is not None and over.any()):
            phi[idx[done]] = p[done]
            conv[idx[done]] = True
            extra[idx[done]] = sol[done, :, 1:]
            keep = ~done & good
            if over is not None:
                keep &= ~over
            phi[idx[~done & ~keep]] = p[~done & ~keep]
            idx, p, g, kk, lm, tl, prev = idx[keep], p[keep], g[keep], kk[keep], lm[keep], tl[keep], prev[keep]
            if idx.size == 0:
                break
    else:
        phi[idx] = p
    return phi, conv, iters, extra


def _arc_tangent(phi, gi, ops):
    """dφ/dλ at λ = 0, where the Jacobian is the constant J0: a product, not a solve."""
    rhs = np.sin(phi[:, 1:-1]) * gi[..., 1] - np.cos(phi[:, 1:-1]) * gi[..., 0]
    return rhs @ ops.J0inv[:, :-1].T


def _stable(psi, ops):
    """Jacobi condition on the discrete Jacobi field ψ (ψ(0) = 0, ψ'(1) = 1).

    The equilibrium is stable iff the solution of the Jacobi equation with ψ(0) = 0,
    ψ'(0) > 0 stays positive on (0, L] and ends with ψ'(L) > 0 (Prüfer angle below
    π/2); with ψ'(1) = 1 that is ψ'(0) > 0 and ψ > 0 at every node.
    """
    return (psi @ ops.D0 > 0.0) & (psi > 0.0).all(axis=1)


def _continuation(phi, k0, gi, ratio, ops, tol, max_iter, sens):
    """Follow the branch from the unloaded arc (λ = 0) to the full load (λ = 1).

    Euler–Newton continuation in the load factor λ with the tangent dφ/dλ as
    predictor. A step is accepted when Newton converges close to the prediction (no
    jump to a distant branch); the Jacobi condition at each accepted step detects a
    loss of stability. An unstable frame is carried on to λ = 1 and reported.
    """
    b = phi.shape[0]
    lam = np.zeros(b)
    dlam = np.minimum(1.0, _FIRST_STEP / np.maximum(ratio, 1e-300))
    status = np.zeros(b, dtype=int)  # 0 running, 1 done, 2 unstable, 3 lost the branch
    running = np.ones(b, dtype=bool)
    where = np.zeros(b)
    iters = np.zeros(b, dtype=int)
    extra = np.full((b, ops.n - 1, 1 + 2 * sens), np.nan)
    tan = _arc_tangent(phi, gi, ops)
    phi = phi.copy()
    for _ in range(1000):
        act = np.flatnonzero(running)
        if act.size == 0:
            break
        lt = np.minimum(1.0, lam[act] + dlam[act])
        pred = phi[act].copy()
        pred[:, 1:] += (lt - lam[act])[:, None] * tan[act]
        # only the last step needs the full tolerance
        t = np.where(lt >= 1.0, tol, 1e-6)
        # an intermediate step that Newton has not settled in _STEP_ITER iterations is
        # rejected (steps accepted along a branch take 2-6), not pursued to max_iter
        newp, conv, it, x = _newton(pred, lt, k0[act], gi[act], ops, t, max_iter, sens=sens, tangent=True,
                                    limit=np.where(lt >= 1.0, max_iter, _STEP_ITER))
        iters[act] += it
        move = np.abs(newp - pred).max(axis=1)
        pstep = np.abs(pred - phi[act]).max(axis=1)
        ok = conv & (move <= np.maximum(0.5 * pstep, 0.05))
        unstable = np.zeros(act.size, dtype=bool)
        unstable[ok] = ~_stable(x[ok, :, 0], ops)
        fresh_loss = ok & unstable & (status[act] == 0)
        # an unstable landing after a long step may be a jump onto another branch, so
        # refine the step; only within a short step is it this branch losing stability
        refine = fresh_loss & (lt - lam[act] > _LOCATE)
        ok &= ~refine
        lost = act[fresh_loss & ~refine]
        status[lost] = 2
        where[lost] = lam[lost]
        acc = act[ok]
        phi[acc] = newp[ok]
        lam[acc] = lt[ok]
        tan[acc] = x[ok, :, -1]
        extra[acc] = x[ok, :, :-1]
        dlam[acc] = np.minimum(1.0, 1.5 * dlam[acc])
        fin = acc[lam[acc] >= 1.0]
        status[fin] = np.where(status[fin] == 2, 2, 1)
        running[fin] = False
        rej = act[~ok]
        dlam[rej] *= 0.25
        dead = rej[dlam[rej] < 1e-4]
        running[dead] = False
        fresh = dead[status[dead] == 0]
        status[fresh] = 3
        where[fresh] = lam[fresh]
    status[running] = 3
    where[running] = lam[running]
    return phi, status, where, iters, extra


_amax = np.maximum.reduce  # without ndarray.max's Python-level wrapper


def _load_ratio_one(fx, fy, wx, wy):
    """:func:`_load_ratio` of one frame on plain floats."""
    fn = math.hypot(fx, fy)
    gmax = max(fn, math.hypot(fx + wx, fy + wy))
    return min(gmax / _STABLE_BOUND, fn / _STABLE_BOUND + math.hypot(wx, wy) / _WEIGHT_BOUND)


def _solve_one(L, ei, k0, base, F, w, ops, state, sens, tol, max_iter, PQ, P, q, continuation=True):
    """One frame on plain floats: the warm-started inner loop of the estimator.

    ``PQ`` (M, n) and ``P`` (K, n) sample positions and angles, ``q`` (n,) is the tip
    row of the integration matrix, ``PQ`` and ``q`` times L (:func:`_sampling_one`). Returns ``(φ at the nodes (n,),
    Newton iterations, positions (M, 2), tip (2,), ∂r/∂F (M, 2, 2), ∂φ/∂F at the rows
    of P (K, 2), ∂r(L)/∂F (2, 2))`` (the last three None without ``sens``), or None
    when the frame needs load continuation (the batched path then takes it), or False
    without ``continuation`` when the warm start converged to an unstable equilibrium
    (:func:`solve`'s status 4).
    """
    n, m = ops.n, ops.n - 1
    scale = L * L / ei
    fx, fy = float(F[0]) * scale, float(F[1]) * scale
    wx, wy = float(w[0]) * scale * L, float(w[1]) * scale * L
    convex = _load_ratio_one(fx, fy, wx, wy) < 1.0
    k0n = k0 * L
    # the load terms as one complex product: with e = cos φ + i sin φ and
    # Gn = −(G_x + i G_y), Re(e Gn) = sin φ G_y − cos φ G_x (the residual's load term)
    # and Im(e Gn) = −(cos φ G_y + sin φ G_x) (the Jacobian's diagonal)
    gn = complex(-wx, -wy) * ops.tail
    gn += complex(-fx, -fy)
    if state is not None:
        p = np.array(state, dtype=float).reshape(n)
        p[0] = base
        start = p.copy()
    elif convex:
        p = base + k0n * ops.sigma
        p[1:] += ops.J0inv[:, :-1] @ (np.exp(1j * p[1:-1]) * gn).real
    else:
        return None
    ncol = 4 if sens else 2
    quad = _QUAD_SENS if sens else _QUAD
    rhs0 = ops.rhs_one[:ncol]  # (ncol, m): the constant entries, transposed
    prev = math.inf
    it = 0
    while it < max_iter:
        it += 1
        e = np.exp(1j * p[1:-1])
        eg = e * gn
        # Fortran-ordered right-hand sides and Jacobian (transposes of C copies): LAPACK
        # takes them without a copy
        rhs = rhs0.copy()
        r0 = rhs[0]
        dp = ops.Dall @ p  # (φ'' at the interior nodes, φ' at the tip)
        np.subtract(eg.real, dp[:-1], out=r0[:-1])
        r0[-1] = k0n - dp[-1]
        if sens:
            np.negative(e.real, out=rhs[2, :-1])
            rhs[3, :-1] = e.imag
        Jt = ops.J0T.copy()
        Jt.reshape(-1)[: (m - 1) * (m + 1) : m + 1] += eg.imag
        _, _, x, info = _dgesv(Jt.T, rhs.T, overwrite_a=True, overwrite_b=True)
        if info != 0:
            return None
        step = x[:, 0]
        size = float(_amax(np.abs(step)))
        if not math.isfinite(size):
            return None
        if size > 1.0:
            step = step / size
        p[1:] += step
        if size <= tol or (size <= quad and size <= 0.1 * prev and size**3 <= tol * prev**2):
            break
        prev = size
    else:
        return None
    if not convex:
        psi = x[:, 1]
        if not (psi @ ops.D0 > 0.0 and (psi > 0.0).all()):
            return None if continuation else False
        if np.abs(p - start).max() > _WARM_MOVE:
            return None
    # sin φ, cos φ and, with sensitivities, their derivatives by F = (∂φ/∂F) (cos φ, −sin φ):
    # one product per sampling matrix
    ec = np.exp(1j * p).view(float).reshape(n, 2)  # (cos φ, sin φ)
    cols = np.empty((n, 6 if sens else 2))
    cols[:, :2] = ec[:, ::-1]
    dang = None
    if sens:
        dphi = np.empty((n, 2))
        dphi[0] = 0.0
        np.multiply(x[:, 2:4], scale, out=dphi[1:])
        ec *= _COS_MINUS_SIN
        np.multiply(ec[:, :, None], dphi[:, None, :], out=cols[:, 2:].reshape(n, 2, 2))
        dang = P @ dphi
    out = PQ @ cols
    tip = q @ cols
    if not sens:
        return p, it, out, tip, None, None, None
    return p, it, out[:, :2], tip[:2], out[:, 2:].reshape(-1, 2, 2), dang, tip[2:].reshape(2, 2)


_COS_MINUS_SIN = np.array([1.0, -1.0])


@functools.lru_cache(maxsize=64)
def _sampling_one(n: int, s_m_bytes: bytes, length_m: float):
    """:func:`_sampling` for :func:`_solve_one`: P, PQ·L and the tip row Q[-1]·L."""
    P, PQ = _sampling(n, (np.frombuffer(s_m_bytes) / length_m).tobytes())
    return P, PQ * length_m, _operators(n).Q[-1] * length_m


def _solve_scalar(L, ei, k0, base, F, w, s_m, ops, state, sens, tol, max_iter):
    """One frame as a :class:`BeamSolution` (:func:`_solve_one`); None needs the batched path."""
    P, PQ, q = _sampling_one(ops.n, s_m.tobytes(), L)
    r = _solve_one(L, ei, k0, base, F, w, ops, state, sens, tol, max_iter, PQ, P, q)
    if r is None:
        return None
    p, it, pos, tip, dpos, dang, dtip = r
    return BeamSolution(
        s_m=s_m,
        angle_rad=P @ p,
        positions_m=pos,
        tip_position_m=tip,
        tip_angle_rad=np.float64(p[-1]),
        success=np.bool_(True),
        message=_OK,
        iterations=np.int64(it),
        method="fast",
        state=p,
        dpositions_dforce=dpos,
        dangle_dforce=dang,
        dtip_position_dforce=dtip,
    )


def solve(
    length_m,
    ei_nm2,
    tip_curvature_per_m,
    force_n,
    distributed_load_n_per_m,
    base_angle_rad,
    s_m,
    *,
    n_nodes: int = DEFAULT_NODES,
    initial=None,
    sensitivities: bool = False,
    tol: float = NEWTON_TOL,
    max_iter: int = NEWTON_MAX_ITER,
    continuation: bool = True,
) -> BeamSolution:
    """Fast spectral solver on already validated arrays (the estimator's inner loop).

    Parameters
    ----------
    length_m : float
        Beam length L [m].
    ei_nm2, tip_curvature_per_m, base_angle_rad : ndarray, shape (...)
        Flexural rigidity EI(P) [N·m²] (paper eq. 15), natural curvature K0 [1/m],
        base tangent angle [rad]; broadcast against each other.
    force_n, distributed_load_n_per_m : ndarray, shape (..., 2)
        Tip force F [N] and distributed load w [N/m] in the base frame.
    s_m : ndarray, shape (M,)
        Output arc lengths in [0, L] [m].
    n_nodes : int
        Chebyshev–Lobatto nodes of the collocation.
    initial : BeamSolution or ndarray, shape (..., n_nodes), optional
        Warm start: a previous solution (its ``state``) or φ at the nodes.
    sensitivities : bool
        Also return ∂r/∂F and ∂φ/∂F from the converged Jacobian.
    tol : float
        Newton stops when the angle error left is below ``tol`` [rad].
    max_iter : int
        Newton iterations per solve (per continuation step).
    continuation : bool
        With ``initial``: False reports a frame beyond the convexity bound whose
        warm-started Newton converged to an *unstable* equilibrium as failed
        (``success=False``) instead of re-solving it by load continuation from the
        unloaded arc. For trial solves whose caller rejects shapes that leave their
        linear prediction anyway (the estimator): the continuation's answer there is a
        distant branch point. Frames that converged to a stable equilibrium far from
        the start, or did not converge, are still continued.

    Returns
    -------
    BeamSolution
    """
    ops = _operators(int(n_nodes))
    n = ops.n
    L = float(length_m)
    ei = np.asarray(ei_nm2, dtype=float)
    k0 = np.asarray(tip_curvature_per_m, dtype=float)
    base = np.asarray(base_angle_rad, dtype=float)
    F = np.asarray(force_n, dtype=float)
    w = np.asarray(distributed_load_n_per_m, dtype=float)
    s_m = np.asarray(s_m, dtype=float)
    state = initial.state if isinstance(initial, BeamSolution) else initial
    if initial is not None:
        if state is None:
            raise ArgumentError("initial: the solution carries no state (solve it with method='fast')")
        state = np.asarray(state, dtype=float)
        if state.ndim == 0 or state.shape[-1] != n:
            raise ArgumentError(f"initial: expected a state of shape (..., {n}) for n_nodes={n}, got {state.shape}")
    if ei.ndim == k0.ndim == base.ndim == 0 and F.shape == w.shape == (2,) and (state is None or np.ndim(state) == 1):
        sol = _solve_scalar(L, float(ei), float(k0), float(base), F, w, s_m, ops, state, sensitivities, tol, max_iter)
        if sol is not None:
            return sol
    shape = np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1])
    B = math.prod(shape)
    ei = np.broadcast_to(ei, shape).reshape(B)
    scale = L * L / ei
    k0n = np.broadcast_to(k0, shape).reshape(B) * L
    base = np.broadcast_to(base, shape).reshape(B)
    f = np.broadcast_to(F, (*shape, 2)).reshape(B, 2) * scale[:, None]
    wn = np.broadcast_to(w, (*shape, 2)).reshape(B, 2) * (scale * L)[:, None]
    gi = f[:, None, :] + wn[:, None, :] * ops.tail[None, :, None]  # (B, n-2, 2)
    ratio = _load_ratio(f, wn)
    convex = ratio < 1.0

    if state is not None:
        phi = np.broadcast_to(state, (*shape, n)).reshape(B, n).copy()
        phi[:, 0] = base
        first = None  # every frame
    else:
        phi = base[:, None] + k0n[:, None] * ops.sigma[None, :]
        first = np.flatnonzero(convex)
        # start convex frames from the linearised solution about the free arc
        phi[first, 1:] += _arc_tangent(phi[first], gi[first], ops)
        if first.size == B:
            first = None

    status = np.zeros(B, dtype=int)  # 1 ok, 2 unstable, 3 no convergence / lost the branch, 4 warm start unstable
    where = np.ones(B)
    extra = np.full((B, n - 1, 1 + 2 * sensitivities), np.nan)
    if first is None:
        start = phi
        phi, conv, iters, x = _newton(phi, np.ones(B), k0n, gi, ops, tol, max_iter, sens=sensitivities)
        near = np.abs(phi - start).max(axis=1) <= _WARM_MOVE
        stable = _stable(x[..., 0], ops)
        ok = conv & (convex | (stable & near))
        status[ok] = 1
        if not continuation:
            status[conv & ~convex & ~stable] = 4
        extra = x
    else:
        iters = np.zeros(B, dtype=int)
        if first.size:
            p, conv, it, x = _newton(
                phi[first], np.ones(first.size), k0n[first], gi[first], ops, tol, max_iter, sens=sensitivities
            )
            iters[first] = it
            phi[first[conv]] = p[conv]
            status[first[conv]] = 1
            extra[first] = x
    rest = np.flatnonzero(status == 0)
    if rest.size:
        start = base[rest, None] + k0n[rest, None] * ops.sigma[None, :]
        p, st_, wl, it, x = _continuation(start, k0n[rest], gi[rest], ratio[rest], ops, tol, max_iter, sensitivities)
        phi[rest] = p
        status[rest] = st_
        where[rest] = wl
        iters[rest] += it
        extra[rest] = x

    sigma_m = np.asarray(s_m, dtype=float) / L
    M = sigma_m.size
    P, PQ = _sampling(n, sigma_m.tobytes())
    sn, cs = np.sin(phi), np.cos(phi)
    pos = np.empty((B, M, 2))
    pos[..., 0] = sn @ PQ.T
    pos[..., 1] = cs @ PQ.T
    pos *= L
    tip = np.empty((B, 2))
    tip[:, 0] = sn @ ops.Q[-1]
    tip[:, 1] = cs @ ops.Q[-1]
    tip *= L

    dpos = dang = dtip = None
    if sensitivities:
        # node-major (n, B, ...) so that each product with P, PQ, Q is one matrix
        # product instead of B small ones (~2× faster for the estimator's batches)
        dphi = np.zeros((n, B, 2))
        dphi[1:] = extra[..., 1:3].transpose(1, 0, 2) * scale[:, None]
        dsc = np.empty((n, B, 2, 2))  # ∂(sin φ, cos φ)/∂F at the nodes
        np.multiply(cs.T[..., None], dphi, out=dsc[:, :, 0])
        np.multiply(sn.T[..., None], dphi, out=dsc[:, :, 1])
        np.negative(dsc[:, :, 1], out=dsc[:, :, 1])
        flat = dsc.reshape(n, -1)
        dang = np.empty((B, M, 2))
        dang[:] = (P @ dphi.reshape(n, -1)).reshape(M, B, 2).transpose(1, 0, 2)
        dpos = np.empty((B, M, 2, 2))
        np.multiply((PQ @ flat).reshape(M, B, 2, 2).transpose(1, 0, 2, 3), L, out=dpos)
        dang = dang.reshape(*shape, M, 2)
        dpos = dpos.reshape(*shape, M, 2, 2)
        dtip = (ops.Q[-1] @ flat).reshape(*shape, 2, 2) * L

    success = status == 1
    if success.all():
        message = _OK if not shape else np.full(shape, _OK)
    else:
        message = _messages(status, where, "fast")
        message = message.reshape(shape) if shape else str(message[0])
    return BeamSolution(
        s_m=np.asarray(s_m, dtype=float),
        angle_rad=(phi @ P.T).reshape(*shape, M),
        positions_m=pos.reshape(*shape, M, 2),
        tip_position_m=tip.reshape(*shape, 2),
        tip_angle_rad=phi[:, -1].reshape(shape),
        success=success.reshape(shape),
        message=message,
        iterations=iters.reshape(shape),
        method="fast",
        state=phi.reshape(*shape, n),
        dpositions_dforce=dpos,
        dangle_dforce=dang,
        dtip_position_dforce=dtip,
    )


def _messages(status, where_lam, method):
    out = np.full(status.shape, _OK, dtype=object)
    for i in np.flatnonzero(status == 2):
        out[i] = (
            f"unstable: the equilibrium loses stability beyond load factor {where_lam[i]:.3g} "
            "(compressive load beyond buckling)"
        )
    for i in np.flatnonzero(status == 3):
        out[i] = (
            f"no convergence ({method}): the branch from the unloaded shape ends near load factor "
            f"{where_lam[i]:.3g} (limit point: buckling or snap-through)"
        )
    out[status == 4] = ("unstable: the warm-started solution is an unstable equilibrium "
                        "(load beyond the convexity bound; not continued from the unloaded shape)")
    return out.astype(str)


# --------------------------------------------------------------------------- shooting


def _shoot_one(L, ei, k0, base, F, w, s_m, rtol, atol, max_newton):
    """Solve one frame by the paper's shooting method.

    Returns (φ at s_m, positions at s_m, tip, tip angle, status, load factor, IVP solves).
    """
    from scipy.integrate import solve_ivp

    f = np.asarray(F) * L * L / ei
    wn = np.asarray(w) * L**3 / ei
    k0n = k0 * L
    ratio = float(_load_ratio(f, wn))

    # state: φ, φ', ψ = ∂φ/∂φ'(0), ψ', χ = ∂φ/∂λ, χ', x/L, y/L
    def rhs(sig, y, lam):
        phi, dphi, psi, dpsi, chi, dchi = y[0], y[1], y[2], y[3], y[4], y[5]
        gx = f[0] + wn[0] * (1.0 - sig)
        gy = f[1] + wn[1] * (1.0 - sig)
        s, c = math.sin(phi), math.cos(phi)
        load = s * gy - c * gx
        q = lam * (c * gy + s * gx)
        return [dphi, lam * load, dpsi, q * psi, dchi, q * chi + load, s, c]

    count = [0]

    def shoot(c0, lam, t_eval=None):
        count[0] += 1
        return solve_ivp(
            rhs,
            (0.0, 1.0),
            [base, c0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            method="DOP853",
            rtol=rtol,
            atol=atol,
            args=(lam,),
            t_eval=t_eval,
        )

    def newton(c0, lam):
        c = c0
        for _ in range(max_newton):
            sol = shoot(c, lam)
            if not sol.success:
                return None, None
            res = sol.y[1, -1] - k0n
            dres = sol.y[3, -1]
            if dres == 0.0 or not math.isfinite(res):
                return None, None
            dc = -res / dres
            c += dc
            if abs(dc) <= 1e-12 * max(1.0, abs(c)):
                return c, sol
        return None, None

    def stable(sol):
        # Jacobi condition: ψ(σ) > 0 on (0, 1] and ψ'(1) > 0 (Prüfer angle below π/2)
        return bool(np.all(sol.y[2, 1:] > 0.0) and sol.y[3, -1] > 0.0)

    def slope(sol):
        # dφ'(0)/dλ along the branch: R(c, λ) = φ'(1) − K0 L = 0
        return -sol.y[5, -1] / sol.y[3, -1]

    steps = max(1, math.ceil(2.0 * ratio))
    lam, dlam = 0.0, 1.0 / steps
    c = k0n
    dc = slope(shoot(c, 0.0))
    status, where = 1, 1.0
    while lam < 1.0:
        lt = min(1.0, lam + dlam)
        guess = c + dc * (lt - lam)
        cn, sol = newton(guess, lt)
        # a corrector far from the predictor means Newton jumped to another branch
        # ... and an unstable landing after a long step may be one too: refine the step
        jump = cn is None or abs(cn - guess) > max(0.5 * abs(guess - c), 0.05)
        unstable = not jump and status == 1 and not stable(sol)
        if jump or (unstable and lt - lam > _LOCATE):
            dlam *= 0.25
            if dlam < 1e-4:
                status, where = 3, lam
                break
            continue
        if unstable:
            status, where = 2, lam
        c, lam, dc = cn, lt, slope(sol)
        dlam = min(dlam * 1.5, 1.0)
    sol = shoot(c, lam, t_eval=np.unique(np.concatenate([s_m / L, [1.0]])))
    idx = np.searchsorted(sol.t, s_m / L)
    y = sol.y
    phi_m = y[0, idx]
    pos = np.stack([y[6, idx], y[7, idx]], axis=-1) * L
    tip = np.array([y[6, -1], y[7, -1]]) * L
    return phi_m, pos, tip, y[0, -1], status, where, count[0]


def _shooting(L, ei, k0, base, F, w, s_m, rtol=1e-12, atol=1e-12, max_newton=30):
    shape = np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1])
    B = math.prod(shape)
    ei = np.broadcast_to(ei, shape).reshape(B)
    k0 = np.broadcast_to(k0, shape).reshape(B)
    base = np.broadcast_to(base, shape).reshape(B)
    F = np.broadcast_to(F, (*shape, 2)).reshape(B, 2)
    w = np.broadcast_to(w, (*shape, 2)).reshape(B, 2)
    M = s_m.size
    angle = np.empty((B, M))
    pos = np.empty((B, M, 2))
    tip = np.empty((B, 2))
    tip_angle = np.empty(B)
    status = np.empty(B, dtype=int)
    where = np.empty(B)
    iters = np.empty(B, dtype=int)
    for i in range(B):
        angle[i], pos[i], tip[i], tip_angle[i], status[i], where[i], iters[i] = _shoot_one(
            L, ei[i], k0[i], base[i], F[i], w[i], s_m, rtol, atol, max_newton
        )
    message = _messages(status, where, "shooting")
    return BeamSolution(
        s_m=s_m,
        angle_rad=angle.reshape(*shape, M),
        positions_m=pos.reshape(*shape, M, 2),
        tip_position_m=tip.reshape(*shape, 2),
        tip_angle_rad=tip_angle.reshape(shape),
        success=(status == 1).reshape(shape),
        message=message.reshape(shape) if shape else str(message[0]),
        iterations=iters.reshape(shape),
        method="shooting",
    )


# --------------------------------------------------------------------------- public


def solve_beam(
    length_m,
    ei_nm2,
    tip_curvature_per_m,
    force_n=(0.0, 0.0),
    distributed_load_n_per_m=(0.0, 0.0),
    base_angle_rad=0.0,
    s_m=None,
    method: str = "fast",
    *,
    sensitivities: bool = False,
    initial=None,
    strict: bool = False,
    warn: bool = True,
    n_nodes: int = DEFAULT_NODES,
    tol: float = 1e-11,
    max_iter: int = 30,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> BeamSolution:
    """Shape of a naturally curved cantilever under a tip force and a distributed load.

    Solves ``EI φ'' = sin φ G_y − cos φ G_x``, ``G(s) = F + w (L − s)``, ``φ(0) = φ_base``,
    ``φ'(L) = K0`` and integrates ``r(s) = ∫ (sin φ, cos φ) ds`` (paper eq. 13–17 in the
    base frame of DESIGN section 2). All inputs except ``length_m`` and ``s_m`` broadcast
    over leading batch axes ``...``.

    Parameters
    ----------
    length_m : float
        Beam length L [m].
    ei_nm2 : array_like, shape (...)
        Flexural rigidity EI(P) [N·m²] (paper eq. 15).
    tip_curvature_per_m : array_like, shape (...)
        Natural curvature K0(P) of the free-bending model [1/m] (paper eq. 14).
    force_n : array_like, shape (..., 2)
        Tip force (Fx, Fy) in the base frame [N].
    distributed_load_n_per_m : array_like, shape (..., 2)
        Uniform load per length, e.g. gravity ``m g / L · ĝ`` [N/m].
    base_angle_rad : array_like, shape (...)
        Tangent angle at the base, from ``+y`` toward ``+x`` [rad]; rotates the free arc.
    s_m : array_like, shape (M,), optional
        Output arc lengths in [0, L] [m]; default ``DEFAULT_POINTS`` evenly spaced points.
    method : {"fast", "shooting", "paper"}
        Spectral Newton solver (default) or the paper's shooting method (``"paper"`` is
        an alias).
    sensitivities : bool
        Also return ``dpositions_dforce``, ``dangle_dforce``, ``dtip_position_dforce``
        (fast method only).
    initial : BeamSolution or ndarray, optional
        Warm start for the fast method (a previous solution or its ``state``).
    strict : bool
        Raise :class:`~bendsense.errors.ConvergenceError` instead of returning frames
        with ``success=False``.
    warn : bool
        Emit a :class:`BeamConvergenceWarning` when some frames fail.
    n_nodes, tol, max_iter : int, float, int
        Fast method: Chebyshev nodes, Newton step tolerance [rad], Newton iterations.
    rtol, atol : float
        Shooting method: tolerances of ``solve_ivp``.

    Returns
    -------
    BeamSolution
        ``success`` is false for frames that did not converge, whose equilibrium is
        unstable (compressive load beyond buckling) or whose branch from the unloaded
        shape ends at a limit point; their shapes are not physical answers.

    Raises
    ------
    ValueError
        A non-finite or ill-shaped input (the message names the argument).
    ConvergenceError
        With ``strict=True``, if any frame fails.
    """
    if isinstance(length_m, bool):
        raise ArgumentError(f"length_m: expected a number, got {length_m!r}")
    L = _as_float("length_m", length_m, positive=True)
    if L.ndim != 0:
        raise ArgumentError(f"length_m: expected a scalar, got shape {L.shape}")
    L = float(L)
    ei = _as_float("ei_nm2", ei_nm2, positive=True)
    k0 = _as_float("tip_curvature_per_m", tip_curvature_per_m)
    F = _as_vector("force_n", force_n)
    w = _as_vector("distributed_load_n_per_m", distributed_load_n_per_m)
    base = _as_float("base_angle_rad", base_angle_rad)
    s = _grid(L, s_m)
    try:
        np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1])
    except ValueError:
        raise ArgumentError(
            "ei_nm2, tip_curvature_per_m, base_angle_rad, force_n[..., :], distributed_load_n_per_m[..., :]: "
            f"batch shapes {ei.shape}, {k0.shape}, {base.shape}, {F.shape[:-1]}, {w.shape[:-1]} do not broadcast"
        ) from None
    if method == "fast":
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, (int, np.integer)) or n_nodes < 4:
            raise ArgumentError(f"n_nodes: expected an integer >= 4, got {n_nodes!r}")
        sol = solve(
            L,
            ei,
            k0,
            F,
            w,
            base,
            s,
            n_nodes=int(n_nodes),
            initial=initial,
            sensitivities=sensitivities,
            tol=tol,
            max_iter=max_iter,
        )
    elif method in ("shooting", "paper"):
        if sensitivities:
            raise ArgumentError("sensitivities: only available with method='fast'")
        sol = _shooting(L, ei, k0, base, F, w, s, rtol=rtol, atol=atol)
    else:
        raise ArgumentError(f"method: must be one of fast, shooting, paper, got {method!r}")
    failed = ~np.asarray(sol.success)
    if failed.any():
        msgs = np.atleast_1d(np.asarray(sol.message))[np.atleast_1d(failed)]
        text = f"{int(failed.sum())} of {failed.size} beam solve(s) failed; first: {msgs[0]}"
        if strict:
            raise ConvergenceError(text)
        if warn:
            warnings.warn(text, BeamConvergenceWarning, stacklevel=2)
    return sol
