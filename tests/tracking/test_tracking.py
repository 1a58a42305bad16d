"""Tracking the force over time (issue 22): the filter and smoother against a dense least-squares solution,
the bandwidth against its definition, the floor, the explicit cases, streaming, and accuracy on a ramp-and-hold.

The independent references are written here: the smoothed states are the generalised
least-squares solution of all frames at once (a dense solve of the force-and-rate
trend's information matrix), the filtered state at frame k the same solution over frames
≤ k; the process noise of a bandwidth B comes from scipy's discrete algebraic Riccati
solver and a root search on the −3 dB condition (not from the library's doubling and
bisection).
"""

import dataclasses
import functools

import numpy as np
import pytest
from forward_model import HiddenSensor, forward
from scipy.linalg import solve_discrete_are
from scipy.optimize import brentq

import bendsense
from bendsense import Track, estimate_force, reconstruct, track
from bendsense.calibration import Calibration
from bendsense.errors import ArgumentError
from bendsense.estimation import ForceEstimate
from bendsense.status import Status
from bendsense.tracking import Tracker
from bendsense.tracking._kalman_kernels import DIFFUSE, DIFFUSE_RATE, process_intensity

CFG = dataclasses.replace(bendsense.load_config(), parameter_covariance=None)
SENSOR = CFG.sensor
RATE_HZ = 2000.0


def q_unit(dt):
    """The integrated random walk's process noise per unit intensity over dt: [[dt³/3, dt²/2], [dt²/2, dt]]."""
    return np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])


