"""Force estimation (paper eq. 18, 21): exact recovery, constraints, uncertainty, batches.

Reference shapes come from the beam model run forwards at known forces (the fast solver,
an independent code path from the estimator's inverse problem), so the estimate must
return the force that made them. Shapes seen by a real sensor are PCC approximations
built from the shifts ``S_i = d φ(L_i)`` of such a beam shape.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

import bendsense
from bendsense.calibration import Calibration
from bendsense.errors import ArgumentError, ConvergenceError, NoNoiseModelWarning
from bendsense.estimation import ForceEstimate, constraint_basis, estimate_force, quadrature
from bendsense.estimation._kernels import SIGMA_STEP
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.mechanics.beam import solve_beam
from bendsense.results import frame_status
from bendsense.shape.pcc import reconstruct, shifts_to_curvatures
from bendsense.sim.sensor import shifts_from_shape
from bendsense.status import Status

CFG = bendsense.load_config()
MODEL = FreeBendingModel.from_config(CFG)
L = CFG.actuator.length_m
W = CFG.weight_per_length_n_per_m
SENSOR = CFG.sensor
S_DENSE = np.linspace(0.0, L, 135)
CONSTRAINTS_1D = ("vertical", "horizontal", "direction", "normal", "follower")


def beam_shape(pressure_pa, force_n, s_m=S_DENSE):
    """The model's shape at known loads (paper eq. 13–17), solved forwards."""
    return solve_beam(L, CFG.stiffness.ei_nm2(pressure_pa), MODEL.tip_curvature_per_m(pressure_pa), force_n, W,
                      0.0, s_m, warn=False)


def pcc_curvatures(sol):
    """What the sensor measures: S_i = d φ(L_i) (paper eq. 3–4), as segment curvatures."""
    shifts = shifts_from_shape(sol.s_m, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    return shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m)


def true_force(constraint, pressure_pa, u, *, direction=(0.6, -0.8)):
    d, _ = constraint_basis(constraint, MODEL.tip_angle_rad(pressure_pa), direction=direction)
    return np.einsum("...ij,...j->...i", d, u)


# --------------------------------------------------------------------------- helpers


def test_quadrature_is_exact_per_segment_and_sums_to_length():
    lengths = SENSOR.lengths_m
    s, w = quadrature(lengths, 0.13, 41)
    assert s.size == 41 and np.all(np.diff(s) > 0) and s.max() < 0.13
    assert math.isclose(w.sum(), 0.13, rel_tol=1e-14)
    # a function with a kink in its third derivative at every junction: exact per segment
    bounds = np.concatenate(([0.0], np.cumsum(lengths)))
    seg = np.searchsorted(bounds[1:-1], s)
    f = (s - bounds[seg]) ** 3
    exact = sum(min(lengths[i], max(0.0, 0.13 - bounds[i])) ** 4 / 4 for i in range(16))
    assert math.isclose(w @ f, exact, rel_tol=1e-12)
    # fewer points than segments: one Gauss–Legendre rule over the length
    s, w = quadrature(lengths, 0.13, 5)
    assert math.isclose(w @ s**9, 0.13**10 / 10, rel_tol=1e-12)


def test_constraint_directions_and_signs():
    phi = np.array([0.0, 0.7, 2.0])
    d, dd = constraint_basis("normal", phi)
    tangent = np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    # eq. 21: F · t_tip = 0, and a positive u pushes against the pressure bending (−x)
    np.testing.assert_allclose(np.einsum("bi,bi->b", d[..., 0], tangent), 0.0, atol=1e-15)
    np.testing.assert_allclose(d[0, :, 0], [-1.0, 0.0])
    np.testing.assert_allclose(dd[..., 0], tangent, atol=1e-15)
    f, _ = constraint_basis("follower", phi, follower_angle_rad=math.pi / 2)
    np.testing.assert_allclose(f, d, atol=1e-15)
    f0, _ = constraint_basis("follower", phi, follower_angle_rad=0.0)
    np.testing.assert_allclose(f0[..., 0], tangent, atol=1e-15)
    np.testing.assert_allclose(constraint_basis("vertical")[0][..., 0], [0.0, 1.0])
    np.testing.assert_allclose(constraint_basis("horizontal")[0][..., 0], [1.0, 0.0])
    np.testing.assert_allclose(constraint_basis("none")[0], np.eye(2))


