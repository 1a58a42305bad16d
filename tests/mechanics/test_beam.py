"""Tests of the curved-beam solver against closed forms and independent methods.

References written here, independent of ``bendsense.mechanics.beam``: the exact elastica of a
straight cantilever under a perpendicular tip load (elliptic integrals), linear beam
theory, the circular arc, the linear buckling load from an eigenvalue (a shooting
computation on the linearised equation), the moment balance of the returned shape,
and central finite differences.
"""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

from bendsense.errors import ConvergenceError
from bendsense.mechanics.beam import BeamConvergenceWarning, BeamSolution, FastOptions, free_arc, solve, solve_beam

L = 0.134  # paper actuator length [m]
MASS = 0.03927  # actuator + sensor [kg]
W_GRAV = MASS * 9.81 / L  # gravity per length [N/m]
GRAVITY = (0.0, -W_GRAV)  # upright rig


def ei_of(p_pa):
    return 2.53e-3 + 1.25e-8 * p_pa


def k0_of(p_pa):
    # stand-in for the free-bending model: θ0 from 0 to 3 rad over 0–120 kPa
    return 3.0 * p_pa / 120e3 / L


# --------------------------------------------------------------------------- references


def exact_elastica(alpha):
    """Tip of a straight cantilever under a tip load perpendicular to its axis.

    Bisshopp & Drucker (1945). With θ the tangent angle from the unloaded axis,
    EI θ'' = −F cos θ, θ(0) = 0, θ'(L) = 0 gives θ'² = 2α (sin θ_L − sin θ) / L² and,
    with 1 + sin θ = 2 k² sin² ψ, k = sin(π/4 + θ_L/2):
    √α = K(k) − F(ψ0, k), sin ψ0 = 1/(k√2); deflection along the load
    x/L = 1 − (2/√α)(E(k) − E(ψ0, k)); along the unloaded axis y/L = √(2 sin θ_L / α).
    Returns (θ_L, x/L, y/L).
    """

    def parts(theta):
        k = math.sin(math.pi / 4 + theta / 2)
        return k * k, math.asin(1.0 / (math.sqrt(2.0) * k))

    def gap(theta):
        m, psi0 = parts(theta)
        return ellipk(m) - ellipkinc(psi0, m) - math.sqrt(alpha)

    theta = brentq(gap, 1e-12, math.pi / 2 - 1e-12, xtol=1e-15, rtol=1e-15)
    m, psi0 = parts(theta)
    x = 1.0 - 2.0 / math.sqrt(alpha) * (ellipe(m) - ellipeinc(psi0, m))
    y = math.sqrt(2.0 * math.sin(theta) / alpha)
    return theta, x, y


def test_exact_elastica_reference_is_self_consistent():
    # the first integral, integrated by quadrature, must give the unit length and the tip
    for alpha in (0.25, 3.0, 10.0):
        theta, x, y = exact_elastica(alpha)

        def ds(t, theta=theta, alpha=alpha):
            return 1.0 / math.sqrt(2.0 * alpha * (math.sin(theta) - math.sin(t)))

        length, _ = quad(ds, 0.0, theta, limit=200, epsabs=1e-13)
        xq, _ = quad(lambda t: math.sin(t) * ds(t), 0.0, theta, limit=200, epsabs=1e-13)
        yq, _ = quad(lambda t: math.cos(t) * ds(t), 0.0, theta, limit=200, epsabs=1e-13)
        assert length == pytest.approx(1.0, abs=1e-9)
        assert xq == pytest.approx(x, abs=1e-9)
        assert yq == pytest.approx(y, abs=1e-9)


