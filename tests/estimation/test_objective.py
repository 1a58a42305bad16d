"""The measurement-model objective: the beam's tangent angle at each coil against the measured S_i / d.

Shapes come from the independent forward model of the tests (scipy ``solve_bvp`` on the
DESIGN.md beam equation, exact shifts ``S_i = d φ(L_i)``), never from the library's solver.
"""

import numpy as np
import pytest
from cli.test_estimate import workdir  # noqa: F401 (the CLI session fixture)
from click.testing import CliRunner
from forward_model import forward
from helpers import curvatures_for as _kappa

import bendsense
from bendsense.cli import main
from bendsense.errors import ArgumentError, ConfigError
from bendsense.estimation import estimate_force
from bendsense.pipeline import LiveProcessor
from bendsense.results import read_results

CFG = bendsense.load_config()
SENSOR = CFG.sensor
# the truths have the config's own parameters: known exactly, no parameter_covariance (σ is the noise's alone)
KNOWN = CFG.replace(parameter_covariance=None)


def _truths(n, seed):
    """Independent frames: pressures 20–120 kPa, tip loads up to 0.25 N in every direction."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        p = rng.uniform(20e3, 120e3)
        a, r = rng.uniform(0.0, 2.0 * np.pi), 0.25 * np.sqrt(rng.uniform())
        out.append(forward(CFG, p, np.array([r * np.cos(a), r * np.sin(a)])))
    return out


@pytest.fixture(scope="module")
def truths():
    return _truths(24, seed=5)


def test_noise_free_exact_shifts_give_the_force_without_pcc_bias(truths):
    kappa = np.array([_kappa(t.shifts_m) for t in truths])
    p = np.array([t.pressure_pa for t in truths])
    force = np.array([t.force_n for t in truths])
    est = estimate_force(kappa, p, CFG, objective="angles", noise_std=1e-7)
    assert est.success.all()
    assert np.abs(est.force_n - force).max() <= 1e-4  # 0.1 mN
    # the paper's position objective on the same shapes carries the PCC model's bias
    paper = estimate_force(kappa, p, CFG, objective="positions", noise_std=1e-7)
    assert np.abs(paper.force_n - force).max() > 1e-3


def test_two_sigma_covers_the_truth_under_shift_noise(truths):
    """Shift noise of known σ (no calibration: the noise is in metres): ±2σ covers 90–98 %."""
    rng = np.random.default_rng(11)
    sigma_s = 4e-6
    kappa, p, force = [], [], []
    for t in truths:
        for _ in range(25):
            kappa.append(_kappa(t.shifts_m + sigma_s * rng.standard_normal(t.shifts_m.shape)))
            p.append(t.pressure_pa)
            force.append(t.force_n)
    est = estimate_force(np.array(kappa), np.array(p), KNOWN, objective="angles", noise_std=sigma_s)
    ok = est.success & np.isfinite(est.std_n).all(axis=-1)
    assert ok.mean() > 0.98
    z = (est.force_n - np.array(force))[ok] / est.std_n[ok]
    cover = (np.abs(z) <= 2.0).mean(axis=0)
    assert np.all((cover >= 0.90) & (cover <= 0.98)), cover
    # χ²/dof of a correct noise model is about 1
    assert 0.8 < np.nanmedian(est.chi2_per_dof[ok]) < 1.2


def test_sigma_is_the_inverse_fisher_information(truths):
    # with weights Σ_θ⁻¹ and no tip-angle constraint, Cov(F) = (JᵀΣ_θ⁻¹J)⁻¹; checked by finite
    # differences of the estimate: Cov = T Σ_S Tᵀ with T = ∂F/∂S
    t = truths[3]
    sigma_s = np.linspace(2e-6, 6e-6, 16)
    base = estimate_force(_kappa(t.shifts_m), t.pressure_pa, KNOWN, objective="angles", noise_std=sigma_s)
    h = 1e-8
    T = np.empty((2, 16))
    for i in range(16):
        up, down = t.shifts_m.copy(), t.shifts_m.copy()
        up[i] += h
        down[i] -= h
        f_up = estimate_force(_kappa(up), t.pressure_pa, KNOWN, objective="angles", noise_std=sigma_s, xtol_n=1e-13)
        f_down = estimate_force(_kappa(down), t.pressure_pa, KNOWN, objective="angles", noise_std=sigma_s,
                                xtol_n=1e-13)
        T[:, i] = (f_up.force_n - f_down.force_n) / (2 * h)
    want = T @ np.diag(sigma_s**2) @ T.T * max(1.0, float(base.chi2_per_dof))
    np.testing.assert_allclose(base.covariance_n2, want, rtol=2e-3, atol=1e-6 * np.abs(want).max())


def test_without_a_noise_model_sigma_is_not_a_number(truths):
    t = truths[0]
    est = estimate_force(_kappa(t.shifts_m), t.pressure_pa, CFG, objective="angles")
    assert est.success and est.uncertainty == "none"
    assert np.isnan(est.std_n).all()
    np.testing.assert_allclose(est.force_n, t.force_n, atol=1e-4)


def test_objective_errors_name_the_option(truths):
    t = truths[0]
    with pytest.raises(ArgumentError, match="objective: must be one of angles, positions, got 'shape'"):
        estimate_force(_kappa(t.shifts_m), t.pressure_pa, CFG, objective="shape")
    with pytest.raises(ArgumentError, match="objective: method='paper' fits the positions"):
        estimate_force(_kappa(t.shifts_m), t.pressure_pa, CFG, objective="angles", method="paper")
    points = t.shape.positions_m[None]
    with pytest.raises(ArgumentError, match="objective: 'angles' fits the coil angles"):
        estimate_force(points, t.pressure_pa, CFG, objective="angles", s_m=t.shape.s_m)
    with pytest.raises(ConfigError, match="estimation.objective"):
        bendsense.config.Config.from_dict({**CFG.to_dict(), "estimation": {"objective": "shape"}})
    # the live processor says so when it is made, not at its first frame
    with pytest.raises(ArgumentError, match="objective: must be one of angles, positions, got 'shape'"):
        LiveProcessor(_any_calibration(), CFG, objective="shape")
    with pytest.raises(ArgumentError, match="noise_std_counts: must be finite and >= 0"):
        _any_calibration().error_model(-1.0)


def _any_calibration():
    from bendsense.calibration import Calibration

    return Calibration(offset=np.zeros(16), coefficients_odd=np.array([0.0, 1e-6]),
                       coefficients_even=np.array([0.0, -1e-6]), degree=1, delta_a_range_odd=(-1e3, 1e3),
                       delta_a_range_even=(-1e3, 1e3), noise_std=np.ones(16))


def test_config_and_cli_choose_the_objective(workdir, tmp_path):  # noqa: F811
    base = ["load", str(workdir / "session.csv"), "--calibration", str(workdir / "cal.yaml"), "reconstruct",
            "estimate", "--constraint", "vertical"]
    runs = {}
    for objective in ("angles", "positions"):
        out = tmp_path / objective
        res = CliRunner().invoke(main, [*base, "--objective", objective, "save", str(out)])
        assert res.exit_code == 0, res.output
        runs[objective] = read_results(out)
    fy_true = runs["angles"]["fy_true_n"].astype(float)
    # the session's shifts are exact (S = d φ(L_i) of a beam): the angles objective recovers the load
    np.testing.assert_allclose(runs["angles"]["fy_n"], fy_true, atol=1e-4)
    assert np.abs(runs["positions"]["fy_n"] - fy_true).max() > 1e-4
    res = CliRunner().invoke(main, [*base, "--objective", "shape"])
    assert res.exit_code == 2 and "--objective" in res.output
    # process and the live processor (live, record --estimate) take the same option, default angles
    session = bendsense.read_session(workdir / "session.csv")
    cal = bendsense.Calibration.load(workdir / "cal.yaml")
    for objective in ("angles", "positions", None):
        out = tmp_path / f"process-{objective}"
        res = CliRunner().invoke(main, ["process", str(workdir / "session.csv"), "--calibration",
                                        str(workdir / "cal.yaml"), "-o", str(out), "--workers", "0",
                                        "--constraint", "vertical", "--no-progress",
                                        *(["--objective", objective] if objective else [])])
        assert res.exit_code == 0, res.output
        got = read_results(out / "session")
        np.testing.assert_allclose(got["fy_n"], runs[objective or "angles"]["fy_n"], rtol=0, atol=1e-9)
        live = LiveProcessor(cal, CFG, constraint="vertical", objective=objective)
        assert live.objective == (objective or "angles")
        block = live.process_block(session.signals[:5], session.pressure_pa[:5])
        np.testing.assert_allclose(block.force_n[:, 1], runs[objective or "angles"]["fy_n"][:5], atol=1e-6)
