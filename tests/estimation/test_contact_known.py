"""The force at a known contact point: ``estimate_force(load="contact", contact_s_m=X)`` (issue 23).

Truths come from the independent forward model (tests/forward_model.py: scipy
``solve_bvp`` with the BVP split at s_c, its own free bending, a hidden nonlinear sensor
that ``Calibration.fit`` calibrates), never from the library's solvers.
"""

import numpy as np
import pytest
from forward_model import HiddenSensor, forward
from helpers import curvatures_for as _kappa

import bendsense
from bendsense.calibration import Calibration
from bendsense.errors import ArgumentError
from bendsense.estimation import estimate_force
from bendsense.mechanics.beam import solve_beam
from bendsense.shape.pcc import reconstruct
from bendsense.status import Status

CFG = bendsense.load_config()
SENSOR = CFG.sensor
L = CFG.actuator.length_m
# the truths have the config's own parameters: known exactly, no parameter_covariance (σ is noise and calibration)
KNOWN = CFG.replace(parameter_covariance=None)


def _loads(rng, n, lo=0.5, hi=0.95):
    """Pressures 20–120 kPa, forces up to 0.25 N in every direction, contacts at lo–hi L."""
    p = rng.uniform(20e3, 120e3, n)
    a, r = rng.uniform(0.0, 2.0 * np.pi, n), 0.25 * np.sqrt(rng.uniform(size=n))
    return p, np.stack([r * np.cos(a), r * np.sin(a)], axis=-1), rng.uniform(lo, hi, n) * L


@pytest.fixture(scope="module")
def truths():
    p, force, sc = _loads(np.random.default_rng(23), 16, 0.3, 1.0)
    return p, force, sc, np.array([forward(CFG, *a, contact_s_m=s).shifts_m for *a, s in zip(p, force, sc)])


def test_noise_free_exact_shifts_give_the_force_at_the_contact(truths):
    p, force, sc, shifts = truths
    est = estimate_force(_kappa(shifts), p, KNOWN, load="contact", contact_s_m=sc, noise_std=1e-7)
    assert est.success.all(), est.message
    assert np.abs(est.force_n - force).max() <= 1e-3  # 1 mN (DESIGN section 5)
    assert np.abs(est.force_n - force).max() <= 1e-4  # in fact: as the tip load's 0.1 mN
    assert est.load == "contact"
    np.testing.assert_array_equal(est.contact_s_m, sc)
    np.testing.assert_array_equal(est.contact_std_m, 0.0)
    # the tip model on the same shapes is far off: the location matters
    tip = estimate_force(_kappa(shifts), p, KNOWN, noise_std=1e-7)
    off = sc < 0.9 * L
    assert np.nanmedian(np.abs(tip.force_n - force).max(axis=1)[off]) > 0.02  # (NaN: the tip model finds no force)


@pytest.mark.parametrize("source", ["model", "shape"])
def test_normal_constraint_at_the_contact(source):
    """A frictionless push at s_c: F ⟂ t(s_c), t of the free arc (K0 s_c) or of the reconstructed shape."""
    p, sc = 60e3, 0.7 * L
    k0 = bendsense.mechanics.actuator.FreeBendingModel.from_config(CFG).tip_curvature_per_m(p)
    phi_c = k0 * sc
    force = 0.15 * np.array([-np.cos(phi_c), np.sin(phi_c)])  # n = (−cos φ, sin φ): toward −x at the free arc
    t = forward(CFG, p, force, contact_s_m=sc)
    est = estimate_force(_kappa(t.shifts_m), p, KNOWN, "normal", load="contact", contact_s_m=sc, noise_std=1e-7,
                         tip_angle_source=source)
    assert est.success
    if source == "model":  # the truth satisfies the constraint: exact
        np.testing.assert_allclose(est.force_n, force, atol=1e-5)
        angle = phi_c
    else:  # the shape's angle at s_c: the pushed shape's (the PCC angle at s_c, from the segment curvatures)
        kappa = _kappa(t.shifts_m)
        bounds = np.concatenate([[0.0], np.cumsum(SENSOR.lengths_m)])
        g = np.searchsorted(bounds, sc) - 1
        angle = (kappa[:g] * SENSOR.lengths_m[:g]).sum() + kappa[g] * (sc - bounds[g])
        assert abs(angle - phi_c) > 0.02  # the push turns the body at s_c: not the free arc's angle
    tangent = np.array([np.sin(angle), np.cos(angle)])
    assert abs(est.force_n @ tangent) < 1e-12
    assert est.force_n[0] < 0  # a push toward −x stays one


