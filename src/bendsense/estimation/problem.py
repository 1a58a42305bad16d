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
from numba import njit
from numba.experimental import structref

from bendsense import _jit
from bendsense.choices import CONSTRAINTS
from bendsense.errors import ArgumentError
from bendsense.estimation.uncertainty import tip_angle_weights
from bendsense.mechanics import _beam_kernels as bk
from bendsense.shape import _kernels as shape_kernels
from bendsense.shape import pcc
from bendsense.validation import float_array

__all__ = ["CONSTRAINTS", "Buffers", "BuffersRef", "Frames", "FramesRef", "Outputs", "Problem", "ProblemRef",
           "Reference", "Target", "Workspace", "WorkspaceRef", "constraint_basis", "quadrature", "reference", "points",
           "chebyshev_nodes_m"]

POSITIONS, ANGLES = 0, 1  # codes of bendsense.choices.OBJECTIVES in the kernels

#: Chebyshev–Lobatto nodes of the estimate's beam. Against a 40-node solve over 15–120 kPa
#: and tip loads up to 0.3 N, 16 nodes are within 4e-9 rad in angle and 3e-10 m in position
#: (20 nodes, the default of :func:`bendsense.mechanics.beam.solve_beam`: 2e-11 rad), some six orders
#: below the sensor's noise, and the 15 × 15 Newton systems cost half the 19 × 19 ones.
N_NODES = 16


class Reference(NamedTuple):
    """The reconstructed shape as the estimate compares it (batched over leading axes ``...``).

    The comparison arc lengths ``s`` (M,) with weights ``w`` over ``[0, Lc]``. A PCC
    shape is its segment curvatures ``kappa`` (..., N) on ``lengths`` (N,) with the
    per-grid constants ``grid`` (:func:`_pcc_grid`); the compiled kernels make its points
    frame by frame (:func:`pcc_reference`). A shape given by points brings them: ``p0``
    (..., M, 2), the tangent angle ``phi`` (..., M) and curvature ``kappa_s`` (..., M)
    at them (for the moment-balance start), the tip angle ``tip_shape`` (...) and the
    angle at the beam's nodes ``state`` (..., n) (its Newton start); :func:`points`
    fills those of a PCC shape.
    """

    s: np.ndarray
    w: np.ndarray
    Lc: float
    batch_shape: tuple
    kappa: np.ndarray | None = None
    lengths: np.ndarray | None = None
    grid: dict | None = None
    p0: np.ndarray | None = None
    phi: np.ndarray | None = None
    kappa_s: np.ndarray | None = None
    tip_shape: np.ndarray | None = None
    state: np.ndarray | None = None


class Frames(NamedTuple):
    """Per-frame inputs of the compiled estimate (B frames, unused fields empty; the kernels hold a FramesRef)."""

    kappa: np.ndarray  # (B, N) segment curvatures of a PCC shape [1/m]
    p0: np.ndarray  # (B, M, 2) points of a shape given by points [m]
    phi_end: np.ndarray  # (B,) its tangent angle at the last point [rad]
    kappa_s: np.ndarray  # (B, M) its curvature at the points [1/m]
    state: np.ndarray  # (B, n) its angle at the beam's nodes [rad]
    tip_shape: np.ndarray  # (B,) its tip angle [rad]
    ei: np.ndarray  # (B,) EI(P) [N m²]
    k0: np.ndarray  # (B,) K0(P) [1/m]
    theta: np.ndarray  # (B,) free-motion tip angle [rad]
    model_cov: np.ndarray  # (B, 2, 2) covariance of (K0, EI) from the identified parameters [1/m², N m³]
    contact: np.ndarray  # (B,) σ_c = s_c / L of the force's point (1: the tip)


