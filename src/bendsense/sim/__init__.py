"""The simulator: the measurement chain run backwards, to exercise bendsense without hardware.

Only simulated physics lives here: ``coils`` holds the physics of the coil arrays (mutual
inductances of filament loops and multi-turn spirals, the receiver signals versus strip
shift); ``sensor`` turns shapes into strip shifts and shifts into the ADC counts of the
paper's hardware; ``actuator`` is the simulated actuator under pressure and loads; and
``scenarios`` writes whole simulated experiments (calibration strips, tip loads, contact,
a time-varying stream). Programs that use the simulator, such as the paper's evaluation
(:mod:`bendsense.apps.evaluation`), are in :mod:`bendsense.apps`.
"""

from bendsense.sim.coils import (
    CoilArrayModel,
    CoilGeometry,
    coaxial_loop_mutual_inductance,
    coil_mutual_inductance,
    loop_mutual_inductance,
)
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
    "SensorReading",
    "VirtualSensor",
    "calibration_shifts",
    "coaxial_loop_mutual_inductance",
    "coil_mutual_inductance",
    "loop_mutual_inductance",
    "shifts_from_angles",
    "shifts_from_curvatures",
    "shifts_from_shape",
]