def test_contact_at_the_tip_is_the_tip_estimate(truths):
    p, force, sc, shifts = truths
    tip = estimate_force(_kappa(shifts), p, KNOWN, noise_std=1e-7)
    at_l = estimate_force(_kappa(shifts), p, KNOWN, load="contact", contact_s_m=L, noise_std=1e-7)
    np.testing.assert_array_equal(at_l.force_n, tip.force_n)
    np.testing.assert_array_equal(at_l.std_n, tip.std_n)
    assert tip.load == "tip" and np.isnan(tip.contact_s_m).all() and tip.contact_jacobian_rad_per_m is None
    assert at_l.contact_jacobian_rad_per_m.shape == at_l.residual_rad.shape


def test_a_shape_needs_more_force_nearer_the_base():
    """The same bending made by a push at the tip takes a larger push at s_c < L (a shorter lever)."""
    p = 50e3
    t = forward(CFG, p, (0.12, 0.0))
    fx = [estimate_force(_kappa(t.shifts_m), p, KNOWN, "horizontal", load="contact", contact_s_m=f * L,
                         noise_std=1e-6).force_n[0] for f in (0.6, 0.8, 0.95)]
    assert fx[0] > fx[1] > fx[2] > 0.12


@pytest.mark.parametrize("s_c", [1e-6, 1e-3])
def test_a_contact_before_every_compared_point_is_no_force_it_can_tell(s_c):
    """Closer to the base than the first compared point the force has no moment arm there: a frame not ok (it
    divided by zero in the start's 2 x 2 solve, a traceback), at every constraint."""
    p = 50e3
    kappa = _kappa(forward(CFG, p, (0.12, 0.0)).shifts_m)
    for constraint in ("none", "normal"):
        est = estimate_force(kappa, p, KNOWN, constraint, load="contact", contact_s_m=s_c, noise_std=1e-6)
        assert not est.success and est.status != Status.OK


def test_contact_jacobian_is_the_beam_sensitivity_at_the_optimum(truths):
    p, force, sc, shifts = truths
    i = 3
    est = estimate_force(_kappa(shifts[i]), p[i], KNOWN, load="contact", contact_s_m=sc[i], noise_std=1e-7)
    model = bendsense.mechanics.actuator.FreeBendingModel.from_config(CFG)
    coils = np.cumsum(SENSOR.lengths_m)[list(est.coils)]
    beam = solve_beam(L, CFG.stiffness.ei_nm2(p[i]), model.tip_curvature_per_m(p[i]), est.force_n,
                      CFG.weight_per_length_n_per_m, s_m=coils, contact_s_m=sc[i], sensitivities=True)
    np.testing.assert_allclose(est.contact_jacobian_rad_per_m, beam.dangle_dcontact, rtol=0,
                               atol=1e-4 * np.abs(beam.dangle_dcontact).max())
    # and the force Jacobian of the window payload is the beam's at the contact (constraint none: u = F)
    np.testing.assert_allclose(est.jacobian_rad_per_n, beam.dangle_dforce, rtol=0,
                               atol=1e-4 * np.abs(beam.dangle_dforce).max())


def test_one_shape_at_many_contact_points_broadcasts(truths):
    p, force, sc, shifts = truths
    where = np.linspace(0.4, 1.0, 5) * L
    est = estimate_force(_kappa(shifts[0]), p[0], KNOWN, load="contact", contact_s_m=where, noise_std=1e-7)
    assert est.force_n.shape == (5, 2) and est.contact_jacobian_rad_per_m.shape[0] == 5
    for j in (1, 4):
        one = estimate_force(_kappa(shifts[0]), p[0], KNOWN, load="contact", contact_s_m=where[j], noise_std=1e-7)
        np.testing.assert_allclose(est.force_n[j], one.force_n, atol=1e-9)
    with pytest.raises(ArgumentError, match=r"contact_s_m: shape \(3,\) does not broadcast against the frames \(16,\)"):
        estimate_force(_kappa(shifts), p, KNOWN, load="contact", contact_s_m=np.full(3, 0.1), noise_std=1e-7)


