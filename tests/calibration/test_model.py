"""The calibration's measurement model: slopes, inverse, angles S/d and their covariance."""

import dataclasses

import numpy as np
import pytest
import yaml

from bendsense.calibration import AngleCovariance, Calibration
from bendsense.errors import ConfigError
from calibration.test_calibration import DATA, ODD, RADII, SENSOR, SyntheticSensor

D = SENSOR.strip_gap_m
L_CUM = np.cumsum(SENSOR.lengths_m)


def fitted(noise=0.0, seed=0, radii=RADII, flat_frames=50, strip_frames=20, sensor=SENSOR, **kwargs):
    model = SyntheticSensor(sensor=sensor)
    rng = np.random.default_rng(seed)
    flat = model.signals(0.0, flat_frames, noise, rng)
    strips = [model.signals(1 / r, strip_frames, noise, rng) for r in radii]
    return model, Calibration.from_data(flat, strips, radii, sensor, **kwargs)


def test_shift_slopes_are_the_derivative_of_the_shifts():
    model, cal = fitted()
    signals = model.signals(1 / 0.065, 1)[0]
    h = 1e-3
    numeric = np.array(
        [(cal.shifts_m(signals + h * e) - cal.shifts_m(signals - h * e))[i] / (2 * h) for i, e in enumerate(np.eye(16))]
    )
    np.testing.assert_allclose(cal.shift_slopes(signals), numeric, rtol=1e-8)
    # the synthetic sensor's own slope: dS/dΔA = scale/U (1 + 2 a u + 3 b u²)
    u = (signals - model.offset) / 1000.0
    p = np.where(ODD[:, None], np.array(model.odd)[None, :], np.array(model.even)[None, :])
    exact = p[:, 0] / 1000.0 * (1 + 2 * p[:, 1] * u + 3 * p[:, 2] * u**2)
    np.testing.assert_allclose(cal.shift_slopes(signals), exact, rtol=1e-9)
    assert cal.shift_slopes(np.tile(signals, (3, 2, 1))).shape == (3, 2, 16)


def test_signals_from_shifts_inverts_the_calibration():
    model, cal = fitted()
    kappa = np.linspace(-5.0, 26.0, 40)
    signals = np.stack([model.signals(k, 1)[0] for k in kappa])
    shifts = cal.shifts_m(signals)
    np.testing.assert_allclose(cal.signals_from_shifts(shifts), signals, rtol=0, atol=1e-8)
    np.testing.assert_allclose(cal.delta_from_shifts(shifts), signals - cal.offset, rtol=0, atol=1e-8)
    # a shift the polynomial never reaches has no inverse: NaN, not a wrong number
    quadratic = dataclasses.replace(
        cal, degree=2, coefficients_odd=[0.0, 1e-6, -1e-9], coefficients_even=[0.0, -1e-6, -1e-9]
    )
    out = quadratic.delta_from_shifts(np.full(16, 1.0e-3))  # max of 1e-6 x − 1e-9 x² is 2.5e-4
    assert np.all(np.isnan(out))
    assert np.isnan(cal.delta_from_shifts(np.full(16, np.nan))).all()


@pytest.mark.parametrize("sleeve", [False, True])
def test_angles_are_the_tangent_angles_of_the_strip(sleeve):
    model = SyntheticSensor()
    extra = SENSOR.sleeve_thickness_m if sleeve else 0.0
    rng = np.random.default_rng(3)
    # the synthetic strips are recorded with the convention's curvature, 1/(R + c) or 1/R
    strips = [model.signals(1 / (r + extra), 5) for r in RADII]
    cal = Calibration.from_data(model.signals(0.0, 5), strips, RADII, SENSOR, sleeve=sleeve)
    r_test = 0.055
    signals = model.signals(1 / (r_test + extra), 2, 0.0, rng)
    np.testing.assert_allclose(cal.angles_rad(signals), np.tile(L_CUM / (r_test + extra), (2, 1)), rtol=1e-9)


def test_angles_use_the_calibrations_own_strip_gap():
    # a sensor with a 1.3 mm gap calibrated under that config: S = κ (1.3 mm) L_i,
    # so S / d_cal is the angle whatever gap the estimate's config states
    wide = dataclasses.replace(SENSOR, strip_gap_m=1.3e-3)
    model, cal = fitted(sensor=wide)
    signals = model.signals(1 / 0.07, 1)[0]
    want = L_CUM / 0.07
    np.testing.assert_allclose(cal.angles_rad(signals), want, rtol=1e-9)
    np.testing.assert_allclose(cal.angles_rad(signals, SENSOR), want, rtol=1e-9)
    assert cal.strip_gap_m(SENSOR) == 1.3e-3
    short = dataclasses.replace(SENSOR, segment_lengths_m=(0.009,) * 16)
    with pytest.raises(ConfigError, match=r"sensor.segment_lengths_m: .* differ from the calibration's"):
        cal.angles_rad(signals, short)
    bare = dataclasses.replace(cal, sensor=None)
    with pytest.raises(ConfigError, match=r"calibration: sensor is missing"):
        bare.angles_rad(signals)
    np.testing.assert_allclose(bare.angles_rad(signals, wide), want, rtol=1e-9)