class Problem(NamedTuple):
    """Constants of an estimate, shared by every frame (their fields; the kernels hold a :class:`ProblemRef`)."""

    pcc: bool  # frames are PCC curvatures (else points)
    kind: int  # constraint kind (:func:`constraint_kind`)
    direction: np.ndarray  # (2,) fixed direction of a 1-D constraint
    follower_angle: float  # [rad]
    shape_angle: bool  # D follows the reconstructed tip angle (∂D/∂φ_L enters the covariance)
    seg_fk: np.ndarray  # (M + n,) segment of the comparison and beam nodes (PCC)
    sigma_fk: np.ndarray  # (M + n,) their arc length within it [m]
    beyond: np.ndarray  # (n,) arc length of the beam's nodes beyond the sensor [m]
    tip_weights: np.ndarray  # (N,) φ(L) = tip_weights · κ (φ(s_c) for a contact's problem: contact_problem)
    lengths: np.ndarray  # (N,) segment lengths [m]
    gap: float  # strip gap d [m]
    seg: np.ndarray  # (M,) segment of each comparison node (a shape given by points: one per point)
    sigma: np.ndarray  # (M,) its arc length within it [m]
    dphi_ds: np.ndarray  # (N,) ∂φ(L)/∂S (∂φ(s_c)/∂S for a contact)
    noise: bool  # a noise model is known (the shift covariance, bendsense.calibration.shift_errors)
    s: np.ndarray  # (M,) comparison arc lengths [m]
    w: np.ndarray  # (M,) their quadrature weights [m]
    L: float  # actuator length [m]
    wload: np.ndarray  # (2,) distributed load [N/m]
    ffix: np.ndarray  # (2,) fixed part of the force [N]
    lower: np.ndarray  # (k,) lower bounds of u
    xtol: float  # Gauss–Newton step tolerance [N]
    max_iter: int
    PQ: np.ndarray  # (M, n) positions at the comparison nodes from the nodes' sin/cos
    q: np.ndarray  # (n,) the same for the tip
    objective: int  # POSITIONS or ANGLES (:data:`OBJECTIVES`)
    PQ_fit: np.ndarray  # the rows of PQ evaluated while fitting (none for the angles objective)
    coils: np.ndarray  # (Nc,) the coils on the actuator (angles objective)
    PA: np.ndarray  # (Nc, n) the tangent angle at the coils from the nodes' angles
    sw: np.ndarray  # (R,) square root of each fitted row's weight: (2M,) positions, (Nc,) ones for angles
    jump_floor: float  # a trial response this far from its linear prediction is no branch jump [m or rad]
    contact: bool  # load="contact": the window payload carries ∂y/∂s_c (kernels.contact_jacobian)


@functools.lru_cache(maxsize=16)
def chebyshev_nodes_m(length_m: float, n_nodes: int = N_NODES) -> np.ndarray:
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
def _pcc_grid(lengths: tuple, n_points: int, beam_length_m: float):
    """Per-grid constants of a PCC reference (cached, read-only) on ``[0, Lc]``, ``Lc = min(L_N, L)``.

    The quadrature nodes, weights, segment and local arc length of each node; the nodes
    followed by the beam's nodes clipped to the sensor length, with the PCC kinematics'
    own grid of them; the tip-angle weights (:func:`tip_angle_weights`) and the arc
    length of each beam node beyond the sensor (where the last curvature is carried on).
    ``lengths``: the segment lengths as a tuple of float (the config's own, hashed as it is).
    """
    lengths = np.array(lengths, dtype=float)
    Lc = min(float(lengths.sum()), beam_length_m)
    s, w = quadrature(lengths, Lc, n_points)
    bounds = np.concatenate(([0.0], np.cumsum(lengths)))
    seg = np.clip(np.searchsorted(bounds[1:-1], s, side="left"), 0, lengths.size - 1)
    sc = chebyshev_nodes_m(beam_length_m, N_NODES)
    s_fk = np.concatenate([s, np.minimum(sc, bounds[-1])])
    fk = pcc._grid(lengths, s_fk)
    out = {"s": s, "w": w, "seg": seg, "sigma": s - bounds[seg], "seg_fk": fk.seg, "sigma_fk": fk.sigma,
           "lengths": fk.lengths, "tip_weights": tip_angle_weights(lengths, beam_length_m),
           "beyond": np.maximum(sc - float(lengths.sum()), 0.0)}
    for a in out.values():
        a.setflags(write=False)
    out["Lc"] = Lc
    return out


_NONE, _FIXED, _NORMAL, _FOLLOWER = 0, 1, 2, 3  # kinds of D: identity, a fixed direction, tip-angle bound
TIP_ANGLE_KINDS = (_NORMAL, _FOLLOWER)


