"""bendsense.control: the PI controller, the loop and its safety stops, against a plant written here.

The plant is a first-order pressure regulator (τ = 25 ms, 0 ≤ p ≤ p_max) and a static
force-vs-pressure map of a finger against a rigid object (no force below the pressure
of first touch, then linear), stepped at 1 kHz in simulated time by a fake driver. The
normal force's sign is checked against the independent forward model
(tests/forward_model.py) through the real processor.
"""

import math
import os
import signal
import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest
from forward_model import forward
from helpers import CONFIG, GAIN, ODD, linear_calibration

from bendsense.control import ControlStop, PIController, Safety, normal_force, run
from bendsense.control.force import contact_normal
from bendsense.device.driver import DeviceStats, Reading
from bendsense.errors import ArgumentError
from bendsense.status import Status, code_of
from bendsense.wire.frames import Sample

TAU_S = 0.025
P_TOUCH_PA = 30e3
SLOPE_N_PER_PA = 6e-6  # ~6 mN per kPa beyond first touch
P_MAX_PA = 120e3
DT_S = 1e-3


@dataclass
class Plant:
    """A regulated pressure line and a finger against a rigid object (the map of the module docstring)."""

    setpoint_pa: float = 0.0
    pressure_pa: float = 0.0

    def advance(self, dt_s):
        target = min(max(self.setpoint_pa, 0.0), P_MAX_PA)
        self.pressure_pa += (target - self.pressure_pa) * (1.0 - math.exp(-dt_s / TAU_S))

    @property
    def force_n(self):
        return SLOPE_N_PER_PA * max(self.pressure_pa - P_TOUCH_PA, 0.0)


@dataclass
class FakeBlock:
    t_s: np.ndarray
    force_n: np.ndarray
    status: np.ndarray
    track = track_status = None

    def __len__(self):
        return self.t_s.size


class FakeProcessor:
    """Turns the fake board's readings into blocks: the force rides in the first ADC count (µN)."""

    def __init__(self, flagged=(), status="model_misfit"):
        self.flagged = set(flagged)  # frame indices reported with ``status`` (its results.csv word)
        self.flag = code_of(status)

    def process_readings(self, readings):
        t = np.array([r.device_us for r in readings]) * 1e-6
        f = np.array([r.sample.adc[0] for r in readings]) * 1e-6
        status = np.array([self.flag if r.sample.seq in self.flagged else Status.OK for r in readings], dtype=np.int8)
        return FakeBlock(t, f, status)


class FakeBoard:
    """The plant at 1 kHz in simulated time; a frame per ``get_batch`` (what a loop that keeps up sees)."""

    def __init__(self, *, lose_after=None, silent_after=None, per_batch=1, per_read=1):
        self.plant = Plant()
        self.k = 0
        self.sent = []  # (frame, line, pressure_pa)
        self.beats = 0
        self.lost = 0
        self.lose_after = lose_after
        self.silent_after = silent_after
        self.per_batch = per_batch
        self.per_read = per_read  # frames of one read of the port (one arrival time)

    def get_batch(self, timeout=None, max_items=4096):
        if self.silent_after is not None and self.k >= self.silent_after:
            time.sleep(min(timeout, 0.01))
            return []
        out = []
        for _ in range(self.per_batch):
            if self.lose_after is not None and self.k >= self.lose_after:
                self.lost += 1  # a frame lost on the wire: its seq is skipped
                self.plant.advance(DT_S)
                self.k += 1
            self.plant.advance(DT_S)
            self.k += 1
            sample = Sample(seq=self.k & 0xFFFF, t_us=self.k * 1000, n_channels=1, status=0, tx_drops=0,
                            pressure_pa=int(self.plant.pressure_pa), adc=(int(round(self.plant.force_n * 1e6)),))
            if len(out) % self.per_read == 0:
                arrived = time.monotonic_ns()
            out.append(Reading(arrived, self.k * 1000, sample))
        return out

    def send_setpoint(self, line, pressure_pa, *, check_line=True):
        self.sent.append((self.k, line, float(pressure_pa)))
        if line == 0:
            self.plant.setpoint_pa = float(pressure_pa)

    def send_heartbeat(self):
        self.beats += 1

    @property
    def stats(self):
        return DeviceStats(frames=self.k, samples=self.k, crc_errors=0, malformed=0, lost=self.lost, queue_drops=0,
                           reconnects=0, overruns=0, bytes=0)


