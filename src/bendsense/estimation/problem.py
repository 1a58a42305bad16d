"""Problem set-up of the force estimate: the reference shape, the quadrature and the constraints.

The estimate compares the model shape with the reconstructed shape ``p⁰(s)`` at the same
arc length over ``[0, Lc]``, ``Lc = min(L_sensor, L_actuator)`` (paper eq. 18). For a PCC
shape the integral is a composite Gauss–Legendre rule over the sensor segments (the PCC
shape is smooth inside a segment and its curvature jumps at the junctions); a shape given
by points is compared at its own points with trapezoid weights.

Constraints (DESIGN section 2) are linear parametrisations ``F = D u`` with ``D`` (2, k)
of orthonormal columns: ``none`` (D = I), ``vertical``, ``horizontal``, ``direction``,
``normal`` (contact force normal to the tip tangent, paper eq. 21: ``D = n_tip =
(−cos φ_L, sin φ_L)``) and ``follower`` (the tip tangent rotated counter-clockwise by
``follower_angle_rad``: ``D = (sin(φ_L − α), cos(φ_L − α))``). ``φ_L`` is the free-motion
tip angle (``tip_angle_source="model"``, the paper) or the reconstructed one (``"shape"``).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from bendsense.errors import ArgumentError

from bendsense.beam import DEFAULT_NODES
from bendsense.estimation.uncertainty import tip_angle_weights

__all__ = ["CONSTRAINTS", "Reference", "constraint_basis", "quadrature", "reference", "chebyshev_nodes_m"]

#: The force constraints (module docstring); the CLI's choices come from here.
CONSTRAINTS = ("none", "vertical", "horizontal", "direction", "normal", "follower")
_N_NODES = DEFAULT_NODES


class Reference(NamedTuple):
    """The reconstructed shape as the estimate compares it (batched over leading axes ``...``).

    ``p0`` (..., M, 2) points at the comparison arc lengths ``s`` (M,) with weights ``w``
    over ``[0, Lc]``; ``phi`` (..., M) and ``kappa_s`` (..., M) their tangent angle and
    curvature (for the moment-balance start); ``tip_shape`` (...) the shape's tip angle;
    ``state`` (..., n) the angle at the beam's nodes (its Newton start). For a PCC shape
    also the segment curvatures ``kappa`` (..., N), ``lengths`` (N,), and each point's
    segment ``seg`` and arc length in it ``sigma`` (M,); None for a shape given by points.
    """

    p0: np.ndarray
    s: np.ndarray
    w: np.ndarray
    Lc: float
    kappa: np.ndarray | None
    lengths: np.ndarray | None
    seg: np.ndarray | None
    sigma: np.ndarray | None
    tip_shape: np.ndarray
    phi: np.ndarray
    kappa_s: np.ndarray
    state: np.ndarray


@functools.lru_cache(maxsize=16)
def chebyshev_nodes_m(length_m: float, n_nodes: int = _N_NODES) -> np.ndarray:
    """Arc lengths of the fast beam solver's Chebyshev–Lobatto nodes, base first [m]."""
    j = np.arange(n_nodes)
    s = 0.5 * length_m * (1.0 - np.cos(np.pi * j / (n_nodes - 1)))
    s.setflags(write=False)
    return s


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
    own grid of them; the tip-angle weights (:func:`tip_angle_weights`) and the arc
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
           "tip_weights": tip_angle_weights(lengths, beam_length_m),
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


def reference(shape, config, s_opt, n_points, L_act) -> Reference:
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
        pos, phi, _, _ = pcc._kinematics(kappa, grid["grid"], 0.0)
        M = s.size
        # the beam's Newton start: the shape's angle at its nodes, the last curvature carried on
        state = phi[..., M:] + kappa[..., -1:] * grid["beyond"]
        return Reference(p0=pos[..., :M, :], s=s, w=grid["w"], Lc=Lc, kappa=kappa, lengths=lengths, seg=seg,
                         sigma=grid["sigma"], tip_shape=kappa @ grid["tip_weights"], phi=phi[..., :M],
                         kappa_s=kappa[..., seg], state=state)
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
    # the beam's Newton start: linear interpolation of φ, the end slope beyond the last point
    sc = chebyshev_nodes_m(L_act)
    j = np.clip(np.searchsorted(s, sc) - 1, 0, s.size - 2)
    t = (sc - s[j]) / (s[j + 1] - s[j])
    state = phi[..., j] * (1.0 - t) + phi[..., j + 1] * t
    state[..., 0] = 0.0
    return Reference(p0=p0, s=s, w=pcc._trapezoid_weights(s), Lc=float(s[-1]), kappa=None, lengths=None, seg=None,
                     sigma=None, tip_shape=phi[..., -1], phi=phi, kappa_s=np.gradient(phi, s, axis=-1, edge_order=2),
                     state=state)