def constraint_kind(constraint: str, direction=(0.0, -1.0)):
    """The compiled basis' arguments of a constraint: (kind, k, fixed direction (2,))."""
    if constraint == "none":
        return _NONE, 2, np.zeros(2)
    if constraint in ("vertical", "horizontal", "direction"):
        d = {"vertical": (0.0, 1.0), "horizontal": (1.0, 0.0)}.get(constraint, direction)
        return _FIXED, 1, np.array(d, dtype=float)
    if constraint in ("normal", "follower"):
        return (_NORMAL if constraint == "normal" else _FOLLOWER), 1, np.zeros(2)
    raise ArgumentError(f"constraint: must be one of {', '.join(CONSTRAINTS)}, got {constraint!r}")


@njit(cache=True)
def basis(kind, phi_tip, direction, follower_angle, D, dD):
    """D (2, k) of ``F = D u`` and ∂D/∂φ_L into ``dD`` for one frame (module docstring)."""
    if kind == _NONE:
        D[0, 0], D[0, 1], D[1, 0], D[1, 1] = 1.0, 0.0, 0.0, 1.0
        dD[:, :] = 0.0
    elif kind == _FIXED:
        D[0, 0], D[1, 0] = direction[0], direction[1]
        dD[:, :] = 0.0
    elif kind == _NORMAL:
        c, s = math.cos(phi_tip), math.sin(phi_tip)
        D[0, 0], D[1, 0], dD[0, 0], dD[1, 0] = -c, s, s, c
    else:
        a = phi_tip - follower_angle
        c, s = math.cos(a), math.sin(a)
        D[0, 0], D[1, 0], dD[0, 0], dD[1, 0] = s, c, c, -s


@njit(cache=True)
def _bases(kind, phi_tip, direction, follower_angle, D, dD):
    for b in range(phi_tip.size):
        basis(kind, phi_tip[b], direction, follower_angle, D[b], dD[b])


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
    kind, k, fixed = constraint_kind(constraint, direction)
    phi = np.asarray(tip_angle_rad, dtype=float)
    D, dD = np.empty((phi.size, 2, k)), np.empty((phi.size, 2, k))
    _bases(kind, np.ascontiguousarray(phi.reshape(-1)), fixed, float(follower_angle_rad), D, dD)
    D, dD = D.reshape(*phi.shape, 2, k), dD.reshape(*phi.shape, 2, k)
    return D, (dD if kind in TIP_ANGLE_KINDS else None)


@njit(cache=True)
def contact_problem(pb, sc, ref):
    """The frame's problem for a force at σ_c = s_c/L < 1: ``pb`` with the grid's sampling and the angle at s_c.

    The sampling of the beam's nodes (``PA``, ``PQ``, ``PQ_fit``, ``q``) follows the
    contact's two Chebyshev domains (:func:`bendsense.mechanics._beam_kernels.contact_sampling`);
    ``tip_weights`` and ``dphi_ds`` give the reconstructed shape's angle at s_c
    (φ(s_c) = c · κ, the last curvature carried on beyond the sensor) and its gradient
    by the shifts, for the constraints at s_c; ``pb``'s own for σ_c ≥ 1. A :class:`Problem` of ``pb``'s
    fields (a :class:`ProblemRef`): the kernels make a ProblemRef of it, a caller from Python gets it whole.
    """
    c, dphi, PQ, q, PQ_fit, PA = pb.tip_weights, pb.dphi_ds, pb.PQ, pb.q, pb.PQ_fit, pb.PA
    if sc < 1.0:
        n = pb.q.size
        s_c = sc * pb.L
        N = pb.lengths.size
        c = np.zeros(N)
        b = 0.0
        for i in range(N):
            c[i] = min(max(s_c - b, 0.0), pb.lengths[i]) if i < N - 1 else max(s_c - b, 0.0)
            b += pb.lengths[i]
        dphi = np.empty(N)
        for i in range(N):
            dphi[i] = c[i] / (pb.lengths[i] * pb.gap) - (c[i + 1] / (pb.lengths[i + 1] * pb.gap) if i + 1 < N
                                                         else 0.0)
        M = pb.s.size
        PQ, P, q = np.empty((M, n)), np.empty((M, n)), np.empty(n)
        bk.contact_sampling(sc, ref, pb.s / pb.L, P, PQ, q)
        Nc = pb.coils.size
        PA, PQc = np.empty((Nc, n)), np.empty((Nc, n))
        ends = np.cumsum(pb.lengths) / pb.L
        coil = np.empty(Nc)
        for a in range(Nc):
            coil[a] = ends[pb.coils[a]]
        bk.contact_sampling(sc, ref, coil, PA, PQc, q)
        PQ_fit = np.ascontiguousarray(PQ if pb.PQ_fit.shape[0] > 0 else PQ[:0])
    return Problem(pb.pcc, pb.kind, pb.direction, pb.follower_angle, pb.shape_angle, pb.seg_fk, pb.sigma_fk, pb.beyond,
                   c, pb.lengths, pb.gap, pb.seg, pb.sigma, dphi, pb.noise, pb.s, pb.w, pb.L, pb.wload, pb.ffix,
                   pb.lower, pb.xtol, pb.max_iter, PQ, q, pb.objective, PQ_fit, pb.coils, PA, pb.sw, pb.jump_floor,
                   pb.contact)


