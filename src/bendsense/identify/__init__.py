"""Identification of the actuator model from measurements (paper section V-C).

Two fits, each a nonlinear least-squares problem with standard errors from the
Jacobian and the residual variance:

**Free bending** (:func:`fit_free_bending`) fits the effective shear modulus μ̄, the
sensor stiffness μ_s and the prebend angle of the free-bending model (paper eq. 8–12)
to measured bending angles without external load. Data CSV (:func:`read_free_bending_csv`)::

    # optional comment lines before the header
    pressure_kpa,bending_angle_deg
    20,24.1
    40,52.7

with one pressure column, ``pressure_pa`` or ``pressure_kpa``, and one angle column,
``bending_angle_rad`` or ``bending_angle_deg``: the measured total bending angle θ at
the tip (the tangent angle of the tip relative to the base, DESIGN section 2). Other
columns are ignored. At small angles μ̄ and μ_s act almost alike (both only stiffen
the linear response); the fit reports their correlation and any of the three
parameters can be fixed.

**Stiffness** (:func:`fit_stiffness`) fits the flexural rigidity EI at each pressure
level from loaded shapes with known tip loads, then ``EI(P) = ei0 + ei1 · P``
(paper eq. 15) by weighted linear regression, as in the paper. Data CSV
(:func:`read_stiffness_csv`), one loaded shape per row::

    pressure_kpa,fx_n,fy_n,tip_x_m,tip_y_m
    40,0,-0.1,0.0712,0.0853

Columns: ``pressure_pa`` or ``pressure_kpa``; ``fx_n``, ``fy_n`` (tip force in the
base frame, DESIGN section 2: the paper's downward tip load of 0.1 N on the upright rig
is ``fy_n = -0.1``); and measured points, either or both of

- ``tip_x_m``, ``tip_y_m``: the tip position r(L) [m];
- shape points ``s1_m, x1_m, y1_m``, ``s2_m, x2_m, y2_m``, …: arc length from the
  base and position of marker i [m]. Empty cells mark markers not seen in a row.

Rows whose pressures differ by at most ``pressure_tolerance_pa`` (default 1 kPa) form
one pressure level. The model shapes come from :func:`bendsense.mechanics.beam.solve_beam` with
K0(P) from the free-bending model of the config (identify it first), gravity
``config.weight_per_length_n_per_m`` and the row's own pressure for K0. Rows with no
load still count: gravity bends them.

The two CSVs are read and checked in :mod:`bendsense.identify.data`; its names are
importable from here. Sessions recorded with bendsense (a free pressure sweep, hanging
weights) become these fits' data in :mod:`bendsense.identify.sessions`; the fits'
covariances are computed in :mod:`bendsense.identify.covariance`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from bendsense import validation as check
from bendsense._blas import one_thread
from bendsense.config import FREE_BENDING_PARAMETERS, STIFFNESS_PARAMETERS
from bendsense.errors import ArgumentError, ConfigError
from bendsense.identify.covariance import (
    _correlation,
    _covariance,
    _covariance_note,
    _full_covariance,
    _pooled_errors,
    _Prior,
    _regress_levels,
    _stderr,
    _with_covariance,
)
from bendsense.identify.data import StiffnessData, read_free_bending_csv, read_stiffness_csv
from bendsense.mechanics.actuator import elastic_moment, elastic_moment_slope, solve_bending_angle

__all__ = [
    "FreeBendingFit",
    "StiffnessData",
    "StiffnessFit",
    "check_fixed",
    "fit_free_bending",
    "fit_stiffness",
    "read_free_bending_csv",
    "read_stiffness_csv",
]

#: A free-bending fit's message where the data do not determine a parameter (its standard error is not finite).
NOT_IDENTIFIABLE = "parameters not identifiable from these data (fix one)"

# typical magnitudes: parameter scales for the optimiser when a start value is 0
_TYPICAL = {
    "shear_modulus_pa": 1e5,
    "sensor_stiffness_nm_per_rad": 1e-3,
    "prebend_angle_rad": 0.1,
    "ei0_nm2": 1e-3,
    "ei1_nm2_per_pa": 1e-8,
}




# --------------------------------------------------------------------------- helpers


def _split_fix(fix, names: tuple[str, ...], values: dict, config=None) -> tuple[list[str], dict]:
    """Free names and fixed values from ``fix``: names, or a mapping name → value (None: the start value).

    With ``config``, a value given for a parameter is checked against its plausible
    range for that actuator (:func:`check_fixed`).
    """
    fixed = {}
    if fix is None:
        fix = ()
    items = fix.items() if isinstance(fix, Mapping) else ((n, None) for n in ([fix] if isinstance(fix, str) else fix))
    given = {}
    for name, value in items:
        if name not in names:
            raise ConfigError(f"fix: unknown parameter {name!r}; allowed: {', '.join(names)}")
        fixed[name] = values[name] if value is None else float(value)
        if value is not None:
            given[name] = fixed[name]
    if config is not None:
        check_fixed(given, config)
    free = [n for n in names if n not in fixed]
    return free, fixed


def _implausible_fit(kind: str, build):
    """``build()``, a config with fitted values; a value no actuator can have is the fit's, and said so."""
    try:
        return build()
    except ConfigError as err:
        raise ConfigError(f"the {kind} fit gives a value no actuator of this geometry can have (the data do not "
                          f"determine it, or hold a unit slip; fix a parameter with --fix): {err}") from None