def pi_of(target=0.15, **kw):
    return PIController(target, max_pressure_pa=kw.pop("max_pressure_pa", P_MAX_PA), **kw)


def as_controller(pi):
    """The PI on the fake blocks (their force is the normal force)."""

    def controller(block):
        return {0: pi.step(block.t_s, block.force_n)}

    controller.fingers = (None,)
    return controller


def closed_loop(pi, seconds, plant=None, on_frame=None):
    """The PI and the plant at 1 kHz: returns t, force, set-point, pressure per frame."""
    plant = plant or Plant()
    rows = []
    for k in range(int(round(seconds / DT_S))):
        plant.advance(DT_S)
        t = (k + 1) * DT_S
        if on_frame is not None:
            on_frame(t, pi)
        plant.setpoint_pa = pi.step([t], [plant.force_n])
        rows.append((t, plant.force_n, plant.setpoint_pa, plant.pressure_pa))
    return np.array(rows).T


# --------------------------------------------------------------------------- the PI controller


def test_pi_reaches_a_step_and_holds_it():
    t, f, sp, p = closed_loop(pi_of(), 1.0)
    reached = t[np.flatnonzero(np.abs(f - 0.15) <= 0.01)[0]]
    assert reached < 0.3
    assert np.all(np.abs(f[t > 0.6] - 0.15) < 1e-4)  # integral action: no steady error on a static plant
    # the pressure a static map needs for 0.15 N, in closed form
    assert sp[-1] == pytest.approx(P_TOUCH_PA + 0.15 / SLOPE_N_PER_PA, rel=1e-3)
    assert sp.max() <= P_MAX_PA and sp.min() >= 0.0
    assert np.all(np.abs(np.diff(sp)) <= 500.0 + 1e-6)  # the slew limit: 0.5 kPa per frame at 1 kHz


def test_pi_anti_windup_leaves_the_limit_at_once():
    # 0.5 N needs 113 kPa: with a 60 kPa limit the output sits at the limit for a second
    limit = 60e3
    lowered = {}

    def lower(t, pi):
        if t >= 1.0 and not lowered:
            pi.target_force_n = 0.05  # reachable again: 38.3 kPa
            lowered["t"] = t

    pi = pi_of(0.5, max_pressure_pa=limit)
    t, f, sp, p = closed_loop(pi, 1.5, on_frame=lower)
    assert sp.max() <= limit
    assert np.all(sp[(t > 0.4) & (t < 1.0)] == limit)
    assert pi.integral_pa <= limit
    # a wound-up integral (∫ e dt over a second at e ≈ 0.32 N: ~6e5 Pa) would hold the limit for ~0.3 s
    left = t[np.flatnonzero((t > 1.0) & (sp < limit))[0]]
    assert left - 1.0 < 0.01
    assert abs(f[-1] - 0.05) < 1e-3


def test_pi_holds_its_integral_without_a_force():
    pi = pi_of()
    closed_loop(pi, 0.5)
    held = pi.integral_pa
    out = pi.step([0.501, 0.502], [np.nan, np.nan])
    assert pi.integral_pa == held
    assert out == pytest.approx(held, abs=1e-9)


