"""Identification of the free-bending and stiffness models (paper section V-C)."""

import dataclasses
import math

import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.cli import main
from bendsense.errors import ConfigError, SessionError
from bendsense.identify import (
    StiffnessData,
    fit_free_bending,
    fit_stiffness,
    read_free_bending_csv,
    read_stiffness_csv,
)
from bendsense.mechanics.actuator import FreeBendingModel, solve_bending_angle
from bendsense.mechanics.beam import solve_beam

CFG = bendsense.load_config()
GEOM = {
    "chamber_radius_m": CFG.actuator.chamber_radius_m,
    "bottom_thickness_m": CFG.actuator.bottom_thickness_m,
    "wall_thickness_m": CFG.actuator.wall_thickness_m,
    "length_m": CFG.actuator.length_m,
}
TRUE_FB = {"shear_modulus_pa": 2.1e5, "sensor_stiffness_nm_per_rad": 2.2e-3, "prebend_angle_rad": 0.06}
P_FB = np.linspace(10e3, 120e3, 12)
SIGMA_FB = math.radians(0.4)
L = CFG.actuator.length_m


def fb_data(rng=None, sigma=SIGMA_FB):
    theta = solve_bending_angle(P_FB, **GEOM, **TRUE_FB)
    if rng is not None:
        theta = theta + sigma * rng.standard_normal(theta.shape)
    return theta


# ------------------------------------------------------------------ free bending


def test_free_bending_exact_data_recovers_parameters():
    fit = fit_free_bending(P_FB, fb_data(), CFG)
    assert fit.success, fit.message
    for name, value in TRUE_FB.items():
        assert fit.params[name] == pytest.approx(value, rel=1e-6)
    assert np.max(np.abs(fit.residuals)) < 1e-10
    assert fit.free == ("shear_modulus_pa", "sensor_stiffness_nm_per_rad", "prebend_angle_rad")
    assert fit.dof == len(P_FB) - 3


def test_free_bending_noisy_within_standard_errors():
    fit = fit_free_bending(P_FB, fb_data(np.random.default_rng(3)), CFG)
    assert fit.success, fit.message
    for name, value in TRUE_FB.items():
        assert abs(fit.params[name] - value) < 4 * fit.stderr[name]
    # μ̄ and μ_s both stiffen the response alike: strongly anticorrelated
    assert fit.correlation.shape == (3, 3)
    assert fit.correlation[0, 1] < -0.9
    np.testing.assert_allclose(np.diag(fit.correlation), 1.0)
    assert fit.rms_rad == pytest.approx(np.sqrt(np.mean(fit.residuals**2)))


def test_free_bending_standard_errors_match_scatter():
    rng = np.random.default_rng(7)
    est, err = [], []
    for _ in range(50):
        fit = fit_free_bending(P_FB, fb_data(rng), CFG)
        est.append([fit.params[n] for n in fit.free])
        err.append([fit.stderr[n] for n in fit.free])
    scatter = np.std(est, axis=0, ddof=1)
    reported = np.mean(err, axis=0)
    # 50 repeats: the scatter itself is known to ~10 %; allow for mild nonlinearity
    np.testing.assert_allclose(reported / scatter, 1.0, atol=0.3)
    mean_bias = np.mean(est, axis=0) - [TRUE_FB[n] for n in fit.free]
    assert np.all(np.abs(mean_bias) < 4 * scatter / np.sqrt(50))


def test_free_bending_residuals_are_model_minus_data():
    y = fb_data(np.random.default_rng(4))
    fit = fit_free_bending(P_FB, y, CFG)
    model = solve_bending_angle(P_FB, **GEOM, **fit.params)
    np.testing.assert_allclose(fit.residuals, model - y, atol=1e-14)


def test_free_bending_fix_by_name_and_value():
    y = fb_data(np.random.default_rng(5), sigma=math.radians(0.1))
    fit = fit_free_bending(P_FB, y, CFG, fix={"sensor_stiffness_nm_per_rad": 2.2e-3, "prebend_angle_rad": 0.06})
    assert fit.free == ("shear_modulus_pa",)
    assert fit.stderr["sensor_stiffness_nm_per_rad"] == 0.0
    assert fit.params["prebend_angle_rad"] == 0.06
    assert abs(fit.params["shear_modulus_pa"] - 2.1e5) < 4 * fit.stderr["shear_modulus_pa"]
    assert fit.correlation.shape == (1, 1)
    # names alone hold the config's values
    fit2 = fit_free_bending(P_FB, y, CFG, fix=["prebend_angle_rad"])
    assert fit2.params["prebend_angle_rad"] == CFG.material.prebend_angle_rad
    assert fit2.dof == len(P_FB) - 2


