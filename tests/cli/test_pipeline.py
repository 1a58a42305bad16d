"""The chained command line: calibrate, then load → reconstruct → save, against a virtual sensor."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import bendsense
from bendsense.cli import main
from bendsense.results import read_results
from bendsense.session import Session, write_session_csv
from bendsense.shape.pcc import fit_arc_curvature
from bendsense.sim.sensor import VirtualSensor, calibration_shifts
from bendsense.status import Status

RADII_M = [0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.2, 0.3, 0.4]


def _recording(path, counts, pressure_pa=np.nan, extra=None):
    counts = np.atleast_2d(counts)
    n = counts.shape[0]
    write_session_csv(Session(np.arange(n) * 0.01, counts, np.full(n, pressure_pa), extra=extra or {}), path)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A calibration manifest and a validation session made with the virtual sensor."""
    root = tmp_path_factory.mktemp("cli")
    config = bendsense.load_config()
    sensor = VirtualSensor.from_config(config, noise_counts=0.5, seed=3)
    frames = 20
    _recording(root / "flat.csv", sensor.measure(np.zeros((frames, 16))).counts)
    strips = []
    for r in RADII_M:
        shifts = np.broadcast_to(calibration_shifts(config.sensor, r), (frames, 16))
        _recording(root / f"r{r * 1e3:03.0f}.csv", sensor.measure(shifts).counts)
        strips.append({"radius_mm": r * 1e3, "recording": f"r{r * 1e3:03.0f}.csv"})
    (root / "manifest.yaml").write_text(yaml.safe_dump({"flat": "flat.csv", "strips": strips}))
    # validation: three arcs the calibration has not seen
    kappa = np.array([1 / 0.04575, 1 / 0.07575, 1 / 0.15075])
    shifts = np.stack([calibration_shifts(config.sensor, 1 / k) for k in kappa])
    _recording(root / "validation.csv", sensor.measure(shifts).counts, 0.0, {"kappa_true_per_m": kappa})
    return root


def test_calibrate_then_reconstruct_and_save(workdir):
    runner = CliRunner()
    res = runner.invoke(main, ["calibrate", str(workdir / "manifest.yaml"), "-o", str(workdir / "cal.yaml"),
                               "--degree", "3"])
    assert res.exit_code == 0, res.output
    out = workdir / "out"
    res = runner.invoke(main, ["load", str(workdir / "validation.csv"), "--calibration", str(workdir / "cal.yaml"),
                               "reconstruct", "--points", "67", "save", str(out)])
    assert res.exit_code == 0, res.output
    results = read_results(out)
    kappa_true = results["kappa_true_per_m"]
    assert results.positions_m.shape == (3, 67, 2) and results.s_m.shape == (67,)
    # every segment of an arc has the arc's curvature, up to the calibration's model error
    # (a cubic for a coil response that is not a polynomial), which differencing the
    # shifts (eq. 3) amplifies per segment; the fitted arc (eq. 19) averages it out
    np.testing.assert_allclose(results.curvature_per_m, kappa_true[:, None] * np.ones(16), rtol=0.15)
    kappa_fit = fit_arc_curvature(results.positions_m, results.s_m)
    np.testing.assert_allclose(kappa_fit, kappa_true, rtol=0.02)  # paper Table I: all below 2.3 %
    assert list(results["status"]) == ["ok"] * 3
    tip = np.column_stack([results["tip_x_m"], results["tip_y_m"]])
    np.testing.assert_allclose(tip, results.positions_m[:, -1], atol=1e-12)


def test_save_refuses_to_overwrite(workdir):
    runner = CliRunner()
    runner.invoke(main, ["calibrate", str(workdir / "manifest.yaml"), "-o", str(workdir / "cal2.yaml")])
    out = workdir / "exists"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    res = runner.invoke(main, ["load", str(workdir / "validation.csv"), "--calibration", str(workdir / "cal2.yaml"),
                               "reconstruct", "save", str(out)])
    assert res.exit_code == 1
    assert "exists and is not empty (use --overwrite" in res.output
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_reconstruct_without_calibration_is_a_usage_error(workdir):
    res = CliRunner().invoke(main, ["load", str(workdir / "validation.csv"), "reconstruct"])
    assert res.exit_code == 2
    assert "--calibration" in res.output
    assert "Traceback" not in res.output


def test_malformed_session_is_one_line(workdir):
    bad = workdir / "bad.csv"
    bad.write_text("t_s,ch1\n0,abc\n")
    res = CliRunner().invoke(main, ["load", str(bad), "export", str(workdir / "never.csv")])
    assert res.exit_code == 1
    assert res.output.strip().splitlines() == [f"Error: {bad}: line 2, column ch1: expected a number, got 'abc'"]
    assert not (workdir / "never.csv").exists()


def test_export_round_trip(workdir):
    out = workdir / "copy.csv"
    res = CliRunner().invoke(main, ["load", str(workdir / "validation.csv"), "export", str(out)])
    assert res.exit_code == 0, res.output
    a, b = bendsense.read_session(workdir / "validation.csv"), bendsense.read_session(out)
    np.testing.assert_array_equal(a.signals, b.signals)
    np.testing.assert_array_equal(a.extra["kappa_true_per_m"], b.extra["kappa_true_per_m"])


