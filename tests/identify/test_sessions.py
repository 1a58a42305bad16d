"""``identify free-bending|stiffness --session``: a lab's actuator identified from sessions recorded with bendsense.

The simulated lab actuator departs from the paper's config by K0 +8 % and EI +15 %
(``simulate --k0-error 0.08 --ei-error 0.15``); its sensor is calibrated by ``bendsense
calibrate`` from simulated strips (the hidden sensor of the simulator, not bendsense's
polynomials). The truth is the simulator's: ``K0_true = 1.08 K0_paper(P)``,
``EI_true = 1.15 EI_paper(P)``.
"""

import math
import re

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import bendsense
from bendsense.cli import main
from bendsense.config import MODEL_PARAMETERS, ParameterCovarianceConfig
from bendsense.errors import DataWarning, SessionError
from bendsense.identify import fit_free_bending
from bendsense.identify.covariance import session_covariance
from bendsense.identify.sessions import fit_free_bending_session
from bendsense.identify.weights import fit_stiffness_session, stiffness_data_from_session
from bendsense.mechanics.actuator import FreeBendingModel, model_jacobian
from bendsense.sim.scenarios import free_sweep_profile, simulate

K0_ERROR, EI_ERROR = 0.08, 0.15
PAPER = bendsense.load_config()
P_CHECK = np.linspace(20e3, 110e3, 10)
LEFT_OUT = r"(\d+) of (\d+) loaded frames not used: their signals outside the calibrated range"


def _prior(config):
    """A stated prior (the paper's values, 10 % on μ̄ and μ_s, 0.05 rad prebend, 15 % on EI), as a lab would start."""
    sd = np.array([0.1 * config.material.shear_modulus_pa, 0.1 * config.material.sensor_stiffness_nm_per_rad, 0.05,
                   0.15 * config.stiffness.ei0_nm2, 0.15 * config.stiffness.ei1_nm2_per_pa])
    cov = tuple(tuple(float(v) for v in row) for row in np.diag(sd**2))
    return config.replace(parameter_covariance=ParameterCovarianceConfig(
        parameters=MODEL_PARAMETERS, covariance=cov, source="test prior"))


PRIOR = _prior(PAPER)


def _lab(root, seed, contact_n=0.0):
    """Calibration, free sweep and hanging weights of one simulated lab (one sensor: one seed)."""
    simulate("calibration", root / "cal", seed=seed, frames_per_strip=20)
    cal = bendsense.Calibration.fit(root / "cal" / "manifest.yaml")
    cal.save(root / "cal.yaml")
    mismatch = {"k0_error": K0_ERROR, "ei_error": EI_ERROR}
    simulate("free-sweep", root / "sweep", seed=seed, n_frames=60, contact_n=contact_n, **mismatch)
    simulate("tip-loads", root / "loads", seed=seed, frames_per_config=2, **mismatch)
    return cal, root / "sweep" / "free_sweep.csv", root / "loads" / "tip_loads.csv"


def _identify(cal, sweep, loads, config, rounds=2):
    """Free bending, then stiffness, ``rounds`` times (each fit uses the other's last values)."""
    fits = []
    for _ in range(rounds):
        fb = fit_free_bending_session(sweep, cal, config)
        config = fb.to_config(config)
        with pytest.warns(DataWarning, match=LEFT_OUT):  # the loads at 110-120 kPa beyond the calibrated range
            st = fit_stiffness_session(loads, cal, config)
        config = st.to_config(config)
        fits.append((fb, st))
    return config, fits


def _sigma(config, row):
    """The stated σ of K0 (row 0) or EI (row 1) at P_CHECK from the config's parameter covariance."""
    J = model_jacobian(config, P_CHECK)[:, row, :]
    return np.sqrt(np.einsum("bi,ij,bj->b", J, config.parameter_covariance.matrix, J))


def _k0(config):
    return FreeBendingModel.from_config(config).tip_curvature_per_m(P_CHECK)


K0_TRUE = (1 + K0_ERROR) * _k0(PAPER)
EI_TRUE = (1 + EI_ERROR) * PAPER.stiffness.ei_nm2(P_CHECK)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    root = tmp_path_factory.mktemp("lab")
    cal, sweep, loads = _lab(root, seed=0, contact_n=0.15)
    config, fits = _identify(cal, sweep, loads, PRIOR)
    return {"root": root, "cal": cal, "sweep": sweep, "loads": loads, "config": config, "fits": fits}


# --------------------------------------------------------------------------- the simulated sessions