def test_free_bending_all_fixed_just_evaluates():
    y = fb_data()
    fit = fit_free_bending(P_FB, y, CFG, fix=TRUE_FB)
    assert fit.free == ()
    assert fit.params == TRUE_FB
    assert np.max(np.abs(fit.residuals)) < 1e-12


def test_a_fit_of_nothing_keeps_the_configs_prior_and_the_cli_refuses_it(tmp_path):
    from bendsense.config import ParameterCovarianceConfig

    prior = ParameterCovarianceConfig(parameters=("shear_modulus_pa", "ei0_nm2"),
                                      covariance=((1e8, 0.0), (0.0, 1e-8)), source="a lab's prior")
    cfg = CFG.replace(parameter_covariance=prior)
    new = fit_free_bending(P_FB, fb_data(), cfg, fix=TRUE_FB).to_config(cfg)
    assert new.parameter_covariance == prior  # not variance 0: nothing was learned about them
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(1))
    result = CliRunner().invoke(main, ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o",
                                       str(tmp_path / "o.yaml"), "--fix", "mu", "--fix", "mu_s", "--fix", "prebend"])
    assert result.exit_code == 2 and "holds every parameter of free-bending" in result.output, result.output
    assert not (tmp_path / "o.yaml").exists()


def test_free_bending_to_config_replaces_material_only():
    fit = fit_free_bending(P_FB, fb_data(), CFG)
    new = fit.to_config(CFG)
    assert new.material.shear_modulus_pa == fit.params["shear_modulus_pa"]
    assert new.material.prebend_angle_rad == fit.params["prebend_angle_rad"]
    assert new.actuator == CFG.actuator and new.stiffness == CFG.stiffness
    assert CFG.material.shear_modulus_pa == 0.18e6
    model = FreeBendingModel.from_config(new)
    np.testing.assert_allclose(model.bending_angle_rad(P_FB), fb_data(), atol=1e-6)


def test_free_bending_report_lists_parameters():
    text = fit_free_bending(P_FB, fb_data(np.random.default_rng(1)), CFG).report()
    for name in TRUE_FB:
        assert name in text
    assert "corr(shear_modulus_pa, sensor_stiffness_nm_per_rad)" in text


def test_free_bending_bad_input():
    with pytest.raises(ConfigError, match="fix: unknown parameter 'mu'"):
        fit_free_bending(P_FB, fb_data(), CFG, fix=["mu"])
    with pytest.raises(ValueError, match="need more than 3 points"):
        fit_free_bending(P_FB[:3], fb_data()[:3], CFG)
    y = fb_data()
    y[2] = np.nan
    with pytest.raises(ValueError, match="bending_angle_rad: must be finite"):
        fit_free_bending(P_FB, y, CFG)
    with pytest.raises(ValueError, match="equal shapes"):
        fit_free_bending(P_FB, fb_data()[:-1], CFG)


def test_read_free_bending_csv_units_and_comments(tmp_path):
    path = tmp_path / "fb.csv"
    path.write_text("# rig 2\n# date\npressure_kpa,bending_angle_deg,extra\n20,30,a\n40.5,60,\n", encoding="utf-8")
    with pytest.raises(SessionError, match="line 4: column extra: not a number"):
        read_free_bending_csv(path)
    path.write_text("# rig 2\npressure_kpa,bending_angle_deg,extra\n20,30,1\n40.5,60,\n", encoding="utf-8")
    p, theta = read_free_bending_csv(path)
    np.testing.assert_allclose(p, [20e3, 40.5e3])
    np.testing.assert_allclose(theta, [math.pi / 6, math.pi / 3])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("pressure_pa,angle\n20000,2\n", "missing bending angle column"),
        ("pressure_pa,pressure_kpa,bending_angle_rad\n1,2,3\n", "give one pressure column"),
        ("pressure_pa,bending_angle_rad\n1,x\n", "line 2: column bending_angle_rad: not a number"),
        ("pressure_pa,bending_angle_rad\n1\n", "line 2: expected 2 values, got 1"),
        ("pressure_pa,bending_angle_rad\n", "no data rows"),
        ("# only a comment\n", "no header row"),
        ("pressure_pa,bending_angle_rad\n20000,\n",
         "column bending_angle_rad: missing or non-finite value in data row 1"),
    ],
)
def test_read_free_bending_csv_errors(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SessionError, match=match):
        read_free_bending_csv(path)