# --------------------------------------------------------------------------- exact recovery


@pytest.fixture(scope="module")
def frames():
    """Pressures 20–120 kPa, forces up to 0.4 N whose beam equilibrium is stable."""
    rng = np.random.default_rng(7)
    n = 48
    p = rng.uniform(20e3, 120e3, n)
    mag = rng.uniform(0.0, 0.4, n)
    ang = rng.uniform(0.0, 2 * math.pi, n)
    return p, mag, ang


@pytest.mark.parametrize("constraint", ("none", *CONSTRAINTS_1D))
def test_fast_recovers_the_model_force_exactly(frames, constraint):
    p, mag, ang = frames
    if constraint == "none":
        u = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)
    else:
        u = (mag * np.sign(np.cos(ang)))[:, None]
    force = true_force(constraint, p, u)
    sol = beam_shape(p, force)
    keep = sol.success  # compressive loads beyond buckling have no shape to match
    assert keep.mean() > 0.8
    est = estimate_force(sol, p, CFG, constraint=constraint, direction=(0.6, -0.8))
    assert est.success[keep].all()
    np.testing.assert_allclose(est.force_n[keep], force[keep], atol=1e-6)
    assert np.nanmax(est.residual_m[keep]) < 1e-7  # at the last beam solve, one tiny step before


def test_the_estimates_beam_is_converged_in_its_nodes(frames):
    """The estimate's beam (N_NODES nodes) is the 40-node beam to < 1e-8 rad and < 1e-9 m, and so is its shape.

    Over the frames' pressures and loads (up to 0.4 N) the beam solved on the estimate's
    nodes equals a 40-node solve; the estimate of a shape it did not make (noisy PCC
    curvatures) returns the model shape of a 40-node beam at its force, up to the final
    Gauss–Newton step below 1e-4 σ that it takes without a solve.
    """
    from bendsense.estimation import N_NODES, chebyshev_nodes_m

    p, mag, ang = frames
    force = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)
    args = (L, CFG.stiffness.ei_nm2(p), MODEL.tip_curvature_per_m(p), force, W, 0.0, chebyshev_nodes_m(L))
    coarse = solve_beam(*args, warn=False, n_nodes=N_NODES)
    fine = solve_beam(*args, warn=False, n_nodes=40)
    ok = coarse.success & fine.success
    assert ok.mean() > 0.8
    assert np.abs(coarse.angle_rad - fine.angle_rad)[ok].max() < 1e-8
    assert np.abs(coarse.positions_m - fine.positions_m)[ok].max() < 1e-9

    noise = 1.0 + 0.02 * np.random.default_rng(5).standard_normal((ok.sum(), SENSOR.n_segments))
    kappa = pcc_curvatures(beam_shape(p[ok], force[ok])) * noise
    est = estimate_force(kappa, p[ok], CFG)
    assert est.success.mean() > 0.9 and est.state.shape[-1] == N_NODES
    good = est.success
    at = solve_beam(L, CFG.stiffness.ei_nm2(p[ok][good]), MODEL.tip_curvature_per_m(p[ok][good]), est.force_n[good], W,
                    0.0, chebyshev_nodes_m(L), warn=False, n_nodes=40)
    np.testing.assert_allclose(est.tip_position_m[good], at.positions_m[:, -1], atol=1e-7)
    np.testing.assert_allclose(est.state[good], at.angle_rad, atol=1e-5)


@pytest.mark.parametrize("constraint", ("none", "vertical", "normal"))
def test_paper_method_agrees_with_fast(constraint):
    p = np.array([35e3, 100e3])
    u = np.array([[0.12, -0.2], [-0.25, 0.1]]) if constraint == "none" else np.array([[0.2], [-0.15]])
    force = true_force(constraint, p, u)
    sol = beam_shape(p, force)
    kappa = pcc_curvatures(sol)  # PCC shapes: the optimum is not the true force
    frames_ = slice(0, 1) if constraint == "none" else slice(None)  # Nelder–Mead is slow
    paper = estimate_force(kappa[frames_], p[frames_], CFG, constraint=constraint, method="paper")
    fast = estimate_force(kappa[frames_], p[frames_], CFG, constraint=constraint, objective="positions")
    assert paper.success.all() and fast.success.all()
    assert paper.method == "paper" and fast.method == "fast"
    np.testing.assert_allclose(paper.force_n, fast.force_n, atol=1e-4)
    np.testing.assert_allclose(fast.force_n, force[frames_], atol=0.03)


