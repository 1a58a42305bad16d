"""Tip force estimation from a reconstructed shape (paper section IV-C, eq. 18 and 21).

The estimate is the force whose beam shape (paper eq. 13–17) is closest to the
reconstructed shape ``p⁰(s)`` at the frame's pressure::

    F̂ = argmin_F ∫₀^Lc ‖p⁰(s) − p(s; F, P)‖² ds,   F = F_fixed + D u,   u ≥ lower   (eq. 18)

compared at the same arc length ``s`` over the common length ``Lc = min(L_sensor,
L_actuator)`` (paper: 0.132 m and 0.134 m). ``K0(P)`` comes from the free-bending model
(eq. 8–12), ``EI(P)`` from the stiffness model (eq. 15), the distributed load from
``config.weight_per_length_n_per_m``, the base angle is 0.

Quadrature
    For a PCC shape (a :class:`~bendsense.pcc.Shape` or segment curvatures) the
    integral is a composite Gauss–Legendre rule over the sensor segments (clipped to
    ``Lc``) with ``config.estimation.n_points`` nodes in total: every segment gets
    ``n_points // segments`` nodes and the remainder goes to the longest segments. The
    PCC shape is smooth inside a segment and its curvature jumps at the junctions, so a
    rule per segment integrates it to ~1e-10 relative with 2–3 nodes per segment, where
    one rule over the whole length would converge only algebraically. With fewer points
    than segments one Gauss–Legendre rule over ``[0, Lc]`` is used. A shape given as
    positions only (a :class:`~bendsense.beam.BeamSolution`, any object with ``s_m`` and
    ``positions_m`` but no ``curvature_per_m``, or an array with ``s_m=``) is compared at
    its own points in ``[0, Lc]`` with trapezoid weights, so that a shape made by the
    beam model itself is matched exactly.

Constraints (DESIGN section 2), ``F = D u`` with ``D`` (2, k) of orthonormal columns
    ``none``: ``D = I``, ``u = (Fx, Fy)``.
    ``vertical``: ``D = (0, 1)``, ``u = Fy`` (the paper's tip-load case ``Fx = 0``).
    ``horizontal``: ``D = (1, 0)``, ``u = Fx``.
    ``direction``: ``D`` = the unit vector ``direction`` (option or config).
    ``normal``: contact force normal to the tip tangent (eq. 21,
    ``Fx sin φ_L + Fy cos φ_L = 0``): ``D = n_tip = (−cos φ_L, sin φ_L)``, so a
    positive ``u`` pushes against the pressure-driven bending (toward ``−x`` for a
    straight tip). ``φ_L`` is the free-motion tip angle at the frame's pressure
    (``tip_angle_source="model"``, the paper) or the reconstructed tip angle
    (``"shape"``).
    ``follower``: the unit tip tangent ``(sin φ_L, cos φ_L)`` rotated counter-clockwise
    (from ``+x`` toward ``+y``) by ``follower_angle_rad``:
    ``D = (sin(φ_L − α), cos(φ_L − α))``; the default ``α = π/2`` is the ``normal``
    direction.
    ``push_only=True`` bounds ``u ≥ 0`` (1-D constraints only).

Solvers
    ``"fast"`` (default): Gauss–Newton on ``u`` with a trust region and projection on
    the bounds, using the analytic shape sensitivities ∂p/∂F of the spectral beam
    solver, vectorised over all frames. Each frame starts from the force that best
    balances the bending moments of the reference shape (``EI (κ − K0) = −M_z``, linear
    in F), and each beam solve starts Newton from the reference shape's tangent angles
    (where the load makes the equilibrium unique; elsewhere load continuation from the
    unloaded arc) or, within the iteration, from the previous state plus its
    first-order change. Along a batch the frames are processed in rounds: round ``r``
    solves frame ``r`` of every block of consecutive frames at once, its start
    corrected by the previous frame's offset from that frame's moment-balance start.
    Converged when the step (or the error left by the observed linear contraction) is
    below ``XTOL_N`` = 1e-10 N. A trial shape that jumps away from its linear
    prediction (onto another branch of equilibria, e.g. past buckling) is rejected.
    Poorly identifiable loads (an axial load on a nearly straight actuator, at low
    pressure): a moment-balance start beyond the convexity bound competes with the
    same start scaled into the convex region (the lower shape distance wins), and a
    frame whose trial steps leave the stable branch ``_MAX_JUMPS`` = 2 times stops
    at its best stable point with ``success=True``, the message ``"not identifiable
    along (x, y): ..."`` and an infinite standard deviation along that direction
    (the fit's optimum lies at the buckling boundary, or the cost is flat there):
    the estimate comes back quickly, flagged, not as a confident number.
    One frame (the real-time path, e.g. ``initial=`` the previous estimate) runs the
    same steps on unbatched arrays with the force parameters as plain floats
    (``_estimate_one``); it agrees with the batched path to round-off (~1e-13 N).
    ``"paper"``: the paper's algorithm as the baseline: the shooting beam solver inside
    ``scipy.optimize.minimize`` with Nelder–Mead (MATLAB's fminsearch) on (Fx, Fy) for
    ``none``, SLSQP (fmincon) with the equality constraint ``D⊥ · F = 0`` (and
    ``D · F ≥ 0`` for ``push_only``) otherwise; a Python loop over frames, started
    from the same moment-balance force so that both search the same basin.

Uncertainty
    Linear propagation of the errors of the shifts S, then a goodness-of-fit check.
    With the weighted residual ``r(u) = W^½ (p(s; u) − p⁰(s))`` and ``J = ∂r/∂u``,
    the optimum moves by ``δu = (JᵀJ)⁻¹ Jᵀ W^½ δp⁰`` when the reconstructed shape
    moves by ``δp⁰ = G δS``, ``G = (∂p⁰/∂κ)(∂κ/∂S)`` through the PCC kinematics
    (analytic) and the differencing of eq. 3–4. So ``Cov(F) = T Σ_S Tᵀ`` with
    ``T = ∂F/∂S`` (including the change of ``D`` with the tip angle for
    ``tip_angle_source="shape"``). ``Σ_S`` (N × N) holds two terms:

    - the signal noise through the calibration's slope (eq. 2),
      ``f_i'(ΔA_i)² noise_std_i²`` on the diagonal (independent channels);
    - the calibration's own model error: the polynomials do not fit the coil
      response exactly, and their misfit is a smooth function of S, so channels
      with similar shifts err together. ``Calibration.shift_error_m(S,
      covariance=True)`` models it from the calibration residuals: RMS envelope
      ``σ_p(|S|)`` per parity, Gaussian correlation in ``S_i − S_j`` with a length
      fitted to the residuals' correlogram, and an odd/even correlation. Absent
      for a calibration without residuals (an exact one) and without a calibration.

    Then the misfit: the residual is pulled back to the shift perturbation that
    explains it best, ``δŜ = −(GᵀWG)⁻¹ GᵀW r`` (the part no PCC shape can show
    drops out), and ``χ² = δŜᵀ C⁺ δŜ`` with ``C`` the covariance that ``Σ_S``
    predicts for ``δŜ`` (rank N − k). ``Cov(F)`` is multiplied by ``χ²/(N − k)``
    where that exceeds 1 (the Birge ratio; ``ForceEstimate.chi2_per_dof``): errors
    beyond the model of ``Σ_S`` that show in the shape (beam or PCC model error,
    a worse calibration) widen σ; an exact model leaves it alone up to the χ²
    fluctuation. Not included, because the shape cannot reveal them: errors of the
    assumed constraint (e.g. ``normal`` with the free-motion tip angle while the
    contact is normal to the loaded tip: a bias ``u Δφ`` across ``D``), of
    ``K0(P)``, ``EI(P)`` and the pressure reading. The residuals of neighbouring
    points are strongly correlated (one noisy coil bends the whole rest of the
    shape), which this accounts for and ``s² (JᵀJ)⁻¹`` would not. A direction in
    which the shape does not depend on the force (an axial load on a straight
    actuator: ``JᵀJ`` singular), or along which the fit stopped at the stability
    boundary (Solvers), gets an infinite standard deviation. Without a
    ``calibration`` the shifts are taken as the signals (unit slope, ``noise_std``
    in metres of shift). When neither noise nor calibration error is known (no
    ``noise_std``, no calibration or one without ``noise_std`` and residuals,
    ``config.estimation.signal_noise_std = 0``) or the shape has no PCC
    curvatures, the fallback treats the residuals as independent per point with
    the variance of the fit (``uncertainty="residual"``), which is optimistic for
    correlated errors.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dsyevd as _dsyevd

from bendsense import beam as _beam
from bendsense.errors import ArgumentError, ConvergenceError

__all__ = [
    "ForceEstimate",
    "estimate_force",
    "constraint_basis",
    "quadrature",
    "CONSTRAINTS",
    "METHODS",
    "XTOL_N",
]

CONSTRAINTS = ("none", "vertical", "horizontal", "direction", "normal", "follower")
METHODS = ("fast", "paper")
#: Gauss–Newton stops when its step is below this [N].
XTOL_N = 1e-10
_OK = "converged"
_MAX_ITER = 100
_MAX_JUMPS = 2  # trial steps off the stable branch before stopping at the boundary
_BOUNDARY_MISFIT = 0.05  # RMS residual / L beyond which a boundary stop is a failure
_BLOCK_FRAMES = 64  # fewest frames per warm-start round worth a vectorised call
_MAX_ROUNDS = 32
_COV_CHUNK = 2048
_N_NODES = _beam.DEFAULT_NODES
_STABLE_BOUND = math.pi**2 / 4  # below it (max |G| L²/EI) the beam's equilibrium is unique


# --------------------------------------------------------------------------- result


@dataclass(frozen=True, eq=False)
class ForceEstimate:
    """Estimated tip force (paper eq. 18), batched over leading axes ``...``.

    Attributes
    ----------
    force_n : ndarray, shape (..., 2)
        Tip force (Fx, Fy) in the base frame [N].
    std_n : ndarray, shape (..., 2)
        Standard deviation of each component [N] from the propagated shift errors
        (signal noise and calibration error, scaled by ``max(1, χ²/dof)``; module
        docstring, Uncertainty); ``inf`` for a component the shape cannot determine.
    covariance_n2 : ndarray, shape (..., 2, 2)
        Covariance of ``force_n`` [N²].
    residual_m : ndarray, shape (...)
        RMS distance between the reconstructed and the model shape over ``[0, Lc]`` [m].
    success : ndarray of bool, shape (...)
        Converged, with a stable beam equilibrium; or stopped at the best stable point
        where the load along one direction is not identifiable (message
        ``"not identifiable along ..."``, ``std_n`` inf along it).
    message : str or ndarray of str, shape (...)
        ``"converged"``, ``"not identifiable along (x, y): ..."`` or the reason for
        ``success=False``.
    iterations : ndarray of int, shape (...)
        Beam solves spent on each frame (objective evaluations for ``paper``).
    wall_time_s : float
        Wall time of the whole call [s].
    method : str
        ``"fast"`` or ``"paper"``.
    constraint : str
        The constraint (see the module docstring).
    uncertainty : str
        ``"propagated"`` (sensor noise through calibration and PCC) or ``"residual"``
        (fallback from the fit residual).
    tip_position_m : ndarray, shape (..., 2)
        Tip of the model shape at the estimate [m].
    state : ndarray, shape (..., n_nodes) or None
        Beam state at the estimate.
    guess_n : ndarray, shape (..., 2) or None
        The moment-balance starting force; with ``force_n`` it corrects the start of
        the next frame (``initial=`` of the next call).
    chi2_per_dof : ndarray, shape (...) or None
        Misfit of the fit against the propagated shift errors, χ²/dof (about 1 when
        the errors are as modelled); ``std_n`` includes the factor ``max(1, χ²/dof)``
        on the variance. NaN for ``uncertainty="residual"`` and failed frames.
    """

    force_n: np.ndarray
    std_n: np.ndarray
    covariance_n2: np.ndarray
    residual_m: np.ndarray
    success: np.ndarray
    message: object
    iterations: np.ndarray
    wall_time_s: float
    method: str
    constraint: str
    uncertainty: str = "propagated"
    tip_position_m: np.ndarray | None = None
    state: np.ndarray | None = field(default=None, repr=False)
    guess_n: np.ndarray | None = field(default=None, repr=False)
    chi2_per_dof: np.ndarray | None = None

    @property
    def batch_shape(self) -> tuple:
        """Shape of the leading frame axes (``()`` for one frame)."""
        return np.shape(self.force_n)[:-1]

    def to_dict(self) -> dict:
        """Plain lists and scalars, for JSON/YAML."""
        return {
            "force_n": np.asarray(self.force_n).tolist(),
            "std_n": np.asarray(self.std_n).tolist(),
            "covariance_n2": np.asarray(self.covariance_n2).tolist(),
            "residual_m": np.asarray(self.residual_m).tolist(),
            "success": np.asarray(self.success).tolist(),
            "message": np.asarray(self.message).tolist(),
            "iterations": np.asarray(self.iterations).tolist(),
            "wall_time_s": float(self.wall_time_s),
            "method": self.method,
            "constraint": self.constraint,
            "uncertainty": self.uncertainty,
            "chi2_per_dof": None if self.chi2_per_dof is None else np.asarray(self.chi2_per_dof).tolist(),
        }

    def plot(self, ax=None, *, shape=None, t_s=None, scale_m_per_n: float = 0.1):
        """Draw the estimate; returns the matplotlib axes.

        One frame: the force as an arrow at the model tip (``scale_m_per_n`` metres per
        newton), over ``shape`` if given. A batch: Fx and Fy against ``t_s`` (default the
        frame index) with ±2σ bands.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        force = np.asarray(self.force_n)
        if force.ndim == 1:
            if shape is not None:
                pos = np.asarray(shape.positions_m).reshape(-1, 2)
                ax.plot(pos[:, 0], pos[:, 1], "-", color="0.4")
            tip = np.zeros(2) if self.tip_position_m is None else np.asarray(self.tip_position_m)
            ax.annotate("", xy=tip + scale_m_per_n * force, xytext=tip,
                        arrowprops={"arrowstyle": "->", "color": "C3"})
            ax.plot([0.0, tip[0], tip[0] + scale_m_per_n * force[0]], [0.0, tip[1], tip[1] + scale_m_per_n * force[1]],
                    alpha=0.0)
            ax.plot([0.0], [0.0], "ks", markersize=4)
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title(f"F = ({force[0]:.3g}, {force[1]:.3g}) N")
            return ax
        force = force.reshape(-1, 2)
        std = np.asarray(self.std_n).reshape(-1, 2)
        t = np.arange(len(force)) if t_s is None else np.asarray(t_s).reshape(-1)
        for i, name in enumerate(("Fx", "Fy")):
            ax.plot(t, force[:, i], label=name, color=f"C{i}")
            band = np.where(np.isfinite(std[:, i]), 2.0 * std[:, i], np.nan)
            ax.fill_between(t, force[:, i] - band, force[:, i] + band, color=f"C{i}", alpha=0.2)
        ax.set_xlabel("t [s]" if t_s is not None else "frame")
        ax.set_ylabel("force [N]")
        ax.legend()
        return ax


