"""Plausibility at the edges: input outside the physically meaningful range never gives an ``ok`` force.

Two kinds of checks live here, both applied where data enter the library:

- **per frame**: a frame whose pressure lies outside the actuator's working range
  (``config.actuator.pressure_range_pa``, default 0..200 kPa) gets no force and the
  status ``pressure_out_of_range`` (:func:`pressure_range_step`, the first step of
  :func:`bendsense.estimation.estimate_force`);
- **per column**: a pressure column whose numbers are a thousand times off its unit
  (kPa numbers in ``pressure_pa``, Pa numbers in ``pressure_kpa``) is refused by the
  session reader with a message that names the probable mistake
  (:func:`check_pressure_column`);
- **per config value**: every physical parameter of a config lies within a bound derived
  from the actuator's geometry and its materials (:class:`Bound`,
  :func:`stiffness_bound_nm2`, :func:`check_config`); a value outside names the field,
  the bound, the likely unit slip and the value in SI units;
- **per frame, the force**: a fitted force beyond what the actuator can carry
  (:func:`force_bound_n`) is no measurement: status ``implausible_force``
  (:func:`force_bound_step`).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math

import numpy as np

from bendsense.errors import ArgumentError, ConfigError, SessionError
from bendsense.validation import float_array

__all__ = [
    "OUT_OF_RANGE",
    "pressure_outside",
    "pressure_range_step",
    "check_pressure_column",
    "check_time_column",
    "check_channels",
    "Bound",
    "IMPLAUSIBLE_FORCE",
    "cross_section",
    "stiffness_bound_nm2",
    "max_curvature_per_m",
    "parameter_bounds",
    "check_config",
    "force_bound_n",
    "force_bound_step",
]

log = logging.getLogger("bendsense")

OUT_OF_RANGE = "pressure_out_of_range"
"""Status (and message prefix) of a frame whose pressure lies outside the actuator's range."""


def pressure_outside(pressure_pa, config) -> np.ndarray:
    """True for each finite pressure outside ``config.actuator.pressure_range_pa`` [Pa].

    Parameters
    ----------
    pressure_pa : float or array_like
        Actuation pressures [Pa]; NaN (no reading) is never outside.
    config : Config
        Its ``actuator.pressure_range_pa`` gives the range [Pa].
    """
    lo, hi = config.actuator.pressure_range_pa
    if isinstance(pressure_pa, float):  # one frame (the live path)
        return np.bool_(lo > pressure_pa or pressure_pa > hi)
    p = float_array("pressure_pa", pressure_pa)
    with np.errstate(invalid="ignore"):
        return np.isfinite(p) & ((p < lo) | (p > hi))


def _kpa(value: float) -> str:
    return f"{value / 1e3:g} kPa"


def pressure_range_step(estimate):
    """Wrap ``estimate_force``: frames outside the actuator's pressure range get no force.

    Those frames are estimated at the nearest end of the range (so that a batch keeps
    its shape and a time series its warm start) and then marked: ``force_n``,
    ``std_n``, ``covariance_n2``, ``residual_m`` NaN, ``success`` False and the message
    ``"pressure_out_of_range: ..."``. With ``strict=True`` they raise
    :class:`~bendsense.errors.ArgumentError` instead.

    Parameters
    ----------
    estimate : callable
        ``estimate_force`` or a function with its signature.
    """
    from bendsense.config import Config, load_config

    @functools.wraps(estimate)
    def estimate_force(shape, pressure_pa, config=None, *args, **options):
        if config is None:
            config = load_config()
        elif not isinstance(config, Config):
            raise ArgumentError(f"config: expected a Config (bendsense.load_config(path)), got "
                                f"{type(config).__name__}")
        outside = pressure_outside(pressure_pa, config)
        if not outside.any():
            return estimate(shape, pressure_pa, config, *args, **options)
        lo, hi = config.actuator.pressure_range_pa
        p = np.asarray(pressure_pa, dtype=float)
        first = float(p[outside].flat[0])
        text = (f"{int(outside.sum())} of {outside.size} pressure(s) outside actuator.pressure_range_pa "
                f"{lo / 1e3:g}..{hi / 1e3:g} kPa (first: {_kpa(first)})")
        if options.get("strict"):
            raise ArgumentError(f"pressure_pa: {text}")
        result = estimate(shape, np.clip(p, lo, hi), config, *args, **options)
        return _mark(result, outside, p, lo, hi)

    return estimate_force


