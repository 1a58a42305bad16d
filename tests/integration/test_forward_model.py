"""The independent forward model of tests/forward_model.py, checked against closed forms and the library."""

import numpy as np
import pytest
from click.testing import CliRunner
from forward_model import HiddenSensor, forward, free_bending_k0, solve_beam_bvp

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.mechanics.actuator import FreeBendingModel

CFG = bendsense.load_config()
L = CFG.actuator.length_m
EI = 2.5e-3


def test_free_bending_matches_the_library_direct_solve():
    model = FreeBendingModel.from_config(CFG)
    pressures = np.array([0.0, 1e4, 2e4, 6e4, 1.2e5, 1.8e5])
    ours = np.array([free_bending_k0(CFG, p) for p in pressures])
    np.testing.assert_allclose(ours, model.solve(pressures) / L, rtol=1e-12, atol=1e-14)
    # the DESIGN.md placeholders: about 25°, 80° and 176° at 20, 60 and 120 kPa
    np.testing.assert_allclose(np.degrees(ours[[2, 3, 4]] * L), [25, 80, 176], atol=2.0)
    soft = free_bending_k0(CFG, 6e4, {"shear_modulus_pa": 9e4, "prebend_angle_rad": 0.1})
    params = {**model.params, "shear_modulus_pa": 9e4, "prebend_angle_rad": 0.1}
    assert soft == pytest.approx(float(bendsense.mechanics.actuator.solve_bending_angle(6e4, **params)) / L, rel=1e-12)


def test_small_load_cantilever():
    force = 1e-5  # F L² / EI ~ 7e-5: the linear theory holds to ~1e-9
    shape = solve_beam_bvp(L, EI, 0.0, (force, 0.0))
    assert shape.tip_position_m[0] == pytest.approx(force * L**3 / (3 * EI), rel=1e-6)
    assert shape.tip_angle_rad == pytest.approx(force * L**2 / (2 * EI), rel=1e-6)
    s = shape.s_m  # deflection curve x(s) = F s² (3L − s) / 6EI
    np.testing.assert_allclose(shape.positions_m[:, 0], force * s**2 * (3 * L - s) / (6 * EI), rtol=1e-5, atol=1e-15)
    # a tip force along +x bends the beam toward +x
    assert np.all(shape.angle_rad[1:] > 0)


def test_pure_moment_gives_a_circle():
    k0 = 20.0
    shape = solve_beam_bvp(L, EI, k0)
    s = shape.s_m
    np.testing.assert_allclose(shape.angle_rad, k0 * s, atol=1e-10)
    np.testing.assert_allclose(shape.curvature_per_m, k0, atol=1e-8)
    arc = np.stack([(1 - np.cos(k0 * s)) / k0, np.sin(k0 * s) / k0], axis=-1)
    np.testing.assert_allclose(shape.positions_m, arc, atol=1e-11)


def test_library_solver_agrees():
    model = FreeBendingModel.from_config(CFG)
    rng = np.random.default_rng(0)
    for _ in range(8):
        pressure = rng.uniform(20e3, 120e3)
        angle = rng.uniform(0, 2 * np.pi)
        force = 0.25 * np.array([np.cos(angle), np.sin(angle)])
        truth = forward(CFG, pressure, force)
        sol = bendsense.solve_beam(
            L,
            CFG.stiffness.ei_nm2(pressure),
            model.tip_curvature_per_m(pressure),
            force,
            CFG.weight_per_length_n_per_m,
            s_m=truth.shape.s_m,
        )
        assert sol.success
        np.testing.assert_allclose(sol.angle_rad, truth.shape.angle_rad, atol=1e-6)
        np.testing.assert_allclose(sol.positions_m, truth.shape.positions_m, atol=1e-6 * L)