# --------------------------------------------------------------------------- pure helpers


def quadrature(lengths_m, length_m: float, n_points: int):
    """Composite Gauss–Legendre nodes and weights over the PCC segments on ``[0, Lc]``.

    Parameters
    ----------
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    length_m : float
        Common length Lc <= Σ l_i over which to integrate [m].
    n_points : int
        Total number of nodes.

    Returns
    -------
    s_m : ndarray, shape (n_points,)
        Nodes, ascending [m].
    weights_m : ndarray, shape (n_points,)
        Weights, summing to Lc [m].
    """
    lengths = np.asarray(lengths_m, dtype=float)
    bounds = np.minimum(np.concatenate(([0.0], np.cumsum(lengths))), length_m)
    seg = np.diff(bounds)
    keep = seg > 1e-12 * length_m
    a, h = bounds[:-1][keep], seg[keep]
    n = int(n_points)
    if n < h.size:
        x, w = np.polynomial.legendre.leggauss(n)
        return 0.5 * length_m * (x + 1.0), 0.5 * length_m * w
    count = np.full(h.size, n // h.size)
    count[np.argsort(-h, kind="stable")[: n % h.size]] += 1
    s, wt = [], []
    for a_i, h_i, q in zip(a, h, count):
        x, w = np.polynomial.legendre.leggauss(int(q))
        s.append(a_i + 0.5 * h_i * (x + 1.0))
        wt.append(0.5 * h_i * w)
    return np.concatenate(s), np.concatenate(wt)


@functools.lru_cache(maxsize=32)
def _pcc_grid(lengths: tuple, length_m: float, n_points: int, beam_length_m: float):
    """Per-grid constants of a PCC reference (cached, read-only).

    The quadrature nodes, weights, segment and local arc length of each node; the nodes
    followed by the beam's nodes clipped to the sensor length, with the PCC kinematics'
    own grid of them; the tip-angle weights (:func:`_tip_angle_weights`) and the arc
    length of each beam node beyond the sensor (where the last curvature is carried on).
    """
    from bendsense import pcc

    lengths = np.asarray(lengths)
    s, w = quadrature(lengths, length_m, n_points)
    bounds = np.concatenate(([0.0], np.cumsum(lengths)))
    seg = np.clip(np.searchsorted(bounds[1:-1], s, side="left"), 0, lengths.size - 1)
    sc = chebyshev_nodes_m(beam_length_m, _N_NODES)
    s_fk = np.concatenate([s, np.minimum(sc, bounds[-1])])
    out = {"s": s, "w": w, "seg": seg, "sigma": s - bounds[seg], "s_fk": s_fk,
           "tip_weights": _tip_angle_weights(lengths, beam_length_m),
           "beyond": np.maximum(sc - float(lengths.sum()), 0.0)}
    for a in out.values():
        a.setflags(write=False)
    out["grid"] = pcc._grid(lengths, s_fk)
    return out


def constraint_basis(constraint: str, tip_angle_rad=0.0, *, direction=(0.0, -1.0), follower_angle_rad=math.pi / 2):
    """The matrix D (..., 2, k) of the linear force parametrisation ``F = D u``.

    Parameters
    ----------
    constraint : str
        One of :data:`CONSTRAINTS` (sign conventions in the module docstring).
    tip_angle_rad : array_like, shape (...)
        Tip tangent angle φ_L for ``normal`` and ``follower`` [rad].
    direction : array_like, shape (2,)
        Unit force direction for ``direction``.
    follower_angle_rad : float
        Counter-clockwise angle α of a follower force from the tip tangent [rad].

    Returns
    -------
    D : ndarray, shape (..., 2, k)
        Orthonormal columns; k = 2 for ``none``, else 1.
    dD : ndarray, shape (..., 2, k) or None
        ∂D/∂φ_L for the tip-angle constraints, else None.
    """
    if type(tip_angle_rad) is float:  # one frame: plain floats
        return _constraint_basis_one(constraint, tip_angle_rad, direction, follower_angle_rad)
    phi = np.asarray(tip_angle_rad, dtype=float)
    if constraint == "none":
        return np.broadcast_to(np.eye(2), (*phi.shape, 2, 2)), None
    if constraint in ("vertical", "horizontal", "direction"):
        d = {"vertical": (0.0, 1.0), "horizontal": (1.0, 0.0)}.get(constraint, direction)
        d = np.asarray(d, dtype=float)
        return np.broadcast_to(d[:, None], (*phi.shape, 2, 1)), None
    if constraint == "normal":
        c, s = np.cos(phi), np.sin(phi)
        return np.stack([-c, s], axis=-1)[..., None], np.stack([s, c], axis=-1)[..., None]
    if constraint == "follower":
        a = phi - float(follower_angle_rad)
        c, s = np.cos(a), np.sin(a)
        return np.stack([s, c], axis=-1)[..., None], np.stack([c, -s], axis=-1)[..., None]
    raise ArgumentError(f"constraint: must be one of {', '.join(CONSTRAINTS)}, got {constraint!r}")


_EYE2 = np.broadcast_to(np.eye(2), (2, 2))
_VERTICAL = np.broadcast_to(np.array([[0.0], [1.0]]), (2, 1))
_HORIZONTAL = np.broadcast_to(np.array([[1.0], [0.0]]), (2, 1))


def _constraint_basis_one(constraint, phi, direction, follower_angle_rad):
    """:func:`constraint_basis` for one tip angle (a float)."""
    if constraint == "none":
        return _EYE2, None
    if constraint == "vertical":
        return _VERTICAL, None
    if constraint == "horizontal":
        return _HORIZONTAL, None
    if constraint == "direction":
        return np.broadcast_to(np.asarray(direction, dtype=float)[:, None], (2, 1)), None
    if constraint == "normal":
        c, s = math.cos(phi), math.sin(phi)
        return np.array([[-c], [s]]), np.array([[s], [c]])
    if constraint == "follower":
        a = phi - float(follower_angle_rad)
        c, s = math.cos(a), math.sin(a)
        return np.array([[s], [c]]), np.array([[c], [-s]])
    raise ArgumentError(f"constraint: must be one of {', '.join(CONSTRAINTS)}, got {constraint!r}")


_MODELS: dict = {}
_LOWER = {(push, k): np.full(k, 0.0 if push else -np.inf) for push in (False, True) for k in (1, 2)}
for _a in _LOWER.values():
    _a.setflags(write=False)


def _config_constants(config):
    """The free-bending model, the distributed load (2,) [N/m] and the strip gap [m] of a config (cached)."""
    entry = _CONSTANTS.get(id(config))
    if entry is None or entry[0] is not config:
        if len(_CONSTANTS) > 16:
            _CONSTANTS.clear()
        wload = np.asarray(config.weight_per_length_n_per_m, dtype=float).copy()
        wload.setflags(write=False)
        entry = (config, (_free_model(config), wload, float(config.sensor.strip_gap_m)))
        _CONSTANTS[id(config)] = entry
    return entry[1]


_CONSTANTS: dict = {}


def _free_model(config):
    from bendsense.actuator import FreeBendingModel

    entry = _MODELS.get(id(config))
    if entry is None or entry[0] is not config:
        if len(_MODELS) > 16:
            _MODELS.clear()
        entry = (config, FreeBendingModel.from_config(config))
        _MODELS[id(config)] = entry
    return entry[1]


# --------------------------------------------------------------------------- the fast core


def _solve_beam(L, ei, k0, F, wload, s_all, M, state, n_nodes, continuation=True):
    """Beam shapes at ``s_all[:M]`` with ∂p/∂F, and ∂φ/∂F at the nodes ``s_all[M:]``.

    ``state`` (b, n) is Newton's start; None starts from the unloaded arc (with load
    continuation where needed). ``continuation=False``: a warm start beyond the
    convexity bound that lands on an unstable equilibrium fails instead of being
    continued from the unloaded arc (trial steps, whose jump test would reject the
    continued shape, a distant point of the branch). Returns positions (b, M, 2),
    ∂p/∂F (b, M, 2, 2), success (b,), state (b, n), tip (b, 2) and ∂φ_nodes/∂F (b, n, 2).
    """
    if F.shape[0] == 1:
        r = _solve_frame(L, float(ei[0]), float(k0[0]), F[0], wload, s_all, M, None if state is None else state[0],
                         n_nodes, _frame_sampling(s_all.tobytes(), L, M, n_nodes), continuation)
        return r[0][None], r[1][None], np.array([r[2]]), r[3][None], r[4][None], r[5][None]
    sol = _beam.solve(L, ei, k0, F, wload, np.zeros(1), s_all, n_nodes=n_nodes, initial=state, sensitivities=True,
                      continuation=continuation)
    return (sol.positions_m[:, :M], sol.dpositions_dforce[:, :M], sol.success, sol.state, sol.tip_position_m,
            sol.dangle_dforce[:, M:])


@functools.lru_cache(maxsize=16)
def _frame_sampling(s_all: bytes, length_m: float, M: int, n_nodes: int):
    """Sampling of one frame's beam solution: positions at the first M points, angles at the rest, the tip."""
    P, PQ, q = _beam._sampling_one(n_nodes, s_all, length_m)
    return _beam._operators(n_nodes), np.ascontiguousarray(PQ[:M]), np.ascontiguousarray(P[M:]), q


def _solve_frame(L, ei, k0, F, wload, s_all, M, state, n_nodes, sampling, continuation=True):
    """:func:`_solve_beam` of one frame, unbatched.

    Returns positions (M, 2), ∂p/∂F (M, 2, 2), success, state (n,), tip (2,) and
    ∂φ_nodes/∂F (n, 2). The solver's one-frame core on plain floats; the batched solver (load continuation)
    where that needs it.
    """
    ops, PQ, Pn, q = sampling
    r = _beam._solve_one(L, ei, k0, 0.0, F, wload, ops, state, True, _beam.NEWTON_TOL, _beam.NEWTON_MAX_ITER, PQ, Pn,
                         q, continuation)
    if r is False:
        # an unstable warm-started equilibrium, not continued: a failed trial
        n = ops.n
        return np.full((M, 2), np.nan), np.full((M, 2, 2), np.nan), False, np.full(n, np.nan), np.full(2, np.nan), \
            np.full((n, 2), np.nan)
    if r is not None:
        return r[2], r[4], True, r[0], r[3], r[5]
    sol = _beam.solve(L, np.array([ei]), np.array([k0]), np.array([F], dtype=float), wload, np.zeros(1), s_all,
                      n_nodes=n_nodes,
                      initial=None if state is None else state[None], sensitivities=True, continuation=continuation)
    return (sol.positions_m[0, :M], sol.dpositions_dforce[0, :M], bool(sol.success[0]), sol.state[0],
            sol.tip_position_m[0], sol.dangle_dforce[0, M:])


def _lm_step(H, g, mu):
    """−(H + μ diag(H) + ε I)⁻¹ g for stacks of 1×1 or 2×2 systems (closed form)."""
    k = g.shape[1]
    tr = H[:, 0, 0] + (H[:, 1, 1] if k == 2 else 0.0)
    eps = 1e-14 * tr + 1e-300
    if k == 1:
        return -g / (H[:, 0, :] * (1.0 + mu[:, None]) + eps[:, None])
    a = H[:, 0, 0] * (1.0 + mu) + eps
    d = H[:, 1, 1] * (1.0 + mu) + eps
    b = H[:, 0, 1]
    det = a * d - b * b
    x0 = (d * g[:, 0] - b * g[:, 1]) / det
    x1 = (a * g[:, 1] - b * g[:, 0]) / det
    return -np.stack([x0, x1], axis=1)


def _apply(D, u):
    """D u for stacks (b, 2, k) and (b, k)."""
    if D.shape[-1] == 1:
        return D[..., 0] * u
    return D[..., 0] * u[:, :1] + D[..., 1] * u[:, 1:]


def _apply_one(D, u):
    """D u for one frame, (2, k) and (k,), with :func:`_apply`'s arithmetic."""
    if D.shape[-1] == 1:
        return D[:, 0] * u[0]
    return D[:, 0] * u[0] + D[:, 1] * u[1]


def _project(D, gF, GF):
    """Reduced gradient Dᵀ g and Hessian Dᵀ G D from their force-space versions."""
    if D.shape[-1] == 1:
        d = D[..., 0]
        g = (d * gF).sum(axis=1)[:, None]
        Gd = np.einsum("bij,bj->bi", GF, d)
        return g, (d * Gd).sum(axis=1)[:, None, None]
    return np.einsum("bij,bi->bj", D, gF), np.einsum("bij,bik,bkl->bjl", D, GF, D)


def _linearise(pos, dpos, p0, w):
    """Cost Σ w ‖p − p⁰‖², force-space gradient Σ w (∂p/∂F)ᵀ (p − p⁰) and Gram matrix."""
    b = pos.shape[0]
    res = (pos - p0).reshape(b, -1)  # (b, 2M)
    wr = res * np.repeat(w, 2)
    A = dpos.reshape(b, -1, 2)  # (b, 2M, 2): ∂p/∂F
    At = np.swapaxes(A, 1, 2)
    cost = np.einsum("bm,bm->b", res, wr)
    gF = (At @ wr[..., None])[..., 0]
    GF = At @ (A * np.repeat(w, 2)[:, None])
    return cost, gF, GF


def _convex_start(L, ei, wload, D, ffix, lower, u):
    """``u`` (b, k) scaled toward the fixed force until the load is provably convex.

    The largest of the factors 1, 0.8, …, 0 at which the beam's convexity measure
    (:func:`bendsense.beam._load_ratio`, Dunkerley) stays below 0.9: a start whose
    equilibrium is unique and stable.
    """
    scale = (L * L / ei)[:, None]
    wn = wload[None, :] * L * scale
    best = np.zeros(u.shape[0])
    for t in (0.2, 0.4, 0.6, 0.8, 1.0):
        ut = np.maximum(u * t, lower)
        inside = _beam._load_ratio((ffix + _apply(D, ut)) * scale, wn) < 0.9
        best = np.where(inside, t, best)
    return np.maximum(u * best[:, None], lower)


def _unique(L, ei, F, wload):
    """Frames (b,) whose load provably has a unique, stable equilibrium.

    The beam solver's convexity measure (:func:`bendsense.beam._load_ratio`: the
    largest |G| or Dunkerley's combination of tip and distributed load) below 1: where
    the solver accepts any converged Newton start as the equilibrium. Gravity alone on
    the upright, nearly straight actuator at low pressure is inside it.
    """
    scale = (L * L / ei)[:, None]
    return _beam._load_ratio(F * scale, wload[None, :] * L * scale) < 1.0


def _gauss_newton(L, ei, k0, wload, s_all, w, p0, D, ffix, lower, u, state, *, xtol, max_iter, n_nodes,
                  cold=None):
    """Batched projected Gauss–Newton with a trust region on u for frames (B,).

    ``s_all`` holds the M comparison points and then the beam's n nodes, ``w`` the
    quadrature weights (M,), ``p0`` (B, M, 2) the reference shape, ``D`` (B, 2, k),
    ``ffix`` (B, 2), ``lower`` (k,), ``u`` (B, k) the start, ``state`` (B, n) the
    beam's Newton start. ``cold``: ``(have (B,), solution)`` with the beam solution
    from the unloaded arc (:func:`_solve_beam` with ``state=None``) at this start for the
    frames ``have``, solved beforehand (:func:`_fast`).
    Returns a dict of arrays; ``status`` 1 converged, 2 beam fails, 3 no convergence,
    4 stopped at the stability boundary (``blocked`` (B, k): the last step that left
    the stable branch).
    """
    B, k = u.shape
    u = np.maximum(u, lower)
    status = np.zeros(B, dtype=int)
    iters = np.ones(B, dtype=int)
    M = w.size
    F = ffix + _apply(D, u)
    # Newton from the reference shape is safe only where the equilibrium is unique;
    # elsewhere a compressive start could land on a buckled branch, and the solver's
    # load continuation from the unloaded arc finds the branch connected to it
    unique = _unique(L, ei, F, wload)
    if unique.all():
        pos, dpos, ok, st, tip, dst = _solve_beam(L, ei, k0, F, wload, s_all, M, state, n_nodes)
    else:
        pos = np.empty((B, M, 2))
        dpos = np.empty((B, M, 2, 2))
        ok = np.empty(B, dtype=bool)
        st = np.empty((B, state.shape[1]))
        tip = np.empty((B, 2))
        dst = np.empty((B, state.shape[1], 2))
        i = np.flatnonzero(unique)
        if i.size:
            pos[i], dpos[i], ok[i], st[i], tip[i], dst[i] = _solve_beam(L, ei[i], k0[i], F[i], wload, s_all, M,
                                                                        state[i], n_nodes)
        i = np.flatnonzero(~unique)
        if cold is not None:
            have, sol = cold
            j = i[have[i]]
            pos[j], dpos[j], ok[j], st[j], tip[j], dst[j] = (a[j] for a in sol)
            i = i[~have[i]]
        if i.size:
            pos[i], dpos[i], ok[i], st[i], tip[i], dst[i] = _solve_beam(L, ei[i], k0[i], F[i], wload, s_all, M, None,
                                                                        n_nodes)
    # the competing convex start below (a start beyond 0.9 of the bound on max |G|)
    scale = L * L / ei
    gmax = np.maximum(np.hypot(F[:, 0], F[:, 1]), np.hypot(F[:, 0] + wload[0] * L, F[:, 1] + wload[1] * L))
    convex = gmax * scale < 0.9 * _STABLE_BOUND
    bad = np.flatnonzero(~ok)
    if bad.size:
        # the start may buckle the beam or lead Newton astray: start over from the
        # unloaded arc by load continuation at the constraint's zero force
        u[bad] = np.maximum(0.0, lower)
        F[bad] = ffix[bad] + _apply(D[bad], u[bad])
        r = _solve_beam(L, ei[bad], k0[bad], F[bad], wload, s_all, M, None, n_nodes)
        pos[bad], dpos[bad], ok[bad], st[bad], tip[bad], dst[bad] = r
        iters[bad] += 1
    far = np.flatnonzero(~convex & ok)
    if far.size:
        # a start beyond the convexity bound can sit on a far, strongly bent part of the
        # branch when the shape hardly shows the axial load (a nearly straight
        # actuator); the start scaled back into the convex region competes with it
        uc = _convex_start(L, ei[far], wload, D[far], ffix[far], lower, u[far])
        moved = np.any(uc != u[far], axis=1)
        far, uc = far[moved], uc[moved]
    if far.size:
        r = _solve_beam(L, ei[far], k0[far], ffix[far] + _apply(D[far], uc), wload, s_all, M, state[far], n_nodes)
        iters[far] += 1
        better = r[2] & (_linearise(r[0], r[1], p0[far], w)[0] < _linearise(pos[far], dpos[far], p0[far], w)[0])
        bi = far[better]
        u[bi] = uc[better]
        pos[bi], dpos[bi], st[bi], tip[bi], dst[bi] = (a[better] for a in (r[0], r[1], r[3], r[4], r[5]))
    status[~ok] = 2
    cost, gF, GF = _linearise(pos, dpos, p0, w)
    g, H = _project(D, gF, GF)
    # trust region on the Gauss–Newton step, in units of the natural force scale EI/L²
    # (far from the optimum the linearisation overshoots by newtons)
    radius = 0.5 * ei / (L * L)
    last = np.full(B, np.inf)
    jumps = np.zeros(B, dtype=int)
    blocked = np.zeros((B, k))
    act = np.flatnonzero(status == 0)
    for _ in range(max_iter):
        if act.size == 0:
            break
        step = _lm_step(H[act], g[act], np.zeros(act.size))
        unew = np.maximum(u[act] + step, lower)
        dstep = unew - u[act]
        size = np.abs(dstep).max(axis=1)
        # converged: the step, or the error left by a contraction at the observed rate,
        # is below xtol; or stalled at the round-off floor of the beam solutions
        prev = last[act]
        seen = np.isfinite(prev)
        rate = size / np.where(seen, prev, 1.0)
        left = np.where(seen & (rate < 0.5), size * rate / (1.0 - rate), size)
        done = (left <= xtol) | (seen & (size <= 1e3 * xtol) & (rate > 0.5))
        last[act] = size
        if done.any():
            di = act[done]
            u[di] = unew[done]
            status[di] = 1
        go = ~done
        idx = act[go]
        if idx.size == 0:
            break
        dstep = dstep[go]
        norm = np.sqrt(np.einsum("bk,bk->b", dstep, dstep))
        shrink = np.minimum(1.0, radius[idx] / norm)
        dstep *= shrink[:, None]
        norm *= shrink
        un = np.maximum(u[idx] + dstep, lower)
        dstep = un - u[idx]
        predicted = -(2.0 * np.einsum("bk,bk->b", g[idx], dstep) + np.einsum("bk,bkl,bl->b", dstep, H[idx], dstep))
        dF = _apply(D[idx], dstep)
        Fn = ffix[idx] + _apply(D[idx], un)
        # first-order prediction of the new beam state: Newton then needs one iteration
        # for small steps
        guess = st[idx] + dst[idx, :, 0] * dF[:, :1] + dst[idx, :, 1] * dF[:, 1:]
        pn, dpn, okn, stn, tipn, dstn = _solve_beam(L, ei[idx], k0[idx], Fn, wload, s_all, M, guess, n_nodes,
                                                    continuation=False)
        iters[idx] += 1
        # a shape far from its linear prediction has jumped to another branch of
        # equilibria (e.g. past buckling onto the buckled one): not a valid trial
        lin = dpos[idx, :, :, 0] * dF[:, None, :1] + dpos[idx, :, :, 1] * dF[:, None, 1:]
        jump = np.abs(pn - pos[idx] - lin).max(axis=(1, 2))
        okn = okn & (jump <= 0.5 * np.abs(lin).max(axis=(1, 2)) + 1e-6 * L)
        cn, gFn, GFn = _linearise(pn, dpn, p0[idx], w)
        rho = (cost[idx] - cn) / np.where(predicted > 0, predicted, np.inf)
        # below ~1e-6 N the cost change is lost in the beam solutions' round-off: the
        # Gauss–Newton step is trusted as it is
        acc = okn & ((rho > 1e-4) | (norm < 1e-6))
        ai = idx[acc]
        u[ai], pos[ai], dpos[ai], st[ai], tip[ai], dst[ai] = un[acc], pn[acc], dpn[acc], stn[acc], tipn[acc], dstn[acc]
        cost[ai], gF[ai], GF[ai] = cn[acc], gFn[acc], GFn[acc]
        g[ai], H[ai] = _project(D[ai], gF[ai], GF[ai])
        grow = acc & (rho > 0.75) & (shrink < 1.0)
        radius[idx[grow]] = 4.0 * radius[idx[grow]]
        cut = ~acc | (rho < 0.25)
        radius[idx[cut]] = 0.25 * norm[cut]
        last[idx[~acc]] = np.inf
        dead = idx[radius[idx] < 1e-12]
        status[dead] = 3
        # trials that leave the stable branch again and again: the optimum lies at the
        # stability boundary (buckling), where the shape no longer tells the load along
        # the blocked step; stop at the best stable point (status 4)
        ji = idx[~okn]
        jumps[ji] += 1
        blocked[ji] = dstep[~okn]
        status[ji[(jumps[ji] >= _MAX_JUMPS) & (status[ji] == 0)]] = 4
        act = np.flatnonzero(status == 0)
    status[status == 0] = 3
    F = ffix + _apply(D, u)
    return {"u": u, "force": F, "status": status, "iterations": iters, "positions": pos, "dpos": dpos,
            "state": st, "tip": tip, "cost": cost, "blocked": blocked}


def _lm_step_one(H, g):
    """:func:`_lm_step` (μ = 0) of one frame on plain floats: H, g nested lists; a list (k,)."""
    if len(g) == 1:
        h = H[0][0]
        return [-g[0] / (h + (1e-14 * h + 1e-300))]
    h00, h01, h11 = H[0][0], H[0][1], H[1][1]
    eps = 1e-14 * (h00 + h11) + 1e-300
    a, d = h00 + eps, h11 + eps
    g0, g1 = g
    det = a * d - h01 * h01
    return [-((d * g0 - h01 * g1) / det), -((a * g1 - h01 * g0) / det)]


def _convex_start_one(L, ei, wload, apply, ffix, lower, u):
    """:func:`_convex_start` of one frame on plain floats (``apply(v)`` = D v; u, lower lists)."""
    scale = L * L / ei
    wx, wy = float(wload[0]) * L * scale, float(wload[1]) * L * scale
    best = 0.0
    for t in (0.2, 0.4, 0.6, 0.8, 1.0):
        fx, fy = apply([max(a * t, b) for a, b in zip(u, lower)])
        if _beam._load_ratio_one((ffix[0] + fx) * scale, (ffix[1] + fy) * scale, wx, wy) < 0.9:
            best = t
    return [max(a * best, b) for a, b in zip(u, lower)]


@functools.lru_cache(maxsize=16)
def _repeat2(w: bytes) -> np.ndarray:
    """The weights of the points repeated for their x and y coordinates (cached)."""
    out = np.repeat(np.frombuffer(w), 2)
    out.setflags(write=False)
    return out


def _gauss_newton_one(L, ei, k0, wload, s_all, w, p0, D, ffix, lower, u, state, *, xtol, max_iter, n_nodes):
    """:func:`_gauss_newton` for one frame, unbatched and with plain floats: the real-time path.

    ``ei``, ``k0`` floats, ``p0`` (M, 2), ``D`` (2, k), ``ffix`` (2,), ``u`` (k,),
    ``state`` (n,). Same algorithm and stopping rules; a batch of one spends most of its
    time in numpy call overhead, which this avoids: the k ≤ 2 force parameters, their
    gradient and Gauss–Newton matrix are Python floats. Returns the dict of
    :func:`_gauss_newton` for the one frame (no batch axis).
    """
    M = w.size
    k = D.shape[1]
    (d00, *d01), (d10, *d11) = D.tolist()
    d01, d11 = (d01 or [0.0])[0], (d11 or [0.0])[0]
    ff0, ff1 = float(ffix[0]), float(ffix[1])
    lo = lower.tolist()
    u = [max(a, b) for a, b in zip(u.tolist(), lo)]
    ei = float(ei)
    k0 = float(k0)
    w2 = _repeat2(w.tobytes())
    ref = p0.reshape(-1)
    sampling = _frame_sampling(s_all.tobytes(), L, M, n_nodes)

    def apply(v):  # D v
        if k == 1:
            return d00 * v[0], d10 * v[0]
        return d00 * v[0] + d01 * v[1], d10 * v[0] + d11 * v[1]

    def force(v):
        fx, fy = apply(v)
        return ff0 + fx, ff1 + fy

    def solve(v, start_, continuation=True):
        return _solve_frame(L, ei, k0, force(v), wload, s_all, M, start_, n_nodes, sampling, continuation)

    F = force(u)
    scale = L * L / ei
    wx, wy = float(wload[0]) * L, float(wload[1]) * L
    unique = _beam._load_ratio_one(F[0] * scale, F[1] * scale, wx * scale, wy * scale) < 1.0  # see _unique
    convex = max(math.hypot(F[0], F[1]), math.hypot(F[0] + wx, F[1] + wy)) * scale < 0.9 * _STABLE_BOUND
    iters = 1
    pos, dpos, ok, st, tip, dst = solve(u, state if unique else None)
    if not ok:
        u = [max(0.0, b) for b in lo]
        pos, dpos, ok, st, tip, dst = solve(u, None)
        iters += 1

    def lin(pos_, dpos_):
        # one Gram matrix of [∂p/∂u, p − p⁰] gives the cost, gradient and Gauss–Newton matrix
        Ar = np.empty((2 * M, k + 1))
        np.matmul(dpos_.reshape(-1, 2), D, out=Ar[:, :k])  # ∂p/∂u
        np.subtract(pos_.reshape(-1), ref, out=Ar[:, k])
        gram = (Ar.T @ (Ar * w2[:, None])).tolist()
        return gram[k][k], gram[k][:k], [row[:k] for row in gram[:k]], Ar[:, :k]

    def out(status, u_):
        return {"u": np.array(u_), "force": np.array(force(u_)), "status": status, "iterations": iters,
                "positions": pos, "dpos": dpos, "state": st, "tip": tip, "cost": cost, "blocked": np.array(blocked)}

    cost = np.nan
    blocked = [0.0] * k
    if not ok:
        return out(2, u)
    cost, g, H, A = lin(pos, dpos)
    if not convex:
        # the competing start inside the convex region (see _gauss_newton)
        uc = _convex_start_one(L, ei, wload, apply, (ff0, ff1), lo, u)
        if uc != u:
            r = solve(uc, state)
            iters += 1
            if r[2]:
                trial = lin(r[0], r[1])
                if trial[0] < cost:
                    u, (pos, dpos, _, st, tip, dst) = uc, r
                    cost, g, H, A = trial
    radius = 0.5 * ei / (L * L)
    last = math.inf
    jumps = 0
    for _ in range(max_iter):
        step = _lm_step_one(H, g)
        unew = [max(a + b, c) for a, b, c in zip(u, step, lo)]
        dstep = [a - b for a, b in zip(unew, u)]
        size = max(abs(a) for a in dstep)
        rate = size / last if last < math.inf else math.nan
        left = size * rate / (1.0 - rate) if rate < 0.5 else size
        if left <= xtol or (rate > 0.5 and size <= 1e3 * xtol):
            return out(1, unew)
        last = size
        norm = math.sqrt(sum(a * a for a in dstep))
        shrink = min(1.0, radius / norm)
        un = [max(a + b * shrink, c) for a, b, c in zip(u, dstep, lo)]
        dstep = [a - b for a, b in zip(un, u)]
        norm *= shrink
        Hd = [sum(a * b for a, b in zip(dstep, col)) for col in zip(*H)]  # dstepᵀ H
        predicted = -(2.0 * sum(a * b for a, b in zip(g, dstep)) + sum(a * b for a, b in zip(Hd, dstep)))
        dF = apply(dstep)
        guess = st + dst @ dF
        pn, dpn, okn, stn, tipn, dstn = solve(un, guess, False)
        iters += 1
        linear = A @ dstep
        if okn:
            jump = pn.reshape(-1) - pos.reshape(-1)
            jump -= linear
            good = float(_amax(np.abs(jump, out=jump))) <= 0.5 * float(_amax(np.abs(linear))) + 1e-6 * L
        else:
            good = False
        if not good:
            jumps += 1
            blocked = dstep
            if jumps >= _MAX_JUMPS:
                return out(4, u)
        if good:
            cn, gn, Hn, An = lin(pn, dpn)
            rho = (cost - cn) / predicted if predicted > 0 else -math.inf
            good = rho > 1e-4 or norm < 1e-6
        if good:
            u, pos, dpos, st, tip, dst = un, pn, dpn, stn, tipn, dstn
            cost, g, H, A = cn, gn, Hn, An
            if rho > 0.75 and shrink < 1.0:
                radius *= 4.0
            elif rho < 0.25:
                radius = 0.25 * norm
        else:
            radius = 0.25 * norm
            last = math.inf
        if radius < 1e-12:
            return out(3, u)
    return out(3, u)


def _fast(prob, u0, state0, *, chain, xtol, max_iter, n_nodes):
    """Run the Gauss–Newton core over the batch in warm-started rounds (module docstring)."""
    B = prob["B"]

    L, wload = prob["L"], prob["wload"]

    def run(idx, u, st, cold=None):
        if B == 1:
            r = _gauss_newton_one(L, prob["ei"][0], prob["k0"][0], wload, prob["s_all"], prob["w"],
                                  prob["p0"][0], prob["D"][0], prob["ffix"][0], prob["lower"], u[0], st[0],
                                  xtol=xtol, max_iter=max_iter, n_nodes=n_nodes)
            return {key: np.asarray(val)[None] for key, val in r.items()}
        return _gauss_newton(L, prob["ei"][idx], prob["k0"][idx], wload, prob["s_all"], prob["w"],
                             prob["p0"][idx], prob["D"][idx], prob["ffix"][idx], prob["lower"], u, st,
                             xtol=xtol, max_iter=max_iter, n_nodes=n_nodes, cold=cold)

    rounds = min(B, _MAX_ROUNDS) if chain else 1
    if rounds <= 1:
        return run(slice(None), u0.copy(), state0)
    # Frames whose start is beyond the convexity bound begin with load continuation
    # from the unloaded arc. Most of them (low pressure, no preceding converged frame)
    # start at their moment-balance guess u0, known now: their continuations run here
    # in one batch instead of a few frames per round; a frame whose start the rounds
    # correct is solved in its round.
    F0 = prob["ffix"] + _apply(prob["D"], u0)
    far = np.flatnonzero(~_unique(L, prob["ei"], F0, wload))
    cold = None
    if far.size > 1:
        sol = _solve_beam(L, prob["ei"][far], prob["k0"][far], F0[far], wload, prob["s_all"], prob["M"], None,
                          n_nodes)
        where = np.full(B, -1)
        where[far] = np.arange(far.size)
        cold = (where, sol)
    out = None
    prev = None
    for r in range(rounds):
        idx = np.arange(r, B, rounds)  # frame r of every block of `rounds` consecutive frames
        u = u0[idx].copy()
        st = None if state0 is None else state0[idx].copy()
        if prev is not None:
            # frame idx − 1 was solved in the previous round, at the same position; its
            # offset from its own moment-balance guess (the PCC and model error) changes
            # slowly along a time series, so it corrects this frame's guess
            p_idx, p_u, p_ok = (a[: idx.size] for a in prev)
            u[p_ok] = np.maximum(u[p_ok] + p_u[p_ok] - u0[p_idx[p_ok]], prob["lower"])
        known = None
        if cold is not None:
            j = cold[0][idx]
            have = (j >= 0) & np.all(u == u0[idx], axis=1)
            if have.any():
                known = (have, tuple(a[np.maximum(j, 0)] for a in cold[1]))
        res = run(idx, u, st, known)
        if out is None:
            out = {key: np.empty((B, *val.shape[1:]), dtype=val.dtype) for key, val in res.items()}
        for key, val in res.items():
            out[key][idx] = val
        prev = (idx, res["u"], res["status"] == 1)
    return out


@functools.lru_cache(maxsize=16)
def chebyshev_nodes_m(length_m: float, n_nodes: int = _N_NODES) -> np.ndarray:
    """Arc lengths of the fast beam solver's Chebyshev–Lobatto nodes, base first [m]."""
    j = np.arange(n_nodes)
    s = 0.5 * length_m * (1.0 - np.cos(np.pi * j / (n_nodes - 1)))
    s.setflags(write=False)
    return s


@functools.lru_cache(maxsize=16)
def _joined(s: bytes, length_m: float, n_nodes: int) -> np.ndarray:
    out = np.concatenate([np.frombuffer(s), chebyshev_nodes_m(length_m, n_nodes)])
    out.setflags(write=False)
    return out


def _shape_state(ref, L, n_nodes):
    """The reference shape's tangent angle at the beam's nodes: the beam's Newton start.

    At the optimum the model shape is the reference shape up to the residual, so this
    start is close for every force near the estimate, where the unloaded arc is not
    (and would need load continuation).
    """
    sc = chebyshev_nodes_m(L, n_nodes)
    if ref["kappa"] is not None:
        return ref["phi_nodes"] + ref["kappa"][..., -1:] * ref["beyond"]
    s, phi = ref["s"], ref["phi"]
    # linear interpolation, and the end slope beyond the last point
    j = np.clip(np.searchsorted(s, sc) - 1, 0, s.size - 2)
    t = (sc - s[j]) / (s[j + 1] - s[j])
    out = phi[..., j] * (1.0 - t) + phi[..., j + 1] * t
    out[..., 0] = 0.0
    return out


def _moment_guess(prob, phi, kappa_s):
    """Starting force from the moment balance ``EI (κ(s) − K0) = −M_z(s)`` (linear in F).

    With the reference shape's curvature and points, the moment of the tip force about
    ``r(s)``, ``(r_L − r(s)) × F``, and of the distributed load are known, so the force
    that best balances the bending moments along the shape is a small weighted linear
    least-squares problem. It is exact for a beam-model shape and close for a PCC one:
    a start near the right basin of the (non-convex) shape distance.
    """
    p0, s, w, L = prob["p0"], prob["s"], prob["w"], prob["L"]
    B = prob["B"]
    phi_end = phi[:, -1]
    tip = p0[:, -1] + (L - s[-1]) * np.stack([np.sin(phi_end), np.cos(phi_end)], axis=-1)
    r_ext = np.concatenate([p0, tip[:, None]], axis=1)
    s_ext = np.concatenate([s, [L]])
    seg = 0.5 * (r_ext[:, 1:] + r_ext[:, :-1]) * np.diff(s_ext)[None, :, None]
    tail = np.cumsum(seg[:, ::-1], axis=1)[:, ::-1]  # ∫_{s_j}^{L} r dσ
    arm_w = tail - (L - s)[None, :, None] * p0
    wl = prob["wload"]
    m_w = arm_w[..., 0] * wl[1] - arm_w[..., 1] * wl[0]
    delta = tip[:, None] - p0
    a = np.stack([-delta[..., 1], delta[..., 0]], axis=-1)  # M_F = a · F
    c = prob["ei"][:, None] * (kappa_s - prob["k0"][:, None]) + m_w + np.einsum("bmi,bi->bm", a, prob["ffix"])
    aD = np.einsum("bmi,bik->bmk", a, prob["D"])
    H = np.einsum("bmk,m,bml->bkl", aD, w, aD)
    g = np.einsum("bmk,m,bm->bk", aD, w, c)
    # a ridge keeps directions the moment balance hardly sees (an axial load on a nearly
    # straight shape) near zero instead of at an arbitrary, possibly buckling, value
    tr = np.trace(H, axis1=1, axis2=2)
    H = H + (1e-6 * tr / H.shape[-1])[:, None, None] * np.eye(H.shape[-1])
    u = _lm_step(H, g, np.zeros(B))
    # the guess only has to land in the right basin; beyond ~3 EI/L² it is not trusted
    cap = 3.0 * prob["ei"] / (L * L)
    norm = np.sqrt(np.einsum("bk,bk->b", u, u))
    u *= np.minimum(1.0, cap / np.maximum(norm, 1e-300))[:, None]
    u = np.where(np.isfinite(u), u, 0.0)
    return np.maximum(u, prob["lower"])


@functools.lru_cache(maxsize=16)
def _moment_geometry(s: bytes, length_m: float):
    """Half the intervals of the points extended to L, and L − s (cached, read-only)."""
    s = np.frombuffer(s)
    half_ds = 0.5 * np.diff(np.concatenate([s, [length_m]]))
    tail_len = (length_m - s)[:, None]
    half_ds = half_ds[:, None]
    for a in (half_ds, tail_len):
        a.setflags(write=False)
    return half_ds, tail_len


_amax = np.maximum.reduce  # without ndarray.max's Python-level wrapper

_ROT = np.array([[0.0, 1.0], [-1.0, 0.0]])  # a = δ @ _ROT = (−δ_y, δ_x): the moment arm of a force


def _moment_guess_one(p0, s, w, L, ei, k0, wload, D, lower, phi_end, kappa_s):
    """:func:`_moment_guess` of one frame (zero fixed force): ``p0`` (M, 2), ``D`` (2, k); u (k,)."""
    M = s.size
    half_ds, tail_len = _moment_geometry(s.tobytes(), L)
    tip = p0[-1] + (L - float(s[-1])) * np.array([math.sin(phi_end), math.cos(phi_end)])
    r_ext = np.empty((M + 1, 2))
    r_ext[:M] = p0
    r_ext[M] = tip
    seg = r_ext[1:] + r_ext[:-1]
    seg *= half_ds
    tail = np.add.accumulate(seg[::-1], axis=0)[::-1]  # ∫_{s_j}^{L} r dσ
    tail -= tail_len * p0  # the lever arms of the distributed load
    c = tail @ np.array([float(wload[1]), -float(wload[0])])  # its moment
    c += ei * (kappa_s - k0)
    aD = (tip - p0) @ (_ROT @ D)  # M_F = a · F = a · D u
    waD = aD * w[:, None]
    H = (aD.T @ waD).tolist()
    k = len(H)
    # the ridge of _moment_guess
    ridge = 1e-6 * sum(H[i][i] for i in range(k)) / k
    for i in range(k):
        H[i][i] += ridge
    u = _lm_step_one(H, (waD.T @ c).tolist())
    norm = math.sqrt(sum(a * a for a in u))
    if math.isfinite(norm):
        f = min(1.0, 3.0 * ei / (L * L) / max(norm, 1e-300))
        u = [a * f if math.isfinite(a * f) else 0.0 for a in u]
    else:  # as _moment_guess: a NaN or infinite step is no guess
        u = [0.0] * k
    return np.maximum(u, lower)


# --------------------------------------------------------------------------- the paper's method


def _tip_angle_weights(lengths, length_m):
    """Weights c with φ(L) = c · κ: the tip angle of the actuator from the segment curvatures.

    The sensor (length L_N) may end short of the actuator tip L, where the contact
    acts; the last segment's curvature is carried on to the tip.
    """
    c = np.array(lengths, dtype=float)
    c[-1] += max(length_m - c.sum(), 0.0)
    return c


def _tip_angle_shift_gradient(lengths, length_m, strip_gap_m):
    """∂φ(L)/∂S (N,) through κ_i = (S_i − S_(i−1)) / (d l_i) (paper eq. 3–4)."""
    c = _tip_angle_weights(lengths, length_m) / (np.asarray(lengths, dtype=float) * strip_gap_m)
    return c - np.append(c[1:], 0.0)


_PAPER_ODE_TOL = 1e-9
_PAPER_BOUND_N = 5.0  # far beyond what bends (or buckles) a soft actuator of this size


def _paper(prob, u0):
    """Shooting beam solver inside Nelder–Mead (free) or SLSQP (constrained), frame by frame."""
    from scipy.optimize import minimize

    B, k = prob["B"], prob["k"]
    L, s, wq, wload = prob["L"], prob["s"], prob["w"], prob["wload"]
    scale = 1.0 / (prob["Lc"] * 1e-6)  # objective in mm² (mean squared distance)
    u_out = np.empty((B, k))
    status = np.ones(B, dtype=int)
    nfev = np.zeros(B, dtype=int)
    for b in range(B):
        p0, ffix, D = prob["p0"][b], prob["ffix"][b], prob["D"][b]
        ei, k0 = float(prob["ei"][b]), float(prob["k0"][b])

        def objective(F, p0=p0, ei=ei, k0=k0):
            # the shooting solver at tolerances like MATLAB's ode45 would be used with,
            # tight enough for 1e-9 m shapes; its 1e-12 default is for the beam tests
            sol = _beam.solve_beam(L, ei, k0, F, wload, 0.0, s, method="shooting", warn=False,
                                   rtol=_PAPER_ODE_TOL, atol=_PAPER_ODE_TOL)
            if not sol.success:
                return 1e12
            d = sol.positions_m - p0
            return float(scale * (wq @ np.einsum("mi,mi->m", d, d)))

        x0 = ffix + D @ u0[b]
        if k == 2:
            res = minimize(objective, x0, method="Nelder-Mead",
                           options={"xatol": 1e-8, "fatol": 1e-16, "maxiter": 4000, "maxfev": 4000,
                                    "initial_simplex": x0 + np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]])})
            u_out[b] = D.T @ (res.x - ffix)
        else:
            d = D[:, 0]
            perp = np.array([-d[1], d[0]])
            cons = [{"type": "eq", "fun": lambda F, perp=perp, ffix=ffix: perp @ (F - ffix),
                     "jac": lambda F, perp=perp: perp}]
            if np.isfinite(prob["lower"][0]):
                cons.append({"type": "ineq", "fun": lambda F, d=d, ffix=ffix: d @ (F - ffix),
                             "jac": lambda F, d=d: d})
            # box bounds as fmincon would be given them: without them SLSQP's first line
            # search tries loads of hundreds of newtons, where every shooting solve fails slowly
            res = minimize(objective, x0, method="SLSQP", constraints=cons,
                           bounds=[(-_PAPER_BOUND_N, _PAPER_BOUND_N)] * 2, options={"ftol": 1e-14, "maxiter": 500})
            u_out[b] = [max(d @ (res.x - ffix), prob["lower"][0])]
        nfev[b] = res.nfev
        if not res.success and objective(ffix + D @ u_out[b]) >= 1e12:
            status[b] = 3
        elif not res.success and k == 2:
            status[b] = 3
    return u_out, status, nfev