def _mark(result, outside, p, lo, hi):
    """``result`` with the frames where ``outside`` is true set to no force and the status."""
    batch = result.batch_shape
    mask = np.broadcast_to(outside, batch)
    p = np.broadcast_to(p, batch)
    nan2 = mask[..., None]
    message = np.array(np.broadcast_to(np.asarray(result.message, dtype=object), batch), dtype=object)
    for index in zip(*np.nonzero(mask)) if batch else [()]:
        message[index] = (f"{OUT_OF_RANGE}: {_kpa(float(p[index]))} outside {lo / 1e3:g}..{hi / 1e3:g} kPa "
                          "(actuator.pressure_range_pa)")
    chi2 = result.chi2_per_dof
    return dataclasses.replace(
        result,
        force_n=np.where(nan2, np.nan, result.force_n),
        std_n=np.where(nan2, np.nan, result.std_n),
        covariance_n2=np.where(mask[..., None, None], np.nan, result.covariance_n2),
        residual_m=np.where(mask, np.nan, result.residual_m),
        success=np.where(mask, False, result.success),
        message=message.astype(str) if batch else str(message[()]),
        chi2_per_dof=None if chi2 is None else np.where(mask, np.nan, chi2),
        p_value=None if result.p_value is None else np.where(mask, np.nan, result.p_value),
        covariance_parts_n2=None if result.covariance_parts_n2 is None else np.where(
            mask[..., None, None, None], np.nan, result.covariance_parts_n2),
    )


def check_pressure_column(name: str, values: np.ndarray, line, error=SessionError) -> None:
    """Refuse a pressure column whose numbers are a thousand times off its unit.

    ``line``: the header line of a CSV column, or the place of a record field (e.g.
    ``"run/frames.bin"``) for the message.

    ``pressure_pa`` whose largest reading is between 1 Pa and 1 kPa holds kilopascals
    (a soft actuator at under 1 kPa does not bend; a column of zeros is an
    unpressurised session and passes); ``pressure_kpa`` with a reading over
    1,000 kPa (1 MPa) holds pascals.

    Parameters
    ----------
    name : str
        Column name, ``pressure_pa`` or ``pressure_kpa``.
    values : ndarray
        The column's values, in the column's unit [Pa or kPa].
    line : int or str
        Where the column is, for the message (see above).
    error : type, default SessionError
        The exception class to raise.
    """
    where = f"line {line}, column" if isinstance(line, int) else f"{line}, field"
    finite = values[np.isfinite(values)]
    if not finite.size:
        return
    top = float(finite.max())
    if name == "pressure_pa" and 1.0 <= top < 1e3:
        raise error(f"{where} pressure_pa: every reading is below 1 kPa (largest {top:g}); "
                    "looks like kilopascals" + (": name the column pressure_kpa" if isinstance(line, int) else ""))
    top = float(np.abs(finite).max())
    if name == "pressure_kpa" and top > 1e3:
        raise error(f"{where} pressure_kpa: readings up to {top:g} kPa (over 1 MPa); "
                    "looks like pascals: name the column pressure_pa")