@njit(cache=True)
def contact_state(state0, tip_sigma, sigma, out):
    """A Newton start on a contact's nodes ``sigma`` (n,): ``state0`` on the tip grid's ``tip_sigma``, interpolated."""
    j = 0
    for i in range(sigma.size):
        while j < tip_sigma.size - 2 and tip_sigma[j + 1] < sigma[i]:
            j += 1
        t = (sigma[i] - tip_sigma[j]) / (tip_sigma[j + 1] - tip_sigma[j])
        out[i] = state0[j] * (1.0 - t) + state0[j + 1] * t


@njit(cache=True)
def pcc_reference(kappa, lengths, seg_fk, sigma_fk, beyond, tip_weights, pos, ang, kappa_s, state):
    """The reference of one PCC frame: points and angles at the comparison nodes, angles at the beam's.

    ``seg_fk``, ``sigma_fk`` (M + n,) place the M comparison nodes followed by the n beam
    nodes (clipped to the sensor) on the segments; writes ``pos`` (M, 2) and ``ang`` (M,)
    (of buffers of M + n rows), the curvature ``kappa_s`` (M,) at the comparison nodes and
    the beam's Newton start ``state`` (n,) (the shape's angle at its nodes, the last
    curvature carried on by ``beyond``; no points there, no trigonometry). Returns the
    shape's tip angle at the actuator tip.
    """
    n_seg = lengths.size
    M = kappa_s.size
    theta = np.empty(n_seg)
    start = np.empty(n_seg)  # each segment's start angle
    tip = np.empty(2)
    acc = 0.0
    for i in range(n_seg):
        theta[i] = kappa[i] * lengths[i]
        start[i] = acc
        acc += theta[i]
    shape_kernels.frame_kinematics(kappa, theta, 0.0, seg_fk[:M], sigma_fk[:M], lengths, pos, ang, tip)
    for j in range(M):
        kappa_s[j] = kappa[seg_fk[j]]
    for j in range(state.size):
        g = seg_fk[M + j]
        state[j] = start[g] + kappa[g] * sigma_fk[M + j] + kappa[n_seg - 1] * beyond[j]
    tip_angle = 0.0
    for i in range(n_seg):
        tip_angle += kappa[i] * tip_weights[i]
    return tip_angle


def reference(shape, config, s_opt, n_points, L_act) -> Reference:
    """Reference shape p⁰ at the comparison nodes and what the uncertainty needs."""
    kappa = None
    array = isinstance(shape, np.ndarray)  # curvatures (the common case) or positions with s_m
    if s_opt is not None:
        pos = float_array("shape", shape)
        s_in = float_array("s_m", s_opt)
        angle = None
    elif not array and hasattr(shape, "curvature_per_m") and hasattr(shape, "lengths_m"):
        kappa = np.asarray(shape.curvature_per_m, dtype=float)
        lengths = tuple(np.asarray(shape.lengths_m, dtype=float).tolist())
    elif not array and hasattr(shape, "positions_m") and hasattr(shape, "s_m"):
        pos = np.asarray(shape.positions_m, dtype=float)
        s_in = np.asarray(shape.s_m, dtype=float)
        angle = getattr(shape, "angle_rad", None)
    else:
        kappa = float_array("shape", shape)
        lengths = config.sensor.segment_lengths_m
        if kappa.ndim == 0 or kappa.shape[-1] != len(lengths):
            raise ArgumentError(
                f"shape: expected a Shape, a BeamSolution or curvatures (..., {len(lengths)}) [1/m], "
                f"got shape {kappa.shape}"
            )
    if kappa is not None:
        # one frame: κ·κ is finite for finite κ below ~1e154 (0.3 against 1 µs); else the exact test
        if not (kappa.ndim == 1 and math.isfinite(kappa.dot(kappa))) and not np.isfinite(kappa).all():
            raise ArgumentError("shape.curvature_per_m: must be finite")
        grid = _pcc_grid(lengths, n_points, L_act)
        return Reference(s=grid["s"], w=grid["w"], Lc=grid["Lc"], batch_shape=kappa.shape[:-1], kappa=kappa,
                         lengths=grid["lengths"], grid=grid)
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
    return Reference(s=s, w=pcc._trapezoid_weights(s), Lc=float(s[-1]), batch_shape=p0.shape[:-2], p0=p0, phi=phi,
                     kappa_s=np.gradient(phi, s, axis=-1, edge_order=2), tip_shape=phi[..., -1], state=state)