def test_paper_method_recovers_the_model_force(monkeypatch):
    import bendsense.estimation.paper as paper

    solves = []  # the shooting solves the paper's method makes, counted where it makes them

    def counted(*args, **kwargs):
        solves.append(kwargs.get("method"))
        return solve_beam(*args, **kwargs)

    monkeypatch.setattr(paper, "solve_beam", counted)
    sol = beam_shape(70e3, (0.1, -0.15))
    est = estimate_force(sol, 70e3, CFG, method="paper")
    np.testing.assert_allclose(est.force_n, [0.1, -0.15], atol=1e-4)
    assert set(solves) == {"shooting"} and int(est.iterations) == len(solves) > 10  # its objective's evaluations


@pytest.mark.parametrize("pressure_pa", [0.0, 20e3, 60e3, 120e3, 180e3])
def test_no_force_gives_zero(pressure_pa):
    sol = beam_shape(pressure_pa, (0.0, 0.0))
    est = estimate_force(sol, pressure_pa, CFG)
    np.testing.assert_allclose(est.force_n, 0.0, atol=1e-8)
    # through the sensor (PCC): only the model error of PCC remains
    est = estimate_force(pcc_curvatures(sol), pressure_pa, CFG)
    np.testing.assert_allclose(est.force_n, 0.0, atol=2e-3)


def test_sign_of_a_push_toward_plus_x():
    # a shape bent further toward +x than the free arc, with no beam model involved
    for p in (0.0, 20e3):
        kappa = np.full(16, float(MODEL.tip_curvature_per_m(p))) + np.linspace(4.0, 0.0, 16)
        est = estimate_force(kappa, p, CFG)
        assert est.success and est.force_n[0] > 0.01
    sol = beam_shape(50e3, (0.2, 0.0))
    assert sol.tip_position_m[0] > beam_shape(50e3, (0.0, 0.0)).tip_position_m[0]
    est = estimate_force(pcc_curvatures(sol), 50e3, CFG, constraint="horizontal")
    assert est.force_n[0] == pytest.approx(0.2, abs=0.01) and est.force_n[1] == 0.0


def contact_force(pressure_pa, u, s_m):
    """A force normal to the loaded tip tangent at ``s_m[-1]``: a fixed point in F."""
    force = np.zeros(2)
    for _ in range(60):
        phi = beam_shape(pressure_pa, force, s_m).angle_rad[-1]
        force = u * np.array([-math.cos(phi), math.sin(phi)])
    return force


def test_normal_constraint_with_the_shape_tip_angle():
    p, s = 80e3, np.linspace(0.0, SENSOR.length_m, 133)
    force = contact_force(p, 0.18, s)
    # a shape given by points: its tip angle is the one at its last point
    est = estimate_force(beam_shape(p, force, s), p, CFG, constraint="normal", tip_angle_source="shape")
    np.testing.assert_allclose(est.force_n, force, atol=1e-6)
    # through the sensor: φ(L_N) = S_N / d, and the last segment's curvature carries the
    # angle on to the actuator tip (L = 0.134 m, 2 mm beyond the sensor) where the contact acts
    kappa = pcc_curvatures(beam_shape(p, force))
    est = estimate_force(kappa, p, CFG, constraint="normal", tip_angle_source="shape")
    np.testing.assert_allclose(est.force_n, force, atol=0.01)
    tip_angle = np.sum(kappa * SENSOR.lengths_m) + kappa[-1] * (CFG.actuator.length_m - SENSOR.length_m)
    assert abs(np.dot(est.force_n, [math.sin(tip_angle), math.cos(tip_angle)])) < 1e-12  # eq. 21


def test_push_only_clamps_a_pull_to_zero():
    p = 60e3
    force = true_force("normal", p, np.array([-0.1]))  # pulling on the contact
    sol = beam_shape(p, force)
    free = estimate_force(sol, p, CFG, constraint="normal")
    np.testing.assert_allclose(free.force_n, force, atol=1e-6)
    push = estimate_force(sol, p, CFG, constraint="normal", push_only=True)
    # the clamped force is reported, but a push-only contact cannot explain a pulled shape:
    # the model stays far from it, so the frame is flagged, not ok
    assert not push.success and str(push.message).startswith("model_misfit")
    assert push.residual_m > 0.05 * CFG.actuator.length_m
    np.testing.assert_allclose(push.force_n, 0.0, atol=1e-12)
    paper = estimate_force(sol, p, CFG, constraint="normal", push_only=True, method="paper")
    np.testing.assert_allclose(paper.force_n, 0.0, atol=1e-4)