def test_forward_gives_the_exact_shifts_at_the_coils():
    truth = forward(CFG, 60e3, (0.1, -0.15))
    ends = np.cumsum(CFG.sensor.lengths_m)
    k = np.searchsorted(truth.shape.s_m, ends)
    np.testing.assert_allclose(truth.shape.s_m[k], ends, rtol=1e-15)
    np.testing.assert_array_equal(truth.angles_rad, truth.shape.angle_rad[k])
    np.testing.assert_allclose(truth.shifts_m, CFG.sensor.strip_gap_m * truth.angles_rad, rtol=1e-15)
    # a tension load (along the tip tangent, away from the base) straightens less than a push
    stiffer = forward(CFG, 60e3, (0.0, 0.0), stiffness={"ei0_nm2": 2 * CFG.stiffness.ei0_nm2})
    free = forward(CFG, 60e3, (0.0, 0.0))
    # gravity pulls the upright arc down: a stiffer beam sags less, toward the free arc
    k0 = free_bending_k0(CFG, 60e3)
    assert abs(stiffer.angles_rad[-1] - k0 * L) < abs(free.angles_rad[-1] - k0 * L)


def test_hidden_sensor_is_monotone_and_not_a_polynomial():
    sensor = HiddenSensor()
    s = np.linspace(-1e-3, 3.6e-3, 400)
    delta = sensor.delta(np.tile(s[:, None], (1, 16)))
    odd = np.arange(16) % 2 == 0
    assert np.all(np.diff(delta[:, odd], axis=0) < 0) and np.all(np.diff(delta[:, ~odd], axis=0) > 0)
    # no cubic in ΔA reproduces S exactly on the calibrated range: a real misfit of µm
    inside = (s >= 0) & (s <= 3.4e-3)
    for ch in (0, 1):
        coef = np.polynomial.polynomial.polyfit(delta[inside, ch], s[inside], 3)
        misfit = np.polynomial.polynomial.polyval(delta[inside, ch], coef) - s[inside]
        assert 3e-7 < np.abs(misfit).max() < 5e-6


def test_hidden_sensor_calibrates_through_the_cli(tmp_path):
    sensor = HiddenSensor(noise_counts=1.5, seed=3)
    manifest = sensor.write_calibration(tmp_path / "cal", CFG, frames=50, flat_frames=200)
    out = tmp_path / "cal.yaml"
    result = CliRunner().invoke(main, ["calibrate", str(manifest), "-o", str(out)])
    assert result.exit_code == 0, result.output
    cal = Calibration.load(out)
    np.testing.assert_allclose(cal.offset, sensor.offsets, atol=4 * 1.5 / np.sqrt(200))
    np.testing.assert_allclose(cal.noise_std_counts(), 1.5, rtol=0.25)
    # a beam frame: the calibrated angles S/d recover φ(L_i) to the calibration's accuracy
    truth = forward(CFG, 80e3, (0.05, -0.1))
    angles = cal.angles_rad(sensor.signals(truth.shifts_m))
    err = angles - truth.angles_rad
    assert np.abs(err).max() < 0.02  # a cubic misfit of a few µm of shift, d = 1 mm
    assert np.abs(err).max() > 1e-7  # and not exact: the map is not a polynomial


def test_point_load_small_deflection_closed_form():
    """A small force at s_c: x(s) = F s² (3 s_c − s) / 6EI before s_c, straight beyond."""
    force, sc = 1e-5, 0.6 * L
    s = np.linspace(0.0, L, 57)
    shape = solve_beam_bvp(L, EI, 0.0, (force, 0.0), s_m=s, contact_s_m=sc)
    before = s <= sc
    x = np.where(before, force * s**2 * (3 * sc - s) / (6 * EI), force * sc**2 * (3 * s - sc) / (6 * EI))
    np.testing.assert_allclose(shape.positions_m[:, 0], x, rtol=1e-5, atol=1e-15)
    angle = np.where(before, force * s * (2 * sc - s) / (2 * EI), force * sc**2 / (2 * EI))
    np.testing.assert_allclose(shape.angle_rad, angle, rtol=1e-5, atol=1e-15)
    assert shape.tip_angle_rad == pytest.approx(force * sc**2 / (2 * EI), rel=1e-6)


