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
    method on the dense collocation Jacobian, positions by spectral integration and
    values at ``s_m`` by barycentric interpolation, compiled per frame with numba
    (:mod:`bendsense.mechanics._beam_kernels`; a batch is a ``prange`` loop over frames). Loads for
    which the energy is provably convex (``max_s |G(s)| L²/EI < π²/4``, so that the
    equilibrium is unique and stable) are solved by Newton from the free arc directly;
    larger loads follow the branch connected to the unloaded arc by load continuation,
    and the Jacobi field at every step flags a loss of stability.
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

from bendsense import _jit
from bendsense._batched import brief_repr
from bendsense.errors import ArgumentError, ConvergenceError, ConvergenceWarning
from bendsense.mechanics import _beam_kernels as _k
from bendsense.status import Status
from bendsense.validation import short

__all__ = [
    "BeamSolution",
    "BeamConvergenceWarning",
    "solve_beam",
    "solve",
    "FastOptions",
    "free_arc",
    "DEFAULT_NODES",
    "DEFAULT_POINTS",
]

#: Chebyshev nodes of the fast method; enough for ~1e-10 L tip accuracy at
#: F L²/EI up to 10 (see tests and ``benchmarks/bench_beam.py``).
DEFAULT_NODES = 20
#: Number of output points of the default ``s_m`` grid (both ends included).
DEFAULT_POINTS = 101

_OK = "converged"
NEWTON_TOL = _k.NEWTON_TOL  # rad: default Newton tolerance of :func:`solve`
NEWTON_MAX_ITER = 30


class BeamConvergenceWarning(ConvergenceWarning):
    """Some frames of a beam solve did not converge or are unstable (``success=False``)."""


