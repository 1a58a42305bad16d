import dataclasses

import numpy as np
import pytest

from bendsense.config import load_config
from bendsense.errors import ConfigError
from bendsense.sim import (
    CoilArrayModel,
    VirtualSensor,
    calibration_shifts,
    shifts_from_angles,
    shifts_from_curvatures,
    shifts_from_shape,
)


@pytest.fixture(scope="module")
def sensor_config():
    return load_config().sensor


@pytest.fixture(scope="module")
def model(sensor_config):
    return CoilArrayModel.from_config(sensor_config)


@pytest.fixture()
def virtual(sensor_config, model):
    return VirtualSensor.from_config(sensor_config, model=model, seed=7)


def test_shifts_from_curvatures_hand_computed():
    # S = d (κ1 l1, κ1 l1 + κ2 l2, κ1 l1 + κ2 l2 + κ3 l3) with d = 1 mm
    shifts = shifts_from_curvatures([10.0, -5.0, 20.0], [0.010, 0.008, 0.010], 0.001)
    np.testing.assert_allclose(shifts, [1e-4, 6e-5, 2.6e-4], rtol=1e-12)


def test_shifts_from_curvatures_batches_and_checks():
    kappa = np.array([[10.0, -5.0, 20.0], [0.0, 0.0, 0.0]])
    out = shifts_from_curvatures(kappa[None], [0.010, 0.008, 0.010], 0.002)
    assert out.shape == (1, 2, 3)
    np.testing.assert_allclose(out[0, 0], [2e-4, 1.2e-4, 5.2e-4], rtol=1e-12)
    assert np.all(out[0, 1] == 0)
    with pytest.raises(ConfigError, match=r"curvature_per_m: expected shape \(\.\.\., 3\)"):
        shifts_from_curvatures(np.zeros(4), [0.01, 0.01, 0.01], 0.001)
    with pytest.raises(ConfigError, match="strip_gap_m: must be > 0"):
        shifts_from_curvatures(np.zeros(3), [0.01, 0.01, 0.01], 0.0)
    with pytest.raises(ConfigError, match="lengths_m"):
        shifts_from_curvatures(np.zeros(3), [0.01, -0.01, 0.01], 0.001)


def test_shifts_from_angles():
    np.testing.assert_allclose(shifts_from_angles([0.5, -1.0], 0.001), [5e-4, -1e-3])


def test_calibration_strip_shifts(sensor_config):
    shifts = calibration_shifts(sensor_config, [0.040, 0.400])
    cumulative = np.array([10.0 + 8 * i for i in range(15)] + [132.0]) * 1e-3
    np.testing.assert_allclose(shifts[0], 25.0 * 1e-3 * cumulative, rtol=1e-12)
    np.testing.assert_allclose(shifts[1], 2.5 * 1e-3 * cumulative, rtol=1e-12)
    assert shifts[0, -1] == pytest.approx(3.3e-3)
    with_sleeve = dataclasses.replace(sensor_config, calibration_adds_sleeve=True)
    np.testing.assert_allclose(calibration_shifts(with_sleeve, 0.040), 1e-3 * cumulative / 0.04075, rtol=1e-12)


def test_shifts_from_pcc_shape_match_curvatures(sensor_config):
    # φ(s) of PCC segments is piecewise linear with kinks at L_i; sampled with the L_i on
    # the grid, the interpolant is exact there
    rng = np.random.default_rng(0)
    kappa = rng.uniform(-20, 20, (3, 16))
    lengths = sensor_config.lengths_m
    ends = np.concatenate([[0.0], np.cumsum(lengths)])
    s = np.unique(np.concatenate([ends, np.linspace(0, 0.134, 50)]))
    seg = np.clip(np.searchsorted(ends, s, side="right") - 1, 0, 15)
    phi_ends = np.concatenate([np.zeros((3, 1)), np.cumsum(kappa * lengths, axis=1)], axis=1)
    phi = phi_ends[:, seg] + kappa[:, seg] * (s - ends[seg])
    expected = shifts_from_curvatures(kappa, lengths, sensor_config.strip_gap_m)
    np.testing.assert_allclose(shifts_from_shape(s, phi, lengths, 1e-3), expected, rtol=0, atol=1e-15)


def test_shifts_from_smooth_shape_are_relative_to_the_base(sensor_config):
    s = np.linspace(0, 0.134, 201)
    base = 0.3  # a tilted base: the strips are pinned there, so it does not shift them

    def phi(x):
        return base + 12.0 * x + 40.0 * x**2 + 0.2 * np.sin(60.0 * x)

    ends = np.cumsum(sensor_config.lengths_m)
    got = shifts_from_shape(s, phi(s), sensor_config.lengths_m, 1e-3)
    np.testing.assert_allclose(got, 1e-3 * (phi(ends) - base), rtol=0, atol=1e-11)


