"""Live view: end-to-end latency per frame and achieved frame rate, headless (Agg).

    python benchmarks/bench_live.py [--seconds 5]

Prints one table:

- the model alone (:class:`LiveProcessor`, reconstruct + warm-started force estimate)
  and the view alone (:class:`LiveView`, artists updated and blitted), per frame, on
  the frames of the simulated board;
- the whole path, device → pseudo-terminal → driver → reconstruct → estimate →
  artists blitted, with the simulated board in another process (as a real board would
  be: its frame synthesis does not compete for this process's GIL) and in this process
  (as in the tests), at 100 and 500 Hz. Latency is from the moment the driver read the
  frame's bytes until its artists were drawn; the view always shows the newest frame.

Target (issue 6): >= 20 displayed frames per second with a shape and a force on each.

The gripper rows (issue 24): three fingers of the simulated gripper
(:func:`bendsense.sim.gripper_config`, closing on a rigid object at s_c = 0.1 m) on one
board at 1 kHz, estimated with a known contact location (``--load contact
--contact-s-m 0.1``, constraint ``normal``) and tracked:

- the model alone (:class:`bendsense.pipeline.gripper.GripperProcessor`, a processor per
  finger): wall time per board frame (three fingers) in blocks of 10 board frames (what
  arrives in 10 ms), and how many times real time that is at 1 kHz;
- ``live`` with a panel per finger (headless), the board in another process: frames
  received and estimated, displayed frames per second, latency and the cost per drawn
  frame;
- the whole path of ``record --estimate``: the board in another process (``sim-device
  --fingers 3 --rate 1000``) → pseudo-terminal → driver → recorder (frames.bin) →
  background estimator (``SESSION/<finger>/results.csv``): frames recorded, rows per
  finger, the backlog (frames received, not yet estimated) sampled every 0.1 s (median and
  largest), the time to work it off after the recording ended. Zero backlog: the
  estimator keeps up, the backlog stays at what arrives between two blocks.

    python benchmarks/bench_live.py --gripper-only [--seconds 5]

The block rows (issue 24, the control loop's cost): a warm processor as
``bendsense control`` runs it (contact at s_c = 0.1 m, constraint ``normal``, tracked at
30 Hz, windowed model check) given the board's readings in blocks of 1, 2, 5 and 10
frames (``process_readings``: what the loop calls per block), one finger
(:class:`LiveProcessor`) and three (:class:`~bendsense.pipeline.gripper.GripperProcessor`),
the fingers closing on the object: the median wall time per block and per frame of the
fastest of five passes, and over all passes. The readings are made ahead; the cold process
(compilation, cache load) is excluded.

    python benchmarks/bench_live.py --blocks-only

``--quick``: few frames and one-second runs (for the docs test; its numbers are not the rows').
"""

import argparse
import itertools
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from bendsense.apps.live_view import LiveView, run_live  # noqa: E402
from bendsense.calibration import Calibration  # noqa: E402
from bendsense.device.driver import Driver  # noqa: E402
from bendsense.device.simdevice import SimulatedDevice, default_source  # noqa: E402
from bendsense.pipeline import LiveProcessor  # noqa: E402
from bendsense.sim.scenarios import simulate, time_varying_frames  # noqa: E402

SEED = 0
GRIPPER_RATE_HZ = 1000.0
CONTACT_S_M = 0.1


def calibration(root: Path) -> Calibration:
    simulate("calibration", root / "cal", seed=SEED)
    return Calibration.fit(root / "cal" / "manifest.yaml")


def model_and_view(cal, constraint, n=300):
    frames = list(itertools.islice(time_varying_frames(None, 100.0, SEED), n))
    proc = LiveProcessor(cal, constraint=constraint)
    done = [proc.process_signals(c, p, t_s=k / 100.0) for k, (p, c) in enumerate(frames)]
    process = np.array([f.process_s for f in done[10:]]) * 1e3
    view = LiveView(proc, headless=True)
    view.update(done[0])
    draw = []
    for f in done[1:]:
        t = time.perf_counter()
        view.update(f, f"seq {f.seq}  fps --  latency -- ms")
        draw.append(time.perf_counter() - t)
    return process, np.array(draw) * 1e3, proc.failures


