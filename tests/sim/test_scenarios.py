"""Simulated scenarios: files, truth, determinism, the frame stream and the CLI."""

import dataclasses
import itertools
import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import bendsense
from bendsense.calibration import read_manifest
from bendsense.cli import main
from bendsense.errors import ArgumentError, ConfigError, OutputError
from bendsense.sim import VirtualSensor, calibration_shifts
from bendsense.sim.scenarios import (
    CALIBRATION_RADII_M,
    SCENARIOS,
    TIP_LOAD_PRESSURES_PA,
    VALIDATION_RADII_M,
    simulate,
    time_varying_frames,
    time_varying_profile,
)

FAST = {"frames_per_strip": 3, "frames_per_config": 2, "duration_s": 0.3}


@pytest.fixture(scope="module")
def all_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "all"
    return simulate("all", out, seed=7, **FAST)


def test_all_scenarios_written(all_dir):
    assert sorted(p.name for p in all_dir.iterdir()) == sorted([*SCENARIOS, ".bendsense-output.json"])
    for name in SCENARIOS:
        doc = yaml.safe_load((all_dir / name / "scenario.yaml").read_text())
        assert doc["scenario"] == name and doc["seed"] == 7
        for file in doc["files"]:
            assert (all_dir / name / file).is_file()
    # no temporary directories left beside the output
    assert [p.name for p in all_dir.parent.iterdir()] == ["all"]


def test_calibration_manifest_resolves(all_dir, config):
    manifest = read_manifest(all_dir / "calibration" / "manifest.yaml")
    assert [r for r, _ in manifest.strips] == pytest.approx(CALIBRATION_RADII_M)
    for radius, path in manifest.strips:
        session = bendsense.read_session_csv(path)
        assert session.signals.shape == (3, 16)
        np.testing.assert_allclose(session.extra["kappa_true_per_m"], 1.0 / radius)
        assert not session.has_pressure
    flat = bendsense.read_session_csv(manifest.flat)
    np.testing.assert_array_equal(flat.extra["kappa_true_per_m"], 0.0)
    cal = bendsense.Calibration.fit(all_dir / "calibration" / "manifest.yaml", degree=3)
    assert cal is not None


def test_noise_free_calibration_counts_are_the_quantised_signal(tmp_path, config):
    out = simulate("calibration", tmp_path / "cal", seed=5, noise_counts=0.0, frames_per_strip=2)
    sensor = VirtualSensor.from_config(config, noise_counts=0.0, seed=5)
    manifest = read_manifest(out / "manifest.yaml")
    for radius, path in manifest.strips:
        expected = np.clip(np.rint(sensor.signal(calibration_shifts(config, radius))), 0, 4095)
        np.testing.assert_array_equal(bendsense.read_session_csv(path).signals, np.broadcast_to(expected, (2, 16)))
    flat = np.clip(np.rint(sensor.signal(np.zeros(16))), 0, 4095)
    np.testing.assert_array_equal(bendsense.read_session_csv(manifest.flat).signals[0], flat)


def test_validation_truth(all_dir):
    index = yaml.safe_load((all_dir / "validation" / "validation.yaml").read_text())
    radii = [s["radius_m"] for s in index["strips"]]
    assert radii == pytest.approx(VALIDATION_RADII_M)
    for strip in index["strips"]:
        session = bendsense.read_session_csv(all_dir / "validation" / strip["recording"])
        np.testing.assert_allclose(session.extra["radius_m"], strip["radius_m"])
        np.testing.assert_allclose(session.extra["kappa_true_per_m"], 1.0 / strip["radius_m"])
    # Table I: 1/45.75 mm = 21.86 1/m
    assert index["strips"][0]["kappa_true_per_m"] == pytest.approx(21.86, abs=0.005)


