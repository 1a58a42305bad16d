"""``bendsense.pipeline.process``: a session through reconstruct → estimate, as the CLI chain and process run it."""

import dataclasses
import functools

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import linear_calibration, loaded_curvatures, signals_for

from bendsense import load_config, read_session
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.errors import ArgumentError, SessionError
from bendsense.pipeline import FrameCounts, LiveProcessor, Processed, estimation_options, process
from bendsense.results import Results, read_results
from bendsense.session import Session, write_session_csv

CONFIG = load_config()
SENSOR = CONFIG.sensor
N = SENSOR.n_segments
FRAMES = 12


@functools.cache
def frames():
    """Pressure [Pa], tip force [N] and signals of a loaded actuator (the beam model, no noise)."""
    t = np.linspace(0.0, 1.0, FRAMES)
    pressure = 40e3 + 40e3 * t
    force = np.column_stack([0.05 * np.sin(2 * np.pi * t), -0.1 - 0.1 * t])
    kappa = loaded_curvatures(pressure, force)
    signals = signals_for(kappa, linear_calibration())
    return pressure, force, signals


def session(pressure=None):
    p, force, signals = frames()
    return Session(0.01 * np.arange(FRAMES), signals, p if pressure is None else pressure,
                   extra={"fx_true_n": force[:, 0], "trial": np.arange(FRAMES)})


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("process")
    write_session_csv(session(), root / "run.csv")
    linear_calibration().save(root / "cal.yaml")
    return root


def assert_same_results(a, b):
    assert list(a.columns) == list(b.columns)
    for name in a.columns:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)
    np.testing.assert_array_equal(a.s_m, b.s_m)
    np.testing.assert_array_equal(a.positions_m, b.positions_m)


def test_equals_the_command_line_chain(files):
    out = files / "out"
    res = CliRunner().invoke(main, ["load", str(files / "run.csv"), "--calibration", str(files / "cal.yaml"),
                                    "reconstruct", "--points", "41", "estimate", "--constraint", "normal",
                                    "--tip-angle-source", "shape", "save", str(out)])
    assert res.exit_code == 0, res.output
    got = process(read_session(files / "run.csv"), load_config(), Calibration.load(files / "cal.yaml"),
                  constraint="normal", tip_angle_source="shape", points=41)
    assert isinstance(got, Results) and isinstance(got, Processed)
    assert_same_results(got, read_results(out))
    assert got.estimate.constraint == "normal" and got.positions_m.shape == (FRAMES, 41, 2)
    assert got.session.source == str(files / "run.csv")


def test_equals_the_batch_command(files):
    res = CliRunner().invoke(main, ["process", str(files / "run.csv"), "--calibration", str(files / "cal.yaml"),
                                    "-o", str(files / "batch"), "--workers", "0", "--no-progress"])
    assert res.exit_code == 0, res.output
    got = process(read_session(files / "run.csv"), load_config(), Calibration.load(files / "cal.yaml"))
    assert_same_results(got, read_results(files / "batch" / "run"))


def test_estimates_the_loads_it_was_given():
    got = process(session(), CONFIG, linear_calibration(), constraint="none")
    _, force, _ = frames()
    np.testing.assert_allclose(got.estimate.force_n, force, atol=2e-3)
    assert list(got["status"]) == ["ok"] * FRAMES
    np.testing.assert_array_equal(got["fx_n"], got.estimate.force_n[:, 0])
    assert got.counts() == FrameCounts(frames=FRAMES, ok=FRAMES)
    assert got.reconstruct_s > 0 and got.estimate_s > 0


def test_a_frame_whose_signal_overflows_its_curvature_has_no_force_and_the_others_do():
    """A signal whose curvature overflows (1e308 through a polynomial calibration; inf here through a linear one) makes
    no shape: that frame is no_shape, without a force, and
    the session's other frames are estimated as before (it stopped the whole estimate with a message naming no
    frame); a session where no frame has a shape is one line naming it."""
    good = session()
    signals = good.signals.copy()
    signals[4, 3] = np.inf
    bad = Session(good.t_s, signals, good.pressure_pa, source="bad.csv")
    got = process(bad, CONFIG, linear_calibration(), constraint="none")
    assert not np.isfinite(got.shape.curvature_per_m[4]).all()
    assert list(got["status"]).count("no_shape") == 1 and got["status"][4] == "no_shape"
    assert np.isnan(got["fx_n"][4]) and got.estimate.message[4].startswith("no shape: a signal that is not finite")
    keep = np.arange(FRAMES) != 4
    np.testing.assert_allclose(got.estimate.force_n[keep], process(good, CONFIG, linear_calibration(),
                               constraint="none").estimate.force_n[keep], atol=1e-9)
    assert got.counts() == FrameCounts(frames=FRAMES, ok=FRAMES - 1, no_shape=1, extrapolated=1)
    signals[:, 3] = np.inf
    with pytest.raises(SessionError, match=r"^bad.csv: no frame has a finite shape"):
        process(Session(good.t_s, signals, good.pressure_pa, source="bad.csv"), CONFIG, linear_calibration())