# --------------------------------------------------------------------------- uncertainty


def _dsinc(v):
    small = np.abs(v) < 1e-2
    safe = np.where(small, 1.0, v)
    direct = (np.cos(safe) - np.sin(safe) / safe) / safe
    v2 = v * v
    return np.where(small, v * (-1.0 / 3.0 + v2 * (1.0 / 30.0 - v2 / 840.0)), direct)


def _sinc(v):
    return np.sinc(v / np.pi)


def _arc_dkappa(kappa, sigma, phi0):
    """∂/∂κ of the chord σ sinc(κσ/2) (sin(φ0 + κσ/2), cos(φ0 + κσ/2)) (paper eq. 5–6)."""
    half = 0.5 * kappa * sigma
    c = sigma * _sinc(half)
    dc = 0.5 * sigma * sigma * _dsinc(half)
    m = phi0 + half
    sm, cm = np.sin(m), np.cos(m)
    return np.stack([dc * sm + 0.5 * sigma * c * cm, dc * cm - 0.5 * sigma * c * sm], axis=-1)


def _shape_sensitivity(kappa, lengths, d, seg_onehot, sigma, seg, pos, e):
    """Σ_j (w_j ∂p_j/∂F)ᵀ ∂p⁰_j/∂S without forming ∂p⁰/∂S: (b, 2, N).

    ``e`` (b, M, 2, 2) holds w_j ∂p_j/∂F. Raising κ_i bends segment i further and rotates
    everything beyond it about its end ``P_i`` (φ grows: a vector v turns by
    R'v = (v_y, −v_x)), so ``∂p_j/∂κ_i = ∂c_i/∂κ_i + l_i R'(p_j − P_i)`` for points
    beyond segment i (``c_i`` its chord) and the in-segment chord derivative for points
    inside it (paper eq. 5–7); suffix sums over the segments contract this with ``e`` in
    O(M + N). Then ``κ_i = (S_i − S_{i−1}) / (d l_i)`` (paper eq. 3–4).
    """
    theta = kappa * lengths
    phi_end = np.cumsum(theta, axis=-1)
    phi_start = phi_end - theta
    half = 0.5 * theta
    chord_len = lengths * _sinc(half)
    mid = phi_start + half
    ends_x = np.cumsum(chord_len * np.sin(mid), axis=-1)
    ends_y = np.cumsum(chord_len * np.cos(mid), axis=-1)
    dchord = _arc_dkappa(kappa, lengths, phi_start)  # (b, N, 2)
    dq = _arc_dkappa(kappa[:, seg], sigma, phi_start[:, seg])  # (b, M, 2)
    rp = np.stack([pos[..., 1], -pos[..., 0]], axis=-1)[..., None]  # R'(p_j): (b, M, 2, 1)
    s_seg = np.tensordot(e, seg_onehot, axes=([1], [0]))  # Σ_{j in q} e_j: (b, 2, 2, N)
    r_seg = np.tensordot((e * rp).sum(axis=2), seg_onehot, axes=([1], [0]))  # (b, 2, N)
    own = np.tensordot((e * dq[..., None]).sum(axis=2), seg_onehot, axes=([1], [0]))  # (b, 2, N)

    def after(x):  # Σ over segments q > i
        c = np.cumsum(x[..., ::-1], axis=-1)[..., ::-1]
        out = np.zeros_like(x)
        out[..., :-1] = c[..., 1:]
        return out

    s_suf = after(s_seg)  # (b, i, k, N)
    r_suf = after(r_seg)
    hk = (dchord[:, None, :, 0] * s_suf[:, 0] + dchord[:, None, :, 1] * s_suf[:, 1]
          + lengths * (r_suf - ends_y[:, None, :] * s_suf[:, 0] + ends_x[:, None, :] * s_suf[:, 1]) + own)
    hk = hk / (d * lengths)
    hs = hk.copy()
    hs[..., :-1] -= hk[..., 1:]
    return hs


