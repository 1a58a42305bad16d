"""Free bending and stiffness of the soft pneumatic bending actuator (paper section IV-A, eq. 8–12, 15).

Without external load the actuator bends into an arc whose angle θ0 balances the
pressure moment against the elasticity of the actuator and of the sensor layer
(paper eq. 8):

    M_a(P) = M_θ0(θ0) + μ_s θ0,

with ``M_a`` from :func:`pressure_moment` (eq. 9) and ``M_θ0`` from
:func:`elastic_moment` (eq. 10–11). The total bending angle adds the prebend angle,
``θ = θ0 + θ_pre``, and the tip curvature of the free arc is ``K0 = θ / L``
(DESIGN section 2). :func:`solve_bending_angle` solves the balance directly;
:class:`FreeBendingModel` precomputes a monotone cubic Hermite interpolant of θ0(P)
so that evaluating many frames costs microseconds.

The flexural rigidity under load is ``EI(P) = ei0 + ei1 · P`` (paper eq. 15),
:func:`ei_nm2`, which is ``bendsense.config.StiffnessConfig.ei_nm2``.

Symbols: a → ``chamber_radius_m``, b → ``bottom_thickness_m``, t →
``wall_thickness_m``, L → ``length_m``, μ̄ → ``shear_modulus_pa``, μ_s →
``sensor_stiffness_nm_per_rad``.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from bendsense import _jit
from bendsense.config import FREE_BENDING_PARAMETERS, MODEL_PARAMETERS, STIFFNESS_PARAMETERS, StiffnessConfig
from bendsense.errors import ArgumentError, ConfigError, ConvergenceError
from bendsense.mechanics import _actuator_kernels
from bendsense.validation import float_array, instance, short

__all__ = [
    "pressure_moment",
    "elastic_moment",
    "elastic_moment_slope",
    "solve_bending_angle",
    "ei_nm2",
    "ei_jacobian",
    "model_jacobian",
    "FreeBendingModel",
    "FREE_BENDING_PARAMETERS",
    "STIFFNESS_PARAMETERS",
    "MODEL_PARAMETERS",
]

_log = logging.getLogger(__name__)

# Gauss–Legendre orders of the eq. 10 quadrature. The integrand is analytic with its
# nearest singularity at λ = 0, far from the stretches λ ∈ [1, 1 + θ0 (a+b+t)/L] that
# occur, so these orders are at round-off (~1e-15 relative) up to θ0 of several turns;
# tests/mechanics/test_actuator.py checks this against a doubled order and adaptive quadrature.
_N_BETA = 12
_N_TAU = 12
_N_PHI = 16


def _finite(name: str, value) -> np.ndarray:
    arr = float_array(name, value)
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].flat[0]
        raise ArgumentError(f"{name}: must be finite, got {float(bad)!r}")
    return arr


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ConfigError(f"{name}: expected a number, got {value!r}")
    return float(value)


def _real(name: str, value) -> float:
    value = _number(name, value)
    if not math.isfinite(value):
        raise ConfigError(f"{name}: must be finite, got {value!r}")
    return value


def _positive(name: str, value) -> float:
    value = _number(name, value)
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: must be finite and > 0, got {value!r}")
    return value


def _nonnegative(name: str, value) -> float:
    value = _number(name, value)
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"{name}: must be finite and >= 0, got {value!r}")
    return value


def pressure_moment(pressure_pa, chamber_radius_m: float, bottom_thickness_m: float) -> np.ndarray:
    """Pressure-induced bending moment M_a (paper eq. 9).

    Parameters
    ----------
    pressure_pa : array_like
        Gauge pressure P in the chamber [Pa].
    chamber_radius_m : float
        Chamber radius a [m].
    bottom_thickness_m : float
        Bottom layer thickness b [m].

    Returns
    -------
    ndarray
        ``(4 a³ + 3π a² b) / 6 · P`` [N·m], same shape as ``pressure_pa``.
    """
    p = _finite("pressure_pa", pressure_pa)
    a = _positive("chamber_radius_m", chamber_radius_m)
    b = _positive("bottom_thickness_m", bottom_thickness_m)
    return (4.0 * a**3 + 3.0 * math.pi * a**2 * b) / 6.0 * p


@functools.lru_cache(maxsize=64)
def _lever_nodes(a: float, b: float, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature of eq. 10 as ``M = μ̄ Σ_n c_n f(1 + θ0 h_n / L)``, f(λ) = λ − λ⁻³.

    ``h`` is the distance of a material fibre from the bottom surface (the stretch is
    ``λ = 1 + θ0 h / L``, eq. 11 with R = L/θ0) and ``c`` its quadrature weight times
    its lever arm and width. Both layers go into one pair of arrays.
    """
    xb, wb = np.polynomial.legendre.leggauss(_N_BETA)
    beta = 0.5 * b * (xb + 1.0)
    c_bottom = 0.5 * b * wb * 2.0 * (a + t) * beta

    xt, wt = np.polynomial.legendre.leggauss(_N_TAU)
    xp, wp = np.polynomial.legendre.leggauss(_N_PHI)
    tau = 0.5 * t * (xt[:, None] + 1.0)
    phi = 0.25 * np.pi * (xp[None, :] + 1.0)
    w = (0.5 * t * wt[:, None]) * (0.25 * np.pi * wp[None, :])
    h_wall = b + (a + tau) * np.sin(phi)
    # (a+τ)² sin φ + b (a+τ) = (a+τ) h
    c_wall = 2.0 * w * (a + tau) * h_wall

    h = np.concatenate([beta, h_wall.ravel()])
    c = np.concatenate([c_bottom, c_wall.ravel()])
    h.setflags(write=False)
    c.setflags(write=False)
    return h, c