def test_noise_part_is_the_slope_times_the_flat_noise():
    model, cal = fitted(noise=1.5, seed=4)
    signals = model.signals(1 / 0.08, 3, 1.5, np.random.default_rng(5))
    cov = cal.angle_covariance(signals)
    assert isinstance(cov, AngleCovariance) and cov.noise.shape == (3, 16, 16) == cov.calibration.shape
    sd = np.abs(cal.shift_slopes(signals)) * cal.noise_std_counts() / D
    np.testing.assert_allclose(np.sqrt(np.diagonal(cov.noise, axis1=-2, axis2=-1)), sd, rtol=1e-12)
    off = cov.noise - np.eye(16) * cov.noise
    assert np.all(off == 0)
    np.testing.assert_allclose(cov.total, cov.noise + cov.calibration)
    np.testing.assert_allclose(cov.std_rad**2, np.diagonal(cov.total, axis1=-2, axis2=-1))
    # flat noise is the flat recording's per-channel standard deviation
    np.testing.assert_allclose(cal.noise_std_counts(), 1.5, rtol=0.3)
    for c in cov.calibration:
        assert np.allclose(c, c.T) and np.linalg.eigvalsh(c).min() > -1e-12 * np.abs(c).max()


@pytest.mark.slow
def test_coefficient_covariance_matches_refits_with_fresh_noise():
    """Monte Carlo: refit with new noise; the spread of coefficients, offsets and shifts."""
    radii = RADII[:6]
    noise = 2.0
    fits = [fitted(noise, seed=s, radii=radii)[1] for s in range(300)]
    truth = fits[0]
    # the covariance at the true noise level (each fit's own estimate scatters ~10 %)
    ref = dataclasses.replace(truth, noise_std=np.full(16, noise)).coefficient_covariance
    vec = np.array([np.concatenate([c.coefficients_odd, c.coefficients_even, c.offset]) for c in fits])
    emp = np.cov(vec.T)
    ratio = np.sqrt(np.diag(ref) / np.diag(emp))
    assert np.all(np.abs(ratio - 1) < 0.25), ratio  # 300 samples: sd of a sd ~4 %
    # the shift error of one exact frame, from the coefficients and offsets alone
    model = SyntheticSensor()
    signals = model.signals(1 / 0.055, 1)[0]
    exact = L_CUM * D / 0.055
    err = np.array([c.shifts_m(signals) - exact for c in fits])
    cal0 = dataclasses.replace(truth, noise_std=np.full(16, noise))
    part = cal0.angle_covariance(signals).calibration * D**2
    part -= cal0.shift_error_m(cal0.shifts_m(signals), covariance=True)  # leave the misfit term out
    np.testing.assert_allclose(np.sqrt(np.diag(part)), np.sqrt(np.diag(np.cov(err.T))), rtol=0.2)
    # odd channels share f_odd's coefficients: correlated; odd and even are independent
    corr = part / np.sqrt(np.outer(np.diag(part), np.diag(part)))
    emp_corr = np.corrcoef(err.T)
    odd_pairs = np.ix_(np.flatnonzero(ODD), np.flatnonzero(ODD))
    assert np.abs(corr[odd_pairs] - emp_corr[odd_pairs]).max() < 0.25
    assert np.all(part[np.ix_(ODD, ~ODD)] == 0)
    assert np.abs(emp_corr[np.ix_(ODD, ~ODD)]).max() < 0.25


def test_covariance_uses_the_fits_own_least_squares_operator():
    # the operator behind coefficient_covariance reproduces the stored coefficients
    # from the stored labels, for both weightings
    from bendsense.calibration import parity_masks

    for weighting in ("none", "shift"):
        _, cal = fitted(noise=0.5, seed=2, weighting=weighting)
        for mask, coef in zip(parity_masks(16), (cal.coefficients_odd, cal.coefficients_even), strict=True):
            keep, op = cal._fit_operator(mask)
            got = op @ cal.fit_shifts_m[:, mask].ravel()[keep]
            np.testing.assert_allclose(got * 1000.0 ** np.arange(4), coef * 1000.0 ** np.arange(4), atol=1e-13)
        q = cal.coefficient_covariance
        assert q.shape == (2 * 4 + 16,) * 2
        assert np.allclose(q, q.T) and np.linalg.eigvalsh(q).min() > -1e-9 * np.abs(q).max()


