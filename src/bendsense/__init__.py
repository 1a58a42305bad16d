"""bendsense: shape and tip force of soft bending actuators from a distributed inductive curvature sensor.

The top level is the notebook workflow::

    config = bendsense.load_config()                       # the paper's prototype, or your YAML
    cal = bendsense.Calibration.load("cal.yaml")           # or Calibration.fit(manifest)
    session = bendsense.read_session("run/")               # native directory or session CSV
    shape = bendsense.reconstruct(session.signals, cal, config.sensor)
    est = bendsense.estimate_force(shape, session.pressure_pa, config, calibration=cal)
    tr = bendsense.track(est, session.t_s)
    results = bendsense.process(session, config, cal)    # the whole chain, as `bendsense load ... save`

The packages follow the data: ``wire`` (the board's frames) → ``session`` (recordings)
→ ``calibration`` (signals → shifts) → ``shape`` (PCC reconstruction) → ``mechanics``
(free bending, the curved beam) → ``estimation`` (force and σ) → ``tracking`` (over
time, window checks) → ``identify`` (the actuator's parameters) → ``pipeline`` (a
session or a live stream through the chain) → ``results``/``output`` (files) →
``batch``, ``device``, ``control``, ``interop`` → ``apps`` → ``cli``. ``sim`` runs the
chain backwards; ``plots`` draws it; ``status`` owns every per-frame status.
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
    "load_config": "bendsense.config",
    "Calibration": "bendsense.calibration",
    "Session": "bendsense.session",
    "read_session": "bendsense.session",
    "read_session_csv": "bendsense.session",
    "reconstruct": "bendsense.shape",
    "Shape": "bendsense.shape",
    "solve_beam": "bendsense.mechanics.beam",
    "BeamSolution": "bendsense.mechanics.beam",
    "estimate_force": "bendsense.estimation",
    "estimate_contact": "bendsense.estimation",
    "ForceEstimate": "bendsense.estimation",
    "track": "bendsense.tracking",
    "check_windows": "bendsense.tracking",
    "Track": "bendsense.tracking",
    "adapt": "bendsense.identify.sessions",
    "process": "bendsense.pipeline",
    "read_results": "bendsense.results",
}
# names the top level had before v1.0, and where they live: a clear error, not a second path
_MOVED = {
    "Config": "bendsense.config", "save_config": "bendsense.config", "Finger": "bendsense.config",
    "GripperConfig": "bendsense.config", "write_session_csv": "bendsense.session",
    "FreeBendingModel": "bendsense.mechanics.actuator", "Tracker": "bendsense.tracking",
    "Adaptation": "bendsense.identify.sessions", "contact_bound": "bendsense.estimation.cramer_rao",
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
    if name in _MOVED:
        raise AttributeError(f"module 'bendsense' has no attribute {name!r}: it is {_MOVED[name]}.{name}")
    raise AttributeError(f"module 'bendsense' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
