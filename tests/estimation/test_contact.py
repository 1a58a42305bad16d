"""Contact at an unknown location (issue 23): ``estimate_contact`` and ``estimate_force(load="contact")``.

Validated against the independent forward model of tests/forward_model.py (scipy
``solve_bvp`` split at s_c) read through hidden nonlinear sensors whose calibration is
fitted from their own noisy recordings. The Cramér–Rao bound of s_c is computed here
from central differences of that BVP at the hidden sensor (signals in counts, the
sensor's 1.5 counts of noise): no number the library printed.
"""

import importlib.util
import multiprocessing
import os
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from forward_model import HiddenSensor, forward

import bendsense
from bendsense.config import ParameterCovarianceConfig
from bendsense.errors import ArgumentError
from bendsense.estimation.contact import LR_THRESHOLD
from bendsense.results import estimate_codes
from bendsense.shape.pcc import reconstruct, shifts_to_curvatures
from bendsense.status import Status

_TOOL = Path(__file__).resolve().parents[2] / "tools" / "contact_eval.py"
_spec = importlib.util.spec_from_file_location("contact_eval", _TOOL)
ce = importlib.util.module_from_spec(_spec)
sys.modules["contact_eval"] = ce  # its dataclasses look their module up
_spec.loader.exec_module(ce)

CFG = bendsense.load_config()
BARE = CFG.replace(parameter_covariance=None)  # the actuator is the config's (identified): no parameter prior
L = CFG.actuator.length_m
GAP = CFG.sensor.strip_gap_m
NOISE_M = 1e-7  # shift noise [m] without a calibration (0.1 mrad of coil angle)


def _kappa(config, angles):
    """Segment curvatures (…, N) of exact coil angles."""
    return shifts_to_curvatures(GAP * np.asarray(angles), config.sensor.lengths_m, GAP)


def _normal_force(pressure_pa, s_c, magnitude):
    """A force of ``magnitude`` normal to the free arc's tangent at ``s_c``, pushing outward."""
    from forward_model import free_bending_k0

    phi = free_bending_k0(CFG, pressure_pa) * s_c
    return magnitude * np.array([-np.cos(phi), np.sin(phi)])


def _quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **k)


# --------------------------------------------------------------------------- exact data


@pytest.mark.parametrize("s_frac", [0.65, 0.8, 0.9])
def test_exact_shifts_locate_the_contact_and_its_force(s_frac):
    P, sc = 60e3, s_frac * L
    F = _normal_force(P, sc, 0.2)
    truth = forward(BARE, P, F, contact_s_m=sc)
    kappa = np.tile(_kappa(BARE, truth.angles_rad), (20, 1))
    est = _quiet(bendsense.estimate_contact, kappa, P, BARE, noise_std=NOISE_M, t_s=np.arange(20) / 2000.0)
    assert est.load == "contact"
    assert np.all(np.abs(est.contact_s_m - sc) < 2e-4), (est.contact_s_m[0], sc)
    assert np.all(np.abs(est.force_n - F) < 1e-3), (est.force_n[0], F)
    assert np.all(np.isfinite(est.contact_std_m)) and np.all(est.contact_std_m > 0)


def test_exact_tip_load_keeps_the_tip_model():
    P, F = 60e3, np.array([-0.15, 0.05])
    truth = forward(BARE, P, F)
    kappa = np.tile(_kappa(BARE, truth.angles_rad), (20, 1))
    est = _quiet(bendsense.estimate_contact, kappa, P, BARE, noise_std=NOISE_M, t_s=np.arange(20) / 2000.0)
    assert np.all(np.isnan(est.contact_s_m)) and np.all(np.isnan(est.contact_std_m))
    tip = _quiet(bendsense.estimate_force, kappa, P, BARE, noise_std=NOISE_M)
    np.testing.assert_allclose(est.force_n, tip.force_n, atol=1e-9)  # the tip model's estimate, frame by frame
    assert np.all(np.abs(est.force_n - F) < 1e-3)


