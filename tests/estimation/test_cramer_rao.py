"""The Cramér–Rao bound of a contact along the finger against a finite-difference Fisher matrix of the forward model.

The reference is built here from nothing of the library's beam: the normal contact by a
fixed-point iteration on the loaded angle at s_c of ``tests/forward_model.py``'s
``solve_bvp`` beam, the Jacobian of the coil angles by central differences of that BVP in
(Fx, Fy, s_c), the shift noise from central differences of the simulated sensor's signal
(counts per metre), and the Fisher matrix ``Jᵀ Σ⁻¹ J`` inverted with numpy.
"""

from __future__ import annotations

import numpy as np
import pytest
from forward_model import forward

from bendsense.config import load_config
from bendsense.errors import ArgumentError
from bendsense.estimation.cramer_rao import contact_bound
from bendsense.sim.sensor import VirtualSensor

CONFIG = load_config()
L = CONFIG.actuator.length_m
NOISE = 1.5


def normal_contact(pressure, f, sc):
    """The force f (−cos φ_c, sin φ_c) normal to the loaded angle φ_c at s_c, by fixed-point iteration."""
    phi = 0.0
    for _ in range(60):
        force = f * np.array([-np.cos(phi), np.sin(phi)])
        shape = forward(CONFIG, pressure, force, contact_s_m=sc, s_m=[sc]).shape
        new = float(shape.angle_rad[np.argmin(abs(shape.s_m - sc))])
        if abs(new - phi) < 1e-13:
            break
        phi = new
    return force


def reference(pressure, f, sc, h=2e-4, hidden=None):
    force = normal_contact(pressure, f, sc)
    truth = forward(CONFIG, pressure, force, contact_s_m=sc)
    x0 = np.array([force[0], force[1], sc])
    J = np.empty((truth.angles_rad.size, 3))
    for k in range(3):
        step = h if k < 2 else 0.5e-3
        up, down = x0.copy(), x0.copy()
        up[k] += step
        down[k] -= step
        J[:, k] = (forward(CONFIG, pressure, up[:2], contact_s_m=up[2]).angles_rad
                   - forward(CONFIG, pressure, down[:2], contact_s_m=down[2]).angles_rad) / (2 * step)
    e = 1e-8
    if hidden is None:
        sensor = VirtualSensor.from_config(CONFIG, noise_counts=0.0, seed=0)
        slope = (sensor.signal(truth.shifts_m + e) - sensor.signal(truth.shifts_m - e)) / (2 * e)  # channel i: S_i
    else:
        slope = (hidden.delta(truth.shifts_m + e) - hidden.delta(truth.shifts_m - e)) / (2 * e)
    sigma_theta = NOISE / np.abs(slope) / CONFIG.sensor.strip_gap_m
    info = J.T @ (J / sigma_theta[:, None] ** 2)
    n = force / np.linalg.norm(force)
    Jn = np.stack([J[:, :2] @ n, J[:, 2]], axis=1)
    info_n = Jn.T @ (Jn / sigma_theta[:, None] ** 2)
    cov, cov_n = np.linalg.inv(info), np.linalg.inv(info_n)
    return {
        "force": force,
        "none": (np.sqrt(cov[2, 2]), np.sqrt(np.diag(cov)[:2]), np.sqrt(np.diag(np.linalg.inv(info[:2, :2])))),
        "normal": (np.sqrt(cov_n[1, 1]), np.sqrt(cov_n[0, 0]), 1 / np.sqrt(info_n[0, 0])),
    }


@pytest.mark.parametrize(("fraction", "f"), [(0.8, 0.2), (0.5, 0.05)])
def test_bound_matches_the_forward_models_fisher_matrix(fraction, f):
    sc, pressure = fraction * L, 60e3
    ref = reference(pressure, f, sc)
    for constraint in ("normal", "none"):
        b = contact_bound(CONFIG, contact_s_m=sc, force_n=f, pressure_pa=pressure, noise_std=NOISE,
                          constraint=constraint)
        assert b.valid
        np.testing.assert_allclose(b.force_n, ref["force"], atol=2e-5 * f)
        sd_sc, sd_f, sd_known = ref[constraint]
        np.testing.assert_allclose(b.contact_std_m, sd_sc, rtol=0.01)
        np.testing.assert_allclose(b.force_std_n, sd_f, rtol=0.01)
        np.testing.assert_allclose(b.force_std_known_n, sd_known, rtol=0.01)