def _check_geometry(chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m):
    return (
        _positive("chamber_radius_m", chamber_radius_m),
        _positive("bottom_thickness_m", bottom_thickness_m),
        _positive("wall_thickness_m", wall_thickness_m),
        _positive("length_m", length_m),
    )


def _unit_moment(theta0, h, c, length_m, slope=False):
    """Σ c f(λ) (and Σ c f'(λ) h / L) for θ0 of any shape; the moment per unit μ̄."""
    lam = 1.0 + theta0[..., None] * (h / length_m)
    inv = 1.0 / lam
    inv3 = inv * inv * inv
    m = (lam - inv3) @ c
    if not slope:
        return m
    dm = (1.0 + 3.0 * inv3 * inv) @ (c * h / length_m)
    return m, dm


def _check_stretch(theta0, h_max, length_m):
    # λ must stay positive: compression beyond the bottom surface has no meaning
    if theta0.size and float(np.min(theta0)) * h_max / length_m <= -1.0:
        raise ArgumentError(
            f"theta0_rad: must be > {-length_m / h_max:.6g} rad (fibres would invert), got {float(np.min(theta0))!r}"
        )


def _elastic(theta0_rad, chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m, shear_modulus_pa, slope):
    """M_θ0 (``slope=False``) or dM_θ0/dθ0 (``slope=True``) after checking the arguments."""
    theta0 = _finite("theta0_rad", theta0_rad)
    a, b, t, length = _check_geometry(chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m)
    mu = _positive("shear_modulus_pa", shear_modulus_pa)
    h, c = _lever_nodes(a, b, t)
    _check_stretch(theta0, a + b + t, length)
    unit = _unit_moment(theta0, h, c, length, slope=slope)
    return mu * (unit[1] if slope else unit)


def elastic_moment(
    theta0_rad,
    *,
    chamber_radius_m: float,
    bottom_thickness_m: float,
    wall_thickness_m: float,
    length_m: float,
    shear_modulus_pa: float,
) -> np.ndarray:
    """Elastic bending moment M_θ0 of the actuator body (paper eq. 10–11).

    The bottom layer contributes ``∫₀ᵇ s_β · 2(a+t) β dβ`` and the hemicylindrical wall
    ``2 ∫₀ᵗ ∫₀^{π/2} s_{τ,φ} ((a+τ)² sin φ + b (a+τ)) dφ dτ`` with the neo-Hookean
    stress ``s = μ̄ (λ − λ⁻³)``. The stretches are written
    ``λ = 1 + θ0 (b + (a+τ) sin φ) / L`` (eq. 11 with R = L/θ0), exact at θ0 = 0.
    Both integrals use Gauss–Legendre quadrature (~1e-15 relative).

    Parameters
    ----------
    theta0_rad : array_like
        Bending angle θ0 of the free arc [rad]; any shape.
    chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m : float
        Geometry a, b, t, L [m].
    shear_modulus_pa : float
        Effective shear modulus μ̄ [Pa].

    Returns
    -------
    ndarray
        M_θ0 [N·m], same shape as ``theta0_rad``.
    """
    return _elastic(
        theta0_rad, chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m, shear_modulus_pa, slope=False
    )