def test_read_missing_file(tmp_path):
    with pytest.raises(SessionError, match="no such file"):
        read_free_bending_csv(tmp_path / "nope.csv")


# ------------------------------------------------------------------ stiffness

P_LEVELS = np.arange(20e3, 121e3, 20e3)
LOADS = np.array([[0.0, 0.0], [0.0, -0.1], [0.0, -0.2], [0.05, -0.3]])
S_MARKERS = np.array([0.03, 0.06, 0.09, 0.12])


def loaded_shapes(pressure, force, s_m=None, config=CFG):
    model = FreeBendingModel.from_config(config)
    return solve_beam(
        L,
        config.stiffness.ei_nm2(pressure),
        model.tip_curvature_per_m(pressure),
        force,
        config.weight_per_length_n_per_m,
        s_m=s_m,
    )


@pytest.fixture(scope="module")
def tip_dataset():
    p = np.repeat(P_LEVELS, len(LOADS))
    f = np.tile(LOADS, (len(P_LEVELS), 1))
    sol = loaded_shapes(p, f)
    assert np.all(sol.success)
    return p, f, sol.tip_position_m


def test_stiffness_exact_tip_data_recovers_line(tip_dataset):
    p, f, tip = tip_dataset
    fit = fit_stiffness(StiffnessData.from_tip(p, f, tip, L), CFG)
    assert fit.success, fit.message
    assert fit.params["ei0_nm2"] == pytest.approx(CFG.stiffness.ei0_nm2, rel=1e-6)
    assert fit.params["ei1_nm2_per_pa"] == pytest.approx(CFG.stiffness.ei1_nm2_per_pa, rel=1e-5)
    np.testing.assert_allclose(fit.level_pressure_pa, P_LEVELS)
    np.testing.assert_allclose(fit.level_ei_nm2, CFG.stiffness.ei_nm2(P_LEVELS), rtol=1e-7)
    assert np.nanmax(np.abs(fit.position_residuals_m)) < 1e-9


def test_stiffness_noisy_tip_data_within_standard_errors(tip_dataset):
    p, f, tip = tip_dataset
    rng = np.random.default_rng(11)
    noisy = tip + 0.5e-3 * rng.standard_normal(tip.shape)
    fit = fit_stiffness(StiffnessData.from_tip(p, f, noisy, L), CFG)
    assert fit.success, fit.message
    for name in ("ei0_nm2", "ei1_nm2_per_pa"):
        assert abs(fit.params[name] - getattr(CFG.stiffness, name)) < 4 * fit.stderr[name]
    true_levels = CFG.stiffness.ei_nm2(P_LEVELS)
    assert np.all(np.abs(fit.level_ei_nm2 - true_levels) < 4 * fit.level_ei_stderr_nm2)
    assert np.all((fit.level_rms_m > 0.1e-3) & (fit.level_rms_m < 1.5e-3))
    assert fit.correlation.shape == (2, 2) and fit.correlation[0, 1] < 0
    np.testing.assert_allclose(
        fit.residuals, fit.level_ei_nm2 - fit.params["ei0_nm2"] - fit.params["ei1_nm2_per_pa"] * P_LEVELS
    )