def test_point_load_large_deflection_balances_the_base_moment():
    """Large loads: beyond s_c the beam is a free arc (φ' = K0), and EI (φ'(0) − K0) = −r(s_c) × F."""
    k0, force, sc = 15.0, np.array([0.2, -0.15]), 0.7 * L
    s = np.unique(np.concatenate([np.linspace(0.0, L, 41), [sc]]))
    shape = solve_beam_bvp(L, EI, k0, force, s_m=s, contact_s_m=sc)
    np.testing.assert_allclose(shape.curvature_per_m[s > sc + 1e-9], k0, atol=1e-7)
    xc, yc = shape.positions_m[np.searchsorted(s, sc)]
    assert EI * (shape.curvature_per_m[0] - k0) == pytest.approx(-(xc * force[1] - yc * force[0]), rel=1e-6)
    # the load's moment vanishes at its point: φ'(s_c) = K0 from both sides, and not before
    k = np.searchsorted(s, sc)
    assert shape.curvature_per_m[k] == pytest.approx(k0, abs=1e-7)
    assert abs(shape.curvature_per_m[k // 2] - k0) > 1.0


def test_point_load_at_the_tip_is_the_library_tip_load():
    model = FreeBendingModel.from_config(CFG)
    pressure, force = 60e3, np.array([0.15, -0.1])
    w = CFG.weight_per_length_n_per_m
    sol = bendsense.solve_beam(L, CFG.stiffness.ei_nm2(pressure), model.tip_curvature_per_m(pressure), force, w)
    k0 = model.tip_curvature_per_m(pressure)
    at_tip = solve_beam_bvp(L, CFG.stiffness.ei_nm2(pressure), k0, force, w, s_m=sol.s_m, contact_s_m=L)
    np.testing.assert_allclose(at_tip.angle_rad, sol.angle_rad, atol=1e-6)
    # the split problem converges to it as s_c → L, at first order in L − s_c
    err = [np.abs(solve_beam_bvp(L, CFG.stiffness.ei_nm2(pressure), k0, force, w, s_m=sol.s_m,
                                 contact_s_m=L * (1 - f)).angle_rad - sol.angle_rad).max() for f in (1e-2, 5e-3)]
    assert 1.8 < err[0] / err[1] < 2.2 and err[1] < 1e-3
    # and a force at 0.7 L bends less than the same force at the tip
    mid = forward(CFG, pressure, force, contact_s_m=0.7 * L)
    tip = forward(CFG, pressure, force)
    free = k0 * CFG.sensor.lengths_m.sum()
    assert abs(mid.angles_rad[-1] - free) < abs(tip.angles_rad[-1] - free)


def test_compliant_base_turns_with_the_base_moment():
    force, c = 1e-5, 40.0  # rad per N·m
    shape = solve_beam_bvp(L, EI, 0.0, (force, 0.0), base_compliance_rad_per_nm=c)
    beta = c * force * L  # small deflection: base moment F L
    assert shape.angle_rad[0] == pytest.approx(beta, rel=1e-6)
    assert shape.tip_position_m[0] == pytest.approx(force * L**3 / (3 * EI) + beta * L, rel=1e-6)
    # an unloaded arc does not turn its base
    assert abs(solve_beam_bvp(L, EI, 20.0, base_compliance_rad_per_nm=c).angle_rad[0]) < 1e-12


def test_compliant_base_is_a_clamped_beam_under_the_rotated_force():
    """ψ = φ − β solves the clamped problem with G turned by −β: what the pinned sensor sees."""
    k0, force, c = 18.0, np.array([0.2, -0.1]), 4.0
    s = np.linspace(0.0, L, 33)
    soft = solve_beam_bvp(L, EI, k0, force, s_m=s, base_compliance_rad_per_nm=c)
    beta = soft.angle_rad[0]
    assert beta == pytest.approx(c * EI * (soft.curvature_per_m[0] - k0), rel=1e-9)
    assert np.degrees(abs(beta)) > 2.0
    cb, sb = np.cos(beta), np.sin(beta)
    turned = np.array([cb * force[0] - sb * force[1], cb * force[1] + sb * force[0]])
    clamped = solve_beam_bvp(L, EI, k0, turned, s_m=s)
    np.testing.assert_allclose(soft.angle_rad - beta, clamped.angle_rad, atol=1e-7)
    truth = forward(CFG, 60e3, force, base_compliance_rad_per_nm=c)
    assert truth.base_angle_rad != 0.0
    np.testing.assert_allclose(truth.shifts_m, CFG.sensor.strip_gap_m * truth.angles_rad, rtol=1e-15)