def _inverse_cov(H):
    """Pseudo-inverse of JᵀJ (b, k, k) and the eigen-directions it cannot resolve."""
    lam, V = np.linalg.eigh(H)
    top = lam[:, -1:]
    singular = lam <= 1e-12 * np.maximum(top, 0.0) + 1e-300
    inv = np.where(singular, 0.0, 1.0 / np.where(singular, 1.0, lam))
    return np.einsum("bik,bk,bjk->bij", V, inv, V), singular, V


def _shape_jacobian(kappa, lengths, d, seg, sigma, pos):
    """∂p⁰_j/∂S_i (b, M, 2, N) of the PCC shape at the comparison points (paper eq. 3–7).

    The explicit matrix that :func:`_shape_sensitivity` contracts: raising κ_i moves a
    point inside segment i along its chord derivative and turns every point beyond the
    segment about the segment's end ``P_i``; then ``κ_i = (S_i − S_{i−1}) / (d l_i)``.
    """
    n = lengths.size
    theta = kappa * lengths
    phi_start = np.cumsum(theta, axis=-1) - theta
    half = 0.5 * theta
    chord = lengths * _sinc(half)
    mid = phi_start + half
    ends_x = np.cumsum(chord * np.sin(mid), axis=-1)
    ends_y = np.cumsum(chord * np.cos(mid), axis=-1)
    dchord = _arc_dkappa(kappa, lengths, phi_start)  # (b, N, 2)
    dq = _arc_dkappa(kappa[:, seg], sigma, phi_start[:, seg])  # (b, M, 2)
    after = (seg[:, None] > np.arange(n)).astype(float)  # (M, N)
    own = (seg[:, None] == np.arange(n)).astype(float)
    out = np.empty((kappa.shape[0], seg.size, 2, n))
    # beyond segment i: dchord_i + l_i R'(p_j − P_i), R'v = (v_y, −v_x)
    out[:, :, 0] = after * (dchord[:, None, :, 0] + lengths * (pos[:, :, 1:2] - ends_y[:, None]))
    out[:, :, 1] = after * (dchord[:, None, :, 1] - lengths * (pos[:, :, 0:1] - ends_x[:, None]))
    out += own[:, None] * dq[..., None]
    out /= d * lengths
    out[..., :-1] -= out[..., 1:].copy()
    return out