def sim_device_process(rate_hz, seconds):
    """The simulated board in its own process; returns (process, port)."""
    code = "from bendsense.cli import main; main()"
    cmd = [sys.executable, "-c", code, "sim-device", "--rate", str(rate_hz), "--seconds", str(seconds + 60)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    return proc, proc.stdout.readline().strip()


def end_to_end(cal, rate_hz, seconds, where, constraint="normal"):
    proc = LiveProcessor(cal, constraint=constraint)
    view = LiveView(proc, headless=True)
    if where == "other process":
        child, port = sim_device_process(rate_hz, seconds)
        try:
            with Driver(port, hello_timeout_s=30.0) as drv:
                drv.start()
                return run_live(drv, proc, view, duration_s=seconds)
        finally:
            child.terminate()
            child.wait()
    with SimulatedDevice(default_source(rate_hz=rate_hz, seed=SEED), rate_hz=rate_hz) as dev, Driver(dev.port) as drv:
        drv.start()
        return run_live(drv, proc, view, duration_s=seconds)


def gripper_processor(cal, gripper):
    from bendsense.pipeline.gripper import GripperProcessor

    proc = GripperProcessor(cal, gripper, constraint="normal", load="contact", contact_s_m=CONTACT_S_M)
    proc.warm_up()
    return proc


def gripper_model(cal, seconds, block=10):
    """Wall time per board frame of the gripper's processor over the simulated board's frames (computed ahead)."""
    from bendsense.sim.gripper import GraspBoard, Regulation, default_objects, gripper_config

    gripper = gripper_config(3)
    board = GraspBoard(gripper, default_objects(3, contact_s_m=CONTACT_S_M), rate_hz=GRIPPER_RATE_HZ, seed=SEED,
                       regulation=Regulation(period_s=4.0))
    n = int(seconds * GRIPPER_RATE_HZ)
    frames = [board(k) for k in range(n)]
    signals = np.array([c for _, c, _ in frames], dtype=float)
    pressure = np.array([p for p, _, _ in frames], dtype=float)
    t_s = np.arange(n) / GRIPPER_RATE_HZ
    proc = gripper_processor(cal, gripper)
    t = time.perf_counter()
    for i in range(0, n, block):
        proc.process_block(signals[i:i + block], pressure[i:i + block], t_s=t_s[i:i + block])
    per_frame = (time.perf_counter() - t) / n
    return per_frame, proc.failures, proc.status_counts.get("ok", 0) / (3 * n)


def gripper_board_process(seconds):
    """The simulated 3-finger board at 1 kHz in its own process; returns (process, port)."""
    cmd = [sys.executable, "-c", "from bendsense.cli import main; main()", "sim-device", "--fingers", "3",
           "--object-s-m", str(CONTACT_S_M), "--rate", str(GRIPPER_RATE_HZ), "--seconds", str(seconds + 120)]
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    return child, child.stdout.readline().strip()


def gripper_live_view(cal, seconds):
    """``live`` of the simulated 3-finger board at 1 kHz: every frame processed, a panel per finger drawn."""
    from bendsense.apps.live_view import GripperView
    from bendsense.sim.gripper import gripper_config

    proc = gripper_processor(cal, gripper_config(3))
    view = GripperView(proc, headless=True)
    child, port = gripper_board_process(seconds)
    try:
        with Driver(port, hello_timeout_s=60.0) as drv:
            drv.start()
            return run_live(drv, proc, view, duration_s=seconds)
    finally:
        child.terminate()
        child.wait()


def gripper_end_to_end(cal, seconds, root):
    """``record --estimate`` of the simulated 3-finger board at 1 kHz (board in another process)."""
    from bendsense.device.estimator import LiveEstimator
    from bendsense.device.recorder import Recorder
    from bendsense.sim.gripper import gripper_config

    gripper = gripper_config(3)
    proc = gripper_processor(cal, gripper)
    child, port = gripper_board_process(seconds)
    backlog = []
    out = root / "gripper-session"
    paths = {name: out / name / "results.csv" for name in gripper.names}
    try:
        with Driver(port, hello_timeout_s=60.0) as drv:
            est = LiveEstimator(proc, results_path=paths)
            rec = Recorder(drv, out, on_records=est.put, extra_files=[f"{n}/results.csv" for n in gripper.names])
            drv.start()
            stats = rec.run(seconds, on_progress=lambda s: backlog.append(est.stats.backlog),
                            progress_interval_s=0.1)
            t = time.perf_counter()
            est.close()
            drain = time.perf_counter() - t
    finally:
        child.terminate()
        child.wait()
    rows = {name: sum(1 for _ in open(path)) - 1 for name, path in paths.items()}
    return stats, rows, backlog, drain


def gripper_rows(cal, seconds, root):
    per_frame, failures, ok = gripper_model(cal, min(seconds, 4.0))
    print(f"gripper: 3 fingers on one board at {GRIPPER_RATE_HZ:.0f} Hz (load contact at {CONTACT_S_M} m, "
          "constraint normal, tracked)")
    print(f"{'model: GripperProcessor, blocks of 10 board frames':<58} {per_frame * 1e6:9.0f} µs per board frame "
          f"({per_frame * 1e6 / 3:.0f} µs per finger frame; {1 / (per_frame * GRIPPER_RATE_HZ):.1f}x real time; "
          f"{ok:.1%} ok, {failures} not converged)")
    stats, rows, backlog, drain = gripper_end_to_end(cal, seconds, root)
    b = np.array(backlog or [0])
    print(f"{'record --estimate, board in another process':<58} {stats.records} frames recorded in "
          f"{stats.elapsed_s:.1f} s (lost {stats.lost}, queue drops {stats.queue_drops}); rows per finger "
          f"{', '.join(f'{k} {v}' for k, v in rows.items())}; backlog median {np.median(b):.0f}, max {b.max():.0f} "
          f"frames; worked off {drain:.2f} s after the end")
    s = gripper_live_view(cal, seconds)
    print(f"{'live, a panel per finger (headless), board in another process':<58} {s.received} frames received, "
          f"{s.estimated} estimated ({s.estimate_hz:.0f}/s); {s.fps:.1f} fps, latency median {s.latency_ms[0]:.0f} ms "
          f"(p95 {s.latency_ms[1]:.0f} ms), draw {s.draw_ms:.1f} ms, process {s.process_ms * 1e3:.0f} µs per board "
          "frame")
    print("target: every frame of every finger estimated and tracked, zero backlog (bounded, worked off at once)")


def board_readings(k, n):
    """``n`` driver readings of the simulated board of ``k`` fingers closing on the object (1: the single actuator)."""
    from bendsense import load_config
    from bendsense.device.driver import Reading
    from bendsense.sim.gripper import GraspBoard, Regulation, default_objects, gripper_config
    from bendsense.wire.frames import Sample

    config = load_config() if k == 1 else gripper_config(k)
    board = GraspBoard(config, default_objects(k, contact_s_m=CONTACT_S_M), rate_hz=GRIPPER_RATE_HZ, seed=SEED,
                       regulation=Regulation(period_s=4.0))
    readings = []
    for i in range(n):
        p, counts, _ = board(i)
        lines = () if k == 1 else tuple(int(round(x)) for x in p)
        sample = Sample(i % 65536, i * 1000, len(counts), 0, 0, int(round(p if k == 1 else p[0])),
                        tuple(int(c) for c in counts), lines)
        readings.append(Reading(10**9 + i * 10**6, i * 1000, sample))
    return readings


def python_loop_ms():
    """This machine's speed at the moment: a plain Python loop of 2 million additions [ms] (a VM's varies 2x)."""
    t = time.perf_counter()
    total = 0
    for i in range(2_000_000):
        total += i
    return (time.perf_counter() - t) * 1e3


def block_rows(cal, sizes=(1, 2, 5, 10), frames=600, repeats=5):
    """Wall time of ``process_readings`` per block of each size, one finger and three; prints the rows.

    Each row runs the compiled live step (one call per finger per block) and the path
    before it (``reconstruct``, ``estimate_force``, the ``Tracker``: what options the step
    does not run still take) in alternate passes over the frames, so that both see the
    machine in the same state; a pass runs one path alone, as a control loop does (block
    for block, each would evict the other's data from the caches). A row is the median
    block of each path's fastest pass (``timeit``'s convention: a VM's slower passes are
    other work on its host), and the median over all its passes.
    """
    from bendsense import load_config
    from bendsense.pipeline.gripper import GripperProcessor
    from bendsense.pipeline.live import _GENERAL
    from bendsense.sim.gripper import gripper_config

    options = {"load": "contact", "contact_s_m": CONTACT_S_M, "constraint": "normal", "bandwidth_hz": 30.0}
    print("control loop's processor: process_readings per block (contact at 0.1 m, normal, 30 Hz track), warm;")
    print(f"the compiled step, and the estimate_force path before it (Python loop of 2e6 additions: "
          f"{python_loop_ms():.0f} ms)")
    print(f"{'fingers':<8} {'frames/block':>12} {'µs per block':>13} {'µs per frame':>13} {'before µs/block':>16}"
          f" {'all passes: µs/block':>21} {'before':>7}")
    for k in (1, 3):
        procs = []
        for general in (False, True):
            proc = LiveProcessor(cal, load_config(), **options) if k == 1 else GripperProcessor(
                cal, gripper_config(k), **options)
            for finger in ([proc] if k == 1 else proc.processors.values()):
                finger._step = _GENERAL if general else None
            proc.warm_up()
            procs.append(proc)
        readings = board_readings(k, 1000 + frames)[1000:]  # from the touch on: the force the loop controls
        for size in sizes:
            passes = ([], [])  # each path's passes: the wall time of every block [s]
            for _ in range(repeats):
                for proc, done in zip(procs, passes):
                    proc.reset()
                    spent = []
                    for i in range(0, frames - size + 1, size):
                        t = time.perf_counter()
                        proc.process_readings(readings[i:i + size])
                        spent.append(time.perf_counter() - t)
                    done.append(spent)
            now, before = (min(float(np.median(x)) for x in done) * 1e6 for done in passes)
            now_all, before_all = (float(np.median(np.concatenate(done))) * 1e6 for done in passes)
            print(f"{k:<8} {size:>12} {now:13.0f} {now / size:13.0f} {before:16.0f} {now_all:21.0f} {before_all:7.0f}")
    print(f"(Python loop of 2e6 additions, after: {python_loop_ms():.0f} ms)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="run time of each end-to-end case [s]")
    parser.add_argument("--gripper-only", action="store_true", help="only the gripper rows")
    parser.add_argument("--blocks-only", action="store_true", help="only the block rows (the control loop's cost)")
    parser.add_argument("--quick", action="store_true", help="few frames and short runs (seconds; for the docs test)")
    args = parser.parse_args()
    if args.quick:
        args.seconds = min(args.seconds, 1.0)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"bendsense live benchmark (headless Agg, matplotlib {matplotlib.__version__}; "
        f"{os.cpu_count()} CPUs, load average {load:.1f})"
    )
    with tempfile.TemporaryDirectory() as tmp:
        cal = calibration(Path(tmp))
        print()
        block_rows(cal, sizes=(1, 10), frames=60, repeats=1) if args.quick else block_rows(cal)
        if args.blocks_only:
            return
        print()
        gripper_rows(cal, args.seconds, Path(tmp))
    if args.gripper_only:
        return
    print()
    print(f"{'case':<66} {'median':>9} {'p95':>9}")
    for constraint in ("normal", "none"):
        process, draw, failures = model_and_view(cal, constraint)
        note = f" ({failures} not converged)" if failures else ""
        print(
            f"{'model: reconstruct + estimate (' + constraint + ') [ms]' + note:<66} "
            f"{np.median(process):9.2f} {np.percentile(process, 95):9.2f}"
        )
    print(f"{'view: update artists + blit [ms]':<66} {np.median(draw):9.2f} {np.percentile(draw, 95):9.2f}")
    print()
    header = (
        f"{'end to end (constraint normal)':<34} {'rate':>6} {'shown':>6} {'fps':>6} "
        f"{'latency ms':>11} {'p95 ms':>7} {'model ms':>9} {'view ms':>8}"
    )
    print(header)
    for where in ("other process", "this process"):
        for rate in (100.0, 500.0):
            s = end_to_end(cal, rate, args.seconds, where)
            print(
                f"{'device in ' + where:<34} {rate:6.0f} {s.frames:6d} {s.fps:6.1f} "
                f"{s.latency_ms[0]:11.1f} {s.latency_ms[1]:7.1f} {s.process_ms:9.2f} {s.draw_ms:8.2f}"
            )
    print()
    print("target: >= 20 fps with shape and force on every displayed frame (display capped at 60 fps)")


if __name__ == "__main__":
    main()