def test_pi_a_late_block_acts_as_a_short_one():
    # a block of 100 frames (the loop 100 ms behind) integrates and slews over 20 ms, not 100 ms
    pi = pi_of()
    pi.step([0.0], [0.0])
    out = pi.step(np.arange(1, 101) * 1e-3, np.zeros(100))
    assert pi.integral_pa == pytest.approx(pi.ki * 0.15 * 0.02)
    assert out == pytest.approx(pi.max_rate * 0.02)  # K_p e + I = 16.5 kPa, slewed to 10 kPa
    # a prompt block (2 frames) is not scaled
    before = pi.integral_pa
    pi.step([0.101, 0.102], [0.0, 0.0])
    assert pi.integral_pa - before == pytest.approx(pi.ki * 0.15 * 0.002)


@pytest.mark.parametrize(("kw", "match"), [({"kp_pa_per_n": -1.0}, "kp_pa_per_n"),
                                           ({"max_pressure_pa": 0.0}, "max_pressure_pa"),
                                           ({"line": 300}, "line"), ({"max_rate_pa_per_s": math.nan}, "max_rate")])
def test_pi_refuses_bad_settings(kw, match):
    with pytest.raises(ArgumentError, match=match):
        pi_of(**kw)


# --------------------------------------------------------------------------- the normal force


def test_normal_force_is_positive_when_the_finger_presses():
    """An object that holds the finger back pushes along n = (−cos φ_c, sin φ_c): N = F · n > 0.

    The physical fact: a finger pressed by an object closes less than a free one (the
    forward model, independent of bendsense); the processor's tracked N then equals the
    push applied.
    """
    from bendsense.pipeline import LiveProcessor

    p, s_c, push = 40e3, 0.1, 0.15
    free = forward(CONFIG, p, (0.0, 0.0), s_m=[s_c])
    phi = float(np.interp(s_c, free.shape.s_m, free.shape.angle_rad))
    for _ in range(30):  # the push normal to the loaded tangent at s_c (a fixed point)
        loaded = forward(CONFIG, p, push * contact_normal(phi), s_m=[s_c], contact_s_m=s_c)
        phi_new = float(np.interp(s_c, loaded.shape.s_m, loaded.shape.angle_rad))
        if abs(phi_new - phi) < 1e-12:
            break
        phi = phi_new
    assert loaded.angles_rad[-1] < free.angles_rad[-1] - 0.05  # held back: the finger closes less
    cal = linear_calibration()
    signals = cal.offset + np.where(ODD, loaded.shifts_m / GAIN, -loaded.shifts_m / GAIN)
    proc = LiveProcessor(cal, CONFIG, load="contact", contact_s_m=s_c, constraint="normal", bandwidth_hz=20.0)
    n = 40
    block = proc.process_block(np.tile(signals, (n, 1)), np.full(n, p), t_s=np.arange(n) * 1e-3)
    nf = normal_force(block)
    assert nf.force_n[-1] == pytest.approx(push, rel=0.02)
    assert np.all(nf.contact_s_m == s_c)
    assert nf.angle_rad[-1] == pytest.approx(phi, abs=2e-3)
    assert 0 < nf.std_n[-1] < 0.05
    assert normal_force(block, tracked=False).force_n[-1] == pytest.approx(push, rel=0.02)


class _Block:
    """What normal_force reads of a processed block, made up: per-frame contact locations and forces."""

    def __init__(self, rng, n, tracked):
        self.s_m = np.linspace(0.0, 0.1, 11)
        self.angle_rad = np.cumsum(rng.uniform(0.0, 0.2, (n, 11)), axis=1)
        self.contact_s_m = rng.choice([np.nan, 0.0, 0.03, 0.05, 0.0999, 0.1, 0.12], n)  # NaN: a tip load
        self.force_n, self.track_force_n = rng.normal(0, 0.2, (n, 2)), rng.normal(0, 0.2, (n, 2))
        self.force_n[::5] = np.nan  # frames without a force
        a = rng.normal(0, 0.01, (2, n, 2, 2))
        self.covariance_n2, self.track_covariance_n2 = a @ a.transpose(0, 1, 3, 2)
        self.status = np.ones(n, dtype=np.int8)
        self.track_status = self.status if tracked else None
        self.n = n

    def __len__(self):
        return self.n


