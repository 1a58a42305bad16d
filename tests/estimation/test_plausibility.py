"""Plausibility at the edges: no ok force outside the actuator's pressure range; channel counts agree."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import bendsense
from bendsense.errors import ArgumentError, SessionError
from bendsense.estimation import estimate_force
from bendsense.estimation.plausibility import check_channels, pressure_outside
from bendsense.mechanics.beam import solve_beam
from bendsense.results import frame_status
from bendsense.session import Session
from bendsense.status import Status

CONFIG = bendsense.load_config()
ROOT = Path(__file__).resolve().parents[2]


def _shapes(pressures):
    """Segment curvatures of the beam model under a small tip load at each pressure."""
    from bendsense.mechanics.actuator import FreeBendingModel

    model = FreeBendingModel.from_config(CONFIG)
    sensor = CONFIG.sensor
    ends = np.cumsum(sensor.lengths_m)
    s = np.concatenate([[0.0], ends])
    kappa = []
    for p in pressures:
        p = min(max(p, 0.0), 200e3)
        sol = solve_beam(CONFIG.actuator.length_m, CONFIG.stiffness.ei_nm2(p), model.tip_curvature_per_m(p),
                         force_n=(0.05, -0.05), distributed_load_n_per_m=CONFIG.weight_per_length_n_per_m, s_m=s)
        kappa.append(np.diff(sol.angle_rad) / sensor.lengths_m)
    return np.array(kappa)


def test_default_range_is_the_paper_prototype():
    assert CONFIG.actuator.pressure_range_pa == (0.0, 200e3)
    np.testing.assert_array_equal(pressure_outside([-1.0, 0.0, 200e3, 200001.0, np.nan], CONFIG),
                                  [True, False, False, True, False])


def test_frames_outside_the_range_get_no_force_and_the_others_are_unchanged():
    pressures = np.array([60e3, -50e3, 120e3, 250e3])
    kappa = _shapes(pressures)
    est = estimate_force(kappa, pressures, CONFIG, warm_start=False)
    inside = estimate_force(kappa[[0, 2]], pressures[[0, 2]], CONFIG, warm_start=False)
    np.testing.assert_allclose(est.force_n[[0, 2]], inside.force_n, rtol=1e-9, atol=1e-12)
    assert np.isnan(est.force_n[[1, 3]]).all() and np.isnan(est.std_n[[1, 3]]).all()
    np.testing.assert_array_equal(est.success, [True, False, True, False])
    assert list(est.status) == [Status.OK, Status.PRESSURE_OUT_OF_RANGE, Status.OK, Status.PRESSURE_OUT_OF_RANGE]
    assert est.message[1] == "pressure_out_of_range: -50 kPa outside 0..200 kPa (actuator.pressure_range_pa)"
    shape = bendsense.shape.pcc.Shape.from_curvatures(kappa, CONFIG.sensor.lengths_m)
    assert list(frame_status(shape, est)) == ["ok", "pressure_out_of_range", "ok", "pressure_out_of_range"]


def test_one_frame_outside_and_strict():
    kappa = _shapes([60e3])[0]
    est = estimate_force(kappa, -5e3, CONFIG)
    assert est.batch_shape == () and not est.success and np.isnan(est.force_n).all()
    assert est.status == Status.PRESSURE_OUT_OF_RANGE and est.message.startswith("pressure_out_of_range: ")
    with pytest.raises(ArgumentError, match=r"pressure_pa: 1 of 1 pressure\(s\) outside actuator.pressure_range_pa "
                                            r"0..200 kPa \(first: -5 kPa\)"):
        estimate_force(kappa, -5e3, CONFIG, strict=True)


def test_a_wider_configured_range_lets_the_frame_through():
    wide = CONFIG.replace(actuator=dataclasses.replace(CONFIG.actuator, pressure_range_pa=(-10e3, 200e3)))
    kappa = _shapes([0.0])[0]
    assert estimate_force(kappa, -5e3, wide).success


def test_a_nan_force_is_never_ok():
    kappa = _shapes([60e3])
    est = estimate_force(kappa, [60e3], CONFIG)
    broken = dataclasses.replace(est, force_n=np.full((1, 2), np.nan))
    shape = bendsense.shape.pcc.Shape.from_curvatures(kappa, CONFIG.sensor.lengths_m)
    assert frame_status(shape, broken)[0] != "ok"


def test_channel_counts_must_agree():
    cal = bendsense.Calibration.load("tests/data/calibration/calibration_v1.yaml")
    session = Session([0.0], np.zeros((1, 8)), [0.0], source="run.csv")
    with pytest.raises(SessionError, match=r"^run.csv: 8 signal channels \(ch1..ch8\), but the calibration cal.yaml "
                                           rf"has {cal.n_channels}$"):
        check_channels(session, cal, CONFIG.sensor, calibration_source="cal.yaml")


# --- physical bounds of config values (issue 21: units and magnitudes) ------------------------

def _cross_section_on_a_grid(a, t, b, hollow, n=1201):
    """Area and second moment about the centroid of the actuator's section, by summing grid cells."""
    r = a + t
    x = np.linspace(-r, r, n)
    y = np.linspace(0.0, b + r, n)
    dx, dy = x[1] - x[0], y[1] - y[0]
    xx, yy = np.meshgrid(x, y)
    inside = (yy <= b) | (xx**2 + (yy - b) ** 2 <= r**2)
    if hollow:
        inside &= ~((yy > b) & (xx**2 + (yy - b) ** 2 < a**2))
    area = inside.sum() * dx * dy
    yc = (yy[inside]).sum() * dx * dy / area
    return area, ((yy[inside] - yc) ** 2).sum() * dx * dy


