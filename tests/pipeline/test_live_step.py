"""The compiled live step (one call per block) against the offline chain, frame by frame.

The offline chain is the public functions a notebook calls on a whole series:
``reconstruct`` → ``estimate_force`` (one warm-started batch) → ``Tracker.update`` (the
whole series as one block) → ``frame_codes``. The live processor gets the same frames in
blocks of 1 to 16 frames and runs them through ``bendsense.pipeline._kernels.live_block``.
Its shapes are the same numbers, its forces agree to the Gauss–Newton tolerance (a
chain is cut at other frames), its statuses and messages are the same, and so is the
track. The frames include the hard ones: pressures outside the actuator's range, a
channel without a signal, signals beyond the calibrated range, frames without a pressure.
"""

import dataclasses

import numpy as np
import pytest

import bendsense
from bendsense._batched import expand_frames
from bendsense.calibration import Calibration
from bendsense.config import ParameterCovarianceConfig
from bendsense.estimation import _NO_SHAPE_MESSAGE, estimate_force
from bendsense.pipeline import LIVE_MAX_ITER, LiveProcessor
from bendsense.pipeline.live import _Step
from bendsense.results import frame_codes
from bendsense.sim.scenarios import time_varying_frames
from bendsense.status import Status
from bendsense.tracking import Tracker

RATE_HZ = 200.0
SIZES = (1, 3, 7, 2, 16, 1, 5)
S_C = 0.1


def _frames(seed, cal):
    """1.5 s of the simulated board (pressure ramps, contact on at 1.2 s), with hard frames put in."""
    rows = list(time_varying_frames(None, RATE_HZ, seed, duration_s=1.5))
    p = np.array([r[0] for r in rows], dtype=float)
    signals = np.array([r[1] for r in rows], dtype=float)
    hi = bendsense.load_config().actuator.pressure_range_pa[1]
    p[40] = hi + 30e3  # beyond the actuator's range: no force
    p[41] = -5e3  # below it
    signals[90, 3] = np.nan  # a channel without a signal: no shape
    odd, even = cal.delta_a_range_odd, cal.delta_a_range_even  # beyond the calibrated range, each way: extrapolated
    signals[120, ::2] = cal.offset[::2] + 1.2 * (odd[0] if odd[0] else odd[1])
    signals[120, 1::2] = cal.offset[1::2] + 1.2 * (even[1] if even[1] else even[0])
    return np.arange(len(rows)) / RATE_HZ, signals, p


def _blocks(proc, t, signals, p):
    """The processor's blocks of the frames, in the sizes of SIZES in turn."""
    blocks, lo, k = [], 0, 0
    while lo < t.size:
        hi = min(t.size, lo + SIZES[k % len(SIZES)])
        blocks.append(proc.process_block(signals[lo:hi], p[lo:hi], t_s=t[lo:hi]))
        lo, k = hi, k + 1
    return blocks