@dataclass(frozen=True, kw_only=True)
class FastOptions:
    """How the fast spectral solver (:func:`solve`) runs: its grid, its Newton iteration, what it returns.

    Attributes
    ----------
    n_nodes : int
        Chebyshev–Lobatto nodes of the collocation (at least 4).
    tol : float
        Newton stops when the angle error left is below ``tol`` [rad].
    max_iter : int
        Newton iterations per solve (per continuation step).
    continuation : bool
        With a warm start: False reports a frame beyond the convexity bound whose
        warm-started Newton converged to an *unstable* equilibrium as failed
        (``success=False``) instead of re-solving it by load continuation from the
        unloaded arc. Frames that converged to a stable equilibrium far from the
        start, or did not converge, are still continued.
    sensitivities : bool
        Also return ∂r/∂F and ∂φ/∂F (and ∂/∂s_c of a contact) from the converged Jacobian.
    """

    n_nodes: int = DEFAULT_NODES
    tol: float = NEWTON_TOL
    max_iter: int = NEWTON_MAX_ITER
    continuation: bool = True
    sensitivities: bool = False

    def __post_init__(self):
        n = self.n_nodes
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 4:
            raise ArgumentError(f"n_nodes: expected an integer >= 4, got {n!r}")
        object.__setattr__(self, "n_nodes", int(n))


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
        ``initial=`` to warm-start a nearby solve (at the same ``contact_s_m``: a
        contact's nodes are those of its two domains, split at s_c).
    dpositions_dforce : ndarray, shape (..., M, 2, 2) or None
        ∂r_a(s_j)/∂F_b [m/N], with ``sensitivities=True``.
    dangle_dforce : ndarray, shape (..., M, 2) or None
        ∂φ(s_j)/∂F_b [rad/N], with ``sensitivities=True``.
    dtip_position_dforce : ndarray, shape (..., 2, 2) or None
        ∂r_a(L)/∂F_b [m/N], with ``sensitivities=True``.
    contact_s_m : ndarray, shape (...) or None
        Arc length s_c where the force acts [m]; None for a tip force (``contact_s_m=None``).
    dpositions_dcontact : ndarray, shape (..., M, 2) or None
        ∂r_a(s_j)/∂s_c [m/m] at fixed s_j, with ``sensitivities=True`` (fast method): how
        the shape changes when the force's point moves along the beam. At s_c = L (a
        tip force) the one-sided derivative, toward the base.
    dangle_dcontact : ndarray, shape (..., M) or None
        ∂φ(s_j)/∂s_c [rad/m] at fixed s_j, with ``sensitivities=True``.
    dtip_position_dcontact : ndarray, shape (..., 2) or None
        ∂r_a(L)/∂s_c [m/m], with ``sensitivities=True``.
    """

    __repr__ = brief_repr  # a line or two, not every value of every frame

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
    contact_s_m: np.ndarray | None = None
    dpositions_dcontact: np.ndarray | None = None
    dangle_dcontact: np.ndarray | None = None
    dtip_position_dcontact: np.ndarray | None = None

    @property
    def length_m(self) -> float:
        """Beam length L [m]."""
        return float(self.s_m[-1]) if self.s_m.size else 0.0

    def plot(self, ax=None, *, max_frames: int = 50, **kwargs):
        """Draw the shape(s) in the base frame in mm (:func:`bendsense.plots.plot_shapes`).

        Frames with ``success=False`` are dashed (and explained in the legend). Keyword
        arguments go to ``Axes.plot``. Returns the matplotlib axes.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; None makes a new figure.
        max_frames : int, default 50
            Most frames drawn, evenly spaced.
        **kwargs
            Passed to ``Axes.plot``.
        """
        from bendsense.plots import plot_shapes

        frames = int(np.prod(np.shape(self.success))) if np.ndim(self.success) else 1
        return plot_shapes(self, ax, max_frames=max_frames, legend=frames <= 8, **kwargs)


# --------------------------------------------------------------------------- operators


_KernelOperators = _k._KernelOperators


@dataclass(frozen=True)
class _Operators:
    n: int
    sigma: np.ndarray
    D: np.ndarray  # d/dσ at the nodes
    Q: np.ndarray  # (Q f)_j = ∫_0^{σ_j} f dσ
    kernel: _KernelOperators


@functools.lru_cache(maxsize=64)
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
    # one domain: collocation rows at the interior nodes (h = 1), the tip row φ'(1) = K0 L
    C = np.vstack([D2[1:-1], D[-1:]])
    m = n - 1
    h2 = np.ones(m)
    h2[-1] = 0.0
    J0 = np.ascontiguousarray(C[:, 1:])
    kernel = _KernelOperators(sigma, C, h2, np.ones(m), 1.0 - sigma[1:], J0, np.linalg.inv(J0), D[0, 1:].copy(), 1.0,
                              m - 1, 1.0)
    return _Operators(n, sigma, D, Q, kernel)


@functools.lru_cache(maxsize=16)
def _split_operators(n: int) -> _k._SplitOperators:
    """The reference operators of the domains of a contact (:func:`bendsense.mechanics._beam_kernels.contact_grid`)."""
    sig, D, D2, Q = np.zeros((n + 1, n)), np.zeros((n + 1, n, n)), np.zeros((n + 1, n, n)), np.zeros((n + 1, n, n))
    for k in range(min(_k.MIN_DOMAIN, n), n + 1):
        ops = _operators(k)
        sig[k, :k], D[k, :k, :k], D2[k, :k, :k], Q[k, :k, :k] = ops.sigma, ops.D, ops.D @ ops.D, ops.Q
    return _k._SplitOperators(sig, D, D2, Q)


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
    return np.ascontiguousarray(P), np.ascontiguousarray(PQ)


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
        raise ArgumentError(f"s_m: must lie in [0, length_m] = [0, {length_m:g}], got [{s.min():g}, {s.max():g}]")
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


def _contact_sigma(contact_s_m, length_m: float) -> np.ndarray:
    """σ_c = s_c / L of ``contact_s_m`` (validated: 0 < s_c ≤ L); within 1e-9 L of the tip: the tip, σ_c = 1.

    So close to the tip the second domain would be too short to resolve its φ' (its
    rows scale with its length); the force moves by at most 1e-9 L.
    """
    tol = 1e-12 * length_m
    if type(contact_s_m) is float and 0.0 < contact_s_m <= length_m + tol:  # one location (a live loop's, per block)
        sigma = contact_s_m / length_m
        return np.array(1.0 if sigma >= 1.0 - 1e-9 else sigma)
    sc = _as_float("contact_s_m", contact_s_m)
    if not np.all((sc > 0.0) & (sc <= length_m + tol)):
        bad = sc[~((sc > 0.0) & (sc <= length_m + tol))].ravel()[0]
        raise ArgumentError(f"contact_s_m: expected 0 < s_c <= length_m = {length_m:g} m, got {bad:g}")
    sigma = sc / length_m
    return np.where(sigma >= 1.0 - 1e-9, 1.0, sigma)


# --------------------------------------------------------------------------- fast core


def solve(
    length_m,
    ei_nm2,
    tip_curvature_per_m,
    force_n,
    distributed_load_n_per_m,
    base_angle_rad,
    s_m,
    *,
    initial=None,
    contact_s_m=None,
    options: FastOptions = FastOptions(),
) -> BeamSolution:
    """Fast spectral solver on already validated arrays (compiled kernels: :mod:`bendsense.mechanics._beam_kernels`).

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
        Output arc lengths 0 ≤ s ≤ L [m].
    initial : BeamSolution or ndarray, shape (..., n_nodes), optional
        Warm start: a previous solution (its ``state``) or φ at the nodes.
    contact_s_m : ndarray, shape (...), optional
        Arc length s_c of the force's point, 0 < s_c ≤ L [m]; None: the tip.
    options : FastOptions, optional
        Nodes, Newton tolerance and iterations, continuation, sensitivities; default
        ``FastOptions()``.

    Returns
    -------
    BeamSolution
    """
    n_nodes, tol, max_iter = options.n_nodes, options.tol, options.max_iter
    sensitivities, continuation = options.sensitivities, options.continuation
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
    sc = np.ones(()) if contact_s_m is None else _contact_sigma(contact_s_m, L)
    shape = np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1], sc.shape)
    B = math.prod(shape)

    def flat(a, tail=()):  # C-contiguous and writable: the one array type the kernels are compiled for
        return np.require(np.broadcast_to(a, (*shape, *tail)).reshape(B, *tail), float, ("C", "W", "A"))

    has_state = state is not None
    st = flat(state, (n,)) if has_state else np.zeros((B, n))
    sigma_m = s_m / L
    M = sigma_m.size
    P, PQ = _sampling(n, sigma_m.tobytes())
    phi = np.empty((B, n))
    q = np.require(ops.Q[-1], float, ("C", "W"))
    status = np.empty(B, dtype=np.int64)
    where = np.empty(B)
    iters = np.empty(B, dtype=np.int64)
    angle = np.empty((B, M))
    pos = np.empty((B, M, 2))
    dpos = np.empty((B, M, 2, 3) if sensitivities else (B, 1, 2, 3))
    dang = np.empty((B, M, 3) if sensitivities else (B, 1, 3))
    tip = np.empty((B, 8))
    _jit.call(_k.solve_frames, L, flat(ei), flat(k0), flat(base), flat(F, (2,)), flat(w, (2,)), flat(sc), st,
              has_state, ops.kernel, _split_operators(n), float(tol), int(max_iter), bool(sensitivities),
              bool(continuation), np.ascontiguousarray(sigma_m), P, PQ, q,
              (phi, status, where, iters, angle, pos, dpos, dang, tip))
    success = status == int(Status.OK)
    if success.all():
        message = _OK if not shape else np.full(shape, _OK)
    else:
        message = _messages(status, where, "fast")
        message = message.reshape(shape) if shape else str(message[0])
    return BeamSolution(
        s_m=s_m,
        angle_rad=angle.reshape(*shape, M),
        positions_m=pos.reshape(*shape, M, 2),
        tip_position_m=tip[:, :2].reshape(*shape, 2),
        tip_angle_rad=phi[:, -1].reshape(shape),
        success=success.reshape(shape),
        message=message,
        iterations=iters.reshape(shape),
        method="fast",
        state=phi.reshape(*shape, n),
        dpositions_dforce=dpos[..., :2].reshape(*shape, M, 2, 2) if sensitivities else None,
        dangle_dforce=dang[..., :2].reshape(*shape, M, 2) if sensitivities else None,
        dtip_position_dforce=tip[:, 2:].reshape(B, 2, 3)[..., :2].reshape(*shape, 2, 2) if sensitivities else None,
        contact_s_m=np.broadcast_to(np.asarray(contact_s_m, dtype=float), shape).copy() if contact_s_m is not None
        else None,
        dpositions_dcontact=dpos[..., 2].reshape(*shape, M, 2) if sensitivities else None,
        dangle_dcontact=dang[..., 2].reshape(*shape, M) if sensitivities else None,
        dtip_position_dcontact=tip[:, 2:].reshape(B, 2, 3)[..., 2].reshape(*shape, 2) if sensitivities else None,
    )


def _messages(status, where_lam, method):
    out = np.full(status.shape, _OK, dtype=object)
    for i in np.flatnonzero(status == Status.UNSTABLE):
        out[i] = (
            f"unstable: the equilibrium loses stability beyond load factor {where_lam[i]:.3g} "
            "(compressive load beyond buckling)"
        )
    for i in np.flatnonzero(status == Status.LOST_BRANCH):
        out[i] = (
            f"no convergence ({method}): the branch from the unloaded shape ends near load factor "
            f"{where_lam[i]:.3g} (limit point: buckling or snap-through)"
        )
    out[status == Status.WARM_UNSTABLE] = ("unstable: the warm-started solution is an unstable equilibrium "
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
    ratio = _k.load_ratio(f[0], f[1], wn[0], wn[1], 0.0)

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
        if jump or (unstable and lt - lam > _k.LOCATE):
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
    contact_s_m=None,
) -> BeamSolution:
    """Shape of a naturally curved cantilever under a point force and a distributed load.

    Solves ``EI φ'' = sin φ G_y − cos φ G_x``, ``G(s) = F [s < s_c] + w (L − s)``,
    ``φ(0) = φ_base``, ``φ'(L) = K0`` and integrates ``r(s) = ∫ (sin φ, cos φ) ds`` (paper
    eq. 13–17 in the base frame of DESIGN section 2; the force at the tip, ``s_c = L``,
    unless ``contact_s_m`` says otherwise). All inputs except ``length_m`` and ``s_m``
    broadcast over leading batch axes ``...``.

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
        Output arc lengths 0 ≤ s ≤ L [m]; default ``DEFAULT_POINTS`` evenly spaced points.
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
    contact_s_m : array_like, shape (...), optional
        Arc length s_c where the force acts, 0 < s_c ≤ L [m] (a contact along the body;
        DESIGN section 2b); None: the tip. Beyond s_c the beam bends under its weight
        only. The fast method splits its Chebyshev grid at s_c (φ'' jumps there); within
        1e-9 L of the tip the force is at the tip. With ``sensitivities``, the solution
        carries ∂/∂s_c too (``dangle_dcontact``, ...). Fast method only.

    Returns
    -------
    BeamSolution
        ``success`` is false for frames that did not converge, whose equilibrium is
        unstable (compressive load beyond buckling) or whose branch from the unloaded
        shape ends at a limit point; their shapes are not physical answers.

    Raises
    ------
    ArgumentError
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
    if not isinstance(method, str) or method not in ("fast", "shooting", "paper"):
        raise ArgumentError(f"method: must be one of fast, shooting, paper, got {short(method)}")
    s = _grid(L, s_m)
    try:
        np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1])
    except ValueError:
        raise ArgumentError(
            "ei_nm2, tip_curvature_per_m, base_angle_rad, force_n[..., :], distributed_load_n_per_m[..., :]: "
            f"batch shapes {ei.shape}, {k0.shape}, {base.shape}, {F.shape[:-1]}, {w.shape[:-1]} do not broadcast"
        ) from None
    if contact_s_m is not None:
        sc = _contact_sigma(contact_s_m, L)
        others = np.broadcast_shapes(ei.shape, k0.shape, base.shape, F.shape[:-1], w.shape[:-1])
        try:
            np.broadcast_shapes(others, sc.shape)
        except ValueError:
            raise ArgumentError(f"contact_s_m: shape {sc.shape} does not broadcast against the other inputs' batch "
                                f"shape {others}") from None
        if method != "fast":
            raise ArgumentError("contact_s_m: only available with method='fast'")
    if method == "fast":
        options = FastOptions(n_nodes=n_nodes, tol=tol, max_iter=max_iter, sensitivities=sensitivities)
        if contact_s_m is not None and n_nodes < 2 * _k.MIN_DOMAIN - 1:
            raise ArgumentError(f"n_nodes: a force along the body (contact_s_m) needs >= {2 * _k.MIN_DOMAIN - 1} "
                                f"nodes, got {n_nodes!r}")
        sol = solve(L, ei, k0, F, w, base, s, initial=initial, contact_s_m=contact_s_m, options=options)
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
