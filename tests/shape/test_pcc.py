"""PCC shape reconstruction (paper eq. 3–7) and the shape metrics (eq. 19–20)."""

import math

import helpers
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from bendsense import load_config
from bendsense.errors import ConfigError
from bendsense.shape.pcc import (
    Shape,
    arc_positions,
    default_s_m,
    fit_arc_curvature,
    forward_kinematics,
    max_position_error,
    reconstruct,
    shifts_to_curvatures,
    tip_pose,
)

SENSOR = load_config().sensor
LENGTHS = SENSOR.lengths_m  # (10, 8 x 14, 10) mm: L_N = 132 mm
L = float(LENGTHS.sum())
BOUNDS = np.concatenate(([0.0], np.cumsum(LENGTHS)))


def paper_chain(kappa, lengths, s):
    """Independent reference: the paper's homogeneous transforms, eq. 5–7, point by point."""

    def local(theta, length, frac):
        if theta == 0.0:
            return np.array([0.0, length * frac])
        return np.array([length / theta * (1 - math.cos(theta * frac)), length / theta * math.sin(theta * frac)])

    def rz(angle):  # R_z(angle) restricted to the plane
        return np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])

    bounds = np.concatenate(([0.0], np.cumsum(lengths)))
    out, angles = [], []
    for si in s:
        i = max(int(np.searchsorted(bounds, si, side="left")) - 1, 0)  # s in (L_{i}, L_{i+1}]
        rot, pos, phi = np.eye(2), np.zeros(2), 0.0
        for j in range(i):
            theta = kappa[j] * lengths[j]
            pos = pos + rot @ local(theta, lengths[j], 1.0)
            rot = rot @ rz(-theta)
            phi += theta
        frac = (si - bounds[i]) / lengths[i]
        out.append(pos + rot @ local(kappa[i] * lengths[i], lengths[i], frac))
        angles.append(phi + kappa[i] * lengths[i] * frac)
    return np.array(out), np.array(angles)


def test_zero_curvature_is_a_straight_line_of_length_L():
    s = default_s_m(LENGTHS)
    pos, ang = forward_kinematics(np.zeros(16), LENGTHS, s)
    np.testing.assert_array_equal(pos[:, 0], 0.0)
    np.testing.assert_allclose(pos[:, 1], s, rtol=0, atol=1e-16)
    np.testing.assert_array_equal(ang, 0.0)
    tip, tip_angle = tip_pose(np.zeros(16), LENGTHS)
    np.testing.assert_allclose(tip, [0.0, L], atol=1e-16)
    assert tip_angle == 0.0


@pytest.mark.parametrize("kappa", [25.0, 6.63, -12.5, 1.0])
def test_constant_curvature_gives_exact_circle_points(kappa):
    s = np.linspace(0.0, L, 57)
    pos, ang = forward_kinematics(np.full(16, kappa), LENGTHS, s)
    expected = np.stack(((1 - np.cos(kappa * s)) / kappa, np.sin(kappa * s) / kappa), axis=-1)
    np.testing.assert_allclose(pos, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ang, kappa * s, rtol=0, atol=1e-14)
    # the centre of curvature is at (1/kappa, 0): every point at distance 1/|kappa|
    np.testing.assert_allclose(np.hypot(pos[:, 0] - 1 / kappa, pos[:, 1]), 1 / abs(kappa), rtol=1e-13)


def test_matches_the_papers_transform_chain():
    rng = np.random.default_rng(7)
    kappa = rng.uniform(-30, 30, 16)
    kappa[3] = 0.0
    s = np.sort(rng.uniform(0, L, 40))
    s = np.concatenate((s, BOUNDS))
    pos, ang = forward_kinematics(kappa, LENGTHS, s)
    ref_pos, ref_ang = paper_chain(kappa, LENGTHS, s)
    np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ang, ref_ang, rtol=0, atol=1e-14)