def test_tip_loads_truth(all_dir, config):
    session = bendsense.read_session_csv(all_dir / "tip-loads" / "tip_loads.csv")
    truth = np.load(all_dir / "tip-loads" / "truth.npz")
    assert len(session) == len(TIP_LOAD_PRESSURES_PA) * 4 * 2
    assert session.meta["excluded_frames"] == "0"
    np.testing.assert_array_equal(session.extra["fx_n"], 0.0)
    np.testing.assert_allclose(session.extra["fy_n"], -session.extra["load_n"])
    assert set(np.round(session.extra["load_n"], 6)) == {0.0, 0.1, 0.2, 0.3}
    assert set(session.pressure_pa) == set(TIP_LOAD_PRESSURES_PA)
    assert truth["positions_m"].shape == (len(session), truth["s_m"].size, 2)
    assert truth["s_m"][-1] == pytest.approx(config.sensor.length_m)
    # a heavier load at the same pressure pulls the tip lower (the rig stands upright)
    at40 = session.pressure_pa == 40e3
    order = np.argsort(session.extra["load_n"][at40])
    assert np.all(np.diff(session.extra["tip_y_m"][at40][order]) <= 1e-12)
    # the truth shape ends at the sensor's end, short of the tip: close to the tip position
    gap = np.hypot(
        truth["positions_m"][:, -1, 0] - session.extra["tip_x_m"],
        truth["positions_m"][:, -1, 1] - session.extra["tip_y_m"],
    )
    assert gap.max() <= config.actuator.length_m - config.sensor.length_m + 1e-9


def test_contact_force_is_normal_to_the_tip_and_pushes_back(all_dir):
    session = bendsense.read_session_csv(all_dir / "contact" / "contact.csv")
    assert sorted(set(session.extra["config"])) == list(range(12))
    fx, fy, phi = session.extra["fx_n"], session.extra["fy_n"], session.extra["tip_angle_rad"]
    np.testing.assert_allclose(fx * np.sin(phi) + fy * np.cos(phi), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.hypot(fx, fy), session.extra["fc_n"], rtol=1e-12)
    assert np.all((session.extra["fc_n"] >= 0) & (session.extra["fc_n"] <= 0.4))
    # against the bending: opposite to the inward normal (cos φ, -sin φ)
    assert np.all(fx * np.cos(phi) - fy * np.sin(phi) <= 1e-12)
    assert np.all(phi >= math.radians(15.0))


def test_time_varying_session_and_stream_agree(all_dir, config):
    session = bendsense.read_session_csv(all_dir / "time-varying" / "session.csv")
    assert len(session) == 30
    np.testing.assert_allclose(session.t_s, np.arange(30) / 100.0)
    pressure, contact = time_varying_profile(session.t_s)
    np.testing.assert_allclose(session.pressure_pa, pressure)
    np.testing.assert_allclose(session.extra["fc_n"], contact)
    stream = list(itertools.islice(time_varying_frames(config, 100.0, seed=7), 30))
    np.testing.assert_allclose([p for p, _ in stream], session.pressure_pa)
    np.testing.assert_array_equal(np.array([c for _, c in stream]), session.signals)


def test_time_varying_profile_shape():
    t = np.arange(0, 10, 0.01)
    pressure, contact = time_varying_profile(t)
    assert pressure.min() == pytest.approx(0.0) and pressure.max() == pytest.approx(100e3, rel=1e-3)
    assert contact.max() == pytest.approx(0.15) and contact.min() == 0.0
    assert np.abs(np.diff(contact)).max() < 0.15 * 0.1  # smooth switching
    np.testing.assert_allclose(time_varying_profile(t + 10.0)[1], contact, atol=1e-12)