def check_fixed(values: Mapping, config, field: str = "fix") -> None:
    """Refuse a value to hold a model parameter at that no actuator of ``config``'s geometry can have.

    The bounds are those of the config's own values
    (:func:`bendsense.mechanics.bounds.parameter_bounds`); ``ei1_nm2_per_pa`` is judged at
    the ``ei0_nm2`` given beside it, else for any plausible ei0. The message names the
    parameter, its range, the likely unit slip (N·m²/kPa for N·m²/Pa, degrees for
    radians, ...) and the value in SI units.

    Parameters
    ----------
    values : mapping of str to float
        Parameter name → value [SI units].
    config : Config
        The actuator (geometry, pressure range).
    field : str, default "fix"
        Prefix of the field in the message (``--fix`` on the command line).

    Raises
    ------
    ArgumentError
    """
    from bendsense.mechanics.bounds import parameter_bounds

    bounds = parameter_bounds(config.actuator, ei0_nm2=values.get("ei0_nm2"))
    for name, value in values.items():
        if value is not None and name in bounds:
            bounds[name].check(f"{field} {name}", float(value), error=ArgumentError)


def _geometry(actuator) -> dict:
    """The geometry keywords of :mod:`bendsense.mechanics.actuator`'s functions, from ``config.actuator``."""
    names = ("chamber_radius_m", "bottom_thickness_m", "wall_thickness_m", "length_m")
    return {n: getattr(actuator, n) for n in names}


def _format_value(value: float, err: float) -> str:
    if err == 0:
        return f"{value:.6g} (fixed)"
    if not math.isfinite(err):
        return f"{value:.6g} ± (not identifiable)"
    return f"{value:.6g} ± {err:.2g}"


# --------------------------------------------------------------------------- free bending


@dataclass(frozen=True, eq=False)
class FreeBendingFit:
    """Result of :func:`fit_free_bending`.

    Attributes
    ----------
    params : dict
        ``shear_modulus_pa`` [Pa], ``sensor_stiffness_nm_per_rad`` [N·m/rad],
        ``prebend_angle_rad`` [rad]; fixed ones at their fixed values.
    stderr : dict
        Standard errors of ``params`` (0 for fixed parameters, inf if not identifiable).
    free : tuple of str
        The fitted parameters, in the order of ``correlation``.
    correlation : ndarray, shape (k, k)
        Correlation matrix of the free parameters.
    residuals : ndarray, shape (n,)
        Model minus measured bending angle [rad].
    pressure_pa, bending_angle_rad : ndarray, shape (n,)
        The data [Pa], [rad].
    dof : int
        Degrees of freedom n − k.
    success : bool
        The optimiser converged and no parameter ended on a bound.
    message : str
        The optimiser's message plus any caveat.
    covariance : ndarray, shape (3, 3)
        Covariance of ``shear_modulus_pa``, ``sensor_stiffness_nm_per_rad``,
        ``prebend_angle_rad`` in that order (``s² (JᵀJ)⁻¹`` for the free ones, 0 for
        fixed ones; inf if not identifiable).
    posterior : dict, optional
        A fit with a prior: ``values`` (every parameter the prior states, the stiffness
        ones included) and ``section`` (the config's ``parameter_covariance``, updated).
    """

    params: dict
    stderr: dict
    free: tuple
    correlation: np.ndarray
    residuals: np.ndarray
    pressure_pa: np.ndarray
    bending_angle_rad: np.ndarray
    dof: int
    success: bool
    message: str
    covariance: np.ndarray | None = None
    posterior: dict | None = None

    @property
    def rms_rad(self) -> float:
        """Root-mean-square residual [rad]."""
        return float(np.sqrt(np.mean(self.residuals**2)))

    def to_config(self, config):
        """A copy of ``config`` with the fitted ``material`` section and its covariance.

        The covariance goes into ``parameter_covariance`` (the block of the three
        free-bending parameters; another fit's block already there is kept, with zero
        cross-covariance). Not written if the parameters are not identifiable or none was
        free (the config's own block stays). A fit with
        a prior writes its posterior: every parameter the prior states, and the whole
        covariance section updated.

        Parameters
        ----------
        config : Config
            The config to copy.
        """
        if self.posterior is not None:
            new = _implausible_fit("free-bending", lambda: config.with_model_parameters(self.posterior["values"]))
            return new.replace(parameter_covariance=self.posterior["section"])
        new = _implausible_fit("free-bending", lambda: config.replace(
            material=dataclasses.replace(config.material, **self.params)))
        if self.covariance is None or not self.free:  # nothing fitted: the config's prior stays as it was
            return new
        what = f"free-bending fit of {len(self.residuals)} points"
        return _with_covariance(new, FREE_BENDING_PARAMETERS, self.covariance, what)

    def report(self) -> str:
        """Short text report: parameters with standard errors, correlation, residuals."""
        lines = [f"free-bending fit (paper eq. 8-12): {len(self.residuals)} points, {self.dof} degrees of freedom"]
        for name in FREE_BENDING_PARAMETERS:
            lines.append(f"  {name:28s} {_format_value(self.params[name], self.stderr[name])}")
        if len(self.free) > 1:
            for i in range(len(self.free)):
                for j in range(i + 1, len(self.free)):
                    lines.append(f"  corr({self.free[i]}, {self.free[j]}) = {self.correlation[i, j]:+.3f}")
        worst = math.degrees(float(np.max(np.abs(self.residuals))))
        lines.append(f"  residual rms {math.degrees(self.rms_rad):.3g} deg, max {worst:.3g} deg")
        lines.append(_covariance_note(self.covariance))
        if not self.success:
            lines.append(f"  WARNING: {self.message}")
        return "\n".join(lines)

    def plot(self, ax=None, config=None):
        """Measured and fitted bending angle over pressure; returns the axes.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; None makes a new figure.
        config : Config, optional
            The config whose actuator geometry the model curve uses; default the paper's.
        """
        import matplotlib.pyplot as plt

        from bendsense.config import load_config

        if ax is None:
            _, ax = plt.subplots()
        cfg = self.to_config(config if config is not None else load_config())
        p = np.linspace(min(0.0, self.pressure_pa.min()), self.pressure_pa.max(), 200)
        theta = solve_bending_angle(p, **_geometry(cfg.actuator), **self.params)
        ax.plot(self.pressure_pa / 1e3, np.degrees(self.bending_angle_rad), "o", label="measured")
        ax.plot(p / 1e3, np.degrees(theta), "-", label="model")
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel("bending angle [deg]")
        ax.legend()
        return ax