def critical_tip_load(ei, w, length=L):
    """Linear buckling load Fy < 0 of the straight upright beam under its own weight.

    Linearising EI φ'' = sin φ G_y − cos φ G_x about φ = 0 with G_x = 0 gives the
    Sturm–Liouville problem EI η'' = (F_y − w (L − s)) η, η(0) = 0, η'(L) = 0; the
    critical F_y is the first root of η'(L) for the initial-value solution η'(0) = 1.
    """

    def end_slope(fy):
        sol = solve_ivp(
            lambda s, y: [y[1], (fy - w * (length - s)) * y[0] / ei],
            (0.0, length),
            [0.0, 1.0],
            rtol=1e-11,
            atol=1e-13,
        )
        return sol.y[1, -1]

    return brentq(end_slope, -1.5, 0.0, xtol=1e-12)  # the second mode needs ~9x more


# --------------------------------------------------------------------------- accuracy


@pytest.mark.parametrize("method", ["fast", "shooting"])
@pytest.mark.parametrize("alpha", [0.25, 1.0, 3.0, 10.0])
def test_exact_elastica(method, alpha):
    ei = 2.53e-3
    force = alpha * ei / L**2
    theta, x, y = exact_elastica(alpha)
    sol = solve_beam(L, ei, 0.0, (force, 0.0), method=method)
    assert sol.success
    np.testing.assert_allclose(sol.tip_position_m, [x * L, y * L], rtol=0, atol=1e-6 * L)
    assert sol.tip_angle_rad == pytest.approx(theta, abs=1e-6)
    # the default settings are far more accurate than the target
    np.testing.assert_allclose(sol.tip_position_m, [x * L, y * L], rtol=0, atol=1e-10 * L)


def test_linear_theory_tip_force():
    ei = 3.1e-3
    fx = 1e-4 * ei / L**2  # α = 1e-4: nonlinear corrections ~ α² ≪ tolerance
    sol = solve_beam(L, ei, 0.0, (fx, 0.0))
    assert sol.tip_position_m[0] == pytest.approx(fx * L**3 / (3 * ei), rel=1e-6)
    assert sol.tip_angle_rad == pytest.approx(fx * L**2 / (2 * ei), rel=1e-6)
    # deflection line x(s) = F s² (3L − s) / 6EI
    s = sol.s_m
    np.testing.assert_allclose(sol.positions_m[:, 0], fx * s**2 * (3 * L - s) / (6 * ei), rtol=1e-6, atol=1e-15)


def test_linear_theory_distributed_load():
    ei = 2.53e-3
    w = 1e-4 * ei / L**3
    sol = solve_beam(L, ei, 0.0, distributed_load_n_per_m=(w, 0.0))
    assert sol.tip_position_m[0] == pytest.approx(w * L**4 / (8 * ei), rel=1e-6)
    assert sol.tip_angle_rad == pytest.approx(w * L**3 / (6 * ei), rel=1e-6)


@pytest.mark.parametrize("k0", [-20.0, 0.0, 1e-9, 5.0, 23.4, 45.0])
@pytest.mark.parametrize("method", ["fast", "shooting"])
def test_unloaded_is_the_natural_arc(k0, method):
    sol = solve_beam(L, 2.53e-3, k0, method=method)
    s = sol.s_m
    if k0 == 0.0:
        x, y = np.zeros_like(s), s
    else:
        x, y = 2 * np.sin(k0 * s / 2) ** 2 / k0, np.sin(k0 * s) / k0  # no cancellation at small K0
    np.testing.assert_allclose(sol.positions_m, np.stack([x, y], axis=-1), rtol=0, atol=1e-12)
    np.testing.assert_allclose(sol.angle_rad, k0 * s, rtol=0, atol=1e-11)
    phi, pos = free_arc(L, k0)
    np.testing.assert_allclose(pos, sol.positions_m, rtol=0, atol=1e-12)


def rotate(v, beta):
    """Rotate base-frame vectors by β from +y toward +x (clockwise)."""
    c, s = math.cos(beta), math.sin(beta)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)