def test_free_sweep_profile_ramps_up_and_back_with_a_touch_on_the_way_down():
    p, fc = free_sweep_profile(11, 100e3, 0.2)
    np.testing.assert_allclose(p, [0, 20e3, 40e3, 60e3, 80e3, 100e3, 80e3, 60e3, 40e3, 20e3, 0], atol=1e-6)
    assert np.flatnonzero(fc).tolist() == [7]  # x = 0.7 of the sweep
    assert fc[7] == 0.2


def test_free_sweep_session_carries_its_truth(lab):
    s = bendsense.read_session(lab["sweep"])
    assert s.has_pressure and len(s) == 60
    touched = s.extra["fc_n"] > 0
    assert 4 <= touched.sum() <= 8
    # the free frames carry no load but gravity, the touched ones a contact force
    assert np.all(s.extra["fx_n"][~touched] == 0) and np.all(s.extra["fy_n"][~touched] == 0)
    assert np.all(np.hypot(s.extra["fx_n"], s.extra["fy_n"])[touched] == pytest.approx(0.15))
    k0 = (1 + K0_ERROR) * FreeBendingModel.from_config(PAPER).tip_curvature_per_m(s.extra["effective_pressure_pa"])
    np.testing.assert_allclose(s.extra["k0_true_per_m"], k0, rtol=1e-9)


# --------------------------------------------------------------------------- the fits


def test_free_frames_are_chosen_by_the_estimator(lab):
    fb = lab["fits"][-1][0]
    truth = bendsense.read_session(lab["sweep"]).extra
    touched = truth["fc_n"] > 0
    assert not np.any(fb.used[touched])  # every touch rejected
    assert set(fb.reason[touched]) <= {"loaded", "model_misfit", "unusable", "not_identifiable"}
    usable = fb.reason != "unusable"
    assert fb.used[usable & ~touched].mean() >= 0.8  # most free frames kept
    assert fb.settled


def test_identified_k0_within_its_sigma_and_closer_than_the_prior(lab):
    config = lab["config"]
    sigma = _sigma(config, 0)
    err = _k0(config) - K0_TRUE
    assert np.all(np.abs(err) <= 2 * sigma), err / sigma
    assert np.all(np.abs(err) < 0.5 * np.abs(_k0(PAPER) - K0_TRUE))
    # a stated σ that means something: the prior's 8 % error is far outside it
    assert np.all(np.abs(_k0(PAPER) - K0_TRUE) > 2.5 * sigma)


def test_identified_ei_within_its_sigma_and_closer_than_the_prior(lab):
    config = lab["config"]
    sigma = _sigma(config, 1)
    err = config.stiffness.ei_nm2(P_CHECK) - EI_TRUE
    assert np.all(np.abs(err) <= 2 * sigma), err / sigma
    prior_err = PAPER.stiffness.ei_nm2(P_CHECK) - EI_TRUE
    assert np.all(np.abs(err) < 0.5 * np.abs(prior_err))
    assert np.all(np.abs(prior_err) > 2.5 * sigma)


@pytest.mark.parametrize("seed", [1, 2])
def test_sigma_holds_for_other_sensors(tmp_path, seed):
    # frames of one session share one calibration error: judged over independent sensors
    cal, sweep, loads = _lab(tmp_path, seed)
    config, _ = _identify(cal, sweep, loads, PRIOR)
    assert np.all(np.abs(_k0(config) - K0_TRUE) <= 2 * _sigma(config, 0))
    assert np.all(np.abs(config.stiffness.ei_nm2(P_CHECK) - EI_TRUE) <= 2 * _sigma(config, 1))


def test_the_calibration_error_does_not_average_down(lab):
    # the same frames' angles fitted as independent points: s²(JᵀJ)⁻¹ shrinks with the
    # frame count and misses the truth by many of its σ; the session's covariance does not
    fb = lab["fits"][-1][0]
    plain = fit_free_bending(fb.fit.pressure_pa, fb.fit.bending_angle_rad, lab["config"])
    cfg = plain.to_config(lab["config"])
    z_plain = np.abs(_k0(cfg) - K0_TRUE) / _sigma(cfg, 0)
    assert z_plain.max() > 3
    assert np.all(np.diag(fb.fit.covariance) > 4 * np.diag(plain.covariance))