@one_thread
def fit_free_bending(
    pressure_pa,
    bending_angle_rad,
    config=None,
    *,
    fix: Iterable[str] | Mapping[str, float] | None = None,
    initial: Mapping[str, float] | None = None,
    data_covariance=None,
    systematic_covariance=None,
    prior: bool = False,
    stiffness_response=None,
    learn_stiffness: bool = False,
) -> FreeBendingFit:
    """Fit μ̄, μ_s and the prebend angle to free-bending data (paper eq. 8–12, section V-C).

    Minimises Σ (θ_model(P_i) − θ_i)² with ``scipy.optimize.least_squares`` and the exact
    Jacobian from the implicit function theorem on eq. 8 (μ̄ ≥ 0, μ_s ≥ 0). Standard
    errors are ``sqrt(diag(s² (JᵀJ)⁻¹))`` with ``s² = RSS / (n − k)``.

    With ``prior`` the config's values and its ``parameter_covariance`` Σ₀ are a Gaussian
    prior: its rows ``Σ₀^(-1/2) (x − x₀)`` join the same least squares, and the data's
    rows are whitened by their covariance (``Σ^(-1/2) (θ_model − θ)``), so that the
    minimum is the posterior mean (a Bayesian update, linearised at the optimum) and the
    sandwich below ``(J̃ᵀJ̃)⁻¹``, the posterior covariance (:func:`bendsense.adapt`). A
    fit without a prior is the special case with no prior rows, the data weighted equally.

    Parameters
    ----------
    pressure_pa : array_like, shape (n,)
        Gauge pressures [Pa].
    bending_angle_rad : array_like, shape (n,)
        Measured total bending angles θ at the tip [rad].
    config : Config, optional
        Geometry (``config.actuator``) and start values (``config.material``);
        default: the paper's prototype.
    fix : iterable of str or mapping, optional
        Parameters to hold: names (held at their start values) or name → value
        (``None``: the start value).
        Names: ``shear_modulus_pa``, ``sensor_stiffness_nm_per_rad``, ``prebend_angle_rad``.
    initial : mapping, optional
        Start values overriding ``config.material``.
    data_covariance : array_like, shape (n, n), optional
        Covariance of the angles [rad²] (correlated errors, e.g. one calibration's for
        every frame of a session); the parameters' covariance is then the sandwich
        ``A Σ Aᵀ`` (``A`` the whitened fit's linear map) with Σ scaled by
        ``max(1, RSS / E[RSS])`` when the residuals scatter more than it says.
    systematic_covariance : array_like, shape (n, n), optional
        With ``data_covariance``: a further error common to the angles that the
        residuals cannot show (e.g. from another fit's parameters) [rad²]; added to the
        sandwich unscaled.
    prior : bool
        Update ``config.parameter_covariance`` (the prior about the config's values)
        with the data; needs ``data_covariance`` (the data's weight against the prior).
        Free-bending parameters with no prior variance are held at their values.
    stiffness_response : array_like, shape (n, 2), optional
        With ``prior``: ∂θ_i/∂(ei0_nm2, ei1_nm2_per_pa), how each measured angle moves
        with the stiffness (the gravity correction of a session's free frames). The
        stiffness the prior states keeps its values and variances; its uncertainty
        weighs the data and the posterior keeps the cross-covariances it implies.
    learn_stiffness : bool
        With ``prior`` and ``stiffness_response``: fit the stiffness too, the angles
        moving by ``stiffness_response @ (b − b₀)`` from the config's ``b₀``; the data
        must see it from more than one side (free frames in two mounts,
        :func:`bendsense.identify.gravity.identify_gravity`).

    Returns
    -------
    FreeBendingFit

    Raises
    ------
    ArgumentError
        Bad data shapes or values, too few points for the free parameters.
    ConfigError
        An unknown parameter name.
    """
    from bendsense.config import Config, load_config

    config = load_config() if config is None else check.instance("config", config, Config, "bendsense.load_config()")
    p, y = _free_bending_data(pressure_pa, bending_angle_rad)
    start = _free_bending_start(config.material, initial)
    free, fixed = _split_fix(fix, FREE_BENDING_PARAMETERS, start, config)
    data_cov = _data_covariance(data_covariance, len(p))
    sys_cov = _data_covariance(systematic_covariance, len(p), "systematic_covariance")
    start.update({n: getattr(config.stiffness, n) for n in STIFFNESS_PARAMETERS})
    belief = _Prior.of(config, prior, fix, start, data_cov, stiffness_response, len(p), learn_stiffness)
    free = [n for n in free if n not in belief.held]
    fixed.update({n: start[n] for n in belief.held})
    names = [*free, *belief.learned]
    if prior and not names:
        raise ArgumentError("prior: states no variance of any free-bending parameter: nothing to learn")
    if len(p) + len(belief.mean) <= len(names):
        raise ArgumentError(
            f"free-bending data: need more than {len(free)} points to fit {len(free)} parameters, got {len(p)}"
        )
    scale = np.array([abs(start[n]) or _TYPICAL[n] for n in names])
    lower = {"shear_modulus_pa": 1e-9, "sensor_stiffness_nm_per_rad": 0.0, "prebend_angle_rad": -np.inf,
             "ei0_nm2": 1e-12, "ei1_nm2_per_pa": -np.inf}
    lb = np.array([lower[n] for n in names]) / scale
    x0 = np.array([start[n] for n in names]) / scale
    x0 = np.maximum(x0, np.where(np.isfinite(lb), lb + 1e-6, -np.inf))
    # weighed against a prior, the data count by their covariance (the stiffness' part included); alone,
    # equally (the sandwich below)
    whiten = np.linalg.inv(np.linalg.cholesky(data_cov + (0.0 if sys_cov is None else sys_cov)
                                              + belief.stiffness_covariance())) if prior else None
    unpack, angles, resid, jac = _free_bending_problem(p, y, _geometry(config.actuator), names, fixed, scale,
                                                       whiten, belief)
    x, ok, message, at_bound = _solve_free_bending(resid, jac, x0, lb, names)
    values = unpack(x)
    r = resid(x)
    joint = None
    if whiten is None:
        cov, dof = _covariance(jac(x) / scale, r, data_cov, sys_cov)
    else:
        joint = belief.sandwich(jac(x), r, whiten, data_cov, sys_cov, scale)
        cov, dof = joint[:len(names), :len(names)], len(p)
    m = len(free)
    stderr = _stderr(cov[:m, :m], free, FREE_BENDING_PARAMETERS)
    if at_bound:  # the solver's own words only where it failed ("`xtol` termination condition is satisfied.")
        bound = f"{', '.join(at_bound)} at its bound (fix it, or the data do not support it)"
        message, ok = (f"{message}; {bound}" if not ok else bound), False
    if not all(math.isfinite(stderr[n]) for n in free):  # (the solver's "`gtol` ... satisfied" is no reason)
        message, ok = NOT_IDENTIFIABLE if ok else f"{message}; {NOT_IDENTIFIABLE}", False
    return FreeBendingFit(
        params={n: values[n] for n in FREE_BENDING_PARAMETERS},
        stderr=stderr,
        free=tuple(free),
        correlation=_correlation(cov[:m, :m]),
        residuals=angles(x),
        pressure_pa=p,
        bending_angle_rad=y,
        dof=dof,
        success=ok,
        message=message,
        covariance=_full_covariance(cov[:m, :m], free, FREE_BENDING_PARAMETERS),
        posterior=belief.posterior(names, values, joint, len(p)) if prior else None,
    )