@njit(cache=True)
def _pcc_references(kappa, lengths, seg_fk, sigma_fk, beyond, tip_weights, pos, ang, kappa_s, state, tip):
    for b in range(kappa.shape[0]):
        tip[b] = pcc_reference(kappa[b], lengths, seg_fk, sigma_fk, beyond, tip_weights, pos[b], ang[b], kappa_s[b],
                               state[b])


def points(ref: Reference) -> Reference:
    """``ref`` with the points, angles, curvatures and beam start of its PCC frames filled in."""
    if ref.kappa is None:
        return ref
    g, n = ref.grid, ref.lengths.size
    kappa = np.ascontiguousarray(ref.kappa.reshape(-1, n))
    B, M, m = kappa.shape[0], ref.s.size, g["seg_fk"].size
    pos, ang, ks = np.empty((B, m, 2)), np.empty((B, m)), np.empty((B, M))
    state, tip = np.empty((B, m - M)), np.empty(B)
    _jit.call(_pcc_references, kappa, g["lengths"], g["seg_fk"], g["sigma_fk"], g["beyond"], g["tip_weights"], pos,
              ang, ks, state, tip)
    batch = ref.batch_shape
    return ref._replace(p0=pos[:, :M].reshape(*batch, M, 2), phi=ang[:, :M].reshape(*batch, M),
                        kappa_s=ks.reshape(*batch, M), tip_shape=tip.reshape(batch), state=state.reshape(*batch, -1))


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once


class Workspace(NamedTuple):
    """Buffers of one beam evaluation (their fields; the kernels hold a :class:`WorkspaceRef`)."""

    #: positions (M, 2) at the comparison nodes
    pos: np.ndarray
    #: ∂p/∂F (M, 2, 2)
    dpos: np.ndarray
    #: the beam's state (n,)
    state: np.ndarray
    #: the tip (+ ∂tip/∂F) (6,)
    tip: np.ndarray
    #: ∂φ_nodes/∂(Fx, Fy, K0, EI, s_c) (n, 5)
    dphi: np.ndarray
    #: the fitted response y (R,): the positions flattened, or the tangent angles at the coils
    y: np.ndarray
    #: ∂y/∂F (R, 2)
    dy: np.ndarray
    #: the whitened residual and its Jacobian by F (R, 3) (:func:`~bendsense.estimation._kernels.whitened`)
    e: np.ndarray
    #: the beam solver's J⁻¹ columns (n - 1, 4) (:func:`bendsense.mechanics._beam_kernels.solve_frame`)
    extra: np.ndarray
    #: the beam solver's own buffers (:func:`bendsense.mechanics._beam_kernels.solver_work`)
    solver: tuple


class Target(NamedTuple):
    """What a frame's fit compares with (:func:`whitened`)."""

    y0: np.ndarray  #: the measured response (R,): the angles at the coils, or the reference positions flattened
    sw: np.ndarray  #: √w (R,): the quadrature weights of the positions objective
    Lw: np.ndarray  #: the Cholesky factor of the angles' covariance (R, R), when ``whiten``
    whiten: bool  #: whether the angles are whitened by ``Lw`` (a noise model is known)