def test_cross_section_matches_a_grid_integration():
    from bendsense.mechanics.bounds import cross_section

    got = cross_section(CONFIG.actuator)
    act = CONFIG.actuator
    for hollow in (False, True):
        area, inertia = _cross_section_on_a_grid(act.chamber_radius_m, act.wall_thickness_m, act.bottom_thickness_m,
                                                 hollow)
        name = "hollow" if hollow else "solid"
        assert got[f"area_{name}_m2"] == pytest.approx(area, rel=5e-3)
        assert got[f"i_{name}_m4"] == pytest.approx(inertia, rel=5e-3)


def test_stiffness_bound_is_e_times_i_of_soft_silicones_and_holds_the_paper():
    from bendsense.mechanics.bounds import stiffness_bound_nm2

    act = CONFIG.actuator
    _, i_solid = _cross_section_on_a_grid(act.chamber_radius_m, act.wall_thickness_m, act.bottom_thickness_m, False)
    _, i_hollow = _cross_section_on_a_grid(act.chamber_radius_m, act.wall_thickness_m, act.bottom_thickness_m, True)
    lo, hi = stiffness_bound_nm2(act)
    assert lo == pytest.approx(0.05e6 * i_hollow / 10, rel=5e-3)
    assert hi == pytest.approx(10e6 * i_solid * 10, rel=5e-3)
    assert lo < CONFIG.stiffness.ei_nm2(0.0) < CONFIG.stiffness.ei_nm2(200e3) < hi
    assert not lo <= 2530.0 <= hi and lo <= 2530.0 * 1e-6 <= hi  # N·mm² is out, its SI value in


def _config_dict():
    import yaml

    return yaml.safe_load((ROOT / "configs" / "paper.yaml").read_text(encoding="utf-8"))


