"""Every frame live: can ``record --estimate`` keep up with a 2 kHz board?

    python benchmarks/bench_record_estimate.py [--seconds 3] [--constraint normal]

Prints two tables:

- the processor alone (:class:`bendsense.pipeline.LiveProcessor`): frames per second
  of reconstruction + warm-started force estimate by block size, on the frames of the
  simulated board at 2 kHz, and how many times real time that is at 2 kHz;
- the whole path at 2 kHz: simulated board (frames computed ahead, so that the board
  keeps its rate) → pseudo-terminal → driver → recorder (frames.bin) → background
  estimator (results.csv): frames recorded, rows written, the largest backlog seen and
  the time to work it off after the recording ended.

One BLAS thread (set before numpy is imported), as the command line uses.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bendsense.calibration import Calibration  # noqa: E402
from bendsense.device.driver import Driver  # noqa: E402
from bendsense.device.estimator import LiveEstimator  # noqa: E402
from bendsense.device.recorder import Recorder  # noqa: E402
from bendsense.device.simdevice import SimulatedDevice  # noqa: E402
from bendsense.pipeline import LiveProcessor  # noqa: E402
from bendsense.sim.scenarios import simulate, time_varying_frames  # noqa: E402

RATE_HZ = 2000.0
SEED = 0


def processor_rates(cal, frames, constraint, sizes=(1, 10, 50, 200, 500)):
    signals = np.array([c for _, c in frames], dtype=float)
    pressure = np.array([p for p, _ in frames], dtype=float)
    t_s = np.arange(len(frames)) / RATE_HZ  # the board's clock: the processor tracks the force over it
    rows = []
    for size in sizes:
        proc = LiveProcessor(cal, constraint=constraint)
        proc.process_block(signals[:size], pressure[:size], t_s=t_s[:size])  # compile and warm up
        proc.reset()
        n = min(len(frames), max(200, 40 * size))
        t = time.perf_counter()
        for i in range(0, n, size):
            proc.process_block(signals[i:i + size], pressure[i:i + size], t_s=t_s[i:i + size])
        dt = time.perf_counter() - t
        rows.append((size, n / dt, proc.failures))
    return rows


def end_to_end(cal, frames, seconds, constraint, root):
    proc = LiveProcessor(cal, constraint=constraint)
    proc.process_block(np.array([frames[0][1]], float), [frames[0][0]], t_s=[0.0])  # compile outside the timing
    proc = LiveProcessor(cal, constraint=constraint)
    backlog = []
    with SimulatedDevice(frames, rate_hz=RATE_HZ) as dev, Driver(dev.port) as drv:
        est = LiveEstimator(proc, results_path=root / "s" / "results.csv")
        rec = Recorder(drv, root / "s", on_records=est.put, extra_files=["results.csv"])
        drv.start()
        stats = rec.run(seconds, on_progress=lambda s: backlog.append(est.stats.backlog),
                        progress_interval_s=0.1)
        t = time.perf_counter()
        est.close()
        drain = time.perf_counter() - t
    rows = sum(1 for _ in open(root / "s" / "results.csv")) - 1
    return stats.records, rows, max(backlog, default=0), drain


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="recording time of the end-to-end case [s]")
    parser.add_argument("--constraint", default="normal")
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"record --estimate at {RATE_HZ:.0f} Hz (constraint {args.constraint}; {os.cpu_count()} CPUs, "
          f"load average {load:.1f})")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        simulate("calibration", root / "cal", seed=SEED)
        cal = Calibration.fit(root / "cal" / "manifest.yaml")
        frames = list(time_varying_frames(None, RATE_HZ, SEED, duration_s=args.seconds + 2.0))
        print()
        print(f"{'block size [frames]':>20} {'frames/s':>10} {'x real time':>12} {'not converged':>14}")
        for size, rate, failures in processor_rates(cal, frames, args.constraint):
            print(f"{size:>20d} {rate:>10.0f} {rate / RATE_HZ:>12.2f} {failures:>14d}")
        recorded, rows, backlog, drain = end_to_end(cal, frames, args.seconds, args.constraint, root)
        print()
        print(f"{'frames recorded':>16} {'rows written':>13} {'max backlog':>12} {'drain [s]':>10}")
        print(f"{recorded:>16d} {rows:>13d} {backlog:>12d} {drain:>10.2f}")
    print()
    print("target: every recorded frame has a row; the backlog stays bounded (keeps up at 2 kHz)")


if __name__ == "__main__":
    main()