def check_time_column(t_s: np.ndarray, source: str, rows=None, error=SessionError) -> None:
    """Refuse time stamps that are not finite or do not increase strictly from frame to frame.

    A session whose ``t_s`` runs backwards, repeats or is out of order (rows sorted
    by another column, two recordings pasted together, a clock reset) would be
    tracked, windowed and plotted as if nothing were wrong; which order is right
    cannot be guessed, so it is refused with the first offending rows (docs/formats.md,
    "Time").

    Parameters
    ----------
    t_s : ndarray, shape (frames,)
        Time stamps [s].
    source : str
        The session's file, for the message (not repeated when a reader adds it).
    rows : sequence of int, optional
        The CSV line of each frame; None: frames are named by their 0-based index.
    error : type, default SessionError
        The exception class to raise.
    """
    t = np.asarray(t_s, dtype=float)
    where = (lambda k: f"line {rows[k]}") if rows is not None else (lambda k: f"frame {k}")
    finite = np.isfinite(t)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise error(f"{where(k)}, column t_s: must be finite, got {t[k]!r}")
    if t.size < 2:
        return
    bad = np.flatnonzero(np.diff(t) <= 0) + 1
    if not bad.size:
        return
    k = int(bad[0])
    how = "repeats" if t[k] == t[k - 1] else "runs backwards"
    also = ""
    if bad.size > 1:
        more = ", ".join(where(int(j)).split()[-1] for j in bad[1:4])
        noun = "line" if rows is not None else "frame"
        noun += "s" if bad.size > 2 else ""
        also = f"; {bad.size} rows out of order in all (also {noun} {more}"
        also += ", ...)" if bad.size > 4 else ")"
    raise error(f"{where(k)}, column t_s: time {how} ({t[k]:.9g} s after {t[k - 1]:.9g} s on "
                f"{where(k - 1)}){also}; t_s must increase from row to row")


def check_channels(session, calibration, sensor, *, calibration_source: str = "") -> None:
    """Refuse a session, calibration and sensor whose channel counts differ (one line naming them).

    Parameters
    ----------
    session : Session
        The session (its signals' channel count).
    calibration : Calibration or None
        The calibration (its channel count), if any.
    sensor : SensorConfig
        The sensor (its segment count).
    calibration_source : str, default ""
        The calibration's file, for the message.
    """
    cal = f"the calibration {calibration_source}" if calibration_source else "the calibration"
    if calibration.n_channels != sensor.n_segments:
        raise SessionError(f"{cal} has {calibration.n_channels} channels, but the config's sensor has "
                           f"{sensor.n_segments} segments (sensor.n_segments)")
    if session.n_channels != calibration.n_channels:
        where = session.source or "the session"
        raise SessionError(f"{where}: {session.n_channels} signal channels (ch1..ch{session.n_channels}), "
                           f"but {cal} has {calibration.n_channels}")


# --- physical bounds of a config's values ---------------------------------------------------
#
# A soft actuator is a silicone beam a few millimetres across and a few centimetres long;
# what its parameters can be follows from its geometry and the materials it is cast from.
# The bounds are wide (a factor WIDEN beyond the materials' range) so that no real
# actuator is refused; what they catch are values off by a unit (a thousand, a million).

YOUNG_MODULUS_PA = (0.05e6, 10e6)
"""Young's modulus E of the soft silicones and elastomers of soft actuators (Ecoflex to
stiff Elastosil/Sylgard grades, ~0.05–10 MPa) [Pa]."""
DENSITY_KG_PER_M3 = (1000.0, 1500.0)
"""Density of silicones and elastomers, unfilled to filled [kg/m³]."""
WIDEN = 10.0
"""Factor by which a bound from the materials is widened on each side: the strain-limiting
layer's fabric or fibres and the glued sensor stiffen the section and shift its neutral
axis, end caps and fittings add mass; a unit slip is a factor of 1000 or more."""
PRESSURE_MAX_PA = 1e6
"""Largest working pressure of a soft pneumatic actuator: fibre-reinforced silicone
actuators work up to a few hundred kPa; over 1 MPa (10 bar) is no soft actuator [Pa]."""
PREBEND_MAX_RAD = math.pi / 2
"""Largest bending angle of an actuator at rest (the prebend of paper eq. 8–12 is a small
fabrication curl; a quarter turn at rest is a differently shaped actuator) [rad]."""
GRAVITY_M_PER_S2 = (1.5, 20.0)
"""Gravity of a rig (the Moon's 1.6 to twice the Earth's), or 0 to switch it off [m/s²]."""