@pytest.mark.parametrize("beta", [0.3, -1.2, 2.5])
def test_base_angle_rotates_the_shape_rigidly(beta):
    k0 = 12.0
    ref = solve_beam(L, 2.53e-3, k0)
    rot = solve_beam(L, 2.53e-3, k0, base_angle_rad=beta)
    np.testing.assert_allclose(rot.positions_m, rotate(ref.positions_m, beta), atol=1e-12)
    np.testing.assert_allclose(rot.angle_rad, ref.angle_rad + beta, atol=1e-11)
    # rotating the base together with the loads is a rigid motion of the loaded shape
    F, w = np.array([0.15, -0.1]), np.array([0.3, -2.0])
    ref = solve_beam(L, 2.53e-3, k0, F, w)
    rot = solve_beam(L, 2.53e-3, k0, rotate(F, beta), rotate(w, beta), base_angle_rad=beta)
    assert ref.success and rot.success
    np.testing.assert_allclose(rot.positions_m, rotate(ref.positions_m, beta), atol=1e-12)


def test_moment_balance_of_the_returned_shape():
    # EI (φ'(s) − K0) = −M_z(s), with M_z from the returned positions (DESIGN section 2)
    ei, k0 = 3.0e-3, 10.0
    F, w = np.array([-0.2, 0.3]), np.array([0.0, -2.9])
    s = np.linspace(0, L, 4001)
    sol = solve_beam(L, ei, k0, F, w, s_m=s)
    r, phi = sol.positions_m, sol.angle_rad
    dphi = np.gradient(phi, s, edge_order=2)
    arm = r[-1] - r  # tip force about r(s)
    m_tip = arm[:, 0] * F[1] - arm[:, 1] * F[0]
    # distributed load: ∫_s^L (r(σ) − r(s)) × w dσ = (R(L) − R(s) − (L − s) r(s)) × w with R = ∫ r
    R = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(s)[:, None], axis=0)])
    lever = R[-1] - R - (L - s)[:, None] * r
    m_w = lever[:, 0] * w[1] - lever[:, 1] * w[0]
    np.testing.assert_allclose(ei * (dphi - k0), -(m_tip + m_w), atol=2e-6)
    # inextensible: the polyline through the points has (almost) the full length
    assert np.sum(np.hypot(*np.diff(r, axis=0).T)) == pytest.approx(L, rel=1e-6)


# --------------------------------------------------------------------------- physics


def test_push_toward_plus_x_bends_toward_plus_x():
    for k0 in (0.0, 10.0, -10.0):
        free = solve_beam(L, 2.53e-3, k0)
        pushed = solve_beam(L, 2.53e-3, k0, (0.05, 0.0))
        assert pushed.tip_position_m[0] > free.tip_position_m[0]
        assert pushed.tip_angle_rad > free.tip_angle_rad


def test_compression_softens_tension_stiffens():
    ei, fx = 2.53e-3, 0.01
    fcr = -(math.pi**2) * ei / (4 * L**2)  # Euler load of the cantilever without gravity
    tips = [solve_beam(L, ei, 0.0, (fx, fy)).tip_position_m[0] for fy in (0.8 * fcr, 0.4 * fcr, 0.0, -0.5 * fcr)]
    assert tips[0] > tips[1] > tips[2] > tips[3] > 0


@pytest.mark.parametrize(("p_kpa", "expected"), [(0, -0.23), (60, -0.33), (120, -0.44)])
def test_buckling_load_with_gravity(p_kpa, expected):
    ei = ei_of(p_kpa * 1e3)
    fcr = critical_tip_load(ei, W_GRAV)
    assert fcr == pytest.approx(expected, abs=0.01)
    # the straight upright beam: stable just below the critical load, flagged just above
    fy = np.array([0.97, 0.995, 1.005, 1.03]) * fcr
    for method in ("fast", "shooting"):
        with pytest.warns(BeamConvergenceWarning, match="unstable"):
            sol = solve_beam(L, ei, 0.0, np.stack([np.zeros(4), fy], axis=-1), GRAVITY, method=method)
        np.testing.assert_array_equal(sol.success, [True, True, False, False])
        assert all("unstable" in m for m in sol.message[2:])
        assert all(m == "converged" for m in sol.message[:2])
        np.testing.assert_allclose(sol.tip_position_m[:2, 0], 0.0, atol=1e-12)
    # an imperfect beam (small lateral load) takes the stable, bent-over branch instead
    sol = solve_beam(L, ei, 0.0, (0.01, 1.03 * fcr), GRAVITY)
    assert sol.success and sol.tip_position_m[0] > 0.2 * L