def test_stream_with_truth_contact_is_normal(config):
    frames = list(itertools.islice(time_varying_frames(config, 50.0, seed=1, truth=True, duration_s=4.0), 200))
    assert len(frames) == 200
    pressure, counts, truth = frames[120]  # t = 2.4 s: contact on
    assert counts.shape == (16,) and counts.dtype == np.uint16
    assert truth["fc_n"] == pytest.approx(0.15) and truth["valid"]
    t = (math.sin(truth["tip_angle_rad"]), math.cos(truth["tip_angle_rad"]))
    assert truth["fx_n"] * t[0] + truth["fy_n"] * t[1] == pytest.approx(0.0, abs=1e-9)


def test_hysteresis_in_the_stream(config):
    frames = list(time_varying_frames(config, 20.0, seed=1, truth=True, duration_s=5.0, hysteresis_pa=10e3))
    p = np.array([f[0] for f in frames])
    p_eff = np.array([f[2]["effective_pressure_pa"] for f in frames])
    peak = int(np.argmax(p))
    h = 10e3
    assert np.all(np.abs(p_eff - p) <= h / 2 + 1e-9)
    # rising from 0: lags by h/2; falling: leads by h/2 once the input has come back by h
    up, down = p[:peak], p[peak:]
    np.testing.assert_allclose(p_eff[:peak], np.maximum(0.0, up - h / 2))
    np.testing.assert_allclose(p_eff[peak:], np.minimum(p[peak] - h / 2, down + h / 2))


def test_same_seed_same_files_other_seed_other_noise(tmp_path):
    a = simulate("tip-loads", tmp_path / "a", seed=3, frames_per_config=1, pressures_pa=[30e3, 60e3])
    b = simulate("tip-loads", tmp_path / "b", seed=3, frames_per_config=1, pressures_pa=[30e3, 60e3])
    c = simulate("tip-loads", tmp_path / "c", seed=4, frames_per_config=1, pressures_pa=[30e3, 60e3])
    for name in ("tip_loads.csv", "truth.npz"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
    sa, sc = (bendsense.read_session_csv(d / "tip_loads.csv") for d in (a, c))
    assert not np.array_equal(sa.signals, sc.signals)
    np.testing.assert_array_equal(sa.extra["tip_x_m"], sc.extra["tip_x_m"])


def test_model_mismatch_reaches_the_truth(tmp_path, config):
    weightless = config.replace(gravity=dataclasses.replace(config.gravity, g_m_per_s2=0.0))
    kw = {"frames_per_config": 1, "pressures_pa": [60e3], "loads_n": [0.0]}
    plain = simulate("tip-loads", tmp_path / "p", weightless, seed=0, **kw)
    off = simulate("tip-loads", tmp_path / "o", weightless, seed=0, k0_error=0.1, **kw)
    k_plain = bendsense.read_session_csv(plain / "tip_loads.csv").extra["kappa_true5_per_m"]
    k_off = bendsense.read_session_csv(off / "tip_loads.csv").extra["kappa_true5_per_m"]
    np.testing.assert_allclose(k_off, 1.1 * k_plain, rtol=1e-7)


def test_library_errors(tmp_path):
    with pytest.raises(ConfigError, match="scenario: must be one of"):
        simulate("nope", tmp_path / "x")
    with pytest.raises(ConfigError, match="options: unknown frames_per_config"):
        simulate("calibration", tmp_path / "x", frames_per_config=2)
    with pytest.raises(ConfigError, match="frames_per_strip: must be an integer >= 1"):
        simulate("validation", tmp_path / "x", frames_per_strip=0)
    with pytest.raises(ArgumentError, match=r"rate_hz: 0.05 Hz over 10 s gives no frame \(one needs more than 0.05"):
        simulate("time-varying", tmp_path / "x", rate_hz=0.05, duration_s=10.0)
    assert not (tmp_path / "x").exists()
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError):
        simulate("validation", tmp_path / "y", frames_per_strip=1)