def test_with_a_calibration_the_noise_goes_through_its_slopes(tmp_path):
    """A hidden sensor's fitted calibration: its slopes are the sensor's own to the fit's accuracy."""
    from forward_model import HiddenSensor

    from bendsense.calibration import Calibration

    hidden = HiddenSensor(noise_counts=NOISE, seed=3)
    cal = Calibration.fit(hidden.write_calibration(tmp_path, CONFIG))
    sc, f, pressure = 0.75 * L, 0.15, 80e3
    ref = reference(pressure, f, sc, hidden=hidden)
    b = contact_bound(CONFIG, cal, contact_s_m=sc, force_n=f, pressure_pa=pressure, noise_std=NOISE,
                      constraint="none")
    np.testing.assert_allclose(b.contact_std_m, ref["none"][0], rtol=0.05)
    np.testing.assert_allclose(b.force_std_known_n, ref["none"][2], rtol=0.05)
    # the calibration's own noise estimate (its flat recording) is the default
    default = contact_bound(CONFIG, cal, contact_s_m=sc, force_n=f, pressure_pa=pressure, constraint="none")
    np.testing.assert_allclose(default.contact_std_m, b.contact_std_m, rtol=0.15)


def test_frames_average_the_noise_down_and_arrays_broadcast():
    sc = np.array([0.6, 0.9]) * L
    one = contact_bound(CONFIG, contact_s_m=sc[:, None], force_n=[0.1, 0.2], pressure_pa=50e3)
    many = contact_bound(CONFIG, contact_s_m=sc[:, None], force_n=[0.1, 0.2], pressure_pa=50e3, frames=100)
    assert one.contact_std_m.shape == (2, 2) and one.force_n.shape == (2, 2, 2)
    np.testing.assert_allclose(many.contact_std_m, one.contact_std_m / 10, rtol=1e-9)
    np.testing.assert_allclose(many.force_std_n, one.force_std_n / 10, rtol=1e-9)
    # each entry equals its own scalar call
    single = contact_bound(CONFIG, contact_s_m=sc[1], force_n=0.1, pressure_pa=50e3)
    np.testing.assert_allclose(one.contact_std_m[1, 0], single.contact_std_m, rtol=1e-9)
    # not knowing s_c costs force precision; a larger force resolves s_c better
    assert np.all(one.force_std_n > one.force_std_known_n)
    assert np.all(one.contact_std_m[:, 1] < one.contact_std_m[:, 0])


def test_no_force_no_location():
    b = contact_bound(CONFIG, contact_s_m=0.7 * L, force_n=0.0, pressure_pa=60e3, constraint="none")
    assert np.isinf(b.contact_std_m)
    assert np.all(np.isfinite(b.force_std_known_n))


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"contact_s_m": 0.2}, "contact_s_m"), ({"contact_s_m": 0.0}, "contact_s_m"), ({"force_n": -0.1}, "force_n"),
    ({"pressure_pa": np.nan}, "pressure_pa"), ({"frames": 0}, "frames"), ({"constraint": "tip"}, "constraint"),
])
def test_bad_arguments_name_themselves(kwargs, name):
    args = {"contact_s_m": 0.1, "force_n": 0.1, "pressure_pa": 60e3, **kwargs}
    with pytest.raises(ArgumentError, match=f"^{name}: "):
        contact_bound(CONFIG, **args)


def test_shapes_that_do_not_broadcast_name_the_arguments_and_their_shapes():
    with pytest.raises(ArgumentError, match=r"^contact_s_m, force_n, pressure_pa: shapes \(2,\), \(3,\), \(\) do not "
                                            r"broadcast to one$"):
        contact_bound(CONFIG, contact_s_m=[0.05, 0.08], force_n=[0.1, 0.2, 0.3], pressure_pa=60e3)
    with pytest.raises(ArgumentError, match=r"^noise_std: expected one value or one per channel \(16,\), got shape "
                                            r"\(3,\)$"):
        contact_bound(CONFIG, contact_s_m=0.08, force_n=0.1, pressure_pa=60e3, noise_std=[1.0, 1.5, 2.0])