def _free_bending_data(pressure_pa, bending_angle_rad):
    """The pressures [Pa] and angles [rad] as float arrays of one shape (n,), checked finite."""
    p = check.float_array("pressure_pa", pressure_pa)
    y = check.float_array("bending_angle_rad", bending_angle_rad)
    if p.ndim != 1 or y.shape != p.shape:
        raise ArgumentError(f"pressure_pa, bending_angle_rad: expected equal shapes (n,), got {p.shape} and {y.shape}")
    for name, arr in (("pressure_pa", p), ("bending_angle_rad", y)):
        if not np.all(np.isfinite(arr)):
            raise ArgumentError(f"{name}: must be finite")
    return p, y


def _data_covariance(cov, n: int, name: str = "data_covariance"):
    """A covariance argument of :func:`fit_free_bending` as a finite symmetric (n, n) array, or None."""
    if cov is None:
        return None
    c = np.asarray(cov, dtype=float)
    if c.shape != (n, n) or not np.all(np.isfinite(c)):
        raise ArgumentError(f"{name}: expected a finite ({n}, {n}) array, got shape {c.shape}")
    return 0.5 * (c + c.T)


def _free_bending_start(material, initial) -> dict:
    """Start values of the free-bending parameters: ``material``'s, overridden by ``initial``."""
    start = {n: getattr(material, n) for n in FREE_BENDING_PARAMETERS}
    if initial:
        for name, value in initial.items():
            if name not in start:
                raise ConfigError(f"initial: unknown parameter {name!r}; allowed: {', '.join(FREE_BENDING_PARAMETERS)}")
            start[name] = float(value)
    return start