def test_shifts_from_shape_checks_coverage(sensor_config):
    s = np.linspace(0, 0.1, 11)
    with pytest.raises(ConfigError, match="s_m: must cover the sensor from 0 to 0.132"):
        shifts_from_shape(s, np.zeros(11), sensor_config.lengths_m, 1e-3)
    with pytest.raises(ConfigError, match=r"angle_rad: expected shape \(\.\.\., 11\)"):
        shifts_from_shape(s, np.zeros(10), sensor_config.lengths_m, 1e-3)


def test_noise_free_signal_is_offset_plus_gain_times_lockin(virtual, model):
    shifts = np.linspace(-3e-3, 3e-3, 16)
    np.testing.assert_allclose(
        virtual.signal(shifts), virtual.offset_counts + virtual.gain_counts * model.direct(shifts), rtol=1e-10
    )
    # flat: only the offsets and the end receivers' small flat-state signal remain
    flat = virtual.signal(np.zeros(16)) - virtual.offset_counts
    assert np.all(np.abs(flat[2:-2]) < 1.0) and np.all(np.abs(flat) < 15)


def test_offsets_near_mid_scale_and_gains(virtual, sensor_config, model):
    assert virtual.n_channels == 16 and virtual.full_scale_counts == 4095
    assert np.all(np.abs(virtual.offset_counts / 2048 - 1) <= 0.03)
    assert np.ptp(virtual.offset_counts) > 10  # randomised per channel
    fixed = VirtualSensor.from_config(sensor_config, model=model, gain=1000.0, offset_counts=2000.0)
    assert np.all(fixed.gain_counts == 1000.0) and np.all(fixed.offset_counts == 2000.0)
    spread = VirtualSensor.from_config(sensor_config, model=model, gain=1000.0, gain_spread=0.05, seed=1)
    assert np.all(np.abs(spread.gain_counts / 1000 - 1) <= 0.05) and np.ptp(spread.gain_counts) > 0


def test_tightest_calibration_strip_uses_the_range_without_saturating(virtual, sensor_config):
    for sign in (1.0, -1.0):
        shifts = sign * calibration_shifts(sensor_config, 0.040)
        values = virtual.signal(shifts)
        assert values.min() > 5 * virtual.noise_counts and values.max() < 4095 - 5 * virtual.noise_counts
        assert np.ptp(values) > 0.7 * 4095
        assert not virtual.measure(shifts).saturated.any()
    # nothing saturates anywhere in the monotonic range (receiver above a transmitter at most)
    grid = np.linspace(-4e-3, 4e-3, 81)[:, None] * np.ones(16)
    assert not virtual.measure(grid).saturated.any()


def test_odd_and_even_channels_move_oppositely_with_curvature(virtual, sensor_config):
    bent = virtual.signal(calibration_shifts(sensor_config, 0.1)) - virtual.signal(np.zeros(16))
    assert np.all(bent[0::2] < 0) and np.all(bent[1::2] > 0)


def test_deterministic_with_a_seed(sensor_config, model):
    shifts = calibration_shifts(sensor_config, [0.05, 0.08, 0.2])
    a = VirtualSensor.from_config(sensor_config, model=model, seed=11)
    b = VirtualSensor.from_config(sensor_config, model=model, seed=11)
    c = VirtualSensor.from_config(sensor_config, model=model, seed=12)
    np.testing.assert_array_equal(a.offset_counts, b.offset_counts)
    first_a, first_b = a.measure(shifts), b.measure(shifts)
    np.testing.assert_array_equal(first_a.counts, first_b.counts)
    np.testing.assert_array_equal(a.measure(shifts).counts, b.measure(shifts).counts)
    assert not np.array_equal(a.offset_counts, c.offset_counts)
    # the stream advances: a second reading has fresh noise
    assert not np.array_equal(first_a.counts, a.measure(shifts).counts)
    np.testing.assert_array_equal(
        a.measure(shifts, rng=np.random.default_rng(5)).counts, b.measure(shifts, rng=np.random.default_rng(5)).counts
    )


