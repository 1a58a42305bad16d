"""Moved to :mod:`bendsense.apps.evaluation`; this import path keeps working."""

from bendsense.apps.evaluation import (
    CAMERA_ANGLE_STD_RAD,
    CAMERA_POINT_STD_M,
    MISMATCH,
    PAPER,
    TRUE_MATERIAL,
    TRUE_STIFFNESS,
    Plan,
    ReproduceResult,
    contact_errors,
    reproduce,
    shape_accuracy,
    static_model_errors,
    tip_load_errors,
    true_config,
)

__all__ = [
    "PAPER",
    "TRUE_MATERIAL",
    "TRUE_STIFFNESS",
    "MISMATCH",
    "CAMERA_ANGLE_STD_RAD",
    "CAMERA_POINT_STD_M",
    "Plan",
    "ReproduceResult",
    "reproduce",
    "true_config",
    "shape_accuracy",
    "static_model_errors",
    "tip_load_errors",
    "contact_errors",
]
