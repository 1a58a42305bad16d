"""Sensitivities of K0(P) and EI(P) to the identified parameters, and their covariance in the config."""

import dataclasses

import numpy as np
import pytest

from bendsense import load_config
from bendsense.config import Config, ParameterCovarianceConfig, save_config
from bendsense.errors import ArgumentError, ConfigError
from bendsense.mechanics.actuator import (
    FREE_BENDING_PARAMETERS,
    MODEL_PARAMETERS,
    FreeBendingModel,
    ei_jacobian,
    model_jacobian,
    solve_bending_angle,
)

CONFIG = load_config()
PRESSURES = np.array([1e3, 2e4, 4e4, 6e4, 9e4, 1.2e5, 1.6e5, 1.99e5, 2.4e5])  # the last above pressure_max_pa

MATERIALS = [
    {},  # the paper's placeholders
    {"shear_modulus_pa": 6e4, "sensor_stiffness_nm_per_rad": 0.0, "prebend_angle_rad": 0.1},  # soft, no sensor
    {"shear_modulus_pa": 4e5, "sensor_stiffness_nm_per_rad": 5e-3, "prebend_angle_rad": -0.05},
]


def central_difference(params, name, pressure):
    """∂θ/∂name of the direct solve (no interpolant) by a central difference."""
    h = 1e-5 * abs(params[name]) if params[name] else 1e-6
    up, down = dict(params), dict(params)
    up[name] += h
    if name == "sensor_stiffness_nm_per_rad" and params[name] == 0:  # μ_s >= 0: a forward difference
        up[name] = h = 1e-10
        return (solve_bending_angle(pressure, **up) - solve_bending_angle(pressure, **down)) / h
    down[name] -= h
    return (solve_bending_angle(pressure, **up) - solve_bending_angle(pressure, **down)) / (2 * h)


@pytest.mark.parametrize("material", MATERIALS)
def test_tip_curvature_jacobian_matches_finite_differences(material):
    config = CONFIG.replace(material=dataclasses.replace(CONFIG.material, **material))
    model = FreeBendingModel.from_config(config)
    jac = model.tip_curvature_jacobian(PRESSURES)
    assert jac.shape == (len(PRESSURES), 3)
    for i, name in enumerate(FREE_BENDING_PARAMETERS):
        fd = central_difference(model.params, name, PRESSURES) / model.length_m
        np.testing.assert_allclose(jac[:, i], fd, rtol=2e-6, atol=1e-12 * np.abs(fd).max(), err_msg=name)
    # signs: a stiffer actuator or sensor bends less; the prebend adds 1/L
    assert np.all(jac[:, 0] < 0) and np.all(jac[:, 2] == pytest.approx(1 / model.length_m))
    if model.sensor_stiffness_nm_per_rad >= 0:
        assert np.all(jac[:, 1] < 0)


def test_slope_over_pressure_matches_finite_differences():
    model = FreeBendingModel.from_config(CONFIG)
    h = 1.0
    fd = (model.solve(PRESSURES + h) - model.solve(PRESSURES - h)) / (2 * h) / model.length_m
    np.testing.assert_allclose(model.tip_curvature_slope(PRESSURES), fd, rtol=1e-6)
    # below zero pressure θ0 is clamped at 0: no sensitivity to anything but the prebend
    low = model.tip_curvature_jacobian(np.array([-5e3, 0.0]))
    np.testing.assert_array_equal(low[:, :2], 0.0)
    assert model.tip_curvature_slope(-5e3) == 0.0


def test_jacobian_vectorises_over_any_shape():
    model = FreeBendingModel.from_config(CONFIG)
    p = PRESSURES[:8].reshape(2, 4)
    flat = model.tip_curvature_jacobian(p.ravel()).reshape(2, 4, 3)
    np.testing.assert_array_equal(model.tip_curvature_jacobian(p), flat)
    assert model.tip_curvature_jacobian(6e4).shape == (3,)


def test_ei_and_model_jacobian():
    p = np.array([0.0, 5e4, 1.2e5])
    np.testing.assert_array_equal(ei_jacobian(p), np.stack([np.ones(3), p], axis=-1))
    full = model_jacobian(CONFIG, p)
    assert full.shape == (3, 2, 5)
    model = FreeBendingModel.from_config(CONFIG)
    np.testing.assert_array_equal(full[:, 0, :3], model.tip_curvature_jacobian(p))
    np.testing.assert_array_equal(full[:, 1, 3:], ei_jacobian(p))
    assert np.all(full[:, 0, 3:] == 0) and np.all(full[:, 1, :3] == 0)
    # EI(P) by finite differences of the config itself
    for j, name in enumerate(MODEL_PARAMETERS[3:], start=3):
        value = CONFIG.model_parameters()[name]
        h = 1e-3 * value
        up = CONFIG.with_model_parameters({name: value + h}).stiffness.ei_nm2(p)
        down = CONFIG.with_model_parameters({name: value - h}).stiffness.ei_nm2(p)
        np.testing.assert_allclose(full[:, 1, j], (up - down) / (2 * h), rtol=1e-9)
    picked = model_jacobian(CONFIG, p, parameters=("ei1_nm2_per_pa", "shear_modulus_pa"))
    np.testing.assert_array_equal(picked, full[..., [4, 0]])
    with pytest.raises(ArgumentError, match=r"parameters: unknown 'gamma0'"):
        model_jacobian(CONFIG, p, parameters=("gamma0",))