def test_stiffness_standard_errors_match_scatter():
    levels = np.array([20e3, 70e3, 120e3])
    loads = np.array([[0.0, -0.1], [0.0, -0.3]])
    p = np.repeat(levels, len(loads))
    f = np.tile(loads, (len(levels), 1))
    tip = loaded_shapes(p, f).tip_position_m
    rng = np.random.default_rng(5)
    est, err = [], []
    for _ in range(20):
        noisy = tip + 0.5e-3 * rng.standard_normal(tip.shape)
        fit = fit_stiffness(StiffnessData.from_tip(p, f, noisy, L), CFG)
        est.append([fit.params["ei0_nm2"], fit.params["ei1_nm2_per_pa"]])
        err.append([fit.stderr["ei0_nm2"], fit.stderr["ei1_nm2_per_pa"]])
    ratio = np.mean(err, axis=0) / np.std(est, axis=0, ddof=1)
    # 20 repeats know the scatter to ~16 %; the per-level errors come from 3 residuals each
    assert np.all((ratio > 0.6) & (ratio < 1.6)), ratio


def test_stiffness_shape_points_with_missing_markers():
    p = np.repeat([30e3, 90e3], 2)
    f = np.array([[0.0, -0.1], [0.0, -0.25], [0.0, -0.1], [0.02, -0.25]])
    sol = loaded_shapes(p, f, s_m=S_MARKERS)
    pos = np.array(sol.positions_m)
    s = np.tile(S_MARKERS, (4, 1))
    s[1, 0] = np.nan  # marker 1 not seen in row 1
    pos[3, 2] = np.nan
    fit = fit_stiffness(StiffnessData(p, f, s, pos), CFG)
    assert fit.success, fit.message
    np.testing.assert_allclose(fit.level_ei_nm2, CFG.stiffness.ei_nm2(np.array([30e3, 90e3])), rtol=1e-7)
    assert np.isnan(fit.position_residuals_m[1, 0]).all() and np.isnan(fit.position_residuals_m[3, 2]).all()
    # two levels, two parameters: the line goes through both points
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-12)


def test_stiffness_levels_group_nearby_pressures(tip_dataset):
    p, f, tip = tip_dataset
    jitter = np.random.default_rng(2).uniform(-300, 300, p.shape)
    fit = fit_stiffness(StiffnessData.from_tip(p + jitter, f, tip, L), CFG, pressure_tolerance_pa=2e3)
    assert len(fit.level_ei_nm2) == len(P_LEVELS)
    np.testing.assert_array_equal(fit.level, np.repeat(np.arange(len(P_LEVELS)), len(LOADS)))
    fine = fit_stiffness(StiffnessData.from_tip(p + jitter, f, tip, L), CFG, pressure_tolerance_pa=0.0)
    assert len(fine.level_ei_nm2) == len(p)


def test_stiffness_single_level_needs_fixed_slope(tip_dataset):
    p, f, tip = tip_dataset
    rows = slice(0, len(LOADS))
    data = StiffnessData.from_tip(p[rows], f[rows], tip[rows], L)
    with pytest.raises(ValueError, match="1 pressure level"):
        fit_stiffness(data, CFG)
    fit = fit_stiffness(data, CFG, fix={"ei1_nm2_per_pa": 0.0})
    assert fit.free == ("ei0_nm2",)
    assert fit.params["ei0_nm2"] == pytest.approx(float(CFG.stiffness.ei_nm2(P_LEVELS[0])), rel=1e-7)


def test_stiffness_to_config_and_report(tip_dataset):
    p, f, tip = tip_dataset
    fit = fit_stiffness(StiffnessData.from_tip(p, f, tip, L), CFG, weighted=False)
    new = fit.to_config(CFG)
    assert new.stiffness.ei0_nm2 == fit.params["ei0_nm2"]
    assert new.material == CFG.material
    text = fit.report()
    assert "ei1_nm2_per_pa" in text and "120.00" in text