@pytest.mark.parametrize("tracked", [True, False])
def test_normal_force_interpolates_the_angle_at_the_contact_frame_by_frame(tracked):
    """N = F · n(φ_c), φ_c linear between the shape's points, the last point's angle beyond them and for a tip load.

    Against the formula on whole arrays, written here; for frames at, between and beyond
    the points, at the base, without a location, without a force.
    """
    rng = np.random.default_rng(3)
    block = _Block(rng, 60, tracked)
    nf = normal_force(block, tip_s_m=0.11)
    s = block.s_m
    at = np.where(np.isfinite(block.contact_s_m), np.minimum(block.contact_s_m, s[-1]), s[-1])
    phi = np.array([np.interp(x, s, row) for x, row in zip(at, block.angle_rad)])
    n = np.stack((-np.cos(phi), np.sin(phi)), axis=-1)
    force, cov = ((block.track_force_n, block.track_covariance_n2) if tracked else
                  (block.force_n, block.covariance_n2))
    np.testing.assert_allclose(nf.angle_rad, phi, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(nf.force_n, np.einsum("ni,ni->n", force, n), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(nf.std_n, np.sqrt(np.einsum("ni,nij,nj->n", n, cov, n)), rtol=1e-12, atol=1e-15)
    assert np.isnan(nf.force_n).sum() == (0 if tracked else 12)  # a frame without a force has no N
    np.testing.assert_array_equal(nf.contact_s_m, np.where(np.isfinite(block.contact_s_m), block.contact_s_m, 0.11))
    assert list(nf.status) == ["ok"] * 60


# --------------------------------------------------------------------------- the loop and its stops


def zeros_at_end(board, lines=(0,)):
    last = {}
    for _, line, value in board.sent:
        last[line] = value
    return all(last.get(k) == 0.0 for k in lines)


def test_run_holds_the_force_and_zeroes_at_the_end():
    board = FakeBoard()
    stop = threading.Event()
    seen = []

    def on_block(block, setpoints):
        seen.append((block.t_s[-1], block.force_n[-1], setpoints[0]))
        if block.t_s[-1] >= 0.6:
            stop.set()

    res = run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, stop=stop,
              on_block=on_block, n_lines=2)
    t, f, sp = np.array(seen).T
    assert res.outcome == "stopped" and res.frames == len(seen) == res.blocks
    assert abs(f[-1] - 0.15) < 2e-3
    assert res.max_setpoint_pa == pytest.approx(sp.max()) and sp.max() <= P_MAX_PA
    # the zeros went out at the frame the loop stopped at; the board's pressure then fell (it kept streaming)
    assert zeros_at_end(board, (0, 1)) and board.sent[-2:] == [(res.frames, 0, 0.0), (res.frames, 1, 0.0)]
    assert 0 <= res.zero_latency_s < 1e-3
    assert board.plant.pressure_pa <= 5e3 and res.zeros[0].fell and res.high == ()
    assert res.per_frame_s > 0


def test_run_clips_what_the_controller_asks():
    board = FakeBoard()
    asks = iter([1e9, -5.0, 50e3])
    stop = threading.Event()

    def controller(block):
        value = next(asks)
        if value == 50e3:
            stop.set()
        return {0: value}

    run(board, FakeProcessor(), controller, max_pressure_pa=80e3, stop=stop)
    sent = [v for _, _, v in board.sent]
    assert sent[:3] == [80e3, 0.0, 50e3]
    assert max(sent) <= 80e3 and sent[-1] == 0.0


@pytest.mark.parametrize("answer", [{0: math.nan}, {3: 1e3}, [1e3]])
def test_run_stops_on_an_answer_that_is_no_setpoint(answer):
    board = FakeBoard()
    with pytest.raises(ControlStop) as info:
        run(board, FakeProcessor(), lambda block: answer, max_pressure_pa=P_MAX_PA, seconds=1.0)
    assert zeros_at_end(board) and info.value.result.blocks == 0


def test_run_zeroes_on_an_error_in_the_controller():
    board = FakeBoard()
    pi = pi_of()

    def controller(block):
        if block.t_s[-1] > 0.2:
            raise ZeroDivisionError("a user's bug")
        return {0: pi.step(block.t_s, block.force_n)}

    with pytest.raises(ZeroDivisionError):
        run(board, FakeProcessor(), controller, max_pressure_pa=P_MAX_PA)
    assert board.plant.setpoint_pa == 0.0 and zeros_at_end(board)
    assert any(v > 0 for _, _, v in board.sent)


@pytest.mark.parametrize("signum", [None, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT])
def test_run_zeroes_on_ctrl_c_sigterm_sighup_and_sigquit(signum):
    board = FakeBoard()

    def on_block(block, setpoints):
        if block.t_s[-1] >= 0.1:
            if signum is None:
                raise KeyboardInterrupt
            os.kill(os.getpid(), signum)
            time.sleep(0.5)  # the handler raises here

    others = (signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)
    before = {other: signal.signal(other, signal.SIG_DFL) for other in others}  # as a shell starts a command
    try:  # (nohup would start it with SIGHUP ignored, and an ignored signal stays ignored: stop_signals.handled)
        with pytest.raises(KeyboardInterrupt):
            run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, on_block=on_block)
        assert zeros_at_end(board)
        for other in others:
            assert signal.getsignal(other) is signal.SIG_DFL  # the loop's handlers are gone again
    finally:
        for other, handler in before.items():
            signal.signal(other, handler)