def test_gravity_is_taken_out_of_the_free_angle(lab):
    # the free-bending angle of a used frame is the simulator's true K0 L, not its tip angle
    fb = lab["fits"][-1][0]
    truth = bendsense.read_session(lab["sweep"]).extra
    k0L = truth["k0_true_per_m"] * PAPER.actuator.length_m
    used = fb.used
    assert np.max(np.abs(fb.bending_angle_rad[used] - k0L[used])) < math.radians(1.5)
    assert np.max(np.abs(truth["tip_angle_rad"][used] - k0L[used])) > math.radians(5)  # gravity matters here


# --------------------------------------------------------------------------- the joint covariance


def test_session_covariance_of_repeated_frames(lab):
    # two identical frames: each one's variance is the frame's Σ_S; their covariance is Σ_S without
    # the noise (the calibration's error is common, the noise independent)
    from bendsense.calibration._kernels import shift_covariance

    cal = lab["cal"]
    signals = bendsense.read_session(lab["sweep"]).signals[[20]]
    S = cal.shifts_m(signals)[0]
    N = S.size
    m = cal.error_model()
    sigma = np.empty((N, N))
    noise = np.empty(N)
    shift_covariance(m, S, sigma, noise)
    u = np.random.default_rng(4).normal(size=N)
    out = session_covariance(cal, cal.shifts_m(np.repeat(signals, 2, axis=0)), np.stack([u, u]), np.array([0, 1]), 2)
    assert out[0, 0] == pytest.approx(u @ sigma @ u, rel=1e-10)
    assert out[0, 1] == pytest.approx(u @ (sigma - np.diag(noise)) @ u, rel=1e-10)
    assert 0 < out[0, 1] < out[0, 0]


def test_session_covariance_blocks_agree_with_one_stack(lab, monkeypatch):
    import bendsense.identify.covariance as ic

    cal = lab["cal"]
    signals = bendsense.read_session(lab["sweep"]).signals[:10]
    w = np.random.default_rng(5).normal(size=signals.shape) * 1e3
    groups = np.array([0, 1, 2, 0, 1, 2, 3, 3, 4, 4])
    whole = session_covariance(cal, cal.shifts_m(signals), w, groups, 5)
    monkeypatch.setattr(ic, "_FRAMES_PER_BLOCK", 3)
    np.testing.assert_allclose(session_covariance(cal, cal.shifts_m(signals), w, groups, 5), whole, rtol=1e-10, atol=0)


def test_sandwich_covariance_matches_refits_under_a_common_error():
    # angles with an error common to all points (as a calibration's) and independent noise:
    # the sandwich covariance of fit_free_bending(data_covariance=Σ) matches the refits' scatter
    p = np.linspace(5e3, 110e3, 30)
    theta = FreeBendingModel.from_config(PAPER).bending_angle_rad(p)
    sd_noise, sd_common = math.radians(0.1), math.radians(1.0)
    cov = np.eye(p.size) * sd_noise**2 + np.outer(theta, theta) / theta.max() ** 2 * sd_common**2
    chol = np.linalg.cholesky(cov)
    rng = np.random.default_rng(8)
    fits = [fit_free_bending(p, theta + chol @ rng.normal(size=p.size), PAPER, data_covariance=cov,
                             fix=["prebend_angle_rad"]) for _ in range(60)]
    values = np.array([[f.params[n] for n in MODEL_PARAMETERS[:2]] for f in fits])
    stated = np.mean([np.sqrt(np.diag(f.covariance)[:2]) for f in fits], axis=0)
    np.testing.assert_allclose(stated / values.std(axis=0, ddof=1), 1.0, atol=0.3)
    plain = fit_free_bending(p, theta + chol @ rng.normal(size=p.size), PAPER, fix=["prebend_angle_rad"])
    assert np.all(np.sqrt(np.diag(plain.covariance)[:2]) < 0.7 * values.std(axis=0, ddof=1))  # understated


# --------------------------------------------------------------------------- loads as mass_kg


def test_mass_column_gives_the_same_loads(lab, tmp_path):
    s = bendsense.read_session(lab["loads"])
    extra = {k: v for k, v in s.extra.items() if k not in ("fx_n", "fy_n")}
    extra["mass_kg"] = s.extra["load_n"] / PAPER.gravity.g_m_per_s2
    path = tmp_path / "masses.csv"
    bendsense.session.write_session_csv(bendsense.Session(s.t_s, s.signals, s.pressure_pa, extra=extra), path)
    with pytest.warns(DataWarning, match=LEFT_OUT):
        a = stiffness_data_from_session(lab["loads"], lab["cal"], lab["config"])
    with pytest.warns(DataWarning, match=LEFT_OUT):
        b = stiffness_data_from_session(path, lab["cal"], lab["config"])
    np.testing.assert_allclose(b.force_n, a.force_n, atol=1e-12)
    assert np.all(a.force_n[:, 0] == 0) and np.all(a.force_n[:, 1] < 0)  # hanging down on the upright rig


