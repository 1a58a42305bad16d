"""Force control on the simulated grasp board: a contact-force step to 0.15 N, scored against the simulator's truth.

    python benchmarks/bench_control.py [--fingers 1 3] [--seconds 1.5] [--rate-hz 1000] [--quick]

The board (:class:`bendsense.sim.gripper.GraspBoard`: one first-order regulator per line,
τ = 25 ms, 0..120 kPa; the default objects: rigid, each finger touched at its own s_c = 0.10, 0.11,
0.095 m from 40, 45, 35 kPa on) streams at 1 kHz (``--rate-hz``) over a pseudo-terminal (in this process, as in
the tests) and writes its truth of every frame with the host time it made the frame. The loop
(:func:`bendsense.control.run`: the driver, the processor — one
:class:`~bendsense.pipeline.LiveProcessor` per finger, contact at the finger's known s_c, normal
constraint, 30 Hz track — and a :class:`~bendsense.control.PIController` per finger at its
defaults) starts with the fingers open and the target 0.15 N, and is stopped after
``--seconds`` by SIGINT sent to it at a known time (Ctrl-C). Printed per finger count:

- rise time: from the first set-point to the first frame whose true force is within
  10 mN of 0.15 N; settling: to the last frame outside that band (DESIGN.md section 5:
  within 0.3 s);
- steady error: the mean true force over the last 0.5 s minus 0.15 N (and its RMS
  ripple), and the tracked estimate's error against the truth there (target ≤ 10 mN);
- peak pressure and set-point against the limit (100 kPa; no pressure above it);
- the stop, over this session and further 0.3 s ones (``--stops``): host time from the
  signal to the last zero set-point written, and on the board's side, the time to the
  first frame with set-point 0 and the frames generated after the signal still holding
  a non-zero one (target: within one frame period). A signal reaches Python between
  two bytecodes: a stop that lands inside a block's compiled estimate waits for it;
- the loop's cost: wall time per frame (process, check, control, send; mean and p99 per
  block) and the frames per block (1: the loop keeps up frame by frame), with the reads of the port they came
  in (the loop reads the port itself, one read a block: its frames arrived while the loop was busy with the
  block before, or were sent together).
"""

import argparse
import copy
import math
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bendsense import load_config
from bendsense.calibration import Calibration
from bendsense.control import Grasp, ModelController, PIController, Safety, run
from bendsense.device.driver import Driver
from bendsense.device.simdevice import SimulatedDevice
from bendsense.pipeline import LiveProcessor
from bendsense.sim.grasp import GraspObject
from bendsense.sim.gripper import DEFAULT_CONTACT_S_M, GraspBoard, default_objects, gripper_config
from bendsense.sim.scenarios import simulate

TARGET_N, BAND_N, LIMIT_PA, RATE_HZ = 0.15, 0.010, 100e3, 1000.0
S_C = DEFAULT_CONTACT_S_M  # where the default objects touch each finger [m]


class Truth:
    """The board's truth rows with the host time each frame was made (``time.perf_counter()``)."""

    def __init__(self):
        self.rows = []

    def write(self, seq, t_us, truth):
        self.rows.append((time.perf_counter(), seq, truth))

    def flush(self):
        pass

    def column(self, name):
        return np.array([r[2][name] for r in self.rows])


#: the simulated board in its own process (as a real board is: its frame synthesis does not compete with the loop
#: for the GIL); its truth rows carry the host time each frame was made (time.perf_counter: CLOCK_MONOTONIC,
#: the same clock in both processes on Linux)
CHILD = r"""
import json, sys, time
import bench_control
from bench_control import board_of
from bendsense.device.simdevice import SimulatedDevice

k, path, bench_control.RATE_HZ = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
board = board_of(k, tuple(float(x) for x in sys.argv[4:6]) or None)


class Truth:
    def __init__(self, fh):
        self.fh = fh

    def write(self, seq, t_us, truth):
        self.fh.write(f"{time.perf_counter()!r}\t{seq}\t{json.dumps(truth)}\n")

    def flush(self):
        self.fh.flush()


with open(path, "w") as fh, SimulatedDevice(board, rate_hz=bench_control.RATE_HZ, truth=Truth(fh),
                                         n_channels=board.n_channels) as dev:
    print(dev.port, board.n_lines, " ".join(board.truth_fingers or []), flush=True)
    sys.stdin.read()  # until the parent closes it
"""