def elastic_moment_slope(
    theta0_rad,
    *,
    chamber_radius_m: float,
    bottom_thickness_m: float,
    wall_thickness_m: float,
    length_m: float,
    shear_modulus_pa: float,
) -> np.ndarray:
    """Derivative dM_θ0/dθ0 of :func:`elastic_moment` [N·m/rad] (same quadrature, exact).

    Parameters
    ----------
    theta0_rad : float or array_like
        Bending angle θ0 of the free actuator [rad].
    chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m : float
        Actuator geometry: chamber radius a, bottom layer thickness b, wall thickness t
        and length L [m].
    shear_modulus_pa : float
        Shear modulus μ̄ of the elastomer [Pa].
    """
    return _elastic(
        theta0_rad, chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m, shear_modulus_pa, slope=True
    )


def _solve_theta0(moment, h, c, length, mu, mu_s, *, max_iter=100):
    """θ0 ≥ 0 with μ̄ m(θ0) + μ_s θ0 = moment, elementwise; safeguarded Newton in a bracket.

    The right side is increasing and concave in θ0 (f(λ) = λ − λ⁻³ is concave), so
    Newton from θ0 = 0 climbs monotonically to the root; the bracket [lo, hi] and the
    bisection fallback only guard against round-off.
    """
    shape = np.shape(moment)
    moment = np.asarray(moment, dtype=float).ravel()
    theta = np.zeros_like(moment)
    lo = np.zeros_like(moment)
    hi = np.full_like(moment, np.inf)
    active = moment > 0
    tol = 4 * np.finfo(float).eps
    for _ in range(max_iter):
        if not active.any():
            return theta.reshape(shape)
        th = theta[active]
        m, dm = _unit_moment(th, h, c, length, slope=True)
        resid = mu * m + mu_s * th - moment[active]
        slope = mu * dm + mu_s
        lo_a = np.where(resid <= 0, th, lo[active])
        hi_a = np.where(resid >= 0, th, hi[active])
        new = th - resid / slope
        outside = ~((new > lo_a) & (new < hi_a))
        fallback = np.where(np.isfinite(hi_a), 0.5 * (lo_a + hi_a), 2.0 * lo_a + 1.0)
        new = np.where(outside, fallback, new)
        done = (np.abs(new - th) <= tol * np.maximum(1.0, np.abs(new))) | (resid == 0)
        idx = np.flatnonzero(active)
        theta[idx] = new
        lo[idx] = lo_a
        hi[idx] = hi_a
        active[idx[done]] = False
    raise ConvergenceError(f"free-bending balance (paper eq. 8) did not converge in {max_iter} iterations")


def solve_bending_angle(
    pressure_pa,
    *,
    chamber_radius_m: float,
    bottom_thickness_m: float,
    wall_thickness_m: float,
    length_m: float,
    shear_modulus_pa: float,
    sensor_stiffness_nm_per_rad: float,
    prebend_angle_rad: float = 0.0,
) -> np.ndarray:
    """Total free bending angle θ = θ0 + θ_pre by solving M_a = M_θ0 + μ_s θ0 (paper eq. 8–12).

    Solves directly (no interpolation) with a bracketed Newton iteration to round-off,
    vectorised over any shape of ``pressure_pa``. Pressures ≤ 0 give θ0 = 0.

    Parameters
    ----------
    pressure_pa : array_like
        Gauge pressure P [Pa].
    chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m : float
        Geometry a, b, t, L [m].
    shear_modulus_pa : float
        Effective shear modulus μ̄ [Pa].
    sensor_stiffness_nm_per_rad : float
        Sensor bending stiffness μ_s [N·m/rad] (eq. 12).
    prebend_angle_rad : float, optional
        Bending angle at zero pressure, added to θ0 [rad].

    Returns
    -------
    ndarray
        θ [rad], same shape as ``pressure_pa``; the tip curvature is θ / L.

    Raises
    ------
    ArgumentError
        If ``pressure_pa`` is not finite; :class:`~bendsense.errors.ConfigError` for a
        bad parameter.
    """
    p = _finite("pressure_pa", pressure_pa)
    a, b, t, length = _check_geometry(chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m)
    mu = _positive("shear_modulus_pa", shear_modulus_pa)
    mu_s = _nonnegative("sensor_stiffness_nm_per_rad", sensor_stiffness_nm_per_rad)
    pre = _real("prebend_angle_rad", prebend_angle_rad)
    h, c = _lever_nodes(a, b, t)
    return _solve_theta0(pressure_moment(p, a, b), h, c, length, mu, mu_s) + pre