def test_overwrite_replaces_only_what_bendsense_wrote(tmp_path):
    out = simulate("validation", tmp_path / "v", frames_per_strip=1, radii_m=[0.05])
    (out / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="holds files bendsense did not write: notes.txt"):
        simulate("validation", out, frames_per_strip=1, radii_m=[0.06], overwrite=True)
    assert (out / "notes.txt").read_text() == "mine" and (out / "r050.csv").exists()
    (out / "notes.txt").unlink()
    simulate("validation", out, frames_per_strip=1, radii_m=[0.06], overwrite=True)
    names = sorted(p.name for p in out.iterdir())
    assert names == [".bendsense-output.json", "r060.csv", "scenario.yaml", "validation.yaml"]  # r050.csv went
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v"]


def test_cli_simulate(tmp_path):
    runner = CliRunner()
    out = tmp_path / "cal"
    result = runner.invoke(main, ["simulate", "calibration", "-o", str(out), "--seed", "2", "--frames", "2"])
    assert result.exit_code == 0, result.output
    assert "calibration: wrote" in result.output
    assert (out / "manifest.yaml").is_file() and (out / "r400.csv").is_file()
    assert len(bendsense.read_session_csv(out / "r040.csv")) == 2


def test_cli_bad_scenario(tmp_path):
    result = CliRunner().invoke(main, ["simulate", "bogus", "-o", str(tmp_path / "x")])
    assert result.exit_code == 2
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and "bogus" in errors[0]
    assert "Traceback" not in result.output
    assert not (tmp_path / "x").exists()


def test_cli_existing_output_untouched(tmp_path):
    out = tmp_path / "v"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    result = CliRunner().invoke(main, ["simulate", "validation", "-o", str(out), "--frames", "1"])
    assert result.exit_code != 0
    assert "exists" in result.output and "Traceback" not in result.output
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    assert (out / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v"]


def test_cli_free_sweep(tmp_path):
    out = tmp_path / "sweep"
    r = CliRunner().invoke(main, ["simulate", "free-sweep", "-o", str(out), "--frames", "11",
                                  "--max-pressure-kpa", "80", "--contact-n", "0.1", "--k0-error", "0.05"])
    assert r.exit_code == 0, r.output
    s = bendsense.read_session(out / "free_sweep.csv")
    np.testing.assert_allclose(s.pressure_pa, 80e3 * (1 - np.abs(np.linspace(-1, 1, 11))), atol=1e-6)
    assert np.flatnonzero(s.extra["fc_n"]).tolist() == [7]
    doc = yaml.safe_load((out / "scenario.yaml").read_text())
    assert doc["options"]["k0_error"] == 0.05 and doc["options"]["n_frames"] == 11
    # options of other scenarios are refused, naming the flag
    r = CliRunner().invoke(main, ["simulate", "tip-loads", "-o", str(tmp_path / "x"), "--max-pressure-kpa", "80"])
    assert r.exit_code != 0 and "--max-pressure-kpa" in r.output and "Traceback" not in r.output
    with pytest.raises(ConfigError, match="n_frames"):
        simulate("free-sweep", tmp_path / "y", n_frames=0)
    # a contact force in mN given in N: beyond what the finger can press, refused before any frame
    from bendsense.control import force_limit_n

    limit = force_limit_n(bendsense.load_config(), 80e3)
    for scenario, extra in (("free-sweep", ["--max-pressure-kpa", "80"]), ("time-varying", [])):
        r = CliRunner().invoke(main, ["simulate", scenario, "-o", str(tmp_path / "mn"), "--contact-n", "150", *extra])
        assert r.exit_code != 0 and "contact_n: 150 N is beyond what the finger can press" in r.output, r.output
        assert "a force in mN given in N?" in r.output and not (tmp_path / "mn").exists()
    with pytest.raises(ConfigError, match="at most"):
        simulate("free-sweep", tmp_path / "z", pressure_max_pa=80e3, contact_n=1.01 * limit)
    simulate("free-sweep", tmp_path / "z", n_frames=11, pressure_max_pa=80e3, contact_n=0.99 * limit)
