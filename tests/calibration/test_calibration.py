"""Sensor calibration (paper eq. 1–2, section V-B) and the ``calibrate`` command."""

import dataclasses
from pathlib import Path

import click
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from bendsense import load_config
from bendsense.calibration import Calibration, cross_validate_degree, polyfit_shift, read_manifest
from bendsense.cli import calibrate as calibrate_cli
from bendsense.cli.pipeline import PipelineGroup, run_steps
from bendsense.errors import ConfigError, SessionError
from bendsense.session import Session, write_session_csv
from bendsense.shape.pcc import fit_arc_curvature, max_position_error, reconstruct

DATA = Path(__file__).parents[1] / "data" / "calibration"
SENSOR = load_config().sensor
N = SENSOR.n_segments
ODD = np.arange(N) % 2 == 0  # channels 1, 3, ... (1-based)
RADII = [0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.10, 0.20, 0.30, 0.40]  # the paper's strips
U = 1000.0  # signal scale of the synthetic sensor [counts]


class SyntheticSensor:
    """An independent sensor model: ΔA_i = f⁻¹(S_i), f a known monotone polynomial per parity.

    ``S = scale · (u + a u² + b u³)`` with u = ΔA / U; the even channels have the
    opposite trend (negative scale), as in the paper.
    """

    def __init__(self, odd=(8e-3, 0.1, 0.05), even=(-7e-3, -0.08, 0.1), offset=None, sensor=SENSOR):
        self.odd, self.even, self.sensor = odd, even, sensor
        self.offset = np.linspace(2000.0, 2300.0, sensor.n_segments) if offset is None else offset

    @staticmethod
    def coefficients(params):
        scale, a, b = params
        return np.array([0.0, scale, scale * a, scale * b]) / U ** np.arange(4)

    @staticmethod
    def _f(params, u):
        scale, a, b = params
        return scale * (u + a * u**2 + b * u**3)

    def _inverse(self, params, shifts):
        lo, hi = np.full_like(shifts, -1.0), np.full_like(shifts, 1.0)
        increasing = params[0] > 0
        for _ in range(80):  # bisection: the polynomial is monotone on [-1, 1]
            mid = 0.5 * (lo + hi)
            above = (self._f(params, mid) > shifts) == increasing
            hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
        return 0.5 * (lo + hi) * U

    def signals(self, kappa, frames=10, noise=0.0, rng=None):
        shifts = kappa * self.sensor.strip_gap_m * np.cumsum(self.sensor.lengths_m)  # S_i = κ d L_i
        odd = np.arange(self.sensor.n_segments) % 2 == 0
        delta = np.where(odd, self._inverse(self.odd, shifts), self._inverse(self.even, shifts))
        out = np.tile(self.offset + delta, (frames, 1))
        if noise:
            out = out + noise * rng.standard_normal(out.shape)
        return out


def write_recording(path, signals):
    t = np.arange(len(signals)) * 0.01
    write_session_csv(Session(t_s=t, signals=signals, pressure_pa=np.full(len(t), np.nan)), path)


def write_manifest(tmp_path, model, radii=RADII, noise=0.0, seed=0, use_mm=False, sleeve=0.0):
    rng = np.random.default_rng(seed)
    write_recording(tmp_path / "flat.csv", model.signals(0.0, noise=noise, rng=rng))
    strips = []
    for r in radii:
        name = f"r{r * 1e3:05.1f}.csv"
        write_recording(tmp_path / name, model.signals(1.0 / (r + sleeve), noise=noise, rng=rng))
        strips.append({"radius_mm": r * 1e3, "recording": name} if use_mm else {"radius_m": r, "recording": name})
    manifest = tmp_path / "manifest.yaml"
    manifest.write_text(yaml.safe_dump({"flat": "flat.csv", "strips": strips}))
    return manifest


# --- fitting ------------------------------------------------------------------------------

params_odd = st.tuples(st.floats(6e-3, 1.5e-2), st.floats(-0.15, 0.15), st.floats(-0.15, 0.15))
params_even = st.tuples(st.floats(-1.5e-2, -6e-3), st.floats(-0.15, 0.15), st.floats(-0.15, 0.15))


