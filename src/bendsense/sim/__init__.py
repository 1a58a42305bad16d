"""The simulator: the measurement chain run backwards, to exercise bendsense without hardware.

Only simulated physics lives here: ``coils`` holds the physics of the coil arrays (mutual
inductances of filament loops and multi-turn spirals, the receiver signals versus strip
shift); ``sensor`` turns shapes into strip shifts and shifts into the ADC counts of the
paper's hardware; ``actuator`` is the simulated actuator under pressure and loads; and
``scenarios`` writes whole simulated experiments (calibration strips, tip loads, contact,
a time-varying stream). The gripper: ``regulator`` (pressure regulators), ``grasp`` (the
object a finger presses), ``gripper`` (the board: :func:`gripper_config`,
:class:`GraspBoard`), ``gripper_scenario`` (``simulate gripper``) and ``truth`` (the
board's truth file). Programs that use the simulator, such as the paper's evaluation
(:mod:`bendsense.apps.evaluation`), are in :mod:`bendsense.apps`.
"""

from bendsense.sim.coils import (
    CoilArrayModel,
    CoilGeometry,
    coaxial_loop_mutual_inductance,
    coil_mutual_inductance,
    loop_mutual_inductance,
)
from bendsense.sim.grasp import GraspObject
from bendsense.sim.gripper import GraspBoard, default_objects, gripper_config
from bendsense.sim.regulator import PressureRegulators
from bendsense.sim.sensor import (
    SensorReading,
    VirtualSensor,
    calibration_shifts,
    shifts_from_angles,
    shifts_from_curvatures,
    shifts_from_shape,
)

__all__ = [
    "CoilArrayModel",
    "CoilGeometry",
    "GraspBoard",
    "GraspObject",
    "PressureRegulators",
    "SensorReading",
    "VirtualSensor",
    "calibration_shifts",
    "coaxial_loop_mutual_inductance",
    "coil_mutual_inductance",
    "default_objects",
    "gripper_config",
    "loop_mutual_inductance",
    "shifts_from_angles",
    "shifts_from_curvatures",
    "shifts_from_shape",
]