def test_read_stiffness_csv_tip_and_shape(tmp_path):
    path = tmp_path / "st.csv"
    path.write_text(
        "# shapes\npressure_kpa,fx_n,fy_n,tip_x_m,tip_y_m,s1_m,x1_m,y1_m,s2_m,x2_m,y2_m\n"
        "40,0,-0.1,0.07,0.08,0.03,0.001,0.03,0.06,0.004,0.059\n"
        "60,0.1,-0.2,0.09,0.07,0.03,0.002,0.03,,,\n",
        encoding="utf-8",
    )
    data = read_stiffness_csv(path, L)
    np.testing.assert_allclose(data.pressure_pa, [40e3, 60e3])
    np.testing.assert_allclose(data.force_n, [[0, -0.1], [0.1, -0.2]])
    assert data.s_m.shape == (2, 3)
    np.testing.assert_allclose(data.s_m[0], [L, 0.03, 0.06])
    np.testing.assert_allclose(data.positions_m[0, 0], [0.07, 0.08])
    np.testing.assert_array_equal(data.observed, [[True, True, True], [True, True, False]])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("pressure_pa,fx_n,tip_x_m,tip_y_m\n1,0,0,0\n", "missing column fy_n"),
        ("pressure_pa,fx_n,fy_n\n1,0,0\n", "no measured points"),
        ("pressure_pa,fx_n,fy_n,tip_x_m\n1,0,0,0\n", "missing column tip_y_m"),
        ("pressure_pa,fx_n,fy_n,s1_m,x1_m\n1,0,0,0.1,0\n", "missing column y1_m"),
        ("pressure_pa,fx_n,fy_n,s1_m,x1_m,y1_m\n1,0,0,0.5,0,0\n", "s1_m: arc lengths must lie in"),
        ("pressure_pa,fx_n,fy_n,s1_m,x1_m,y1_m\n1,0,0,,,\n", "row 0 has no measured point"),
    ],
)
def test_read_stiffness_csv_errors(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SessionError, match=match):
        read_stiffness_csv(path, L)


# ------------------------------------------------------------------ CLI


def write_fb_csv(path, rng):
    theta = fb_data(rng)
    rows = "\n".join(f"{float(p) / 1e3!r},{math.degrees(t)!r}" for p, t in zip(P_FB, theta, strict=True))
    path.write_text(f"# synthetic\npressure_kpa,bending_angle_deg\n{rows}\n", encoding="utf-8")
    return theta


