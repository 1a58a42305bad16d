"""The sensor board: serial driver, simulated board, replay, recorder and port listing.

Layers, from the wire up: :mod:`bendsense.wire.frames` (protocol, pure) ←
:mod:`~bendsense.device.driver` (serial port, reader thread) ←
:mod:`~bendsense.device.recorder` (session directory on disk), with
:mod:`~bendsense.device.estimator` estimating a recording's frames as they arrive. The
simulated board (:mod:`~bendsense.device.simdevice`) and the replay of a recording
(:mod:`~bendsense.device.replay`) need a POSIX pseudo-terminal. Applications that use the
board (the live window, the demo) are in :mod:`bendsense.apps`.
"""

from importlib import import_module

_LAZY = {
    "Driver": "bendsense.device.driver",
    "Reading": "bendsense.device.driver",
    "Event": "bendsense.device.driver",
    "DeviceStats": "bendsense.device.driver",
    "Reconnect": "bendsense.device.driver",
    "Recorder": "bendsense.device.recorder",
    "RecorderStats": "bendsense.device.recorder",
    "SimulatedDevice": "bendsense.device.simdevice",
    "SimStats": "bendsense.device.simdevice",
    "default_source": "bendsense.device.simdevice",
    "scripted_board": "bendsense.device.simdevice",
    "ramp_source": "bendsense.device.simdevice",
    "PortInfo": "bendsense.device.ports",
    "list_ports": "bendsense.device.ports",
}

__all__ = list(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bendsense.device' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