def test_strict_and_warning():
    fy = -1.0  # far beyond buckling of the straight beam
    with pytest.raises(ConvergenceError, match="unstable"):
        solve_beam(L, 2.53e-3, 0.0, (0.0, fy), strict=True)
    with pytest.warns(BeamConvergenceWarning, match="1 of 1"):
        sol = solve_beam(L, 2.53e-3, 0.0, (0.0, fy))
    assert not sol.success and isinstance(sol.message, str)
    sol = solve_beam(L, 2.53e-3, 0.0, (0.0, fy), warn=False)
    assert not sol.success


GRID_P = [0.0, 60e3, 120e3]
GRID_F = [-0.4, -0.2, 0.0, 0.2, 0.4]


def test_fast_matches_shooting_on_the_paper_workspace():
    fx, fy = np.meshgrid(GRID_F, GRID_F, indexing="ij")
    forces = np.stack([fx.ravel(), fy.ravel()], axis=-1)
    for p in GRID_P:
        args = (L, ei_of(p), k0_of(p), forces, GRAVITY)
        fast = solve_beam(*args, warn=False)
        ref = solve_beam(*args, method="shooting", warn=False)
        both = fast.success & ref.success
        assert both.sum() >= forces.shape[0] - 2
        err = np.linalg.norm(fast.tip_position_m[both] - ref.tip_position_m[both], axis=-1)
        np.testing.assert_array_less(err, 1e-8 * np.linalg.norm(ref.tip_position_m[both], axis=-1))
        np.testing.assert_allclose(fast.positions_m[both], ref.positions_m[both], rtol=0, atol=1e-8 * L)
        # where the fast method refuses, the frame is compressive and near or beyond buckling
        fcr = critical_tip_load(ei_of(p), W_GRAV)
        for i in np.flatnonzero(~fast.success):
            f = forces[i]
            tangent = np.array([math.sin(k0_of(p) * L), math.cos(k0_of(p) * L)])
            assert f @ tangent < 0 and np.linalg.norm(f) > 0.5 * abs(fcr), (p, f, fast.message[i])
            assert not ref.success[i]


def test_fast_follows_the_branch_from_the_unloaded_shape():
    # curved actuator pushed against its curvature and compressed: the shooting method
    # without branch checks jumps to the other side; the tracked branch is continuous
    p, f = 30e3, np.array([-0.2, -0.4])
    args = (L, ei_of(p), k0_of(p))
    lams = np.linspace(0, 1, 21)
    path = solve_beam(*args, lams[:, None] * f, lams[:, None] * np.array(GRAVITY))
    assert path.success.all()
    steps = np.linalg.norm(np.diff(path.tip_position_m, axis=0), axis=-1)
    assert steps.max() < 0.15 * L
    end = solve_beam(*args, f, GRAVITY)
    np.testing.assert_allclose(end.tip_position_m, path.tip_position_m[-1], atol=1e-12)


def test_soft_region_is_not_mistaken_for_buckling():
    # near-snap: along this load path the stiffness drops to a few % of the unloaded
    # value (λ ≈ 0.87) and two more equilibria exist at full load, one of them
    # unstable and close to the continuation predictor
    p = 18556.34
    f = np.array([-0.12050784, -0.29500324])
    args = (L, ei_of(p), 0.46390841953999307 / L)
    fast = solve_beam(*args, f, GRAVITY)
    ref = solve_beam(*args, f, GRAVITY, method="shooting")
    assert fast.success and ref.success
    np.testing.assert_allclose(fast.tip_position_m, ref.tip_position_m, atol=1e-8 * L)
    # a warm start across the soft region must not slide onto the other stable branch
    before = solve_beam(*args, 0.9 * f, 0.9 * np.array(GRAVITY))
    warm = solve_beam(*args, 0.95 * f, 0.95 * np.array(GRAVITY), initial=before)
    cold = solve_beam(*args, 0.95 * f, 0.95 * np.array(GRAVITY))
    np.testing.assert_allclose(warm.tip_position_m, cold.tip_position_m, atol=1e-12)
    assert cold.tip_position_m[0] > 0.5 * L


