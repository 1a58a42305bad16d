"""Configuration: the sensor, the actuator, its material and stiffness, gravity and estimation options.

Every section is a frozen, keyword-only dataclass with SI units in its field names
and its checks in ``__post_init__`` (:mod:`bendsense.config.sections`).
``Config.from_dict`` / ``Config.to_dict`` map to and from the YAML layout of
``configs/paper.yaml``; an invalid value raises :class:`~bendsense.errors.ConfigError`
naming the field path and the value, e.g.
``sensor.segment_lengths_m[3]: must be > 0, got -0.008``.

A config with ``fingers:`` is a gripper: several named actuators on one board
(:class:`GripperConfig` of :class:`Finger`, :mod:`bendsense.config.gripper`);
:func:`load_config` returns one or the other (:mod:`bendsense.config.files`).
"""

from importlib import resources  # noqa: F401 (where the built-in configs are read from)

from bendsense.config.files import load_config, parse_config, save_config
from bendsense.config.gripper import FINGER_NAME, MAX_CHANNEL, MAX_LINE, Finger, GripperConfig
from bendsense.config.sections import (
    ANGLE_SOURCES,
    CONSTRAINTS,
    FREE_BENDING_PARAMETERS,
    METHODS,
    MODEL_PARAMETERS,
    OBJECTIVES,
    PAPER_CONFIG,
    PRESSURE_RANGE_PA,
    SMALL_M,
    STIFFNESS_PARAMETERS,
    ActuatorConfig,
    Config,
    EstimationConfig,
    GravityConfig,
    MaterialConfig,
    ParameterCovarianceConfig,
    SensorConfig,
    StiffnessConfig,
)

__all__ = [
    "SensorConfig",
    "ActuatorConfig",
    "MaterialConfig",
    "StiffnessConfig",
    "GravityConfig",
    "EstimationConfig",
    "ParameterCovarianceConfig",
    "Config",
    "Finger",
    "GripperConfig",
    "load_config",
    "save_config",
    "parse_config",
    "PAPER_CONFIG",
    "MODEL_PARAMETERS",
    "FREE_BENDING_PARAMETERS",
    "STIFFNESS_PARAMETERS",
    "FINGER_NAME",
    "MAX_CHANNEL",
    "MAX_LINE",
    "ANGLE_SOURCES",
    "CONSTRAINTS",
    "METHODS",
    "OBJECTIVES",
    "PRESSURE_RANGE_PA",
    "SMALL_M",
]
