"""bendsense.mechanics.pressing: the model's force on a rigid object, against the simulator's own root solve.

The simulator (:class:`bendsense.sim.grasp.FingerGrasp`) finds the same equilibrium by a
different method (bracketed Illinois steps on the penetration, its contact force through
``solve_contact``'s load ramp): two solvers agreeing is the check. Physical facts beside:
no force at the touch, a force that rises with the pressure, and an object nearer the base
(a shorter lever) pressed harder per kPa.
"""

import math

import numpy as np
import pytest

import bendsense
from bendsense.errors import ArgumentError
from bendsense.mechanics.pressing import pressing_force
from bendsense.sim.actuator import SimulatedActuator
from bendsense.sim.grasp import FingerGrasp, GraspObject
from bendsense.sim.sensor import VirtualSensor

CONFIG = bendsense.load_config()


@pytest.mark.parametrize(("s_c", "touch_pa"), [(0.07, 50e3), (0.10, 40e3), (0.12, 30e3), (CONFIG.actuator.length_m,
                                                                                          20e3)])
def test_pressing_force_is_the_simulators_equilibrium(s_c, touch_pa):
    finger = SimulatedActuator.from_config(CONFIG, sensor=VirtualSensor.from_config(CONFIG))
    grasp = FingerGrasp(finger, GraspObject(s_c, touch_pa, math.inf), max_pressure_pa=100e3)
    p = touch_pa + np.linspace(0.0, 40e3, 9)
    expected = grasp.solve(p).contact_n
    got = pressing_force(CONFIG, s_c, [touch_pa], p)[0]
    np.testing.assert_allclose(got, expected, rtol=1e-3, atol=1e-6)  # 0.1 %: the two solvers' tolerances


def test_no_force_before_the_touch_a_rising_force_after_and_a_stiffer_object_near_the_base():
    p = np.linspace(20e3, 80e3, 13)
    near, far = pressing_force(CONFIG, 0.07, [40e3], p)[0], pressing_force(CONFIG, 0.12, [40e3], p)[0]
    assert np.all(near[p <= 40e3] == 0.0) and np.all(far[p <= 40e3] == 0.0)
    assert np.all(np.diff(near[p >= 40e3]) > 0) and np.all(np.diff(far[p >= 40e3]) > 0)
    assert np.all(near[p > 40e3] > far[p > 40e3])


def test_a_pressure_without_an_equilibrium_is_nan_and_a_bad_location_an_error():
    f = pressing_force(CONFIG, 0.12, [80e3], [80e3, 100e3, 400e3])[0]
    assert f[0] == 0.0 and np.isnan(f[-1])
    with pytest.raises(ArgumentError, match="contact_s_m"):
        pressing_force(CONFIG, 0.0, [40e3], [50e3])
