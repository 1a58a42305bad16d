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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="run time of each end-to-end case [s]")
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"bendsense live benchmark (headless Agg, matplotlib {matplotlib.__version__}; "
        f"{os.cpu_count()} CPUs, load average {load:.1f})"
    )
    with tempfile.TemporaryDirectory() as tmp:
        cal = calibration(Path(tmp))
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