@pytest.mark.parametrize(("section", "key", "value", "message"), [
    ("stiffness", "ei0_nm2", 2530.0, r"^stiffness\.ei0_nm2 = 2530 is not a plausible bending stiffness for this "
     r"actuator \(4\.4e-6\.\.0\.11 N·m², from its cross-section\); if it was entered in N·mm², it is 0\.00253 N·m²$"),
    ("stiffness", "ei1_nm2_per_pa", 1.25e-5, r"^stiffness\.ei1_nm2_per_pa = 1\.25e-5 .*if it was entered in N·m²/kPa, "
     r"it is 1\.25e-8 N·m²/Pa$"),
    ("actuator", "pressure_range_pa", [0.0, 1e12], r"^actuator\.pressure_range_pa\[1\] = 1e12 is not a plausible "
     r"maximum pressure of a soft pneumatic actuator \(1000\.\.1e6 Pa\)$"),
    ("actuator", "pressure_range_pa", [0.0, 200.0], r"pressure_range_pa\[1\] = 200 .*entered in kPa, it is 200000 Pa$"),
    ("actuator", "mass_kg", 39.27, r"^actuator\.mass_kg = 39\.27 .*if it was entered in g, it is 0\.03927 kg$"),
    ("actuator", "length_m", 134.0, r"^actuator\.length_m = 134 .*if it was entered in mm, it is 0\.134 m$"),
    ("sensor", "strip_gap_m", 0.1,
     r"^sensor\.strip_gap_m = 0\.1 .*at most the shortest segment.*in cm, it is 0\.001 m$"),
    ("material", "prebend_angle_rad", 5.0,
     r"^material\.prebend_angle_rad = 5 .*entered in degrees, it is 0\.0872665 rad"),
    ("material", "shear_modulus_pa", 0.18,
     r"^material\.shear_modulus_pa = 0\.18 .*entered in MPa, it is 180000 Pa$"),
])
def test_each_unit_slip_is_named_with_the_si_value(section, key, value, message):
    from bendsense.config import Config
    from bendsense.errors import ConfigError

    data = _config_dict()
    data[section][key] = value
    with pytest.raises(ConfigError, match=message):
        Config.from_dict(data)


def test_the_mass_bound_comes_from_the_volume_and_silicone_density():
    from bendsense.config import Config
    from bendsense.errors import ConfigError

    act = CONFIG.actuator
    area, _ = _cross_section_on_a_grid(act.chamber_radius_m, act.wall_thickness_m, act.bottom_thickness_m, False)
    top = 1500.0 * area * act.length_m * 10  # densest silicone, the whole envelope, widened tenfold
    data = _config_dict()
    data["actuator"]["mass_kg"] = 0.98 * top
    Config.from_dict(data)
    data["actuator"]["mass_kg"] = 1.02 * top
    with pytest.raises(ConfigError, match=r"actuator\.mass_kg = .* not a plausible mass"):
        Config.from_dict(data)


def test_shipped_configs_pass():
    from bendsense.config import load_config

    for path in ("configs/paper.yaml", "src/bendsense/data/paper.yaml"):
        load_config(ROOT / path)


def test_identify_fix_names_the_parameter_given_not_another():
    from bendsense.identify import check_fixed, fit_free_bending

    with pytest.raises(ArgumentError, match=r"^fix prebend_angle_rad = 5 .*if it was entered in degrees, "
                                            r"it is 0\.0872665 rad$"):
        fit_free_bending([20e3, 60e3, 120e3], np.radians([25.0, 80.0, 176.0]), CONFIG,
                         fix={"prebend_angle_rad": 5.0})
    with pytest.raises(ArgumentError, match=r"^fix ei1_nm2_per_pa = 1\.25e-5 .*if it was entered in N·m²/kPa, "
                                            r"it is 1\.25e-8 N·m²/Pa$"):
        check_fixed({"ei1_nm2_per_pa": 1.25e-5}, CONFIG)
    with pytest.raises(ArgumentError, match=r"^--fix ei0_nm2 = 2530 .*N·mm²"):
        check_fixed({"ei0_nm2": 2530.0}, CONFIG, field="--fix")
    check_fixed({"ei0_nm2": 2.53e-3, "ei1_nm2_per_pa": 1.25e-8, "prebend_angle_rad": 0.05}, CONFIG)


