"""The beam with its point force along the body (``solve_beam(..., contact_s_m=)``, issue 23).

References written here or independent of ``bendsense.mechanics.beam``: scipy's ``solve_bvp`` with
the BVP split at s_c (``tests/forward_model.py``), linear beam theory of a cantilever
loaded at s_c, the free arc beyond the contact without weight, and central finite
differences of both solvers for ∂/∂s_c.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from bendsense.errors import ArgumentError
from bendsense.mechanics.beam import solve_beam

sys.path.insert(0, str(Path(__file__).parents[1]))
from forward_model import solve_beam_bvp  # noqa: E402

L = 0.134
W = (0.0, -0.03927 * 9.81 / L)  # the paper actuator's weight per length, upright rig [N/m]


def ei_of(p_pa):
    return 2.53e-3 + 1.25e-8 * p_pa


def k0_of(p_pa):
    return 3.0 * p_pa / 120e3 / L


CASES = [(p, F, f) for p in (20e3, 70e3, 115e3) for F in ((0.3, 0.0), (-0.2, 0.1), (0.1, -0.25), (0.05, 0.3))
         for f in (0.15, 0.3, 0.5, 0.7, 0.85, 0.97)]


@pytest.mark.parametrize("p, force, frac", CASES[::3] + CASES[1::7])
def test_tip_against_solve_bvp(p, force, frac):
    ref = solve_beam_bvp(L, ei_of(p), k0_of(p), force, W, contact_s_m=frac * L, tol=1e-10)
    sol = solve_beam(L, ei_of(p), k0_of(p), force, W, contact_s_m=frac * L)
    assert sol.success
    np.testing.assert_allclose(sol.tip_position_m, ref.tip_position_m, rtol=0, atol=1e-6 * L)
    assert sol.tip_angle_rad == pytest.approx(ref.tip_angle_rad, abs=1e-6)
    # the angles along the body, on both sides of the contact
    s = np.linspace(0.0, L, 27)
    ref = solve_beam_bvp(L, ei_of(p), k0_of(p), force, W, s_m=s, contact_s_m=frac * L, tol=1e-10)
    sol = solve_beam(L, ei_of(p), k0_of(p), force, W, s_m=s, contact_s_m=frac * L)
    np.testing.assert_allclose(sol.angle_rad, ref.angle_rad, rtol=0, atol=2e-6)
    np.testing.assert_allclose(sol.positions_m, ref.positions_m, rtol=0, atol=1e-6 * L)


def test_batch_of_contacts_against_solve_bvp_everywhere():
    """All the cases in one batch (per-frame s_c), at the estimate's 16 nodes: within 2e-6 L."""
    p = np.array([c[0] for c in CASES])
    F = np.array([c[1] for c in CASES])
    sc = np.array([c[2] for c in CASES]) * L
    sol = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=sc, n_nodes=16)
    assert sol.success.all()
    assert sol.tip_position_m.shape == (len(CASES), 2)
    for i in range(0, len(CASES), 5):
        ref = solve_beam_bvp(L, ei_of(p[i]), k0_of(p[i]), F[i], W, contact_s_m=sc[i], tol=1e-10)
        np.testing.assert_allclose(sol.tip_position_m[i], ref.tip_position_m, rtol=0, atol=2e-6 * L)


@pytest.mark.parametrize("frac", [0.2, 0.5, 0.8])
def test_linear_theory_load_at_sc(frac):
    """A straight beam (K0 = 0, no weight) under a small load F ⟂ at a: tip deflection F a² (3L − a) / (6 EI)."""
    ei = 2.53e-3
    a = frac * L
    force = 1e-4 * ei / L**2  # F L²/EI = 1e-4: the nonlinear terms are ~1e-8 relative
    sol = solve_beam(L, ei, 0.0, (force, 0.0), contact_s_m=a, s_m=np.array([0.0, a, L]))
    assert sol.tip_position_m[0] == pytest.approx(force * a * a * (3 * L - a) / (6 * ei), rel=1e-6)
    assert sol.positions_m[1, 0] == pytest.approx(force * a**3 / (3 * ei), rel=1e-6)
    assert sol.tip_angle_rad == pytest.approx(force * a * a / (2 * ei), rel=1e-6)
    assert sol.tip_position_m[1] == pytest.approx(L, abs=1e-7 * L)


