"""Force control in the loop: a finger holds an object with a set contact force (DESIGN.md section 2b, "Control").

- :func:`run` (:mod:`~bendsense.control.loop`): per block of frames from the board,
  process, call a controller, clip its set-points to the pressure limit and send them
  (SETPOINT frames); set-point 0 on every line whatever ends the loop, recorded line by
  line (:class:`LineZero`, :func:`zero_report`);
- :class:`ModelController` (:mod:`~bendsense.control.model`): a finger's contact normal
  force held through its model's pressing curve (approach, touch, feed-forward, a
  mismatch observer): no overshoot at the touch; :class:`PIController`
  (:mod:`~bendsense.control.pi`): a PI loop with anti-windup; :class:`Grasp`: one
  controller per finger;
- :func:`normal_force` (:mod:`~bendsense.control.force`): the controlled quantity, F · n at
  the contact, from the tracked force and the estimated shape; :func:`force_limit_n` the
  most a finger can press with at a pressure limit (a target beyond it is refused);
- :class:`Safety`, :class:`ControlStop` (:mod:`~bendsense.control.safety`): the safety
  model, the loop's own stops (lost frames, silence, a pressure beyond the limit, a
  controlled finger without a force or flagged by the model);
- :class:`ControlRecording` (:mod:`~bendsense.control.record`): the session on disk;
- :class:`Sweep` (:mod:`~bendsense.control.sweep`): a free pressure sweep, a controller that
  ignores the force (``identify free-bending --port``).

A controller is any callable ``controller(block) -> {line: pressure_pa}`` (python-control's
habit: plain callables, their state in a small object). docs/grasping.md walks through a
grasp on the simulated board.
"""

from bendsense.control.force import NormalForce, contact_normal, force_limit_n, normal_force
from bendsense.control.loop import DEFAULT_MAX_PRESSURE_PA, ControlResult, LineZero, run, zero_report
from bendsense.control.model import ModelController
from bendsense.control.pi import (
    DEFAULT_KI_PA_PER_N_S,
    DEFAULT_KP_PA_PER_N,
    DEFAULT_MAX_RATE_PA_PER_S,
    TRACK_BANDWIDTH_HZ,
    FingerController,
    Grasp,
    PIController,
)
from bendsense.control.record import CONTROL_LOG, ControlRecording
from bendsense.control.safety import ControlStop, Safety
from bendsense.control.sweep import Sweep

__all__ = ["run", "ControlResult", "LineZero", "zero_report", "ModelController", "PIController", "FingerController",
           "Grasp", "normal_force",
           "contact_normal", "force_limit_n", "NormalForce",
           "Safety", "ControlStop", "Sweep", "ControlRecording", "CONTROL_LOG", "DEFAULT_KP_PA_PER_N",
           "DEFAULT_KI_PA_PER_N_S", "DEFAULT_MAX_RATE_PA_PER_S", "TRACK_BANDWIDTH_HZ", "DEFAULT_MAX_PRESSURE_PA"]
