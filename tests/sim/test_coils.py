import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.constants import mu_0
from scipy.special import ellipe, ellipk

from bendsense.config import load_config
from bendsense.errors import ConfigError
from bendsense.sim.coils import (
    CoilArrayModel,
    CoilGeometry,
    coaxial_loop_mutual_inductance,
    coil_mutual_inductance,
    loop_mutual_inductance,
)


def maxwell_coaxial(a, b, z):
    """Maxwell's closed form, written here independently of the library's Landen form."""
    m = 4 * a * b / ((a + b) ** 2 + z**2)
    k = np.sqrt(m)
    return mu_0 * np.sqrt(a * b) * ((2 / k - k) * ellipk(m) - (2 / k) * ellipe(m))


def neumann_double(a, b, z, rho, n=600):
    """Neumann's formula μ0/4π ∮∮ dl1·dl2/|r1 − r2| by the trapezoidal rule in both angles."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    u, v = np.meshgrid(t, t, indexing="ij")
    dist = np.sqrt((a * np.cos(u) - rho - b * np.cos(v)) ** 2 + (a * np.sin(u) - b * np.sin(v)) ** 2 + z**2)
    dot = a * b * np.cos(u - v)
    return mu_0 / (4 * np.pi) * (dot / dist).sum() * (2 * np.pi / n) ** 2


@pytest.fixture(scope="module")
def paper_model():
    return CoilArrayModel.from_config(load_config().sensor)


radius = st.floats(0.5e-3, 5e-3)


@settings(max_examples=60, deadline=None)
@given(a=radius, b=radius, z=st.floats(0.3e-3, 10e-3))
def test_coaxial_matches_maxwell_closed_form(a, b, z):
    ref = maxwell_coaxial(a, b, z)
    assert coaxial_loop_mutual_inductance(a, b, z) == pytest.approx(ref, rel=1e-9)
    assert loop_mutual_inductance(a, b, z, 0.0) == pytest.approx(ref, rel=1e-9)


def test_textbook_value_for_equal_coaxial_loops():
    # Equal loops with k² = 0.8 (a = b = 1, z = 1): M = μ0 [(2/k − k) K − (2/k) E]
    k = math.sqrt(0.8)
    expected = mu_0 * ((2 / k - k) * ellipk(0.8) - 2 / k * ellipe(0.8))
    assert loop_mutual_inductance(1.0, 1.0, 1.0) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    "a, b, z, rho",
    [(3e-3, 3e-3, 1e-3, 2e-3), (3e-3, 1.2e-3, 0.9e-3, 4e-3), (2e-3, 3e-3, 1.1e-3, 7e-3), (3e-3, 3e-3, 1e-3, 3e-3)],
)
def test_lateral_offset_matches_neumann_double_integral(a, b, z, rho):
    assert loop_mutual_inductance(a, b, z, rho) == pytest.approx(neumann_double(a, b, z, rho), rel=1e-9)


@settings(max_examples=40, deadline=None)
@given(a=radius, b=radius, z=st.floats(0.5e-3, 5e-3), rho=st.floats(0.0, 20e-3))
def test_symmetry_and_reciprocity(a, b, z, rho):
    m = loop_mutual_inductance(a, b, z, rho)
    scale = loop_mutual_inductance(a, b, z, 0.0)
    assert loop_mutual_inductance(a, b, z, -rho) == pytest.approx(m, rel=1e-12, abs=1e-12 * scale)
    assert loop_mutual_inductance(a, b, -z, rho) == pytest.approx(m, rel=1e-12, abs=1e-12 * scale)
    assert loop_mutual_inductance(b, a, z, rho) == pytest.approx(m, rel=1e-10, abs=1e-11 * scale)


@pytest.mark.parametrize("theta", [0.0, 0.4, 1.0, math.acos(1 / math.sqrt(3)) + 0.2, math.pi / 2])
def test_far_field_tends_to_dipole_limit(theta):
    a, b = 3e-3, 2e-3
    errors = []
    for distance in (0.1, 0.3, 1.0):
        z, rho = distance * math.cos(theta), distance * math.sin(theta)
        dipole = mu_0 * math.pi * a**2 * b**2 * (3 * math.cos(theta) ** 2 - 1) / (4 * distance**3)
        errors.append(abs(loop_mutual_inductance(a, b, z, rho) / dipole - 1))
    # the leading correction is O((a/R)²)
    assert errors[-1] < 1e-3
    assert errors[0] / errors[1] == pytest.approx(9, rel=0.05)
    assert errors[1] / errors[2] == pytest.approx(1 / 0.09, rel=0.05)


@pytest.mark.parametrize("rho", [0.0, 2e-3, 3e-3, 4e-3, 6e-3, 30e-3])
def test_default_quadrature_is_converged(rho):
    # wire-to-wire distance down to 0.8 mm for 3 mm loops, the closest case in the sensor
    fine = loop_mutual_inductance(3e-3, 3e-3, 0.8e-3, rho, n_quad=1024)
    scale = loop_mutual_inductance(3e-3, 3e-3, 0.8e-3, 0.0)
    assert abs(loop_mutual_inductance(3e-3, 3e-3, 0.8e-3, rho) - fine) < 1e-12 * scale


def test_loop_inputs_broadcast():
    rho = np.linspace(0, 5e-3, 6)
    out = loop_mutual_inductance(3e-3, np.array([[1e-3], [2e-3]]), 1e-3, rho)
    assert out.shape == (2, 6)
    assert out[1, 3] == pytest.approx(loop_mutual_inductance(3e-3, 2e-3, 1e-3, rho[3]), rel=1e-14)
    with pytest.raises(ConfigError, match="n_quad"):
        loop_mutual_inductance(1e-3, 1e-3, 1e-3, n_quad=1)


def test_flat_spiral_geometry():
    coil = CoilGeometry.flat_spiral()
    assert coil.n_turns == 20
    assert max(coil.radii_m) == pytest.approx(3e-3) and min(coil.radii_m) == pytest.approx(1.2e-3)
    assert sorted(set(coil.z_m)) == pytest.approx([-5e-5, 5e-5])
    sensor = load_config().sensor
    assert CoilGeometry.from_sensor_config(sensor) == coil
    with pytest.raises(ConfigError, match="coil.layers"):
        CoilGeometry.flat_spiral(turns=5, layers=2)
    with pytest.raises(ConfigError, match=r"coil.radii_m\[1\]: must be > 0"):
        CoilGeometry(radii_m=(1e-3, -1e-3), z_m=(0, 0))
    with pytest.raises(ConfigError, match="coil.z_m: expected 2 values"):
        CoilGeometry(radii_m=(1e-3, 2e-3), z_m=(0,))


def test_coil_mutual_inductance_sums_the_turn_pairs():
    a = CoilGeometry(radii_m=(1e-3, 2e-3), z_m=(0.0, 1e-4))
    b = CoilGeometry(radii_m=(1.5e-3, 3e-3, 2.5e-3), z_m=(0.0, 0.0, -1e-4))
    rho = np.array([[0.0, 2e-3], [5e-3, 11e-3]])
    expected = np.zeros_like(rho)
    for ra, za in zip(a.radii_m, a.z_m, strict=True):
        for rb, zb in zip(b.radii_m, b.z_m, strict=True):
            expected += loop_mutual_inductance(ra, rb, 1e-3 + zb - za, rho)
    np.testing.assert_allclose(coil_mutual_inductance(a, b, 1e-3, rho), expected, rtol=1e-13)


def test_pair_spline_matches_exact_coil_inductance(paper_model):
    rho = np.array([0.0, 0.37e-3, 2.9e-3, 4e-3, 6.3e-3, 9.1e-3, 13.7e-3, 33e-3, 97e-3])
    exact = coil_mutual_inductance(paper_model.transmitter_coil, paper_model.receiver_coil, 1e-3, rho)
    err = np.abs(paper_model.coil_mutual_inductance(rho) - exact) / paper_model.mutual_ref_h
    assert err.max() < 1e-8


def test_table_matches_direct_sum(paper_model):
    rng = np.random.default_rng(3)
    shifts = rng.uniform(-4e-3, 4e-3, (200, 16))
    np.testing.assert_allclose(paper_model.signal(shifts), paper_model.direct(shifts), rtol=0, atol=1e-9)
    # beyond the table the direct sum takes over
    far = rng.uniform(-12e-3, 12e-3, (20, 16))
    np.testing.assert_allclose(paper_model.signal(far), paper_model.direct(far), rtol=0, atol=1e-9)


def test_direct_sum_is_the_physics(paper_model):
    # one receiver, its two neighbours and the next pair on each side, straight from the
    # turn-pair sums (no spline): interior receiver 8 (0-based 7) at a shift of 1.3 mm
    p, s = 8e-3, 1.3e-3
    coil = paper_model.receiver_coil
    signal = 0.0
    for j in range(5, 11):
        signal += (-1) ** j * coil_mutual_inductance(coil, coil, 1e-3, 7 * p + s - (j - 0.5) * p)
    others = [j for j in range(17) if not 5 <= j < 11]
    far = sum((-1) ** j * paper_model.coil_mutual_inductance(7 * p + s - (j - 0.5) * p) for j in others)
    expected = (signal + far) / paper_model.mutual_ref_h
    shifts = np.zeros(16)
    shifts[7] = s
    # the model takes M_coil from a spline of the turn sums, accurate to 1e-8 of M_ref
    assert paper_model.signal(shifts)[7] == pytest.approx(float(expected), abs=1e-8)


def test_derivative_matches_finite_differences(paper_model):
    shifts = np.linspace(-3e-3, 3e-3, 16)
    h = 1e-7
    fd = (paper_model.signal(shifts + h) - paper_model.signal(shifts - h)) / (2 * h)
    np.testing.assert_allclose(paper_model.derivative(shifts), fd, rtol=1e-6)


def test_odd_and_even_receivers_have_opposite_monotonic_trends(paper_model):
    grid = np.linspace(-3.5e-3, 3.5e-3, 3501)
    u = paper_model.signal(np.repeat(grid[:, None], 16, axis=1))
    steps = np.diff(u, axis=0)
    odd = np.arange(16) % 2 == 0  # 1-based odd receivers
    assert np.all(steps[:, odd] < 0)
    assert np.all(steps[:, ~odd] > 0)


def test_monotonic_over_half_a_pitch(paper_model):
    ranges = paper_model.monotonic_range_m()
    assert np.all(ranges[:, 0] <= -3.9e-3) and np.all(ranges[:, 1] >= 3.9e-3)
    # and no further than the next transmitter: the signal peaks when the receiver is above it
    assert np.all(ranges[:, 0] >= -4.01e-3) and np.all(ranges[:, 1] <= 4.01e-3)


def test_differential_signal_vanishes_at_zero_shift():
    # one receiver midway between two opposite transmitters: exactly zero and odd in S
    coil = CoilGeometry.flat_spiral(turns=2, layers=1)
    model = CoilArrayModel.build(n_receivers=1, pitch_m=8e-3, gap_m=1e-3, receiver_coil=coil)
    assert abs(model.signal(np.zeros(1))[0]) < 1e-12
    s = np.linspace(0.1e-3, 3.9e-3, 39)[:, None]
    np.testing.assert_allclose(model.signal(-s), -model.signal(s), rtol=0, atol=1e-12)


def test_flat_array_signal_is_small(paper_model):
    u0 = paper_model.signal(np.zeros(16))
    full = np.abs(paper_model.signal(np.full(16, 3.3e-3)))
    # interior receivers see a symmetric array; only the ends feel the missing neighbours
    assert np.all(np.abs(u0[2:-2]) < 1e-3 * full[2:-2])
    assert np.all(np.abs(u0) < 1e-2 * full)


def test_emf_scales_with_frequency_and_current(paper_model):
    shifts = np.full(16, 1e-3)
    v = paper_model.emf_v(shifts, frequency_hz=1e6, current_a=0.01)
    expected = 2 * np.pi * 1e6 * 0.01 * paper_model.direct(shifts) * paper_model.mutual_ref_h
    np.testing.assert_allclose(v, expected, rtol=1e-8)


def test_model_rejects_bad_input(paper_model):
    with pytest.raises(ConfigError, match=r"shifts_m: expected shape \(\.\.\., 16\)"):
        paper_model.signal(np.zeros(15))
    with pytest.raises(ConfigError, match="pitch_m: must be > 0"):
        CoilArrayModel.build(n_receivers=2, pitch_m=0.0, gap_m=1e-3, receiver_coil=CoilGeometry.flat_spiral())


def test_the_coil_spline_kept_between_processes_is_the_one_computed(tmp_path, monkeypatch):
    import bendsense.sim.coils as coils

    sensor = load_config().sensor
    monkeypatch.setattr(coils, "CACHE_DIR", tmp_path / "cache")
    coils._coil_spline.cache_clear()
    computed = CoilArrayModel.from_config(sensor)  # computes, writes the file
    (written,) = (tmp_path / "cache").glob("coils-*.npy")
    coils._coil_spline.cache_clear()
    monkeypatch.setattr(coils, "coil_mutual_inductance", lambda *a, **k: pytest.fail("computed again"))
    read = CoilArrayModel.from_config(sensor)  # as a second process would: from the file
    rho = np.linspace(0.0, 0.1, 57)
    assert np.array_equal(read.coil_mutual_inductance(rho), computed.coil_mutual_inductance(rho))
    # a file cut short (a full disk, a kill) or a cache that cannot be written: computed, no error
    monkeypatch.undo()
    monkeypatch.setattr(coils, "CACHE_DIR", tmp_path / "cache")
    written.write_bytes(written.read_bytes()[:100])
    coils._coil_spline.cache_clear()
    assert np.array_equal(CoilArrayModel.from_config(sensor).coil_mutual_inductance(rho),
                          computed.coil_mutual_inductance(rho))
    (tmp_path / "blocked").write_text("a file where the cache directory would be")
    monkeypatch.setattr(coils, "CACHE_DIR", tmp_path / "blocked")
    coils._coil_spline.cache_clear()
    assert np.array_equal(CoilArrayModel.from_config(sensor).coil_mutual_inductance(rho),
                          computed.coil_mutual_inductance(rho))
    coils._coil_spline.cache_clear()
