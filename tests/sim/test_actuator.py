"""The simulated actuator: true shapes against closed forms, and the shape → counts chain."""

import dataclasses
import math

import numpy as np
import pytest

from bendsense.errors import ConfigError
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.sim import VirtualSensor, shifts_from_curvatures
from bendsense.sim.actuator import SimulatedActuator, play_operator


@pytest.fixture(scope="module")
def weightless(config):
    return config.replace(gravity=dataclasses.replace(config.gravity, g_m_per_s2=0.0))


def arc(s, kappa):
    """Closed-form points of an arc from the origin along +y, bending toward +x."""
    s = np.asarray(s)
    return np.stack([(1 - np.cos(kappa * s)) / kappa, np.sin(kappa * s) / kappa], axis=-1)


@pytest.mark.parametrize("pressure_pa", [20e3, 60e3, 120e3])
def test_unloaded_weightless_actuator_is_the_free_arc(weightless, pressure_pa):
    sim = SimulatedActuator.from_config(weightless, noise_counts=0.0)
    frames = sim.frames(pressure_pa)
    k0 = float(FreeBendingModel.from_config(weightless).tip_curvature_per_m(pressure_pa))
    L = weightless.actuator.length_m
    assert frames.valid
    np.testing.assert_allclose(frames.tip_curvature_per_m, k0, rtol=1e-12)
    np.testing.assert_allclose(frames.angle_rad, k0 * frames.s_m, atol=1e-9)
    np.testing.assert_allclose(frames.positions_m, arc(frames.s_m, k0), atol=1e-9 * L)
    np.testing.assert_allclose(frames.tip_position_m, arc(L, k0), atol=1e-9 * L)
    np.testing.assert_allclose(frames.tip_angle_rad, k0 * L, atol=1e-9)
    np.testing.assert_allclose(frames.curvature_per_m, k0, rtol=1e-7)
    # the sensor covers [0, L_sensor] of the longer actuator
    assert frames.s_m[-1] == pytest.approx(weightless.sensor.length_m)
    assert weightless.sensor.length_m < L


def test_shape_shifts_counts_chain(weightless):
    sim = SimulatedActuator.from_config(weightless, noise_counts=0.0, seed=3)
    frames = sim.frames(50e3)
    k0 = float(frames.tip_curvature_per_m)
    shifts = shifts_from_curvatures(np.full(16, k0), weightless.sensor.lengths_m, weightless.sensor.strip_gap_m)
    np.testing.assert_allclose(frames.shifts_m, shifts, rtol=1e-7, atol=1e-12)
    # same hardware, built independently from the same seed
    sensor = VirtualSensor.from_config(weightless, noise_counts=0.0, seed=3)
    expected = np.clip(np.rint(sensor.signal(shifts)), 0, 4095)
    assert np.abs(frames.counts.astype(float) - expected).max() <= 1  # rounding at a half count
    assert frames.counts.dtype.kind == "u"


def test_noise_is_seeded_and_added(config):
    a = SimulatedActuator.from_config(config, noise_counts=2.0, seed=1).frames(np.full(200, 40e3))
    b = SimulatedActuator.from_config(config, noise_counts=2.0, seed=1).frames(np.full(200, 40e3))
    clean = SimulatedActuator.from_config(config, noise_counts=2.0, seed=1).frames(40e3, noise=False)
    np.testing.assert_array_equal(a.counts, b.counts)
    spread = (a.counts.astype(float) - clean.counts.astype(float)).std()
    assert 1.5 < spread < 2.6


def test_straight_cantilever_small_tip_force(weightless):
    # P = 0: no natural curvature; a small +x force gives the linear cantilever F L^3 / 3EI
    sim = SimulatedActuator.from_config(weightless, noise_counts=0.0)
    force = 1e-4
    frames = sim.frames(0.0, (force, 0.0))
    L = weightless.actuator.length_m
    ei = weightless.stiffness.ei0_nm2
    assert frames.tip_position_m[0] == pytest.approx(force * L**3 / (3 * ei), rel=1e-3)
    # the sensor line: deflection F s^2 (3L - s) / 6EI
    s = frames.s_m
    np.testing.assert_allclose(frames.positions_m[:, 0], force * s**2 * (3 * L - s) / (6 * ei), rtol=2e-3, atol=1e-12)


@pytest.mark.parametrize("pressure_pa", [0.0, 30e3, 80e3])
def test_plus_x_tip_force_bends_toward_plus_x(config, pressure_pa):
    sim = SimulatedActuator.from_config(config, noise_counts=0.0)
    free = sim.frames(pressure_pa)
    pushed = sim.frames(pressure_pa, (0.1, 0.0))
    assert free.valid and pushed.valid
    assert pushed.tip_position_m[0] > free.tip_position_m[0]
    assert np.all(pushed.angle_rad[1:] > free.angle_rad[1:])