class SwallowingProcessor(FakeProcessor):
    """A processor under which the loop's KeyboardInterrupt is lost, as seen under load (the first Ctrl-C gone)."""

    def __init__(self):
        super().__init__()
        self.swallowed = 0

    def process_readings(self, readings):
        block = super().process_readings(readings)
        if block.t_s[-1] >= 0.1 and not self.swallowed:
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)  # the handler raises here
            except KeyboardInterrupt:
                self.swallowed = block.t_s[-1]
        return block


def test_a_stop_signal_whose_keyboardinterrupt_is_lost_under_the_loop_still_stops_it():
    board = FakeBoard()
    proc = SwallowingProcessor()
    with pytest.raises(KeyboardInterrupt) as info:
        run(board, proc, as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=5.0)
    assert proc.swallowed and zeros_at_end(board)
    result = info.value.result
    assert result.outcome == "interrupted"
    assert result.frames == round(proc.swallowed * 1e3)  # the next turn of the loop: no frame after the signal's


class ConvertingProcessor(FakeProcessor):
    """A processor whose call turns the signal's KeyboardInterrupt into its own error, as numba's unboxing does."""

    def process_readings(self, readings):
        block = super().process_readings(readings)
        if block.t_s[-1] >= 0.1:
            try:
                os.kill(os.getpid(), signal.SIGHUP)
                time.sleep(0.5)  # the handler raises here
            except KeyboardInterrupt:
                raise TypeError("can't unbox a <class 'numba.typed.typedlist.List'> as a <NULL>") from None
        return block


def test_a_stop_signal_that_a_call_under_the_loop_turns_into_another_error_is_an_interrupt():
    # seen on CI: SIGHUP during the live step's call, whose typed list's unboxing reported a TypeError (exit 1)
    board = FakeBoard()
    with pytest.raises(KeyboardInterrupt) as info:
        run(board, ConvertingProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=5.0)
    assert isinstance(info.value.__cause__, TypeError) and zeros_at_end(board)
    assert info.value.result.outcome == "interrupted"