def _free_bending_problem(p, y, geom, names, fixed, scale, whiten=None, prior=None):
    """The least-squares problem in the scaled fitted parameters x: ``(unpack, angles, resid, jac)``.

    ``unpack(x)`` gives every parameter's value, ``angles(x)`` the angle residuals
    θ_model(P_i) − θ_i [rad], ``resid(x)``
    them whitened by ``whiten`` and followed by the prior rows, ``jac(x)`` its exact
    Jacobian in x from the implicit function theorem on eq. 8.
    """
    prior = _Prior() if prior is None else prior

    def unpack(x):
        values = dict(fixed)
        values.update({n: float(v) for n, v in zip(names, x * scale, strict=True)})
        return values

    def model(values):
        theta = solve_bending_angle(p, **geom, **{n: values[n] for n in FREE_BENDING_PARAMETERS})
        return theta, theta - values["prebend_angle_rad"]

    def angles(x):
        values = unpack(x)
        return model(values)[0] + prior.moved(values) - y

    def resid(x):
        r = angles(x) if whiten is None else whiten @ angles(x)
        return r if prior.root is None else np.concatenate([r, prior.root @ (x * scale - prior.mean)])

    def jac(x):
        values = unpack(x)
        theta0 = model(values)[1]
        mu, mu_s = values["shear_modulus_pa"], values["sensor_stiffness_nm_per_rad"]
        # eq. 8: μ̄ m(θ0) + μ_s θ0 = M_a(P) with m = M_θ0 / μ̄; differentiate implicitly
        m = elastic_moment(theta0, **geom, shear_modulus_pa=1.0)
        dm = elastic_moment_slope(theta0, **geom, shear_modulus_pa=1.0)
        denom = mu * dm + mu_s
        cols = {
            "shear_modulus_pa": -m / denom,
            "sensor_stiffness_nm_per_rad": -theta0 / denom,
            "prebend_angle_rad": np.ones_like(theta0),
            **{n: prior.linear[:, i] for i, n in enumerate(prior.learned)},
        }
        j = np.stack([cols[n] for n in names], axis=-1) * scale if names else np.zeros((len(p), 0))
        j = j if whiten is None else whiten @ j
        return j if prior.root is None else np.concatenate([j, prior.root * scale], axis=0)

    return unpack, angles, resid, jac


def _solve_free_bending(resid, jac, x0, lb, free):
    """Bounded least squares in x: ``(x, success, message, names at their lower bound)``."""
    from scipy.optimize import least_squares

    if not free:
        return np.zeros(0), True, "all parameters fixed", []
    sol = least_squares(
        resid,
        x0,
        jac=jac,
        bounds=(lb, np.inf),
        method="trf",
        x_scale=1.0,
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
        max_nfev=500,
    )
    lb = np.asarray(lb, dtype=float)
    near = np.isfinite(lb) & (sol.x <= lb * (1 + 1e-9) + 1e-12)
    x = np.where(near, lb, sol.x)  # at its bound: the bound itself, not the solver's 1.8e-34 beside a 0
    at_bound = [n for n, a in zip(free, near, strict=True) if a]
    return x, bool(sol.success), str(sol.message), at_bound


# --------------------------------------------------------------------------- stiffness