def test_snap_across_to_the_other_side_is_followed():
    # bend toward +x, push toward −x and compress: the tracked branch crosses over to
    # the −x side near λ ≈ 0.68 while an unstable, almost straight equilibrium stays
    # close to the path (both methods must step past it rather than land on it)
    p = 17688.04
    f = np.array([-0.02581754, -0.43908921])
    args = (L, ei_of(p), 0.07376836249353437 / L, f, GRAVITY)
    fast = solve_beam(*args)
    ref = solve_beam(*args, method="shooting")
    assert fast.success and ref.success
    np.testing.assert_allclose(fast.positions_m, ref.positions_m, atol=1e-8 * L)
    assert fast.tip_position_m[0] < -0.5 * L


def test_fast_matches_shooting_on_random_workspace_frames():
    rng = np.random.default_rng(11)
    n = 40
    p = rng.uniform(0, 120e3, n)
    forces = rng.uniform(-0.4, 0.4, (n, 2))
    args = (L, ei_of(p), k0_of(p), forces, GRAVITY)
    fast = solve_beam(*args, warn=False)
    ref = solve_beam(*args, method="shooting", warn=False)
    np.testing.assert_array_equal(fast.success, ref.success)
    ok = fast.success
    np.testing.assert_allclose(fast.positions_m[ok], ref.positions_m[ok], rtol=0, atol=1e-8 * L)


# --------------------------------------------------------------------------- sensitivities


@pytest.mark.parametrize(
    ("p", "force"),
    [(0.0, (0.05, 0.02)), (60e3, (-0.3, 0.2)), (120e3, (0.25, -0.3)), (30e3, (-0.2, -0.4))],
)
def test_sensitivities_match_finite_differences(p, force):
    args = (L, ei_of(p), k0_of(p))
    sol = solve_beam(*args, force, GRAVITY, sensitivities=True)
    assert sol.success
    h = 1e-6
    for b in range(2):
        e = np.zeros(2)
        e[b] = h
        hi = solve_beam(*args, np.add(force, e), GRAVITY, initial=sol)
        lo = solve_beam(*args, np.subtract(force, e), GRAVITY, initial=sol)
        dpos = (hi.positions_m - lo.positions_m) / (2 * h)
        dang = (hi.angle_rad - lo.angle_rad) / (2 * h)
        dtip = (hi.tip_position_m - lo.tip_position_m) / (2 * h)
        np.testing.assert_allclose(sol.dpositions_dforce[..., b], dpos, rtol=0, atol=1e-6 * np.abs(dpos).max())
        np.testing.assert_allclose(sol.dangle_dforce[..., b], dang, rtol=0, atol=1e-6 * np.abs(dang).max())
        np.testing.assert_allclose(sol.dtip_position_dforce[..., b], dtip, rtol=0, atol=1e-6 * np.abs(dtip).max())
    np.testing.assert_allclose(sol.dtip_position_dforce, sol.dpositions_dforce[-1], atol=1e-15)


def test_batched_sensitivities_equal_single_frame():
    rng = np.random.default_rng(3)
    p = rng.uniform(0, 120e3, 6)
    forces = rng.uniform(-0.3, 0.3, (6, 2))
    batch = solve_beam(L, ei_of(p), k0_of(p), forces, GRAVITY, sensitivities=True)
    for i in range(6):
        one = solve_beam(L, ei_of(p[i]), k0_of(p[i]), forces[i], GRAVITY, sensitivities=True)
        np.testing.assert_allclose(batch.positions_m[i], one.positions_m, atol=1e-13)
        np.testing.assert_allclose(batch.dpositions_dforce[i], one.dpositions_dforce, rtol=1e-8, atol=1e-14)


# --------------------------------------------------------------------------- API


