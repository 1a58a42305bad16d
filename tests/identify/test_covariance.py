"""``identify`` writes the covariance of the identified parameters into the config it produces."""

import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.cli import main
from bendsense.config import MODEL_PARAMETERS
from bendsense.identify import StiffnessData, fit_free_bending, fit_stiffness
from identify.test_identify import CFG, LOADS, P_FB, P_LEVELS, TRUE_FB, L, fb_data, loaded_shapes, write_fb_csv


@pytest.fixture(scope="module")
def tips():
    p = np.repeat(P_LEVELS, len(LOADS))
    f = np.tile(LOADS, (len(P_LEVELS), 1))
    return p, f, loaded_shapes(p, f).tip_position_m


def test_free_bending_covariance_matches_the_scatter_of_refits():
    rng = np.random.default_rng(21)
    est, covs = [], []
    for _ in range(40):
        fit = fit_free_bending(P_FB, fb_data(rng), CFG)
        est.append([fit.params[n] for n in MODEL_PARAMETERS[:3]])
        covs.append(fit.covariance)
    reported = np.mean(covs, axis=0)
    empirical = np.cov(np.array(est).T)
    sd_r, sd_e = np.sqrt(np.diag(reported)), np.sqrt(np.diag(empirical))
    np.testing.assert_allclose(sd_r / sd_e, 1.0, atol=0.35)
    # the correlations too (μ̄ and μ_s strongly anticorrelated)
    corr_r = reported / np.outer(sd_r, sd_r)
    corr_e = empirical / np.outer(sd_e, sd_e)
    assert np.abs(corr_r - corr_e).max() < 0.15
    assert corr_r[0, 1] < -0.9


def test_free_bending_block_in_the_config():
    fit = fit_free_bending(P_FB, fb_data(np.random.default_rng(3)), CFG, fix=["prebend_angle_rad"])
    new = fit.to_config(CFG.replace(parameter_covariance=None))
    section = new.parameter_covariance
    assert section.parameters == MODEL_PARAMETERS[:3]
    c = section.matrix
    assert c[2, 2] == 0 and np.all(c[2] == 0)  # fixed: exact
    assert c[0, 0] == pytest.approx(fit.stderr["shear_modulus_pa"] ** 2, rel=1e-12)
    assert "identify free-bending" in section.source
    # the config it gives validates and round-trips
    assert bendsense.config.Config.from_dict(new.to_dict()) == new
    # from the shipped config: the stiffness block stays its prior (not fitted yet), named as such
    prior = CFG.parameter_covariance
    section = fit.to_config(CFG).parameter_covariance
    assert section.parameters == MODEL_PARAMETERS
    np.testing.assert_array_equal(section.matrix[:3, :3], c)
    np.testing.assert_array_equal(section.matrix[3:, 3:], prior.matrix[3:, 3:])
    assert np.all(section.matrix[:3, 3:] == 0)
    assert section.source.startswith("identify free-bending,") and "identify stiffness" not in section.source
    kept = "ei0_nm2, ei1_nm2_per_pa kept from the config's prior (prior for an actuator not identified"
    assert kept in section.source


def test_not_identifiable_is_not_written():
    # two points for three parameters cannot identify them: no covariance written, the config's own block stays
    # (dropping it would make the parameters exact: a config without a parameter's variance takes it as truth)
    few = fit_free_bending(P_FB[:4], fb_data()[:4] + [0.001, -0.002, 0.001, 0.0], CFG)
    known = CFG.replace(parameter_covariance=None)
    with_old = fit_free_bending(P_FB, fb_data(np.random.default_rng(2)), CFG).to_config(known)
    assert with_old.parameter_covariance is not None
    few_cov = few.covariance.copy()
    few_cov[0, 0] = np.inf
    broken = type(few)(**{**few.__dict__, "covariance": few_cov})
    old = with_old.parameter_covariance
    assert broken.to_config(with_old).parameter_covariance.parameters == old.parameters
    np.testing.assert_array_equal(broken.to_config(with_old).parameter_covariance.matrix, old.matrix)
    assert "NOT written" in broken.report()
    assert broken.to_config(known).parameter_covariance is None  # none before, none invented
    # from the shipped config: its whole prior stays, the free-bending block as the stiffness one
    kept = broken.to_config(CFG).parameter_covariance
    assert kept.parameters == CFG.parameter_covariance.parameters
    np.testing.assert_array_equal(kept.matrix, CFG.parameter_covariance.matrix)