def test_the_beam_inputs_of_an_estimate_inside_and_past_the_free_bending_table():
    """θ, K0, EI and Σ(K0, EI) of estimate_force's frames: the compiled table inside it, the direct solve past it.

    Against the direct solve of eq. 8, EI = γ0 + γ1 P and ``J Σ Jᵀ`` written out here. The
    table ends at ``estimation.pressure_max_pa`` (150 kPa here), inside the actuator's range
    (to 200 kPa): a frame past it must not take the table's end.
    """
    from bendsense.estimation import _beam_inputs, estimate_force

    config = dataclasses.replace(CONFIG, estimation=dataclasses.replace(CONFIG.estimation, pressure_max_pa=1.5e5))
    section = config.parameter_covariance
    assert section is not None  # the shipped prior: a model part to propagate
    model = FreeBendingModel.from_config(config)
    for p in (np.array([2e4, 9e4, 1.4e5]), np.array([9e4, 1.8e5])):  # inside the table; a frame past it
        theta, ei, k0, cov = _beam_inputs(config, p)
        np.testing.assert_allclose(theta, model.solve(p), rtol=0, atol=1e-8)  # the table's error bound
        np.testing.assert_allclose(k0, theta / config.actuator.length_m, rtol=1e-15)
        np.testing.assert_allclose(ei, config.stiffness.ei0_nm2 + config.stiffness.ei1_nm2_per_pa * p, rtol=1e-15)
        J = model_jacobian(config, p, section.parameters)
        expected = np.einsum("bij,jk,blk->bil", J, np.asarray(section.covariance), J)
        for a, b in ((0, 0), (0, 1), (1, 1)):
            np.testing.assert_allclose(cov[:, a, b], expected[:, a, b], rtol=1e-9,
                                       atol=1e-12 * np.sqrt(expected[:, a, a] * expected[:, b, b]).max())
        np.testing.assert_array_equal(cov[:, 0, 1], cov[:, 1, 0])
    past = estimate_force(np.full(config.sensor.n_segments, 4.0), 1.8e5, config, noise_std=0.02)
    assert past.success


# --- the covariance section of the config ----------------------------------------------------


def covariance_section(names=("shear_modulus_pa", "ei0_nm2"), matrix=((1e8, 3e-2), (3e-2, 1e-11))):
    return {"parameters": list(names), "covariance": [list(r) for r in matrix], "source": "test"}


def test_covariance_section_round_trips_through_yaml(tmp_path):
    data = CONFIG.to_dict()
    assert data.pop("parameter_covariance")["parameters"] == list(MODEL_PARAMETERS)  # the shipped prior, replaced
    data["parameter_covariance"] = covariance_section()
    config = Config.from_dict(data)
    section = config.parameter_covariance
    assert section.parameters == ("shear_modulus_pa", "ei0_nm2")
    np.testing.assert_array_equal(section.matrix, [[1e8, 3e-2], [3e-2, 1e-11]])
    assert section.std["shear_modulus_pa"] == pytest.approx(1e4)
    save_config(config, tmp_path / "c.yaml")
    back = load_config(tmp_path / "c.yaml")
    assert back.parameter_covariance == section and back.to_dict() == config.to_dict()
    # the estimator's Jacobian follows the section's order by default
    assert model_jacobian(config, 5e4).shape == (2, 2)


@pytest.mark.parametrize(
    ("section", "message"),
    [
        (covariance_section(names=("shear_modulus_pa", "gamma1")), r"parameters\[1\]: must be one of"),
        (covariance_section(names=("ei0_nm2", "ei0_nm2")), r"parameters: each name once"),
        (covariance_section(matrix=((1e8, 3e-2),)), r"covariance: expected 2 rows"),
        (covariance_section(matrix=((1e8, 3e-2), (3e-2,))), r"covariance\[1\]: expected 2 values, got 1"),
        (covariance_section(matrix=((1e8, 3e-2), (-3e-2, 1e-11))), r"covariance: must be symmetric"),
        (covariance_section(matrix=((1e8, 3e-1), (3e-1, 1e-11))), r"covariance: must be positive semi-definite"),
        (covariance_section(matrix=((-1.0, 0.0), (0.0, 1e-11))), r"covariance\[0\]\[0\]: a variance must be >= 0"),
        (covariance_section(matrix=((1e8, "x"), (0.0, 1e-11))), r"covariance\[0\]\[1\]: expected a number"),
        ({"parameters": ["ei0_nm2"], "covariance": [[1e-12]], "extra": 1}, r"parameter_covariance: unknown keys extra"),
    ],
)
def test_covariance_section_is_validated(section, message):
    data = CONFIG.to_dict()
    data["parameter_covariance"] = section
    with pytest.raises(ConfigError, match=message):
        Config.from_dict(data)


def test_blocks_and_parameter_replacement():
    block = ParameterCovarianceConfig.from_blocks(
        [(("shear_modulus_pa", "prebend_angle_rad"), [[4e6, 1.0], [1.0, 1e-4]]), (("ei1_nm2_per_pa",), [[1e-20]])],
        source="two fits",
    )
    np.testing.assert_array_equal(block.matrix, [[4e6, 1.0, 0], [1.0, 1e-4, 0], [0, 0, 1e-20]])
    values = CONFIG.model_parameters()
    assert list(values) == list(MODEL_PARAMETERS) and values["ei0_nm2"] == CONFIG.stiffness.ei0_nm2
    changed = CONFIG.with_model_parameters({"shear_modulus_pa": 2e5, "ei1_nm2_per_pa": 2e-8})
    assert changed.material.shear_modulus_pa == 2e5 and changed.stiffness.ei1_nm2_per_pa == 2e-8
    assert changed.material.sensor_stiffness_nm_per_rad == CONFIG.material.sensor_stiffness_nm_per_rad
    with pytest.raises(ArgumentError, match=r"parameters: expected names from shear_modulus_pa, .*, got 'mu'"):
        CONFIG.with_model_parameters({"mu": 1.0})