LENGTH_SLIPS = (("mm", 1e-3), ("cm", 1e-2))
PRESSURE_SLIPS = (("kPa", 1e3), ("bar", 1e5), ("psi", 6894.757), ("MPa", 1e6))
MODULUS_SLIPS = (("kPa", 1e3), ("MPa", 1e6))
EI_SLIPS = (("N·mm²", 1e-6), ("N·cm²", 1e-4))
EI1_SLIPS = (("N·m²/kPa", 1e-3), ("N·mm²/Pa", 1e-6), ("N·mm²/kPa", 1e-9))
MASS_SLIPS = (("g", 1e-3),)
ANGLE_SLIPS = (("degrees", math.pi / 180),)
TORQUE_SLIPS = (("N·mm/rad", 1e-3),)
GRAVITY_SLIPS = (("units of g", 9.80665), ("cm/s²", 1e-2))


def _g(x: float, digits: int = 2) -> str:
    """``x`` to ``digits`` significant digits, exponents short (``1e6``, ``4.4e-6``)."""
    text = f"{float(f'{x:.{digits}g}'):g}"
    if "e" in text:
        mantissa, exponent = text.split("e")
        text = f"{mantissa}e{int(exponent)}"
    return text


@dataclasses.dataclass(frozen=True)
class Bound:
    """The plausible range of one physical value and the unit slips that explain a value outside.

    Parameters
    ----------
    what : str
        What the value is, for the message (``"bending stiffness for this actuator"``).
    lo, hi : float
        Inclusive bounds [``unit``].
    unit : str
        The SI unit of the value (``"N·m²"``).
    why : str
        Where the bound comes from (``"from its cross-section"``).
    slips : tuple of (str, float)
        Units a user may have written the value in, each with its factor to ``unit``,
        most likely first.
    typical : float, optional
        A typical value [``unit``]: of several slips that bring the value into the
        bound, the message names the one nearest to it (in ratio); default the
        geometric mean of a positive bound, else the first slip that fits.
    """

    what: str
    lo: float
    hi: float
    unit: str
    why: str = ""
    slips: tuple = ()
    typical: float | None = None

    def contains(self, value: float) -> bool:
        """True if ``lo <= value <= hi``."""
        return self.lo <= value <= self.hi

    def message(self, field: str, value: float) -> str:
        """``field = value is not a plausible ... (lo..hi unit why); if it was entered in U, it is V unit``."""
        why = f", {self.why}" if self.why else ""
        span = f"{_g(self.lo)}..{_g(self.hi)} {self.unit}{why}"
        text = f"{field} = {_g(value, 6)} is not a plausible {self.what} ({span})"
        fits = [(name, value * factor) for name, factor in self.slips if self.contains(value * factor)]
        typical = self.typical if self.typical is not None else (
            math.sqrt(self.lo * self.hi) if self.lo > 0 else None)
        if typical is not None and len(fits) > 1:
            fits = [min(fits, key=lambda f: abs(math.log(abs(f[1]) / typical)) if f[1] else math.inf)]
        if fits:
            name, si = fits[0]
            text += f"; if it was entered in {name}, it is {_g(si, 6)} {self.unit}"
        return text

    def check(self, field: str, value: float, error=ConfigError) -> float:
        """``value``, or raise ``error`` with :meth:`message` if it lies outside the bound.

        Parameters
        ----------
        field : str
            The field or option, for the message.
        value : float
            The value [``unit``].
        error : type, default ConfigError
            The exception class to raise.
        """
        if not self.contains(value):
            raise error(self.message(field, value))
        return value