def test_windows_follow_the_window_test_and_share_one_location():
    P = np.r_[np.full(150, 50e3), np.full(150, 80e3)]  # a pressure step at frame 150
    F = [_normal_force(p, 0.8 * L, 0.2) for p in (50e3, 80e3)]
    angles = [forward(BARE, p, f, contact_s_m=0.8 * L).angles_rad for p, f in zip((50e3, 80e3), F)]
    kappa = np.repeat(_kappa(BARE, np.array(angles)), 150, axis=0)
    t = np.arange(300) / 2000.0
    est = _quiet(bendsense.estimate_contact, kappa, P, BARE, noise_std=NOISE_M, t_s=t)
    # 50 ms windows cut at the step; a remainder under half a window (24.5 ms) joins its segment's previous window
    bounds = [0, 150, 300]
    for a, b in zip(bounds[:-1], bounds[1:]):
        assert np.unique(est.contact_s_m[a:b]).size == 1
    assert est.contact_s_m[149] != est.contact_s_m[150]  # two fits (equal to round-off only: the same s_c)
    np.testing.assert_allclose(est.contact_s_m, 0.8 * L, atol=2e-4)


# --------------------------------------------------------------------------- unresolved


def test_force_along_the_tangent_is_unresolved():
    P, sc = 60e3, 0.8 * L
    from forward_model import free_bending_k0

    phi = free_bending_k0(CFG, P) * sc
    F = -0.2 * np.array([np.sin(phi), np.cos(phi)])  # along the tangent, toward the base
    F = F + 0.03 * np.array([-np.cos(phi), np.sin(phi)])  # 8.5° off it
    truth = forward(BARE, P, F, contact_s_m=sc)
    kappa = np.tile(_kappa(BARE, truth.angles_rad), (100, 1))
    est = _quiet(bendsense.estimate_contact, kappa, P, BARE, noise_std=1e-6, t_s=np.arange(100) / 2000.0)
    assert np.all(np.isinf(est.contact_std_m) | np.isnan(est.contact_s_m))
    if np.isfinite(est.contact_s_m).any():
        assert set(estimate_codes(est, 100)) == {Status.CONTACT_UNRESOLVED}
        assert "tangent" in str(est.message[0]) or "σ(s_c)" in str(est.message[0])


@pytest.mark.parametrize("counts", [1.5, 15.0])
def test_one_frame_never_a_confident_wrong_location(counts):
    """``estimate_force(load="contact", contact_s_m=None)``: the window of one frame, honestly.

    At the hidden sensors' 1.5 counts one frame places a 0.15 N contact to ~1 mm (the
    Cramér–Rao bound below is ~0.5–1.3 mm); at 15 counts (~1 1/m per segment, the noise
    the issue's bound assumed) σ(s_c) exceeds a segment: mostly ``contact_unresolved``.
    """
    sensor, cal = ce.calibration(CFG, 0, 1.5)
    noisy = HiddenSensor(noise_counts=counts, seed=0)  # the same sensor, more noise
    rng = np.random.default_rng(3)
    P = rng.uniform(40e3, 100e3, 40)
    sc = rng.uniform(0.6, 0.9, 40) * L
    angles = np.array([forward(CFG, p, _normal_force(p, s, 0.15), contact_s_m=s).angles_rad for p, s in zip(P, sc)])
    shape = reconstruct(noisy.signals(GAP * angles, rng), cal, CFG.sensor)
    est = _quiet(bendsense.estimate_force, shape, P, BARE, load="contact", calibration=cal, noise_std=counts)
    assert est.load == "contact" and est.contact_s_m.shape == (40,)
    located = np.isfinite(est.contact_std_m)
    z = np.abs(est.contact_s_m - sc)[located] / est.contact_std_m[located]
    assert np.all(z <= 3.5) and np.mean(z <= 2.0) >= 0.85, np.sort(z)
    unresolved = estimate_codes(est, 40) == Status.CONTACT_UNRESOLVED
    assert np.array_equal(unresolved, np.isinf(est.contact_std_m))
    if counts > 10:
        assert np.mean(located) < 0.5, np.mean(located)
    else:
        assert np.mean(located) > 0.9, np.mean(located)
    one = _quiet(bendsense.estimate_force, shape.curvature_per_m[0], P[0], BARE, load="contact", calibration=cal,
                 noise_std=counts)
    assert one.batch_shape == () and one.load == "contact"
    assert one.contact_s_m == est.contact_s_m[0]