def test_options_fall_back_to_the_config():
    estimation = dataclasses.replace(CONFIG.estimation, constraint="vertical", objective="positions")
    config = CONFIG.replace(estimation=estimation)
    got = process(session(), config, linear_calibration())
    assert (got.estimate.constraint, got.estimate.method, got.estimate.objective) == ("vertical", "fast", "positions")
    np.testing.assert_array_equal(got.estimate.force_n[:, 0], 0.0)  # Fx = 0 under the vertical constraint
    given = process(session(), config, linear_calibration(), constraint="none", objective="angles")
    assert (given.estimate.constraint, given.estimate.objective) == ("none", "angles")
    # the defaults process and LiveProcessor share
    assert estimation_options(config) == ("vertical", "fast", "positions")
    assert estimation_options(config, method="paper") == ("vertical", "paper", "positions")
    assert estimation_options(CONFIG, method="paper") == (CONFIG.estimation.constraint, "paper", "positions")
    live = LiveProcessor(linear_calibration(), config)
    assert (live.constraint, live.method, live.objective) == estimation_options(config)
    with pytest.raises(ArgumentError, match=r"objective: must be one of angles, positions, got 'pcc'"):
        process(session(), CONFIG, linear_calibration(), objective="pcc")


def test_a_constant_pressure_fills_the_frames_without_a_reading():
    p, _, _ = frames()
    partial = p.copy()
    partial[::3] = np.nan
    with pytest.raises(SessionError, match=r"4 of 12 frames have no pressure reading \(give pressure_pa"):
        process(session(partial), CONFIG, linear_calibration())
    got = process(session(partial), CONFIG, linear_calibration(), pressure_pa=50e3)
    np.testing.assert_array_equal(got["pressure_pa"], np.where(np.isnan(partial), 50e3, p))
    constant = process(session(np.full(FRAMES, np.nan)), CONFIG, linear_calibration(), pressure_pa=50e3)
    same = process(session(np.full(FRAMES, 50e3)), CONFIG, linear_calibration())
    assert_same_results(constant, same)


def test_shapes_only():
    got = process(session(np.full(FRAMES, np.nan)), CONFIG, linear_calibration(), estimate=False, points=21)
    assert got.estimate is None and not got.has_forces
    assert "fx_n" not in got.columns and got.positions_m.shape == (FRAMES, 21, 2)
    assert got.counts() == FrameCounts(frames=FRAMES, ok=FRAMES) and got.estimate_s == 0.0
    estimated = process(session(), CONFIG, linear_calibration(), shape=got.shape)
    assert estimated.shape is got.shape and estimated.reconstruct_s == 0.0
    assert_same_results(estimated, process(session(), CONFIG, linear_calibration(), points=21))


def test_pressure_out_of_range_and_extrapolated_frames_are_counted():
    p, _, signals = frames()
    p = p.copy()
    p[[1, 4]] = 250e3  # beyond actuator.pressure_range_pa
    s = session(p)
    s.signals[2, 3] += 5000.0  # beyond the calibrated range of ΔA
    got = process(s, CONFIG, linear_calibration())
    counts = got.counts()
    assert counts.frames == FRAMES and counts.out_of_range == 2 and counts.extrapolated == 1
    assert list(got["status"][[1, 4]]) == ["pressure_out_of_range"] * 2
    assert np.isnan(got["fx_n"][[1, 4]]).all()


def test_mistakes_are_one_line():
    cal = linear_calibration()
    with pytest.raises(ArgumentError, match=r"calibration: expected a Calibration \(Calibration.load\(path\), or the "
                                            r"path\), got NoneType"):
        process(session(), CONFIG)
    with pytest.raises(SessionError, match=r"^the session: no frames$"):
        process(Session(np.zeros(0), np.zeros((0, N)), np.zeros(0)), CONFIG, cal)
    narrow = Session([0.0], np.zeros((1, 8)), [4e4], source="narrow.csv")
    with pytest.raises(SessionError, match=r"narrow.csv: 8 signal channels \(ch1..ch8\), but the calibration cal.yaml "
                                           "has 16"):
        process(narrow, CONFIG, cal, calibration_source="cal.yaml")
    with pytest.raises(ArgumentError, match=r"shape: expected the shapes of the session's 12 frames"):
        process(session(), CONFIG, cal, shape=process(session(), CONFIG, cal, estimate=False).shape[:3])