def cross_section(actuator) -> dict:
    """Second moments and areas of the actuator's cross-section (paper Fig. 3(b)).

    The section is a bottom layer (thickness b, width 2(a + t)) under a half-annulus of
    inner radius a (the chamber) and outer radius a + t. ``solid`` fills the chamber (an
    upper bound of the material's I), ``hollow`` leaves it empty.

    Parameters
    ----------
    actuator : ActuatorConfig
        Its ``chamber_radius_m``, ``wall_thickness_m``, ``bottom_thickness_m``.

    Returns
    -------
    dict
        ``i_solid_m4``, ``i_hollow_m4`` [m⁴] about the section's centroid,
        ``area_solid_m2``, ``area_hollow_m2`` [m²].
    """
    a, t, b = actuator.chamber_radius_m, actuator.wall_thickness_m, actuator.bottom_thickness_m
    r = a + t
    w = 2.0 * r

    def half_disk(radius, sign):  # (area, centroid height, I about own centroid), flat side on y = b
        return (sign * math.pi * radius**2 / 2.0, b + 4.0 * radius / (3.0 * math.pi),
                sign * (math.pi / 8.0 - 8.0 / (9.0 * math.pi)) * radius**4)

    out = {}
    for name, parts in (("solid", [(w * b, b / 2.0, w * b**3 / 12.0), half_disk(r, 1.0)]),
                        ("hollow", [(w * b, b / 2.0, w * b**3 / 12.0), half_disk(r, 1.0), half_disk(a, -1.0)])):
        area = sum(p[0] for p in parts)
        yc = sum(p[0] * p[1] for p in parts) / area
        out[f"i_{name}_m4"] = sum(p[2] + p[0] * (p[1] - yc) ** 2 for p in parts)
        out[f"area_{name}_m2"] = area
    return out


def stiffness_bound_nm2(actuator) -> tuple[float, float]:
    """Plausible flexural rigidity EI of the actuator [N·m²]: ``E·I`` from its cross-section.

    ``E_min · I_hollow / WIDEN .. E_max · I_solid · WIDEN`` with E of soft silicones
    (:data:`YOUNG_MODULUS_PA`) and I from :func:`cross_section`. The paper's prototype:
    4.4e-6..0.11 N·m² (its γ0 = 2.53e-3 N·m², E ≈ 2.5 MPa).

    Parameters
    ----------
    actuator : ActuatorConfig
        The actuator's geometry.
    """
    cs = cross_section(actuator)
    return (YOUNG_MODULUS_PA[0] * cs["i_hollow_m4"] / WIDEN, YOUNG_MODULUS_PA[1] * cs["i_solid_m4"] * WIDEN)


def max_curvature_per_m(sensor) -> float:
    """The largest curvature the sensor can measure [1/m]: ``min(1/d, π/l_min)``.

    Its two strips, a gap d apart, cannot bend to a radius below d (they would fold onto
    each other), and a piecewise-constant-curvature segment of length l that turns by
    more than half a turn is no longer told apart from a smaller bend (paper eq. 5–7).

    Parameters
    ----------
    sensor : SensorConfig
        Its ``strip_gap_m`` and ``segment_lengths_m``.
    """
    return min(1.0 / sensor.strip_gap_m, math.pi / min(sensor.segment_lengths_m))


def pressure_bound(what: str = "working pressure of a soft pneumatic actuator") -> Bound:
    """Plausible gauge pressure of a soft actuator: 1 kPa..:data:`PRESSURE_MAX_PA` [Pa].

    Parameters
    ----------
    what : str
        What the value is, for the message.
    """
    return Bound(what, 1e3, PRESSURE_MAX_PA, "Pa", slips=PRESSURE_SLIPS, typical=100e3)


def shear_modulus_bound() -> Bound:
    """Plausible effective shear modulus μ̄ (paper eq. 10–12): E/3 of soft silicones, widened [Pa]."""
    return Bound("shear modulus of a silicone actuator", YOUNG_MODULUS_PA[0] / 3.0 / WIDEN,
                 YOUNG_MODULUS_PA[1] / 3.0 * WIDEN, "Pa", "E/3 of soft silicones", MODULUS_SLIPS)


def prebend_bound() -> Bound:
    """Plausible prebend angle: ``|θ_pre| <= π/2`` (:data:`PREBEND_MAX_RAD`) [rad]."""
    return Bound("prebend angle", -PREBEND_MAX_RAD, PREBEND_MAX_RAD, "rad", "a curl at rest", ANGLE_SLIPS)


def angle_bound(what: str) -> Bound:
    """Plausible angle: one turn either way [rad].

    Parameters
    ----------
    what : str
        What the angle is, for the message.
    """
    return Bound(what, -2.0 * math.pi, 2.0 * math.pi, "rad", "one turn", ANGLE_SLIPS)


