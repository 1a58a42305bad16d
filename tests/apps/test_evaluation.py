"""``bendsense reproduce``: the paper's evaluation on simulated data (quick run)."""

import math
import re

import numpy as np
import pytest
from click.testing import CliRunner

from bendsense.apps.evaluation import PAPER, shape_accuracy
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.config import load_config
from bendsense.output import write_dir
from bendsense.shape.pcc import arc_positions

FIGURES = ("fig8_validation_shapes.png", "fig9_static_model.png", "fig10_tip_load_error.png", "identification.png",
           "coverage_calibration.png", "model_error.png")
RADII_MM = (45.75, 55.75, 65.75, 75.75, 85.75, 95.75, 150.75)
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce") / "report"
    with write_dir(out) as earlier:  # an earlier run's output, with a file this run does not write
        (earlier / "stale.txt").write_text("from an earlier run")
    result = CliRunner().invoke(main, ["reproduce", "-o", str(out), "--quick", "--seed", "3", "--overwrite"])
    assert result.exit_code == 0, result.output
    return out, result.output, (out / "report.md").read_text(encoding="utf-8")


def section(text, title):
    start = text.index(title)
    nxt = text.find("\n## ", start + 1)
    return text[start:] if nxt < 0 else text[start:nxt]


def table_rows(text):
    """Rows of the markdown tables in ``text`` (header and rule lines dropped)."""
    rows = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("|") and not line.startswith("|---") and not (
            i + 1 < len(lines) and lines[i + 1].startswith("|---")
        ):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


def numbers(cell):
    return [float(x) for x in NUMBER.findall(cell.replace("−", "-"))]


def test_report_and_figures_written(run):
    out, output, report = run
    assert not (out / "stale.txt").exists()  # --overwrite replaced the earlier output
    assert "wrote" in output
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        assert 5_000 < len(data) < 400_000
        assert f"]({name})" in report
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no temporary directories left
    for title in ("Table I", "Fig. 8", "Identification", "Fig. 9", "Fig. 10", "Table II", "Model error", "Timing"):
        assert f"## {title}" in report


def test_table_i(run):
    rows = table_rows(section(run[2], "## Table I"))
    kappa_val = numbers(" ".join(rows[0][2:]))
    # κ_val = 1 / R_val, computed here from the paper's radii
    np.testing.assert_allclose(kappa_val, [1e3 / r for r in RADII_MM], atol=0.006)
    assert len(rows) == 1 + 3 * 3
    for k, n in enumerate((1, 2, 3)):
        recon, dkappa, dp = rows[1 + 3 * k : 4 + 3 * k]
        assert recon[0] == str(n)
        ours = lambda row: np.array([numbers(c)[0] for c in row[2:9]])  # noqa: E731
        kr = ours(recon)
        assert np.all(np.isfinite(kr))
        # δκ as reported agrees with κ_recon and κ_val of the same table
        exact = 1e3 / np.array(RADII_MM)
        rounding = 0.005 / exact * 100 + 0.005  # κ_recon is printed with 2 decimals
        assert np.all(np.abs(ours(dkappa) - np.abs(kr - exact) / exact * 100) <= rounding)
        limit = 5.0 if n == 3 else 10.0
        assert np.all(ours(dkappa) < limit)
        assert np.all((ours(dp) >= 0) & (ours(dp) < limit))
        mean_std = numbers(dkappa[9])[:2]
        assert mean_std[0] == pytest.approx(np.mean(ours(dkappa)), abs=0.01)
        # the paper's numbers ride along in parentheses
        assert numbers(recon[2])[1] == PAPER["table_i"][n]["kappa_recon_per_m"][0]


def test_model_error_section(run):
    """The simulated board's mismatches: correct data is neither flagged nor under-covered, the prior covers."""
    text = section(run[2], "## Model error")
    assert "bendsense's own model" in text
    rows = table_rows(text)
    assert [r[0] for r in rows] == ["nothing (control)", "K0 +5 %", "EI +15 %", "base rotates 0.05 rad/rad"]
    for row in rows:
        flagged, held = numbers(row[1])
        assert held == 12 and 0 <= flagged <= 100  # 3 holds of 4 windows each
        assert all(0 <= v <= 100 for cell in row[2:] for v in numbers(cell))
    control = rows[0]
    assert numbers(control[1])[0] <= 5.0
    assert min(numbers(control[2])) >= 85.0  # per frame, nothing undeclared to miss
    for row in rows[1:3]:  # K0 +5 %, EI +15 %: the shipped prior covers them
        assert min(numbers(row[3])) >= 85.0


def test_identification_plausible(run):
    rows = table_rows(section(run[2], "## Identification"))
    assert [r[0].split()[0] for r in rows] == ["μ̄", "μ_s", "prebend", "γ0", "γ1"]
    for row in rows:
        true, nominal, identified = numbers(row[1])[0], numbers(row[2])[0], numbers(row[3])[0]
        assert all(math.isfinite(v) for v in (true, nominal, identified))
    # the well-determined parameters come out near the truth despite the mismatch
    mu, ei0 = rows[0], rows[3]
    assert numbers(mu[3])[0] == pytest.approx(numbers(mu[1])[0], rel=0.2)
    assert numbers(ei0[3])[0] == pytest.approx(numbers(ei0[1])[0], rel=0.2)