class Board:
    """A board of k fingers in a child process (:data:`CHILD`); ``truth(since)`` reads its rows after a host time."""

    def __init__(self, k, root: Path, place=None):
        import subprocess

        self.path = root / f"truth{k}{'' if place is None else '-{:g}-{:g}'.format(*place)}.tsv"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parent),
                                                            os.environ.get("PYTHONPATH", "")]))
        where = [] if place is None else [repr(float(x)) for x in place]
        self.proc = subprocess.Popen([sys.executable, "-c", CHILD, str(k), str(self.path), repr(RATE_HZ), *where],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        port, n_lines, *fingers = self.proc.stdout.readline().split(" ")
        self.port, self.n_lines = port, int(n_lines)
        self._read = 0  # bytes of the truth file read so far
        self.driver = Driver(self.port).open()
        for line in range(self.n_lines):  # the board holds its lines at 0 until the first session, not its profile
            self.driver.send_setpoint(line, 0.0)
        self.truth_fingers = [f.strip() for f in fingers if f.strip()] or None

    def truth(self, since_s):
        import json

        out = Truth()
        with open(self.path, encoding="utf-8") as fh:
            fh.seek(self._read)  # the rows after the previous session's
            for line in fh:
                if not line.endswith("\n"):
                    break
                self._read += len(line.encode("utf-8"))
                parts = line.rstrip("\n").split("\t")
                if len(parts) == 3 and float(parts[0]) >= since_s:
                    out.rows.append((float(parts[0]), int(parts[1]), json.loads(parts[2])))
        return out

    def close(self):
        self.driver.close()
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def processor(cal, k, s_c=S_C[0]):
    """One LiveProcessor for the single actuator (the object at ``s_c``), a gripper processor of k fingers otherwise."""
    options = {"load": "contact", "constraint": "normal", "bandwidth_hz": 30.0}
    if k == 1:
        proc = LiveProcessor(cal, load_config(), contact_s_m=s_c, **options)
    else:
        from bendsense.pipeline.gripper import GripperProcessor

        gripper = gripper_config(k)
        proc = GripperProcessor(cal, gripper, **options,
                                finger_options={f.name: {"contact_s_m": S_C[i]} for i, f in enumerate(gripper.fingers)})
    proc.warm_up()
    return proc


def controller(k, kind="model", target=TARGET_N, s_c=None):
    """The controller(s) of k fingers: ``model`` (ModelController at the fingers' known contacts) or ``pi``."""
    def one(config, contact_s_m, **kw):
        if kind == "pi":
            return PIController(target, max_pressure_pa=LIMIT_PA, **kw)
        return ModelController(target, config, max_pressure_pa=LIMIT_PA, contact_s_m=contact_s_m, **kw)

    if k == 1:
        return one(load_config(), S_C[0] if s_c is None else s_c)
    gripper = gripper_config(k)
    return Grasp([one(f.config, S_C[i], line=f.pressure_line, finger=f.name) for i, f in enumerate(gripper.fingers)])


def session(board, proc, ctl, seconds):
    """A session on the board (a :class:`Board` in its own process, or a GraspBoard here, copied fresh).

    Returns (truth, the loop's result, the signal's time, the board).
    """
    proc.reset()
    ctl.reset()
    sent = {}

    def interrupt():
        sent["t"] = time.perf_counter()
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    def loop(driver):
        # the Ctrl-C this sends must raise: a process started in the background by a shell without job
        # control begins with SIGINT ignored (and Python then installs no KeyboardInterrupt for it)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        driver.start()
        timer = threading.Timer(seconds, interrupt)
        timer.start()
        try:
            # a loaded machine may hold the board's process back for 0.1 s: not what this measures
            run(driver, proc, ctl, max_pressure_pa=LIMIT_PA, n_lines=board.n_lines, safety=Safety(silence_s=1.0))
            raise RuntimeError("the loop ended before the signal")
        except KeyboardInterrupt as err:
            result = err.result
        time.sleep(0.05)  # frames after the stop
        return result

    t0 = time.perf_counter()
    if isinstance(board, Board):  # one port for all its sessions (a simulated board closes when its port does)
        result = loop(board.driver)
        board.driver.stop()
        time.sleep(0.3)  # the regulators let the pressure down before the next session
        end = time.monotonic() + 1.0
        while board.driver.get_batch(timeout=0.05) and time.monotonic() < end:
            pass  # the frames sent after the stop, before the next session
        return board.truth(t0), result, sent["t"], board
    board = copy.deepcopy(board)  # the regulators and the noise from the start; the tables made once
    truth = Truth()
    with SimulatedDevice(board, rate_hz=RATE_HZ, truth=truth, n_channels=board.n_channels) as dev, \
            Driver(dev.port) as driver:
        result = loop(driver)
    return truth, result, sent["t"], board


def board_of(k, place=None):
    """The simulated board of k fingers on the default objects, or one finger on a rigid object at ``place``
    = (s_c [m], touch pressure [Pa])."""
    config = load_config() if k == 1 else gripper_config(k)
    objects = default_objects(k) if place is None else [GraspObject(place[0], place[1], math.inf)]
    return GraspBoard(config, objects, rate_hz=RATE_HZ, seed=0)


def score(truth, result, t_signal, board, k):
    """The step's figures per finger, and the stop's and the loop's."""
    host = np.array([r[0] for r in truth.rows])
    names = [None] if board.truth_fingers is None else board.truth_fingers
    out = []
    for i, name in enumerate(names):
        p = "" if name is None else f"{name}_"
        lp = "" if name is None else f"line{i}_"
        force = np.hypot(truth.column(f"{p}fx_n"), truth.column(f"{p}fy_n"))
        setpoint, pressure = truth.column(f"{lp}setpoint_pa"), truth.column(f"{lp}pressure_pa")
        t = host - host[np.flatnonzero(setpoint > 0)[0]]
        running = (t >= 0) & (host < t_signal)
        inside = np.abs(force - TARGET_N) <= BAND_N
        rise = t[np.flatnonzero(running & inside)[0]] if np.any(running & inside) else math.nan
        outside = np.flatnonzero(running & ~inside)
        settle = t[outside[-1] + 1] if outside.size else 0.0
        steady = running & (host >= t_signal - 0.5)
        after = (host > t_signal) & (setpoint > 0)
        zero = np.flatnonzero((host > t_signal) & (setpoint == 0))
        touched = np.flatnonzero(running & (force > 0))
        from_touch = settle - t[touched[0]] if touched.size else math.nan
        out.append({"finger": name or "(one actuator)", "rise_s": rise, "settle_s": settle,
                    "overshoot_n": float(force[running].max() - TARGET_N), "settle_from_touch_s": from_touch,
                    "steady_error_n": float(np.mean(force[steady]) - TARGET_N),
                    "ripple_n": float(np.std(force[steady])), "peak_pressure_pa": float(pressure.max()),
                    "peak_setpoint_pa": float(setpoint.max()), "frames_after_stop": int(after.sum()),
                    "board_zero_s": float(host[zero[0]] - t_signal) if zero.size else math.nan})
    loop = {"per_frame_s": result.per_frame_s,
            "p99_block_per_frame_s": float(np.percentile(result.loop_s / np.maximum(result.block_frames, 1), 99)),
            "frames_per_block": float(np.mean(result.block_frames)),
            "p90_block_frames": float(np.percentile(result.block_frames, 90)),
            "max_block_frames": float(np.max(result.block_frames)),
            "reads_per_block": float(np.mean(result.block_reads)),
            "frames_per_read": float(np.sum(result.block_frames) / max(np.sum(result.block_reads), 1)),
            "own_per_frame_s": float(np.sum(result.loop_s - result.process_s) / max(result.frames, 1)),
            "host_zero_s": result.stopped_at_s + result.zero_latency_s - t_signal, "frames": result.frames}
    return out, loop




def rows(quick=False, fingers=(1, 3), seconds=1.5, stop_repeats=None, in_process=False, kind="model", also=()):
    """(what, target, measured, pass) rows for run_all.py's table; ``also``: further (fingers, rate [Hz]) runs."""
    global RATE_HZ
    stop_repeats = (2 if quick else 9) if stop_repeats is None else stop_repeats
    runs = [(k, RATE_HZ) for k in fingers] + list(also)
    rate0 = RATE_HZ
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        simulate("calibration", root / "cal", seed=0, frames_per_strip=20 if quick else 50)
        cal = Calibration.fit(root / "cal" / "manifest.yaml")
        table = []
        for k, rate in runs:
            RATE_HZ = rate  # the board's, the session's and the rows' rate
            template = board_of(k) if in_process else Board(k, root)
            try:
                table += _rows_of(k, template, processor(cal, k), controller(k, kind), seconds, stop_repeats)
            finally:
                RATE_HZ = rate0
                if not in_process:
                    template.close()
    return table


def _rows_of(k, template, proc, ctl, seconds, stop_repeats):
    """The rows of k fingers: the step session, then the stops."""
    table = []
    truth, result, t_signal, board = session(template, proc, ctl, seconds)
    per, loop = score(truth, result, t_signal, board, k)
    stops = [score(*session(template, proc, ctl, 0.3), k) for _ in range(stop_repeats)]
    host_zero = np.array([loop["host_zero_s"], *(s[1]["host_zero_s"] for s in stops)])
    board_zero = np.array([max(r["board_zero_s"] for r in p) for p, _ in [(per, loop), *stops]])
    late = np.array([max(r["frames_after_stop"] for r in p) for p, _ in [(per, loop), *stops]])
    worst = max(per, key=lambda r: r["settle_s"])
    label = f"control, {k} finger{'s' if k > 1 else ''} at {RATE_HZ / 1e3:g} kHz"
    period_ms = 1e3 / RATE_HZ
    table.append((f"{label}: step to 0.15 N, settled (rise)", "<= 0.3 s",
                  f"{worst['settle_s']:.3f} s ({max(r['rise_s'] for r in per):.3f} s), worst finger",
                  worst["settle_s"] <= 0.3))
    over = max(r["overshoot_n"] for r in per)
    table.append((f"{label}: overshoot of the true force at the touch (settled after the touch)", "<= 15 mN",
                  f"{over * 1e3:.1f} mN ({max(r['settle_from_touch_s'] for r in per):.3f} s), worst finger",
                  over <= 0.015))
    err = max(abs(r["steady_error_n"]) for r in per)
    table.append((f"{label}: steady error vs the simulator's truth", "<= 10 mN",
                  f"{err * 1e3:.2f} mN (ripple {max(r['ripple_n'] for r in per) * 1e3:.2f} mN RMS)", err <= 0.01))
    peak = max(r["peak_pressure_pa"] for r in per)
    table.append((f"{label}: peak pressure / set-point (limit 100 kPa)", "<= limit",
                  f"{peak / 1e3:.1f} / {max(r['peak_setpoint_pa'] for r in per) / 1e3:.1f} kPa",
                  peak <= LIMIT_PA and max(r["peak_setpoint_pa"] for r in per) <= LIMIT_PA))
    table.append((f"{label}: set-point 0 after Ctrl-C, {host_zero.size} stops (host write; board)",
                  f"<= 1 frame ({period_ms:g} ms)",
                  f"host median {np.median(host_zero) * 1e3:.2f} ms, max {host_zero.max() * 1e3:.2f} ms; board's "
                  f"first zero frame median {np.median(board_zero) * 1e3:.2f} ms; frames still set after the "
                  f"signal: median {np.median(late):.0f}, max {late.max()}", np.median(host_zero) <= 1.0 / RATE_HZ))
    table.append((f"{label}: loop per frame (process, check, control, send)", f"keeps up (< {period_ms:g} ms)",
                  f"{loop['per_frame_s'] * 1e6:.0f} µs mean, p99 {loop['p99_block_per_frame_s'] * 1e6:.0f} µs; "
                  f"{loop['frames_per_block']:.2f} frames per block (arrived in {loop['reads_per_block']:.2f} reads "
                  f"of {loop['frames_per_read']:.2f} frames); the processor's part: all but "
                  f"{loop['own_per_frame_s'] * 1e6:.0f} µs", loop["per_frame_s"] < 1.0 / RATE_HZ))
    table.append((f"{label}: frames per block (the loop acts on every frame)", "<= 1.5",
                  f"{loop['frames_per_block']:.2f} (p90 {loop['p90_block_frames']:.0f}, largest "
                  f"{loop['max_block_frames']:.0f})", loop["frames_per_block"] <= 1.5))
    return table


TARGETS_N = (0.05, 0.15, 0.3)
#: object places: (s_c [m], touch pressure [Pa]), near the base (stiff) to near the tip
PLACES = ((0.07, 50e3), (0.10, 40e3), (0.12, 30e3))


def step_responses(cal, kinds=("model", "pi"), seconds=0.9):
    """One finger at 1 kHz, its board in its own process: a step to each target at each object place, per
    controller kind, each session cut at the Ctrl-C that ends it (its zeros are no part of the step).

    Returns {(kind, place, target): (t from the first set-point [s], true force [N], overshoot [N], settled
    after the touch [s])}."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for place in PLACES:
            board = Board(1, Path(tmp), place)
            try:
                proc = processor(cal, 1, place[0])
                for kind in kinds:
                    for target in TARGETS_N:
                        truth, _, t_signal, _ = session(board, proc, controller(1, kind, target, place[0]), seconds)
                        host, setpoint = np.array([r[0] for r in truth.rows]), truth.column("setpoint_pa")
                        force = np.hypot(truth.column("fx_n"), truth.column("fy_n"))
                        keep = (host >= host[np.flatnonzero(setpoint > 0)[0]]) & (host < t_signal)
                        t, force = host[keep] - host[keep][0], force[keep]
                        touch = t[np.flatnonzero(force > 0)[0]]
                        outside = np.flatnonzero(np.abs(force - target) > BAND_N)
                        settle = t[outside[-1] + 1] - touch if outside.size and outside[-1] + 1 < t.size else math.nan
                        out[kind, place, target] = (t, force, float(force.max() - target), settle)
            finally:
                board.close()
    return out


def step_rows(steps):
    """The table's rows of :func:`step_responses`: the worst overshoot and settling per controller kind."""
    table = []
    for kind in sorted({k[0] for k in steps}):
        mine = {k: v for k, v in steps.items() if k[0] == kind}
        over, settle = max(v[2] for v in mine.values()), max(v[3] for v in mine.values())
        table.append((f"control ({kind}), 1 finger: steps to {', '.join(f'{x:g}' for x in TARGETS_N)} N at "
                      f"{len(PLACES)} object places: worst overshoot; settled within 10 mN after the touch",
                      "<= 15 mN; <= 0.3 s", f"{over * 1e3:.1f} mN; {settle:.3f} s", over <= 0.015 and settle <= 0.3))
    return table


def step_figure(steps, path):
    """The step responses as a figure: one panel per object place, the true force against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(PLACES), figsize=(12, 3.6), sharey=True, constrained_layout=True)
    colours = dict(zip(TARGETS_N, ("tab:blue", "tab:orange", "tab:green"), strict=True))
    for ax, place in zip(axes, PLACES, strict=True):
        for (kind, where, target), (t, force, *_) in steps.items():
            if where == place:
                ax.plot(t, force * 1e3, color=colours[target], ls="-" if kind == "model" else "--", lw=1.2,
                        label=f"{kind}, {target * 1e3:g} mN")
        for target in TARGETS_N:
            ax.axhspan((target - BAND_N) * 1e3, (target + BAND_N) * 1e3, color=colours[target], alpha=0.12, lw=0)
        ax.set_title(f"object at s_c = {place[0] * 1e3:g} mm, touched at {place[1] / 1e3:g} kPa", fontsize=9)
        ax.set_xlabel("time from the first set-point [s]")
    axes[0].set_ylabel("true contact force [mN]")
    axes[0].legend(fontsize=7, ncol=2)
    fig.suptitle("Steps on the simulated board at 1 kHz: ModelController (solid) and PIController (dashed); "
                 "bands ±10 mN", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    global RATE_HZ
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fingers", type=int, nargs="+", default=[1, 3], help="finger counts to run (1..4)")
    ap.add_argument("--rate-hz", type=float, default=RATE_HZ, help="the board's frame rate [Hz] (default 1000)")
    ap.add_argument("--seconds", type=float, default=1.5, help="run time of each session before Ctrl-C [s]")
    ap.add_argument("--stops", type=int, default=None, help="further short sessions stopped by Ctrl-C (default 9; "
                    "2 with --quick)")
    ap.add_argument("--quick", action="store_true", help="a smaller calibration, fewer stops")
    ap.add_argument("--in-process", action="store_true",
                    help="the simulated board in this process (as in the tests) instead of its own")
    ap.add_argument("--controller", choices=("model", "pi"), default="model", help="the controller of the sessions")
    ap.add_argument("--steps", action="store_true",
                    help="also steps to 0.05, 0.15, 0.3 N at three object places, model and PI controllers")
    ap.add_argument("--figure", type=Path, help="with --steps: write the step responses here (PNG)")
    args = ap.parse_args()
    RATE_HZ = args.rate_hz
    table = rows(args.quick, args.fingers, args.seconds, args.stops, args.in_process, args.controller)
    if args.steps:
        with tempfile.TemporaryDirectory() as tmp:
            simulate("calibration", Path(tmp) / "cal", seed=0, frames_per_strip=20 if args.quick else 50)
            steps = step_responses(Calibration.fit(Path(tmp) / "cal" / "manifest.yaml"))
        table += step_rows(steps)
        if args.figure:
            step_figure(steps, args.figure)
    width = max(len(r[0]) for r in table)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; Python {sys.version.split()[0]}")
    print(f"{'what':<{width}}  {'target':<18}  {'measured':<70}  pass?")
    for what, target, value, ok in table:
        print(f"{what:<{width}}  {target:<18}  {value:<70}  {'yes' if ok else 'NO'}")


if __name__ == "__main__":
    main()