# --------------------------------------------------------------------------- uncertainty


def _cubic_calibration(noise):
    """An invertible cubic per parity (odd channels fall, even ones rise with S)."""
    c_odd = np.array([0.0, -2.0e-5, 0.0, -4.0e-6])
    c_even = np.array([0.0, 1.5e-5, 0.0, 3.0e-6])
    return Calibration(offset=np.full(16, 2000.0), coefficients_odd=c_odd, coefficients_even=c_even, degree=3,
                       delta_a_range_odd=(-1e3, 1e3), delta_a_range_even=(-1e3, 1e3), noise_std=np.full(16, noise))


def _signals_for(cal, shifts):
    """Invert the (monotone) calibration per channel by bisection: independent of the code."""
    coef = np.where((np.arange(16) % 2 == 0)[:, None], cal.coefficients_odd, cal.coefficients_even)
    lo, hi = np.full(16, -1e3), np.full(16, 1e3)
    f = lambda x: sum(coef[:, j] * x**j for j in range(4))  # noqa: E731
    sign = np.sign(coef[:, 1])
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        above = sign * (f(mid) - shifts) > 0
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    return cal.offset + 0.5 * (lo + hi)


@pytest.mark.parametrize(("constraint", "pressure_pa", "u", "noise"), [
    ("none", 60e3, (0.1, -0.15), 0.05),
    ("none", 25e3, (-0.05, 0.1), 0.03),
    ("normal", 90e3, (0.2,), 0.15),
])
def test_two_sigma_coverage_of_the_true_force(constraint, pressure_pa, u, noise):
    """≥ 500 noisy frames as one batch: the true force lies within ±2σ in 90–98 %.

    The signals are those of the true beam shape seen by the sensor, ``S_i = d φ(L_i)``,
    through a known cubic calibration, plus Gaussian noise. Their noise-free PCC
    reconstruction differs from the beam shape (PCC model error), which biases the
    estimate; the noise level is chosen so that this bias is a small fraction of σ,
    and the test checks that it is.
    """
    known = CFG.replace(parameter_covariance=None)  # the true beam has the config's parameters: σ is the noise's
    cal = _cubic_calibration(noise)  # noise in signal units: σ_S ≈ 2e-5 m per unit
    force = true_force(constraint, pressure_pa, np.array(u))
    sol = beam_shape(pressure_pa, force)
    shifts = shifts_from_shape(sol.s_m, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    clean = _signals_for(cal, shifts)
    np.testing.assert_allclose(cal.shifts_m(clean), shifts, atol=1e-12)
    bias = estimate_force(reconstruct(clean, cal, SENSOR), pressure_pa, known, constraint=constraint,
                          calibration=cal)
    n = 600
    rng = np.random.default_rng(11)
    signals = clean + noise * rng.standard_normal((n, 16))
    est = estimate_force(reconstruct(signals, cal, SENSOR), pressure_pa, known, constraint=constraint,
                         calibration=cal)
    # χ² beyond chance (p < 0.001) flags a frame model_misfit, its force kept: about 1 in 1000
    misfit = np.char.startswith(est.message.astype(str), "model_misfit")
    assert (est.success | misfit).all() and misfit.sum() <= 3 and est.uncertainty == "propagated"
    std = est.std_n.mean(axis=0)
    assert np.all(np.abs(bias.force_n - force) < 0.35 * std + 1e-12)  # the PCC bias is small against σ
    # the spread of the estimates is what the propagation predicts
    active = std > 1e-9
    np.testing.assert_allclose(est.force_n.std(axis=0)[active], std[active], rtol=0.12)
    inside = np.abs(est.force_n - force) <= 2.0 * est.std_n
    coverage = inside[:, active].mean(axis=0)
    assert np.all((coverage >= 0.90) & (coverage <= 0.98)), coverage


@pytest.mark.parametrize(("constraint", "source"), [("none", "model"), ("normal", "model"), ("normal", "shape")])
def test_uncertainty_matches_finite_differences_of_the_estimator(constraint, source):
    """std with one noisy channel (σ_S = 1, unit slope) is |∂F/∂S_i|, by differences.

    The propagation is the Gauss–Newton linearisation (it drops the residual times the
    model's second derivative), exact for a zero residual; the true force satisfies
    the constraint so that only the small PCC residual is left.
    """
    p = 70e3
    if constraint == "none":
        force = np.array([0.08, -0.12])
    elif source == "model":
        force = true_force("normal", p, np.array([0.15]))
    else:
        force = contact_force(p, 0.15, np.linspace(0.0, SENSOR.length_m, 133))
    sol = beam_shape(p, force)
    shifts = shifts_from_shape(sol.s_m, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)

    def est(s, **kw):
        kappa = shifts_to_curvatures(s, SENSOR.lengths_m, SENSOR.strip_gap_m)
        return estimate_force(kappa, p, CFG, constraint=constraint, tip_angle_source=source, objective="positions",
                              **kw)

    h = 1e-7
    for i in (0, 7, 15):
        noise = np.zeros(16)
        noise[i] = 1.0
        std = est(shifts, noise_std=noise).std_n
        up, down = shifts.copy(), shifts.copy()
        up[i] += h
        down[i] -= h
        deriv = (est(up, xtol_n=1e-13).force_n - est(down, xtol_n=1e-13).force_n) / (2 * h)
        np.testing.assert_allclose(std, np.abs(deriv), rtol=2e-3, atol=1e-6 * np.abs(deriv).max())


def test_axial_load_on_a_straight_actuator_is_not_identifiable():
    straight = np.zeros(16)
    est = estimate_force(straight, 0.0, CFG, noise_std=1e-6)
    assert est.success
    assert np.isfinite(est.std_n[0]) and est.std_n[1] == np.inf
    np.testing.assert_allclose(est.force_n, 0.0, atol=1e-12)
    # results.csv does not call it ok (DESIGN section 3): its axial force is no measurement
    shape = SimpleNamespace(tip_angle_rad=np.zeros(1), curvature_per_m=straight[None], extrapolated=np.zeros(1, bool))
    assert list(frame_status(shape, est)) == ["not_identifiable"]
    # nearly straight (a small side load): the axial component is determined, but poorly
    kappa = pcc_curvatures(beam_shape(0.0, (0.01, 0.0)))
    est = estimate_force(kappa, 0.0, CFG, noise_std=1e-6)
    assert est.success
    assert est.std_n[1] > 20 * est.std_n[0]


@pytest.mark.parametrize("objective", ["angles", "positions"])
def test_no_noise_model_gives_no_sigma_and_one_warning(objective):
    """Never a residual-based σ that looks precise: NaN, uncertainty="none", one warning."""
    sol = beam_shape(60e3, (0.1, 0.1))
    with pytest.warns(NoNoiseModelWarning, match="no noise model") as record:
        est = estimate_force(pcc_curvatures(sol), 60e3, CFG, objective=objective)
    assert len(record) == 1 and record[0].filename == __file__  # it points at the caller's line
    assert est.success and np.all(np.isfinite(est.force_n))
    assert est.uncertainty == "none"
    assert np.isnan(est.std_n).all() and np.isnan(est.covariance_n2).all()
    with_noise = estimate_force(pcc_curvatures(sol), 60e3, CFG, objective=objective, noise_std=0.01)
    assert with_noise.uncertainty == "propagated" and np.all(with_noise.std_n > 0)


# --------------------------------------------------------------------------- batches


def test_batch_shapes_broadcast_and_match_single_frames():
    rng = np.random.default_rng(5)
    p = rng.uniform(30e3, 110e3, (2, 3))
    force = rng.uniform(-0.2, 0.2, (2, 3, 2))
    kappa = pcc_curvatures(beam_shape(p, force))
    est = estimate_force(kappa, p, CFG)
    assert est.force_n.shape == (2, 3, 2) and est.std_n.shape == (2, 3, 2)
    assert est.covariance_n2.shape == (2, 3, 2, 2) and est.residual_m.shape == (2, 3)
    assert est.success.shape == (2, 3) and est.message.shape == (2, 3) and est.iterations.shape == (2, 3)
    one = estimate_force(kappa[1, 2], p[1, 2], CFG)
    assert one.force_n.shape == (2,) and isinstance(one.message, str)
    np.testing.assert_allclose(est.force_n[1, 2], one.force_n, atol=1e-9)
    # one shape, many pressures
    many = estimate_force(kappa[0, 0], np.array([40e3, 60e3, 80e3]), CFG)
    assert many.force_n.shape == (3, 2)
    np.testing.assert_allclose(many.force_n[1], estimate_force(kappa[0, 0], 60e3, CFG).force_n, atol=1e-9)


def test_warm_start_along_a_smooth_series_reaches_the_cold_optimum_at_no_more_cost():
    t = np.linspace(0.0, 2.0, 200)
    p = 70e3 + 40e3 * np.sin(2 * math.pi * 0.5 * t)
    force = np.stack([0.15 * np.sin(2 * math.pi * t), -0.1 + 0.05 * np.cos(math.pi * t)], axis=-1)
    kappa = pcc_curvatures(beam_shape(p, force))
    warm = estimate_force(kappa, p, CFG)
    cold = estimate_force(kappa, p, CFG, warm_start=False)
    assert warm.success.all() and cold.success.all()
    np.testing.assert_allclose(warm.force_n, cold.force_n, atol=1e-8)
    # the integrated moment balance starts a noise-free cold frame so close that it
    # converges in two solves (the start and one step), as a warm frame does
    assert warm.iterations.mean() <= cold.iterations.mean() <= 2.1
    # the previous estimate as the start of a single real-time frame
    prev = estimate_force(kappa[100], p[100], CFG)
    nxt = estimate_force(kappa[101], p[101], CFG, initial=prev)
    np.testing.assert_allclose(nxt.force_n, warm.force_n[101], atol=1e-8)


def test_failed_frames_are_flagged_not_raised():
    good = pcc_curvatures(beam_shape(60e3, (0.1, -0.1)))
    # an arc at zero pressure: only a compressive load beyond buckling would bend the
    # straight actuator so; no stable equilibrium of the model matches it
    kappa = np.stack([good, np.full(16, 2.0)])
    est = estimate_force(kappa, np.array([60e3, 0.0]), CFG)
    assert est.success.tolist() == [True, False]
    assert est.message[0] == "converged" and est.message[1] != "converged"
    assert np.isnan(est.force_n[1]).all() and np.isfinite(est.force_n[0]).all()
    est = estimate_force(kappa, np.array([60e3, 0.0]), CFG, max_iter=0)
    assert not est.success.any() and all("no convergence" in m for m in est.message)
    with pytest.raises(ConvergenceError, match="1 of 2 force estimate"):
        estimate_force(kappa, np.array([60e3, 0.0]), CFG, strict=True)


def test_an_estimate_does_not_depend_on_the_frames_estimated_before():
    """The kernels work in buffers kept with the estimate's constants: nothing a frame leaves there reaches another.

    Frames estimated alone give the same numbers bit for bit before and after (and in the
    reverse order of) frames that fail, are not identifiable, or run as a warm series.
    """
    rng = np.random.default_rng(11)
    p = rng.uniform(30e3, 100e3, 6)
    kappa = pcc_curvatures(beam_shape(p, rng.uniform(-0.15, 0.15, (6, 2))))
    cal = _cubic_calibration(0.2)

    def alone(order):
        return {i: estimate_force(kappa[i], p[i], CFG, calibration=cal) for i in order}

    first = alone(range(6))
    assert not estimate_force(np.full(16, 40.0), 0.0, CFG, calibration=cal).success  # no stable equilibrium
    assert estimate_force(np.full(16, 2.0), 0.0, CFG, calibration=cal).status == Status.NOT_IDENTIFIABLE
    assert estimate_force(kappa[::-1], p[::-1], CFG, calibration=cal).success.all()  # a chained series
    again = alone(range(5, -1, -1))
    for i in range(6):
        for field in ("force_n", "std_n", "covariance_parts_n2", "residual_m", "chi2_per_dof", "iterations",
                      "status", "state", "guess_n", "residual_rad", "jacobian_rad_per_n", "model_factor_rad"):
            np.testing.assert_array_equal(getattr(again[i], field), getattr(first[i], field), err_msg=field)


def test_bad_arguments_name_the_field():
    kappa = np.zeros(16)
    with pytest.raises(ValueError, match="constraint: must be one of"):
        estimate_force(kappa, 0.0, CFG, constraint="sideways")
    with pytest.raises(ValueError, match="method: must be one of"):
        estimate_force(kappa, 0.0, CFG, method="magic")
    with pytest.raises(TypeError, match="colour"):
        estimate_force(kappa, 0.0, CFG, colour="red")
    with pytest.raises(ValueError, match="push_only: only for the 1-D constraints"):
        estimate_force(kappa, 0.0, CFG, push_only=True)
    with pytest.raises(ValueError, match="shape: expected"):
        estimate_force(np.zeros(15), 0.0, CFG)
    with pytest.raises(ValueError, match=r"^pressure_pa: must be finite, got nan$"):
        estimate_force(kappa, np.nan, CFG)
    many = np.full(1000, 5e4)
    many[[7, 500]] = np.nan  # the first named, not the whole array
    with pytest.raises(ValueError, match=r"^pressure_pa: must be finite, got nan at frame 7 \(2 of 1000 frames\)$"):
        estimate_force(np.broadcast_to(kappa, (1000, kappa.size)), many, CFG)
    with pytest.raises(ValueError, match="direction: expected a unit vector"):
        estimate_force(kappa, 0.0, CFG, constraint="direction", direction=(1.0, 1.0))
    with pytest.raises(ValueError, match="pressure_pa: shape"):
        estimate_force(np.zeros((3, 16)), np.zeros(2), CFG)


def test_result_object(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sol = beam_shape(60e3, (0.1, -0.1))
    est = estimate_force(sol, 60e3, None)  # None: the paper's config
    assert isinstance(est, ForceEstimate) and est.constraint == "none" and est.wall_time_s > 0
    d = est.to_dict()
    assert d["force_n"] == pytest.approx([0.1, -0.1], abs=1e-6) and d["success"] is True
    ax = est.plot(shape=sol)  # plots.plot_force: mm, an arrow from the model's tip
    assert ax.get_xlabel() == "x [mm]" and "F = (0.1" in ax.get_title()
    arrow = [a for a in ax.texts if hasattr(a, "xy")][0]
    np.testing.assert_allclose(arrow.xyann, est.tip_position_m * 1e3)
    np.testing.assert_allclose(np.subtract(arrow.xy, arrow.xyann), 100.0 * est.force_n)
    batch = estimate_force(pcc_curvatures(beam_shape(np.full(4, 60e3), np.zeros((4, 2)))), 60e3, CFG,
                           noise_std=1e-6)
    ax = batch.plot(t_s=np.arange(4) * 0.1)
    assert ax.get_xlabel() == "t [s]" and len(ax.collections) == 2  # the two ±2σ bands
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), batch.force_n[:, 0])
    plt.close("all")