def test_noise_statistics(sensor_config, model):
    noisy = VirtualSensor.from_config(sensor_config, model=model, noise_counts=4.0, seed=3)
    shifts = np.zeros((20000, 16))
    diff = noisy.measure(shifts).counts - noisy.signal(shifts)
    # Gaussian noise plus uniform rounding error: variance σ² + 1/12
    assert diff.std() == pytest.approx(np.sqrt(16 + 1 / 12), rel=0.02)
    assert abs(diff.mean()) < 0.02


def test_quantisation_and_saturation(sensor_config, model):
    quiet = VirtualSensor.from_config(sensor_config, model=model, noise_counts=0.0, seed=0)
    reading = quiet.quantize([-3.0, -0.4, 0.0, 12.4, 12.6, 4094.6, 4095.4, 4096.0, 1e6])
    np.testing.assert_array_equal(reading.counts, [0, 0, 0, 12, 13, 4095, 4095, 4095, 4095])
    np.testing.assert_array_equal(reading.saturated, [1, 0, 0, 0, 0, 0, 0, 1, 1])
    assert reading.counts.dtype == np.uint16
    shifts = calibration_shifts(sensor_config, 0.1)
    np.testing.assert_array_equal(quiet.measure(shifts).counts, np.rint(quiet.signal(shifts)))
    # a gain far too high drives the odd channels to 0 and the even ones to full scale
    loud = VirtualSensor.from_config(sensor_config, model=model, gain=20000.0, noise_counts=0.0)
    big = loud.measure(calibration_shifts(sensor_config, [0.04, 0.4]))
    assert np.all(big.counts[0, 4::2] == 0) and np.all(big.counts[0, 5::2] == 4095)
    assert np.all(big.saturated[0, 4:]) and big.frame_saturated[0]
    assert not big.saturated[1, 0]
    ten = VirtualSensor.from_config(sensor_config, model=model, adc_bits=10, noise_counts=0.0)
    assert ten.full_scale_counts == 1023
    assert abs(ten.signal(np.zeros(16)).mean() / 512 - 1) < 0.03
    assert ten.volts(1024) == pytest.approx(3.3)


def test_convenience_methods(virtual, sensor_config):
    kappa = np.full(16, 10.0)
    np.testing.assert_allclose(virtual.shifts_from_curvatures(kappa), calibration_shifts(sensor_config, 0.1))
    s = np.linspace(0, 0.134, 101)
    np.testing.assert_allclose(virtual.shifts_from_shape(s, 10.0 * s), calibration_shifts(sensor_config, 0.1))


def test_from_config_rejects_bad_options(sensor_config, model):
    with pytest.raises(ConfigError, match="adc_bits: must be an integer in 1..16"):
        VirtualSensor.from_config(sensor_config, model=model, adc_bits=0)
    with pytest.raises(ConfigError, match="noise_counts: must be >= 0"):
        VirtualSensor.from_config(sensor_config, model=model, noise_counts=-1)
    with pytest.raises(ConfigError, match="gain: expected a finite number or 16 finite values"):
        VirtualSensor.from_config(sensor_config, model=model, gain=[1.0, 2.0])
    with pytest.raises(ConfigError, match="model: expected 15 receivers"):
        lengths = sensor_config.segment_lengths_m[:15]
        short = dataclasses.replace(sensor_config, n_segments=15, segment_lengths_m=lengths)
        VirtualSensor.from_config(short, model=model)
    with pytest.raises(ConfigError, match=r"shifts_m: expected shape \(\.\.\., 16\)"):
        VirtualSensor.from_config(sensor_config, model=model).measure(np.zeros(3))


def test_shifts_from_an_unloaded_beam_solution_are_an_arc(virtual, sensor_config):
    beam = pytest.importorskip("bendsense.mechanics.beam")
    # no load: the beam keeps its free-bending curvature, a calibration-strip arc
    solution = beam.solve_beam(0.134, 3e-3, 12.5, force_n=(0.0, 0.0), distributed_load_n_per_m=(0.0, 0.0))
    shifts = virtual.shifts_from_shape(solution.s_m, solution.angle_rad)
    np.testing.assert_allclose(shifts, calibration_shifts(sensor_config, 0.080), rtol=1e-6, atol=1e-12)


def test_direct_construction_gets_the_seeded_noise_stream(virtual):
    twin = VirtualSensor(
        model=virtual.model,
        lengths_m=virtual.lengths_m,
        strip_gap_m=virtual.strip_gap_m,
        gain_counts=virtual.gain_counts,
        offset_counts=virtual.offset_counts,
        noise_counts=virtual.noise_counts,
        seed=virtual.seed,
    )
    shifts = np.full((5, 16), 1e-3)
    np.testing.assert_array_equal(twin.measure(shifts).counts, virtual.measure(shifts).counts)