def _misfit(G, w, r, J, Tu, cov_s):
    """χ² of the fit residual against the propagated shift covariance, and its dof (b,).

    The residual ``r = p(F̂) − p⁰`` is pulled back to the shift perturbation that
    best explains it, ``δŜ = −(GᵀWG)⁻¹ GᵀW r`` (G = ∂p⁰/∂S): the part of ``r`` that no
    PCC shape can show (the beam shape is not piecewise-constant) drops out. If
    the shifts err by ``δS ~ N(0, Σ_S)`` and the model is right, ``δŜ = (I − Z T) δS``
    with ``Z = (GᵀWG)⁻¹ GᵀW J`` and ``T = ∂u/∂S``, so ``χ² = δŜᵀ C⁺ δŜ`` with
    ``C = (I − ZT) Σ_S (I − ZT)ᵀ`` of rank N − k follows χ² with N − k degrees of
    freedom.
    """
    b, M, _, n = G.shape
    Gf = G.reshape(b, 2 * M, n)
    GtW = np.swapaxes(Gf * np.repeat(w, 2)[:, None], 1, 2)  # (b, N, 2M)
    rhs = GtW @ np.concatenate([r.reshape(b, 2 * M, 1), J.reshape(b, 2 * M, -1)], axis=-1)
    sol = np.linalg.solve(GtW @ Gf, rhs)
    proj = np.eye(n) - sol[..., 1:] @ Tu
    C = proj @ cov_s @ np.swapaxes(proj, 1, 2)
    lam, V = np.linalg.eigh(0.5 * (C + np.swapaxes(C, 1, 2)))
    keep = (np.arange(n) >= Tu.shape[1]) & (lam > 1e-10 * lam[:, -1:])
    z = (np.swapaxes(V, 1, 2) @ sol[..., :1])[..., 0]  # V^T δŜ up to the sign
    chi2 = np.sum(np.where(keep, z * z / np.where(keep, lam, 1.0), 0.0), axis=1)
    return chi2, keep.sum(axis=1)