@settings(max_examples=25, deadline=None)
@given(odd=params_odd, even=params_even)
def test_round_trip_recovers_known_polynomials(odd, even):
    model = SyntheticSensor(odd, even)
    flat = model.signals(0.0)
    strips = [model.signals(1 / r) for r in RADII]
    cal = Calibration.from_data(flat, strips, RADII, SENSOR, degree=3)
    for got, params in ((cal.coefficients_odd, odd), (cal.coefficients_even, even)):
        want = SyntheticSensor.coefficients(params)
        # compare scaled to the unit interval u = ΔA/U, where all terms are O(scale)
        np.testing.assert_allclose(
            got * U ** np.arange(4), want * U ** np.arange(4), rtol=0, atol=1e-9 * abs(params[0])
        )
    np.testing.assert_allclose(cal.offset, model.offset, rtol=1e-12)
    for r in cal.strip_residuals:
        assert r.rms_shift_m < 1e-12
    # fit → evaluate → refit gives the same polynomial
    delta = np.linspace(*cal.delta_a_range_odd, 30)
    again = polyfit_shift(delta, np.polynomial.polynomial.polyval(delta, cal.coefficients_odd), 3)
    np.testing.assert_allclose(again * U ** np.arange(4), cal.coefficients_odd * U ** np.arange(4), atol=1e-12)


def test_fit_from_manifest_and_reconstruct_validation_strips(tmp_path):
    model = SyntheticSensor()
    manifest = write_manifest(tmp_path, model, use_mm=True)
    cal = Calibration.fit(manifest)  # sensor=None: the paper's
    assert cal.degree == 3 and cal.n_channels == 16 and not cal.sleeve
    np.testing.assert_allclose(
        cal.coefficients_odd * U ** np.arange(4), model.coefficients(model.odd) * U ** np.arange(4), atol=1e-12
    )
    np.testing.assert_allclose(
        cal.coefficients_even * U ** np.arange(4), model.coefficients(model.even) * U ** np.arange(4), atol=1e-12
    )
    assert [r.recording for r in cal.strip_residuals] == [f"r{r * 1e3:05.1f}.csv" for r in RADII]
    assert [r.radius_m for r in cal.strip_residuals] == pytest.approx(RADII)
    # Table I's validation radii (R + c): exact polynomial data reconstructs exact arcs
    r_val = np.array([45.75, 55.75, 65.75, 75.75, 85.75, 95.75, 150.75]) * 1e-3
    signals = np.stack([model.signals(1 / r, frames=1)[0] for r in r_val])
    shape = reconstruct(signals, cal, SENSOR)
    np.testing.assert_allclose(shape.curvature_per_m, (1 / r_val)[:, None] * np.ones(16), rtol=1e-8)
    np.testing.assert_allclose(fit_arc_curvature(shape.positions_m, shape.s_m), 1 / r_val, rtol=1e-8)
    assert np.all(max_position_error(shape.positions_m, shape.s_m, 1 / r_val, SENSOR.length_m) < 1e-6)
    assert not shape.extrapolated.any()


def test_sleeve_option_and_config(tmp_path):
    model = SyntheticSensor()
    c = SENSOR.sleeve_thickness_m
    manifest = write_manifest(tmp_path, model, sleeve=c)  # strips bend the sensor to R + c
    plain = Calibration.fit(manifest, SENSOR)
    with_sleeve = Calibration.fit(manifest, SENSOR, sleeve=True)
    from_config = Calibration.fit(manifest, dataclasses.replace(SENSOR, calibration_adds_sleeve=True))
    assert with_sleeve.sleeve and from_config.sleeve and not plain.sleeve
    want = model.coefficients(model.odd) * U ** np.arange(4)
    np.testing.assert_allclose(with_sleeve.coefficients_odd * U ** np.arange(4), want, atol=1e-12)
    np.testing.assert_array_equal(from_config.coefficients_odd, with_sleeve.coefficients_odd)
    assert plain.strip_residuals[0].rms_shift_m > 1e-6  # κ = 1/R is the wrong ground truth here
    assert with_sleeve.strip_residuals[0].curvature_per_m == pytest.approx(1 / (0.04 + c))


