"""Physical bounds of a config's values, from the actuator's geometry and materials.

A soft actuator is a silicone beam a few millimetres across and a few centimetres long;
what its parameters can be follows from its geometry and the materials it is cast from:
the bending stiffness ``E·I`` from the cross-section (:func:`stiffness_bound_nm2`), the
mass from the volume and silicone density, the segment lengths and gap from the
actuator's length, the curvature the sensor can measure from its gap and segments
(:func:`max_curvature_per_m`), pressures up to 1 MPa. The bounds are wide (a factor
:data:`WIDEN` beyond the materials' range) so that no real actuator is refused; what
they catch are values off by a unit (a thousand, a million). A value outside its
:class:`Bound` raises an error naming the field, the bound, the likely unit slip and
the value in SI units (:func:`check_config`, called by ``Config``; the same bounds
check ``identify --fix`` and the pressure options of the command line).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bendsense.errors import ConfigError

__all__ = [
    "Bound",
    "cross_section",
    "stiffness_bound_nm2",
    "max_curvature_per_m",
    "pressure_bound",
    "shear_modulus_bound",
    "prebend_bound",
    "angle_bound",
    "parameter_bounds",
    "check_config",
]

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
        """True if ``lo <= value <= hi``.

        Parameters
        ----------
        value : float
            The value [``unit``].
        """
        return self.lo <= value <= self.hi

    def message(self, field: str, value: float) -> str:
        """``field = value is not a plausible ... (lo..hi unit, why); if it was entered in U, it is V unit``.

        Parameters
        ----------
        field : str
            The field or option.
        value : float
            The value as given [``unit``].
        """
        why = f", {self.why}" if self.why else ""
        unit = f" {self.unit}" if self.unit else ""
        span = f"{_g(self.lo)}..{_g(self.hi)}{unit}{why}"
        text = f"{field} = {_g(value, 6)} is not a plausible {self.what} ({span})"
        fits = [(name, value * factor) for name, factor in self.slips if self.contains(value * factor)]
        typical = self.typical if self.typical is not None else (
            math.sqrt(self.lo * self.hi) if self.lo > 0 else None)
        if typical is not None and len(fits) > 1:
            fits = [min(fits, key=lambda f: abs(math.log(abs(f[1]) / typical)) if f[1] else math.inf)]
        if fits:
            name, si = fits[0]
            text += f"; if it was entered in {name}, it is {_g(si, 6)}{unit}"
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