def _covariance(prob, res, cov_s):
    """Cov(F) (B, 2, 2) and χ²/dof (B,) by linear propagation of the shift errors (module docstring).

    ``cov_s`` (B, N, N) is the covariance of the shifts; None uses the fit residual. The
    propagated covariance is scaled by χ²/dof of the fit where that exceeds 1.
    """
    B, k = prob["B"], prob["k"]
    w = prob["w"]
    cov = np.empty((B, 2, 2))
    ratio = np.full(B, np.nan)
    pcc = prob["kappa"] is not None and cov_s is not None
    if pcc:
        onehot = np.zeros((prob["M"], prob["lengths"].size))
        onehot[np.arange(prob["M"]), prob["seg"]] = 1.0
    for lo in range(0, B, _COV_CHUNK):
        sl = slice(lo, min(B, lo + _COV_CHUNK))
        D = prob["D"][sl]
        Dt = np.swapaxes(D, 1, 2)
        dpos = res["dpos"][sl]
        _, _, GF = _linearise(res["positions"][sl], dpos, prob["p0"][sl], w)
        H = Dt @ GF @ D
        Hinv, singular, V = _inverse_cov(H)
        if pcc:
            e = w[:, None, None] * dpos
            hs = Dt @ _shape_sensitivity(prob["kappa"][sl], prob["lengths"], prob["d"], onehot, prob["sigma"],
                                         prob["seg"], prob["p0"][sl], e)  # (b, k, N)
            if prob["dD"] is not None:
                # D follows the reconstructed tip angle φ_L (see _tip_angle_weights)
                dphi_ds = _tip_angle_shift_gradient(prob["lengths"], prob["L"], prob["d"])  # (N,)
                Fd = _apply(prob["dD"][sl], res["u"][sl])  # (∂D/∂φ_L) u
                hs -= (Dt @ (GF @ Fd[..., None])) * dphi_ds
            Tu = Hinv @ hs  # ∂u/∂S (b, k, N)
            T = D @ Tu  # ∂F/∂S (b, 2, N)
            if prob["dD"] is not None:
                T += Fd[..., None] * dphi_ds
            c = T @ cov_s[sl] @ np.swapaxes(T, 1, 2)
            G = _shape_jacobian(prob["kappa"][sl], prob["lengths"], prob["d"], prob["seg"], prob["sigma"],
                                prob["p0"][sl])
            J = np.einsum("bmif,bfk->bmik", dpos, D)
            chi2, dof = _misfit(G, w, res["positions"][sl] - prob["p0"][sl], J, Tu, cov_s[sl])
            ratio[sl] = chi2 / np.maximum(dof, 1)
            # a misfit beyond the propagated errors (model error the shifts' covariance
            # does not know) scales the covariance, the Birge ratio; never shrinks it
            c *= np.maximum(ratio[sl], 1.0)[:, None, None]
        else:
            r = res["positions"][sl] - prob["p0"][sl]
            dof = max(2 * prob["M"] - k, 1)
            var = np.einsum("bmi,bmi->b", r, r) / dof  # per coordinate
            _, _, mid = _linearise(r, dpos, r, w * w)
            cu = var[:, None, None] * (Hinv @ (Dt @ mid @ D) @ Hinv)
            c = D @ cu @ Dt
        if singular.any():
            dirs = D @ V  # force directions of the eigenvectors
            for q in range(k):
                hit = singular[:, q]
                if hit.any():
                    v = dirs[hit, :, q]
                    outer = v[:, :, None] * v[:, None, :]
                    c[hit] = np.where(np.abs(outer) > 1e-12, np.inf, c[hit])
        cov[sl] = c
    return cov, ratio


@functools.lru_cache(maxsize=16)
def _jacobian_grid(lengths: bytes, seg: bytes, sigma: bytes):
    """Per-grid constants of :func:`_shape_jacobian_one` (cached, read-only).

    Segment index of the segments and then of the points, half their arc lengths,
    their arc lengths squared over 2, the mask of the segments before each point's
    and the index pairs (point, own segment).
    """
    lengths, seg, sigma = np.frombuffer(lengths), np.frombuffer(seg, dtype=np.intp), np.frombuffer(sigma)
    n = lengths.size
    idx = np.concatenate([np.arange(n), seg])
    arc = np.concatenate([lengths, sigma])
    out = (idx, 0.5 * arc, 0.5 * arc * arc, (seg[:, None] > np.arange(n)).astype(float), np.arange(seg.size), seg,
           1j * lengths)
    for a in out:
        a.setflags(write=False)
    return out


def _shape_jacobian_one(kappa, lengths, d, seg, sigma, pos):
    """:func:`_shape_jacobian` of one frame, (M, 2, N), in complex arithmetic.

    Planar vectors are complex numbers ``y + i x``: a chord of length σ at angle
    ``m`` is ``σ sinc(h) e^{im}`` and its derivative by κ is
    ``σ²/2 (sinc'(h) + i sinc(h)) e^{im}`` (``h = κσ/2``, :func:`_arc_dkappa`); the
    turn ``R'v = (v_y, −v_x)`` of the points beyond a segment is ``i v``.
    """
    n = lengths.size
    idx, half_arc, half_arc2, after, rows, own, il = _jacobian_grid(lengths.tobytes(), seg.tobytes(), sigma.tobytes())
    theta = kappa * lengths
    start = np.add.accumulate(theta)
    start -= theta  # φ at the start of every segment
    h = kappa[idx] * half_arc  # half angles of the segments, then of the points' arcs
    eh = np.exp(1j * h)
    zero = h == 0.0
    sinc = eh.imag / (h + zero)
    sinc += zero  # sin h / h, exactly 1 at 0
    # sinc'(h) = (cos h − sinc h) / h, by its series where that cancels (as _dsinc)
    small = np.abs(h) < 1e-2
    safe = h + small
    dsinc = (eh.real - sinc) / safe
    if small.any():
        h2 = h * h
        series = h2 / -840.0
        series += 1.0 / 30.0
        series *= h2
        series -= 1.0 / 3.0
        series *= h
        np.copyto(dsinc, series, where=small)
    em = np.exp(1j * start[idx])
    em *= eh  # e^{im}, m = φ0 + h
    dchord = dsinc + 1j * sinc
    dchord *= em
    dchord *= half_arc2
    ends = np.add.accumulate(lengths * sinc[:n] * em[:n])  # segment end points P_i
    pc = np.empty(seg.size, dtype=complex)
    pc.real = pos[:, 1]
    pc.imag = pos[:, 0]
    G = pc[:, None] - ends
    G *= il
    G += dchord[:n]
    G *= after
    G[rows, own] += dchord[n:]
    out = np.empty((seg.size, 2, n))
    dl = d * lengths
    np.divide(G.imag, dl, out=out[:, 0])
    np.divide(G.real, dl, out=out[:, 1])
    out[..., :-1] -= out[..., 1:].copy()
    return out


def _inverse_cov_one(H):
    """:func:`_inverse_cov` of one (k, k) matrix."""
    if H.shape[0] == 1:
        h = float(H[0, 0])
        singular = h <= 1e-12 * max(h, 0.0) + 1e-300
        return np.array([[0.0 if singular else 1.0 / h]]), np.array([singular]), np.ones((1, 1))
    lam, V = np.linalg.eigh(H)
    top = max(float(lam[1]), 0.0)
    singular = [x <= 1e-12 * top + 1e-300 for x in lam.tolist()]
    inv = [0.0 if s else 1.0 / x for s, x in zip(singular, lam.tolist())]
    (v00, v01), (v10, v11) = V.tolist()
    h01 = v00 * inv[0] * v10 + v01 * inv[1] * v11
    Hinv = np.array([[v00 * inv[0] * v00 + v01 * inv[1] * v01, h01], [h01, v10 * inv[0] * v10 + v11 * inv[1] * v11]])
    return Hinv, np.array(singular), V


def _misfit_one(Gf, w2, r, J, Tu, cov_s):
    """:func:`_misfit` of one frame: ``Gf`` (2M, N), ``w2`` (2M,), ``r`` (2M,), ``J`` (2M, k)."""
    n = Gf.shape[1]
    GtW = (Gf * w2[:, None]).T  # (N, 2M)
    rj = np.empty((r.size, 1 + J.shape[1]))
    rj[:, 0] = r
    rj[:, 1:] = J
    # LAPACK directly (np.linalg.solve and eigh call the same routines, with more overhead)
    _, _, sol, info = _dgesv(GtW @ Gf, GtW @ rj, overwrite_a=True, overwrite_b=True)
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    proj = np.eye(n) - sol[:, 1:] @ Tu
    C = proj @ cov_s @ proj.T
    C = C + C.T
    C *= 0.5
    lam, V, info = _dsyevd(C, compute_v=1, lower=1, overwrite_a=1)
    if info > 0:
        raise np.linalg.LinAlgError("Eigenvalues did not converge")
    keep = lam > 1e-10 * lam[-1]
    keep[: Tu.shape[0]] = False
    z = V.T @ sol[:, 0]
    return float(np.sum(z[keep] ** 2 / lam[keep])), int(keep.sum())


def _covariance_one(ref, res, D, dD, w2, L, d, cov_s):
    """:func:`_covariance` of one frame with small dense products: Cov(F) (2, 2) and χ²/dof.

    The PCC shape's Jacobian ``G = ∂p⁰/∂S`` is formed once (2M × N) and serves both the
    propagation (``Σ_j (w_j ∂p_j/∂F)ᵀ G_j``, which the batched path contracts without
    forming G) and the misfit.
    """
    k = D.shape[1]
    A = res["dpos"].reshape(-1, 2)  # ∂p/∂F (2M, 2)
    wA = A * w2[:, None]
    GF = A.T @ wA
    Hinv, singular, V = _inverse_cov_one(D.T @ GF @ D)
    r = (res["positions"] - ref["p0"]).reshape(-1)
    ratio = math.nan
    if cov_s is not None:
        kappa, lengths = ref["kappa"].reshape(-1), ref["lengths"]  # one frame, any batch shape
        Gf = _shape_jacobian_one(kappa, lengths, d, ref["seg"], ref["sigma"], ref["p0"].reshape(-1, 2)).reshape(
            -1, lengths.size)
        hs = D.T @ (wA.T @ Gf)  # (k, N)
        if dD is not None:
            # D follows the reconstructed tip angle φ_L (see _tip_angle_weights)
            dphi_ds = _tip_angle_shift_gradient(lengths, L, d)
            Fd = dD @ res["u"]
            hs -= (D.T @ (GF @ Fd))[:, None] * dphi_ds
        Tu = Hinv @ hs  # ∂u/∂S
        T = D @ Tu  # ∂F/∂S
        if dD is not None:
            T += Fd[:, None] * dphi_ds
        c = T @ cov_s @ T.T
        chi2, dof = _misfit_one(Gf, w2, r, A @ D, Tu, cov_s)
        ratio = chi2 / max(dof, 1)
        c *= max(ratio, 1.0)
    else:
        dof = max(r.size - k, 1)
        var = float(r @ r) / dof  # per coordinate
        mid = A.T @ (A * (w2 * w2)[:, None])
        c = D @ (var * (Hinv @ (D.T @ mid @ D) @ Hinv)) @ D.T
    if singular.any():
        dirs = D @ V  # force directions of the eigenvectors
        for q in np.flatnonzero(singular):
            v = dirs[:, q]
            c = np.where(np.abs(v[:, None] * v[None, :]) > 1e-12, np.inf, c)
    return c, ratio


def _shift_covariance_one(kappa, lengths, d, noise_std, calibration):
    """:func:`_shift_covariance` of one frame (N,) → (N, N)."""
    S = np.add.accumulate(kappa * lengths)
    S *= d
    if calibration is None:
        sd = np.broadcast_to(noise_std, S.shape)
        return np.diag(sd * sd)
    cols, dcols = calibration._coefficient_columns, calibration._slope_columns
    if not dcols:
        return np.zeros((S.size, S.size))

    def poly(c, x):  # Horner's rule; c highest power first, (N,) or stacked (2, N)
        out = c[0].copy()
        for ck in c[1:]:
            out *= x
            out += ck
        return out

    both = calibration._value_slope_columns
    nonzero, safe = calibration._linear_slope
    x = (S - cols[-1]) / safe
    x[~nonzero] = 0.0
    for _ in range(50):
        dx, fp = poly(both, x)  # f(x), f'(x)
        if not fp.all():
            fp[fp == 0] = 1.0
        dx -= S
        dx /= fp
        x = x - dx
        tol = np.abs(x)
        np.maximum(tol, 1.0, out=tol)
        tol *= 1e-12
        if (np.abs(dx, out=dx) <= tol).all():
            break
    sd = np.abs(poly(dcols, x))
    sd *= noise_std
    cov = calibration.shift_error_m(S, covariance=True)
    cov.flat[:: S.size + 1] += sd * sd
    return cov