def test_continuity_at_segment_junctions():
    rng = np.random.default_rng(3)
    kappa = rng.uniform(-40, 40, 16)
    eps = 1e-9
    junctions = BOUNDS[1:-1]
    before, a_before = forward_kinematics(kappa, LENGTHS, junctions - eps)
    after, a_after = forward_kinematics(kappa, LENGTHS, junctions + eps)
    np.testing.assert_array_less(np.hypot(*(after - before).T), 2 * eps * (1 + 1e-6))
    np.testing.assert_array_less(np.abs(a_after - a_before), 2 * eps * 40 + 1e-15)
    # the tangent is continuous too: finite differences across each junction follow it
    chord = (after - before) / (2 * eps)
    tangent = np.stack((np.sin(a_before), np.cos(a_before)), axis=-1)
    np.testing.assert_allclose(chord, tangent, atol=1e-6)


def arc_length(kappa, n=20001):
    s = np.linspace(0.0, L, n)
    pos, _ = forward_kinematics(kappa, LENGTHS, s)
    return np.sum(np.hypot(*np.diff(pos, axis=-2).T))


def test_arc_length_is_preserved():
    rng = np.random.default_rng(11)
    for _ in range(3):
        kappa = rng.uniform(-50, 50, 16)
        # a chord of an arc of length h is h (1 − κ²h²/24): relative error ~1e-9 here
        assert arc_length(kappa) == pytest.approx(L, rel=1e-8)


curvatures = st.lists(
    st.one_of(st.just(0.0), st.floats(-60, -1e-3), st.floats(1e-3, 60)),
    min_size=16,
    max_size=16,
).map(np.array)


