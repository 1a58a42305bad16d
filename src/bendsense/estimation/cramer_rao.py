"""What the sensor can tell about a contact along the finger: the Cramér–Rao bound on ``s_c`` and the force.

A point force ``f`` at arc length ``s_c``, normal to the loaded finger there (a
frictionless contact, as :meth:`bendsense.sim.actuator.SimulatedActuator.solve_contact`
makes it), moves the coil angles ``θ_i = φ(L_i) − φ(0) = S_i / d`` the sensor measures.
With ``J = ∂θ/∂(force parameters, s_c)`` from the beam solver's sensitivities at the
coils (``dangle_dforce`` and the contact-location sensitivity of
:func:`bendsense.mechanics.beam.solve_beam`) and the angles' noise covariance
``Σ_θ = diag(σ_S,i²) / d²``, the Fisher information of ``n`` independent frames is
``I = n Jᵀ Σ_θ⁻¹ J`` and no unbiased estimator does better than ``Cov ≥ I⁻¹``:

- ``contact_std_m = √(I⁻¹)_{s_c s_c}``: the location, unknown;
- ``force_std_n``: the force with the location unknown (the force block of ``I⁻¹``);
- ``force_std_known_n = √((I_FF)⁻¹)``: the force at a known location.

The force parameters follow ``constraint``: ``"normal"``, one magnitude along the
contact normal (the direction known, as the ``normal`` constraint states it), or
``"none"``, both components free (a force nearly along the tangent then leaves ``s_c``
unresolved: moving the point along the tangent does not change the moment).

The noise ``σ_S,i`` is the signal noise per channel through the slope of the sensor:
the calibration's own (:meth:`bendsense.calibration.Calibration.error_model`, its noise
part, at the frame's shifts) when one is given, else the simulated sensor's
(:meth:`bendsense.sim.sensor.VirtualSensor.from_config` of the config, ``g_i u_i'(S_i)``
counts per metre). Only the noise averages over frames; a calibration's coefficient
error and the model parameters' are a bias shared by every frame, outside this bound
(the estimators carry them in their σ).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ArgumentError
from bendsense.validation import instance, short

__all__ = ["ContactBound", "contact_bound", "BOUND_CONSTRAINTS"]

BOUND_CONSTRAINTS = ("normal", "none")
#: Default signal noise without a calibration [counts] (the simulator's, ``bendsense simulate``).
DEFAULT_NOISE_COUNTS = 1.5


@dataclass(frozen=True, eq=False)
class ContactBound:
    """The Cramér–Rao bound of a contact at ``s_c``, batched over the broadcast inputs ``...``.

    Attributes
    ----------
    contact_std_m : ndarray, shape (...)
        Smallest σ of ``s_c`` (location unknown) [m]; inf where the data cannot resolve it.
    force_std_n : ndarray, shape (...) or (..., 2)
        Smallest σ of the force with ``s_c`` unknown [N]: of the magnitude (``normal``)
        or of (Fx, Fy) (``none``).
    force_std_known_n : ndarray, shape (...) or (..., 2)
        The same with ``s_c`` known [N].
    force_n : ndarray, shape (..., 2)
        The contact force in the base frame [N] (normal to the loaded tangent at s_c).
    fisher : ndarray, shape (..., k + 1, k + 1)
        Fisher information of the ``frames`` frames over (force parameters, s_c), in
        N and m (k = 1 for ``normal``, 2 for ``none``).
    noise_std_m : ndarray, shape (..., N)
        σ of each strip shift at the contact's shifts [m].
    constraint : str
        ``"normal"`` or ``"none"``.
    frames : int
        Independent frames the bound is for.
    valid : ndarray of bool, shape (...)
        The beam (and the normal-contact iteration) converged.
    """

    contact_std_m: np.ndarray
    force_std_n: np.ndarray
    force_std_known_n: np.ndarray
    force_n: np.ndarray
    fisher: np.ndarray
    noise_std_m: np.ndarray
    constraint: str
    frames: int
    valid: np.ndarray


def _array(name, value, low=None, low_open=False, high=None):
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{name}: expected a number or an array of numbers, got {value!r}") from None
    bad = ~np.isfinite(a)
    if low is not None:
        bad |= (a <= low) if low_open else (a < low)
    if high is not None:
        bad |= a > high
    if np.any(bad):
        span = "" if low is None else f" {'>' if low_open else '>='} {low:g}"
        span += "" if high is None else f" and <= {high:g}"
        raise ArgumentError(f"{name}: must be finite{span}, got {short(np.ravel(a)[np.ravel(bad)][0])}")
    return a


def _noise_std_m(sensor, calibration, noise_std, shifts):
    """σ of each shift (..., N) [m] at the shifts (..., N): the signal noise through the sensor's slope."""
    if calibration is not None:
        from bendsense.calibration._kernels import shift_covariance

        sigma_a = calibration.noise_std if noise_std is None else noise_std
        model = calibration.error_model(np.broadcast_to(np.asarray(sigma_a, dtype=float), (shifts.shape[-1],)))
        flat = shifts.reshape(-1, shifts.shape[-1])
        out = np.empty((flat.shape[0], flat.shape[1]))
        cov = np.empty((flat.shape[1], flat.shape[1]))
        for b, s in enumerate(flat):
            shift_covariance(model, np.ascontiguousarray(s), cov, out[b])
        return np.sqrt(out).reshape(shifts.shape)
    slope = np.abs(sensor.gain_counts * sensor.model.derivative(shifts))  # counts per metre of shift
    with np.errstate(divide="ignore"):
        return np.where(slope > 0, np.asarray(noise_std, dtype=float) / slope, np.inf)