def test_bad_arguments_name_the_argument():
    with pytest.raises(ArgumentError, match="^shape"):
        bendsense.estimate_contact(np.zeros((3, 5)), 50e3, BARE, noise_std=NOISE_M)
    with pytest.raises(ArgumentError, match="^t_s"):
        bendsense.estimate_contact(np.zeros((3, 16)), 50e3, BARE, noise_std=NOISE_M, t_s=[0, 1])
    with pytest.raises(ArgumentError, match="^threshold"):
        bendsense.estimate_contact(np.zeros((3, 16)), 50e3, BARE, noise_std=NOISE_M, threshold=-1)
    with pytest.raises(ArgumentError, match="^contact_s_m: not an option"):
        bendsense.estimate_contact(np.zeros((3, 16)), 50e3, BARE, noise_std=NOISE_M, contact_s_m=0.1)
    with pytest.raises(ArgumentError, match="^noise_std"):  # no noise model: no location
        _quiet(bendsense.estimate_contact, np.full((3, 16), 5.0), 50e3, BARE, noise_std=0.0)
    with pytest.raises(ArgumentError, match="^window_s"):
        bendsense.estimate_contact(np.zeros((3, 16)), 50e3, BARE, noise_std=NOISE_M, t_s=[0, 1, 2], window_s=0)
    with pytest.raises(ArgumentError, match="^shape: no frames"):  # as estimate_force (an IndexError once)
        bendsense.estimate_contact(np.zeros((0, 16)), np.zeros(0), BARE, noise_std=NOISE_M, t_s=np.zeros(0))


# --------------------------------------------------------------------------- the Cramér–Rao bound


