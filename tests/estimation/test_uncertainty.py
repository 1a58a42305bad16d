"""The force's uncertainty budget (issue 12): sensor noise, calibration error, model parameters.

Truths come from the independent forward model (tests/forward_model.py: scipy
``solve_bvp`` on the DESIGN.md beam, its own free-bending solve, a hidden nonlinear
sensor), never from the library's solvers. The calibration is fitted from the hidden
sensor's recordings; the estimate is the default one (``objective="angles"``).
"""

import dataclasses

import numpy as np
import pytest
from forward_model import HiddenSensor, forward
from helpers import curvatures_for as _kappa

import bendsense
from bendsense.calibration import Calibration
from bendsense.config import ParameterCovarianceConfig
from bendsense.estimation import estimate_force
from bendsense.estimation.result import BUDGET
from bendsense.shape.pcc import reconstruct

# the truths below are made with the config's own parameters: they are known exactly, so the
# config declares no parameter_covariance (the shipped config's prior would cover an actuator
# that differs, and over-cover these; tests/estimation/test_parameter_prior.py tests it)
CFG = bendsense.load_config().replace(parameter_covariance=None)
SENSOR = CFG.sensor
SECTIONS = {"shear_modulus_pa": "material", "sensor_stiffness_nm_per_rad": "material",
            "prebend_angle_rad": "material", "ei0_nm2": "stiffness", "ei1_nm2_per_pa": "stiffness"}
# an identified covariance: 4-5 % on the moduli, 0.01 rad prebend, correlated within each fit
NAMES = tuple(SECTIONS)
STD = np.array([0.04 * 180e3, 0.05 * 1.5e-3, 0.01, 0.05 * 2.53e-3, 0.05 * 1.25e-8])
CORR = np.eye(5)
CORR[0, 1] = CORR[1, 0] = -0.3
CORR[3, 4] = CORR[4, 3] = -0.5
SIGMA_THETA = STD[:, None] * CORR * STD[None, :]


def _with(config, name, value):
    section = getattr(config, SECTIONS[name])
    return config.replace(**{SECTIONS[name]: dataclasses.replace(section, **{name: value})})


def _identified(config=CFG):
    return config.replace(parameter_covariance=ParameterCovarianceConfig(
        parameters=NAMES, covariance=tuple(tuple(row) for row in SIGMA_THETA.tolist())))


def _loads(rng, n):
    """Pressures 20–120 kPa, tip loads up to 0.25 N in every direction."""
    p = rng.uniform(20e3, 120e3, n)
    a, r = rng.uniform(0.0, 2.0 * np.pi, n), 0.25 * np.sqrt(rng.uniform(size=n))
    return p, np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


def _coverage(est, force):
    z = (est.force_n - force) / est.std_n
    return (np.abs(z) <= 2.0).mean(axis=0)


@pytest.mark.parametrize("objective", ["angles", "positions"])
def test_the_model_part_is_the_parameter_covariance_through_dF_dtheta(objective):
    """σ_model of each parameter alone is |∂F/∂θ| σ_θ, by central differences of the estimate."""
    truth = forward(CFG, 70e3, np.array([0.08, -0.12]))
    kappa = _kappa(truth.shifts_m)
    for j, name in enumerate(NAMES):
        one = CFG.replace(parameter_covariance=ParameterCovarianceConfig(parameters=(name,),
                                                                         covariance=((STD[j] ** 2,),)))
        est = estimate_force(kappa, 70e3, one, objective=objective, noise_std=1e-7, xtol_n=1e-12)
        value = getattr(getattr(CFG, SECTIONS[name]), name)
        h = 1e-4 * STD[j]
        up, down = (estimate_force(kappa, 70e3, _with(CFG, name, value + s * h), objective=objective,
                                   noise_std=1e-7, xtol_n=1e-12).force_n for s in (1, -1))
        birge = np.sqrt(max(1.0, float(est.chi2_per_dof)))  # the misfit factor scales every part
        np.testing.assert_allclose(est.budget["model"], birge * np.abs(up - down) / (2 * h) * STD[j], rtol=1e-4)


def test_the_parts_add_up_and_each_has_its_source(tmp_path):
    sensor = HiddenSensor(noise_counts=1.5)
    cal = Calibration.fit(sensor.write_calibration(tmp_path, CFG))
    rng = np.random.default_rng(2)
    p, force = _loads(rng, 8)
    shifts = np.array([forward(CFG, pi, fi).shifts_m for pi, fi in zip(p, force)])
    shape = reconstruct(sensor.signals(shifts, rng), cal, SENSOR)
    est = estimate_force(shape, p, _identified(), calibration=cal)
    assert est.success.all() and est.uncertainty == "propagated"
    parts = est.budget
    assert set(parts) == set(BUDGET) == {"noise", "calibration", "model"}
    total = sum(parts[name] ** 2 for name in BUDGET)
    np.testing.assert_allclose(total, est.std_n**2, rtol=1e-9)
    assert all(np.all(parts[name] > 0) for name in BUDGET)
    # without the identified covariance the model part is zero and the rest unchanged
    bare = estimate_force(shape, p, CFG, calibration=cal)
    assert np.all(bare.budget["model"] == 0.0)
    # (each scaled by its own misfit factor: the model part enters the χ² too)
    birge = np.sqrt(np.maximum(1.0, bare.chi2_per_dof) / np.maximum(1.0, est.chi2_per_dof))[:, None]
    np.testing.assert_allclose(bare.budget["noise"], est.budget["noise"] * birge, rtol=1e-9)
    assert np.all(bare.std_n < est.std_n)