def test_weighting_shift_is_exact_on_exact_data_and_differs_on_noisy_data():
    model = SyntheticSensor()
    rng = np.random.default_rng(1)
    exact = Calibration.from_data(model.signals(0), [model.signals(1 / r) for r in RADII], RADII, weighting="shift")
    np.testing.assert_allclose(
        exact.coefficients_odd * U ** np.arange(4), model.coefficients(model.odd) * U ** np.arange(4), atol=1e-12
    )
    flat = model.signals(0, 20, 2.0, rng)
    strips = [model.signals(1 / r, 20, 2.0, rng) for r in RADII]
    a = Calibration.from_data(flat, strips, RADII, weighting="none")
    b = Calibration.from_data(flat, strips, RADII, weighting="shift")
    assert a.weighting == "none" and b.weighting == "shift"
    assert not np.allclose(a.coefficients_odd, b.coefficients_odd, rtol=1e-9, atol=0)
    with pytest.raises(ConfigError, match="weighting: must be one of none, shift, got 'strip'"):
        Calibration.from_data(flat, strips, RADII, weighting="strip")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_auto_degree_picks_the_true_degree(seed):
    # a clearly cubic sensor, noisy frames: CV must neither underfit (2) nor overfit (4, 5)
    model = SyntheticSensor(odd=(8e-3, 0.0, 0.15), even=(-8e-3, 0.0, -0.15))
    rng = np.random.default_rng(seed)
    flat = model.signals(0, 30, 1.0, rng)
    strips = [model.signals(1 / r, 30, 1.0, rng) for r in RADII]
    cal = Calibration.from_data(flat, strips, RADII, degree="auto")
    assert cal.degree == 3
    assert sorted(cal.cv_errors_m) == [1, 2, 3, 4, 5]
    assert cal.cv_errors_m[1] > cal.cv_errors_m[2] > cal.cv_errors_m[3]
    assert "CV rms" in cal.report() and "<- chosen" in cal.report()
    # noise estimate from the flat recording
    np.testing.assert_allclose(cal.noise_std, 1.0, rtol=0.5)


def test_cross_validation_is_leave_one_strip_out():
    # a line fitted without the strip at x = 2 predicts it with error |y2 − 2| exactly
    delta = np.array([[0.0, 0.0], [1.0, -1.0], [2.0, -2.0], [3.0, -3.0]])
    shifts = np.array([[0.0, 0.0], [1.0, 1.0], [2.5, 2.5], [3.0, 3.0]])
    cv = cross_validate_degree(delta, shifts, groups=[-1, 0, 1, 2], degrees=[1])
    preds = []
    for leave in (1, 2, 3):
        keep = [i for i in range(4) if i != leave]
        c = np.polyfit(delta[keep, 0], shifts[keep, 0], 1)
        preds.append(np.polyval(c, delta[leave, 0]) - shifts[leave, 0])
    assert cv[1] == pytest.approx(np.sqrt(np.mean(np.square(preds))), rel=1e-12)


def test_degree_checks():
    model = SyntheticSensor()
    flat, strips = model.signals(0), [model.signals(1 / r) for r in RADII[:2]]
    with pytest.raises(ConfigError, match=r"degree: must be 1..5 or 'auto', got 7"):
        Calibration.from_data(flat, strips, RADII[:2], degree=7)
    with pytest.raises(ConfigError, match=r"degree: 'auto' needs at least 2 calibration strips"):
        Calibration.from_data(flat, strips[:1], RADII[:1], degree="auto")
    # 4 channels, flat + 1 strip: 3 distinct ΔA levels per parity (0 and two channels)
    small = dataclasses.replace(SENSOR, n_segments=4, segment_lengths_m=(0.01, 0.008, 0.008, 0.01))
    model4 = SyntheticSensor(offset=np.zeros(4), sensor=small)
    Calibration.from_data(model4.signals(0), [model4.signals(20.0)], [0.05], small, degree=2)
    with pytest.raises(ConfigError, match=r"degree: 3 needs at least 4 distinct signal levels per parity, got 3"):
        Calibration.from_data(model4.signals(0), [model4.signals(20.0)], [0.05], small, degree=3)


# --- extrapolation ------------------------------------------------------------------------


def test_in_range_flags_extrapolation_per_frame():
    model = SyntheticSensor()
    rng = np.random.default_rng(3)
    flat = model.signals(0, 50, 0.5, rng)
    cal = Calibration.from_data(flat, [model.signals(1 / r) for r in RADII], RADII)
    assert cal.in_range(flat).all()  # a noisy flat sensor is not an extrapolation
    inside = model.signals(1 / 0.045, frames=1)[0]
    beyond = model.signals(1 / 0.030, frames=1)[0]  # tighter than the tightest strip
    backward = model.signals(-1 / 0.1, frames=1)[0]  # bent the other way: never calibrated
    assert cal.in_range(np.stack([inside, beyond, backward])).tolist() == [True, False, False]
    assert cal.in_range(inside).shape == ()
    with pytest.raises(ValueError, match="signals: expected 16 channels"):
        cal.in_range(np.zeros(15))


