"""Configuration sections: the sensor, the actuator, its material and stiffness, gravity and estimation options.

Every section is a frozen, keyword-only dataclass with SI units in its field names
and its checks in ``__post_init__``. ``Config.from_dict`` / ``Config.to_dict``
map to and from the YAML layout of ``configs/paper.yaml``; an invalid value raises
:class:`~bendsense.errors.ConfigError` naming the field path and the value, e.g.
``sensor.segment_lengths_m[3]: must be > 0, got -0.008``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from bendsense import validation as check
from bendsense.choices import ANGLE_SOURCES, CONSTRAINTS, METHODS, OBJECTIVES  # noqa: F401 (re-exported)
from bendsense.errors import ConfigError
from bendsense.mechanics import bounds

__all__ = [
    "SensorConfig",
    "ActuatorConfig",
    "MaterialConfig",
    "StiffnessConfig",
    "GravityConfig",
    "EstimationConfig",
    "ParameterCovarianceConfig",
    "Config",
    "PAPER_CONFIG",
    "MODEL_PARAMETERS",
    "FREE_BENDING_PARAMETERS",
    "STIFFNESS_PARAMETERS",
]

PAPER_CONFIG = "paper.yaml"
SMALL_M = 0.1
"""Largest plausible cross-section dimension (strip gap, sleeve, wall, chamber radius) [m]."""
PRESSURE_RANGE_PA = (0.0, 200e3)
"""Default working range of the actuator's gauge pressure (the paper's prototype) [Pa]."""
# the identified model parameters θ (paper eq. 8–12, 15) and the config section of each
FREE_BENDING_PARAMETERS = ("shear_modulus_pa", "sensor_stiffness_nm_per_rad", "prebend_angle_rad")
STIFFNESS_PARAMETERS = ("ei0_nm2", "ei1_nm2_per_pa")
MODEL_PARAMETERS = FREE_BENDING_PARAMETERS + STIFFNESS_PARAMETERS
_PARAMETER_SECTION = {
    **dict.fromkeys(FREE_BENDING_PARAMETERS, "material"),
    **dict.fromkeys(STIFFNESS_PARAMETERS, "stiffness"),
}


def _fail(path: str, message: str) -> ConfigError:
    return ConfigError(f"{path}: {message}")


# the checks of bendsense.validation, raising ConfigError
def _number(path: str, value: Any, *, positive: bool = False, nonnegative: bool = False) -> float:
    return check.number(path, value, error=ConfigError, positive=positive, nonnegative=nonnegative)


def _length(path: str, value: Any, *, max_m: float = check.MAX_LENGTH_M, positive: bool = True,
            typical_m: float = 0.01) -> float:
    """A length [m]: finite, > 0 (or >= 0) and at most ``max_m``.

    Beyond, the message names the unit slip (mm or cm, whichever gives a value nearer
    ``typical_m``) and the value in metres.
    """
    value = _number(path, value, positive=positive, nonnegative=not positive)
    what = "length" if max_m >= check.MAX_LENGTH_M else "cross-section or sensor dimension"
    bounds.Bound(what, 0.0, max_m, "m", "", bounds.LENGTH_SLIPS, typical=typical_m).check(path, value)
    return value


def _integer(path: str, value: Any, *, minimum: int | None = None, maximum: int | None = None) -> int:
    return check.integer(path, value, error=ConfigError, minimum=minimum, maximum=maximum)


def _numbers(path: str, value: Any, length: int | None = None, *, positive: bool = False, check_one=None) -> tuple:
    if not isinstance(value, (list, tuple)):
        raise check.fail(path, "a list of numbers", value, ConfigError)
    if length is not None and len(value) != length:
        raise check.fail(path, f"{length} values", len(value), ConfigError)
    one = check_one or (lambda where, v: _number(where, v, positive=positive))
    return tuple(one(f"{path}[{i}]", v) for i, v in enumerate(value))


def _choice(path: str, value: Any, choices: tuple[str, ...]) -> str:
    return check.choice(path, value, choices, error=ConfigError)


def _boolean(path: str, value: Any) -> bool:
    return check.boolean(path, value, error=ConfigError)


def _names(names) -> str:
    """At most 8 names, comma-separated (a message never lists a file's worth of keys)."""
    names = [check.key(n) for n in names]
    return ", ".join(names) if len(names) <= 8 else ", ".join(names[:8]) + f", ... ({len(names)} in all)"


class _Section:
    """Mixin: dict conversion with unknown/missing-key checks for a config section."""

    section: ClassVar[str]
    #: Model parameters with a default in Python that a YAML section must still give: left out of a
    #: partial section, the default would change the physics silently (``ei1_nm2_per_pa`` 0).
    model_keys: ClassVar[tuple] = ()

    @classmethod
    def from_dict(cls, data: Any):
        path = cls.section
        if not isinstance(data, dict):
            raise check.fail(path, "a mapping", data, ConfigError)
        names = [f.name for f in dataclasses.fields(cls)]
        required = [
            f.name
            for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING or f.name in cls.model_keys
        ]
        unknown = sorted(set(data) - set(names), key=str)
        if unknown:
            raise _fail(path, f"unknown keys {_names(unknown)}; allowed: {', '.join(names)}")
        missing = [n for n in required if n not in data]
        if missing:
            raise _fail(path, f"missing keys {', '.join(missing)}")
        return cls(**data)

    def to_dict(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out


@dataclass(frozen=True, kw_only=True)
class SensorConfig(_Section):
    """The distributed inductive curvature sensor (paper section II, V-A).

    Parameters
    ----------
    n_segments : int
        Number of receiver coils and PCC segments N.
    segment_lengths_m : tuple of float
        Segment lengths l_i [m], base to tip.
    strip_gap_m : float
        Distance d between receiver and transmitter strips [m].
    sleeve_thickness_m : float
        Silicone sleeve thickness c [m].
    calibration_adds_sleeve : bool
        If true, a calibration strip of radius R gives κ_cal = 1/(R + c);
        the paper's default is κ_cal = 1/R.
    coil_diameter_m, coil_turns, coil_pitch_m : float, int, float
        Coil geometry, used by the simulator (1 to 200 turns).
    """

    section: ClassVar[str] = "sensor"
    n_segments: int
    segment_lengths_m: tuple
    strip_gap_m: float
    sleeve_thickness_m: float
    calibration_adds_sleeve: bool = False
    coil_diameter_m: float = 0.006
    coil_turns: int = 20
    coil_pitch_m: float = 0.008

    def __post_init__(self):
        p = self.section
        n = _integer(f"{p}.n_segments", self.n_segments, minimum=1, maximum=64)
        set_ = object.__setattr__
        lengths = _numbers(f"{p}.segment_lengths_m", self.segment_lengths_m, n, check_one=_length)
        set_(self, "segment_lengths_m", lengths)
        # small dimensions: over 0.1 m is a unit mistake ("looks like millimetres")
        set_(self, "strip_gap_m", _length(f"{p}.strip_gap_m", self.strip_gap_m, max_m=SMALL_M, typical_m=1e-3))
        set_(self, "sleeve_thickness_m",
             _length(f"{p}.sleeve_thickness_m", self.sleeve_thickness_m, max_m=SMALL_M, positive=False,
                     typical_m=1e-3))
        _boolean(f"{p}.calibration_adds_sleeve", self.calibration_adds_sleeve)
        set_(self, "coil_diameter_m", _length(f"{p}.coil_diameter_m", self.coil_diameter_m, max_m=SMALL_M))
        # the simulator sums turns² mutual inductances: 100 turns take 15 s a frame set, 1000 a quarter of an hour
        _integer(f"{p}.coil_turns", self.coil_turns, minimum=1, maximum=200)
        set_(self, "coil_pitch_m", _length(f"{p}.coil_pitch_m", self.coil_pitch_m, max_m=SMALL_M))

    @property
    def lengths_m(self) -> np.ndarray:
        """Segment lengths l_i as an array [m]."""
        return np.asarray(self.segment_lengths_m, dtype=float)

    @property
    def length_m(self) -> float:
        """Total sensor length L_N [m]."""
        return float(sum(self.segment_lengths_m))


@dataclass(frozen=True, kw_only=True)
class ActuatorConfig(_Section):
    """Geometry and mass of the soft bending actuator (paper Fig. 3(b), V-A).

    Parameters
    ----------
    chamber_radius_m : float
        Inner chamber radius a [m].
    bottom_thickness_m : float
        Bottom (strain-limiting) layer thickness b [m].
    wall_thickness_m : float
        Wall thickness t [m].
    length_m : float
        Actuator length L [m].
    mass_kg : float
        Total mass of actuator and sensor [kg].
    pressure_range_pa : tuple of float
        ``[min, max]`` gauge pressure the actuator works at [Pa] (default 0..200 kPa,
        the paper's prototype). Frames outside it get the status
        ``pressure_out_of_range`` and no force.
    """

    section: ClassVar[str] = "actuator"
    chamber_radius_m: float
    bottom_thickness_m: float
    wall_thickness_m: float
    length_m: float
    mass_kg: float
    pressure_range_pa: tuple = PRESSURE_RANGE_PA

    def __post_init__(self):
        p, set_ = self.section, object.__setattr__
        for name in ("chamber_radius_m", "bottom_thickness_m", "wall_thickness_m"):
            set_(self, name, _length(f"{p}.{name}", getattr(self, name), max_m=SMALL_M, typical_m=3e-3))
        set_(self, "length_m", _length(f"{p}.length_m", self.length_m, typical_m=0.1))
        set_(self, "mass_kg", _number(f"{p}.mass_kg", self.mass_kg, positive=True))
        lo, hi = _numbers(f"{p}.pressure_range_pa", self.pressure_range_pa, 2)
        where = f"{p}.pressure_range_pa"
        if lo < -101_325:
            raise check.fail(where, "a minimum >= -101325 Pa (vacuum)", lo, ConfigError)
        if not hi > lo:
            raise check.fail(where, "[min, max] with min < max", [lo, hi], ConfigError)
        bounds.pressure_bound("maximum pressure of a soft pneumatic actuator").check(f"{where}[1]", hi)
        set_(self, "pressure_range_pa", (lo, hi))


@dataclass(frozen=True, kw_only=True)
class MaterialConfig(_Section):
    """Material parameters of the free-bending model (paper eq. 10–12).

    Parameters
    ----------
    shear_modulus_pa : float
        Effective shear modulus μ̄ [Pa].
    sensor_stiffness_nm_per_rad : float
        Sensor bending stiffness μ_s [N·m/rad].
    prebend_angle_rad : float
        Bending angle at zero pressure, added to θ0 [rad].
    """

    section: ClassVar[str] = "material"
    model_keys: ClassVar[tuple] = ("prebend_angle_rad",)
    shear_modulus_pa: float
    sensor_stiffness_nm_per_rad: float
    prebend_angle_rad: float = 0.0

    def __post_init__(self):
        p = self.section
        object.__setattr__(
            self, "shear_modulus_pa", _number(f"{p}.shear_modulus_pa", self.shear_modulus_pa, positive=True)
        )
        bounds.shear_modulus_bound().check(f"{p}.shear_modulus_pa", self.shear_modulus_pa)
        object.__setattr__(
            self,
            "sensor_stiffness_nm_per_rad",
            _number(f"{p}.sensor_stiffness_nm_per_rad", self.sensor_stiffness_nm_per_rad, nonnegative=True),
        )
        object.__setattr__(self, "prebend_angle_rad", _number(f"{p}.prebend_angle_rad", self.prebend_angle_rad))
        bounds.prebend_bound().check(f"{p}.prebend_angle_rad", self.prebend_angle_rad)


@dataclass(frozen=True, kw_only=True)
class StiffnessConfig(_Section):
    """Pressure-dependent flexural rigidity EI(P) = ei0 + ei1·P (paper eq. 15)."""

    section: ClassVar[str] = "stiffness"
    model_keys: ClassVar[tuple] = ("ei1_nm2_per_pa",)
    ei0_nm2: float
    ei1_nm2_per_pa: float = 0.0

    def __post_init__(self):
        p = self.section
        object.__setattr__(self, "ei0_nm2", _number(f"{p}.ei0_nm2", self.ei0_nm2, positive=True))
        object.__setattr__(self, "ei1_nm2_per_pa", _number(f"{p}.ei1_nm2_per_pa", self.ei1_nm2_per_pa))

    def ei_nm2(self, pressure_pa):
        """Flexural rigidity EI [N·m²] at gauge pressure ``pressure_pa`` [Pa].

        Parameters
        ----------
        pressure_pa : float or array_like
            Gauge pressure P [Pa].
        """
        return self.ei0_nm2 + self.ei1_nm2_per_pa * np.asarray(pressure_pa, dtype=float)


@dataclass(frozen=True, kw_only=True)
class GravityConfig(_Section):
    """Gravity: acceleration g and its unit direction in the base frame (DESIGN section 2)."""

    section: ClassVar[str] = "gravity"
    g_m_per_s2: float = 9.81
    direction: tuple = (0.0, -1.0)

    def __post_init__(self):
        p = self.section
        object.__setattr__(self, "g_m_per_s2", _number(f"{p}.g_m_per_s2", self.g_m_per_s2, nonnegative=True))
        gravity = bounds.Bound("gravity of a rig", *bounds.GRAVITY_M_PER_S2, "m/s²", "or 0: none",
                                     bounds.GRAVITY_SLIPS, typical=9.81)
        if self.g_m_per_s2 != 0.0:
            gravity.check(f"{p}.g_m_per_s2", self.g_m_per_s2)
        d = _numbers(f"{p}.direction", self.direction, 2)
        norm = math.hypot(*d)
        if abs(norm - 1.0) > 1e-6:
            hint = ""
            if gravity.contains(norm):  # the acceleration vector where its direction belongs
                hint = (f"; looks like the acceleration in m/s²: direction [{d[0] / norm:g}, {d[1] / norm:g}] "
                        f"with g_m_per_s2: {norm:g}")
            raise _fail(f"{p}.direction", f"must be a unit vector, got {list(d)} (norm {norm:.6g}){hint}")
        object.__setattr__(self, "direction", d)


@dataclass(frozen=True, kw_only=True)
class EstimationConfig(_Section):
    """Options of the force estimate (paper eq. 18, 21; DESIGN section 2).

    Parameters
    ----------
    constraint : str
        ``none``, ``vertical``, ``horizontal``, ``direction`` (along ``direction``),
        ``normal`` (normal to the tip tangent) or ``follower`` (at
        ``follower_angle_rad`` to the tip tangent).
    method : str
        ``fast`` (default) or ``paper`` (shooting + Nelder–Mead / SLSQP).
    objective : str
        ``positions`` (default): the beam's points against the PCC shape's at quadrature
        nodes (paper eq. 18); ``angles``: the beam's tangent angle at each coil against
        the measured ``S_i / d``, weighted by the inverse covariance of the measured
        angles (what the sensor measures; no PCC bias).
    n_points : int
        Sample points along the actuator for the shape-distance quadrature.
    tip_angle_source : str
        Where ``normal``/``follower`` take the tip angle: ``model`` (free-bending
        model, as in the paper) or ``shape`` (the reconstructed shape).
    direction : tuple of float
        Unit direction of the force for ``constraint: direction``.
    follower_angle_rad : float
        Angle of a follower force from the tip tangent [rad].
    push_only : bool
        Bound the force magnitude along its constrained direction to >= 0.
    signal_noise_std : float
        Standard deviation of the signal noise ΔA used for the force uncertainty
        when the calibration does not provide one [signal units].
    pressure_max_pa : float
        Upper end of the precomputed free-bending interpolant [Pa].
    """

    section: ClassVar[str] = "estimation"
    constraint: str = "none"
    method: str = "fast"
    objective: str = "angles"
    n_points: int = 41
    tip_angle_source: str = "model"
    direction: tuple = (0.0, -1.0)
    follower_angle_rad: float = math.pi / 2
    push_only: bool = False
    signal_noise_std: float = 0.0
    pressure_max_pa: float = 200e3

    def __post_init__(self):
        p = self.section
        _choice(f"{p}.constraint", self.constraint, CONSTRAINTS)
        _choice(f"{p}.method", self.method, METHODS)
        _choice(f"{p}.objective", self.objective, OBJECTIVES)
        _integer(f"{p}.n_points", self.n_points, minimum=3, maximum=1000)
        _choice(f"{p}.tip_angle_source", self.tip_angle_source, ANGLE_SOURCES)
        d = _numbers(f"{p}.direction", self.direction, 2)
        norm = math.hypot(*d)
        if abs(norm - 1.0) > 1e-6:
            raise _fail(f"{p}.direction", f"must be a unit vector, got {list(d)} (norm {norm:.6g})")
        object.__setattr__(self, "direction", d)
        object.__setattr__(self, "follower_angle_rad", _number(f"{p}.follower_angle_rad", self.follower_angle_rad))
        bounds.angle_bound("angle from the tip tangent").check(f"{p}.follower_angle_rad",
                                                                     self.follower_angle_rad)
        _boolean(f"{p}.push_only", self.push_only)
        object.__setattr__(
            self, "signal_noise_std", _number(f"{p}.signal_noise_std", self.signal_noise_std, nonnegative=True)
        )
        object.__setattr__(
            self, "pressure_max_pa", _number(f"{p}.pressure_max_pa", self.pressure_max_pa, positive=True)
        )
        bounds.pressure_bound("maximum pressure of a soft pneumatic actuator").check(
            f"{p}.pressure_max_pa", self.pressure_max_pa)


@dataclass(frozen=True, kw_only=True)
class ParameterCovarianceConfig(_Section):
    """Covariance of the identified model parameters θ (written by ``bendsense identify``).

    Parameters
    ----------
    parameters : tuple of str
        Names from ``MODEL_PARAMETERS`` (``shear_modulus_pa``,
        ``sensor_stiffness_nm_per_rad``, ``prebend_angle_rad``, ``ei0_nm2``,
        ``ei1_nm2_per_pa``), each once, in the order of the matrix. Parameters not
        listed are treated as exact.
    covariance : tuple of tuple of float
        Symmetric positive semi-definite k × k matrix in the parameters' SI units
        (e.g. [Pa²] for ``shear_modulus_pa``).
    source : str
        How it was obtained (e.g. which fits, and that separate fits give a block
        diagonal matrix).
    """

    section: ClassVar[str] = "parameter_covariance"
    parameters: tuple
    covariance: tuple
    source: str = ""

    def __post_init__(self):
        p = self.section
        names = self.parameters
        if not isinstance(names, (list, tuple)) or not names:
            raise _fail(f"{p}.parameters", f"expected a non-empty list of names, got {check.short(names)}")
        for i, name in enumerate(names):
            if name not in MODEL_PARAMETERS:
                allowed = ", ".join(MODEL_PARAMETERS)
                raise _fail(f"{p}.parameters[{i}]", f"must be one of {allowed}, got {check.short(name)}")
        if len(set(names)) != len(names):
            raise _fail(f"{p}.parameters", f"each name once, got {check.short(list(names))}")
        k = len(names)
        rows = self.covariance
        if not isinstance(rows, (list, tuple)) or len(rows) != k:
            got = len(rows) if isinstance(rows, (list, tuple)) else check.short(rows)
            raise _fail(f"{p}.covariance", f"expected {k} rows (one per parameter), got {got}")
        matrix = tuple(_numbers(f"{p}.covariance[{i}]", row, k) for i, row in enumerate(rows))
        c = np.array(matrix, dtype=float).reshape(k, k)
        diag = np.diag(c)
        if np.any(diag < 0):
            i = int(np.argmin(diag))
            raise _fail(f"{p}.covariance[{i}][{i}]", f"a variance must be >= 0, got {check.short(diag[i])}")
        scale = np.sqrt(np.outer(diag, diag))
        tol = 1e-9 * scale + 1e-300
        asym = np.abs(c - c.T)
        if np.any(asym > tol):
            i, j = np.unravel_index(int(np.argmax(asym - tol)), c.shape)
            raise _fail(
                f"{p}.covariance",
                f"must be symmetric, got [{i}][{j}] = {check.short(c[i, j])} and [{j}][{i}] = {check.short(c[j, i])}"
            )
        # positive semi-definite, judged on the correlation matrix (units differ by 1e20)
        sd = np.sqrt(diag)
        inv = np.where(sd > 0, 1.0 / np.where(sd > 0, sd, 1.0), 0.0)
        low = float(np.linalg.eigvalsh(c * np.outer(inv, inv)).min())
        if low < -1e-9:
            raise _fail(f"{p}.covariance", f"must be positive semi-definite, got a correlation eigenvalue {low:.3g}")
        if not isinstance(self.source, str):
            raise _fail(f"{p}.source", f"expected a string, got {check.short(self.source)}")
        object.__setattr__(self, "parameters", tuple(names))
        object.__setattr__(self, "covariance", matrix)

    @property
    def matrix(self) -> np.ndarray:
        """The covariance as a (k, k) array, in the order of ``parameters``."""
        return np.array(self.covariance, dtype=float)

    @property
    def std(self) -> dict:
        """Standard deviation of each parameter, by name [its SI unit]."""
        return {n: math.sqrt(v) for n, v in zip(self.parameters, np.diag(self.matrix), strict=True)}

    def to_dict(self) -> dict:
        """The YAML layout (plain lists)."""
        out = {"parameters": list(self.parameters), "covariance": [list(row) for row in self.covariance]}
        if self.source:
            out["source"] = self.source
        return out

    @classmethod
    def from_blocks(cls, blocks, source: str = "") -> ParameterCovarianceConfig:
        """Assemble a block-diagonal covariance from independent fits.

        Parameters
        ----------
        blocks : iterable of (names, matrix)
            Each fit's parameter names and covariance; a name in several blocks is
            an error. Cross-covariances between blocks are zero.
        source : str
            Stored as ``source``.
        """
        names, mats = [], []
        for block_names, block in blocks:
            names.extend(block_names)
            mats.append(np.asarray(block, dtype=float).reshape(len(block_names), len(block_names)))
        c = np.zeros((len(names), len(names)))
        i = 0
        for m in mats:
            c[i : i + len(m), i : i + len(m)] = m
            i += len(m)
        return cls(parameters=tuple(names), covariance=tuple(tuple(float(v) for v in row) for row in c), source=source)


_SECTIONS = {
    "sensor": SensorConfig,
    "actuator": ActuatorConfig,
    "material": MaterialConfig,
    "stiffness": StiffnessConfig,
    "gravity": GravityConfig,
    "estimation": EstimationConfig,
    "parameter_covariance": ParameterCovarianceConfig,
}
_OPTIONAL = ("parameter_covariance",)  # sections that may be absent (None)


@dataclass(frozen=True, kw_only=True)
class Config:
    """A whole bendsense configuration: one field per section."""

    sensor: SensorConfig
    actuator: ActuatorConfig
    material: MaterialConfig
    stiffness: StiffnessConfig
    gravity: GravityConfig = field(default_factory=GravityConfig)
    estimation: EstimationConfig = field(default_factory=EstimationConfig)
    parameter_covariance: ParameterCovarianceConfig | None = None
    name: str = ""

    def __post_init__(self):
        for key, cls in _SECTIONS.items():
            if key in _OPTIONAL and getattr(self, key) is None:
                continue
            if not isinstance(getattr(self, key), cls):
                raise _fail(key, f"expected a {cls.__name__}, got {type(getattr(self, key)).__name__}")
        if not isinstance(self.name, str):
            raise check.fail("name", "a string", self.name, ConfigError)
        # the bounds that need the geometry (EI from the cross-section, mass from the volume, ...);
        # each segment within the length first, so that segments in cm are not blamed on length_m
        bounds.check_config(self)

    @classmethod
    def from_dict(cls, data: Any) -> Config:
        """Build a config from the YAML layout; raises `ConfigError` naming the bad field.

        Parameters
        ----------
        data : dict
            The config YAML's layout, as read by ``yaml.safe_load``.
        """
        if not isinstance(data, dict):
            raise check.fail("config", "a mapping of sections", data, ConfigError)
        allowed = ["name", *_SECTIONS]
        unknown = sorted(set(data) - set(allowed), key=str)
        if unknown:
            raise ConfigError(f"config: unknown keys {_names(unknown)}; allowed: {', '.join(allowed)}")
        missing = [k for k in ("sensor", "actuator", "material", "stiffness") if k not in data]
        if missing:
            raise ConfigError(f"config: missing keys {', '.join(missing)}")
        # an optional section may be given as null: absent (e.g. parameters known exactly, as in a simulation)
        kwargs = {k: c.from_dict(data[k]) for k, c in _SECTIONS.items()
                  if k in data and not (k in _OPTIONAL and data[k] is None)}
        if "name" in data:
            kwargs["name"] = data["name"]
        return cls(**kwargs)

    def to_dict(self) -> dict:
        """The YAML layout of this config (plain lists, floats and strings)."""
        out = {"name": self.name} if self.name else {}
        out.update({k: getattr(self, k).to_dict() for k in _SECTIONS if getattr(self, k) is not None})
        return out

    def replace(self, **sections) -> Config:
        """A copy with whole sections replaced, e.g. ``config.replace(stiffness=...)``.

        Parameters
        ----------
        **sections
            Whole sections by name, e.g. ``stiffness=StiffnessConfig(...)``.
        """
        return dataclasses.replace(self, **sections)

    def model_parameters(self) -> dict:
        """The identified model parameters θ by name (``MODEL_PARAMETERS``) [SI units]."""
        return {n: getattr(getattr(self, _PARAMETER_SECTION[n]), n) for n in MODEL_PARAMETERS}

    def with_model_parameters(self, values) -> Config:
        """A copy with some of the ``MODEL_PARAMETERS`` replaced: ``{name: value}``.

        Parameters
        ----------
        values : dict
            ``{name: value}`` of ``MODEL_PARAMETERS`` [SI units].
        """
        unknown = [check.short(str(n)) for n in values if n not in MODEL_PARAMETERS]
        if unknown:
            raise check.fail("parameters", f"names from {', '.join(MODEL_PARAMETERS)}", ", ".join(unknown), raw=True)
        sections = {}
        for name, value in values.items():
            key = _PARAMETER_SECTION[name]
            sections.setdefault(key, {})[name] = float(value)
        return self.replace(**{k: dataclasses.replace(getattr(self, k), **v) for k, v in sections.items()})

    @property
    def weight_per_length_n_per_m(self) -> np.ndarray:
        """Gravity as a distributed load w = (m g / L) ĝ in the base frame [N/m]."""
        q = self.actuator.mass_kg * self.gravity.g_m_per_s2 / self.actuator.length_m
        return q * np.asarray(self.gravity.direction)