def _crb_s(sensor, P, F, sc, frames):
    """σ(s_c) of the Cramér–Rao bound: Fisher of (Fx, Fy, s_c) from central differences of the BVP's signals."""
    def signals(theta):
        t = forward(CFG, P, theta[:2], contact_s_m=theta[2])
        return sensor.delta(GAP * t.angles_rad)

    theta = np.array([F[0], F[1], sc])
    steps = np.array([2e-3, 2e-3, 5e-4])
    J = np.empty((sensor.n_channels, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = steps[j]
        J[:, j] = (signals(theta + d) - signals(theta - d)) / (2 * steps[j])
    fisher = frames * J.T @ J / sensor.noise_counts**2
    return float(np.sqrt(np.linalg.inv(fisher)[2, 2]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sigma_of_the_location_against_the_cramer_rao_bound(seed):
    """σ(s_c)'s sensor-noise part is the Cramér–Rao bound of the hidden sensor's noise for one frame, and above it
    over a window of 100; the whole σ never falls below the bound and keeps the calibration's floor."""
    sensor, cal = ce.calibration(CFG, seed, 1.5)
    P, sc = 70e3, 0.85 * L
    F = _normal_force(P, sc, 0.25)
    truth = forward(CFG, P, F, contact_s_m=sc)
    noise_free = HiddenSensor(noise_counts=0.0, seed=seed)
    shape = reconstruct(noise_free.signals(GAP * truth.angles_rad), cal, CFG.sensor)
    kappa = shape.curvature_per_m
    one = _quiet(bendsense.estimate_force, kappa, P, BARE, load="contact", calibration=cal)
    crb1 = _crb_s(sensor, P, F, sc, 1)
    sigma1 = _quiet(_sigma_unclipped, kappa[None], P, cal, 1)
    noise1 = _quiet(_sigma_unclipped, kappa[None], P, cal, 1, part=0)
    # the sensor-noise part is the bound (up to the fitted calibration's slopes and its estimate of the noise)
    assert 0.85 * crb1 <= noise1 <= 1.15 * crb1, (noise1, crb1)
    # the whole σ adds the calibration's part (~0.3 mm here): above the bound, never below it
    assert crb1 <= sigma1 <= 1.7 * crb1, (sigma1, crb1)
    assert abs(float(one.contact_std_m) - sigma1) <= 0.05 * sigma1  # the estimate reports it (at its own ŝ)
    crb100 = _crb_s(sensor, P, F, sc, 100)
    noise100 = _quiet(_sigma_unclipped, np.tile(kappa, (100, 1)), P, cal, 100, part=0)
    sigma100 = _quiet(_sigma_unclipped, np.tile(kappa, (100, 1)), P, cal, 100)
    # over a window the fit weighs the calibration's shared part too, so its noise part sits above the noise-only
    # bound (the price of not trusting the calibration), never below it
    assert 0.85 * crb100 <= noise100 < noise1 / 3, (noise100, crb100)
    assert sigma100 >= 3 * crb100, (sigma100, crb100)  # the calibration's part does not: σ stays at its floor


def _sigma_unclipped(kappa, P, cal, frames, part=None):
    """σ(s_c) of the window's fit (or its sensor-noise part, ``part=0``), whether or not it is beyond a segment."""
    from bendsense.estimation import contact

    est = bendsense.estimate_force(kappa[:1], P, BARE, load="contact", contact_s_m=np.array([0.85 * L]),
                                   calibration=cal)
    T, er, ee, parts, _ = contact._metric(est, np.array([frames]))
    return float(1.0 / np.sqrt(ee[0]) if part is None else np.sqrt(parts[0, part]) / ee[0])


# --------------------------------------------------------------------------- DESIGN section 5, a small sample


@pytest.fixture(scope="module")
def evaluation():
    # 64 contact holds (256 windows), 64 tip holds. Run alone, the sensors on both cores; under pytest-xdist the
    # other worker has the other core, and two more interpreters would only add their start and kernel loads
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return ce.run(CFG, range(16), 8, use_cache=False)[0]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        scores, _ = ce.run(CFG, range(16), 8, use_cache=False, executor=pool)
    return scores


def test_contact_targets_on_a_small_sample(evaluation):
    """The section 5 rows (tools/contact_eval.py prints them on a larger sample)."""
    s = evaluation
    assert s["contact_windows"] >= 200 and s["tip_windows"] >= 200
    assert s["median_error_m"] <= 8e-3, s
    assert s["s_coverage"] >= 0.85, s
    assert np.all(s["force_coverage"] >= 0.85), s
    assert s["tip_kept"] >= 0.90, s


def test_threshold_is_the_stated_mixture_quantile():
    from scipy import stats

    assert abs(0.5 * stats.chi2.sf(LR_THRESHOLD, 1) - 0.01) < 1e-4


def test_budget_on_exact_shapes_with_gaussian_noise():
    """Shift noise only (no calibration, no parameters): σ(s_c) and the force's σ (with the location's part and its
    covariance with ŝ) are the spread of the errors over independent windows."""
    rng = np.random.default_rng(0)
    sigma_m, n = 2e-6, 100
    zs, zf = [], []
    for P, frac in [(90e3, 0.8), (50e3, 0.7), (70e3, 0.9)]:
        sc = frac * L
        F = _normal_force(P, sc, 0.2)
        truth = forward(BARE, P, F, contact_s_m=sc)
        W = 40
        kappa = _kappa(BARE, truth.angles_rad + sigma_m / GAP * rng.standard_normal((W * n, 16)))
        est = _quiet(bendsense.estimate_contact, kappa, P, BARE, noise_std=sigma_m, t_s=np.arange(W * n) / 2000.0)
        zs.append((est.contact_s_m[::n] - sc) / est.contact_std_m[::n])
        zf.append((est.force_n - F) / est.std_n)
    zs, zf = np.concatenate(zs), np.concatenate(zf)
    assert 0.8 <= np.std(zs) <= 1.2, np.std(zs)
    assert np.all((0.8 <= np.std(zf, axis=0)) & (np.std(zf, axis=0) <= 1.2)), np.std(zf, axis=0)


# --------------------------------------------------------------------------- honest model choice (issue 31)


def test_a_window_that_cannot_decide_covers_every_hypothesis():
    """Contacts at 0.3–0.45 L of 0.02–0.1 N, location unknown, 6.6 mrad per coil, an identified actuator.

    Where a window's data cannot tell a contact near the base from a tip load, the old
    estimate kept the tip model and its narrow σ: of such holds (8 sensors × 4), 25 %
    kept the tip, Fy was covered 61 % and 10 % of the frames were ``ok`` and beyond 3σ.
    The force and σ now cover the mixture of the hypotheses the window allows. Four
    sensors, each calibrated on its own; five 100-frame contact holds and two tip holds
    each (one window per hold); the truth from the independent ``solve_bvp`` beam.
    """
    counts = 6.6e-3 * GAP / HiddenSensor.s0_m * np.sqrt(HiddenSensor.gain_odd * HiddenSensor.gain_even)
    sd = np.array([0.01 * CFG.material.shear_modulus_pa, 0.02 * CFG.stiffness.ei0_nm2,
                   0.02 * CFG.stiffness.ei1_nm2_per_pa])
    identified = CFG.replace(parameter_covariance=ParameterCovarianceConfig(  # an identification's: 1 % on μ̄, 2 % on EI
        parameters=("shear_modulus_pa", "ei0_nm2", "ei1_nm2_per_pa"), covariance=tuple(map(tuple, np.diag(sd**2)))))
    n = 100
    zs, oks, tip_kept, tip_sigma = [], [], [], []
    for seed in range(4):
        sensor, cal = ce.calibration(CFG, seed, counts)
        rng = np.random.default_rng(310 + seed)
        P = rng.uniform(30e3, 110e3, 7)
        sc = np.append(rng.uniform(0.3, 0.45, 5) * L, [L, L])
        F = [_normal_force(p, s, m) for p, s, m in zip(P[:5], sc, rng.uniform(0.02, 0.1, 5))]
        F += [0.2 * np.array([np.cos(a), np.sin(a)]) * rng.uniform(0.1, 1.0) for a in rng.uniform(0, 2 * np.pi, 2)]
        angles = np.array([forward(CFG, p, f, contact_s_m=s, tol=1e-7).angles_rad for p, f, s in zip(P, F, sc)])
        shape = reconstruct(sensor.signals(GAP * np.repeat(angles, n, axis=0), rng), cal, CFG.sensor)
        est = _quiet(bendsense.estimate_contact, shape, np.repeat(P, n), identified, calibration=cal,
                     t_s=np.arange(7 * n) / 2000.0)
        z = np.abs(est.force_n - np.repeat(F, n, axis=0)) / est.std_n
        zs.append(z[:5 * n])
        oks.append(estimate_codes(est, 7 * n)[:5 * n] == Status.OK)
        tip_kept.append(np.isnan(est.contact_s_m[:5 * n:n]))
        tip = _quiet(bendsense.estimate_force, shape.curvature_per_m[5 * n:], np.repeat(P[5:], n), identified,
                     calibration=cal)
        tip_sigma.append(np.hypot(*est.std_n[5 * n:].T) / np.hypot(*tip.std_n.T))
    z, ok = np.concatenate(zs), np.concatenate(oks)
    cover, silent = np.mean(np.where(np.isfinite(z), z, np.inf) <= 2.0, axis=0), np.mean(ok & np.any(z > 3.0, axis=1))
    print(f"contacts at 0.3-0.45 L: {100 * np.mean(tip_kept):.0f} % of windows keep the tip model; coverage {cover}, "
          f"{100 * silent:.1f} % silent; tip holds' σ / the tip model's: median {np.median(tip_sigma):.2f}")
    assert np.any(np.concatenate(tip_kept))  # some windows cannot decide: the case this test is about
    assert np.all(cover >= 0.85), cover
    assert silent <= 0.02, silent
    # a tip load the data decide keeps (nearly) the tip model's σ: the mixture adds only what the data allow
    assert np.median(tip_sigma) <= 1.3, np.median(tip_sigma)