def test_batch_shapes_broadcast():
    ei = ei_of(np.array([0.0, 60e3, 120e3]))[:, None]  # (3, 1)
    forces = np.array([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.05], [0.02, -0.1]])[None]  # (1, 4, 2)
    s = np.linspace(0, L, 7)
    sol = solve_beam(L, ei, 8.0, forces, GRAVITY, s_m=s, sensitivities=True)
    assert sol.positions_m.shape == (3, 4, 7, 2)
    assert sol.angle_rad.shape == (3, 4, 7)
    assert sol.tip_position_m.shape == (3, 4, 2)
    assert sol.tip_angle_rad.shape == sol.success.shape == sol.iterations.shape == (3, 4)
    assert np.shape(sol.message) == (3, 4)
    assert sol.dpositions_dforce.shape == (3, 4, 7, 2, 2)
    assert sol.dangle_dforce.shape == (3, 4, 7, 2)
    assert sol.state.shape[:2] == (3, 4)
    for i in range(3):
        for j in range(4):
            one = solve_beam(L, float(ei[i, 0]), 8.0, forces[0, j], GRAVITY, s_m=s)
            np.testing.assert_allclose(sol.positions_m[i, j], one.positions_m, atol=1e-13)
    assert isinstance(sol, BeamSolution)


def test_warm_start_reduces_iterations():
    rng = np.random.default_rng(7)
    p = rng.uniform(0, 120e3, 50)
    forces = rng.uniform(-0.3, 0.3, (50, 2))
    args = (L, ei_of(p), k0_of(p))
    cold = solve_beam(*args, forces, GRAVITY)
    warm = solve_beam(*args, forces + 1e-3, GRAVITY, initial=cold)
    again = solve_beam(*args, forces + 1e-3, GRAVITY)
    assert warm.success.all()
    np.testing.assert_allclose(warm.positions_m, again.positions_m, atol=1e-12)
    assert warm.iterations.sum() < cold.iterations.sum()
    assert warm.iterations.max() <= 3
    # the pure core takes the same arguments positionally, without validation
    core = solve(L, ei_of(p), k0_of(p), forces + 1e-3, np.array(GRAVITY), 0.0, cold.s_m, initial=cold.state)
    np.testing.assert_allclose(core.positions_m, warm.positions_m, atol=0)


