"""The simulator with a contact along the body, against the independent forward model (tests/forward_model.py)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from click.testing import CliRunner
from forward_model import forward

import bendsense
from bendsense.cli import main
from bendsense.errors import ConfigError
from bendsense.sim.actuator import SimulatedActuator
from bendsense.sim.scenarios import ALONG_BODY_FRACTIONS, time_varying_frames, touch_locations

CONFIG = bendsense.load_config()
L = CONFIG.actuator.length_m


@pytest.fixture(scope="module")
def sim():
    return SimulatedActuator.from_config(CONFIG, noise_counts=0.0, seed=0)


@pytest.mark.parametrize("fraction", [0.45, 0.7, 0.9])
def test_contact_at_sc_is_normal_and_matches_the_bvp(sim, fraction):
    sc = fraction * L
    p = np.array([40e3, 90e3])
    f = np.array([0.2, 0.1])
    frames = sim.frames(p, contact_n=f, contact_s_m=sc, noise=False)
    assert frames.valid.all() and frames.contact_s_m == sc
    np.testing.assert_allclose(np.hypot(*frames.force_n.T), f, rtol=1e-12)
    for b in range(2):
        truth = forward(CONFIG, p[b], frames.force_n[b], contact_s_m=sc, s_m=[sc])
        phi_c = float(truth.shape.angle_rad[np.argmin(abs(truth.shape.s_m - sc))])
        # frictionless: F ⟂ t(s_c) = (sin φ_c, cos φ_c), pushing against the bending
        fx, fy = frames.force_n[b]
        assert fx * math.sin(phi_c) + fy * math.cos(phi_c) == pytest.approx(0.0, abs=2e-6 * f[b])
        assert fx * math.cos(phi_c) - fy * math.sin(phi_c) < 0
        # the same shifts as solve_bvp with the load at s_c (sensor ends, free beyond s_c)
        np.testing.assert_allclose(frames.shifts_m[b], truth.shifts_m, atol=1e-9)
        np.testing.assert_allclose(frames.tip_position_m[b], truth.shape.tip_position_m, atol=1e-7)


def test_a_contact_at_L_is_the_tip_contact(sim):
    a = sim.frames(60e3, contact_n=0.15, noise=False)
    b = sim.frames(60e3, contact_n=0.15, contact_s_m=L, noise=False)
    np.testing.assert_allclose(b.force_n, a.force_n, atol=1e-10)
    np.testing.assert_allclose(b.shifts_m, a.shifts_m, atol=1e-12)


@pytest.mark.parametrize("bad", [0.0, -0.01, 0.2, math.nan, "x"])
def test_bad_location_is_named(sim, bad):
    with pytest.raises(ConfigError, match="^contact_s_m: "):
        sim.frames(60e3, contact_n=0.1, contact_s_m=bad)


def test_touch_locations():
    t = np.array([0.0, 2.0, 4.9, 5.0, 7.0, 12.0, 17.0, 22.0, 27.0, 32.0])
    loc = touch_locations(t, L, "along-body") / L
    np.testing.assert_allclose(loc, [0.5, 0.5, 0.5, 0.7, 0.7, 0.85, 1.0, 0.6, 0.9, 0.5])
    np.testing.assert_allclose(touch_locations(t, L, None), L)
    np.testing.assert_allclose(touch_locations(t, L, 0.1), 0.1)
    with pytest.raises(ConfigError, match="^contact_s_m: "):
        touch_locations(t, L, "middle")
    assert set(np.round(touch_locations(np.arange(0, 30, 0.5), L, "along-body") / L, 6)) == set(ALONG_BODY_FRACTIONS)


def test_stream_touches_along_the_body_normal_to_the_loaded_shape():
    rows = list(itertools.islice(
        time_varying_frames(CONFIG, 20.0, seed=1, truth=True, duration_s=8.0, contact_s_m="along-body"), 160))
    for k in (50, 150):  # t = 2.5 s (first touch, 0.5 L) and 7.5 s (second, 0.7 L)
        _, _, truth = rows[k]
        assert truth["valid"] and truth["fc_n"] == pytest.approx(0.15)
        sc = truth["contact_s_m"]
        assert sc == pytest.approx((0.5 if k == 50 else 0.7) * L)
        phi_c = np.interp(sc, truth["s_m"], truth["angle_rad"])
        assert truth["fx_n"] * math.sin(phi_c) + truth["fy_n"] * math.cos(phi_c) == pytest.approx(0.0, abs=2e-3 * 0.15)


def test_cli_simulate_contact_along_the_body(tmp_path):
    out = tmp_path / "c"
    r = CliRunner().invoke(main, ["simulate", "contact", "-o", str(out), "--contact-s-m", "0.09", "--frames", "3",
                                  "--rate", "2000", "--noise-counts", "0"])
    assert r.exit_code == 0, r.output
    s = bendsense.read_session(out / "contact.csv")
    names = list(s.extra)
    assert names.index("contact_s_m") == names.index("fy_n") + 1
    np.testing.assert_allclose(s.extra["contact_s_m"], 0.09)
    np.testing.assert_allclose(np.diff(s.t_s), 1 / 2000)
    # the truth force is the one that bends the finger to these counts: solve_bvp agrees at every configuration
    sim = SimulatedActuator.from_config(CONFIG, noise_counts=0.0, seed=0)
    for k in range(0, len(s), 3):
        force = np.array([s.extra["fx_n"][k], s.extra["fy_n"][k]])
        truth = forward(CONFIG, s.pressure_pa[k], force, contact_s_m=0.09)
        expected = sim.sensor.quantize(sim.sensor.signal(truth.shifts_m)).counts
        assert np.abs(s.signals[k] - expected).max() <= 1
    # a tip contact keeps its columns
    r = CliRunner().invoke(main, ["simulate", "contact", "-o", str(tmp_path / "tip"), "--frames", "1"])
    assert r.exit_code == 0, r.output
    assert "contact_s_m" not in bendsense.read_session(tmp_path / "tip" / "contact.csv").extra


@pytest.mark.parametrize(("args", "text"), [
    (["contact", "--contact-s-m", "0.5"], "contact_s_m"),
    (["contact", "--contact-s-m", "-1"], "--contact-s-m"),
    (["contact", "--contact-s-m", "along-body"], "--contact-s-m"),
    (["time-varying", "--contact-s-m", "middle"], "--contact-s-m"),
    (["tip-loads", "--contact-s-m", "0.1"], "--contact-s-m"),
])
def test_cli_bad_location_one_line(tmp_path, args, text):
    r = CliRunner().invoke(main, ["simulate", args[0], "-o", str(tmp_path / "x"), *args[1:]])
    assert r.exit_code != 0 and "Traceback" not in r.output
    errors = [line for line in r.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and text in errors[0], r.output
    assert not (tmp_path / "x").exists()


def test_sim_device_refuses_a_location_for_the_ramp():
    r = CliRunner().invoke(main, ["sim-device", "--source", "ramp", "--contact-s-m", "0.1", "--seconds", "0.1"])
    assert r.exit_code != 0 and "--contact-s-m" in r.output and "Traceback" not in r.output


def test_sim_device_source_touches_along_the_body():
    from bendsense.device.simdevice import default_source

    fixed = list(itertools.islice(default_source(rate_hz=20.0, seed=2, contact_s_m=0.08, duration_s=3.0), 60))
    tip = list(itertools.islice(default_source(rate_hz=20.0, seed=2, duration_s=3.0), 60))
    assert len(fixed) == len(tip) == 60
    # before the first touch (t < 1.5 s) the frames are the same; during it (t = 2.5 s) they differ
    np.testing.assert_array_equal(np.array([c for _, c in fixed[:25]]), np.array([c for _, c in tip[:25]]))
    assert np.abs(fixed[50][1].astype(int) - tip[50][1].astype(int)).max() > 20
    with pytest.raises(ConfigError, match="^contact_s_m: "):
        default_source(rate_hz=20.0, contact_s_m=0.5)