class SignalledBoard(FakeBoard):
    """A fake board whose first zero set-point brings a stop signal: a second Ctrl-C while the loop zeros."""

    def __init__(self, signum):
        super().__init__()
        self.signum, self.signalled = signum, False

    def send_setpoint(self, line, pressure_pa, *, check_line=True):
        if pressure_pa == 0.0 and self.k > 1 and not self.signalled:  # the zeros at the end (not the first block's)
            self.signalled = True
            os.kill(os.getpid(), self.signum)
        super().send_setpoint(line, pressure_pa, check_line=check_line)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("first", ["ctrl-c", "duration"])
def test_a_stop_signal_while_the_loop_zeros_acts_after_every_line_has_its_zero(signum, first):
    board = SignalledBoard(signum)
    stop = threading.Event()

    def on_block(block, setpoints):
        if block.t_s[-1] >= 0.1:
            if first == "ctrl-c":
                raise KeyboardInterrupt
            stop.set()

    with pytest.raises(KeyboardInterrupt) as info:  # after a normal end too: the signal is acted on, late
        run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, stop=stop, on_block=on_block,
            n_lines=3)
    assert board.signalled and zeros_at_end(board, (0, 1, 2))
    zeros = board.sent[-3:]
    assert [(line, v) for _, line, v in zeros] == [(0, 0.0), (1, 0.0), (2, 0.0)]
    result = info.value.result
    assert result.unsent == () and [z.line for z in result.zeros] == [0, 1, 2]
    assert result.outcome == ("interrupted" if first == "ctrl-c" else "stopped")


def test_run_stops_on_lost_frames():
    board = FakeBoard(lose_after=200)
    with pytest.raises(ControlStop, match="frames lost within 1 s") as info:
        run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=5.0,
            safety=Safety(max_lost_frames=10))
    assert zeros_at_end(board)
    assert 200 < board.sent[-1][0] <= 200 + 2 * 12  # every other frame lost: the 11th loss stops it
    assert info.value.result.outcome.startswith("safety stop")


def test_run_stops_when_the_board_falls_silent():
    board = FakeBoard(silent_after=100)
    t0 = time.monotonic()
    with pytest.raises(ControlStop, match="no frame from the board"):
        run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=5.0,
            safety=Safety(silence_s=0.05))
    assert time.monotonic() - t0 < 1.0
    assert zeros_at_end(board)


def test_run_waits_for_the_first_frame_then_stops():
    board = FakeBoard(silent_after=0)
    with pytest.raises(ControlStop, match="no frame from the board within 0.05 s of the start"):
        run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=5.0,
            safety=Safety(silence_s=0.01, first_frame_s=0.05))
    assert board.sent == [(0, 0, 0.0)]  # nothing but the zero


@pytest.mark.parametrize("flag", ["model_misfit", "not_identifiable"])
def test_run_stops_on_a_run_of_flags_not_on_a_chance_one(flag):
    # isolated flagged frames (a frame's χ² beyond chance) do not stop the loop ...
    board = FakeBoard()
    stop = threading.Event()
    run(board, FakeProcessor(flagged={50, 120, 121, 300}, status=flag), as_controller(pi_of()),
        max_pressure_pa=P_MAX_PA, stop=stop, on_block=lambda b, s: b.t_s[-1] >= 0.4 and stop.set(),
        safety=Safety(flagged_s=0.01))
    assert board.k >= 400
    # ... a run of them for 10 ms does, at its 11th frame
    board = FakeBoard(per_batch=3)
    with pytest.raises(ControlStop, match=rf"{flag} for 10 ms .* at t = 0.21\d s"):
        run(board, FakeProcessor(flagged=range(200, 260), status=flag), as_controller(pi_of()),
            max_pressure_pa=P_MAX_PA, seconds=5.0, safety=Safety(flagged_s=0.01))
    assert zeros_at_end(board) and board.sent[-1][0] <= 213


