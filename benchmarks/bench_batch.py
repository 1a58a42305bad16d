"""Batch throughput: many simulated sessions processed end to end (read, reconstruct, estimate, write).

    python benchmarks/bench_batch.py [--sessions 100] [--seconds 10] [--workers 2] [--no-dask]

The sessions come from the simulator's ``time-varying`` scenario (pressure ramps, a
contact force switching on and off, 100 Hz): ``--distinct`` different runs (contact
force magnitudes 0.05 to 0.25 N) written as session CSVs and copied up to
``--sessions`` files, so that generating them does not dominate the run. The
calibration is fitted from the simulator's ``calibration`` scenario of the same seed.
Each executor processes the same files into a fresh output directory; the table
reports wall time and frames per second (all frames over the wall time of the batch,
including process start-up, file reading and writing). The Dask cluster's start-up
is timed separately and not included.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from bendsense.batch import process_sessions
from bendsense.calibration import Calibration
from bendsense.config import load_config
from bendsense.session import Session, write_session_csv
from bendsense.sim.scenarios import simulate, time_varying_frames
from bendsense.sim.sensor import VirtualSensor


def make_sessions(root: Path, config, n_sessions: int, n_distinct: int, seconds: float, rate_hz: float, seed: int):
    sensor = VirtualSensor.from_config(config, seed=seed)  # the hardware of simulate(..., seed)
    distinct = []
    for k, contact in enumerate(np.linspace(0.05, 0.25, n_distinct)):
        rows = list(time_varying_frames(config, rate_hz, seed, duration_s=seconds, contact_n=float(contact),
                                        sensor=sensor))
        pressure = np.array([p for p, _ in rows])
        counts = np.array([c for _, c in rows], dtype=float)
        path = root / f"run{k:03d}.csv"
        write_session_csv(Session(np.arange(len(rows)) / rate_hz, counts, pressure), path)
        distinct.append(path)
    for k in range(n_distinct, n_sessions):
        shutil.copyfile(distinct[k % n_distinct], root / f"run{k:03d}.csv")
    return len(rows)


def run(label, root, out, calibration, config, **kwargs):
    report = process_sessions(root, out, calibration=calibration, config=config, progress=False, **kwargs)
    if report.n_failed:
        print(report.table())
        raise SystemExit(f"{label}: {report.n_failed} sessions failed")
    not_converged = sum(s.not_converged for s in report.sessions)
    return label, report, not_converged


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=100)
    parser.add_argument("--distinct", type=int, default=10, help="different simulated runs among the sessions")
    parser.add_argument("--seconds", type=float, default=10.0, help="session length at 100 Hz [s]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-dask", action="store_true")
    parser.add_argument("--serial", action="store_true", help="also run in-process, one session after another")
    args = parser.parse_args()

    config = load_config()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_batch.") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        simulate("calibration", tmp / "cal", seed=args.seed)
        calibration = Calibration.fit(tmp / "cal" / "manifest.yaml", sensor=config.sensor)
        (tmp / "runs").mkdir()
        frames = make_sessions(tmp / "runs", config, args.sessions, min(args.distinct, args.sessions),
                               args.seconds, 100.0, args.seed)
        print(f"generated {args.sessions} sessions x {frames} frames ({min(args.distinct, args.sessions)} distinct) "
              f"and the calibration in {time.perf_counter() - t0:.1f} s")

        if args.serial:
            rows.append(run("in-process (1 core)", tmp / "runs", tmp / "out0", calibration, config, workers=0))
        with cf.ProcessPoolExecutor(args.workers) as pool:
            rows.append(run(f"ProcessPoolExecutor, {args.workers} workers", tmp / "runs", tmp / "out1",
                            calibration, config, executor=pool))
        if not args.no_dask:
            try:
                from dask.distributed import Client, LocalCluster
            except ImportError:
                print("dask.distributed not installed: skipping the Dask run (pip install bendsense[distributed])")
            else:
                t0 = time.perf_counter()
                with LocalCluster(n_workers=args.workers, processes=True, threads_per_worker=1,
                                  dashboard_address=None, silence_logs=50) as cluster, Client(cluster) as client:
                    client.run(lambda: __import__("bendsense.estimation"))  # warm the workers' imports
                    start_s = time.perf_counter() - t0
                    label = f"Dask LocalCluster, {args.workers} workers"
                    rows.append(run(label, tmp / "runs", tmp / "out2", calibration, config,
                                    executor=client.get_executor()))
                print(f"Dask LocalCluster start-up: {start_s:.1f} s (not included below)")

    print()
    cpus = os.cpu_count()
    print(f"machine: {cpus} CPUs, load average {os.getloadavg()[0]:.1f} (1 min) at the end of the run")
    print(f"{'executor':<36} {'sessions':>8} {'frames':>9} {'wall [s]':>9} {'frames/s':>10} "
          f"{'per session [s]':>16} {'not conv.':>9}")
    for label, report, not_converged in rows:
        per = np.median([s.seconds for s in report.sessions])
        print(f"{label:<36} {len(report.sessions):8d} {report.frames:9d} {report.wall_s:9.2f} "
              f"{report.frames_per_s:10,.0f} {per:16.3f} {not_converged:9d}")


if __name__ == "__main__":
    main()