def _inverse(info):
    """I⁻¹ (..., k, k), inf on the diagonal where I is singular (a direction the data do not see)."""
    scale = np.sqrt(np.abs(np.einsum("...ii->...i", info)))
    scale = np.where(scale > 0, scale, 1.0)
    norm = info / (scale[..., :, None] * scale[..., None, :])  # the correlation form: conditioning, not units
    lam = np.linalg.eigvalsh(norm)
    singular = ~(lam[..., 0] > 1e-12 * lam[..., -1])
    safe = np.where(singular[..., None, None], np.eye(info.shape[-1]), norm)
    inv = np.linalg.inv(safe) / (scale[..., :, None] * scale[..., None, :])
    diag = np.einsum("...ii->...i", inv).copy()
    diag[singular] = np.inf
    return inv, diag


def contact_bound(config=None, calibration=None, *, contact_s_m, force_n, pressure_pa, noise_std=None, frames=1,
                  constraint: str = "normal") -> ContactBound:
    """Cramér–Rao bound on the contact location and force from the coil angles (module docstring).

    Parameters
    ----------
    config : Config, optional
        The actuator and sensor; default the paper's prototype.
    calibration : Calibration, optional
        Its slopes map the signal noise to shift noise; default the simulated sensor's slopes.
    contact_s_m : float or array_like
        Contact location s_c, 0 < s_c <= L [m]; broadcasts with ``force_n`` and ``pressure_pa``.
    force_n : float or array_like
        Magnitude f >= 0 of the contact force, normal to the loaded tangent at s_c and
        pushing against the bending [N].
    pressure_pa : float or array_like
        Pressure [Pa].
    noise_std : float or array_like (N,), optional
        Signal noise per channel [counts]; default the calibration's, else 1.5 counts.
    frames : int
        Independent frames of one quasi-static hold (a 50 ms window at 2 kHz: 100).
    constraint : {"normal", "none"}
        The force parameters: one magnitude along the normal, or both components.

    Returns
    -------
    ContactBound

    Raises
    ------
    ArgumentError
        For a bad argument (the message names it).
    """
    from bendsense.config import Config, load_config
    from bendsense.sim.actuator import SimulatedActuator

    config = load_config() if config is None else config
    instance("config", config, Config)
    if constraint not in BOUND_CONSTRAINTS:
        raise ArgumentError(f"constraint: must be one of {', '.join(BOUND_CONSTRAINTS)}, got {constraint!r}")
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
        raise ArgumentError(f"frames: must be an integer >= 1, got {frames!r}")
    length = config.actuator.length_m
    sc = _array("contact_s_m", contact_s_m, 0.0, True, length)
    f = _array("force_n", force_n, 0.0)
    p = _array("pressure_pa", pressure_pa)
    if noise_std is None and calibration is None:
        noise_std = DEFAULT_NOISE_COUNTS
    if noise_std is not None:
        noise_std = _array("noise_std", noise_std, 0.0)
        if noise_std.ndim and noise_std.shape != (config.sensor.n_segments,):
            raise ArgumentError(f"noise_std: expected one value or one per channel ({config.sensor.n_segments},), "
                                f"got shape {noise_std.shape}")
    try:
        shape = np.broadcast_shapes(sc.shape, f.shape, p.shape)
    except ValueError:
        raise ArgumentError(f"contact_s_m, force_n, pressure_pa: shapes {sc.shape}, {f.shape}, {p.shape} do not "
                            "broadcast to one") from None
    B = math.prod(shape)
    sc, f, p = (np.broadcast_to(a, shape).reshape(B) for a in (sc, f, p))
    sim = SimulatedActuator.from_config(config, noise_counts=0.0, seed=0)
    ends = np.cumsum(config.sensor.lengths_m)
    coils = ends[ends <= length * (1 + 1e-12)]
    grid = np.append(0.0, coils)
    k = 1 if constraint == "normal" else 2
    J = np.zeros((B, coils.size, k + 1))
    force = np.full((B, 2), np.nan)
    theta = np.zeros((B, coils.size))
    valid = np.zeros(B, dtype=bool)
    for value in np.unique(sc):  # one contact point per beam solve; the other inputs in one batch
        idx = np.flatnonzero(sc == value)
        F, truth = sim.solve_contact(p[idx], f[idx], contact_s_m=float(value))
        sol = sim.solve(p[idx], F, contact_s_m=float(value), s_m=grid, sensitivities=True, initial=truth.state)
        dF = sol.dangle_dforce[:, 1:, :] - sol.dangle_dforce[:, :1, :]
        dc = sol.dangle_dcontact[:, 1:] - sol.dangle_dcontact[:, :1]
        normal = F / np.maximum(np.linalg.norm(F, axis=-1, keepdims=True), 1e-300)
        if constraint == "normal":
            # f = 0: the normal of the unloaded finger at s_c (the direction a first touch takes)
            free = sim.solve(p[idx], np.zeros(2), s_m=np.array([float(value)]))
            phi_c = free.angle_rad[:, 0]
            normal = np.where(f[idx, None] > 0, normal, np.stack([-np.cos(phi_c), np.sin(phi_c)], axis=-1))
            J[idx, :, 0] = np.einsum("brj,bj->br", dF, normal)
        else:
            J[idx, :, :2] = dF
        J[idx, :, k] = dc
        force[idx] = F
        theta[idx] = sol.angle_rad[:, 1:] - sol.angle_rad[:, :1]
        valid[idx] = np.asarray(truth.success) & np.asarray(sol.success)
    n_channels = config.sensor.n_segments
    shifts = np.zeros((B, n_channels))
    shifts[:, : coils.size] = config.sensor.strip_gap_m * theta  # a coil beyond the actuator measures nothing
    sigma_s = _noise_std_m(sim.sensor, calibration, noise_std, shifts)
    w = (config.sensor.strip_gap_m / sigma_s[:, : coils.size]) ** 2  # 1 / σ_θ²
    info = frames * np.einsum("bri,br,brj->bij", J, w, J)
    _, diag = _inverse(info)
    _, diag_known = _inverse(info[:, :k, :k])
    nan = ~valid
    diag[nan], diag_known[nan] = np.nan, np.nan
    std, std_known = np.sqrt(diag), np.sqrt(diag_known)
    force_shape = shape if k == 1 else (*shape, 2)
    return ContactBound(
        contact_std_m=std[:, k].reshape(shape),
        force_std_n=std[:, :k].reshape(force_shape),
        force_std_known_n=std_known.reshape(force_shape),
        force_n=force.reshape(*shape, 2),
        fisher=info.reshape(*shape, k + 1, k + 1),
        noise_std_m=sigma_s.reshape(*shape, -1),
        constraint=constraint,
        frames=int(frames),
        valid=valid.reshape(shape),
    )