def test_output_grid_and_interpolation():
    dense = solve_beam(L, 2.53e-3, 10.0, (0.1, -0.1), GRAVITY)
    s = dense.s_m[[0, 10, 50, 75, 100]]
    sol = solve_beam(L, 2.53e-3, 10.0, (0.1, -0.1), GRAVITY, s_m=s)
    np.testing.assert_array_equal(sol.s_m, s)
    assert dense.s_m.shape == (101,) and dense.s_m[0] == 0.0 and dense.s_m[-1] == L
    np.testing.assert_allclose(sol.positions_m[-1], sol.tip_position_m, atol=1e-15)
    np.testing.assert_allclose(sol.positions_m[0], [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(sol.positions_m, dense.positions_m[[0, 10, 50, 75, 100]], atol=1e-15)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"length_m": float("nan")}, "length_m"),
        ({"length_m": -1.0}, "length_m"),
        ({"ei_nm2": np.inf}, "ei_nm2"),
        ({"ei_nm2": 0.0}, "ei_nm2"),
        ({"tip_curvature_per_m": [1.0, np.nan]}, "tip_curvature_per_m"),
        ({"force_n": (np.nan, 0.0)}, "force_n"),
        ({"force_n": (1.0, 2.0, 3.0)}, "force_n"),
        ({"distributed_load_n_per_m": (0.0, np.inf)}, "distributed_load_n_per_m"),
        ({"base_angle_rad": np.nan}, "base_angle_rad"),
        ({"s_m": [0.0, 0.2]}, "s_m"),
        ({"s_m": [[0.0, 0.1]]}, "s_m"),
        ({"method": "magic"}, "method"),
        ({"n_nodes": 2}, "n_nodes"),
        ({"ei_nm2": [1.0, 2.0, 3.0], "tip_curvature_per_m": [1.0, 2.0]}, "broadcast"),
    ],
)
def test_bad_inputs_raise_value_error(kwargs, match):
    args = {"length_m": L, "ei_nm2": 2.53e-3, "tip_curvature_per_m": 0.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        solve_beam(**args)


def test_initial_must_match_the_nodes():
    sol = solve_beam(L, 2.53e-3, 5.0, n_nodes=16)
    with pytest.raises(ValueError, match="initial"):
        solve_beam(L, 2.53e-3, 5.0, initial=sol, n_nodes=20)
    shoot = solve_beam(L, 2.53e-3, 5.0, method="shooting")
    with pytest.raises(ValueError, match="initial"):
        solve_beam(L, 2.53e-3, 5.0, initial=shoot)


def test_plot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sol = solve_beam(L, 2.53e-3, np.array([0.0, 10.0]), (0.05, -0.05), GRAVITY)
    ax = sol.plot()  # plots.plot_shapes: mm like every other figure
    assert ax.get_xlabel() == "x [mm]" and ax.get_ylabel() == "y [mm]"
    assert ax.get_aspect() == 1.0
    tips = [line.get_xydata()[-1] for line in ax.get_lines() if len(line.get_xydata()) == sol.s_m.size]
    np.testing.assert_allclose(tips, sol.tip_position_m * 1e3)
    plt.close(ax.figure)
    # a frame without a converged solution is dashed and the legend says why
    failed = dataclasses.replace(sol, success=np.array([True, False]))
    ax = failed.plot()
    styles = [line.get_linestyle() for line in ax.get_lines() if len(line.get_xydata()) == sol.s_m.size]
    assert styles == ["-", "--"]
    assert "not converged" in " ".join(t.get_text() for t in ax.get_legend().get_texts())
    plt.close(ax.figure)


@settings(max_examples=15, deadline=None)
@given(
    p=st.floats(0, 120e3),
    fx=st.floats(-0.4, 0.4),
    fy=st.floats(-0.15, 0.4),
    beta=st.floats(-0.5, 0.5),
)
def test_fast_matches_shooting_property(p, fx, fy, beta):
    args = (L, ei_of(p), k0_of(p), (fx, fy), GRAVITY, beta)
    fast = solve_beam(*args)
    ref = solve_beam(*args, method="shooting")
    assert fast.success and ref.success
    np.testing.assert_allclose(fast.tip_position_m, ref.tip_position_m, rtol=0, atol=1e-8 * L)


def test_warm_start_without_continuation():
    """``continuation=False`` reports an unstable warm landing instead of re-solving it."""
    from bendsense.mechanics.beam import DEFAULT_NODES

    ei = ei_of(0.0)
    fcr = critical_tip_load(ei, W_GRAV)
    s = np.linspace(0.0, L, 11)
    straight = np.zeros(DEFAULT_NODES)
    args = (L, np.asarray(ei), np.asarray(0.0), np.array([0.0, 1.03 * fcr]), GRAVITY, np.asarray(0.0), s)
    # beyond buckling, Newton from the straight state stays on the (unstable) straight branch
    sol = solve(*args, initial=straight, options=FastOptions(continuation=False))
    assert not sol.success and "unstable" in str(sol.message)
    np.testing.assert_allclose(sol.positions_m[..., 0], 0.0, atol=1e-12)
    # a frame well inside the convexity bound is the same with or without continuation
    mild = (L, np.asarray(ei_of(60e3)), np.asarray(k0_of(60e3)), np.array([0.05, -0.05]), GRAVITY,
            np.asarray(0.0), s)
    start = solve_beam(L, ei_of(60e3), k0_of(60e3), (0.04, -0.04), GRAVITY, s_m=s)
    a = solve(*mild, initial=start, options=FastOptions(continuation=False))
    b = solve(*mild, initial=start, options=FastOptions(continuation=True))
    assert a.success and b.success
    np.testing.assert_array_equal(a.positions_m, b.positions_m)