def ei_nm2(pressure_pa, ei0_nm2: float, ei1_nm2_per_pa: float) -> np.ndarray:
    """Flexural rigidity EI(P) = ei0 + ei1 · P (paper eq. 15) [N·m²].

    The same formula as :meth:`bendsense.config.StiffnessConfig.ei_nm2`, which it calls.

    Parameters
    ----------
    pressure_pa : float or array_like
        Actuation pressure P [Pa].
    ei0_nm2 : float
        Flexural rigidity at zero pressure, γ0 [N·m²].
    ei1_nm2_per_pa : float
        Its growth with pressure, γ1 [N·m²/Pa].
    """
    p = _finite("pressure_pa", pressure_pa)
    return StiffnessConfig(ei0_nm2=ei0_nm2, ei1_nm2_per_pa=ei1_nm2_per_pa).ei_nm2(p)


def ei_jacobian(pressure_pa) -> np.ndarray:
    """Sensitivity of EI(P) = ei0 + ei1 · P (paper eq. 15) to its coefficients.

    Parameters
    ----------
    pressure_pa : array_like, shape (...)
        Gauge pressure P [Pa].

    Returns
    -------
    ndarray, shape (..., 2)
        ∂EI/∂(``ei0_nm2``, ``ei1_nm2_per_pa``) = (1, P) [1, Pa], in the order of
        :data:`STIFFNESS_PARAMETERS`.
    """
    p = _finite("pressure_pa", pressure_pa)
    return np.stack([np.ones(p.shape), p], axis=-1)


def model_jacobian(config, pressure_pa, parameters=None) -> np.ndarray:
    """Sensitivity of the beam model's inputs (K0, EI) to the identified parameters θ.

    The force estimate's model-parameter uncertainty is ``∂F/∂θ Σ_θ ∂F/∂θᵀ``
    with ``∂r/∂θ = ∂r/∂K0 ∂K0/∂θ + ∂r/∂EI ∂EI/∂θ`` (docs/theory.md); this gives
    the second factors, per frame, from :meth:`FreeBendingModel.tip_curvature_jacobian`
    and :func:`ei_jacobian`.

    Parameters
    ----------
    config : Config
        Actuator, material, stiffness and ``estimation.pressure_max_pa``.
    pressure_pa : array_like, shape (...)
        Gauge pressure P [Pa].
    parameters : sequence of str, optional
        Names from :data:`MODEL_PARAMETERS`, in the order wanted; default: those of
        ``config.parameter_covariance`` if present, else all five.

    Returns
    -------
    ndarray, shape (..., 2, k)
        Row 0: ∂K0/∂θ_j [1/m per unit of θ_j]; row 1: ∂EI/∂θ_j [N·m² per unit].
    """
    if parameters is None:
        cov = getattr(config, "parameter_covariance", None)
        parameters = cov.parameters if cov is not None else MODEL_PARAMETERS
    unknown = [n for n in parameters if n not in MODEL_PARAMETERS]
    if unknown:
        allowed = ", ".join(MODEL_PARAMETERS)
        raise ArgumentError(f"parameters: unknown {', '.join(short(n) for n in unknown)}; allowed: {allowed}")
    p = _finite("pressure_pa", pressure_pa)
    out = np.zeros((*p.shape, 2, len(parameters)))
    free = [(j, FREE_BENDING_PARAMETERS.index(n)) for j, n in enumerate(parameters) if n in FREE_BENDING_PARAMETERS]
    stiff = [(j, STIFFNESS_PARAMETERS.index(n)) for j, n in enumerate(parameters) if n in STIFFNESS_PARAMETERS]
    if free:
        jk = FreeBendingModel.from_config(config).tip_curvature_jacobian(p)
        for j, i in free:
            out[..., 0, j] = jk[..., i]
    if stiff:
        je = ei_jacobian(p)
        for j, i in stiff:
            out[..., 1, j] = je[..., i]
    return out