# --- files --------------------------------------------------------------------------------


def test_save_load_round_trip_is_exact(tmp_path):
    model = SyntheticSensor()
    rng = np.random.default_rng(5)
    cal = Calibration.from_data(
        model.signals(0, 10, 0.3, rng), [model.signals(1 / r, 10, 0.3, rng) for r in RADII], RADII, degree="auto"
    )
    path = tmp_path / "cal.yaml"
    cal.save(path)
    text = path.read_text()
    assert "format: bendsense-calibration" in text and "version: 1" in text
    back = Calibration.load(path)
    for name in ("offset", "coefficients_odd", "coefficients_even", "noise_std", "fit_delta_a", "fit_shifts_m"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name))
    assert back.to_dict() == cal.to_dict()
    assert back.strip_residuals == cal.strip_residuals and back.sensor == cal.sensor
    signals = model.signals(1 / 0.065, 3, 0.3, rng)
    np.testing.assert_array_equal(back.shifts_m(signals), cal.shifts_m(signals))


def test_legacy_v1_file_still_loads():
    cal = Calibration.load(DATA / "calibration_v1.yaml")
    assert cal.degree == 2 and cal.n_channels == 16 and cal.weighting == "none"
    # the file's polynomials: S = 1e-6 ΔA + 1e-10 ΔA² (odd), −1e-6 ΔA + 2e-10 ΔA² (even)
    signals = np.array(cal.offset) + np.where(ODD, 100.0, -100.0)
    expected = np.where(ODD, 1e-6 * 100 + 1e-10 * 100**2, -1e-6 * -100 + 2e-10 * 100**2)
    np.testing.assert_allclose(cal.shifts_m(signals), expected, rtol=1e-14)
    assert cal.delta_a_range_odd == (0.0, 600.0) and cal.delta_a_range_even == (-650.0, 0.0)
    assert cal.sensor == SENSOR


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": "other"}, r"format: expected 'bendsense-calibration', got 'other'"),
        ({"version": 2}, r"version: this bendsense reads version 1, got 2"),
        ({"coefficients_odd": [0.0, 1.0]}, r"coefficients_odd: expected 3 coefficients \(degree 2\), got 2"),
        ({"offset": [1.0, "x"]}, r"offset: expected a list of numbers"),
        ({"delta_a_range_odd": [5.0, 1.0]}, r"delta_a_range_odd: expected \[min, max\] with min <= max"),
        ({"slope": 1}, r"calibration: unknown keys slope"),
        ({"noise_std": [0.1] * 15}, r"noise_std: expected 16 numbers, got 15"),
    ],
)
def test_load_errors_name_the_field(tmp_path, change, message):
    data = yaml.safe_load((DATA / "calibration_v1.yaml").read_text())
    data.update(change)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=message):
        Calibration.load(path)
    with pytest.raises(ConfigError, match=r"missing.yaml: cannot read calibration"):
        Calibration.load(tmp_path / "missing.yaml")


# --- manifest errors ------------------------------------------------------------------------


@pytest.fixture
def manifest_dir(tmp_path):
    model = SyntheticSensor()
    write_manifest(tmp_path, model, radii=RADII[:3])
    return tmp_path


