"""The simulated grasp's physics: regulators (closed form) and a finger pressing an object (independent beam).

The object's force is checked against the independent forward model (tests/forward_model.py,
scipy's solve_bvp with the load at s_c): under the simulator's force the finger's point at
s_c must sit on the object's face (rigid) or inside it by F/k (compliant), the force must be
normal to the finger there, and there is no force before the free finger reaches the face.
"""

import math

import numpy as np
import pytest
from forward_model import forward

from bendsense.config import load_config
from bendsense.errors import ConfigError
from bendsense.sim.actuator import SimulatedActuator
from bendsense.sim.grasp import FingerGrasp, GraspObject
from bendsense.sim.regulator import PressureRegulators, closing_profile

S_C = 0.10
TOUCH_PA = 40e3
K_COMPLIANT = 20.0


@pytest.fixture(scope="module")
def config():
    return load_config()


@pytest.fixture(scope="module")
def grasps(config):
    sim = SimulatedActuator.from_config(config)
    # a coarse table (4 kPa) keeps the build short; the checks below use exact solves
    rigid = FingerGrasp(sim, GraspObject(S_C, TOUCH_PA), max_pressure_pa=100e3, step_pa=4000.0)
    soft = FingerGrasp(sim, GraspObject(S_C, TOUCH_PA, K_COMPLIANT), max_pressure_pa=100e3, step_pa=4000.0)
    return rigid, soft


def _point(config, pressure_pa, force_n):
    """The finger's point and tangent angle at s_c from the independent BVP."""
    truth = forward(config, pressure_pa, force_n, contact_s_m=S_C, s_m=[S_C])
    shape = truth.shape
    i = int(np.argmin(abs(shape.s_m - S_C)))
    return shape.positions_m[i], float(shape.angle_rad[i])


def _face(config):
    """The object's face from the BVP: the free finger's point at s_c at the touch pressure, and its normal."""
    q, phi = _point(config, TOUCH_PA, (0.0, 0.0))
    return q, np.array([math.cos(phi), -math.sin(phi)])


@pytest.mark.parametrize("pressure_pa", [55e3, 80e3])
@pytest.mark.parametrize("which", ["rigid", "compliant"])
def test_the_force_puts_the_point_on_the_object(config, grasps, which, pressure_pa):
    grasp = grasps[0] if which == "rigid" else grasps[1]
    q, n0 = _face(config)
    state = grasp.solve([pressure_pa])
    force = state.force_n[0]
    f = float(np.hypot(*force))
    assert state.valid[0] and f > 0.01
    r, phi = _point(config, pressure_pa, force)
    penetration = float((r - q) @ n0)
    expected = 0.0 if which == "rigid" else f / K_COMPLIANT
    assert penetration == pytest.approx(expected, abs=2e-6)  # the point is on the face (or in it by F/k)
    tangent = np.array([math.sin(phi), math.cos(phi)])
    assert abs(force @ tangent) < 1e-4 * f  # normal to the finger at s_c (frictionless)
    assert force @ np.array([math.cos(phi), -math.sin(phi)]) < 0  # and pushing the finger back
    # without the force the free finger would be inside the object
    free, _ = _point(config, pressure_pa, (0.0, 0.0))
    assert float((free - q) @ n0) > expected + 1e-3


def test_no_force_before_touch(config, grasps):
    q, n0 = _face(config)
    rigid, soft = grasps
    pressures = np.array([0.0, 20e3, 39e3])
    for grasp in grasps:
        state = grasp.solve(pressures)
        assert np.all(state.force_n == 0.0) and np.all(state.contact_n == 0.0)
    for p in pressures:  # the free finger has not reached the face
        free, _ = _point(config, p, (0.0, 0.0))
        assert float((free - q) @ n0) < 0
    force, _ = rigid.lookup(pressures)
    assert np.all(force == 0.0)


def test_force_grows_with_pressure_and_rigid_pushes_harder(grasps):
    rigid, soft = grasps
    on = rigid.table_pressure_pa > TOUCH_PA
    f_rigid = np.hypot(*rigid.table_force_n.T)
    f_soft = np.hypot(*soft.table_force_n.T)
    assert rigid.table_valid.all() and soft.table_valid.all()
    assert np.all(np.diff(f_rigid[on]) > 0) and np.all(np.diff(f_soft[on]) > 0)
    assert np.all(f_rigid[on] > f_soft[on]) and np.all(f_soft[on] > 0)
    # the compliant object gives way: its contact point goes deeper, by F/k exactly
    p = np.array([60e3, 90e3])
    s_rigid, s_soft = rigid.solve(p), soft.solve(p)
    assert np.all(s_soft.penetration_m > s_rigid.penetration_m + 1e-3)
    assert s_soft.penetration_m == pytest.approx(s_soft.contact_n / K_COMPLIANT, abs=1e-8)