def test_pressure_options_name_the_slip():
    from click.testing import CliRunner

    from bendsense.cli import main

    res = CliRunner().invoke(main, ["load", str(ROOT / "tests" / "data" / "invalid" / "good" / "session.csv"),
                                    "--pressure-kpa", "60000"])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "--pressure-kpa = 60000 is not a plausible gauge pressure" in res.output
    assert "if it was entered in Pa, it is 60 kPa" in res.output


# --- no frame is ok with a force the actuator cannot carry -----------------------------------

def _wide_gap_config():
    # eight long segments and a strip gap as wide as one (16.5 mm): the sensor measures curvatures up to
    # 1/d = 60.6 1/m only, so a moderate tip force is already beyond what this actuator can carry
    sensor = dataclasses.replace(CONFIG.sensor, n_segments=8, segment_lengths_m=(0.0165,) * 8, strip_gap_m=0.0165)
    return CONFIG.replace(sensor=sensor)


def _beam_curvatures(config, force_n, pressure_pa):
    from bendsense.mechanics.actuator import FreeBendingModel

    s = np.concatenate([[0.0], np.cumsum(config.sensor.lengths_m)])
    sol = solve_beam(config.actuator.length_m, config.stiffness.ei_nm2(pressure_pa),
                     FreeBendingModel.from_config(config).tip_curvature_per_m(pressure_pa), force_n=force_n,
                     distributed_load_n_per_m=config.weight_per_length_n_per_m, s_m=s)
    assert sol.success
    return np.diff(sol.angle_rad) / config.sensor.lengths_m


def test_a_force_beyond_what_the_actuator_carries_is_never_ok():

    config = _wide_gap_config()
    p = 60e3
    # the bound, computed here from its definition: 10 EI(P) min(1/d, π/l_min) / L
    kappa_max = min(1.0 / 0.0165, np.pi / 0.0165)
    bound = 10.0 * (2.53e-3 + 1.25e-8 * p) * kappa_max / 0.134
    assert 2.0 < bound < 20.0
    kappa = np.array([_beam_curvatures(config, (2.0, 0.0), p), _beam_curvatures(config, (20.0, 0.0), p)])
    est = estimate_force(kappa, np.full(2, p), config, warm_start=False)
    # both fits find their force (the estimator is not at fault) ...
    np.testing.assert_allclose(est.force_n, [[2.0, 0.0], [20.0, 0.0]], atol=1e-3)
    # ... but the second is beyond what the actuator can carry: flagged, force kept
    assert list(est.success) == [True, False]
    assert list(est.status) == [Status.OK, Status.IMPLAUSIBLE_FORCE]
    assert est.message[1].startswith(f"implausible_force: |F| = 20 N is beyond the {bound:.3g} N")
    assert est.residual_m[1] < 0.05 * 0.134  # a fit that matches the shape: no model_misfit to hide behind
    shape = bendsense.shape.pcc.Shape.from_curvatures(kappa, config.sensor.lengths_m)
    assert list(frame_status(shape, est)) == ["ok", "implausible_force"]
    one = estimate_force(kappa[1], p, config)  # the one-frame path
    assert not one.success and one.status == Status.IMPLAUSIBLE_FORCE
    from bendsense.errors import ConvergenceError

    with pytest.raises(ConvergenceError, match="implausible_force"):
        estimate_force(kappa[1:], np.full(1, p), config, warm_start=False, strict=True)


def test_the_paper_prototype_carries_tens_of_newtons_not_kilonewtons():
    from bendsense.estimation.plausibility import force_bound_n

    # paper: 10 EI(P) min(1/1 mm, π/8 mm) / 134 mm
    assert force_bound_n(0.0, CONFIG) == pytest.approx(10 * 2.53e-3 * (np.pi / 0.008) / 0.134)
    p = np.array([0.0, 200e3])
    np.testing.assert_allclose(force_bound_n(p, CONFIG), 10 * (2.53e-3 + 1.25e-8 * p) * (np.pi / 0.008) / 0.134)
    assert 50.0 < force_bound_n(0.0, CONFIG) < force_bound_n(200e3, CONFIG) < 200.0  # tens of newtons