def parameter_bounds(actuator, pressure_range_pa=None, ei0_nm2=None) -> dict:
    """Plausible values of the model parameters (``MODEL_PARAMETERS``) of this actuator, by name.

    ``ei0_nm2``: :func:`stiffness_bound_nm2`; ``ei1_nm2_per_pa``: EI(P) within that bound
    over the pressure range (with ``ei0_nm2`` given, at that ei0; else for any plausible
    one); ``shear_modulus_pa``: E/3 of soft silicones; ``sensor_stiffness_nm_per_rad``:
    ``0..EI_max / L`` (a layer along the actuator is no stiffer than the actuator can be);
    ``prebend_angle_rad``: :data:`PREBEND_MAX_RAD`.

    Parameters
    ----------
    actuator : ActuatorConfig
        The actuator's geometry and pressure range.
    pressure_range_pa : tuple of float, optional
        Default ``actuator.pressure_range_pa`` [Pa].
    ei0_nm2 : float, optional
        The stiffness at zero pressure, if known [N·m²].
    """
    lo_ei, hi_ei = stiffness_bound_nm2(actuator)
    p_lo, p_hi = actuator.pressure_range_pa if pressure_range_pa is None else pressure_range_pa
    ei1_lo, ei1_hi = -math.inf, math.inf
    for p in (p_lo, p_hi):
        if p == 0.0:
            continue
        ends = ((lo_ei - hi_ei) / p, hi_ei / p) if ei0_nm2 is None else ((lo_ei - ei0_nm2) / p, (hi_ei - ei0_nm2) / p)
        ei1_lo, ei1_hi = max(ei1_lo, min(ends)), min(ei1_hi, max(ends))
    span = f"over {p_lo / 1e3:g}..{p_hi / 1e3:g} kPa"
    return {
        "ei0_nm2": Bound("bending stiffness for this actuator", lo_ei, hi_ei, "N·m²", "from its cross-section",
                         EI_SLIPS),
        "ei1_nm2_per_pa": Bound("pressure stiffening for this actuator", ei1_lo, ei1_hi, "N·m²/Pa",
                                f"to keep EI(P) within {_g(lo_ei)}..{_g(hi_ei)} N·m² {span}", EI1_SLIPS,
                                typical=(ei0_nm2 or math.sqrt(lo_ei * hi_ei)) / max(abs(p_lo), abs(p_hi), 1.0)),
        "shear_modulus_pa": shear_modulus_bound(),
        "sensor_stiffness_nm_per_rad": Bound("sensor bending stiffness for this actuator", 0.0,
                                             hi_ei / actuator.length_m, "N·m/rad", "at most EI_max / L",
                                             TORQUE_SLIPS),
        "prebend_angle_rad": prebend_bound(),
    }