def with_manifest(directory, data):
    path = directory / "manifest.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("strips", "message"),
    [
        ([{"radius_m": 0.04, "recording": "nothere.csv"}], r"strips\[0\].recording: no such recording 'nothere.csv'"),
        ([{"radius_m": 0.04, "radius_mm": 40, "recording": "r040.0.csv"}], r"strips\[0\]: give exactly one of"),
        ([{"radius_m": -0.04, "recording": "r040.0.csv"}], r"strips\[0\].radius_m: expected > 0, got -0.04"),
        ([{"radius_mm": 0, "recording": "r040.0.csv"}], r"strips\[0\].radius_mm: expected > 0, got 0"),
        (
            [{"radius_m": 0.04, "recording": "r040.0.csv"}, {"radius_m": 0.05, "recording": "r050.0.csv"},
             {"radius_cm": 4, "recording": "r060.0.csv"}],
            r"strips\[2\].radius_cm: unknown key; allowed: radius_m, radius_mm, recording",
        ),
        ([{"recording": "r040.0.csv"}], r"strips\[0\]: missing key radius_m or radius_mm"),
        ([{"radius_m": 0.04}], r"strips\[0\]: missing key recording"),
        ([], r"strips: expected a non-empty list"),
        ([{"radius_m": 40, "recording": "r040.0.csv"}], r"strips\[0\].radius_m: .* looks like millimetres"),
        ([{"radius_mm": 0.05, "recording": "r050.0.csv"}], r"strips\[0\].radius_mm: .* looks like metres"),
        ([{"radius_m": 0.04, "recording": "r040.0.csv"}, {"radius_m": 0.05, "recording": "r040.0.csv"}],
         r"strips\[1\].recording: r040.0.csv is listed twice \(strips\[0\] too\)"),
        ([{"radius_m": 0.04, "recording": "flat.csv"}], r"strips\[0\].recording: flat.csv is the flat recording too"),
    ],
)
def test_manifest_errors(manifest_dir, strips, message):
    path = with_manifest(manifest_dir, {"flat": "flat.csv", "strips": strips})
    with pytest.raises(ConfigError, match=message) as info:
        Calibration.fit(path)
    assert str(path) in str(info.value)


def test_manifest_top_level_errors(manifest_dir):
    with pytest.raises(ConfigError, match=r"flat: no such recording 'flat2.csv'"):
        read_manifest(with_manifest(manifest_dir, {"flat": "flat2.csv", "strips": []}))
    with pytest.raises(ConfigError, match=r"strips: missing key"):
        read_manifest(with_manifest(manifest_dir, {"flat": "flat.csv"}))
    with pytest.raises(ConfigError, match=r"radius: unknown key; allowed: flat, strips"):
        read_manifest(with_manifest(manifest_dir, {"flat": "flat.csv", "strips": [], "radius": 1}))
    with pytest.raises(ConfigError, match=r"cannot read manifest"):
        read_manifest(manifest_dir / "nope.yaml")


def test_manifest_channel_count_and_malformed_recording(manifest_dir):
    write_recording(manifest_dir / "short.csv", np.zeros((3, 15)))
    path = with_manifest(manifest_dir, {"flat": "flat.csv", "strips": [{"radius_m": 0.04, "recording": "short.csv"}]})
    with pytest.raises(
        ConfigError, match=r"strips\[0\].recording \(short.csv\): expected 16 channels \(sensor.n_segments\), got 15"
    ):
        Calibration.fit(path)
    (manifest_dir / "broken.csv").write_text("t_s,ch1\n0.0,abc\n")
    path = with_manifest(
        manifest_dir, {"flat": "broken.csv", "strips": [{"radius_m": 0.04, "recording": "r040.0.csv"}]}
    )
    with pytest.raises(SessionError, match=r"broken.csv: line 2"):
        Calibration.fit(path)


# --- CLI ------------------------------------------------------------------------------------


def cli():
    @click.group(cls=PipelineGroup, chain=True)
    def group():
        pass

    @group.result_callback()
    def run(steps):
        run_steps(steps)

    @group.command("next-step")
    @click.option("--flag", is_flag=True)
    def next_step(flag):
        return lambda state: click.echo(f"next step ran, calibration degree {state['calibration'].degree}, {flag}")

    group.add_command(next_step, "next.yaml")  # a command name that is also an output file name
    for command in calibrate_cli.COMMANDS:
        group.add_command(command)
    return group


def test_cli_options_after_the_argument_and_chaining(tmp_path, monkeypatch):
    # click parses chained subcommands without interspersed options; calibrate allows them
    manifest = write_manifest(tmp_path, SyntheticSensor(), radii=RADII[:4])
    out = tmp_path / "cal.yaml"
    args = ["calibrate", str(manifest), "-o", str(out), "--degree", "2", "next-step", "--flag"]
    result = CliRunner().invoke(cli(), args)
    assert result.exit_code == 0, result.output
    assert "next step ran, calibration degree 2, True" in result.output
    # an option value equal to a command name is still a value
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli(), ["calibrate", "-o", "next.yaml", str(manifest)])
    assert result.exit_code == 0, result.output
    assert Calibration.load(tmp_path / "next.yaml").degree == 3