@pytest.mark.parametrize(("per_batch", "per_read"), [(1, 1), (3, 3), (4, 2), (3, 1)])
def test_run_counts_the_reads_each_block_came_in(per_batch, per_read):
    # frames read together arrived together (the board's or the driver's bunching); reads over 1: the loop lagged
    board = FakeBoard(per_batch=per_batch, per_read=per_read)
    res = run(board, FakeProcessor(), as_controller(pi_of()), max_pressure_pa=P_MAX_PA, seconds=0.05)
    assert res.blocks > 0 and res.block_reads.shape == res.block_frames.shape == (res.blocks,)
    assert (res.block_frames == per_batch).all() and (res.block_reads == per_batch // per_read).all()


def test_run_refuses_bad_arguments():
    with pytest.raises(ArgumentError, match="max_pressure_pa"):
        run(FakeBoard(), FakeProcessor(), lambda b: {}, max_pressure_pa=-1.0)
    with pytest.raises(ArgumentError, match="silence_s"):
        Safety(silence_s=0.0)


# --------------------------------------------------------------------------- the command's checks


@pytest.mark.parametrize(("extra", "gripper", "match"), [
    (["--finger", "thumb"], False, "'--finger': names a finger of a gripper config"),
    (["--finger", "pinky"], True, "finger 'pinky': not a finger of this gripper; its fingers: thumb, index"),
    ([], "shared", "Error: the config's fingers: fingers thumb and index both drive pressure line 0: control one of "
                   "them (--finger NAME)"),
    (["--finger", "thumb", "--finger", "index"], "shared",
     "'--finger': fingers thumb and index both drive pressure line 0: control one of them"),
    (["--max-pressure-kpa", "0"], False, "'--max-pressure-kpa': expected a pressure limit > 0 kPa, got 0"),
])
def test_control_refuses_what_it_cannot_do(tmp_path, extra, gripper, match):
    from click.testing import CliRunner

    from bendsense.cli import main
    from bendsense.config import save_config
    from bendsense.sim import gripper_config

    cal = tmp_path / "cal.yaml"
    linear_calibration().save(cal)
    args = ["control", "/dev/null", "--calibration", str(cal), "--target-force-n", "0.15", *extra]
    if gripper:
        config = gripper_config(2).to_dict()
        if gripper == "shared":
            config["fingers"][1]["pressure_line"] = 0
        save_config(type(gripper_config(2)).from_dict(config), tmp_path / "g.yaml")
        args += ["--config", str(tmp_path / "g.yaml")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == (1 if match.startswith("Error: the config") else 2), res.output
    assert match in " ".join(res.output.split()) and "Traceback" not in res.output


def test_a_repeated_finger_controls_each_named_finger_once():
    from bendsense.cli.control import _controllers
    from bendsense.cli.device import live_load
    from bendsense.sim import gripper_config

    config = gripper_config(3)
    tuning = {"controller": "pi", "kp_pa_per_n": 5e4, "ki_pa_per_n_s": 3e6, "max_rate_pa_per_s": 5e5}
    grasp = _controllers(config, ("index", "thumb", "index"), 0.15, 100e3, tuning, live_load("tip", None, config), 30.0)
    assert grasp.fingers == ("thumb", "index") and [c.line for c in grasp.controllers] == [0, 1]


def test_the_silence_limit_follows_a_slow_board():
    from bendsense.control.safety import Guard

    assert Guard(Safety(), (None,), rate_hz=1000.0).silence_s == 0.1
    assert Guard(Safety(), (None,), rate_hz=35.0).silence_s == pytest.approx(10 / 35)  # the paper's 35 Hz board
    assert Guard(Safety(silence_s=0.5), (None,), rate_hz=35.0).silence_s == 0.5


def test_the_model_controller_is_told_the_tracks_bandwidth():
    from bendsense.cli.control import _controllers, _tuning
    from bendsense.cli.device import live_load

    tuning = _tuning("model", None, None, None, None)
    ctl = _controllers(CONFIG, (), 0.15, 100e3, tuning, live_load("tip", None, CONFIG), 12.0)
    assert ctl.track_bandwidth_hz == 12.0  # its lag is the track's (bendsense control --bandwidth-hz 12)