def test_ei_error_scales_the_linear_deflection(weightless):
    base = SimulatedActuator.from_config(weightless, noise_counts=0.0).frames(0.0, (1e-4, 0.0))
    stiffer = SimulatedActuator.from_config(weightless, noise_counts=0.0, ei_error=0.25).frames(0.0, (1e-4, 0.0))
    assert stiffer.tip_position_m[0] == pytest.approx(base.tip_position_m[0] / 1.25, rel=1e-4)
    np.testing.assert_allclose(stiffer.ei_nm2, 1.25 * weightless.stiffness.ei0_nm2)


def test_k0_error_and_base_rotation(weightless):
    p = 60e3
    k0 = float(FreeBendingModel.from_config(weightless).tip_curvature_per_m(p))
    L = weightless.actuator.length_m
    off = SimulatedActuator.from_config(weightless, noise_counts=0.0, k0_error=-0.1).frames(p)
    np.testing.assert_allclose(off.curvature_per_m, 0.9 * k0, rtol=1e-7)

    beta = 0.05
    plain = SimulatedActuator.from_config(weightless, noise_counts=0.0).frames(p)
    turned = SimulatedActuator.from_config(weightless, noise_counts=0.0, base_rotation_rad_per_rad=beta).frames(p)
    phi0 = beta * k0 * L
    assert turned.base_angle_rad == pytest.approx(phi0)
    np.testing.assert_allclose(turned.angle_rad, plain.angle_rad + phi0, atol=1e-9)
    # without loads the whole arc turns rigidly about the base (clockwise = toward +x)
    rot = np.array([[math.cos(phi0), math.sin(phi0)], [-math.sin(phi0), math.cos(phi0)]])
    np.testing.assert_allclose(turned.tip_position_m, rot @ plain.tip_position_m, atol=1e-9 * L)
    # the strips are pinned at the base: the sensor does not see the rotation
    np.testing.assert_allclose(turned.shifts_m, plain.shifts_m, atol=1e-12)
    np.testing.assert_array_equal(turned.counts, plain.counts)


def test_batch_equals_single_frames(config):
    sim = SimulatedActuator.from_config(config, noise_counts=0.0)
    pressure = np.array([[20e3, 50e3], [90e3, 120e3]])
    force = np.array([[0.0, -0.1], [0.2, 0.05]])
    batch = sim.frames(pressure, force[..., None] * [1.0, 0.5])
    assert batch.counts.shape == (2, 2, 16)
    assert batch.positions_m.shape == (2, 2, sim.n_points, 2)
    for i in range(2):
        for j in range(2):
            one = sim.frames(pressure[i, j], force[i, j] * np.array([1.0, 0.5]))
            np.testing.assert_allclose(batch.angle_rad[i, j], one.angle_rad, atol=1e-9)
            np.testing.assert_array_equal(batch.counts[i, j], one.counts)


def test_buckled_frames_are_marked_invalid(weightless):
    sim = SimulatedActuator.from_config(weightless, noise_counts=0.0)
    # an axial load far beyond the cantilever's buckling load pi^2 EI / 4L^2 ~ 0.35 N
    frames = sim.frames(np.array([0.0, 0.0, 40e3]), np.array([[0.0, 0.0], [0.0, -3.0], [0.0, 0.0]]))
    np.testing.assert_array_equal(frames.valid, [True, False, True])
    assert frames.n_invalid == 1
    assert frames.select(frames.valid).counts.shape == (2, 16)


def test_play_operator_closed_form():
    up = np.linspace(0.0, 100.0, 101)
    down = up[::-1]
    x = np.concatenate([up, down])
    h = 20.0
    y = play_operator(x, h)
    np.testing.assert_allclose(y[:101], np.maximum(0.0, up - h / 2))
    # after the reversal the output holds until the input has come back by h
    expected_down = np.where(down > 100 - h, 100 - h / 2, down + h / 2)
    np.testing.assert_allclose(y[101:], expected_down)
    np.testing.assert_array_equal(play_operator(x, 0.0), x)


def test_hysteresis_acts_on_time_series_only(weightless):
    sim = SimulatedActuator.from_config(weightless, noise_counts=0.0, hysteresis_pa=10e3)
    p = np.array([0.0, 50e3, 30e3])
    series = sim.frames(p, time_series=True)
    np.testing.assert_allclose(series.effective_pressure_pa, [0.0, 45e3, 35e3])
    np.testing.assert_allclose(series.pressure_pa, p)
    static = sim.frames(p)
    np.testing.assert_allclose(static.effective_pressure_pa, p)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"ei_error": -1.0}, "ei_error: must be a finite number > -1"),
        ({"k0_error": float("nan")}, "k0_error"),
        ({"hysteresis_pa": -1.0}, "hysteresis_pa: must be a finite number >= 0"),
        ({"base_rotation_rad_per_rad": "x"}, "base_rotation_rad_per_rad"),
        ({"n_points": 1}, "n_points"),
    ],
)
def test_invalid_mismatch_parameters(config, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        SimulatedActuator.from_config(config, **kwargs)


def test_bad_force_shape(config):
    with pytest.raises(ConfigError, match="force_n"):
        SimulatedActuator.from_config(config).frames(1e4, (1.0, 2.0, 3.0))