@pytest.mark.parametrize("constraint", ("none", "vertical", "normal"))
def test_single_frame_path_equals_the_batched_path(frames, constraint):
    """One frame takes a lean path of its own; it must give the batch's numbers, cold and warm."""
    p, mag, ang = frames
    idx = np.arange(0, 48, 3)
    force = np.column_stack([mag[idx] * np.cos(ang[idx]), mag[idx] * np.sin(ang[idx])]) * 0.5
    kappa = pcc_curvatures(beam_shape(p[idx], force))
    cal = _cubic_calibration(0.2)
    batch = estimate_force(kappa, p[idx], CFG, constraint=constraint, warm_start=False, calibration=cal)
    previous = None
    for i in range(idx.size):
        one = estimate_force(kappa[i], p[idx][i], CFG, constraint=constraint, calibration=cal)
        assert one.force_n.shape == (2,)
        np.testing.assert_allclose(one.force_n, batch.force_n[i], atol=1e-12)
        np.testing.assert_allclose(one.std_n, batch.std_n[i], rtol=1e-9)
        assert str(one.message) == str(batch.message[i]) and int(one.iterations) == int(batch.iterations[i])
        # a batch of one frame keeps its batch axis and the same numbers
        one_of_batch = estimate_force(kappa[i : i + 1], p[idx][i : i + 1], CFG, constraint=constraint, calibration=cal)
        assert one_of_batch.force_n.shape == (1, 2)
        np.testing.assert_allclose(one_of_batch.std_n[0], one.std_n, rtol=1e-12)
        # warm-started from the previous frame, as the live view does: the same optimum, to
        # the SIGMA_STEP σ within which each converges (kernels.SIGMA_STEP)
        warm = estimate_force(kappa[i], p[idx][i], CFG, constraint=constraint, calibration=cal, initial=previous)
        tol = np.maximum(1e-8, 2 * SIGMA_STEP * np.nan_to_num(one.std_n, posinf=0.0))
        assert np.all(np.abs(warm.force_n - batch.force_n[i]) <= tol)
        previous = warm