def test_static_model_and_tip_loads(run):
    rows = table_rows(section(run[2], "## Fig. 9"))
    assert [r[0] for r in rows] == ["20", "40", "80", "120", "max"]
    values = np.array([[numbers(c)[0] for c in r[1:]] for r in rows])
    assert np.all(np.isfinite(values)) and np.all((values > 0) & (values < 15))
    np.testing.assert_allclose(values[-1], values[:-1].max(axis=0))
    rows = table_rows(section(run[2], "## Fig. 10"))
    assert [r[0] for r in rows] == ["0–0.3 N", "0–0.2 N"]
    for row in rows:  # both objectives, then the paper, then the two coverages
        for cell in row[1:3]:
            mean, std = numbers(cell)
            assert 0 < mean < 50 and 0 <= std < 50
        for cell in row[4:6]:
            assert cell.endswith(" %") and 0 <= numbers(cell)[0] <= 100
    assert numbers(rows[0][3]) == list(PAPER["fig10_all_pct"])


def test_coverage_calibration(run):
    text = section(run[2], "## Calibration of the uncertainty")
    rows = table_rows(text)
    assert [r[0] for r in rows] == ["±1σ", "±2σ", "±3σ"]
    assert [numbers(r[1])[0] for r in rows] == [68.3, 95.4, 99.7]
    for r in rows:
        assert all(0 <= numbers(c)[0] <= 100 for c in r[2:4])
    # coverage grows with the level
    for col in (2, 3):
        got = [numbers(r[col])[0] for r in rows]
        assert got == sorted(got)
    assert "coverage_calibration.png" in text


def test_table_ii(run):
    here, paper = section(run[2], "## Table II").split("Paper (12 configurations):")
    angles, positions = here.split("Here, PCC positions")
    assert "Here, coil angles (default):" in angles
    for part in (angles, positions):
        rows = table_rows(part)
        assert [r[0] for r in rows] == ["0–0.1", "0.1–0.2", "0.2–0.3", "0.3–0.4", "mean of full range"]
        counts = [int(r[1]) for r in rows]
        assert sum(counts[:4]) == counts[4] == 6 * 2  # quick: 6 configurations × 2 frames
        for row in rows:
            assert len(row) == 2 + 9 + 3
            for cell in row[2:11]:
                assert cell == "–" or 0 <= float(cell) < 1000
            for cell in row[11:]:  # a coverage column per mode
                assert cell == "–" or (cell.endswith(" %") and 0 <= numbers(cell)[0] <= 100)
        assert all(math.isfinite(float(c)) for c in rows[-1][2:11])
    prow = table_rows(paper)[-1]
    assert [float(c) for c in prow[1:]] == [14.90, 12.91, 7.21, 5.15, 6.77, 4.86]


def test_timing(run):
    rows = table_rows(section(run[2], "## Timing"))
    assert len(rows) == 11
    for row in rows:
        assert row[1] == "not timed (--quick)" if "paper's method" in row[0] else numbers(row[1])[0] > 0
    assert "0.42 s" in [r[2] for r in rows] and "1.38 s" in [r[2] for r in rows]


def test_refuses_to_overwrite(run):
    out = run[0]
    before = (out / "report.md").stat().st_mtime_ns
    result = CliRunner().invoke(main, ["reproduce", "-o", str(out), "--quick"])
    assert result.exit_code != 0
    assert "exists" in result.output and "--overwrite" in result.output
    assert "Traceback" not in result.output
    assert (out / "report.md").stat().st_mtime_ns == before


def test_paper_table_i_transcription():
    # the "All" column of the paper is the mean ± sample std of its own per-radius values
    for n in (1, 2, 3):
        row = PAPER["table_i"][n]
        for values, quoted in ((row["dkappa_pct"], row["dkappa_all_pct"]), (row["dp_max_pct"], row["dp_max_all_pct"])):
            assert np.mean(values) == pytest.approx(quoted[0], abs=0.01)  # the paper rounds
            assert np.std(values, ddof=1) == pytest.approx(quoted[1], abs=0.01)
    kappa = np.array(PAPER["table_i"]["kappa_val_per_m"])
    np.testing.assert_allclose(kappa, 1e3 / np.array(PAPER["table_i"]["radius_mm"]), atol=0.006)


def test_shape_accuracy_exact_on_ideal_sensor():
    # an ideal sensor whose signals are the shifts: S = ΔA, so every strip is an exact arc
    sensor = load_config().sensor
    n = sensor.n_segments
    cal = Calibration(offset=np.zeros(n), coefficients_odd=[0.0, 1.0], coefficients_even=[0.0, 1.0], degree=1,
                      delta_a_range_odd=(-1.0, 1.0), delta_a_range_even=(-1.0, 1.0))
    cumulative = np.cumsum(sensor.lengths_m)
    kappa = [21.86, 6.63]
    strips = [(np.tile(k * sensor.strip_gap_m * cumulative, (3, 1)), k) for k in kappa]
    s = np.linspace(0.0, cumulative[-1], 50)
    table = shape_accuracy(cal, strips, sensor, s)
    np.testing.assert_allclose(table["kappa_recon_per_m"], kappa, rtol=1e-9)
    np.testing.assert_allclose(table["dkappa_pct"], 0.0, atol=1e-7)
    np.testing.assert_allclose(table["dp_max_pct"], 0.0, atol=1e-9)
    np.testing.assert_allclose(table["shapes"], arc_positions(np.array(kappa), s), atol=1e-12)