def _shift_covariance(kappa, lengths, d, noise_std, calibration):
    """Σ_S (b, N, N) [m²]: covariance of the shifts (module docstring, Uncertainty).

    The signal noise through the calibration slope f'(ΔA) (paper eq. 2), independent
    per channel, plus the calibration's own model error, correlated across channels
    (:meth:`~bendsense.calibration.Calibration.shift_error_m`).
    """
    from bendsense.calibration import parity_masks

    S = d * np.cumsum(kappa * lengths, axis=-1)  # S_i = d φ(L_i) (paper eq. 3–4)
    if calibration is None:
        sd = np.broadcast_to(noise_std, S.shape)
        return sd[..., :, None] * np.eye(S.shape[-1]) * sd[..., None, :]
    n = S.shape[-1]
    odd, _ = parity_masks(n)
    coef = np.where(odd[:, None], calibration.coefficients_odd, calibration.coefficients_even)  # (N, n+1)
    dcoef = coef[:, 1:] * np.arange(1, coef.shape[1])
    if dcoef.shape[1] == 0:
        return np.zeros((*S.shape, n))

    def poly(c, x):
        out = np.broadcast_to(c[:, -1], x.shape).copy()
        for j in range(c.shape[1] - 2, -1, -1):
            out = out * x + c[:, j]
        return out

    slope0 = dcoef[:, 0]
    x = np.where(slope0 != 0, (S - coef[:, 0]) / np.where(slope0 != 0, slope0, 1.0), 0.0)
    for _ in range(50):
        fp = poly(dcoef, x)
        dx = (poly(coef, x) - S) / np.where(fp != 0, fp, 1.0)
        x = x - dx
        if np.all(np.abs(dx) <= 1e-12 * np.maximum(1.0, np.abs(x))):
            break
    sd = np.abs(poly(dcoef, x)) * noise_std
    return sd[..., :, None] * np.eye(n) * sd[..., None, :] + calibration.shift_error_m(S, covariance=True)


# --------------------------------------------------------------------------- inputs