def assert_within(actual, desired, std, fraction=1e-3):
    """``actual`` equals ``desired`` to ``fraction`` of its σ (the Gauss–Newton iteration stops at a step of 1e-4 σ)."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    np.testing.assert_array_equal(np.isnan(actual), np.isnan(desired))
    both = np.isfinite(desired) & np.isfinite(std)
    np.testing.assert_array_less(np.abs(actual - desired)[both], fraction * np.asarray(std)[both] + 1e-15)


def _joined(blocks, name):
    return np.concatenate([np.asarray(getattr(b, name)) for b in blocks])


@pytest.fixture(scope="module")
def identified():
    """The paper's config with an identification's parameter covariance (1 % on μ̄, 2 % on EI)."""
    cfg = bendsense.load_config()
    sd = np.array([0.01 * cfg.material.shear_modulus_pa, 0.02 * cfg.stiffness.ei0_nm2,
                   0.02 * cfg.stiffness.ei1_nm2_per_pa])
    return cfg.replace(parameter_covariance=ParameterCovarianceConfig(
        parameters=("shear_modulus_pa", "ei0_nm2", "ei1_nm2_per_pa"), covariance=tuple(map(tuple, np.diag(sd**2)))))


@pytest.mark.parametrize("case", ["tip", "contact", "identified"])
def test_the_compiled_block_gives_the_offline_chain_frame_by_frame(calibration_path, identified, case):
    cal = Calibration.load(calibration_path)
    config = identified if case == "identified" else bendsense.load_config()
    load = {"load": "contact", "contact_s_m": S_C} if case == "contact" else {}
    t, signals, p = _frames(3, cal)
    proc = LiveProcessor(cal, config, constraint="normal", bandwidth_hz=30.0, **load)
    blocks = _blocks(proc, t, signals, p)
    assert isinstance(proc._step, _Step)  # the compiled step ran these blocks

    shape = bendsense.reconstruct(signals, cal, config.sensor, s_m=proc.s_m)
    # estimate_force refuses the frame without a shape: the others, and that one as the live step gives it
    ok = np.isfinite(shape.curvature_per_m).all(axis=1)
    est = expand_frames(estimate_force(shape.curvature_per_m[ok], p[ok], config, constraint="normal", calibration=cal,
                                       max_iter=LIVE_MAX_ITER, **load), ok)
    est = dataclasses.replace(est, status=np.where(ok, est.status, Status.NO_SHAPE).astype(np.int8),
                              message=np.where(ok, est.message, _NO_SHAPE_MESSAGE))
    tracked = Tracker(bandwidth_hz=30.0).update(est, t, p)

    # the shapes: the same kernel, the same numbers
    for name in ("curvature_per_m", "positions_m", "tip_angle_rad", "extrapolated"):
        np.testing.assert_array_equal(np.concatenate([getattr(b.shape, name) for b in blocks]), getattr(shape, name))
    # the forces, their σ and the model check: to the iteration's tolerance
    live = [b.estimate for b in blocks]
    assert_within(_joined(blocks, "force_n"), est.force_n, est.std_n)  # where the iteration stops: within 1e-3 σ
    np.testing.assert_allclose(_joined(blocks, "std_n"), est.std_n, rtol=2e-3)
    np.testing.assert_allclose(np.concatenate([e.p_value for e in live]), est.p_value, rtol=1e-3, atol=1e-9)
    np.testing.assert_array_equal(np.concatenate([e.status for e in live]), est.status)
    np.testing.assert_array_equal(np.concatenate([e.success for e in live]), est.success)
    np.testing.assert_array_equal(np.concatenate([e.message for e in live]), est.message)
    # the frames' statuses, and the hard frames got theirs
    codes = _joined(blocks, "status")
    np.testing.assert_array_equal(codes, frame_codes(shape, est))
    assert codes[40] == codes[41] == Status.PRESSURE_OUT_OF_RANGE and codes[90] == Status.NO_SHAPE
    assert shape.extrapolated[120] and codes[120] != Status.OK and np.isnan(_joined(blocks, "force_n")[[40, 41]]).all()
    # the track: its force, σ, window check and statuses
    assert_within(_joined(blocks, "track_force_n"), tracked.force_n, tracked.std_n)
    np.testing.assert_allclose(_joined(blocks, "track_std_n"), tracked.std_n, rtol=2e-3)
    np.testing.assert_allclose(_joined(blocks, "window_p_value"), tracked.window_p_value, rtol=1e-3, atol=1e-9)
    np.testing.assert_array_equal(_joined(blocks, "track_status"), tracked.status)
    assert np.isfinite(tracked.window_p_value).sum() > 100  # the window check ran
    if case == "identified":  # the parameters' part of σ is in
        assert np.nanmin(est.covariance_parts_n2[:, 2, 0, 0]) > 0
        np.testing.assert_allclose(np.concatenate([e.covariance_parts_n2 for e in live]), est.covariance_parts_n2,
                                   rtol=4e-3, atol=1e-15)
    # the results.csv rows of the blocks, joined, are one row per frame with the offline forces
    columns = [b.columns() for b in blocks]
    assert_within(np.concatenate([c["fx_n"] for c in columns]), est.force_n[:, 0], est.std_n[:, 0])
    assert list(columns[0]) == list(columns[-1]) and sum(len(c["status"]) for c in columns) == t.size


def test_frames_without_a_pressure_leave_the_others_as_they_were(calibration_path):
    """A board that loses its pressure sensor for some frames: those get a shape only, the rest their own force."""
    cal = Calibration.load(calibration_path)
    t, signals, p = _frames(4, cal)
    signals[90] = signals[89]  # a shape in every frame
    gone = np.zeros(t.size, dtype=bool)
    gone[[5, 6, 50, 51, 52, 200]] = True
    proc = LiveProcessor(cal, constraint="normal")
    blocks = _blocks(proc, t, signals, np.where(gone, np.nan, p))
    force, codes = _joined(blocks, "force_n"), _joined(blocks, "status")
    assert (codes[gone] == Status.NO_PRESSURE).all() and np.isnan(force[gone]).all()
    shape = bendsense.reconstruct(signals[~gone], cal, s_m=proc.s_m)
    est = estimate_force(shape, p[~gone], constraint="normal", calibration=cal, max_iter=LIVE_MAX_ITER)
    assert_within(force[~gone], est.force_n, est.std_n)
    assert proc.estimated == int((~gone).sum())
    messages = np.concatenate([b.estimate.message for b in blocks])
    assert (messages[gone] == "no pressure reading").all()


def test_options_the_step_does_not_run_go_through_estimate_force(calibration_path):
    """The paper's method and a contact located per frame: the general path, the same block objects."""
    cal = Calibration.load(calibration_path)
    t, signals, p = _frames(5, cal)
    for options in ({"method": "paper"}, {"load": "contact"}):
        proc = LiveProcessor(cal, constraint="normal", **options)
        block = proc.process_block(signals[100:102], p[100:102], t_s=t[100:102])
        assert proc._step is not None and not isinstance(proc._step, _Step)
        assert block.estimate is not None and np.isfinite(block.force_n).all()