def _pcc_points(kappa, s_m):
    """Points (M, 2) at ``s_m`` of arcs of curvatures ``kappa`` on the sensor's segments (closed form, base angle 0)."""
    start = np.concatenate(([0.0], np.cumsum(SENSOR.lengths_m)))
    phi, x, y, out = 0.0, 0.0, 0.0, []
    for i, k in enumerate(kappa):
        for t in s_m[(s_m >= start[i]) & (s_m < start[i + 1])] - start[i]:  # x = ∫ sin φ, y = ∫ cos φ
            out.append((x + (math.cos(phi) - math.cos(phi + k * t)) / k,
                        y + (math.sin(phi + k * t) - math.sin(phi)) / k))
        x += (math.cos(phi) - math.cos(phi + k * SENSOR.lengths_m[i])) / k
        y += (math.sin(phi + k * SENSOR.lengths_m[i]) - math.sin(phi)) / k
        phi += k * SENSOR.lengths_m[i]
    return np.array(out)


@pytest.mark.parametrize("constraint", ("none", "normal"))
def test_the_estimate_reports_the_beam_at_its_own_force(frames, constraint):
    """The iteration stops once the error left is below SIGMA_STEP σ, its last step taken
    without a beam solve: the shape it reports (nodes' angles, tip, residual) must be the
    beam's at the force it reports, not the iterate's before it (tens of µm away).
    Checked against the forward solver at the reported force, on noisy frames."""
    p, mag, ang = frames
    force = np.column_stack([mag * np.cos(ang), mag * np.sin(ang)]) * 0.5
    noisy = pcc_curvatures(beam_shape(p, force)) + np.random.default_rng(3).normal(scale=0.3, size=(p.size, 16))
    est = estimate_force(noisy, p, CFG, constraint=constraint, warm_start=False, calibration=_cubic_calibration(0.2))
    ok = est.status == Status.OK
    assert ok.sum() >= 40
    nodes = bendsense.estimation.chebyshev_nodes_m(L)
    sol = beam_shape(p[ok], est.force_n[ok], nodes)
    # the step's square is left (2e-6 rad here); the iterate before it was up to 2e-3 rad away
    np.testing.assert_allclose(est.state[ok], sol.angle_rad, rtol=0, atol=2e-5)
    np.testing.assert_allclose(est.tip_position_m[ok], sol.tip_position_m, rtol=0, atol=1e-5 * L)
    # the residual: the RMS distance over [0, Lc] of the beam there from the PCC shape, by the estimate's quadrature
    s, w = quadrature(SENSOR.lengths_m, min(SENSOR.lengths_m.sum(), L), CFG.estimation.n_points)
    model = beam_shape(p[ok], est.force_n[ok], s).positions_m
    measured = np.array([_pcc_points(k, s) for k in noisy[ok]])
    rms = np.sqrt(np.einsum("j,bj->b", w, ((model - measured) ** 2).sum(-1)) / w.sum())
    np.testing.assert_allclose(est.residual_m[ok], rms, rtol=1e-3, atol=2e-7)


def test_option_values_of_the_wrong_kind_name_the_option():
    kappa = np.full(16, 5.0)
    with pytest.raises(ArgumentError, match="push_only: expected True or False, got 'yes'"):
        estimate_force(kappa, 60e3, CFG, constraint="normal", push_only="yes")
    with pytest.raises(ArgumentError, match="follower_angle_rad: expected a finite angle"):
        estimate_force(kappa, 60e3, CFG, constraint="follower", follower_angle_rad=float("nan"))
    with pytest.raises(ArgumentError, match="xtol_n: expected a finite tolerance"):
        estimate_force(kappa, 60e3, CFG, xtol_n=float("nan"))
    with pytest.raises(ArgumentError, match="n_points: must be between 3 and 1000"):
        estimate_force(kappa, 60e3, CFG, n_points=10**9)
    with pytest.raises(ArgumentError, match="config: expected a Config"):
        estimate_force(kappa, 60e3, "configs/paper.yaml")
