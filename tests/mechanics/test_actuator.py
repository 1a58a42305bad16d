"""Free-bending model (paper eq. 8–12) and stiffness model (eq. 15)."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import integrate

import bendsense
from bendsense.errors import ConfigError
from bendsense.mechanics import actuator
from bendsense.mechanics.actuator import (
    FreeBendingModel,
    ei_nm2,
    elastic_moment,
    elastic_moment_slope,
    pressure_moment,
    solve_bending_angle,
)

GEOM = {
    "chamber_radius_m": 6.35e-3,
    "bottom_thickness_m": 2e-3,
    "wall_thickness_m": 2e-3,
    "length_m": 0.134,
}
MU = 0.18e6
MU_S = 1.5e-3


def paper_form_moment(theta0, a, b, t, L, mu):
    """Eq. 10–11 exactly as printed (with R = L/θ0), by adaptive quadrature."""
    R = L / theta0

    def s(lam):
        return mu * (lam - lam**-3)

    bottom, _ = integrate.quad(lambda be: s(be * theta0 / L + 1) * 2 * (a + t) * be, 0, b, epsabs=0, epsrel=1e-13)
    wall, _ = integrate.dblquad(
        lambda ph, ta: s((R + b + math.sin(ph) * (a + ta)) / R) * ((a + ta) ** 2 * math.sin(ph) + b * (a + ta)),
        0,
        t,
        0,
        math.pi / 2,
        epsabs=0,
        epsrel=1e-13,
    )
    return bottom + 2 * wall


def small_strain_slope(a, b, t, L, mu):
    """dM/dθ0 at θ0 = 0 in closed form: λ − λ⁻³ ≈ 4 (λ − 1)."""

    def wall(r):
        return b**2 * math.pi / 4 * r**2 + 2 * b * r**3 / 3 + math.pi * r**4 / 16

    return mu * 4 / L * (2 * (a + t) * b**3 / 3 + 2 * (wall(a + t) - wall(a)))


def test_pressure_moment_closed_form():
    a, b = 6.35e-3, 2e-3
    got = pressure_moment(np.array([0.0, 1e3, 60e3]), a, b)
    np.testing.assert_allclose(got, (4 * a**3 + 3 * np.pi * a**2 * b) / 6 * np.array([0.0, 1e3, 60e3]), rtol=1e-15)


@pytest.mark.parametrize("theta0", [1e-3, 0.3, 1.4, 3.0, 6.0])
def test_elastic_moment_matches_adaptive_quadrature_of_printed_form(theta0):
    got = elastic_moment(theta0, **GEOM, shear_modulus_pa=MU)
    want = paper_form_moment(theta0, *GEOM.values(), MU)
    assert got == pytest.approx(want, rel=1e-11)


def test_elastic_moment_quadrature_converged(monkeypatch):
    theta = np.linspace(0.0, 12.0, 25)
    base = elastic_moment(theta, **GEOM, shear_modulus_pa=MU)
    monkeypatch.setattr(actuator, "_N_BETA", 2 * actuator._N_BETA)
    monkeypatch.setattr(actuator, "_N_TAU", 2 * actuator._N_TAU)
    monkeypatch.setattr(actuator, "_N_PHI", 2 * actuator._N_PHI)
    actuator._lever_nodes.cache_clear()
    try:
        fine = elastic_moment(theta, **GEOM, shear_modulus_pa=MU)
    finally:
        actuator._lever_nodes.cache_clear()
    np.testing.assert_allclose(base, fine, rtol=1e-12, atol=0)


def test_elastic_moment_at_zero_and_small_strain_slope():
    assert elastic_moment(0.0, **GEOM, shear_modulus_pa=MU) == 0.0
    slope0 = small_strain_slope(*GEOM.values(), MU)
    assert elastic_moment_slope(0.0, **GEOM, shear_modulus_pa=MU) == pytest.approx(slope0, rel=1e-13)
    eps = 1e-7
    assert elastic_moment(eps, **GEOM, shear_modulus_pa=MU) / eps == pytest.approx(slope0, rel=1e-6)


def test_elastic_moment_slope_matches_finite_difference():
    theta = np.array([0.2, 1.0, 2.5, 5.0])
    h = 1e-5
    fd = (
        elastic_moment(theta + h, **GEOM, shear_modulus_pa=MU) - elastic_moment(theta - h, **GEOM, shear_modulus_pa=MU)
    ) / (2 * h)
    np.testing.assert_allclose(elastic_moment_slope(theta, **GEOM, shear_modulus_pa=MU), fd, rtol=1e-8)


def test_elastic_moment_vectorised_shape_and_linear_in_mu():
    theta = np.linspace(0, 3, 12).reshape(3, 4)
    m1 = elastic_moment(theta, **GEOM, shear_modulus_pa=MU)
    assert m1.shape == (3, 4)
    np.testing.assert_allclose(elastic_moment(theta, **GEOM, shear_modulus_pa=2 * MU), 2 * m1, rtol=1e-15)
    for i in range(3):
        for j in range(4):
            assert m1[i, j] == pytest.approx(elastic_moment(theta[i, j], **GEOM, shear_modulus_pa=MU), rel=1e-14)


def test_solve_balances_moments():
    p = np.array([1e3, 20e3, 60e3, 120e3, 200e3, 500e3])
    theta = solve_bending_angle(p, **GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S)
    lhs = pressure_moment(p, GEOM["chamber_radius_m"], GEOM["bottom_thickness_m"])
    rhs = elastic_moment(theta, **GEOM, shear_modulus_pa=MU) + MU_S * theta
    np.testing.assert_allclose(rhs, lhs, rtol=1e-13)
    # independent check of the balance with the printed eq. 10-11 and adaptive quadrature
    for i in (1, 3):
        rhs_ref = paper_form_moment(theta[i], *GEOM.values(), MU) + MU_S * theta[i]
        assert rhs_ref == pytest.approx(lhs[i], rel=1e-11)


def test_paper_config_angles_match_design():
    model = FreeBendingModel.from_config(bendsense.load_config())
    got = np.degrees(model.solve([20e3, 60e3, 120e3]))
    # DESIGN.md section 2: θ0 ≈ 25°, 80°, 176° for the placeholder μ̄, μ_s
    np.testing.assert_allclose(got, [25, 80, 176], atol=1.0)


def test_small_pressure_linear_limit():
    p = 1.0  # 1 Pa: θ0 ≈ M_a / (M'(0) + μ_s)
    theta = solve_bending_angle(p, **GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S)
    lin = pressure_moment(p, GEOM["chamber_radius_m"], GEOM["bottom_thickness_m"]) / (
        small_strain_slope(*GEOM.values(), MU) + MU_S
    )
    assert theta == pytest.approx(lin, rel=1e-5)


def test_nonpositive_pressure_gives_prebend_only():
    theta = solve_bending_angle(
        [-5e3, 0.0], **GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S, prebend_angle_rad=0.1
    )
    np.testing.assert_array_equal(theta, [0.1, 0.1])
    model = FreeBendingModel(**GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S, prebend_angle_rad=0.1)
    np.testing.assert_array_equal(model.bending_angle_rad(np.array([-1.0, 0.0])), [0.1, 0.1])
    assert model.bending_angle_rad(-3.0) == 0.1


def test_prebend_adds_and_curvature_is_angle_over_length():
    kw = dict(**GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S)
    p = np.array([10e3, 80e3])
    plain = solve_bending_angle(p, **kw)
    pre = solve_bending_angle(p, **kw, prebend_angle_rad=-0.2)
    np.testing.assert_allclose(pre - plain, -0.2, rtol=0, atol=1e-15)
    model = FreeBendingModel(**kw, prebend_angle_rad=-0.2)
    np.testing.assert_allclose(model.tip_curvature_per_m(p), model.bending_angle_rad(p) / GEOM["length_m"], rtol=1e-15)
    np.testing.assert_array_equal(model.tip_angle_rad(p), model.bending_angle_rad(p))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_pressure_raises_naming_argument(bad):
    kw = dict(**GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S)
    with pytest.raises(ValueError, match="pressure_pa"):
        solve_bending_angle([1e3, bad], **kw)
    model = FreeBendingModel(**kw)
    with pytest.raises(ValueError, match="pressure_pa"):
        model.bending_angle_rad(np.array([1e3, bad]))
    with pytest.raises(ValueError, match="pressure_pa"):
        model.bending_angle_rad(float(bad))
    with pytest.raises(ValueError, match="theta0_rad"):
        elastic_moment(bad, **GEOM, shear_modulus_pa=MU)


def test_bad_parameters_raise_config_error():
    with pytest.raises(ConfigError, match="shear_modulus_pa"):
        FreeBendingModel(**GEOM, shear_modulus_pa=-1.0, sensor_stiffness_nm_per_rad=MU_S)
    with pytest.raises(ConfigError, match="sensor_stiffness_nm_per_rad"):
        solve_bending_angle(1e3, **GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=-1e-3)
    with pytest.raises(ConfigError, match="length_m"):
        elastic_moment(0.1, **{**GEOM, "length_m": 0.0}, shear_modulus_pa=MU)


def test_interpolant_error_on_random_pressures():
    model = FreeBendingModel.from_config(bendsense.load_config())
    p = np.random.default_rng(1).uniform(0, model.pressure_max_pa, 5000)
    err = np.abs(model.bending_angle_rad(p) - model.solve(p))
    assert err.max() <= 1e-8
    assert model.interpolation_error_rad <= 1e-8
    # the table's own nodes and ends are exact
    ends = np.array([0.0, model.pressure_max_pa])
    np.testing.assert_allclose(model.bending_angle_rad(ends), model.solve(ends), atol=1e-13, rtol=0)


def test_interpolant_is_monotone():
    model = FreeBendingModel.from_config(bendsense.load_config())
    p = np.linspace(0, model.pressure_max_pa, 200001)
    assert np.all(np.diff(model.bending_angle_rad(p)) > 0)


def test_above_range_uses_direct_solve():
    model = FreeBendingModel(**GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S, pressure_max_pa=50e3)
    p = np.array([10e3, 50e3, 50e3 + 1e-6, 120e3, 300e3])
    direct = model.solve(p)
    got = model.bending_angle_rad(p)
    np.testing.assert_allclose(got[2:], direct[2:], rtol=0, atol=1e-14)
    assert abs(got[:2] - direct[:2]).max() <= 1e-8
    assert model.bending_angle_rad(120e3) == pytest.approx(direct[3], abs=1e-14)


def test_scalar_and_array_paths_agree_and_shapes_kept():
    model = FreeBendingModel.from_config(bendsense.load_config())
    p = np.random.default_rng(2).uniform(-1e3, 250e3, (4, 5))
    arr = model.bending_angle_rad(p)
    assert arr.shape == (4, 5)
    scal = np.array([[model.bending_angle_rad(float(x)) for x in row] for row in p])
    np.testing.assert_allclose(arr, scal, rtol=2e-15, atol=1e-15)
    assert np.ndim(model.bending_angle_rad(3e4)) == 0
    assert np.ndim(model.bending_angle_rad(np.float64(3e4))) == 0
    assert model.bending_angle_rad(np.array(3e4)).shape == ()


def test_table_cached_per_parameter_set():
    kw = dict(**GEOM, shear_modulus_pa=MU, sensor_stiffness_nm_per_rad=MU_S)
    m1 = FreeBendingModel(**kw)
    m2 = FreeBendingModel(**kw, prebend_angle_rad=0.3)
    m3 = FreeBendingModel(**{**kw, "shear_modulus_pa": 2 * MU})
    assert m1._table is m2._table
    assert m1._table is not m3._table


def test_from_config_uses_config_sections():
    cfg = bendsense.load_config()
    model = FreeBendingModel.from_config(cfg)
    assert model.length_m == cfg.actuator.length_m
    assert model.shear_modulus_pa == cfg.material.shear_modulus_pa
    assert model.pressure_max_pa == cfg.estimation.pressure_max_pa
    assert bendsense.mechanics.actuator.FreeBendingModel is FreeBendingModel


@settings(max_examples=30, deadline=None)
@given(
    a=st.floats(2e-3, 15e-3),
    b=st.floats(0.5e-3, 5e-3),
    t=st.floats(0.5e-3, 5e-3),
    length=st.floats(0.05, 0.3),
    mu=st.floats(2e4, 2e6),
    mu_s=st.floats(0.0, 1e-2),
    p_max=st.floats(1e4, 5e5),
)
def test_interpolant_accuracy_and_monotonicity_for_any_parameters(a, b, t, length, mu, mu_s, p_max):
    kw = dict(chamber_radius_m=a, bottom_thickness_m=b, wall_thickness_m=t, length_m=length)
    # up to two full turns at pressure_max_pa: beyond any real actuator
    assume(solve_bending_angle(p_max, **kw, shear_modulus_pa=mu, sensor_stiffness_nm_per_rad=mu_s) <= 4 * np.pi)
    model = FreeBendingModel(
        chamber_radius_m=a,
        bottom_thickness_m=b,
        wall_thickness_m=t,
        length_m=length,
        shear_modulus_pa=mu,
        sensor_stiffness_nm_per_rad=mu_s,
        pressure_max_pa=p_max,
    )
    p = np.sort(np.random.default_rng(0).uniform(0, p_max, 500))
    direct = model.solve(p)
    assert np.all(np.diff(direct) >= 0)
    interp = model.bending_angle_rad(p)
    assert np.max(np.abs(interp - direct)) <= 1e-8
    assert np.all(np.diff(interp) >= 0)


def test_ei_linear_in_pressure_and_same_as_config():
    cfg = bendsense.load_config()
    p = np.array([0.0, 20e3, 120e3])
    got = ei_nm2(p, cfg.stiffness.ei0_nm2, cfg.stiffness.ei1_nm2_per_pa)
    np.testing.assert_allclose(got, 2.53e-3 + 1.25e-5 * p / 1e3, rtol=1e-14)
    np.testing.assert_array_equal(got, cfg.stiffness.ei_nm2(p))
    with pytest.raises(ConfigError, match="ei0_nm2"):
        ei_nm2(p, 0.0, 1e-8)