def check_config(config) -> None:
    """Refuse a config whose physical values no actuator of its geometry can have.

    Called by ``Config.__post_init__`` after each section checked its own fields (their
    absolute bounds); here the bounds that need the geometry, most basic field first so
    that the message blames the field that is off: segment lengths (at most the
    actuator's length; their sum at most 1.05 times it), strip gap (at most the shortest segment), sleeve (at most the
    section's height), cross-section dimensions (at most a quarter of the length: a beam),
    mass (from the volume and silicone density), ``ei0_nm2``, ``ei1_nm2_per_pa``,
    ``sensor_stiffness_nm_per_rad`` (:func:`parameter_bounds`) and the standard
    deviations of ``parameter_covariance`` (at most the parameter's whole plausible
    range).

    Parameters
    ----------
    config : Config
        The config to check.

    Raises
    ------
    ConfigError
        Naming the field, the bound, the likely unit slip and the value in SI units.
    """
    act, sensor = config.actuator, config.sensor
    length = act.length_m
    segment = Bound("segment length for this actuator", 0.0, length, "m", "at most the actuator's length_m",
                    LENGTH_SLIPS, typical=length / sensor.n_segments)
    for i, value in enumerate(sensor.segment_lengths_m):
        segment.check(f"sensor.segment_lengths_m[{i}]", value)
    sensor_m = float(sum(sensor.segment_lengths_m))
    if sensor_m > 1.05 * length:
        raise ConfigError(f"actuator.length_m: {length:g} m is shorter than the sensor glued along it "
                          f"(sensor.segment_lengths_m sum to {sensor_m:g} m)")
    shortest = min(sensor.segment_lengths_m)
    Bound("strip gap for this sensor", 0.0, shortest, "m", "at most the shortest segment",
          LENGTH_SLIPS, typical=shortest / 8.0).check("sensor.strip_gap_m", sensor.strip_gap_m)
    height = act.chamber_radius_m + act.wall_thickness_m + act.bottom_thickness_m
    Bound("sleeve thickness for this actuator", 0.0, height, "m", "at most the cross-section's height a + t + b",
          LENGTH_SLIPS, typical=height / 10.0).check("sensor.sleeve_thickness_m", sensor.sleeve_thickness_m)
    dimension = Bound("cross-section dimension for this actuator", 0.0, length / 4.0, "m",
                      "at most a quarter of its length_m: a beam", LENGTH_SLIPS, typical=length / 40.0)
    for name in ("chamber_radius_m", "wall_thickness_m", "bottom_thickness_m"):
        dimension.check(f"actuator.{name}", getattr(act, name))
    cs = cross_section(act)
    Bound("mass for this actuator", DENSITY_KG_PER_M3[0] * cs["area_hollow_m2"] * length / WIDEN,
          DENSITY_KG_PER_M3[1] * cs["area_solid_m2"] * length * WIDEN, "kg", "from its volume and silicone density",
          MASS_SLIPS).check("actuator.mass_kg", act.mass_kg)
    bounds = parameter_bounds(act, ei0_nm2=config.stiffness.ei0_nm2)
    bounds["ei0_nm2"].check("stiffness.ei0_nm2", config.stiffness.ei0_nm2)
    bounds["ei1_nm2_per_pa"].check("stiffness.ei1_nm2_per_pa", config.stiffness.ei1_nm2_per_pa)
    bounds["sensor_stiffness_nm_per_rad"].check("material.sensor_stiffness_nm_per_rad",
                                                config.material.sensor_stiffness_nm_per_rad)
    cov = config.parameter_covariance
    if cov is not None:
        for i, (name, var) in enumerate(zip(cov.parameters, np.diag(cov.matrix), strict=True)):
            b = bounds[name]
            top = max(abs(b.lo), abs(b.hi)) ** 2
            Bound(f"variance of {name}", 0.0, top, f"({b.unit})²", f"σ at most {_g(math.sqrt(top))} {b.unit}, "
                  "its whole plausible range", tuple((f"({u})²", f * f) for u, f in b.slips)).check(
                f"parameter_covariance.covariance[{i}][{i}]", float(var))


# --- per frame: a force the actuator cannot carry -------------------------------------------

IMPLAUSIBLE_FORCE = "implausible_force"
"""Status (and message prefix) of a frame whose fitted force is beyond what the actuator can carry."""
FORCE_MARGIN = 10.0
"""Factor of :func:`force_bound_n` over the force that bends the actuator by the sensor's range."""


def force_bound_n(pressure_pa, config):
    """The largest tip force a measured shape of this actuator can come from [N].

    ``F_max(P) = FORCE_MARGIN · EI(P) · κ_max / L``, with ``κ_max`` the largest
    curvature the sensor can measure (:func:`max_curvature_per_m`) and ``FORCE_MARGIN``
    = 10. Why: in equilibrium ``EI (κ(s) − K0) = −M_z(s)`` (DESIGN section 2), and the
    moment of a tip force F about a point of the beam is ``|F|`` times that point's
    distance from the force's line of action. Every curvature of a shape the sensor
    measured, the natural one K0 included, is within ``κ_max``, so
    ``|F| · h ≤ 2 EI κ_max`` with ``h`` the largest distance of the beam from the line of
    action. A factor 10 leaves ``h`` down to L/5: only an actuator lying along its own
    load line is left out, and there the load is compression (it buckles at
    ``π² EI / 4L²``, far below the bound) or tension, which no shape shows (such a
    frame is ``not_identifiable``: its force is where the fit stopped, not a
    measurement). For the paper's prototype ``F_max`` is 74 N at 0 kPa and 147 N at
    200 kPa, beyond anything a 13 cm silicone finger holds; forces beyond it come from
    a unit slip (an EI in N·mm², a calibration a thousand times off), not from a load.

    Parameters
    ----------
    pressure_pa : float or array_like
        Gauge pressures [Pa].
    config : Config
        The actuator (``stiffness``, ``actuator.length_m``) and its sensor.

    Returns
    -------
    float or ndarray
        ``F_max`` at each pressure [N] (NaN where the pressure is).
    """
    scale = FORCE_MARGIN * max_curvature_per_m(config.sensor) / config.actuator.length_m
    if isinstance(pressure_pa, float):
        return scale * config.stiffness.ei_nm2(pressure_pa)
    return scale * config.stiffness.ei_nm2(np.asarray(pressure_pa, dtype=float))