def test_a_warmed_processor_pickles_and_goes_on_alike(calibration_path):
    """A processor that has run (its compiled step made) copies and pickles; the copy goes on as the original."""
    import copy
    import pickle

    cal = Calibration.load(calibration_path)
    t, signals, p = _frames(6, cal)
    proc = LiveProcessor(cal, constraint="normal")
    proc.process_block(signals[:20], p[:20], t_s=t[:20])
    assert isinstance(proc._step, _Step)
    for lo, copied in ((20, lambda x: pickle.loads(pickle.dumps(x))), (25, copy.deepcopy)):
        twin = copied(proc)
        mine, theirs = (x.process_block(signals[lo:lo + 5], p[lo:lo + 5], t_s=t[lo:lo + 5]) for x in (proc, twin))
        np.testing.assert_array_equal(theirs.force_n, mine.force_n)
        np.testing.assert_array_equal(theirs.status, mine.status)
        proc = twin  # the next copy is of the copy that went on


def test_a_block_without_frames_is_an_empty_block(calibration_path):
    """A loop that finds nothing arrived gets an empty block (columns of no rows), and the counts stay."""
    proc = LiveProcessor(Calibration.load(calibration_path), constraint="normal")
    for block in (proc.process_readings([]), proc.process_block(np.empty((0, 16)), np.empty(0), t_s=np.empty(0))):
        assert len(block) == 0 and block.force_n.shape == (0, 2) and block.status.shape == (0,)
        columns = block.columns()
        assert all(len(v) == 0 for v in columns.values()) and "fx_n" in columns and "kappa16" in columns
    assert proc.frames == 0 and proc.status_counts == {} and proc.estimated == 0 and proc.failures == 0


def test_another_thread_runs_while_a_block_is_computed(calibration_path):
    """The compiled step releases the GIL: a loop's reader thread is not held up for the block's whole call.

    A thread counts beside a long block (hundreds of frames, one compiled call of
    ~50–200 ms). Holding the GIL, the call would stop the thread for all of it; it is held
    for the Python around the call only.
    """
    import threading
    import time

    cal = Calibration.load(calibration_path)
    t, signals, p = _frames(7, cal)
    proc = LiveProcessor(cal, constraint="normal")
    proc.process_block(signals[:2], p[:2], t_s=t[:2])  # the step made, its kernels loaded
    rows = np.resize(np.arange(t.size), 1500)
    stop, ticks = threading.Event(), []

    def count():
        while not stop.is_set():
            ticks.append(time.perf_counter())

    thread = threading.Thread(target=count)
    thread.start()
    try:
        time.sleep(0.02)
        start = time.perf_counter()
        proc.process_block(signals[rows], p[rows], t_s=1.0 + np.arange(rows.size) / RATE_HZ)
        spent = time.perf_counter() - start
    finally:
        stop.set()
        thread.join()
    during = np.array([x for x in ticks if start <= x <= start + spent])
    assert spent > 0.03 and during.size > 100
    gaps = np.diff(np.concatenate(([start], during, [start + spent])))
    assert gaps.max() < 0.5 * spent, (gaps.max(), spent)


@pytest.mark.parametrize(("n", "estimating"), [(1, True), (4, True), (3, False)])
def test_a_block_reads_each_output_where_the_step_wrote_it(calibration_path, n, estimating):
    """The kernel's views of its four buffers (``carve``) and the block's (``_fields``) are the same runs.

    Each output the kernel carves must start at the same byte of the same buffer as the
    block's view of it, with its shape and type.
    """
    from bendsense.pipeline._kernels import carve
    from bendsense.pipeline.live import _Arrays

    proc = LiveProcessor(Calibration.load(calibration_path), constraint="normal", estimate=estimating)
    step = proc._compiled_step()
    buffers, layout = step.outputs(n)
    R, N = step.sizes
    kernel = carve(n, n if estimating else 0, N, step.grid.s.size, R, step.est.problem[2], *buffers)
    arrays = _Arrays(step, buffers, layout, np.zeros(n))
    for group, outputs in zip(("shape", "estimate", "track", "status", "counts"), kernel):
        outputs = outputs if isinstance(outputs, tuple) else (outputs,)
        assert len(outputs) == len(layout[group])
        for index, theirs in enumerate(outputs):
            mine = arrays.field(group, index)
            assert (mine.shape, mine.dtype) == (theirs.shape, theirs.dtype), (group, index)
            if mine.size:
                assert mine.ctypes.data == theirs.ctypes.data, (group, index)
    assert sum(b.size for b in buffers) == sum(stop - start for runs in layout.values() for _, start, stop, _ in runs)