@settings(max_examples=40, deadline=None)
@given(kappa=curvatures, base=st.floats(-3.0, 3.0))
def test_property_against_the_paper_chain_and_invariants(kappa, base):
    s = np.linspace(0.0, L, 23)
    pos, ang = forward_kinematics(kappa, LENGTHS, s, base_angle_rad=base)
    ref_pos, ref_ang = paper_chain(kappa, LENGTHS, s)
    # a base angle rotates the whole curve about the origin (R_z(−base))
    c, s_ = math.cos(base), math.sin(base)
    rotated = np.stack((c * ref_pos[:, 0] + s_ * ref_pos[:, 1], -s_ * ref_pos[:, 0] + c * ref_pos[:, 1]), axis=-1)
    np.testing.assert_allclose(pos, rotated, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ang, ref_ang + base, rtol=0, atol=1e-12)
    # points never leave the ball of radius s around the base (length is preserved)
    assert np.all(np.hypot(pos[:, 0], pos[:, 1]) <= s + 1e-15)
    tip, tip_angle = tip_pose(kappa, LENGTHS, base)
    np.testing.assert_allclose(tip, pos[-1], atol=1e-15)
    assert tip_angle == pytest.approx(base + float(np.sum(kappa * LENGTHS)), abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(kappa=curvatures)
def test_property_arc_length(kappa):
    assert arc_length(kappa, n=4001) == pytest.approx(L, rel=1e-6)


def test_small_angle_limit_is_exact():
    s = default_s_m(LENGTHS)
    p0, a0 = forward_kinematics(np.zeros(16), LENGTHS, s)
    p1, a1 = forward_kinematics(np.full(16, 1e-12), LENGTHS, s)
    # x = κ s²/2 to first order: ~9e-15 m at the tip; nothing else changes
    np.testing.assert_allclose(p1[:, 0], 1e-12 * s**2 / 2, rtol=1e-9, atol=1e-30)
    np.testing.assert_allclose(p1[:, 1], p0[:, 1], rtol=0, atol=1e-16)
    np.testing.assert_allclose(a1, 1e-12 * s, rtol=1e-12)
    assert np.max(np.abs(p1 - p0)) < 1e-14
    np.testing.assert_allclose(arc_positions(1e-12, s), p1, rtol=0, atol=1e-16)


def test_broadcasting_over_batches_and_base_angles():
    rng = np.random.default_rng(5)
    kappa = rng.uniform(-30, 30, (2, 3, 4, 16))
    base = rng.uniform(-1, 1, (2, 3, 4))
    s = np.linspace(0, L, 13)
    pos, ang = forward_kinematics(kappa, LENGTHS, s, base_angle_rad=base)
    assert pos.shape == (2, 3, 4, 13, 2) and ang.shape == (2, 3, 4, 13)
    for idx in np.ndindex(2, 3, 4):
        p, a = forward_kinematics(kappa[idx], LENGTHS, s, base_angle_rad=base[idx])
        np.testing.assert_allclose(pos[idx], p, rtol=0, atol=1e-16)
        np.testing.assert_allclose(ang[idx], a, rtol=0, atol=1e-15)
    tip, tip_angle = tip_pose(kappa, LENGTHS, base)
    assert tip.shape == (2, 3, 4, 2) and tip_angle.shape == (2, 3, 4)
    np.testing.assert_allclose(tip, pos[..., -1, :], atol=1e-16)
    # frames of a (frames, N) batch
    flat = kappa.reshape(-1, 16)
    pos2, _ = forward_kinematics(flat, LENGTHS, s, base_angle_rad=base.reshape(-1))
    np.testing.assert_array_equal(pos2.reshape(pos.shape), pos)


def test_unsorted_points_and_range_check():
    kappa = np.linspace(-10, 20, 16)
    s = np.array([0.1, 0.0, L, 0.05, 0.0101])
    pos, ang = forward_kinematics(kappa, LENGTHS, s)
    order = np.argsort(s)
    pos_sorted, ang_sorted = forward_kinematics(kappa, LENGTHS, s[order])
    np.testing.assert_array_equal(pos[order], pos_sorted)
    np.testing.assert_array_equal(ang[order], ang_sorted)
    with pytest.raises(ValueError, match=r"s_m: arc lengths must lie in \[0, 0.132\] m"):
        forward_kinematics(kappa, LENGTHS, [0.0, L + 1e-6])
    with pytest.raises(ValueError, match="s_m"):
        forward_kinematics(kappa, LENGTHS, [-1e-3])
    with pytest.raises(ValueError, match="curvature_per_m: expected 16 values"):
        forward_kinematics(kappa[:15], LENGTHS, s)


def test_shifts_to_curvatures():
    d = SENSOR.strip_gap_m
    # a constant-curvature arc: S_i = κ d L_i gives κ on every segment (paper V-B, eq. 3–4)
    shifts = 12.5 * d * np.cumsum(LENGTHS)
    np.testing.assert_allclose(shifts_to_curvatures(shifts, LENGTHS, d), 12.5, rtol=1e-12)
    rng = np.random.default_rng(2)
    S = rng.normal(size=(4, 16)) * 1e-4
    kappa = shifts_to_curvatures(S, LENGTHS, d)
    expected = np.empty_like(S)
    expected[:, 0] = S[:, 0] / (d * LENGTHS[0])
    for i in range(1, 16):
        expected[:, i] = (S[:, i] - S[:, i - 1]) / (d * LENGTHS[i])
    np.testing.assert_allclose(kappa, expected, rtol=1e-12)


def brute_force_kappa(pos, s):
    """Independent eq. 19: bounded scalar minimisation of the trapezoid integral."""

    def cost(k):
        p = np.stack(((1 - np.cos(k * s)) / k, np.sin(k * s) / k), axis=-1) if k != 0 else np.stack((0 * s, s), axis=-1)
        return np.trapezoid(np.sum((pos - p) ** 2, axis=-1), s)

    return minimize_scalar(cost, bounds=(-60, 60), method="bounded", options={"xatol": 1e-10}).x


def test_fit_arc_curvature():
    s = default_s_m(LENGTHS)
    # exact on arcs (including κ = 0 exactly)
    for k in (0.0, 21.86, -6.63, 1e-9):
        pos = arc_positions(k, s)
        assert fit_arc_curvature(pos, s) == pytest.approx(k, abs=1e-10)
    straight, _ = forward_kinematics(np.zeros(16), LENGTHS, s)
    assert fit_arc_curvature(straight, s) == 0.0
    # on non-circular PCC shapes: the same minimiser as a brute-force scalar search
    rng = np.random.default_rng(4)
    kappa = rng.normal(12, 4, (3, 16))
    pos, _ = forward_kinematics(kappa, LENGTHS, s)
    fitted = fit_arc_curvature(pos, s)
    assert fitted.shape == (3,)
    for i in range(3):
        assert fitted[i] == pytest.approx(brute_force_kappa(pos[i], s), abs=1e-7)


def test_max_position_error():
    s = default_s_m(LENGTHS)
    kappa = 10.0
    pos = np.stack((np.zeros_like(s), s), axis=-1)  # straight line vs an arc of κ = 10
    arc = np.stack(((1 - np.cos(kappa * s)) / kappa, np.sin(kappa * s) / kappa), axis=-1)
    expected = np.max(np.linalg.norm(pos - arc, axis=-1)) / L * 100
    assert max_position_error(pos, s, kappa, L) == pytest.approx(expected, rel=1e-12)
    assert max_position_error(arc, s, kappa, L) == pytest.approx(0.0, abs=1e-12)
    batch = np.stack((pos, arc))
    np.testing.assert_allclose(max_position_error(batch, s, [kappa, kappa], L), [expected, 0.0], atol=1e-12)


def linear_calibration(gain_m_per_unit=1e-5):
    """S = ±gain · ΔA, the odd and even channels with opposite signs; range ±500 units."""
    return helpers.linear_calibration(gain_m_per_unit, offset=np.linspace(100.0, 250.0, 16), delta_a=500.0,
                                      noise_std=None, sensor=None)


def signals_for(kappa, cal, gain=1e-5):
    return helpers.signals_for(kappa, cal, gain)


def test_reconstruct_chain():
    cal = linear_calibration()
    rng = np.random.default_rng(9)
    kappa = rng.uniform(-20, 20, (5, 16))
    shape = reconstruct(signals_for(kappa, cal), cal, SENSOR)
    assert isinstance(shape, Shape)
    np.testing.assert_allclose(shape.curvature_per_m, kappa, rtol=1e-9, atol=1e-9)
    assert shape.s_m.shape == (101,) and shape.s_m[-1] == L
    pos, ang = forward_kinematics(kappa, LENGTHS, shape.s_m)
    np.testing.assert_allclose(shape.positions_m, pos, atol=1e-12)
    np.testing.assert_allclose(shape.angle_rad, ang, atol=1e-9)
    np.testing.assert_allclose(shape.tip_position_m, pos[:, -1], atol=1e-12)
    np.testing.assert_allclose(shape.tip_angle_rad, ang[:, -1], atol=1e-9)
    assert shape.extrapolated.shape == (5,) and not shape.extrapolated.any()
    # sensor=None is the paper's sensor; a whole Config is accepted as well
    other = reconstruct(signals_for(kappa, cal)[0], cal, None, s_m=[0.0, L])
    np.testing.assert_allclose(other.positions_m, pos[0, [0, -1]], atol=1e-12)
    assert reconstruct(signals_for(kappa, cal), cal, load_config()).positions_m.shape == (5, 101, 2)


def test_reconstruct_flags_extrapolation_per_frame():
    cal = linear_calibration()
    kappa = np.array([np.full(16, 5.0), np.full(16, 80.0)])  # the second needs |ΔA| > 500
    shape = reconstruct(signals_for(kappa, cal), cal, SENSOR)
    assert shape.extrapolated.tolist() == [False, True]
    np.testing.assert_allclose(shape.curvature_per_m[1], 80.0, rtol=1e-9)  # computed anyway, but flagged


def test_reconstruct_errors():
    cal = linear_calibration()
    with pytest.raises(ValueError, match=r"signals: expected 16 channels"):
        reconstruct(np.zeros((3, 15)), cal, SENSOR)
    short = load_config().sensor.__class__(
        n_segments=2, segment_lengths_m=(0.01, 0.01), strip_gap_m=0.001, sleeve_thickness_m=0.0
    )
    with pytest.raises(ConfigError, match=r"calibration.n_channels: expected 2 \(sensor.n_segments\), got 16"):
        reconstruct(np.zeros(2), cal, short)


def test_shape_indexing_and_plot(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = Shape.from_curvatures(np.linspace(0, 20, 3)[:, None] * np.ones(16), LENGTHS, s_m=np.linspace(0, L, 11))
    assert len(shape) == 3 and shape.batch_shape == (3,)
    one = shape[1]
    assert one.positions_m.shape == (11, 2) and one.batch_shape == ()
    np.testing.assert_array_equal(one.tip_position_m, shape.tip_position_m[1])
    assert shape[1:].positions_m.shape == (2, 11, 2)
    assert shape.frame(2).tip_angle_rad == pytest.approx(20 * L)
    ax = shape.plot()
    # in mm like every other figure: a line per frame, its tip dot, the base
    assert ax.get_xlabel() == "x [mm]" and len(ax.lines) == 3 * 2 + 1
    np.testing.assert_allclose(np.column_stack(ax.lines[2].get_data()), shape.positions_m[1] * 1e3)
    ax.figure.savefig(tmp_path / "shape.png")
    assert (tmp_path / "shape.png").stat().st_size > 0
    # many frames: no legend of 50 labels, a colour bar of the frames says what the colours mean
    many = Shape.from_curvatures(np.linspace(0, 20, 200)[:, None] * np.ones(16), LENGTHS, s_m=np.linspace(0, L, 11))
    ax = many.plot()
    bars = [a for a in ax.figure.axes if a is not ax]
    assert ax.get_legend() is None and len(bars) == 1 and bars[0].get_ylabel() == "frame"
    assert bars[0].get_ylim() == (0.0, 199.0)
    plt.close("all")


def test_reconstruct_blocks_and_base_angles_agree_with_single_frames():
    cal = linear_calibration()
    rng = np.random.default_rng(12)
    kappa = rng.uniform(-20, 20, (4100, 16))  # more than one block of the fused kernel
    signals = signals_for(kappa, cal)
    s = np.linspace(0, L, 7)
    batch = reconstruct(signals, cal, SENSOR, s_m=s, base_angle_rad=0.3)
    for i in (0, 4095, 4096, 4099):
        one = reconstruct(signals[i], cal, SENSOR, s_m=s, base_angle_rad=0.3)
        np.testing.assert_allclose(batch.positions_m[i], one.positions_m, rtol=0, atol=1e-16)
        np.testing.assert_allclose(batch.angle_rad[i], one.angle_rad, rtol=0, atol=1e-15)
    per_frame_base = reconstruct(signals, cal, SENSOR, s_m=s, base_angle_rad=np.full(4100, 0.3))
    np.testing.assert_allclose(per_frame_base.positions_m, batch.positions_m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(per_frame_base.tip_angle_rad, batch.tip_angle_rad, rtol=0, atol=1e-13)
    pos, _ = forward_kinematics(batch.curvature_per_m, LENGTHS, s, base_angle_rad=0.3)
    np.testing.assert_allclose(batch.positions_m, pos, rtol=0, atol=1e-16)


def test_the_grid_cache_leaves_the_callers_arrays_alone():
    lengths, s = LENGTHS.copy(), np.linspace(0.0, L, 7)
    kappa = np.full(16, 10.0)
    first, _ = forward_kinematics(kappa, lengths, s)
    assert lengths.flags.writeable and s.flags.writeable
    # an array changed in place is a new grid, not the cached one: one arc of 10 /m over twice the length
    lengths *= 2.0
    second, _ = forward_kinematics(kappa, lengths, 2.0 * s)
    np.testing.assert_allclose(second[-1], arc_tip(10.0, 2.0 * L), atol=1e-12)
    np.testing.assert_allclose(first[-1], arc_tip(10.0, L), atol=1e-12)


def arc_tip(kappa, length):
    theta = kappa * length
    return np.array([(1.0 - np.cos(theta)) / kappa, np.sin(theta) / kappa])