class Buffers(NamedTuple):
    """Per-thread buffers of :func:`setup`: one frame's inputs of the fit (the kernels hold a :class:`BuffersRef`)."""

    pos: np.ndarray  #: the reference shape's points (m, 2)
    ang: np.ndarray  #: its angles (m,)
    ks: np.ndarray  #: κ at the beam's nodes
    state: np.ndarray  #: the beam's start (n,)
    D: np.ndarray  #: the constraint basis (2, k)
    dD: np.ndarray  #: ∂D/∂φ_L (2, k)
    cov_s: np.ndarray  #: Σ_S, the shifts' covariance (N, N)
    no_kappa: np.ndarray  #: κ of a shape given by points: zeros (N,)
    y0: np.ndarray  #: the target's measured response (R,)
    Lw: np.ndarray  #: the target's Cholesky factor (R, R), or (1, 1)
    noise_var: np.ndarray  #: Σ_S's signal-noise variances (N,)
    shifts: np.ndarray  #: the measured shifts (N,) [m]
    on_grid: np.ndarray  #: the reference's angles on a contact's nodes (n,)
    guess: np.ndarray  #: the iteration's k-vectors (11, k) (:func:`~bendsense.estimation._kernels.estimate_block`)
    gram: np.ndarray  #: the iteration's 2-vectors and 2×2 matrices (7, 2, 2); row 6 stays zero (a zero force)
    state_guess: np.ndarray  #: a trial's first-order state (n,)
    H: np.ndarray  #: the reduced Gauss–Newton matrix (k, k)


class Outputs(NamedTuple):
    """What the estimate kernels write per frame (B frames), in the order of the plain tuple they are called with."""

    force: np.ndarray  #: (B, 2) [N]
    cov: np.ndarray  #: (B, 2, 2) [N²]
    status: np.ndarray  #: (B,) int64 codes (:class:`bendsense.status.Status`)
    iters: np.ndarray  #: (B,) int64
    residual: np.ndarray  #: (B,) [m]
    chi2: np.ndarray  #: (B,) χ²/dof
    p_value: np.ndarray  #: (B,)
    guess_n: np.ndarray  #: (B, 2) the moment-balance start [N]
    state: np.ndarray  #: (B, n) the beam's state
    tip: np.ndarray  #: (B, 2) [m]
    direction: np.ndarray  #: (B, 2) the direction a non-identifiable load lies along
    std: np.ndarray  #: (B, 2) [N]
    parts: np.ndarray  #: (B, 3, 2, 2) the budget's parts [N²]
    success: np.ndarray  #: (B,) bool
    payload: np.ndarray  #: (B, coils, 6) the window test's payload (:func:`payload`)
    shifts: np.ndarray  #: (B, N) the measured shifts [m]


@structref.register
class _ProblemRefType(_jit.StructType):
    pass


@structref.register
class _FramesRefType(_jit.StructType):
    pass


@structref.register
class _WorkspaceRefType(_jit.StructType):
    pass


@structref.register
class _BuffersRefType(_jit.StructType):
    pass


class ProblemRef(structref.StructRefProxy):
    """A :class:`Problem` as the kernels hold it: one object, not a tuple of its 20 arrays.

    A compiled function takes a reference to every array of a tuple it is given (an
    atomic count in and one out), and numba copies a tuple's every field wherever it is
    passed; this is one pointer. Made in the kernels from a Problem's fields
    (``ProblemRef(*pb)``); its fields are read as a Problem's. :class:`FramesRef`,
    :class:`WorkspaceRef` and :class:`BuffersRef` are the same of the other structures.
    """


class FramesRef(structref.StructRefProxy):
    """A :class:`Frames` as the kernels hold it (:class:`ProblemRef`)."""


class WorkspaceRef(structref.StructRefProxy):
    """A :class:`Workspace` as the kernels hold it (:class:`ProblemRef`)."""


class BuffersRef(structref.StructRefProxy):
    """A :class:`Buffers` as the kernels hold it (:class:`ProblemRef`)."""


structref.define_proxy(ProblemRef, _ProblemRefType, list(Problem._fields))
structref.define_proxy(FramesRef, _FramesRefType, list(Frames._fields))
structref.define_proxy(WorkspaceRef, _WorkspaceRefType, list(Workspace._fields))
structref.define_proxy(BuffersRef, _BuffersRefType, list(Buffers._fields))