@dataclass(frozen=True, eq=False)
class StiffnessFit:
    """Result of :func:`fit_stiffness`.

    Attributes
    ----------
    params : dict
        ``ei0_nm2`` [N·m²] and ``ei1_nm2_per_pa`` [N·m²/Pa] of EI(P) = ei0 + ei1·P (eq. 15).
    stderr : dict
        Standard errors of ``params`` (0 for fixed parameters).
    free : tuple of str
        The fitted parameters, in the order of ``correlation``.
    correlation : ndarray, shape (k, k)
        Correlation matrix of the free parameters.
    residuals : ndarray, shape (levels,)
        Per-level EI minus the fitted line [N·m²].
    level_pressure_pa : ndarray, shape (levels,)
        Mean pressure of each level [Pa].
    level_ei_nm2, level_ei_stderr_nm2 : ndarray, shape (levels,)
        EI fitted at each level and its standard error [N·m²].
    level_rms_m : ndarray, shape (levels,)
        RMS position residual of each level's fit [m].
    level : ndarray of int, shape (n,)
        Level index of each data row.
    position_residuals_m : ndarray, shape (n, M, 2)
        Model minus measured points at the level's EI [m]; NaN where not measured.
    success : bool
        Every level fit converged with stable beam solutions.
    message : str
        Summary, with the levels that failed.
    covariance : ndarray, shape (2, 2)
        Covariance of ``ei0_nm2``, ``ei1_nm2_per_pa`` (0 for a fixed one).
    """

    params: dict
    stderr: dict
    free: tuple
    correlation: np.ndarray
    residuals: np.ndarray
    level_pressure_pa: np.ndarray
    level_ei_nm2: np.ndarray
    level_ei_stderr_nm2: np.ndarray
    level_rms_m: np.ndarray
    level: np.ndarray
    position_residuals_m: np.ndarray
    success: bool
    message: str
    covariance: np.ndarray | None = None

    def to_config(self, config):
        """A copy of ``config`` with the fitted ``stiffness`` section and its covariance.

        The covariance of ``ei0_nm2``, ``ei1_nm2_per_pa`` goes into
        ``parameter_covariance`` beside the free-bending block (block diagonal:
        the two fits are separate).

        Parameters
        ----------
        config : Config
            The config to copy.
        """
        new = _implausible_fit("stiffness", lambda: config.replace(
            stiffness=dataclasses.replace(config.stiffness, **self.params)))
        if self.covariance is None or not self.free:  # nothing fitted: the config's prior stays as it was
            return new
        what = f"stiffness fit of {len(self.level_ei_nm2)} pressure levels"
        return _with_covariance(new, STIFFNESS_PARAMETERS, self.covariance, what)

    def report(self) -> str:
        """Short text report: EI per level, the fitted line with standard errors."""
        lines = [f"stiffness fit (paper eq. 15): {len(self.level)} shapes at {len(self.level_ei_nm2)} pressure levels"]
        lines.append("  pressure [kPa]   EI [N m^2]              rms [mm]")
        for p, ei, se, rms in zip(
            self.level_pressure_pa, self.level_ei_nm2, self.level_ei_stderr_nm2, self.level_rms_m, strict=True
        ):
            lines.append(f"  {p / 1e3:14.2f}   {ei:<9.5g} ± {se:<10.2g}  {rms * 1e3:8.3g}")
        for name in STIFFNESS_PARAMETERS:
            lines.append(f"  {name:16s} {_format_value(self.params[name], self.stderr[name])}")
        if len(self.free) == 2:
            lines.append(f"  corr(ei0_nm2, ei1_nm2_per_pa) = {self.correlation[0, 1]:+.3f}")
        lines.append(_covariance_note(self.covariance))
        if not self.success:
            lines.append(f"  WARNING: {self.message}")
        return "\n".join(lines)

    def plot(self, ax=None):
        """EI per pressure level with error bars and the fitted line; returns the axes.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; None makes a new figure.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(layout="constrained")
        p, mm2 = self.level_pressure_pa, 1e6  # EI in N·mm²: thousands, not 0.00300
        ax.errorbar(p / 1e3, self.level_ei_nm2 * mm2, yerr=self.level_ei_stderr_nm2 * mm2, fmt="o",
                    label="per pressure level (± 1 standard error)")
        grid = np.linspace(min(0.0, p.min()), p.max(), 50)
        ei0, ei1 = self.params["ei0_nm2"], self.params["ei1_nm2_per_pa"]
        ax.plot(grid / 1e3, (ei0 + ei1 * grid) * mm2, "-",
                label=f"EI(P) = {ei0 * mm2:.4g} + {ei1 * mm2 * 1e3:.4g} P[kPa] N·mm²")
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel("EI [N·mm²]")
        ax.set_title("stiffness fit", fontsize="medium")
        ax.legend(loc="upper left", fontsize="small")
        return ax


def _pressure_levels(pressure_pa: np.ndarray, tolerance_pa: float) -> np.ndarray:
    """Level index per row: sorted pressures split where consecutive ones differ by more than the tolerance."""
    order = np.argsort(pressure_pa, kind="stable")
    jumps = np.diff(pressure_pa[order]) > tolerance_pa
    level_sorted = np.concatenate([[0], np.cumsum(jumps)])
    level = np.empty(len(pressure_pa), dtype=int)
    level[order] = level_sorted
    return level


_FAILED_RESIDUAL_M = 1.0  # stands in for a failed beam solve: far worse than any real misfit


def _fit_level(data: StiffnessData, rows, k0, w, length_m, ei_start, method):
    """EI at one pressure level: 1-parameter least squares in log EI on the measured points."""
    from scipy.optimize import least_squares

    from bendsense.mechanics.beam import solve_beam

    obs = data.observed[rows]
    s_all = data.s_m[rows]
    grid, inverse = np.unique(np.where(obs, s_all, 0.0), return_inverse=True)
    inverse = inverse.reshape(s_all.shape)
    force = data.force_n[rows]
    measured = data.positions_m[rows]
    local = np.arange(len(rows))[:, None]

    def shapes(log_ei):
        sol = solve_beam(length_m, math.exp(log_ei), k0[rows], force, w, s_m=grid, method=method, warn=False)
        return sol.positions_m[local, inverse], np.asarray(sol.success)

    def resid(x):
        pos, ok = shapes(float(x[0]))
        r = pos - measured
        r[~ok] = _FAILED_RESIDUAL_M
        return r[obs].ravel()

    x0 = np.array([math.log(ei_start)])
    sol = least_squares(resid, x0, method="trf", diff_step=1e-6, x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    pos, ok = shapes(float(sol.x[0]))
    r = resid(sol.x)
    jac = np.atleast_2d(sol.jac)
    cov, dof = _covariance(jac, r)
    ei = math.exp(float(sol.x[0]))
    se = ei * math.sqrt(cov[0, 0]) if dof > 0 else math.inf  # delta method from log EI
    full = np.full(measured.shape, np.nan)
    full[obs] = (pos - measured)[obs]
    # ∂EI/∂(measured points): x̂ moves by (jᵀj)⁻¹jᵀ δ(measured), EI = exp(x̂)
    sens = np.zeros(measured.shape)
    with np.errstate(invalid="ignore", divide="ignore"):  # a level whose beam never answered: NaN, and failed
        sens[obs] = (ei * jac[:, 0] / float(jac[:, 0] @ jac[:, 0])).reshape(-1, 2)
    success = bool(sol.success) and bool(np.all(ok)) and math.isfinite(se)
    return ei, se, float(np.sqrt(np.mean(r**2))), full, success, sens


@one_thread
def fit_stiffness(
    data: StiffnessData,
    config=None,
    *,
    fix: Iterable[str] | Mapping[str, float] | None = None,
    pressure_tolerance_pa: float = 1e3,
    weighted: bool = True,
    method: str = "fast",
    level_covariance=None,
) -> StiffnessFit:
    """Fit EI per pressure level from loaded shapes, then EI(P) = ei0 + ei1·P (paper eq. 15, V-C).

    At each level, EI minimises the distance between the measured points and the beam
    model (paper eq. 16–17 via :func:`bendsense.mechanics.beam.solve_beam`) with K0(P) from the
    free-bending model of ``config`` and gravity ``config.weight_per_length_n_per_m``.
    The line through the levels is a linear regression weighted by 1/σ_EI² (or
    unweighted; σ_EI from the position residuals pooled over the levels, one camera
    noise); its standard errors propagate the per-level ones, scaled up by
    sqrt(χ²/(levels − k)) when the levels scatter more than their errors say.

    Parameters
    ----------
    data : StiffnessData
        Loaded shapes (:func:`read_stiffness_csv`).
    config : Config, optional
        Actuator, free-bending material, gravity, and start values (``config.stiffness``);
        default: the paper's prototype.
    fix : iterable of str or mapping, optional
        ``ei0_nm2`` and/or ``ei1_nm2_per_pa`` to hold: names or name → value
        (``None``: the value in ``config.stiffness``).
    pressure_tolerance_pa : float
        Rows whose sorted pressures differ by at most this much form one level [Pa].
    weighted : bool
        Weight the regression by the per-level standard errors.
    method : str
        Beam solver, ``fast`` or ``shooting`` (the paper's method).
    level_covariance : callable, optional
        ``level_covariance(sensitivity, level, level_ei_nm2)`` → two (levels, levels)
        covariances [N²·m⁴] of the levels' EI: from the measured points' errors (a
        calibration common to all rows, :func:`bendsense.identify.weights.fit_stiffness_session`)
        and a systematic part the residuals cannot show (from K0's uncertainty);
        ``sensitivity`` (n, M, 2) is ∂EI of each row's level / ∂ its measured points
        [N·m²/m], ``level`` (n,) each row's level, ``level_ei_nm2`` the levels' fitted EI.
        It adds to the levels' own variances; the line's covariance is then
        the sandwich of the regression over it.

    Returns
    -------
    StiffnessFit

    Raises
    ------
    ArgumentError
        Too few levels or points for the free parameters.
    """
    from bendsense.config import load_config
    from bendsense.mechanics.actuator import FreeBendingModel

    if config is None:
        config = load_config()
    if not isinstance(data, StiffnessData):
        raise ArgumentError(f"data: expected the table of hanging-weight frames (read_stiffness_csv(path)), got "
                            f"{type(data).__name__}")
    if not (math.isfinite(pressure_tolerance_pa) and pressure_tolerance_pa >= 0):
        raise ArgumentError(f"pressure_tolerance_pa: must be finite and >= 0, got {pressure_tolerance_pa!r}")
    start = {n: getattr(config.stiffness, n) for n in STIFFNESS_PARAMETERS}
    free, fixed = _split_fix(fix, STIFFNESS_PARAMETERS, start, config)
    length = config.actuator.length_m
    k0 = FreeBendingModel.from_config(config).tip_curvature_per_m(data.pressure_pa)
    w = config.weight_per_length_n_per_m
    level = _pressure_levels(data.pressure_pa, pressure_tolerance_pa)
    n_levels = int(level.max()) + 1
    if n_levels < len(free):
        raise ArgumentError(
            f"stiffness data: {n_levels} pressure level(s) cannot determine {len(free)} parameters "
            f"({', '.join(free)}); measure more pressures or fix one"
        )
    lp, lei, lse, lrms, pos_res, failed, sens = _fit_levels(data, level, n_levels, config.stiffness, k0, w, length,
                                                            method)
    level_cov = None
    if level_covariance is not None:
        data_cov, sys_cov = (np.asarray(c, dtype=float) for c in level_covariance(sens, level, lei))
        data_cov = data_cov + np.diag(np.where(np.isfinite(lse), lse, 0.0) ** 2)
        level_cov = (data_cov, sys_cov)
        lse = np.sqrt(np.diag(data_cov + sys_cov))
    values, residuals, cov, use_weights = _regress_levels(lp, lei, lse, free, fixed, weighted, level_cov)
    message = "converged"
    stderr = _stderr(cov, free, STIFFNESS_PARAMETERS)
    success = not failed
    if failed:
        message = f"level fit failed at {', '.join(failed)} (beam solve unstable or not converged)"
    if weighted and not use_weights:
        message += "; some level has no finite standard error: unweighted regression"
    if not values["ei0_nm2"] > 0:
        success = False
        message += f"; fitted ei0_nm2 = {values['ei0_nm2']:.3g} is not positive"
    return StiffnessFit(
        params=values,
        stderr=stderr,
        free=tuple(free),
        correlation=_correlation(cov),
        residuals=residuals,
        level_pressure_pa=lp,
        level_ei_nm2=lei,
        level_ei_stderr_nm2=lse,
        level_rms_m=lrms,
        level=level,
        position_residuals_m=pos_res,
        success=success,
        message=message,
        covariance=_full_covariance(cov, free, STIFFNESS_PARAMETERS),
    )


def _fit_levels(data: StiffnessData, level, n_levels: int, stiffness, k0, w, length_m, method):
    """EI at every pressure level (:func:`_fit_level`), started from ``stiffness``'s line.

    Returns the levels' mean pressures [Pa], EI [N m²], its standard errors, the RMS
    position residuals [m], the position residuals per row and point [m], the levels
    whose fit failed (as "40 kPa") and ∂EI/∂(measured points) per row [N m²/m].
    """
    lp, lei, lse, lrms = (np.empty(n_levels) for _ in range(4))
    counts = np.zeros(n_levels, dtype=int)
    pos_res = np.full(data.positions_m.shape, np.nan)
    sens = np.zeros(data.positions_m.shape)
    failed = []
    for j in range(n_levels):
        rows = np.flatnonzero(level == j)
        lp[j] = float(np.mean(data.pressure_pa[rows]))
        n_obs = counts[j] = int(data.observed[rows].sum()) * 2
        if n_obs < 2:
            raise ArgumentError(f"stiffness data: level {lp[j] / 1e3:.3g} kPa has one coordinate only; need two")
        ei_start = float(stiffness.ei_nm2(lp[j]))
        if not ei_start > 0:
            ei_start = stiffness.ei0_nm2
        lei[j], lse[j], lrms[j], pos_res[rows], ok, sens[rows] = _fit_level(data, rows, k0, w, length_m, ei_start,
                                                                            method)
        if not ok:
            failed.append(f"{lp[j] / 1e3:.3g} kPa")
    return lp, lei, _pooled_errors(lse, lrms, counts), lrms, pos_res, failed, sens