@pytest.mark.parametrize("kwargs, match", [
    ({"load": "tip", "contact_s_m": 0.1}, "contact_s_m: only with load='contact'"),
    ({"load": "side"}, "load: must be one of tip, contact, got 'side'"),
    ({"load": "contact", "contact_s_m": 0.0}, "contact_s_m: expected 0 < s_c <= length_m"),
    ({"load": "contact", "contact_s_m": 0.2}, "contact_s_m: expected 0 < s_c <= length_m = 0.134 m, got 0.2"),
    ({"load": "contact", "contact_s_m": "x"}, "contact_s_m: expected numbers"),
    ({"load": "contact", "contact_s_m": float("nan")}, "contact_s_m: must be finite"),
    ({"load": "contact", "contact_s_m": 0.1, "method": "paper"}, "load: method='paper' estimates the paper's tip load"),
])
def test_bad_contact_arguments(kwargs, match):
    with pytest.raises(ArgumentError, match=match):
        estimate_force(np.full(16, 5.0), 40e3, KNOWN, noise_std=1e-6, **kwargs)


def test_two_sigma_covers_the_force_at_a_known_contact(tmp_path):
    """1.5 counts through fitted calibrations of three hidden sensors: ±2σ covers 88–99 % of each component.

    Frames of one sensor share its calibration error: the coverage is taken over several
    independent sensors, each with its own loads and noise draws.
    """
    hits, zs, inside_all = [], [], []
    for seed in (3, 7, 11):
        sensor = HiddenSensor(noise_counts=1.5, seed=seed)
        cal = Calibration.fit(sensor.write_calibration(tmp_path / f"s{seed}", CFG))
        rng = np.random.default_rng(seed)
        p, force, sc = _loads(rng, 50)
        shifts = np.array([forward(CFG, *a, contact_s_m=s).shifts_m for *a, s in zip(p, force, sc)])
        signals = sensor.signals(np.repeat(shifts, 3, axis=0), rng)
        shape = reconstruct(signals, cal, SENSOR)
        est = estimate_force(shape, np.repeat(p, 3), KNOWN, load="contact", contact_s_m=np.repeat(sc, 3),
                             calibration=cal)
        inside = ~np.asarray(shape.extrapolated)
        assert inside.mean() > 0.8 and est.success[inside].mean() >= 0.98
        truth = np.repeat(force, 3, axis=0)
        hits.append(np.abs(est.force_n - truth) <= 2.0 * est.std_n)
        zs.append((est.force_n - truth) / est.std_n)
        inside_all.append(inside)
    cover = np.concatenate(hits).mean(axis=0)
    print(f"±2σ coverage at a known contact: {cover}")
    assert np.all((cover >= 0.88) & (cover <= 0.99)), cover
    z = np.concatenate(zs)[np.concatenate(inside_all)]
    assert np.all(np.abs(np.sqrt(np.mean(z**2, axis=0)) - 1.0) < 0.25)


def test_a_shape_given_by_points_at_a_known_contact():
    """The forward model's own points (no PCC): the positions objective finds the force at s_c."""
    p, sc, force = 70e3, 0.75 * L, np.array([0.08, -0.12])
    t = forward(CFG, p, force, contact_s_m=sc, s_m=np.linspace(0.0, L, 61))
    shape = t.shape
    est = estimate_force(shape.positions_m, p, KNOWN, s_m=shape.s_m, load="contact", contact_s_m=sc)
    assert est.success and est.objective == "positions"
    np.testing.assert_allclose(est.force_n, force, atol=1e-3)
    with pytest.raises(ArgumentError, match="tip_angle_source: 'shape' at a contact needs a PCC shape"):
        estimate_force(shape.positions_m, p, KNOWN, "normal", s_m=shape.s_m, load="contact", contact_s_m=sc,
                       tip_angle_source="shape")