def test_a_fit_to_angles_in_degrees_is_not_written_as_a_config():
    from bendsense.errors import ConfigError
    from bendsense.identify import fit_free_bending

    # bending angles in degrees where radians belong: the fit runs, its prebend is no actuator's
    fit = fit_free_bending([20e3, 40e3, 60e3, 90e3, 120e3], [25.0, 50.0, 80.0, 130.0, 176.0], CONFIG)
    with pytest.raises(ConfigError, match=r"^the free-bending fit gives a value no actuator of this geometry can "
                                          r"have .*material\.prebend_angle_rad = "):
        fit.to_config(CONFIG)


def test_a_session_at_rest_is_estimated(tmp_path, caplog):
    """Every pressure_pa reading below 1 kPa (a regulator's noise around its offset): read and estimated as it is,
    without the advice to call the column pressure_kpa (1000 times wrong) and without the kPa warning."""
    import logging

    from click.testing import CliRunner
    from helpers import linear_calibration, loaded_curvatures, signals_for

    from bendsense.cli import main
    from bendsense.results import read_results
    from bendsense.session import write_session_csv

    cal = linear_calibration()
    cal.save(tmp_path / "cal.yaml")
    pressure = np.random.default_rng(5).uniform(150.0, 900.0, 40)
    signals = signals_for(loaded_curvatures(pressure, np.zeros((40, 2))), cal)
    write_session_csv(Session(np.arange(40) * 0.01, signals, pressure), tmp_path / "rest.csv")
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        res = CliRunner().invoke(main, ["load", str(tmp_path / "rest.csv"), "--calibration", str(tmp_path / "cal.yaml"),
                                        "reconstruct", "estimate", "save", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert not [r for r in caplog.records if "kPa" in r.getMessage()]
    out = read_results(tmp_path / "out")
    np.testing.assert_allclose(out["pressure_pa"], pressure)
    ok = out["status"] == "ok"  # the others: straight, an axial load is not identifiable (σ inf along it)
    assert set(out["status"]) <= {"ok", "not_identifiable"} and ok.any() and np.abs(out["fx_n"][ok]).max() < 0.01


def test_pressures_in_kpa_given_as_pa_are_warned_of():
    """The shapes of an actuator at 20-100 kPa with their pressures in kPa passed as Pa: a DataWarning naming the
    config's range; the same in Pa, and at rest, pass without it."""
    import warnings

    from bendsense.errors import DataWarning

    p_kpa = np.linspace(20.0, 100.0, 30)
    kappa = _shapes(p_kpa * 1e3)
    with pytest.warns(DataWarning, match=r"^pressure_pa: every pressure is below 1 kPa \(largest 100 Pa\), where the "
                                         r"actuator hardly bends, but read as kPa they lie inside "
                                         r"actuator.pressure_range_pa 0..200 kPa: pressures in kPa given as Pa\?"):
        estimate_force(kappa, p_kpa, CONFIG)
    ramp = np.linspace(0.0, 100.0, 30)  # a ramp from the vented zero, in kPa given as Pa: warned as well
    with pytest.warns(DataWarning, match=r"^pressure_pa: every pressure is below 1 kPa \(largest 100 Pa\)"):
        estimate_force(_shapes(ramp * 1e3), ramp, CONFIG)
    noise = np.random.default_rng(3).normal(0.0, 40.0, 30)  # a sensor at rest: noise around zero
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        estimate_force(kappa, p_kpa * 1e3, CONFIG)
        estimate_force(kappa[:3], np.array([0.0, 80.0, 300.0]), CONFIG)  # at rest: 300 kPa would be out of range
        estimate_force(kappa[:3], np.array([0.0, 0.0, 60.0]), CONFIG)  # at rest: mostly the vented zero
        estimate_force(_shapes(np.zeros(30)), noise, CONFIG)