def _reference(shape, config, s_opt, n_points, L_act):
    """Reference shape p⁰ at the comparison nodes and what the uncertainty needs."""
    from bendsense import pcc

    kappa = None
    if s_opt is not None:
        pos = np.asarray(shape, dtype=float)
        s_in = np.asarray(s_opt, dtype=float)
        angle = None
    elif hasattr(shape, "curvature_per_m") and hasattr(shape, "lengths_m"):
        kappa = np.asarray(shape.curvature_per_m, dtype=float)
        lengths = np.asarray(shape.lengths_m, dtype=float)
    elif hasattr(shape, "positions_m") and hasattr(shape, "s_m"):
        pos = np.asarray(shape.positions_m, dtype=float)
        s_in = np.asarray(shape.s_m, dtype=float)
        angle = getattr(shape, "angle_rad", None)
    else:
        kappa = np.asarray(shape, dtype=float)
        lengths = config.sensor.lengths_m
        if kappa.ndim == 0 or kappa.shape[-1] != lengths.size:
            raise ArgumentError(
                f"shape: expected a Shape, a BeamSolution or curvatures (..., {lengths.size}) [1/m], "
                f"got shape {kappa.shape}"
            )
    if kappa is not None:
        if not np.isfinite(kappa).all():
            raise ArgumentError("shape.curvature_per_m: must be finite")
        Lc = min(float(lengths.sum()), L_act)
        grid = _pcc_grid(tuple(lengths.tolist()), Lc, n_points, L_act)
        s, seg = grid["s"], grid["seg"]
        # the comparison points and the beam's nodes (for its Newton start) in one pass
        if kappa.shape == lengths.shape:  # one frame
            pos, phi, _, _ = pcc._kernel_one(kappa, kappa * grid["grid"].lengths, 0.0, grid["grid"])
        else:
            pos, phi, _, _ = pcc._kinematics(kappa, grid["grid"], 0.0)
        M = s.size
        return {"p0": pos[..., :M, :], "s": s, "w": grid["w"], "Lc": Lc, "kappa": kappa, "lengths": lengths,
                "seg": seg, "sigma": grid["sigma"], "tip_shape": kappa @ grid["tip_weights"], "phi": phi[..., :M],
                "phi_nodes": phi[..., M:], "kappa_s": kappa[..., seg], "beyond": grid["beyond"]}
    if s_in.ndim != 1 or s_in.size < 2 or np.any(np.diff(s_in) <= 0) or s_in[0] < 0:
        raise ArgumentError(f"s_m: expected at least 2 increasing arc lengths from >= 0, got shape {s_in.shape}")
    if pos.shape[-2:] != (s_in.size, 2):
        raise ArgumentError(f"shape.positions_m: expected shape (..., {s_in.size}, 2) to match s_m, got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ArgumentError("shape.positions_m: must be finite")
    Lc = min(float(s_in[-1]), L_act)
    keep = s_in <= Lc * (1.0 + 1e-12)
    s = s_in[keep]
    p0 = pos[..., keep, :]
    # tangent angle and curvature by differences, for the starting guess only
    if angle is not None and np.shape(angle)[-1:] == (s_in.size,):
        phi = np.asarray(angle, dtype=float)[..., keep]
    else:
        dp = np.gradient(p0, s, axis=-2, edge_order=2)
        phi = np.unwrap(np.arctan2(dp[..., 0], dp[..., 1]), axis=-1)
    # the tip angle of a shape given by points: at its last compared point
    return {"p0": p0, "s": s, "w": pcc._trapezoid_weights(s), "Lc": float(s[-1]), "kappa": None,
            "tip_shape": phi[..., -1], "phi": phi, "kappa_s": np.gradient(phi, s, axis=-1, edge_order=2)}


def _noise_std(noise_opt, calibration, est):
    """Signal noise per channel (option, else the calibration's if nonzero, else the config's)."""
    if noise_opt is None and calibration is None and type(est.signal_noise_std) is float:
        sigma_a = est.signal_noise_std  # validated by the config (finite, >= 0)
        return np.float64(sigma_a)
    if noise_opt is not None:
        sigma_a = np.asarray(noise_opt, dtype=float)
    elif calibration is not None and np.any(np.asarray(calibration.noise_std) > 0):
        sigma_a = np.asarray(calibration.noise_std, dtype=float)
    else:
        sigma_a = np.asarray(est.signal_noise_std, dtype=float)
    if np.any(sigma_a < 0) or not np.all(np.isfinite(sigma_a)):
        raise ArgumentError(f"noise_std: must be finite and >= 0, got {sigma_a.tolist()}")
    return sigma_a


def _boundary_message(v):
    return (f"not identifiable along ({v[0]:.3f}, {v[1]:.3f}): trial loads leave the stable branch "
            "(buckling) or the shape's linear range; best stable estimate, std inf")


def _misfit_message(residual_m):
    return (f"no stable equilibrium matches the shape: stopped at the stability boundary {residual_m * 1e3:.3g} mm "
            "from it (a load beyond buckling?)")


_FAILURES = {2: "beam model fails (buckling or no equilibrium) at every trial force",
             3: "no convergence in the iteration limit"}


def _estimate_one(ref, pressure, batch, config, L, constraint, *, source, direction, follower, push_only, initial,
                  initial_force, noise_opt, calibration, strict, xtol, max_iter, t_start):
    """:func:`estimate_force` (fast) of one frame: the real-time path.

    The same steps as the batched path on unbatched arrays, with the frame's scalars as
    plain floats and what depends only on the grid, the calibration or the config
    cached; the numbers agree with the batched path to round-off.
    """
    est = config.estimation
    M = ref["s"].size
    p0 = ref["p0"].reshape(M, 2)
    model, wload, gap = _config_constants(config)
    theta = float(model.bending_angle_rad(pressure))  # free-motion tip angle
    k0 = theta / model.length_m  # as model.tip_curvature_per_m
    ei = float(config.stiffness.ei_nm2(pressure))
    if not ei > 0:
        raise ArgumentError(f"pressure_pa: EI(P) must be > 0, got {ei!r} N·m² at {pressure!r} Pa")
    phi_L = theta if source == "model" else float(np.reshape(ref["tip_shape"], -1)[0])
    D, dD = constraint_basis(constraint, phi_L, direction=direction, follower_angle_rad=follower)
    k = D.shape[-1]
    if source == "model":
        dD = None
    lower = _LOWER[push_only, k]
    s, w = ref["s"], ref["w"]
    kappa = None if ref["kappa"] is None else ref["kappa"].reshape(-1)
    ffix = np.zeros(2)

    # starting points
    state0 = _shape_state(ref, L, _N_NODES).reshape(_N_NODES)
    if initial is not None and not isinstance(initial, ForceEstimate):
        raise ArgumentError(f"initial: expected a ForceEstimate, got {type(initial).__name__}")
    phi = ref["phi"].reshape(M)
    guess = _moment_guess_one(p0, s, w, L, ei, k0, wload, D, lower, float(phi[-1]), ref["kappa_s"].reshape(M))
    u0 = None
    if initial is not None and initial_force is None and initial.guess_n is not None:
        # the previous frame's offset from its own moment-balance start (see estimate_force)
        prev_f, prev_g = (np.asarray(a, dtype=float) for a in (initial.force_n, initial.guess_n))
        if prev_f.shape != (*batch, 2) or prev_g.shape != (*batch, 2):
            prev_f = np.broadcast_to(prev_f, (*batch, 2))
            prev_g = np.broadcast_to(prev_g, (*batch, 2))
        prev_f, prev_g = prev_f.reshape(2), prev_g.reshape(2)
        u0 = guess.copy()
        if all(math.isfinite(x) for x in (*prev_f.tolist(), *prev_g.tolist())):
            u0 += (prev_f - prev_g) @ D
    elif initial is not None and initial_force is None:
        initial_force = initial.force_n
    if u0 is not None:
        pass
    elif initial_force is not None:
        f0 = np.asarray(initial_force, dtype=float)
        if f0.shape[-1:] != (2,) or not np.all(np.isfinite(f0)):
            raise ArgumentError(f"initial_force_n: expected finite values of shape (..., 2), got shape {f0.shape}")
        u0 = np.broadcast_to(f0, (*batch, 2)).reshape(2) @ D
    else:
        u0 = guess
    u0 = np.maximum(u0, lower)
    res = _gauss_newton_one(L, ei, k0, wload, _joined(s.tobytes(), L, _N_NODES), w, p0, D, ffix, lower, u0, state0,
                            xtol=xtol, max_iter=max_iter, n_nodes=_N_NODES)

    # uncertainty
    cov_s = None
    uncertainty = "residual"
    if kappa is not None:
        if noise_opt is None and calibration is not None and calibration._noise_positive:
            # validated when the calibration was made
            sigma_a, positive = calibration.noise_std, True
        else:
            sigma_a = _noise_std(noise_opt, calibration, est)
            positive = bool((sigma_a > 0).any())
        if positive or calibration is not None:
            lengths = ref["lengths"]
            cov_s = _shift_covariance_one(kappa, lengths, gap, np.broadcast_to(sigma_a, (lengths.size,)), calibration)
            if np.trace(cov_s) > 0:
                uncertainty = "propagated"
            else:
                cov_s = None
    w2 = _repeat2(w.tobytes())
    cov, chi2_dof = _covariance_one(ref, res, D, dD, w2, L, gap, cov_s)

    status = res["status"]
    message = _OK
    diff = (res["positions"] - p0).reshape(-1)
    residual = math.sqrt(float(diff @ (diff * w2)) / float(w.sum()))
    if status == 4:
        # stopped at the stability boundary (see estimate_force)
        v = _apply_one(D, res["blocked"])
        v /= max(math.hypot(v[0], v[1]), 1e-300)
        cov = np.where(np.abs(v[:, None] * v[None, :]) > 1e-12, np.inf, cov)
        if residual > _BOUNDARY_MISFIT * L:
            status = 3
            message = _misfit_message(residual)
        else:
            message = _boundary_message(v)
    elif status != 1:
        message = _FAILURES[status]
    success = status in (1, 4)
    if not success and strict:
        raise ConvergenceError(f"1 of 1 force estimate(s) failed; first: {message}")
    if success:
        force = res["force"]
        std = np.sqrt(np.diagonal(cov))
    else:
        force = std = np.full(2, np.nan)
        cov = np.full((2, 2), np.nan)
        chi2_dof = math.nan
    if batch:
        residual, success, chi2_dof = np.full(batch, residual), np.full(batch, success), np.full(batch, chi2_dof)
        message, iters = np.full(batch, message), np.full(batch, res["iterations"])
    else:
        residual, success, chi2_dof = np.array(residual), np.array(success), np.array(chi2_dof)
        iters = np.array(res["iterations"])
    return ForceEstimate(
        force_n=force.reshape(*batch, 2),
        std_n=std.reshape(*batch, 2),
        covariance_n2=cov.reshape(*batch, 2, 2),
        residual_m=residual,
        success=success,
        message=message,
        iterations=iters,
        wall_time_s=time.perf_counter() - t_start,
        method="fast",
        constraint=constraint,
        uncertainty=uncertainty,
        tip_position_m=res["tip"].reshape(*batch, 2),
        state=res["state"].reshape(*batch, res["state"].size),
        guess_n=_apply_one(D, guess).reshape(*batch, 2),
        chi2_per_dof=chi2_dof,
    )


def _option(options, name, default):
    value = options.pop(name, None)
    return default if value is None else value


def estimate_force(shape, pressure_pa, config=None, constraint: str = "none", method: str = "fast",
                   **options) -> ForceEstimate:
    """Tip force from a reconstructed shape and the pressure (paper eq. 18, 21).

    Parameters
    ----------
    shape : Shape, BeamSolution or array_like
        A :class:`~bendsense.pcc.Shape` (its curvatures and segment lengths are used),
        segment curvatures (..., N) [1/m] on ``config.sensor``, a shape given by points
        (any object with ``s_m`` (M,) and ``positions_m`` (..., M, 2), e.g. a
        :class:`~bendsense.beam.BeamSolution`), or positions (..., M, 2) [m] with the
        option ``s_m``. Leading axes are frames.
    pressure_pa : array_like, shape (...)
        Pressure of each frame [Pa]; broadcasts against the shape's batch axes.
    config : Config, optional
        ``None``: the paper's prototype (:func:`bendsense.load_config`).
    constraint : str
        One of :data:`CONSTRAINTS`; sign conventions in the module docstring.
    method : {"fast", "paper"}
        Gauss–Newton with analytic sensitivities, or the paper's shooting +
        Nelder–Mead / SLSQP.
    **options
        ``push_only`` (bool, default ``config.estimation.push_only``): ``u ≥ 0`` for
        1-D constraints. ``tip_angle_source`` (``"model"`` | ``"shape"``),
        ``direction`` (unit (2,)), ``follower_angle_rad`` [rad]: defaults from
        ``config.estimation``. ``initial_force_n`` (..., 2) [N]: start of every frame
        (otherwise F = 0 for the first frame of each block and the previous frame's
        estimate for the others). ``initial``: a previous :class:`ForceEstimate`
        (its force and beam state start every frame; real-time use).
        ``warm_start`` (bool, default True): chain frames along the first batch axis.
        ``noise_std`` (N,) or float: signal noise per channel [signal units];
        default ``calibration.noise_std`` if nonzero, else
        ``config.estimation.signal_noise_std``. ``calibration``: the
        :class:`~bendsense.calibration.Calibration` whose slopes map signal noise to
        shifts. ``strict`` (bool): raise :class:`~bendsense.errors.ConvergenceError`
        if a frame fails. ``s_m``: arc lengths of positions given as an array.
        ``n_points``: quadrature nodes (default ``config.estimation.n_points``).
        ``xtol_n``, ``max_iter``: fast-method stopping rule.

    Returns
    -------
    ForceEstimate
        Frames that fail (no convergence, or every trial force buckles the beam) have
        ``success=False`` and a message; nothing is raised unless ``strict=True``.

    Raises
    ------
    ValueError
        For a bad argument or option (the message names it).
    ConvergenceError
        With ``strict=True`` when a frame fails.
    """
    t_start = time.perf_counter()
    if config is None:
        from bendsense.config import load_config

        config = load_config()
    est = config.estimation
    if constraint is None:
        constraint = est.constraint
    if method is None:
        method = est.method
    if constraint not in CONSTRAINTS:
        raise ArgumentError(f"constraint: must be one of {', '.join(CONSTRAINTS)}, got {constraint!r}")
    if method not in METHODS:
        raise ArgumentError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    options = dict(options)
    push_only = bool(_option(options, "push_only", est.push_only))
    source = _option(options, "tip_angle_source", est.tip_angle_source)
    if source not in ("model", "shape"):
        raise ArgumentError(f"tip_angle_source: must be one of model, shape, got {source!r}")
    direction = np.asarray(_option(options, "direction", est.direction), dtype=float)
    if direction.shape != (2,) or not np.all(np.isfinite(direction)) or abs(np.hypot(*direction) - 1.0) > 1e-6:
        raise ArgumentError(f"direction: expected a unit vector (2,), got {direction.tolist()}")
    follower = float(_option(options, "follower_angle_rad", est.follower_angle_rad))
    initial_force = options.pop("initial_force_n", None)
    initial = options.pop("initial", None)
    warm_start = bool(_option(options, "warm_start", True))
    noise_opt = options.pop("noise_std", None)
    calibration = options.pop("calibration", None)
    strict = bool(_option(options, "strict", False))
    s_opt = options.pop("s_m", None)
    n_points = int(_option(options, "n_points", est.n_points))
    xtol = float(_option(options, "xtol_n", XTOL_N))
    max_iter = int(_option(options, "max_iter", _MAX_ITER))
    if options:
        raise ArgumentError(
            f"options: unknown {', '.join(sorted(options))}; allowed: push_only, tip_angle_source, direction, "
            "follower_angle_rad, initial_force_n, initial, warm_start, noise_std, calibration, strict, s_m, "
            "n_points, xtol_n, max_iter"
        )
    if n_points < 3:
        raise ArgumentError(f"n_points: must be >= 3, got {n_points}")
    if push_only and constraint == "none":
        raise ArgumentError("push_only: only for the 1-D constraints (vertical, horizontal, direction, normal, "
                         "follower), got constraint='none'")

    L = float(config.actuator.length_m)
    ref = _reference(shape, config, s_opt, n_points, L)
    P = np.asarray(pressure_pa, dtype=float)
    if not np.isfinite(P).all():
        raise ArgumentError(f"pressure_pa: must be finite, got {pressure_pa!r}")
    p0 = ref["p0"]
    try:
        batch = () if p0.ndim == 2 and P.ndim == 0 else np.broadcast_shapes(p0.shape[:-2], P.shape)
    except ValueError:
        raise ArgumentError(f"pressure_pa: shape {P.shape} does not broadcast against the shape's frames "
                         f"{p0.shape[:-2]}") from None
    B = math.prod(batch)
    if B == 1 and method == "fast":
        return _estimate_one(ref, float(P.reshape(-1)[0]), batch, config, L, constraint, source=source,
                             direction=direction, follower=follower, push_only=push_only, initial=initial,
                             initial_force=initial_force, noise_opt=noise_opt, calibration=calibration,
                             strict=strict, xtol=xtol, max_iter=max_iter, t_start=t_start)
    M = ref["s"].size
    p0 = np.broadcast_to(p0, (*batch, M, 2)).reshape(B, M, 2)
    Pf = np.broadcast_to(P, batch).reshape(B)
    model = _free_model(config)
    k0 = np.asarray(model.tip_curvature_per_m(Pf), dtype=float).reshape(B)
    ei = np.asarray(config.stiffness.ei_nm2(Pf), dtype=float).reshape(B)
    if not np.all(ei > 0):
        raise ArgumentError(f"pressure_pa: EI(P) must be > 0, got {float(ei.min())!r} N·m² "
                         f"at {float(Pf[np.argmin(ei)])!r} Pa")
    tip_shape = np.broadcast_to(ref["tip_shape"], batch).reshape(B)
    phi_L = np.asarray(model.tip_angle_rad(Pf), dtype=float).reshape(B) if source == "model" else tip_shape
    D, dD = constraint_basis(constraint, phi_L, direction=direction, follower_angle_rad=follower)
    D = np.ascontiguousarray(np.broadcast_to(D, (B, *D.shape[-2:])))
    k = D.shape[-1]
    prob = {
        "B": B, "k": k, "M": M, "L": L, "Lc": ref["Lc"], "s": ref["s"], "w": ref["w"],
        "s_all": _joined(ref["s"].tobytes(), L, _N_NODES),
        "p0": p0, "ei": ei, "k0": k0, "wload": np.asarray(config.weight_per_length_n_per_m, dtype=float),
        "D": D, "dD": None if (dD is None or source == "model") else np.broadcast_to(dD, (B, 2, k)),
        "ffix": np.zeros((B, 2)), "lower": np.full(k, 0.0 if push_only else -np.inf),
        "kappa": None, "d": float(config.sensor.strip_gap_m),
    }
    if ref["kappa"] is not None:
        N = ref["lengths"].size
        prob.update(kappa=np.broadcast_to(ref["kappa"], (*batch, N)).reshape(B, N), lengths=ref["lengths"],
                    seg=ref["seg"], sigma=ref["sigma"])

    # starting points
    st = _shape_state(ref, L, _N_NODES)
    state0 = np.ascontiguousarray(np.broadcast_to(st, (*batch, _N_NODES)).reshape(B, _N_NODES))
    if initial is not None:
        if not isinstance(initial, ForceEstimate):
            raise ArgumentError(f"initial: expected a ForceEstimate, got {type(initial).__name__}")
    phi = np.broadcast_to(ref["phi"], (*batch, M)).reshape(B, M)
    kap = np.broadcast_to(ref["kappa_s"], (*batch, M)).reshape(B, M)
    guess = _moment_guess(prob, phi, kap)
    u0 = None
    if initial is not None and initial_force is None and initial.guess_n is not None:
        # the previous frame's offset from its own moment-balance start corrects this
        # frame's start (the PCC and model error change slowly along a time series)
        prev_f = np.broadcast_to(np.asarray(initial.force_n, dtype=float), (*batch, 2)).reshape(B, 2)
        prev_g = np.broadcast_to(np.asarray(initial.guess_n, dtype=float), (*batch, 2)).reshape(B, 2)
        ok_prev = np.isfinite(prev_f).all(axis=1) & np.isfinite(prev_g).all(axis=1)
        u0 = guess.copy()
        u0[ok_prev] += np.einsum("bij,bi->bj", D[ok_prev], prev_f[ok_prev] - prev_g[ok_prev])
        chain = False
    elif initial is not None and initial_force is None:
        initial_force = initial.force_n
    if u0 is not None:
        pass
    elif initial_force is not None:
        f0 = np.asarray(initial_force, dtype=float)
        if f0.shape[-1:] != (2,) or not np.all(np.isfinite(f0)):
            raise ArgumentError(f"initial_force_n: expected finite values of shape (..., 2), got shape {f0.shape}")
        f0 = np.broadcast_to(f0, (*batch, 2)).reshape(B, 2)
        u0 = np.einsum("bij,bi->bj", D, f0 - prob["ffix"])
        chain = False
    else:
        u0 = guess
        chain = warm_start
    u0 = np.maximum(u0, prob["lower"])

    if method == "fast":
        res = _fast(prob, u0, state0, chain=chain, xtol=xtol, max_iter=max_iter, n_nodes=_N_NODES)
    else:
        # the paper's baseline starts where fminsearch/fmincon would: at zero force
        u, status, nfev = _paper(prob, np.maximum(np.zeros_like(u0), prob["lower"]))
        # the shape, its sensitivities and the uncertainty at the paper's optimum come
        # from the fast solver (the paper gives no uncertainty)
        F = prob["ffix"] + np.einsum("bij,bj->bi", D, u)
        pos, dpos, ok, st, tip, _ = _solve_beam(L, ei, k0, F, prob["wload"], prob["s_all"], M, state0, _N_NODES)
        status = np.where(ok, status, 2)
        res = {"u": u, "force": F, "status": status, "iterations": nfev, "positions": pos, "dpos": dpos,
               "state": st, "tip": tip}

    # uncertainty
    cov_s = None
    uncertainty = "residual"
    if prob["kappa"] is not None:
        sigma_a = _noise_std(noise_opt, calibration, est)
        if np.any(sigma_a > 0) or calibration is not None:
            cov_s = _shift_covariance(prob["kappa"], prob["lengths"], prob["d"],
                                      np.broadcast_to(sigma_a, (prob["lengths"].size,)), calibration)
            if np.any(np.trace(cov_s, axis1=-2, axis2=-1) > 0):
                uncertainty = "propagated"
            else:
                cov_s = None
    cov, chi2_dof = _covariance(prob, res, cov_s)

    status = res["status"]
    edge = np.flatnonzero(status == 4)
    boundary = []
    if edge.size:
        # stopped at the stability boundary: the load along the blocked step is not
        # identifiable, whatever the linearisation at the boundary says
        v = _apply(D[edge], res["blocked"][edge])
        v /= np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-300)[:, None]
        outer = v[:, :, None] * v[:, None, :]
        cov[edge] = np.where(np.abs(outer) > 1e-12, np.inf, cov[edge])
        boundary = [f"not identifiable along ({x:.3f}, {y:.3f}): trial loads leave the stable branch "
                    "(buckling) or the shape's linear range; best stable estimate, std inf" for x, y in v]
    diff = res["positions"] - p0
    residual = np.sqrt(np.einsum("bmi,bmi,m->b", diff, diff, prob["w"]) / prob["w"].sum())
    # a best stable shape this far off means no stable equilibrium matches the shape
    # (it needs a load beyond buckling), not a merely unidentifiable direction
    misfit = edge[residual[edge] > _BOUNDARY_MISFIT * L]
    for i in misfit:
        boundary[int(np.searchsorted(edge, i))] = (
            f"no stable equilibrium matches the shape: stopped at the stability boundary {residual[i] * 1e3:.3g} mm "
            "from it (a load beyond buckling?)")
    status[misfit] = 3
    success = (status == 1) | (status == 4)
    force = np.where(success[:, None], res["force"], np.nan)
    messages = np.full(B, _OK, dtype=object)
    messages[status == 2] = "beam model fails (buckling or no equilibrium) at every trial force"
    messages[status == 3] = ("no convergence in the iteration limit" if method == "fast"
                             else "optimizer did not converge")
    for i, text in zip(edge, boundary):
        messages[i] = text
    if not success.all() and strict:
        first = messages[~success][0]
        raise ConvergenceError(f"{int((~success).sum())} of {B} force estimate(s) failed; first: {first}")
    std = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    std = np.where(success[:, None], std, np.nan)
    cov = np.where(success[:, None, None], cov, np.nan)
    message = messages.astype(str).reshape(batch) if batch else str(messages[0])
    return ForceEstimate(
        force_n=force.reshape(*batch, 2),
        std_n=std.reshape(*batch, 2),
        covariance_n2=cov.reshape(*batch, 2, 2),
        residual_m=residual.reshape(batch),
        success=success.reshape(batch),
        message=message,
        iterations=np.asarray(res["iterations"]).reshape(batch),
        wall_time_s=time.perf_counter() - t_start,
        method=method,
        constraint=constraint,
        uncertainty=uncertainty,
        tip_position_m=res["tip"].reshape(*batch, 2),
        state=res["state"].reshape(*batch, res["state"].shape[-1]),
        guess_n=(prob["ffix"] + _apply(D, guess)).reshape(*batch, 2),
        chi2_per_dof=np.where(success, chi2_dof, np.nan).reshape(batch),
    )


