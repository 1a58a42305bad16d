"""``bendsense.identify.gravity``: EI(P) and the free bending from free sweeps in two mounts, no weights.

Data the estimator did not make: the independent forward model of tests/forward_model.py
(scipy ``solve_bvp``, its own eq. 8–12, the weight along the mount's gravity) and hidden
non-polynomial sensors, each calibrated on its own. Each actuator sweeps 0 → 110 kPa → 0
upright (the config's mount, gravity −y) and hanging (+y). The true actuators are off the
config by K0 −8 % / EI +15 % and K0 +8 % / EI −15 %; noise ~3.2 mrad per coil (the
simulated board's) and ~6.6 mrad.
"""

import dataclasses
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from forward_model import HiddenSensor, free_bending_k0, free_sweep

import bendsense
from bendsense.errors import ArgumentError, SessionError
from bendsense.identify.gravity import identify_gravity
from bendsense.session import Session

# under xdist, one worker: both cases of `identified` (a module fixture of seconds) made once, not on both workers
pytestmark = pytest.mark.xdist_group("identify-gravity")
CFG = bendsense.load_config()
HANGING = (0.0, 1.0)
LEVELS = np.array([20e3, 60e3, 100e3])
# (K0 scale, EI scale) of the true actuator, and the sensor's seed and noise [counts] (~3.2 and ~6.6 mrad)
CASES = {"K0-8%/EI+15%, 3.2 mrad": (0.92, 1.15, 0, 8.0), "K0+8%/EI-15%, 6.6 mrad": (1.08, 0.85, 1, 16.5)}


def _mounted(direction):
    return CFG.replace(gravity=dataclasses.replace(CFG.gravity, direction=direction))


@pytest.fixture(scope="module")
def identified():
    """Each case of CASES: (result, K0 scale, true stiffness, the two sessions, the calibration)."""
    return [_identify(*case) for case in CASES.values()]


def _identify(k0_scale, ei_scale, seed, noise):
    truth = {"k0_scale": k0_scale, "stiffness": {"ei0_nm2": ei_scale * CFG.stiffness.ei0_nm2,
                                                  "ei1_nm2_per_pa": ei_scale * CFG.stiffness.ei1_nm2_per_pa}}
    sensor = HiddenSensor(noise_counts=noise, seed=seed)
    with tempfile.TemporaryDirectory() as tmp:
        calibration = bendsense.Calibration.fit(sensor.write_calibration(Path(tmp), CFG, frames=40, flat_frames=80))
    rng = np.random.default_rng(seed)
    sessions = []
    for config in (CFG, _mounted(HANGING)):
        p, angles = free_sweep(config, 600, **truth)
        sessions.append(Session(np.arange(p.size) / 500.0, sensor.signals(CFG.sensor.strip_gap_m * angles, rng), p))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify_gravity(sessions, CFG, calibration, turned=HANGING)
    return result, k0_scale, truth["stiffness"], sessions, calibration


@pytest.mark.parametrize("case", range(len(CASES)), ids=list(CASES))
def test_two_mounts_find_ei_and_k0_within_1_percent(identified, case):
    result, k0_scale, stiffness, _, _ = identified[case]
    ei_true = stiffness["ei0_nm2"] + stiffness["ei1_nm2_per_pa"] * LEVELS
    ei = result.config.stiffness.ei_nm2(LEVELS)
    k0_true = k0_scale * np.array([free_bending_k0(CFG, p) for p in LEVELS])
    k0 = bendsense.mechanics.actuator.FreeBendingModel.from_config(result.config).tip_curvature_per_m(LEVELS)
    assert np.all(np.abs(ei / ei_true - 1) <= 0.01), ei / ei_true - 1
    assert np.all(np.abs(k0 / k0_true - 1) <= 0.01), k0 / k0_true - 1
    prior_ei = CFG.stiffness.ei_nm2(LEVELS)
    assert np.all(np.abs(prior_ei / ei_true - 1) > 0.12)  # the config's EI was 15 % off


@pytest.mark.parametrize("case", range(len(CASES)), ids=list(CASES))
def test_the_posterior_sigma_of_ei_covers_the_truth_and_shrinks(identified, case):
    result, _, stiffness, _, _ = identified[case]
    section = result.config.parameter_covariance
    idx = [section.parameters.index(n) for n in ("ei0_nm2", "ei1_nm2_per_pa")]
    cov = section.matrix[np.ix_(idx, idx)]
    basis = np.stack([np.ones(LEVELS.size), LEVELS], axis=-1)
    sd = np.sqrt(np.einsum("ij,jk,ik->i", basis, cov, basis))
    ei_true = stiffness["ei0_nm2"] + stiffness["ei1_nm2_per_pa"] * LEVELS
    z = (result.config.stiffness.ei_nm2(LEVELS) - ei_true) / sd
    assert np.all(np.abs(z) <= 3.0), z
    prior = CFG.parameter_covariance.matrix[np.ix_(idx, idx)]
    sd_prior = np.sqrt(np.einsum("ij,jk,ik->i", basis, prior, basis))
    assert np.all(sd < 0.1 * sd_prior), sd / sd_prior
    assert result.config.parameter_covariance.source.startswith("identify gravity ")
    assert "two mounts" in result.report() and "ei0_nm2" in result.report()


def test_identify_stiffness_turned_session_writes_the_same_config(identified, tmp_path):
    from click.testing import CliRunner

    from bendsense.cli import main
    from bendsense.session import write_session_csv

    result, _, _, sessions, calibration = identified[0]
    for name, session in zip(("up.csv", "down.csv"), sessions, strict=True):
        write_session_csv(session, tmp_path / name)
    calibration.save(tmp_path / "cal.yaml")
    args = ["identify", "stiffness", "--session", str(tmp_path / "up.csv"), "--turned-session",
            str(tmp_path / "down.csv"), "--calibration", str(tmp_path / "cal.yaml"), "-o", str(tmp_path / "a.yaml")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert "gravity (two mounts)" in res.output
    written = bendsense.load_config(tmp_path / "a.yaml")
    np.testing.assert_allclose(written.stiffness.ei_nm2(LEVELS), result.config.stiffness.ei_nm2(LEVELS), rtol=1e-3)
    res = CliRunner().invoke(main, [*args[:-2], "-o", str(tmp_path / "b.yaml"), "--fix", "ei0"])
    assert res.exit_code == 2 and "--fix" in res.output and not (tmp_path / "b.yaml").exists()


def test_one_mount_twice_is_refused():
    with pytest.raises(ArgumentError, match="nearly the first mount's gravity"):
        identify_gravity([None, None], CFG, None, turned=(0.1, -1.0))
    with pytest.raises(ArgumentError, match="expected two free sweeps"):
        identify_gravity([None], CFG, None)


def test_two_sweeps_in_one_mount_are_refused_not_fitted_to_a_stiff_actuator(identified):
    # the hanging sweep given as both mounts: no difference of sag, which only an EI ~20x the prior's explains
    # (the upright one twice drives the shear modulus to its bound: refused as implausible before this check)
    _, _, _, sessions, calibration = identified[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(SessionError, match=r"the two sweeps put EI\(P\) \d+ σ of the config's prior from it .*"
                                               r"were they really two mounts"):
            identify_gravity([sessions[1], sessions[1]], CFG, calibration, turned=HANGING)