def test_stiffness_block_joins_the_free_bending_block(tips):
    p, f, tip = tips
    noisy = tip + 0.3e-3 * np.random.default_rng(12).standard_normal(tip.shape)
    fb = fit_free_bending(P_FB, fb_data(np.random.default_rng(4)), CFG)
    config = fb.to_config(CFG)
    st = fit_stiffness(StiffnessData.from_tip(p, f, noisy, L), config)
    both = st.to_config(config)
    section = both.parameter_covariance
    assert section.parameters == MODEL_PARAMETERS
    c = section.matrix
    np.testing.assert_allclose(c[:3, :3], fb.covariance, rtol=1e-12)  # symmetrised in the config
    np.testing.assert_allclose(c[3:, 3:], st.covariance, rtol=1e-9)
    assert np.all(c[:3, 3:] == 0) and np.all(c[3:, :3] == 0)
    assert "block diagonal" in section.source
    assert st.covariance[0, 0] == pytest.approx(st.stderr["ei0_nm2"] ** 2, rel=1e-12)
    # refitting free bending replaces its block and keeps the stiffness one
    again = fit_free_bending(P_FB, fb_data(np.random.default_rng(5)), CFG).to_config(both)
    np.testing.assert_allclose(again.parameter_covariance.matrix[3:, 3:], c[3:, 3:], rtol=1e-12)
    assert not np.array_equal(again.parameter_covariance.matrix[:3, :3], c[:3, :3])


def test_cli_writes_the_covariance_section(tmp_path, tips):
    write_fb_csv(tmp_path / "fb.csv", np.random.default_rng(8))
    free = tmp_path / "free.yaml"
    result = CliRunner().invoke(main, ["identify", "free-bending", str(tmp_path / "fb.csv"), "-o", str(free)])
    assert result.exit_code == 0, result.output
    assert "covariance written to the config's parameter_covariance section" in result.output
    text = free.read_text()
    assert "parameter_covariance:" in text
    loaded = bendsense.load_config(free)
    # the shipped config's prior for the stiffness stays until identify stiffness replaces it
    assert loaded.parameter_covariance.parameters == MODEL_PARAMETERS
    np.testing.assert_array_equal(loaded.parameter_covariance.matrix[3:, 3:], CFG.parameter_covariance.matrix[3:, 3:])
    p, f, tip = tips
    noisy = tip + 0.3e-3 * np.random.default_rng(12).standard_normal(tip.shape)
    lines = ["pressure_pa,fx_n,fy_n,tip_x_m,tip_y_m"]
    lines += [",".join(repr(float(v)) for v in (a, *b, *c)) for a, b, c in zip(p, f, noisy, strict=True)]
    (tmp_path / "st.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = tmp_path / "actuator.yaml"
    args = ["identify", "stiffness", str(tmp_path / "st.csv"), "--config", str(free), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    final = bendsense.load_config(out)
    assert final.parameter_covariance.parameters == MODEL_PARAMETERS
    np.testing.assert_array_equal(final.parameter_covariance.matrix[:3, :3],
                                  loaded.parameter_covariance.matrix[:3, :3])
    assert "kept from the config's prior" not in final.parameter_covariance.source  # both blocks fitted now
    sd = final.parameter_covariance.std
    assert 0 < sd["ei0_nm2"] < 0.1 * final.stiffness.ei0_nm2
    assert TRUE_FB["shear_modulus_pa"] == pytest.approx(final.material.shear_modulus_pa, rel=0.2)