@functools.lru_cache(maxsize=64)
def reference_intensity(bandwidth_hz, dt_s):
    """q [1/s³] of the trend model whose steady filter is −3 dB at ``bandwidth_hz``: scipy's DARE, a root search.

    Force and rate, F = [[1, Δt], [0, 1]], H = [1, 0], R = 1, Q = q q_unit(Δt); the
    steady prior covariance from ``scipy.linalg.solve_discrete_are``, the gain K, the
    force output's response ``e₁ᵀ (I − (I − K H) F e^(−iω))⁻¹ K`` at ω = 2π B Δt.
    """
    F = np.array([[1.0, dt_s], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    w = 2 * np.pi * bandwidth_hz * dt_s

    def excess(log_q):
        P = solve_discrete_are(F.T, H.T, np.exp(log_q) * q_unit(dt_s), np.eye(1))
        K = P @ H.T / (H @ P @ H.T + 1.0)
        M = (np.eye(2) - K @ H) @ F
        h = (np.linalg.inv(np.eye(2) - M * np.exp(-1j * w)) @ K)[0, 0]
        return abs(h) ** 2 - 0.5

    return float(np.exp(brentq(excess, np.log(1e-20 / dt_s ** 3), np.log(10.0 / dt_s ** 3), xtol=1e-12)))


def synthetic(n, rng, *, floor=1e-8):
    """A ForceEstimate of ``n`` frames by hand: forces, noise covariances (correlated), a floor, all ok."""
    a = rng.uniform(0.5e-3, 3e-3, (n, 2))
    c = rng.uniform(-0.8, 0.8, n)
    R = np.empty((n, 2, 2))
    R[:, 0, 0], R[:, 1, 1] = a[:, 0] ** 2, a[:, 1] ** 2
    R[:, 0, 1] = R[:, 1, 0] = c * a[:, 0] * a[:, 1]
    parts = np.zeros((n, 3, 2, 2))
    parts[:, 0] = R
    parts[:, 1] = np.eye(2) * floor
    parts[:, 2] = np.array([[2.0, 0.5], [0.5, 1.0]]) * floor
    truth = np.cumsum(rng.normal(0, 2e-3, (n, 2)), axis=0)
    z = truth + np.einsum("nij,nj->ni", np.linalg.cholesky(R), rng.standard_normal((n, 2)))
    return _estimate(z, parts), truth


def _estimate(z, parts, success=None, message=None):
    n = z.shape[0]
    success = np.ones(n, bool) if success is None else success
    cov = parts.sum(axis=1)
    return ForceEstimate(
        force_n=z, std_n=np.sqrt(np.diagonal(cov, axis1=1, axis2=2)), covariance_n2=cov, residual_m=np.zeros(n),
        success=success, status=np.where(success, Status.OK, Status.NOT_CONVERGED).astype(np.int8),
        message=np.full(n, "converged") if message is None else message, iterations=np.ones(n, int),
        wall_time_s=0.0, method="fast", constraint="none", covariance_parts_n2=parts)


def _cut(est, lo, hi):
    """Frames lo:hi of a ForceEstimate."""
    B = est.batch_shape[0]
    return dataclasses.replace(est, **{
        f.name: getattr(est, f.name)[lo:hi] for f in dataclasses.fields(est)
        if isinstance(getattr(est, f.name), np.ndarray) and getattr(est, f.name).ndim
        and getattr(est, f.name).shape[0] == B})


def gls(z, R, use, Q, restart, dt):
    """Dense generalised least squares of the force-and-rate trend: smoothed forces and covariances (B, 2), (B, 2, 2).

    Unknowns (Fx, Fy, Ḟx, Ḟy) at each frame; rows: z_k = H_k x_k + v_k (observed force
    components), x_k − F_k x_(k−1) ~ N(0, Q_k) (F_k = [[I, Δt_k I], [0, I]]) unless k
    restarts, x at a restart ~ N(0, diag(DIFFUSE, DIFFUSE, DIFFUSE_RATE, DIFFUSE_RATE)).
    """
    B = z.shape[0]
    A = np.zeros((4 * B, 4 * B))
    b = np.zeros(4 * B)
    prior = np.diag([DIFFUSE, DIFFUSE, DIFFUSE_RATE, DIFFUSE_RATE])
    for k in range(B):
        s = slice(4 * k, 4 * k + 4)
        obs = np.flatnonzero(use[k])
        if obs.size:
            Ri = np.linalg.inv(R[k][np.ix_(obs, obs)])
            H = np.eye(4)[obs]
            A[s, s] += H.T @ Ri @ H
            b[s] += H.T @ Ri @ z[k, obs]
        if restart[k]:
            A[s, s] += np.linalg.inv(prior)
        else:  # the row x_k − F x_(k−1): [−F, I] with weight Q⁻¹
            F = np.eye(4)
            F[0, 2] = F[1, 3] = dt[k]
            J = np.zeros((4, 4 * B))
            J[:, 4 * k - 4:4 * k] = -F
            J[:, s] = np.eye(4)
            A += J.T @ np.linalg.inv(Q[k]) @ J
    d = 1.0 / np.sqrt(np.diag(A))  # equilibrated: forces [N] and rates [N/s] differ by the frame rate
    C = d[:, None] * np.linalg.inv(d[:, None] * A * d[None, :]) * d[None, :]
    x = C @ b
    return x.reshape(B, 4)[:, :2], np.array([C[4 * k:4 * k + 2, 4 * k:4 * k + 2] for k in range(B)])


def _reference_q(est, bandwidth_hz, t):
    """The process noise of the design: q(B, median Δt) R̄ ⊗ q_unit(Δt_k), R̄ the latest full frame's noise variances."""
    R = est.covariance_parts_n2[:, 0]
    z = np.asarray(est.force_n)
    use = np.isfinite(z) & np.isfinite(est.std_n)
    Q = np.zeros((z.shape[0], 4, 4))
    ref = np.zeros((2, 2))
    dt = np.diff(t, prepend=t[0])
    q = reference_intensity(bandwidth_hz, float(np.median(np.diff(t))))
    for k in range(z.shape[0]):
        Q[k] = q * np.kron(q_unit(dt[k]), ref)
        if use[k].all():
            ref = np.diag(np.diag(R[k]))
    return z, R, use, Q, dt


@pytest.fixture(scope="module")
def cases():
    """A series with a failed frame, a frame observed along y only, a gap and a pressure step."""
    rng = np.random.default_rng(3)
    est, truth = synthetic(60, rng)
    z = est.force_n.copy()
    std = est.std_n.copy()
    success = est.success.copy()
    message = est.message.astype(object)
    status = est.status.copy()
    z[10] = np.nan  # failed
    success[10] = False
    message[10] = "no convergence in the iteration limit"
    status[10] = Status.NOT_CONVERGED
    std[25, 0] = np.inf  # not identifiable along x
    message[25] = "not identifiable along (1.000, 0.000): ..."
    status[25] = Status.NOT_IDENTIFIABLE
    est = dataclasses.replace(est, force_n=z, std_n=std, success=success, status=status, message=message.astype(str))
    t = np.arange(60) / RATE_HZ
    t[40:] += 0.1  # a gap
    pressure = np.full(60, 40e3)
    pressure[50:] = 45e3  # a pressure step
    return est, t, pressure


@pytest.mark.parametrize("mode", ["smooth", "filter"])
def test_the_tracker_equals_a_dense_least_squares_solution(cases, mode):
    est, t, pressure = cases
    B = 30.0
    tr = track(est, t, mode=mode, bandwidth_hz=B, pressure_pa=pressure)
    z, R, use, Q, dt = _reference_q(est, B, t)
    restart = np.zeros(60, bool)
    restart[[0, 40, 50]] = True
    floor = est.covariance_parts_n2[:, 1] + est.covariance_parts_n2[:, 2]
    floor[10] = floor[9]  # a failed frame carries the floor of its neighbour
    if mode == "smooth":
        x, P = gls(z, R, use, Q, restart, dt)
    else:  # the filtered state: the same solution over the frames up to k
        x, P = np.empty((60, 2)), np.empty((60, 2, 2))
        for k in range(60):
            xs, Ps = gls(z[:k + 1], R, use, Q, restart, dt)
            x[k], P[k] = xs[k], Ps[k]
    np.testing.assert_allclose(tr.force_n, x, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(tr.covariance_n2, P + floor, rtol=1e-6, atol=1e-14)
    assert tr.bandwidth_hz == B and tr.mode == mode
    assert tr.status[10] == Status.NOT_CONVERGED and tr.status[25] == Status.NOT_IDENTIFIABLE
    assert tr.status[0] == Status.OK and tr.to_columns()["track_status"][25] == "not_identifiable"


def test_a_restart_forgets_the_past_and_the_floor_is_never_averaged_down(cases):
    est, t, pressure = cases
    tr = track(est, t, mode="filter", bandwidth_hz=5.0, pressure_pa=pressure)
    parts = est.covariance_parts_n2
    for k in (40, 50):  # after a gap and a pressure step: the frame's own estimate and covariance
        np.testing.assert_allclose(tr.force_n[k], est.force_n[k], rtol=1e-9)
        np.testing.assert_allclose(tr.covariance_n2[k], parts[k].sum(axis=0), rtol=1e-6)
    floor = np.diagonal(parts[:, 1] + parts[:, 2], axis1=1, axis2=2)
    ok = np.isfinite(floor).all(axis=1)
    assert np.all(tr.std_n[ok] ** 2 >= floor[ok])
    # a frame without a force is predicted only: the state moves by its rate, its σ grows; nothing else learnt
    assert np.isfinite(tr.force_n[10]).all() and np.all(tr.std_n[10] > tr.std_n[9])
    other = dataclasses.replace(est, force_n=np.where(np.arange(60)[:, None] == 10, np.nan, est.force_n))
    np.testing.assert_array_equal(track(other, t, mode="filter", bandwidth_hz=5.0, pressure_pa=pressure).force_n,
                                  tr.force_n)
    # x is not observed at frame 25: its filtered x changes only through its correlation with y
    assert np.isfinite(tr.force_n[25]).all()


def test_the_bandwidth_is_the_minus_3_db_frequency_of_the_steady_state_filter():
    """A sinusoid at B through the filter comes out at 1/√2 of its amplitude (uncorrelated noise, constant R)."""
    n = 8000
    t = np.arange(n) / RATE_HZ
    for B in (2.0, 20.0, 200.0):
        z = np.stack([np.sin(2 * np.pi * B * t), 0.5 * np.cos(2 * np.pi * B * t)], axis=1)
        parts = np.zeros((n, 3, 2, 2))
        parts[:, 0] = np.diag([1e-6, 4e-6])
        tr = track(_estimate(z, parts), t, mode="filter", bandwidth_hz=B)
        late = t > t[-1] / 2
        basis = np.stack([np.sin(2 * np.pi * B * t[late]), np.cos(2 * np.pi * B * t[late])], axis=1)
        for c, amplitude in ((0, 1.0), (1, 0.5)):
            coef = np.linalg.lstsq(basis, tr.force_n[late, c], rcond=None)[0]
            assert np.hypot(*coef) / amplitude == pytest.approx(2 ** -0.5, rel=2e-3)


def test_the_bandwidth_maps_to_the_steady_state_filter_of_the_trend_model():
    """The library's q(B, Δt) (structured doubling, bisection) is scipy's DARE and a root search, to 1e-6."""
    for B, dt in ((0.05, 5e-4), (2.0, 5e-4), (20.0, 5e-4), (200.0, 5e-4), (5.0, 0.01), (30.0, 1e-3)):
        assert process_intensity(B, dt) == pytest.approx(reference_intensity(B, dt), rel=1e-6)


def test_the_maximum_likelihood_bandwidth_finds_the_trend():
    """A force whose rate is a random walk of known intensity, observed in noise: the chosen B is the one of its q."""
    rng = np.random.default_rng(5)
    n, dt = 20000, 1 / RATE_HZ
    for B_true in (3.0, 40.0):
        q = reference_intensity(B_true, dt)
        R = np.diag([1e-6, 2.25e-6])
        L = np.linalg.cholesky(np.kron(q_unit(dt), q * R))  # the exact increments of (Fx, Fy, Ḟx, Ḟy)
        x = np.zeros(4)
        truth = np.empty((n, 2))
        F = np.eye(4)
        F[0, 2] = F[1, 3] = dt
        for k in range(n):
            x = F @ x + L @ rng.standard_normal(4)
            truth[k] = x[:2]
        z = truth + rng.standard_normal((n, 2)) * np.sqrt(np.diag(R))
        parts = np.zeros((n, 3, 2, 2))
        parts[:, 0] = R
        tr = track(_estimate(z, parts), np.arange(n) * dt)
        assert tr.bandwidth_hz == pytest.approx(B_true, rel=0.25)


def test_the_shortened_search_finds_the_likelihood_maximum_of_a_dense_grid():
    """Every m-th frame, then parabolas on the whole series: B within 1 % of the best of a dense grid (0.2 % apart)."""
    import importlib

    mod = importlib.import_module("bendsense.tracking.track")
    rng = np.random.default_rng(11)
    n, dt = 12000, 1 / RATE_HZ
    t = np.arange(n) * dt
    truth = np.stack([0.05 * np.sin(2 * np.pi * 1.3 * t), 0.03 * np.minimum(t % 1.0, 0.4)], axis=1)  # smooth, ramps
    R = np.diag([4e-6, 9e-6])
    z = truth + rng.standard_normal((n, 2)) * np.sqrt(np.diag(R))
    Rn = np.broadcast_to(R, (n, 2, 2)).copy()
    starts = np.zeros(n, bool)
    starts[[0, 7000]] = True
    dts = np.diff(t, prepend=0.0)
    chosen = mod.ml_bandwidth(z, Rn, dts, starts, dt)
    grid = np.logspace(np.log10(chosen) - 0.3, np.log10(chosen) + 0.3, 301)
    ll = mod._log_likelihoods(z, Rn, dts, starts, grid, dt)
    assert 0 < np.argmax(ll) < grid.size - 1
    assert chosen == pytest.approx(grid[np.argmax(ll)], rel=0.01)


def test_streaming_block_by_block_gives_the_filter_of_the_whole_series(cases):
    est, t, pressure = cases
    whole = track(est, t, mode="filter", bandwidth_hz=12.0, pressure_pa=pressure)
    tracker = Tracker(bandwidth_hz=12.0)
    cuts = [0, 1, 7, 8, 30, 41, 59, 60]
    blocks = [tracker.update(_cut(est, lo, hi), t[lo:hi], pressure[lo:hi]) for lo, hi in zip(cuts[:-1], cuts[1:])]
    for name in ("force_n", "std_n", "covariance_n2"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in blocks]), getattr(whole, name))
    np.testing.assert_array_equal(np.concatenate([b.status for b in blocks]), whole.status)
    with pytest.raises(ArgumentError, match="t_s_block: must not decrease"):
        tracker.update(_cut(est, 0, 2), t[:2], pressure[:2])


def test_bad_arguments_are_named(cases):
    est, t, _ = cases
    with pytest.raises(ArgumentError, match="mode: must be one of smooth, filter"):
        track(est, t, mode="kalman")
    with pytest.raises(ArgumentError, match="bandwidth_hz: expected a frequency > 0"):
        track(est, t, bandwidth_hz=-1.0)
    with pytest.raises(ArgumentError, match="mode: a Tracker filters causally"):
        Tracker(mode="smooth")
    with pytest.raises(ArgumentError, match="estimate: expected the estimates of a time series"):
        track(dataclasses.replace(est, force_n=np.zeros((2, 30, 2))), t)
    tracker = Tracker()
    with pytest.raises(ArgumentError, match="t_s_block: expected finite times"):
        tracker.update(_cut(est, 0, 2), [0.0, np.nan])
    with pytest.raises(ArgumentError, match="t_s_block: must not decrease, got -1.0 s after 0.0 s"):
        tracker.update(_cut(est, 0, 2), [0.0, -1.0])
    np.testing.assert_array_equal(tracker.update(_cut(est, 0, 2), t[:2]).force_n,  # a refused block changed nothing
                                  Tracker().update(_cut(est, 0, 2), t[:2]).force_n)


def test_columns_and_plot(cases):
    import matplotlib
    import matplotlib.pyplot

    matplotlib.use("Agg")
    est, t, pressure = cases
    tr = track(est, t, bandwidth_hz=5.0, pressure_pa=pressure)
    assert isinstance(tr, Track)
    cols = tr.to_columns()
    assert list(cols) == ["fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n", "track_status"]
    np.testing.assert_array_equal(cols["fy_track_std_n"], tr.std_n[:, 1])
    assert tr.plot().get_xlabel() == "t [s]"
    # frames whose track is not ok (sigma of tens of newtons where the shape determines nothing) are left out
    # of the line and the band, and the limits follow the forces: before, the band set them (+-130 N for 0.1 N)
    wild = dataclasses.replace(tr, std_n=tr.std_n.copy(), status=tr.status.copy())
    wild.std_n[:20] = 60.0
    wild.status[:20] = Status.NOT_IDENTIFIABLE
    ax = wild.plot()
    low, high = ax.get_ylim()
    kept = np.asarray(tr.frame_force_n)[20:]
    assert high - low < 3 * (np.nanmax(kept) - np.nanmin(kept)) + 0.1
    ticks = [line for line in ax.get_lines() if line.get_marker() == "|"]
    assert len(ticks) == 1 and np.isin(t[:20], ticks[0].get_xdata()).all()
    matplotlib.pyplot.close("all")


# --------------------------------------------------------------------------- a ramp-and-hold on real sensors


@pytest.fixture(scope="module")
def ramp_and_hold(tmp_path_factory):
    """Five hidden sensors (1.5 counts, degree-5 calibrations), one 2 s ramp-and-hold series each at 2 kHz.

    Two holds at different loads joined by 0.3 s ramps, 30 kPa; the forward model's
    shifts exact at 51 points along the path, linear between (≪ the noise).
    """
    t = np.arange(4000) / RATE_HZ
    knots_t = [0, 0.3, 0.9, 1.2, 1.8, 2.0]
    knots_f = np.array([[0, 0], [0.06, -0.08], [0.06, -0.08], [-0.03, -0.1], [-0.03, -0.1], [0, 0]])
    truth = np.stack([np.interp(t, knots_t, knots_f[:, c]) for c in range(2)], axis=1)
    s_path = np.concatenate([np.linspace(a, b, 11)[:-1] for a, b in zip(knots_t[:-1], knots_t[1:])] + [[2.0]])
    f_path = np.stack([np.interp(s_path, knots_t, knots_f[:, c]) for c in range(2)], axis=1)
    exact = np.array([forward(CFG, 30e3, f).shifts_m for f in f_path])
    shifts = np.stack([np.interp(t, s_path, exact[:, j]) for j in range(exact.shape[1])], axis=1)
    runs = []
    for seed in range(1, 6):
        rng = np.random.default_rng(100 + seed)
        hidden = HiddenSensor(noise_counts=1.5, seed=seed)
        cal = Calibration.fit(hidden.write_calibration(tmp_path_factory.mktemp(f"r{seed}"), CFG, frames=1000),
                              degree=5)
        est = estimate_force(reconstruct(hidden.signals(shifts, rng), cal, SENSOR), 30e3, CFG, calibration=cal)
        runs.append((est, track(est, t), track(est, t, mode="filter")))
    return truth, runs


def test_the_smoother_cuts_the_error_and_covers_the_truth_over_several_sensors(ramp_and_hold):
    truth, runs = ramp_and_hold
    per_frame = np.concatenate([est.force_n - truth for est, _, _ in runs])
    smooth = np.concatenate([tr.force_n - truth for _, tr, _ in runs])
    inside = np.concatenate([np.abs(tr.force_n - truth) <= 2 * tr.std_n for _, tr, _ in runs])
    ratio = np.sqrt(np.mean(smooth ** 2) / np.mean(per_frame ** 2))
    assert ratio <= 0.45
    assert 0.85 <= inside[:, 0].mean() <= 0.99 and 0.85 <= inside[:, 1].mean() <= 0.99
    assert all((tr.status == Status.OK).mean() > 0.99 for _, tr, _ in runs)
    for est, smooth, filtered in runs:  # never below the frame's calibration and parameter parts
        floor = np.diagonal(est.covariance_parts_n2[:, 1] + est.covariance_parts_n2[:, 2], axis1=1, axis2=2)
        assert np.all(smooth.std_n ** 2 >= floor) and np.all(filtered.std_n ** 2 >= floor)
        assert np.all(smooth.std_n < est.std_n)  # and below the frame's own σ, where the noise averages down


def test_the_causal_filter_cuts_the_error_and_covers_the_truth_on_ramps_too(ramp_and_hold):
    """The force-and-rate state follows a ramp without lag: the filter's ±2σ holds over the whole series."""
    truth, runs = ramp_and_hold
    per_frame = np.concatenate([est.force_n - truth for est, _, _ in runs])
    filtered = np.concatenate([tr.force_n - truth for _, _, tr in runs])
    ratio = np.sqrt(np.mean(filtered ** 2) / np.mean(per_frame ** 2))
    inside = np.concatenate([np.abs(tr.force_n - truth) <= 2 * tr.std_n for _, _, tr in runs])
    assert ratio <= 0.6
    assert 0.85 <= inside[:, 0].mean() <= 0.99 and 0.85 <= inside[:, 1].mean() <= 0.99


def test_streaming_windows_report_the_latest_completed_window(ramp_and_hold):
    """A frame's streamed window p is that of the window completed when it arrived (offline: its own window's)."""
    from bendsense import check_windows

    est = ramp_and_hold[1][0][0]
    t = np.arange(4000) / RATE_HZ
    offline = check_windows(est, t).window_p_value
    tracker = Tracker(bandwidth_hz=10.0)
    cuts = list(range(0, 4000, 37)) + [4000]
    streamed = np.concatenate([tracker.update(_cut(est, lo, hi), t[lo:hi]).window_p_value
                               for lo, hi in zip(cuts[:-1], cuts[1:])])
    assert np.isnan(streamed[:100]).all()  # no window has completed yet
    np.testing.assert_array_equal(streamed[100:], offline[:-100])
    assert np.isfinite(offline).all() and np.unique(offline).size == 40


def test_a_tracker_takes_single_frames(cases):
    """The live path estimates one frame at a time (batch shape ()): the same numbers as blocks."""
    est, t, pressure = cases
    whole = Tracker(bandwidth_hz=12.0).update(est, t, pressure)
    tracker = Tracker(bandwidth_hz=12.0)
    one = [tracker.update(dataclasses.replace(
        _cut(est, k, k + 1), **{name: getattr(_cut(est, k, k + 1), name)[0] for name in
                                ("force_n", "std_n", "covariance_n2", "residual_m", "success", "status",
                                 "iterations", "covariance_parts_n2")}, message=str(est.message[k])), t[k], pressure[k])
        for k in range(60)]
    np.testing.assert_array_equal(np.concatenate([o.force_n for o in one]), whole.force_n)
    np.testing.assert_array_equal(np.concatenate([o.status for o in one]), whole.status)


@pytest.mark.parametrize("mode", ["smooth", "filter", "stream"])
def test_an_estimate_without_a_noise_model_never_tracks_ok_to_nan(mode):
    est, _ = synthetic(40, np.random.default_rng(5))
    # what estimate_force gives without a calibration: forces, no σ, no covariance parts
    est = dataclasses.replace(est, std_n=np.full((40, 2), np.nan), covariance_n2=np.full((40, 2, 2), np.nan),
                              covariance_parts_n2=None)
    t = np.arange(40) * 1e-3
    if mode == "stream":
        tracker = Tracker(bandwidth_hz=12.0)
        tr = [tracker.update(_cut(est, lo, lo + 8), t[lo:lo + 8]) for lo in range(0, 40, 8)]
        force, std, status = (np.concatenate([getattr(b, n) for b in tr]) for n in ("force_n", "std_n", "status"))
    else:
        tr = track(est, t, mode=mode, bandwidth_hz=12.0)
        force, std, status = tr.force_n, tr.std_n, tr.status
    nan = ~(np.isfinite(force).all(axis=1) & np.isfinite(std).all(axis=1))
    assert nan.any()  # nothing to weigh the frames with: the track has no value
    assert set(np.asarray(status)[nan]) == {Status.NO_FORCE}