def test_cli_free_bending_round_trip(tmp_path):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(8))
    out = tmp_path / "fitted.yaml"
    result = CliRunner().invoke(main, ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "shear_modulus_pa" in result.output
    loaded = bendsense.load_config(out)
    fit = fit_free_bending(*read_free_bending_csv(tmp_path / "fb.csv"), CFG)
    for name, value in fit.params.items():
        assert getattr(loaded.material, name) == pytest.approx(value, rel=1e-9)
    assert loaded.actuator == CFG.actuator and loaded.stiffness == CFG.stiffness


def test_cli_fix_and_config(tmp_path):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(9))
    base = CFG.replace(material=dataclasses.replace(CFG.material, prebend_angle_rad=0.06))
    bendsense.config.save_config(base, tmp_path / "base.yaml")
    out = tmp_path / "fitted.yaml"
    args = ["identify", "free-bending", str(tmp_path / "fb.csv"), "--config", str(tmp_path / "base.yaml")]
    args += ["-o", str(out), "--fix", "prebend", "--fix", "mu_s=0.0022"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    loaded = bendsense.load_config(out)
    assert loaded.material.prebend_angle_rad == 0.06
    assert loaded.material.sensor_stiffness_nm_per_rad == 0.0022


def test_cli_stiffness_round_trip(tmp_path, tip_dataset):
    p, f, tip = tip_dataset
    noisy = tip + 0.3e-3 * np.random.default_rng(12).standard_normal(tip.shape)
    lines = ["pressure_pa,fx_n,fy_n,tip_x_m,tip_y_m"]
    lines += [",".join(repr(float(v)) for v in (a, *b, *c)) for a, b, c in zip(p, f, noisy, strict=True)]
    (tmp_path / "st.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = tmp_path / "fitted.yaml"
    result = CliRunner().invoke(main, ["identify", "stiffness", str(tmp_path / "st.csv"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    loaded = bendsense.load_config(out)
    fit = fit_stiffness(read_stiffness_csv(tmp_path / "st.csv", L), CFG)
    assert loaded.stiffness.ei0_nm2 == pytest.approx(fit.params["ei0_nm2"], rel=1e-9)
    assert loaded.stiffness.ei1_nm2_per_pa == pytest.approx(fit.params["ei1_nm2_per_pa"], rel=1e-9)


def test_cli_stiffness_writes_no_config_from_a_fit_whose_levels_failed(tmp_path, tip_dataset):
    p, f, tip = tip_dataset
    lines = ["pressure_pa,fx_n,fy_n,tip_x_m,tip_y_m"]  # loads 1000x too large (grams): no beam fits
    lines += [",".join(repr(float(v)) for v in (a, *(1e3 * b), *c)) for a, b, c in zip(p, f, tip, strict=True)]
    (tmp_path / "st.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    fit = fit_stiffness(read_stiffness_csv(tmp_path / "st.csv", L), CFG)
    assert not fit.success and "level fit failed" in fit.message  # the fit says so itself
    out = tmp_path / "fitted.yaml"
    result = CliRunner().invoke(main, ["identify", "stiffness", str(tmp_path / "st.csv"), "-o", str(out)])
    assert result.exit_code == 1 and "the stiffness fit failed (level fit failed at" in result.output, result.output
    assert "no config written" in result.output and not out.exists() and "Traceback" not in result.output


def test_cli_free_bending_writes_no_config_from_data_that_determine_nothing(tmp_path):
    """Four equal rows determine none of the three parameters: no config (it was written, exit 0, with only a warning
    in the solver's words), and the fit's message is ours, not scipy's "`gtol` termination condition"."""
    (tmp_path / "fb.csv").write_text("pressure_kpa,bending_angle_deg\n" + "20,24.1\n" * 4, encoding="utf-8")
    fit = fit_free_bending(*read_free_bending_csv(tmp_path / "fb.csv"), CFG)
    assert not fit.success and fit.message == "parameters not identifiable from these data (fix one)"
    out = tmp_path / "fitted.yaml"
    result = CliRunner().invoke(main, ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(out)])
    assert result.exit_code == 1 and "the free-bending fit failed (parameters not identifiable" in result.output
    assert "no config written" in result.output and not out.exists() and "Traceback" not in result.output
    assert "termination condition" not in result.output


def test_cli_refuses_to_overwrite(tmp_path):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(1))
    out = tmp_path / "fitted.yaml"
    out.write_text("keep me", encoding="utf-8")
    args = ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code != 0
    assert "--overwrite" in result.output
    assert out.read_text(encoding="utf-8") == "keep me"
    result = CliRunner().invoke(main, [*args, "--overwrite"])  # not bendsense's file: kept even so
    assert result.exit_code == 1 and "bendsense did not write it" in result.output, result.output
    assert out.read_text(encoding="utf-8") == "keep me"
    out.unlink()
    assert CliRunner().invoke(main, args).exit_code == 0
    result = CliRunner().invoke(main, [*args, "--overwrite"])  # its own output it replaces
    assert result.exit_code == 0, result.output
    bendsense.load_config(out)


@pytest.mark.parametrize(
    ("kind", "text", "match"),
    [
        ("free-bending", "pressure_pa,angle\n20000,2\n", "missing bending angle column"),
        ("free-bending", "pressure_pa,bending_angle_rad\n1,oops\n", "not a number"),
        ("free-bending", "pressure_pa,bending_angle_rad\n1e3,0.1\n2e3,0.2\n", "need more than 3 points"),
        ("stiffness", "pressure_pa,fx_n,fy_n\n1,0,0\n", "no measured points"),
    ],
)
def test_cli_bad_file_one_line_error(tmp_path, kind, text, match):
    (tmp_path / "bad.csv").write_text(text, encoding="utf-8")
    out = tmp_path / "out.yaml"
    result = CliRunner().invoke(main, ["identify", kind, str(tmp_path / "bad.csv"), "-o", str(out)])
    assert result.exit_code != 0
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and match in lines[0], result.output
    assert "Traceback" not in result.output
    assert not out.exists()


def test_cli_bad_fix_is_usage_error(tmp_path):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(1))
    result = CliRunner().invoke(
        main, ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(tmp_path / "o.yaml"), "--fix", "ei0"]
    )
    assert result.exit_code == 2
    assert "--fix" in result.output and "unknown parameter" in result.output


def test_cli_unknown_kind(tmp_path):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(1))
    result = CliRunner().invoke(main, ["identify", "bending", str(tmp_path / "fb.csv"), "-o", str(tmp_path / "o.yaml")])
    assert result.exit_code == 2


def test_plots_draw(tmp_path, tip_dataset):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(1))
    fig_path = tmp_path / "fit.png"
    result = CliRunner().invoke(
        main,
        ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(tmp_path / "o.yaml"), "--plot", str(fig_path)],
    )
    assert result.exit_code == 0, result.output
    assert fig_path.stat().st_size > 0
    p, f, tip = tip_dataset
    fit = fit_stiffness(StiffnessData.from_tip(p, f, tip, L), CFG)
    ax = fit.plot()
    assert ax.get_ylabel() == "EI [N·mm²]"
    np.testing.assert_allclose(ax.lines[0].get_ydata(), fit.level_ei_nm2 * 1e6)
    ax.figure.canvas.draw()  # the axis label inside the figure (it was cut at the left edge)
    assert ax.yaxis.label.get_window_extent().x0 >= 0
    plt.close("all")