# ---------------------------------------------------------------------------------------
# Interpolant


_TABLE_TOL_RAD = 1e-9  # error target at the test points; the interpolant stays below 1e-8
_TABLE_START = 32
_TABLE_MAX = 1 << 13


@dataclass(frozen=True)
class _Table:
    """Piecewise cubic θ0(P) on nodes ``p_pa`` (n+1,), coefficients in u ∈ [0, 1] per interval."""

    p_pa: np.ndarray  # (n+1,) node pressures, p_pa[0] = 0, p_pa[-1] = p_max
    inv_width: np.ndarray  # (n,) 1 / (p_pa[k+1] − p_pa[k])
    coef: np.ndarray  # (n, 4) θ0 = c0 + u (c1 + u (c2 + u c3))
    bucket_pa: float  # width of the uniform lookup buckets
    bucket_start: np.ndarray  # (n_buckets,) interval that holds the bucket's left end
    error_rad: float  # largest error found at the test points
    converged: bool
    kernel_args: tuple = ()  # (p_pa, inv_width, coef, bucket_pa, bucket_start) as the kernel takes them

    def __post_init__(self):
        # C-contiguous and writable (the kernel never writes): numba types a read-only or strided array
        # argument on its slow path, ~10 µs a call (a one-frame lookup is ~1 µs)
        arrays = (self.p_pa, self.inv_width, self.coef)
        args = (*(np.array(a, dtype=float, order="C") for a in arrays), float(self.bucket_pa),
                np.array(self.bucket_start, dtype=np.int64, order="C"))
        object.__setattr__(self, "kernel_args", args)


@functools.lru_cache(maxsize=32)
def _hermite_table(a, b, t, length, mu, mu_s, p_max) -> _Table:
    """Cubic Hermite interpolant of θ0(P) on [0, p_max] (cached per parameter set).

    The nodes are uniform in θ0, where eq. 8 is explicit: P(θ0) = (μ̄ m(θ0) + μ_s θ0) / c_a
    and dθ0/dP = c_a / (μ̄ m'(θ0) + μ_s) (implicit function theorem), so no root finding
    is needed except for θ0(p_max). Uniform θ0 nodes crowd where θ0(P) is steep, which a
    uniform P grid would miss for soft materials. The grid doubles until, at every
    interval's θ0-midpoint (near where the Hermite error peaks), the error is below
    ``_TABLE_TOL_RAD`` and the Fritsch–Carlson condition holds (monotone interpolant).
    A uniform bucket index no wider than the narrowest interval finds the interval of a
    pressure in O(1).
    """
    h, c = _lever_nodes(a, b, t)
    c_a = (4.0 * a**3 + 3.0 * math.pi * a**2 * b) / 6.0
    theta_max = float(_solve_theta0(c_a * p_max, h, c, length, mu, mu_s))

    def pressure_and_slope(theta):
        m, dm = _unit_moment(theta, h, c, length, slope=True)
        return (mu * m + mu_s * theta) / c_a, c_a / (mu * dm + mu_s)

    n = _TABLE_START
    while True:
        theta = np.linspace(0.0, theta_max, 2 * n + 1)
        p_all, slope_all = pressure_and_slope(theta)
        p, y, slope = p_all[::2], theta[::2], slope_all[::2]
        p[-1] = p_max  # equal up to round-off; exact so the range check is exact
        width = np.diff(p)
        m0, m1 = slope[:-1] * width, slope[1:] * width
        y0, y1 = y[:-1], y[1:]
        coef = np.stack([y0, m0, 3.0 * (y1 - y0) - 2.0 * m0 - m1, 2.0 * (y0 - y1) + m0 + m1], axis=-1)
        u = (p_all[1::2] - p[:-1]) / width
        approx = coef[:, 0] + u * (coef[:, 1] + u * (coef[:, 2] + u * coef[:, 3]))
        err = float(np.max(np.abs(approx - theta[1::2])))
        delta = y1 - y0
        monotone = bool(np.all(width > 0)) and bool(np.all((m0 / delta) ** 2 + (m1 / delta) ** 2 <= 9.0))
        converged = err <= _TABLE_TOL_RAD and monotone
        if converged or n >= _TABLE_MAX:
            break
        n *= 2
    n_buckets = int(math.ceil(1.5 * p_max / float(np.min(width)))) if monotone else 1
    bucket = p_max / n_buckets
    start = np.searchsorted(p, np.arange(n_buckets) * bucket, side="right") - 1
    start = np.clip(start, 0, n - 1).astype(np.intp)
    inv_width = 1.0 / width
    for arr in (p, inv_width, coef, start):
        arr.setflags(write=False)
    return _Table(p, inv_width, coef, bucket, start, err, converged)


