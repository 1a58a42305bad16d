"""Tip force estimation from a reconstructed shape (paper section IV-C, eq. 18 and 21).

The estimate is the force whose beam shape (paper eq. 13–17) is closest to the
reconstructed shape ``p⁰(s)`` at the frame's pressure::

    F̂ = argmin_F ∫₀^Lc ‖p⁰(s) − p(s; F, P)‖² ds,   F = F_fixed + D u,   u ≥ lower   (eq. 18)

``K0(P)`` comes from the free-bending model (eq. 8–12), ``EI(P)`` from the stiffness
model (eq. 15), the distributed load from ``config.weight_per_length_n_per_m``.

The package reads as the algorithm:

- :mod:`~bendsense.estimation.problem`: the reference shape, quadrature and constraints;
- :mod:`~bendsense.estimation.kernels`: the compiled per-frame estimate (moment-balance
  start, trust-region Gauss–Newton around the spectral beam solver), batched by a
  ``prange`` loop over frames;
- :mod:`~bendsense.estimation.uncertainty`: propagation of the shift errors and the χ²;
- :mod:`~bendsense.estimation.paper`: the paper's shooting + ``scipy.optimize`` baseline;
- :mod:`~bendsense.estimation.result`: :class:`ForceEstimate` and the status messages.

Poorly identifiable loads (an axial load on a nearly straight actuator) stop at the best
stable point with ``success=True``, the message ``"not identifiable along (x, y): ..."``
and an infinite standard deviation along that direction.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from bendsense import _jit
from bendsense import beam as _beam
from bendsense.errors import ArgumentError, ConvergenceError
from bendsense.plausibility import pressure_range_step
from bendsense.estimation import kernels as _kernels
from bendsense.estimation.paper import paper_fit
from bendsense.estimation.problem import CONSTRAINTS, chebyshev_nodes_m, constraint_basis, quadrature, reference
from bendsense.estimation.result import ForceEstimate, messages
from bendsense.estimation.uncertainty import noise_std as _signal_noise
from bendsense.estimation.uncertainty import shift_covariance, tip_angle_shift_gradient
from bendsense.status import Status

__all__ = [
    "ForceEstimate",
    "estimate_force",
    "constraint_basis",
    "quadrature",
    "chebyshev_nodes_m",
    "CONSTRAINTS",
    "METHODS",
    "OBJECTIVES",
    "XTOL_N",
]

METHODS = ("fast", "paper")
#: Residuals the fit can minimise (the positions of paper eq. 18).
OBJECTIVES = ("positions",)
#: Gauss–Newton stops when its step is below this [N].
XTOL_N = 1e-10
MAX_ITER = 100
_CHAIN = 32  # consecutive frames per warm-started block along a batch
_N_NODES = _beam.DEFAULT_NODES


def _c(a, dtype=float):
    """A C-contiguous, writable array: the one array type the kernels are compiled for."""
    if type(a) is np.ndarray and a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=dtype, order="C")


def _models(config):
    from bendsense.actuator import FreeBendingModel

    cached = getattr(config, "_free_bending_cache", None)
    if cached is None:
        cached = FreeBendingModel.from_config(config)
        try:
            object.__setattr__(config, "_free_bending_cache", cached)
        except (AttributeError, TypeError):
            pass
    return cached


# first step, kept apart from the estimator: frames outside the actuator's pressure range get no force
@pressure_range_step
def estimate_force(shape, pressure_pa, config=None, constraint: str | None = "none", method: str | None = "fast", *,
                   objective: str = "positions", push_only: bool | None = None, tip_angle_source: str | None = None,
                   direction=None, follower_angle_rad: float | None = None, initial_force_n=None,
                   initial: ForceEstimate | None = None, warm_start: bool = True, noise_std=None, calibration=None,
                   strict: bool = False, s_m=None, n_points: int | None = None, xtol_n: float = XTOL_N,
                   max_iter: int = MAX_ITER) -> ForceEstimate:
    """Tip force from a reconstructed shape and the pressure (paper eq. 18, 21).

    Parameters
    ----------
    shape : Shape, BeamSolution or array_like
        A :class:`~bendsense.pcc.Shape` (its curvatures and segment lengths are used),
        segment curvatures (..., N) [1/m] on ``config.sensor``, a shape given by points
        (any object with ``s_m`` (M,) and ``positions_m`` (..., M, 2)), or positions
        (..., M, 2) [m] with ``s_m``. Leading axes are frames.
    pressure_pa : array_like, shape (...)
        Pressure of each frame [Pa]; broadcasts against the shape's batch axes.
    config : Config, optional
        ``None``: the paper's prototype (:func:`bendsense.load_config`).
    constraint : str
        One of :data:`CONSTRAINTS` (:mod:`~bendsense.estimation.problem`); None: the config's.
    method : {"fast", "paper"}
        The compiled Gauss–Newton core, or the paper's shooting + Nelder–Mead / SLSQP.
    objective : {"positions"}
        The residual fitted (paper eq. 18 on the PCC positions).
    push_only : bool
        ``u ≥ 0`` for the 1-D constraints (default ``config.estimation.push_only``).
    tip_angle_source, direction, follower_angle_rad
        ``"model"`` or ``"shape"`` tip angle for ``normal``/``follower``; the unit
        direction (2,) of ``direction``; the follower angle [rad]. Defaults from the config.
    initial_force_n : array_like, shape (..., 2), optional
        Start of every frame [N].
    initial : ForceEstimate, optional
        The previous estimate (real-time use): its offset from its own moment-balance
        start corrects this frame's start.
    warm_start : bool
        Chain frames along the batch: a frame's start is corrected by its predecessor's.
    noise_std : float or array_like (N,), optional
        Signal noise per channel [signal units]; default ``calibration.noise_std`` if
        nonzero, else ``config.estimation.signal_noise_std``.
    calibration : Calibration, optional
        Maps signal noise to shift errors (its slopes) and adds its model error.
    strict : bool
        Raise :class:`~bendsense.errors.ConvergenceError` if a frame fails.
    s_m : array_like, shape (M,), optional
        Arc lengths of positions given as an array [m].
    n_points : int, optional
        Quadrature nodes (default ``config.estimation.n_points``).
    xtol_n, max_iter : float, int
        Stopping rule of the Gauss–Newton iteration.

    Returns
    -------
    ForceEstimate
        Frames that fail have ``success=False``, NaN force and a message. Frames whose
        pressure lies outside ``config.actuator.pressure_range_pa`` have no force,
        ``success=False`` and the message ``"pressure_out_of_range: ..."``
        (:func:`bendsense.plausibility.pressure_range_step`).

    Raises
    ------
    ArgumentError
        For a bad argument (the message names it).
    ConvergenceError
        With ``strict=True`` when a frame fails.
    """
    t_start = time.perf_counter()
    if config is None:
        from bendsense.config import load_config

        config = load_config()
    est = config.estimation
    constraint = est.constraint if constraint is None else constraint
    method = est.method if method is None else method
    if constraint not in CONSTRAINTS:
        raise ArgumentError(f"constraint: must be one of {', '.join(CONSTRAINTS)}, got {constraint!r}")
    if method not in METHODS:
        raise ArgumentError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    if objective not in OBJECTIVES:
        raise ArgumentError(f"objective: must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    push_only = bool(est.push_only if push_only is None else push_only)
    source = est.tip_angle_source if tip_angle_source is None else tip_angle_source
    if source not in ("model", "shape"):
        raise ArgumentError(f"tip_angle_source: must be one of model, shape, got {source!r}")
    direction = np.asarray(est.direction if direction is None else direction, dtype=float)
    if direction.shape != (2,) or not np.all(np.isfinite(direction)) or abs(np.hypot(*direction) - 1.0) > 1e-6:
        raise ArgumentError(f"direction: expected a unit vector (2,), got {direction.tolist()}")
    follower = float(est.follower_angle_rad if follower_angle_rad is None else follower_angle_rad)
    n_points = int(est.n_points if n_points is None else n_points)
    if n_points < 3:
        raise ArgumentError(f"n_points: must be >= 3, got {n_points}")
    if push_only and constraint == "none":
        raise ArgumentError("push_only: only for the 1-D constraints (vertical, horizontal, direction, normal, "
                         "follower), got constraint='none'")
    if initial is not None and not isinstance(initial, ForceEstimate):
        raise ArgumentError(f"initial: expected a ForceEstimate, got {type(initial).__name__}")

    L = float(config.actuator.length_m)
    ref = reference(shape, config, s_m, n_points, L)
    P = np.asarray(pressure_pa, dtype=float)
    if not np.isfinite(P).all():
        raise ArgumentError(f"pressure_pa: must be finite, got {pressure_pa!r}")
    try:
        batch = np.broadcast_shapes(ref.p0.shape[:-2], P.shape)
    except ValueError:
        raise ArgumentError(f"pressure_pa: shape {P.shape} does not broadcast against the shape's frames "
                         f"{ref.p0.shape[:-2]}") from None
    B = math.prod(batch)
    M = ref.s.size

    def flat(a, tail=(), dtype=float):
        a = np.asarray(a)
        if a.shape != (B, *tail):
            a = a.reshape(B, *tail) if a.size == B * math.prod(tail) else np.broadcast_to(a, (*batch, *tail)).reshape(
                B, *tail)
        return _c(a, dtype)

    Pf = flat(P)
    model = _models(config)
    theta = flat(model.bending_angle_rad(Pf))  # free-motion tip angle
    k0 = theta / model.length_m  # as model.tip_curvature_per_m
    ei = flat(config.stiffness.ei_nm2(Pf))
    if not np.all(ei > 0):
        raise ArgumentError(f"pressure_pa: EI(P) must be > 0, got {float(ei.min())!r} N·m² "
                         f"at {float(Pf[np.argmin(ei)])!r} Pa")
    phi_L = theta if source == "model" else flat(ref.tip_shape)
    D, dD = constraint_basis(constraint, phi_L, direction=direction, follower_angle_rad=follower)
    k = D.shape[-1]
    D = flat(D, (2, k))
    has_dD = dD is not None and source == "shape"
    dD = flat(dD, (2, k)) if has_dD else np.zeros((B, 2, k))
    lower = np.full(k, 0.0 if push_only else -np.inf)
    ffix = np.zeros((B, 2))
    wload = _c(np.array(config.weight_per_length_n_per_m, dtype=float))
    p0 = flat(ref.p0, (M, 2))

    # starting points: the moment-balance guess (in the kernel), corrected by the previous
    # estimate's offset from its own guess, or a given force
    u_init = np.zeros((B, k))
    offset = np.zeros((B, k))
    use_guess = True
    chain = warm_start
    if initial is not None and initial_force_n is None and initial.guess_n is not None:
        prev_f = flat(np.asarray(initial.force_n, dtype=float), (2,))
        prev_g = flat(np.asarray(initial.guess_n, dtype=float), (2,))
        good = np.isfinite(prev_f).all(axis=1) & np.isfinite(prev_g).all(axis=1)
        offset[good] = np.einsum("bij,bi->bj", D[good], prev_f[good] - prev_g[good])
        chain = False
    elif initial is not None and initial_force_n is None:
        initial_force_n = initial.force_n
    if initial_force_n is not None and (initial is None or initial.guess_n is None):
        f0 = np.asarray(initial_force_n, dtype=float)
        if f0.shape[-1:] != (2,) or not np.all(np.isfinite(f0)):
            raise ArgumentError(f"initial_force_n: expected finite values of shape (..., 2), got shape {f0.shape}")
        u_init = np.einsum("bij,bi->bj", D, flat(f0, (2,)) - ffix)
        use_guess = False
        chain = False

    noise = _noise_model(ref, B, config, noise_std, calibration, L)
    ops = _beam._operators(_N_NODES)  # read-only arrays: their own, fixed types
    _, PQ = _beam._sampling(_N_NODES, (ref.s / L).tobytes())
    PQ, q = _c(PQ), _c(ops.Q[-1])
    state0 = flat(ref.state, (_N_NODES,))
    force, cov = np.empty((B, 2)), np.empty((B, 2, 2))
    status, iters = np.empty(B, dtype=np.int64), np.zeros(B, dtype=np.int64)
    residual, chi2, guess_n = np.empty(B), np.empty(B), np.full((B, 2), np.nan)
    state, tip, blocked_dir = np.empty((B, _N_NODES)), np.empty((B, 2)), np.zeros((B, 2))
    common = (L, wload, ei, k0, D, dD, has_dD, ffix)
    if method == "fast":
        block = min(B, _CHAIN) if chain and B > 1 else 1
        args = (p0, _c(ref.s), _c(ref.w), *common, lower, flat(ref.phi[..., -1]), flat(ref.kappa_s, (M,)), state0,
                u_init, offset, float(xtol_n), int(max_iter), ops.kernel, PQ, q, noise,
                (force, cov, status, iters, residual, chi2, guess_n, state, tip, blocked_dir))
        if block >= B:  # one block (one frame, a short series): the same kernel without the threads
            _jit.call(_kernels.estimate_block, 0, B, use_guess, block > 1, *args)
        else:
            _jit.call(_kernels.estimate_frames, block, use_guess, *args)
    else:
        # the paper's baseline starts where fminsearch/fmincon would: at zero force; the
        # shape, its sensitivities and the uncertainty at its optimum come from the fast solver
        u, run_status, iters = paper_fit(L, ref.s, ref.w, ref.Lc, wload, p0, ei, k0, D, ffix, lower,
                                         np.maximum(np.zeros((B, k)), lower))
        _jit.call(_kernels.evaluate_frames, p0, _c(ref.w), *common, _c(u), _c(run_status, np.int64), state0,
                  ops.kernel, PQ, q, noise, (force, cov, status, residual, chi2, state, tip))
    # a NaN force is never a success
    bad = ((status == Status.OK) | (status == Status.NOT_IDENTIFIABLE)) & ~np.isfinite(force).all(axis=1)
    if bad.any():
        status[bad] = Status.NOT_CONVERGED
        force[bad], cov[bad], chi2[bad] = np.nan, np.nan, np.nan
    success = (status == Status.OK) | (status == Status.NOT_IDENTIFIABLE)
    text = messages(status, residual, blocked_dir, method)
    if strict and not success.all():
        raise ConvergenceError(f"{int((~success).sum())} of {B} force estimate(s) failed; first: {text[~success][0]}")
    return ForceEstimate(
        force_n=force.reshape(*batch, 2),
        std_n=np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1)).reshape(*batch, 2),
        covariance_n2=cov.reshape(*batch, 2, 2),
        residual_m=residual.reshape(batch),
        success=success.reshape(batch),
        message=text.reshape(batch) if batch else str(text[0]),
        iterations=np.asarray(iters).reshape(batch),
        wall_time_s=time.perf_counter() - t_start,
        method=method,
        constraint=constraint,
        uncertainty="propagated" if noise[0] else "residual",
        tip_position_m=tip.reshape(*batch, 2),
        state=state.reshape(*batch, _N_NODES),
        guess_n=guess_n.reshape(*batch, 2),
        chi2_per_dof=chi2.reshape(batch),
    )


@functools.lru_cache(maxsize=16)
def _tip_gradient(lengths: bytes, length_m: float, gap: float) -> np.ndarray:
    """∂φ_L/∂S (N,) of a sensor (cached)."""
    return _c(tip_angle_shift_gradient(np.frombuffer(lengths), length_m, gap))


def _noise_model(ref, B, config, noise_opt, calibration, L):
    """The kernels' noise arguments: (has_cov, Σ_S (B, N, N), κ (B, N), lengths, gap, seg, σ, ∂φ_L/∂S).

    Σ_S is the shift covariance of every frame of a PCC shape with a noise model
    (signal noise or calibration error); otherwise ``has_cov`` is False and the arrays
    are placeholders (the residual fallback).
    """
    gap = float(config.sensor.strip_gap_m)
    if ref.kappa is not None:
        sigma_a = _signal_noise(noise_opt, calibration, config.estimation)
        if np.any(sigma_a > 0) or calibration is not None:
            N = ref.lengths.size
            kappa = np.broadcast_to(ref.kappa, (*ref.p0.shape[:-2], N)).reshape(-1, N)
            kappa = _c(np.broadcast_to(kappa, (B, N)))
            cov_s = shift_covariance(kappa, ref.lengths, gap, np.broadcast_to(sigma_a, (N,)), calibration)
            if np.any(np.trace(cov_s, axis1=-2, axis2=-1) > 0):
                return (True, _c(cov_s), _c(kappa), _c(ref.lengths), gap, _c(ref.seg, np.int64), _c(ref.sigma),
                        _tip_gradient(ref.lengths.tobytes(), L, gap))
    return (False, np.zeros((B, 1, 1)), np.zeros((B, 1)), np.zeros(1), gap, np.zeros(1, dtype=np.int64), np.zeros(1),
            np.zeros(1))