def test_stiffness_with_paper_shooting_solver_agrees():
    # data from the spectral solver, fit with the paper's shooting method: an independent check
    p = np.array([30e3, 30e3, 90e3, 90e3])
    f = np.array([[0.0, -0.1], [0.0, -0.2], [0.0, -0.1], [0.05, -0.2]])
    tip = loaded_shapes(p, f).tip_position_m
    fit = fit_stiffness(StiffnessData.from_tip(p, f, tip, L), CFG, method="shooting")
    assert fit.success, fit.message
    np.testing.assert_allclose(fit.level_ei_nm2, CFG.stiffness.ei_nm2(np.array([30e3, 90e3])), rtol=1e-6)


def test_unit_mistakes_in_identification_data_are_refused(tmp_path):
    degrees = tmp_path / "fb.csv"
    degrees.write_text("pressure_kpa,bending_angle_rad\n20,25\n40,55\n60,80\n")
    with pytest.raises(SessionError, match=r"fb\.csv: column bending_angle_rad: angles up to 80 rad \(over a full "
                                           r"turn\); looks like degrees"):
        read_free_bending_csv(degrees)
    mm = tmp_path / "st.csv"
    mm.write_text("pressure_kpa,fx_n,fy_n,tip_x_m,tip_y_m\n40,0,-0.1,60.5,110.2\n80,0,-0.1,95.0,70.1\n")
    with pytest.raises(SessionError, match=r"st\.csv: measured points up to 125\.7\d* m from the base, farther "
                                           r"than the actuator is long \(0\.134 m\); looks like millimetres"):
        read_stiffness_csv(mm, 0.134)


def test_a_parameter_at_its_bound_is_said_without_the_solvers_own_words():
    """A sensor without stiffness (μ_s = 0 true): noisy angles put the fit at the bound μ_s = 0 in about half the
    draws; the report's warning then names the bound, not scipy's "`gtol` termination condition is satisfied."."""
    theta = solve_bending_angle(P_FB, **GEOM, **{**TRUE_FB, "sensor_stiffness_nm_per_rad": 0.0})
    fits = [fit_free_bending(P_FB, theta + SIGMA_FB * np.random.default_rng(seed).standard_normal(theta.shape), CFG)
            for seed in range(6)]
    bound = [f for f in fits if not f.success]
    assert bound and len(bound) < len(fits)
    for fit in bound:
        assert fit.message == "sensor_stiffness_nm_per_rad at its bound (fix it, or the data do not support it)"
        assert "WARNING: sensor_stiffness_nm_per_rad at its bound" in fit.report()
        # the bound itself, not the solver's float beside it (it printed 1.8e-34 next to the warning)
        assert fit.params["sensor_stiffness_nm_per_rad"] == 0.0
        assert "sensor_stiffness_nm_per_rad  0 ± " in fit.report()


def test_a_session_csv_given_as_measured_data_says_how_identify_reads_it(tmp_path):
    from bendsense.identify.data import read_free_bending_csv, read_stiffness_csv

    path = tmp_path / "free_sweep.csv"
    path.write_text("t_s,pressure_kpa," + ",".join(f"ch{i}" for i in range(1, 17)) + "\n0,50," +
                    ",".join(["2000"] * 16) + "\n")
    hint = r"\(a session CSV of coil signals: identify reads it with --session SESSION --calibration CAL\)"
    with pytest.raises(SessionError, match=r"missing bending angle column .*" + hint):
        read_free_bending_csv(path)
    with pytest.raises(SessionError, match=r"missing column fx_n " + hint):
        read_stiffness_csv(path, L)