def test_input_columns_named_like_results_are_kept(tmp_path):
    from types import SimpleNamespace

    from bendsense.results import write_results
    from bendsense.shape.pcc import Shape

    truth = np.array([0.1, 0.2])
    session = Session([0.0, 0.1], np.zeros((2, 16)), [1e4, 2e4], extra={"fx_n": truth, "trial": np.array([7, 8])})
    shape = Shape.from_curvatures(np.zeros((2, 16)), bendsense.load_config().sensor.lengths_m)
    write_results(tmp_path / "shape_only", session, shape)
    shape_only = read_results(tmp_path / "shape_only")
    # passed through, and never posing as an estimate when there is none
    np.testing.assert_array_equal(shape_only["input_fx_n"], truth)
    assert "fx_n" not in shape_only.columns and not shape_only.has_forces

    estimate = SimpleNamespace(force_n=np.array([[0.5, 0.0], [0.6, 0.0]]), std_n=np.full((2, 2), 0.01),
                               residual_m=np.zeros(2), success=np.array([True, True]),
                               status=np.full(2, Status.OK))
    write_results(tmp_path / "forces", session, shape, estimate)
    results = read_results(tmp_path / "forces")
    np.testing.assert_array_equal(results["fx_n"], [0.5, 0.6])
    np.testing.assert_array_equal(results["input_fx_n"], truth)
    np.testing.assert_array_equal(results["trial"], [7, 8])
    assert results.extra_names == ("input_fx_n", "trial")


def test_the_choices_are_declared_once_and_help_stays_free_of_numpy():
    import subprocess
    import sys

    from bendsense import choices, config, estimation
    from bendsense.cli import _common

    for name in ("CONSTRAINTS", "METHODS", "OBJECTIVES", "ANGLE_SOURCES"):
        assert getattr(_common, name) is getattr(choices, name) is getattr(config, name)
    assert estimation.CONSTRAINTS is estimation.problem.CONSTRAINTS is choices.CONSTRAINTS
    assert estimation.METHODS is choices.METHODS and estimation.OBJECTIVES is choices.OBJECTIVES
    # the calibration model's choices: declared once, offered by calibrate
    from bendsense.calibration import polynomials

    assert polynomials.DEGREES is choices.CALIBRATION_DEGREES
    assert polynomials.WEIGHTINGS is choices.CALIBRATION_WEIGHTINGS
    # the CLI's options come from the same tuples, and `bendsense --help` does not load numpy
    code = ("import sys; from bendsense.cli import main; from click.testing import CliRunner; "
            "r = CliRunner().invoke(main, ['estimate', '--help']); "
            "assert r.exit_code == 0 and 'angles|positions' in r.output, r.output; "
            "print('numpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_shapes_only_results_work_downstream(tmp_path):
    from click.testing import CliRunner

    from bendsense.cli import main

    data = Path(__file__).parents[1] / "data"
    good = (data / "invalid" / "good" / "session.csv").read_text().splitlines()
    rows = [good[0] + ",fx_n,fy_n"] + [line + f",{0.1 * i},-0.05" for i, line in enumerate(good[1:])]
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "truth.csv").write_text("\n".join(rows) + "\n")
    cal = data / "calibration" / "calibration_v1.yaml"
    runner = CliRunner()
    res = runner.invoke(main, ["process", str(tmp_path / "runs"), "--calibration", str(cal), "-o",
                               str(tmp_path / "out"), "--no-estimate", "--workers", "0", "--no-progress"])
    assert res.exit_code == 0, res.output
    results = read_results(tmp_path / "out" / "truth")
    assert not results.has_forces and "fx_n" not in results.columns
    np.testing.assert_allclose(results["input_fx_n"], [0.0, 0.1, 0.2, 0.3])
    res = runner.invoke(main, ["plot", str(tmp_path / "out" / "truth"), "-o", str(tmp_path / "fig.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(main, ["load", str(tmp_path / "runs" / "truth.csv"), "--calibration", str(cal),
                               "reconstruct", "save", str(tmp_path / "chain"), "plot", str(tmp_path / "chain.svg")])
    assert res.exit_code == 0, res.output
    assert "no force estimate" in (tmp_path / "chain.svg").read_text()



def test_plot_of_results_with_an_infinite_pressure_is_one_line(workdir, tmp_path):
    runner = CliRunner()
    cal = tmp_path / "cal.yaml"
    assert runner.invoke(main, ["calibrate", str(workdir / "manifest.yaml"), "-o", str(cal)]).exit_code == 0
    out = tmp_path / "out"
    res = runner.invoke(main, ["load", str(workdir / "validation.csv"), "--calibration", str(cal), "reconstruct",
                               "save", str(out)])
    assert res.exit_code == 0, res.output
    lines = (out / "results.csv").read_text().splitlines()
    header = lines[0].split(",")
    row = lines[2].split(",")
    row[header.index("pressure_pa")] = "inf"
    lines[2] = ",".join(row)
    (out / "results.csv").write_text("\n".join(lines) + "\n")
    res = runner.invoke(main, ["plot", str(out), "-o", str(tmp_path / "f.png")])
    assert res.exit_code == 1 and "line 3, column pressure_pa: must be finite or nan, got inf" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "f.png").exists()
