"""bendsense: shape and tip force of soft bending actuators from a distributed inductive curvature sensor.

The data flow, module by module: ``frames`` (device bytes) → ``session`` (recordings)
→ ``calibration`` (signals → shifts) → ``pcc`` (shifts → curvatures → shape) →
``actuator`` (free bending, stiffness) → ``beam`` (curved cantilever under load) →
``estimation`` (tip force) → ``tracking`` (the force over time, model checks over
windows), with ``pipeline`` running a session or a live stream through the chain.
``sim`` runs the chain backwards; ``plots``, ``device``, ``apps`` (the live view, the
demo, the paper's evaluation) and ``cli`` sit at the edges.
"""

from importlib import import_module

from bendsense.errors import (
    BendsenseError,
    ConfigError,
    ConvergenceError,
    DeviceError,
    FrameError,
    SessionError,
)

__version__ = "0.1.0"

# Public names, imported lazily so that `import bendsense` and the CLI start fast.
_LAZY = {
    "Config": "bendsense.config",
    "load_config": "bendsense.config",
    "save_config": "bendsense.config",
    "Finger": "bendsense.config",
    "GripperConfig": "bendsense.config",
    "Session": "bendsense.session",
    "read_session": "bendsense.session",
    "read_session_csv": "bendsense.session",
    "write_session_csv": "bendsense.session",
    "Calibration": "bendsense.calibration",
    "Shape": "bendsense.shape.pcc",
    "reconstruct": "bendsense.shape.pcc",
    "FreeBendingModel": "bendsense.mechanics.actuator",
    "BeamSolution": "bendsense.mechanics.beam",
    "solve_beam": "bendsense.mechanics.beam",
    "ForceEstimate": "bendsense.estimation",
    "estimate_force": "bendsense.estimation",
    "estimate_contact": "bendsense.estimation",
    "track": "bendsense.tracking",
    "Track": "bendsense.tracking",
    "Tracker": "bendsense.tracking",
    "check_windows": "bendsense.tracking",
    "adapt": "bendsense.identify.sessions",
    "Adaptation": "bendsense.identify.sessions",
    "contact_bound": "bendsense.estimation.cramer_rao",
    "ContactBound": "bendsense.estimation.cramer_rao",
}

__all__ = [
    "BendsenseError",
    "ConfigError",
    "ConvergenceError",
    "DeviceError",
    "FrameError",
    "SessionError",
    "__version__",
    *_LAZY,
]


def __getattr__(name):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bendsense' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