def test_beyond_the_contact_the_beam_is_the_free_arc():
    """Without weight nothing loads the beam beyond s_c: φ'(s) = K0 there (DESIGN section 2, moment-free)."""
    p, sc = 60e3, 0.55 * L
    s = np.linspace(sc, L, 9)
    sol = solve_beam(L, ei_of(p), k0_of(p), (0.2, -0.1), contact_s_m=sc, s_m=s)
    np.testing.assert_allclose(sol.angle_rad - sol.angle_rad[0], k0_of(p) * (s - sc), rtol=0, atol=1e-9)
    # ... and before it the force bends it: the curvature differs from K0
    inside = solve_beam(L, ei_of(p), k0_of(p), (0.2, -0.1), contact_s_m=sc, s_m=np.array([0.0, 0.5 * sc]))
    assert abs(inside.angle_rad[1] - k0_of(p) * 0.5 * sc) > 1e-3


def test_tip_contact_is_the_tip_load_and_the_limit_is_continuous():
    p, F = 60e3, (0.15, -0.1)
    tip = solve_beam(L, ei_of(p), k0_of(p), F, W, sensitivities=True)
    at_l = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=L, sensitivities=True)
    np.testing.assert_array_equal(at_l.angle_rad, tip.angle_rad)
    np.testing.assert_array_equal(at_l.positions_m, tip.positions_m)
    near = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=L * (1 - 1e-6))
    np.testing.assert_allclose(near.tip_position_m, tip.tip_position_m, rtol=0, atol=1e-6 * L)
    # the one-sided derivative at the tip predicts the move inward
    h = 1e-4 * L
    inward = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=L - h)
    predicted = tip.tip_position_m - h * tip.dtip_position_dcontact
    np.testing.assert_allclose(inward.tip_position_m, predicted, rtol=0, atol=1e-8 * L)


def test_a_push_along_the_body_bends_less_than_at_the_tip():
    """The same push toward +x at s_c < L moves the tip less toward +x, and less the nearer the base."""
    p, F = 40e3, (0.15, 0.0)
    free = solve_beam(L, ei_of(p), k0_of(p), (0.0, 0.0), W).tip_position_m[0]
    moves = [solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=f * L).tip_position_m[0] - free
             for f in (0.3, 0.6, 0.9, 1.0)]
    assert all(m > 0 for m in moves)
    assert np.all(np.diff(moves) > 0)


@pytest.mark.parametrize("frac", [0.35, 0.6, 0.8])
def test_contact_sensitivity_matches_finite_differences_of_the_solver(frac):
    p, F = 80e3, np.array([0.12, -0.2])
    s = np.linspace(0.0, L, 17)
    sol = solve_beam(L, ei_of(p), k0_of(p), F, W, s_m=s, contact_s_m=frac * L, sensitivities=True)
    h = 1e-5 * L
    hi = solve_beam(L, ei_of(p), k0_of(p), F, W, s_m=s, contact_s_m=frac * L + h)
    lo = solve_beam(L, ei_of(p), k0_of(p), F, W, s_m=s, contact_s_m=frac * L - h)
    scale = np.abs(sol.dangle_dcontact).max()
    assert scale > 0.5  # rad/m: a contact moving 1 mm turns the tip by ~1 mrad
    np.testing.assert_allclose(sol.dangle_dcontact, (hi.angle_rad - lo.angle_rad) / (2 * h), rtol=0,
                               atol=1e-4 * scale)
    np.testing.assert_allclose(sol.dpositions_dcontact, (hi.positions_m - lo.positions_m) / (2 * h), rtol=0,
                               atol=1e-4 * np.abs(sol.dpositions_dcontact).max())
    np.testing.assert_allclose(sol.dtip_position_dcontact, (hi.tip_position_m - lo.tip_position_m) / (2 * h), rtol=0,
                               atol=1e-4 * np.abs(sol.dtip_position_dcontact).max())
    # the force sensitivities at a contact too
    e = 1e-6
    for b in range(2):
        dF = np.zeros(2)
        dF[b] = e
        up = solve_beam(L, ei_of(p), k0_of(p), F + dF, W, s_m=s, contact_s_m=frac * L)
        dn = solve_beam(L, ei_of(p), k0_of(p), F - dF, W, s_m=s, contact_s_m=frac * L)
        np.testing.assert_allclose(sol.dangle_dforce[:, b], (up.angle_rad - dn.angle_rad) / (2 * e), rtol=0,
                                   atol=1e-5 * np.abs(sol.dangle_dforce).max())