@dataclass(frozen=True, kw_only=True, eq=False)
class FreeBendingModel:
    """Free bending θ(P) and tip curvature K0(P) of the actuator (paper eq. 8–12).

    Construction precomputes (and caches per parameter set) a monotone cubic Hermite
    interpolant of θ0(P) on ``[0, pressure_max_pa]`` with error below 1e-8 rad; above
    that range the model falls back to the direct solve, so it never extrapolates.

    Parameters
    ----------
    chamber_radius_m, bottom_thickness_m, wall_thickness_m, length_m : float
        Geometry a, b, t, L [m].
    shear_modulus_pa : float
        Effective shear modulus μ̄ [Pa].
    sensor_stiffness_nm_per_rad : float
        Sensor bending stiffness μ_s [N·m/rad].
    prebend_angle_rad : float
        Bending angle at zero pressure [rad].
    pressure_max_pa : float
        Upper end of the interpolated range [Pa].

    Examples
    --------
    >>> import bendsense
    >>> model = bendsense.mechanics.actuator.FreeBendingModel.from_config(bendsense.load_config())
    >>> round(float(np.degrees(model.bending_angle_rad(60e3))), 1)
    79.5
    """

    chamber_radius_m: float
    bottom_thickness_m: float
    wall_thickness_m: float
    length_m: float
    shear_modulus_pa: float
    sensor_stiffness_nm_per_rad: float
    prebend_angle_rad: float = 0.0
    pressure_max_pa: float = 200e3
    _table: _Table = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        for name in ("chamber_radius_m", "bottom_thickness_m", "wall_thickness_m", "length_m", "shear_modulus_pa"):
            set_(self, name, _positive(name, getattr(self, name)))
        mu_s = _nonnegative("sensor_stiffness_nm_per_rad", self.sensor_stiffness_nm_per_rad)
        set_(self, "sensor_stiffness_nm_per_rad", mu_s)
        set_(self, "prebend_angle_rad", _real("prebend_angle_rad", self.prebend_angle_rad))
        set_(self, "pressure_max_pa", _positive("pressure_max_pa", self.pressure_max_pa))
        table = _hermite_table(*self._key())
        if not table.converged:
            # only for absurd parameters (hundreds of turns at pressure_max_pa): stay exact, if slow
            _log.warning(
                "free-bending interpolant did not reach %.0e rad (error %.2g rad); using the direct solve",
                _TABLE_TOL_RAD,
                table.error_rad,
            )
        set_(self, "_table", table)

    @property
    def interpolation_error_rad(self) -> float:
        """Largest interpolant error found while building the table [rad]."""
        return self._table.error_rad

    def _key(self):
        return (
            self.chamber_radius_m,
            self.bottom_thickness_m,
            self.wall_thickness_m,
            self.length_m,
            self.shear_modulus_pa,
            self.sensor_stiffness_nm_per_rad,
            self.pressure_max_pa,
        )

    @classmethod
    def from_config(cls, config) -> FreeBendingModel:
        """Build the model of ``config.actuator`` and ``config.material``.

        The interpolant covers ``[0, config.estimation.pressure_max_pa]``.

        Parameters
        ----------
        config : Config
            Its ``actuator``, ``material`` and ``estimation.pressure_max_pa``.
        """
        from bendsense.config import Config

        instance("config", config, Config, "bendsense.load_config(path)")
        act, mat = config.actuator, config.material
        return cls(
            chamber_radius_m=act.chamber_radius_m,
            bottom_thickness_m=act.bottom_thickness_m,
            wall_thickness_m=act.wall_thickness_m,
            length_m=act.length_m,
            shear_modulus_pa=mat.shear_modulus_pa,
            sensor_stiffness_nm_per_rad=mat.sensor_stiffness_nm_per_rad,
            prebend_angle_rad=mat.prebend_angle_rad,
            pressure_max_pa=config.estimation.pressure_max_pa,
        )

    @property
    def params(self) -> dict:
        """The solver's keyword arguments (for :func:`solve_bending_angle`)."""
        return {
            "chamber_radius_m": self.chamber_radius_m,
            "bottom_thickness_m": self.bottom_thickness_m,
            "wall_thickness_m": self.wall_thickness_m,
            "length_m": self.length_m,
            "shear_modulus_pa": self.shear_modulus_pa,
            "sensor_stiffness_nm_per_rad": self.sensor_stiffness_nm_per_rad,
            "prebend_angle_rad": self.prebend_angle_rad,
        }

    def solve(self, pressure_pa) -> np.ndarray:
        """θ [rad] by the direct solve of eq. 8 (slow path; reference for the interpolant).

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return solve_bending_angle(pressure_pa, **self.params)

    def _lookup(self, pressure_pa, slope: bool):
        """The checked pressures, θ0 [rad] and, if ``slope``, dθ0/dP [rad/Pa] (0 below 0 Pa) there (any shape).

        One compiled lookup of the interpolant for every caller, one frame or a batch
        (:func:`bendsense.mechanics._actuator_kernels.hermite`, which also checks that the
        pressures are finite); the direct solve above its range, or everywhere if it did
        not converge. The arrays are C-contiguous and writable, as the kernels take them.
        """
        p = np.array(float_array("pressure_pa", pressure_pa), order="C")
        tab = self._table
        if not tab.converged:
            _finite("pressure_pa", p)
            theta = self.solve(p) - self.prebend_angle_rad
            d = np.zeros(p.shape)
            exact = np.ones(p.shape, dtype=bool)
        else:
            theta, d = np.empty(p.shape), np.empty(p.shape)
            above = _jit.call(_actuator_kernels.hermite, p.reshape(-1), *tab.kernel_args, theta.reshape(-1),
                              d.reshape(-1))
            if above < 0:
                raise ArgumentError(f"pressure_pa: must be finite, got {float(p.flat[-1 - above])!r}")
            if not above:
                return p, theta, (d if slope else None)
            exact = p > self.pressure_max_pa
            theta[exact] = self.solve(p[exact]) - self.prebend_angle_rad
        if not slope:
            return p, theta, None
        d[exact] = self._exact_slope(p[exact])
        d[p < 0] = 0.0
        return p, theta, d

    def theta0_rad(self, pressure_pa) -> np.ndarray:
        """Pressure-induced bending angle θ0 without the prebend [rad], same shape as ``pressure_pa``.

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        _, theta, _ = self._lookup(pressure_pa, slope=False)
        return theta if isinstance(pressure_pa, np.ndarray) else theta[()]  # a number for a number

    def bending_angle_rad(self, pressure_pa) -> np.ndarray:
        """Total free bending angle θ = θ0(P) + θ_pre [rad] (paper eq. 8 plus prebend).

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return self.theta0_rad(pressure_pa) + self.prebend_angle_rad

    def tip_angle_rad(self, pressure_pa) -> np.ndarray:
        """Tangent angle at the tip in free motion [rad]; equal to θ for a base angle of 0.

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return self.bending_angle_rad(pressure_pa)

    def tip_curvature_per_m(self, pressure_pa) -> np.ndarray:
        """Curvature of the free arc K0 = θ / L [1/m] (paper section IV-A).

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return self.bending_angle_rad(pressure_pa) / self.length_m

    # -- sensitivities (uncertainty of the model parameters) ----------------------------

    def bending_angle_slope(self, pressure_pa) -> np.ndarray:
        """dθ/dP, the slope of the free bending angle over pressure [rad/Pa].

        By the implicit function theorem on eq. 8, ``dθ0/dP = c_a / (μ̄ m'(θ0) + μ_s)``
        with ``M_a = c_a P`` (eq. 9) and ``m = M_θ0 / μ̄``. Inside the interpolated
        range it is the derivative of the Hermite interpolant (which matches that
        slope at every node; between nodes to ~1e-7 relative); above it, the formula
        at the directly solved θ0. Zero for P < 0, where θ0 = 0.

        Parameters
        ----------
        pressure_pa : array_like
            Gauge pressure P [Pa].

        Returns
        -------
        ndarray
            dθ/dP [rad/Pa], same shape as ``pressure_pa``.
        """
        return self._lookup(pressure_pa, slope=True)[2]

    def _exact_slope(self, p):
        """dθ0/dP = c_a / (μ̄ m'(θ0) + μ_s) at the directly solved θ0 (eq. 8–9)."""
        h, c = _lever_nodes(self.chamber_radius_m, self.bottom_thickness_m, self.wall_thickness_m)
        theta0 = self.solve(p) - self.prebend_angle_rad
        _, dm = _unit_moment(np.asarray(theta0, dtype=float), h, c, self.length_m, slope=True)
        return self._moment_per_pa / (self.shear_modulus_pa * dm + self.sensor_stiffness_nm_per_rad)

    @property
    def _moment_per_pa(self) -> float:
        a, b = self.chamber_radius_m, self.bottom_thickness_m
        return (4.0 * a**3 + 3.0 * math.pi * a**2 * b) / 6.0  # c_a of eq. 9 [N·m/Pa]

    def tip_curvature_slope(self, pressure_pa) -> np.ndarray:
        """dK0/dP = (dθ/dP) / L [1/(m·Pa)] (see :meth:`bending_angle_slope`).

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return self.bending_angle_slope(pressure_pa) / self.length_m

    def tip_curvature_jacobian(self, pressure_pa) -> np.ndarray:
        """Sensitivity of K0(P) to the material parameters (paper eq. 8–12).

        Implicit differentiation of the balance ``μ̄ m(θ0) + μ_s θ0 = c_a P``
        (eq. 8–9, 12) at fixed P gives, with ``D = μ̄ m'(θ0) + μ_s = c_a / (dθ0/dP)``,

            ∂θ0/∂μ̄ = −m(θ0) / D,   ∂θ0/∂μ_s = −θ0 / D,   ∂θ/∂θ_pre = 1,

        and ``m(θ0) = (c_a P − μ_s θ0) / μ̄`` from the balance itself, so one
        interpolant lookup per frame gives all three; ``K0 = θ / L``.

        Parameters
        ----------
        pressure_pa : array_like, shape (...)
            Gauge pressure P [Pa].

        Returns
        -------
        ndarray, shape (..., 3)
            ∂K0/∂(``shear_modulus_pa``, ``sensor_stiffness_nm_per_rad``,
            ``prebend_angle_rad``) [1/(m·Pa), rad/(m·N·m), 1/(m·rad)], in the
            order of :data:`FREE_BENDING_PARAMETERS`.
        """
        mu, mu_s, c_a = self.shear_modulus_pa, self.sensor_stiffness_nm_per_rad, self._moment_per_pa
        p, theta0, slope = self._lookup(pressure_pa, slope=True)
        out = np.empty((*p.shape, 3))
        _jit.call(_actuator_kernels.curvature_jacobian, p.reshape(-1), np.ascontiguousarray(theta0).reshape(-1),
                  slope.reshape(-1), c_a, mu, mu_s, self.length_m, out.reshape(-1, 3))
        return out

    def elastic_moment(self, theta0_rad) -> np.ndarray:
        """M_θ0(θ0) + μ_s θ0, the total restoring moment [N·m] (paper eq. 10–12).

        Parameters
        ----------
        theta0_rad : float or array_like
            Pressure-induced bending angle θ0 [rad].
        """
        p = self.params
        del p["prebend_angle_rad"], p["sensor_stiffness_nm_per_rad"]
        theta0 = _finite("theta0_rad", theta0_rad)
        return elastic_moment(theta0, **p) + self.sensor_stiffness_nm_per_rad * theta0