def test_cli_through_the_bendsense_command(tmp_path):
    from bendsense.cli import main

    manifest = write_manifest(tmp_path, SyntheticSensor(), radii=RADII[:4])
    out = tmp_path / "cal.yaml"
    result = CliRunner().invoke(main, ["calibrate", str(manifest), "-o", str(out), "--degree", "auto"])
    assert result.exit_code == 0, result.output
    assert Calibration.load(out).n_channels == 16


def test_cli_writes_a_calibration_that_loads(tmp_path):
    model = SyntheticSensor()
    manifest = write_manifest(tmp_path, model)
    out = tmp_path / "cal.yaml"
    runner = CliRunner()
    result = runner.invoke(cli(), ["calibrate", str(manifest), "-o", str(out), "--degree", "auto"])
    assert result.exit_code == 0, result.output
    assert "degree 3" in result.output and "CV rms" in result.output and f"wrote {out}" in result.output
    cal = Calibration.load(out)
    np.testing.assert_allclose(
        cal.coefficients_odd * U ** np.arange(4), model.coefficients(model.odd) * U ** np.arange(4), atol=1e-12
    )
    # refuses to overwrite
    before = out.read_bytes()
    result = runner.invoke(cli(), ["calibrate", str(manifest), "-o", str(out), "--degree", "2"])
    assert result.exit_code == 1 and "exists (use --overwrite" in result.output
    assert out.read_bytes() == before
    result = runner.invoke(cli(), ["calibrate", str(manifest), "-o", str(out), "--degree", "2", "--overwrite"])
    assert result.exit_code == 0 and Calibration.load(out).degree == 2


def test_cli_with_config_and_plot(tmp_path):
    model = SyntheticSensor()
    manifest = write_manifest(tmp_path, model, sleeve=SENSOR.sleeve_thickness_m)
    config = tmp_path / "config.yaml"
    data = load_config().to_dict()
    data["sensor"]["calibration_adds_sleeve"] = True
    config.write_text(yaml.safe_dump(data))
    out, fig = tmp_path / "cal.yaml", tmp_path / "fit.png"
    result = CliRunner().invoke(
        cli(), ["calibrate", str(manifest), "-o", str(out), "--config", str(config), "--plot", str(fig)]
    )
    assert result.exit_code == 0, result.output
    assert Calibration.load(out).sleeve and fig.stat().st_size > 0


def test_cli_user_errors_are_one_line(tmp_path):
    model = SyntheticSensor()
    manifest = write_manifest(tmp_path, model, radii=RADII[:2])
    result = CliRunner().invoke(cli(), ["calibrate", str(manifest), "-o", str(tmp_path / "c.yaml"), "--degree", "7"])
    assert result.exit_code == 2
    assert "Invalid value for '--degree': expected 1..5 or 'auto', got '7'" in result.output
    assert "Traceback" not in result.output
    bad = with_manifest(tmp_path, {"flat": "flat.csv", "strips": [{"radius_m": 0, "recording": "flat.csv"}]})
    result = CliRunner().invoke(cli(), ["calibrate", str(bad), "-o", str(tmp_path / "c.yaml")])
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and "strips[0].radius_m: expected > 0, got 0" in errors[0]
    assert not (tmp_path / "c.yaml").exists()


def test_two_strips_of_the_same_radius_warn(manifest_dir, caplog):
    import logging

    path = with_manifest(manifest_dir, {"flat": "flat.csv", "strips": [
        {"radius_m": 0.04, "recording": "r040.0.csv"}, {"radius_m": 0.04, "recording": "r050.0.csv"}]})
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        read_manifest(path)
    assert "strips[0] and strips[1] have the same radius 0.04 m (r040.0.csv, r050.0.csv)" in caplog.text


def test_a_session_csv_given_as_the_calibration_says_what_it_looks_like(tmp_path):
    session = Session(np.arange(3) * 0.1, np.full((3, 4), 2000.0), np.full(3, 50e3))
    write_session_csv(session, tmp_path / "run.csv")
    with pytest.raises(ConfigError, match=r"run\.csv: calibration: expected a mapping .*got 't_s,pressure_pa,ch1.*"
                                          r"\(a session CSV\? a calibration is the YAML of 'bendsense calibrate'\)"):
        Calibration.load(tmp_path / "run.csv")