def force_bound_step(estimate):
    """Wrap ``estimate_force``: a frame whose force is beyond :func:`force_bound_n` is not ok.

    The force is kept (as with ``model_misfit``) but a frame that succeeded gets
    ``success`` False and the message ``"implausible_force: ..."`` (status ``implausible_force``); with
    ``strict=True`` such a frame raises :class:`~bendsense.errors.ConvergenceError`.

    Parameters
    ----------
    estimate : callable
        ``estimate_force`` or a function with its signature.
    """

    @functools.wraps(estimate)
    def estimate_force(shape, pressure_pa, config=None, *args, **options):
        result = estimate(shape, pressure_pa, config, *args, **options)
        if config is None:
            from bendsense.config import load_config

            config = load_config()
        force = np.asarray(result.force_n, dtype=float)
        if force.ndim == 1:  # one frame (the live path): float arithmetic
            magnitude = math.hypot(float(force[0]), float(force[1]))
            p = float(np.asarray(pressure_pa, dtype=float).reshape(-1)[0])
            top = force_bound_n(p, config)
            if not (magnitude > top and bool(result.success)):  # a failed frame keeps its own reason
                return result
            over, magnitude, top, p = np.bool_(True), np.float64(magnitude), np.float64(top), np.float64(p)
        else:
            magnitude = np.hypot(force[..., 0], force[..., 1])
            p = np.broadcast_to(np.asarray(pressure_pa, dtype=float), magnitude.shape)
            top = force_bound_n(p, config)
            with np.errstate(invalid="ignore"):  # a failed frame keeps its own reason
                over = np.isfinite(magnitude) & (magnitude > top) & np.broadcast_to(result.success, magnitude.shape)
            if not over.any():
                return result
        if options.get("strict"):
            from bendsense.errors import ConvergenceError

            first = np.argwhere(np.atleast_1d(over))[0]
            m, t = np.atleast_1d(magnitude)[tuple(first)], np.atleast_1d(top)[tuple(first)]
            raise ConvergenceError(f"{int(np.count_nonzero(over))} frame(s) {IMPLAUSIBLE_FORCE}: |F| = {m:.3g} N "
                                   f"beyond the {t:.3g} N this actuator can carry")
        return _mark_force(result, over, magnitude, top, p)

    return estimate_force


def _mark_force(result, over, magnitude, top, p):
    """``result`` with the frames where ``over`` is true flagged ``implausible_force`` (force kept)."""
    batch = result.batch_shape
    message = np.array(np.broadcast_to(np.asarray(result.message, dtype=object), batch), dtype=object)
    for index in zip(*np.nonzero(over)) if batch else [()]:
        message[index] = (f"{IMPLAUSIBLE_FORCE}: |F| = {float(magnitude[index]):.3g} N is beyond the "
                          f"{float(top[index]):.3g} N this actuator can carry at {float(p[index]) / 1e3:g} kPa "
                          f"({FORCE_MARGIN:g} EI(P) κ_max / L): check the units of the config's stiffness and the "
                          "calibration")
    return dataclasses.replace(result, success=np.where(over, False, result.success),
                               message=message.astype(str) if batch else str(message[()]))