@pytest.mark.parametrize("noise_counts", [0.25, 1.5, 4.0])
def test_two_sigma_covers_the_truth_through_a_fitted_calibration(noise_counts, tmp_path):
    """600 frames (150 loads × 4 noise draws) through the hidden sensor and a fitted calibration.

    Many independent loads: at low noise the error of a frame is mostly the calibration's,
    the same for every noise draw of one load.
    """
    sensor = HiddenSensor(noise_counts=noise_counts, seed=3)
    cal = Calibration.fit(sensor.write_calibration(tmp_path, CFG))
    rng = np.random.default_rng(int(noise_counts * 100))
    p, force = _loads(rng, 150)
    shifts = np.array([forward(CFG, pi, fi).shifts_m for pi, fi in zip(p, force)])
    signals = sensor.signals(np.repeat(shifts, 4, axis=0), rng)
    shape = reconstruct(signals, cal, SENSOR)
    est = estimate_force(shape, np.repeat(p, 4), CFG, calibration=cal)
    force = np.repeat(force, 4, axis=0)
    # a load that bends a segment backwards leaves the calibrated range (negative shifts):
    # those frames are 'extrapolated', not ok, whatever their force
    inside = ~np.asarray(shape.extrapolated)
    assert inside.mean() > 0.85 and est.success[inside].mean() >= 0.99 and np.isfinite(est.force_n).all()
    cover = _coverage(est, force)
    within = (np.abs(est.force_n - force) <= 2.0 * est.std_n)[inside].mean(axis=0)
    print(f"noise {noise_counts} counts: ±2σ coverage {cover}, in the calibrated range {within}")
    assert np.all((cover >= 0.90) & (cover <= 0.98)), cover
    # not inflated either: the errors in units of σ have an RMS near 1 where the model holds
    z = ((est.force_n - force) / est.std_n)[inside]
    assert np.all(np.abs(np.sqrt(np.mean(z**2, axis=0)) - 1.0) < 0.15)


def _identified_by_the_fits():
    """A config as ``bendsense identify`` writes it: free bending from noisy camera angles,
    then EI(P) from noisy tip positions (the data of test_identify), with its covariance."""
    from identify.test_identify import LOADS, P_FB, P_LEVELS, fb_data, loaded_shapes

    from bendsense.identify import StiffnessData, fit_free_bending, fit_stiffness

    config = fit_free_bending(P_FB, fb_data(np.random.default_rng(4)), CFG).to_config(CFG)
    p = np.repeat(P_LEVELS, len(LOADS))
    f = np.tile(LOADS, (len(P_LEVELS), 1))
    tip = loaded_shapes(p, f).tip_position_m + 0.3e-3 * np.random.default_rng(12).standard_normal((p.size, 2))
    return fit_stiffness(StiffnessData.from_tip(p, f, tip, CFG.actuator.length_m), config).to_config(config)


@pytest.mark.parametrize("source", ["stated", "identified"])
def test_two_sigma_covers_the_truth_with_parameters_drawn_from_the_identified_covariance(source):
    """Each truth's actuator is drawn from N(θ̂, Σ_θ); the estimate knows θ̂ and Σ_θ only.

    ``stated``: a covariance of the form identify writes (4–5 % on the moduli);
    ``identified``: the one the fits of free bending and stiffness wrote themselves.
    """
    config = _identified() if source == "stated" else _identified_by_the_fits()
    section = config.parameter_covariance
    assert section.parameters == NAMES
    sigma_theta = np.asarray(section.covariance, dtype=float)
    rng = np.random.default_rng(7)
    n, draws = 100, 5
    p, force = _loads(rng, n)
    thetas = rng.multivariate_normal(np.array([getattr(getattr(config, SECTIONS[k]), k) for k in NAMES]),
                                     sigma_theta, n)
    shifts = []
    for pi, fi, th in zip(p, force, thetas):
        values = dict(zip(NAMES, th))
        material = {k: v for k, v in values.items() if SECTIONS[k] == "material"}
        stiffness = {k: v for k, v in values.items() if SECTIONS[k] == "stiffness"}
        shifts.append(forward(config, pi, fi, material=material, stiffness=stiffness).shifts_m)
    sigma_s = 2e-6  # small sensor noise: the parameters dominate the error
    noisy = np.repeat(np.array(shifts), draws, axis=0)
    noisy = noisy + sigma_s * rng.standard_normal(noisy.shape)
    P, F = np.repeat(p, draws), np.repeat(force, draws, axis=0)
    est = estimate_force(_kappa(noisy), P, config, noise_std=sigma_s)
    ok = est.success | np.char.startswith(est.message.astype(str), "model_misfit")
    assert ok.all()
    cover = _coverage(est, F)
    assert np.all((cover >= 0.90) & (cover <= 0.98)), cover
    print(f"{source}: ±2σ coverage {cover}")
    # the same frames without the parameters' covariance: σ too small, the truth left out
    blind = estimate_force(_kappa(noisy), P, config.replace(parameter_covariance=None), noise_std=sigma_s)
    assert np.all(_coverage(blind, F) < 0.85)