@pytest.mark.slow
def test_saved_calibration_keeps_the_model(tmp_path):
    model, cal = fitted(noise=1.0, seed=7)
    path = tmp_path / "cal.yaml"
    cal.save(path)
    back = Calibration.load(path)
    signals = model.signals(1 / 0.06, 2, 1.0, np.random.default_rng(8))
    a, b = cal.angle_covariance(signals), back.angle_covariance(signals)
    np.testing.assert_allclose(b.noise, a.noise, rtol=1e-12)
    np.testing.assert_allclose(b.calibration, a.calibration, rtol=1e-9, atol=1e-20)
    np.testing.assert_array_equal(back.angles_rad(signals), cal.angles_rad(signals))


def test_old_files_load_and_say_what_is_missing(tmp_path):
    legacy = Calibration.load(DATA / "calibration_v1.yaml")
    signals = np.array(legacy.offset) + np.where(ODD, 100.0, -100.0)
    expected = np.where(ODD, 1e-6 * 100 + 1e-10 * 100**2, -1e-6 * -100 + 2e-10 * 100**2) / D
    np.testing.assert_allclose(legacy.angles_rad(signals), expected, rtol=1e-14)
    np.testing.assert_allclose(legacy.noise_std_counts(), 0.5)
    with pytest.raises(ConfigError, match=r"calibration: fit_delta_a, fit_shifts_m are missing"):
        legacy.angle_covariance(signals)
    # a file without noise_std: loads, but the noise is missing, not zero
    data = yaml.safe_load((DATA / "calibration_v1.yaml").read_text())
    del data["noise_std"]
    path = tmp_path / "no_noise.yaml"
    path.write_text(yaml.safe_dump(data))
    cal = Calibration.load(path)
    assert not cal.noise_known
    with pytest.raises(ConfigError, match=r"calibration: noise_std is missing"):
        cal.noise_std_counts()
    with pytest.raises(ConfigError, match=r"noise_std is missing"):
        cal.angle_covariance(signals)
    cal.save(tmp_path / "again.yaml")
    assert yaml.safe_load((tmp_path / "again.yaml").read_text())["noise_std"] is None
    assert not Calibration.load(tmp_path / "again.yaml").noise_known
    # a one-frame flat cannot measure noise
    model = SyntheticSensor()
    one = Calibration.from_data(model.signals(0.0, 1), [model.signals(1 / r, 3) for r in RADII], RADII, SENSOR)
    assert not one.noise_known
    assert "flat noise std (mean over channels): not measured" in one.report()


def test_shift_covariance_is_the_delta_method_written_out():
    # Σ_S = L Q Lᵀ (the coefficients' and offsets' covariance through ∂S/∂(a, b, A0)) + the misfit
    # envelopes' correlated part + the noise through the slope, each term built here with numpy
    from bendsense.calibration._kernels import shift_covariance

    model, cal = fitted(noise=1.5, seed=6)
    signals = model.signals(1 / 0.07, 1, 1.5, np.random.default_rng(7))[0]
    m = cal.error_model()
    S = cal.shifts_m(signals[None])[0]
    x = signals - cal.offset
    slope = cal.shift_slopes(signals[None])[0]
    k, n = m.coef.shape[1], S.size
    L = np.zeros((n, 2 * k + n))
    for i in range(n):
        block = 0 if m.odd[i] else k
        L[i, block:block + k] = x[i] ** np.arange(k)
        L[i, 2 * k + i] = -slope[i]
    err = np.array([np.interp(abs(s), m.grid_m, m.sigma_odd_m if odd else m.sigma_even_m) for s, odd in zip(S, m.odd)])
    d = (S[:, None] - S[None, :]) / m.length_m
    misfit = np.outer(err, err) * np.exp(-0.5 * d**2) * np.where(np.eye(n, dtype=bool), 1.0, m.parity)
    expected = L @ m.coef_cov @ L.T + misfit + np.diag((slope * m.noise_std) ** 2)
    assert m.length_m > 0 and np.any(m.coef_cov) and np.any(err)  # every term is there
    out, noise = np.empty((n, n)), np.empty(n)
    trace = shift_covariance(m, S, out, noise)
    np.testing.assert_allclose(out, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(noise, (slope * m.noise_std) ** 2, rtol=1e-9)
    assert trace == pytest.approx(np.trace(expected), rel=1e-12)