# --------------------------------------------------------------------------- the command line


def _run(args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _config_file(tmp_path, config):
    path = tmp_path / "prior.yaml"
    bendsense.config.save_config(config, path)
    return path


def test_cli_free_bending_and_stiffness_from_sessions(lab, tmp_path):
    prior = _config_file(tmp_path, PRIOR)
    out1, fig = tmp_path / "free.yaml", tmp_path / "free.png"
    r = _run(["identify", "free-bending", "--session", lab["sweep"], "--calibration", lab["root"] / "cal.yaml",
              "--config", prior, "-o", out1, "--figure", fig])
    assert r.exit_code == 0, r.output
    assert "free frames:" in r.output and "loaded" in r.output
    assert fig.stat().st_size > 10_000
    doc = yaml.safe_load(out1.read_text())
    assert set(MODEL_PARAMETERS[:3]) <= set(doc["parameter_covariance"]["parameters"])
    expected = fit_free_bending_session(lab["sweep"], lab["cal"], PRIOR)
    assert doc["material"]["shear_modulus_pa"] == pytest.approx(expected.fit.params["shear_modulus_pa"], rel=1e-9)
    out2 = tmp_path / "actuator.yaml"
    r = _run(["identify", "stiffness", "--session", lab["loads"], "--calibration", lab["root"] / "cal.yaml",
              "--config", out1, "-o", out2, "--figure", tmp_path / "st.png"])
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load(out2.read_text())
    assert set(MODEL_PARAMETERS) == set(doc["parameter_covariance"]["parameters"])


def _one_line_error(result, pattern):
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.startswith("Error")]
    assert len(lines) == 1, result.output
    assert pattern in lines[0], result.output


def test_cli_says_a_sessions_data_warning_as_one_line_with_its_error(lab, tmp_path, caplog):
    s = bendsense.read_session(lab["sweep"])
    kpa = tmp_path / "kpa.csv"  # pressures in kPa written as Pa: the library's DataWarning names the likely slip
    bendsense.session.write_session_csv(bendsense.Session(s.t_s, s.signals, s.pressure_pa / 1e3), kpa)
    r = _run(["identify", "free-bending", "--session", kpa, "--calibration", lab["root"] / "cal.yaml", "-o",
              tmp_path / "x.yaml"])
    assert r.exit_code != 0 and "Traceback" not in r.output and "Error" in r.output
    said = [rec.getMessage() for rec in caplog.records if rec.name == "bendsense" and rec.levelname == "WARNING"]
    assert any("pressures in kPa given as Pa?" in m for m in said), said  # said, though an error ends the fit
    assert "DataWarning" not in r.output and "sessions.py" not in r.output, r.output


def test_cli_a_calibration_of_another_sensor_is_named_by_its_file(lab, tmp_path):
    from helpers import linear_calibration

    linear_calibration(offset=np.full(8, 2000.0), noise_std=None, sensor=None).save(tmp_path / "cal8.yaml")
    _one_line_error(_run(["identify", "free-bending", "--session", lab["sweep"], "--calibration",
                          tmp_path / "cal8.yaml", "-o", tmp_path / "x.yaml"]),
                    f"{tmp_path / 'cal8.yaml'}: the calibration has 8 channels, but the config's sensor has 16")


def test_cli_bad_inputs_are_one_line(lab, tmp_path):
    cal = lab["root"] / "cal.yaml"
    out = tmp_path / "x.yaml"
    fb = tmp_path / "fb.csv"
    fb.write_text("pressure_kpa,bending_angle_deg\n10,12\n20,25\n30,37\n40,50\n")
    _one_line_error(_run(["identify", "free-bending", fb, "--session", lab["sweep"], "--calibration", cal, "-o",
                          out]), "give DATA.csv or --session, not both")
    _one_line_error(_run(["identify", "free-bending", "--session", lab["sweep"], "-o", out]),
                    "--calibration")
    _one_line_error(_run(["identify", "free-bending", "--session", lab["sweep"], "--calibration",
                          tmp_path / "missing.yaml", "-o", out]), "missing.yaml")
    _one_line_error(_run(["identify", "stiffness", "-o", out]), "give DATA.csv, or --session")
    # a session without pressure
    s = bendsense.read_session(lab["sweep"])
    nop = tmp_path / "nopressure.csv"
    bendsense.session.write_session_csv(bendsense.Session(s.t_s, s.signals, np.nan), nop)
    _one_line_error(_run(["identify", "free-bending", "--session", nop, "--calibration", cal, "-o", out]),
                    "no pressure reading")
    # too few frames to find free ones
    few = tmp_path / "few.csv"
    bendsense.session.write_session_csv(bendsense.Session(s.t_s[:3], s.signals[:3], s.pressure_pa[:3]), few)
    _one_line_error(_run(["identify", "free-bending", "--session", few, "--calibration", cal, "-o", out]),
                    "free frame(s) found")
    # hanging weights without their load
    _one_line_error(_run(["identify", "stiffness", "--session", few,
                          "--calibration", cal, "-o", out]), "no load columns")
    assert not out.exists()