def test_contact_sensitivity_matches_finite_differences_of_solve_bvp():
    p, F, sc = 50e3, (0.1, 0.2), 0.7 * L
    coils = np.cumsum((10e-3,) + (14e-3,) * 8 + (10e-3,))[:-1]
    sol = solve_beam(L, ei_of(p), k0_of(p), F, W, s_m=coils, contact_s_m=sc, sensitivities=True)
    h = 1e-3 * L
    hi = solve_beam_bvp(L, ei_of(p), k0_of(p), F, W, s_m=coils, contact_s_m=sc + h, tol=1e-11)
    lo = solve_beam_bvp(L, ei_of(p), k0_of(p), F, W, s_m=coils, contact_s_m=sc - h, tol=1e-11)
    fd = (hi.angle_rad - lo.angle_rad) / (2 * h)
    np.testing.assert_allclose(sol.dangle_dcontact, fd, rtol=0, atol=2e-3 * np.abs(fd).max())


def test_batch_broadcasts_contacts_and_matches_single_frames():
    p = np.array([30e3, 60e3, 90e3])
    sc = np.array([0.5 * L, L, 0.8 * L])
    F = np.array([[0.1, 0.0], [0.0, -0.1], [-0.1, 0.1]])
    batch = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=sc, sensitivities=True)
    np.testing.assert_array_equal(batch.contact_s_m, sc)
    assert batch.dangle_dcontact.shape == (3, 101)
    for i in range(3):
        one = solve_beam(L, ei_of(p[i]), k0_of(p[i]), F[i], W, contact_s_m=sc[i], sensitivities=True)
        np.testing.assert_allclose(batch.angle_rad[i], one.angle_rad, rtol=0, atol=1e-14)
        np.testing.assert_allclose(batch.dangle_dcontact[i], one.dangle_dcontact, rtol=0, atol=1e-12)
    # one contact for every frame
    same = solve_beam(L, ei_of(p), k0_of(p), F, W, contact_s_m=0.5 * L)
    np.testing.assert_allclose(same.angle_rad[0], batch.angle_rad[0], rtol=0, atol=1e-12)


def test_warm_start_at_a_contact():
    p, sc = 70e3, 0.6 * L
    cold = solve_beam(L, ei_of(p), k0_of(p), (0.2, 0.1), W, contact_s_m=sc)
    warm = solve_beam(L, ei_of(p), k0_of(p), (0.21, 0.1), W, contact_s_m=sc, initial=cold)
    ref = solve_beam(L, ei_of(p), k0_of(p), (0.21, 0.1), W, contact_s_m=sc)
    np.testing.assert_allclose(warm.angle_rad, ref.angle_rad, rtol=0, atol=1e-10)
    assert warm.iterations < cold.iterations


def test_buckling_at_a_contact_is_reported():
    """A compressive force at s_c buckles a straight beam at π² EI / (4 s_c²) (no weight)."""
    ei, sc = 2.53e-3, 0.5 * L
    critical = math.pi**2 * ei / (4 * sc**2)
    fy = np.array([0.97, 0.995, 1.005, 1.03]) * -critical
    sol = solve_beam(L, ei, 0.0, np.stack([np.zeros(4), fy], axis=-1), contact_s_m=sc, warn=False)
    np.testing.assert_array_equal(sol.success, [True, True, False, False])
    assert all("unstable" in m for m in sol.message[2:])
    # an imperfect beam (small lateral load) takes the stable, bent-over branch instead
    bent = solve_beam(L, ei, 0.0, (0.01, -1.03 * critical), contact_s_m=sc)
    assert bent.success and bent.positions_m[50, 0] > 0.1 * sc


@pytest.mark.parametrize("value, match", [(0.0, "contact_s_m: expected 0 < s_c <= length_m"),
                                          (-0.01, "contact_s_m: expected 0 < s_c"),
                                          (0.2, "contact_s_m: expected 0 < s_c <= length_m = 0.134 m, got 0.2"),
                                          (float("nan"), "contact_s_m: must be finite"),
                                          ("a", "contact_s_m: expected numbers")])
def test_bad_contact_raises(value, match):
    with pytest.raises(ArgumentError, match=match):
        solve_beam(L, 2.53e-3, 5.0, (0.1, 0.0), contact_s_m=value)


def test_contact_needs_the_fast_method_and_enough_nodes():
    with pytest.raises(ArgumentError, match="contact_s_m: only available with method='fast'"):
        solve_beam(L, 2.53e-3, 5.0, (0.1, 0.0), contact_s_m=0.1, method="shooting")
    with pytest.raises(ArgumentError, match="n_nodes: a force along the body"):
        solve_beam(L, 2.53e-3, 5.0, (0.1, 0.0), contact_s_m=0.1, n_nodes=8)
    with pytest.raises(ArgumentError, match="contact_s_m: shape"):
        solve_beam(L, np.full(3, 2.53e-3), 5.0, (0.1, 0.0), contact_s_m=np.full(2, 0.1))