def test_table_interpolates_the_exact_equilibrium(grasps):
    rigid, _ = grasps
    p = np.array([41e3, 57.3e3, 75.9e3, 98e3])  # between nodes
    exact = rigid.solve(p)
    force, signal = rigid.lookup(p)
    assert np.all(abs(force - exact.force_n) < 2e-3)  # 4 kPa nodes: within 2 mN (the device uses 0.5 kPa)
    frames = rigid.actuator.frames(p, exact.force_n, solution=exact.solution, noise=False)
    assert np.all(abs(signal - rigid.actuator.sensor.signal(frames.shifts_m)) < 2.0)  # counts
    for pressure in [*p, -5.0, 150e3]:  # the board's one-pressure path: the same numbers
        fx, fy, row = rigid.lookup_one(pressure)
        f_all, s_all = rigid.lookup([pressure])
        assert [fx, fy] == pytest.approx(f_all[0].tolist(), abs=1e-15) and row == pytest.approx(s_all[0], abs=1e-9)


def test_object_arguments_are_checked(grasps):
    with pytest.raises(ConfigError, match="stiffness_n_per_m"):
        GraspObject(S_C, TOUCH_PA, 0.0)
    with pytest.raises(ConfigError, match="touch_pressure_pa"):
        GraspObject(S_C, -1.0)
    with pytest.raises(ConfigError, match="above the pressure limit"):
        FingerGrasp(grasps[0].actuator, GraspObject(S_C, 130e3), max_pressure_pa=120e3)
    with pytest.raises(ConfigError, match="contact_s_m"):
        FingerGrasp(grasps[0].actuator, GraspObject(0.2, TOUCH_PA))


# --------------------------------------------------------------------------- regulators


def test_regulator_step_response_is_the_first_order_lag():
    rate, tau = 1000.0, 0.025
    reg = PressureRegulators(2, rate, tau_s=tau, profile=lambda t: 0.0)
    assert reg.set(1, 50e3)
    p = np.array([reg.step(k / rate)[1] for k in range(1, 101)])
    k = np.arange(1, 101)
    assert p == pytest.approx(50e3 * (1 - np.exp(-k / (rate * tau))), rel=1e-12)
    assert reg.pressure_pa[0] == 0.0 and reg.host.tolist() == [False, True]


def test_regulator_limits_and_host_control():
    reg = PressureRegulators(3, 500.0, tau_s=0.01, max_pressure_pa=100e3, profile=lambda t: 250e3)
    assert reg.set(0, 400e3) and reg.set(2, -5e3)
    assert not reg.set(3, 10e3) and not reg.set(1, float("nan"))
    for k in range(200):
        p = reg.step(k / 500.0)
        assert np.all((p >= 0) & (p <= 100e3))
    assert reg.setpoint_pa.tolist() == [100e3, 100e3, 0.0]  # clipped; line 1 follows the (clipped) profile
    assert reg.pressure_pa[0] == pytest.approx(100e3) and reg.pressure_pa[2] == 0.0
    with pytest.raises(ConfigError, match="tau_s"):
        PressureRegulators(1, 500.0, tau_s=0.0)


def test_a_setpoint_is_in_force_on_receipt_between_frames():
    # a host that sends zeros and stops the stream before the next frame: the board holds its zeros all the same
    reg = PressureRegulators(2, 500.0, tau_s=0.01, profile=lambda t: 30e3)
    before = reg.step(0.0).copy()
    assert reg.setpoint_pa.tolist() == [30e3, 30e3]
    reg.set(0, 0.0)
    assert reg.setpoint_pa.tolist() == [0.0, 30e3]  # no frame since
    reg.release()
    assert reg.setpoint_pa.tolist() == [0.0, 0.0]
    assert reg.step(0.002) == pytest.approx(before * np.exp(-1 / (500.0 * 0.01)), rel=1e-12)  # both fall


def test_closing_profile():
    t = np.array([0.0, 1.0, 2.0, 3.0, 5.0, 5.5, 6.0, 7.0, 8.0 + 1.0])
    expected = 70e3 * np.array([0.0, 0.5, 1.0, 1.0, 1.0, 0.5, 0.0, 0.0, 0.5])
    assert closing_profile(t, close_pa=70e3, period_s=8.0) == pytest.approx(expected)