def test_library_errors_name_the_problem(lab):
    s = bendsense.read_session(lab["sweep"])
    with pytest.raises(SessionError, match="give the load as fx_n, fy_n or as mass_kg, not both"):
        extra = {**s.extra, "mass_kg": np.zeros(len(s))}
        stiffness_data_from_session(bendsense.Session(s.t_s, s.signals, s.pressure_pa, extra=extra), lab["cal"])


def test_a_native_session_directory_gives_the_same_fit(lab, tmp_path):
    from bendsense.session.native import import_session_csv

    native = tmp_path / "sweep.bsess"
    import_session_csv(lab["sweep"], native)
    a = fit_free_bending_session(lab["sweep"], lab["cal"], PRIOR)
    b = fit_free_bending_session(native, lab["cal"], PRIOR)
    assert np.array_equal(a.used, b.used)
    for name in MODEL_PARAMETERS[:3]:
        assert b.fit.params[name] == pytest.approx(a.fit.params[name], rel=1e-3, abs=1e-6)


def test_long_sessions_are_thinned_evenly(lab):
    fb = fit_free_bending_session(lab["sweep"], lab["cal"], PRIOR, max_frames=20)
    considered = fb.reason != "thinned"
    assert considered.sum() <= 20 + np.count_nonzero(fb.reason == "unusable")
    assert np.count_nonzero(fb.reason == "thinned") >= 30
    # spread over the whole sweep, up and down
    p = fb.pressure_pa[fb.used]
    assert p.max() > 80e3 and np.flatnonzero(fb.used).max() > 45
    assert "thinned" in fb.report()


def test_report_says_when_ei_is_taken_as_exact(lab):
    without = fit_free_bending_session(lab["sweep"], lab["cal"], PAPER.replace(parameter_covariance=None))
    assert "takes its EI(P) as exact" in without.report()
    assert "as exact" not in lab["fits"][-1][0].report()


# --------------------------------------------------------------------------- against the independent forward model

TRUE_MATERIAL = {"shear_modulus_pa": 1.6e5, "sensor_stiffness_nm_per_rad": 1.2e-3, "prebend_angle_rad": 0.03}
TRUE_STIFFNESS = {"ei0_nm2": 1.15 * PAPER.stiffness.ei0_nm2, "ei1_nm2_per_pa": 1.15 * PAPER.stiffness.ei1_nm2_per_pa}


@pytest.fixture(scope="module")
def independent(tmp_path_factory):
    """Sessions made by tests/forward_model.py (scipy's solve_bvp, its own eq. 8–12, a non-polynomial sensor)."""
    from forward_model import HiddenSensor, forward

    root = tmp_path_factory.mktemp("independent")
    sensor = HiddenSensor(noise_counts=1.5, seed=3)
    cal = bendsense.Calibration.fit(sensor.write_calibration(root / "cal", PAPER, frames=30, flat_frames=60))
    rng = np.random.default_rng(11)

    def session(pressures, forces, name, extra=None):
        shifts = np.array([forward(PAPER, p, f, material=TRUE_MATERIAL, stiffness=TRUE_STIFFNESS).shifts_m
                           for p, f in zip(pressures, forces, strict=True)])
        s = bendsense.Session(np.arange(len(pressures)) / 35.0, sensor.signals(shifts, rng), np.asarray(pressures),
                              extra=extra or {})
        bendsense.session.write_session_csv(s, root / name)
        return root / name

    up = np.linspace(2e3, 110e3, 14)
    p_sweep = np.concatenate([up, up[::-1]])
    sweep = session(p_sweep, np.zeros((p_sweep.size, 2)), "sweep.csv")
    # weights over the whole range of the sweep: EI(P) extrapolated beyond its levels is poorly known, and the
    # sweep's gravity correction needs it everywhere
    p_loads = np.repeat([20e3, 40e3, 60e3, 80e3, 100e3], 2)
    f_loads = np.tile([[0.0, -0.1], [0.0, -0.25]], (5, 1))
    loads = session(p_loads, f_loads, "loads.csv", {"fx_n": f_loads[:, 0], "fy_n": f_loads[:, 1]})
    config, _ = _identify(cal, sweep, loads, PRIOR)
    return config


def test_independent_forward_model_k0_and_ei_within_sigma(independent):
    from forward_model import free_bending_k0

    k0_true = np.array([free_bending_k0(PAPER, p, TRUE_MATERIAL) for p in P_CHECK[:-1]])
    ei_true = TRUE_STIFFNESS["ei0_nm2"] + TRUE_STIFFNESS["ei1_nm2_per_pa"] * P_CHECK[:-1]
    k0 = FreeBendingModel.from_config(independent).tip_curvature_per_m(P_CHECK[:-1])
    ei = independent.stiffness.ei_nm2(P_CHECK[:-1])
    s_k0, s_ei = _sigma(independent, 0)[:-1], _sigma(independent, 1)[:-1]
    assert np.all(np.abs(k0 - k0_true) <= 2 * s_k0), (k0 - k0_true) / s_k0
    assert np.all(np.abs(ei - ei_true) <= 2 * s_ei), (ei - ei_true) / s_ei
    # closer than the paper's values
    assert np.all(np.abs(k0 - k0_true) < np.abs(_k0(PAPER)[:-1] - k0_true))
    assert np.all(np.abs(ei - ei_true) < np.abs(PAPER.stiffness.ei_nm2(P_CHECK[:-1]) - ei_true))


def test_systematic_part_is_not_scaled_by_the_residuals():
    # residuals scattering beyond the stated data covariance scale that covariance up, not the
    # systematic part (an error common to all points, e.g. from EI through the gravity correction)
    p = np.linspace(5e3, 110e3, 30)
    theta = FreeBendingModel.from_config(PAPER).bending_angle_rad(p)
    data = np.eye(p.size) * math.radians(0.05) ** 2
    shape = theta / theta.max()
    systematic = np.outer(shape, shape) * math.radians(1.0) ** 2
    rng = np.random.default_rng(2)
    added = []
    for noise_deg in (0.2, 1.0):
        y = theta + math.radians(noise_deg) * rng.normal(size=p.size)
        fix = ["sensor_stiffness_nm_per_rad"]  # μ̄ and μ_s nearly collinear: their covariance moves with the fit
        with_sys = fit_free_bending(p, y, PAPER, data_covariance=data, systematic_covariance=systematic, fix=fix)
        without = fit_free_bending(p, y, PAPER, data_covariance=data, fix=fix)
        added.append(with_sys.covariance - without.covariance)
    # the same systematic part adds the same covariance whatever the residual scatter (25x apart in variance)
    np.testing.assert_allclose(added[1], added[0], rtol=0.1, atol=1e-3 * np.abs(added[0]).max())
    assert added[0][0, 0] > 0 and added[0][2, 2] > 0 and np.all(added[0][1] == 0)  # μ_s held: no variance


def test_loaded_frames_left_out_are_said_with_their_pressures(lab):
    """A loaded frame beyond the calibrated range is not used: the fit says how many and where (it had fewer
    levels than the session without a word: 10 at 20-110 kPa of a session at 20-120 kPa)."""
    s = bendsense.read_session(lab["loads"])
    loaded = np.hypot(s.extra["fx_n"], s.extra["fy_n"]) > 0
    with pytest.warns(DataWarning, match=LEFT_OUT + r" or their pressure outside actuator\.pressure_range_pa "
                                                    r"\((\d+)\.\.(\d+) kPa\)") as caught:
        data = stiffness_data_from_session(lab["loads"], lab["cal"], lab["config"])
    said = re.search(LEFT_OUT + r".*\((\d+)\.\.(\d+) kPa\)", str(caught[0].message))
    left, of, lo, hi = (int(x) for x in said.groups())
    assert of == loaded.sum() and left == of - len(data.pressure_pa) > 0
    used = set(np.round(data.pressure_pa / 1e3).astype(int))
    assert hi == max(np.round(s.pressure_pa[loaded] / 1e3).astype(int)) and hi not in used and lo >= 20
