"""Batch throughput: many simulated sessions processed end to end (read, reconstruct, estimate, write).

    python benchmarks/bench_batch.py [--sessions 100] [--seconds 10] [--workers 2] [--no-dask]
                                     [--constraint none] [--no-estimation-table] [--serial] [--quick]

The sessions come from the simulator's ``time-varying`` scenario (pressure ramps, a
contact force switching on and off, 100 Hz): ``--distinct`` different runs (contact
force magnitudes 0.05 to 0.25 N) written as session CSVs and copied up to
``--sessions`` files, so that generating them does not dominate the run. The
calibration is fitted from the simulator's ``calibration`` scenario of the same seed.

Two tables:

- **End to end** (``bendsense.batch.process_sessions``): each executor processes the
  same files into a fresh output directory; wall time and frames per second over the
  whole batch (reading, reconstruction, estimation with ``--constraint``, default the
  config's, and writing). The executors' start-up (worker processes and their imports,
  the Dask cluster) is timed separately and not included.
- **Estimation step** (``--no-estimation-table`` skips it): ``estimate_force`` with the
  calibration's propagated uncertainty on the reconstructed frames of the distinct
  sessions, for the constraints ``none`` and ``normal``, in this process and on a
  process pool with ``--workers`` workers (one task per session, the signals sent
  along); frames per second of wall time and the CPU time per frame in the workers.

Like ``run_all.py`` (and the ``bendsense`` command) the script sets
``OPENBLAS_NUM_THREADS=1`` (and OMP/MKL) before numpy is imported, for itself and the
processes it starts: the estimator's matrices are tiny and threaded BLAS only adds
overhead on a shared 2-core machine.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import concurrent.futures as cf  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bendsense.batch import process_sessions  # noqa: E402
from bendsense.calibration import Calibration  # noqa: E402
from bendsense.config import load_config  # noqa: E402
from bendsense.session import Session, read_session_csv, write_session_csv  # noqa: E402
from bendsense.sim.scenarios import simulate, time_varying_frames  # noqa: E402
from bendsense.sim.sensor import VirtualSensor  # noqa: E402


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
    return len(rows), distinct


def _warm():
    """Import what a batch task needs (run once per worker before the clock starts)."""
    import bendsense.batch  # noqa: F401
    import bendsense.estimation  # noqa: F401
    import bendsense.results  # noqa: F401
    import bendsense.shape.pcc  # noqa: F401

    return os.getpid()


def warm_pool(pool, workers):
    """Start every worker of a process pool and import the pipeline in it; returns the time [s]."""
    t0 = time.perf_counter()
    # one task per worker, each held until all have started, so that every process imports
    pids = set()
    while len(pids) < workers:
        pids.update(pool.map(_sleepy_warm, range(workers)))
    return time.perf_counter() - t0


def _sleepy_warm(_):
    time.sleep(0.2)
    return _warm()


def run(label, root, out, calibration, config, **kwargs):
    report = process_sessions(root, out, calibration=calibration, config=config, progress=False, **kwargs)
    if report.n_failed:
        print(report.table())
        raise SystemExit(f"{label}: {report.n_failed} sessions failed")
    not_converged = sum(s.not_converged for s in report.sessions)
    return label, report, not_converged


def estimate_task(signals, pressure_pa, calibration, config, constraint):
    """Reconstruct and estimate one session's frames; returns (frames, estimate CPU [s], wall [s], failed)."""
    from bendsense.estimation import estimate_force
    from bendsense.shape.pcc import reconstruct

    shape = reconstruct(signals, calibration, config.sensor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c0, t0 = time.process_time(), time.perf_counter()
        est = estimate_force(shape, pressure_pa, config, constraint=constraint, calibration=calibration)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    return len(pressure_pa), cpu, wall, int(np.count_nonzero(~est.success))


def estimation_rows(sessions, calibration, config, pool, workers):
    rows = []
    for constraint in ("none", "normal"):
        args = [(s.signals, s.pressure_pa, calibration, config, constraint) for s in sessions]
        t0 = time.perf_counter()
        single = [estimate_task(*a) for a in args]
        wall1 = time.perf_counter() - t0
        t0 = time.perf_counter()
        futures = [pool.submit(estimate_task, *a) for a in args]
        multi = [f.result() for f in futures]
        wall2 = time.perf_counter() - t0
        frames = sum(r[0] for r in single)
        for label, res, wall in (("this process", single, wall1), (f"process pool, {workers} workers", multi, wall2)):
            cpu = sum(r[1] for r in res)
            rows.append((constraint, label, frames, wall, frames / wall, cpu / frames * 1e6, sum(r[3] for r in res)))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=100)
    parser.add_argument("--distinct", type=int, default=10, help="different simulated runs among the sessions")
    parser.add_argument("--seconds", type=float, default=10.0, help="session length at 100 Hz [s]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--constraint", default=None, help="end-to-end constraint (default: the config's)")
    parser.add_argument("--no-dask", action="store_true")
    parser.add_argument("--no-estimation-table", action="store_true")
    parser.add_argument("--serial", action="store_true", help="also run in-process, one session after another")
    parser.add_argument("--quick", action="store_true", help="a few seconds: 4 sessions of 2 s, 2 distinct")
    args = parser.parse_args()
    if args.quick:
        args.sessions, args.distinct, args.seconds = 4, 2, 2.0

    config = load_config()
    constraint = args.constraint or config.estimation.constraint
    rows = []
    estimation = []
    with tempfile.TemporaryDirectory(prefix="bench_batch.") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        simulate("calibration", tmp / "cal", seed=args.seed)
        calibration = Calibration.fit(tmp / "cal" / "manifest.yaml", sensor=config.sensor)
        (tmp / "runs").mkdir()
        n_distinct = min(args.distinct, args.sessions)
        frames, distinct = make_sessions(tmp / "runs", config, args.sessions, n_distinct, args.seconds, 100.0,
                                         args.seed)
        print(f"generated {args.sessions} sessions x {frames} frames ({n_distinct} distinct) "
              f"and the calibration in {time.perf_counter() - t0:.1f} s; end-to-end constraint: {constraint}")

        if args.serial:
            rows.append(run("in-process (1 core)", tmp / "runs", tmp / "out0", calibration, config, workers=0,
                            constraint=constraint))
        with cf.ProcessPoolExecutor(args.workers) as pool:
            start_s = warm_pool(pool, args.workers)
            print(f"process pool start-up and imports: {start_s:.1f} s (not included below)")
            rows.append(run(f"ProcessPoolExecutor, {args.workers} workers", tmp / "runs", tmp / "out1",
                            calibration, config, executor=pool, constraint=constraint))
            if not args.no_estimation_table:
                sessions = [read_session_csv(p) for p in distinct]
                estimation = estimation_rows(sessions, calibration, config, pool, args.workers)
        if not args.no_dask:
            try:
                from dask.distributed import Client, LocalCluster
            except ImportError:
                print("dask.distributed not installed: skipping the Dask run (pip install bendsense[distributed])")
            else:
                t0 = time.perf_counter()
                with LocalCluster(n_workers=args.workers, processes=True, threads_per_worker=1,
                                  dashboard_address=":0", silence_logs=50) as cluster, Client(cluster) as client:
                    client.run(_warm)  # the workers' imports
                    start_s = time.perf_counter() - t0
                    label = f"Dask LocalCluster, {args.workers} workers"
                    rows.append(run(label, tmp / "runs", tmp / "out2", calibration, config,
                                    executor=client.get_executor(), constraint=constraint))
                print(f"Dask LocalCluster start-up and imports: {start_s:.1f} s (not included below)")

    print()
    cpus = os.cpu_count()
    print(f"machine: {cpus} CPUs, load average {os.getloadavg()[0]:.1f} (1 min) at the end of the run")
    print(f"end to end (read, reconstruct, estimate '{constraint}', write):")
    print(f"{'executor':<36} {'sessions':>8} {'frames':>9} {'wall [s]':>9} {'frames/s':>10} "
          f"{'per session [s]':>16} {'not conv.':>9}")
    for label, report, not_converged in rows:
        per = np.median([s.seconds for s in report.sessions])
        print(f"{label:<36} {len(report.sessions):8d} {report.frames:9d} {report.wall_s:9.2f} "
              f"{report.frames_per_s:10,.0f} {per:16.3f} {not_converged:9d}")
    if estimation:
        print()
        print(f"estimation step (estimate_force with the calibration's uncertainty, {n_distinct} sessions):")
        print(f"{'constraint':<11} {'where':<28} {'frames':>7} {'wall [s]':>9} {'frames/s':>10} "
              f"{'CPU/frame [us]':>15} {'failed':>7}")
        for constraint_, label, n, wall, rate, cpu_us, failed in estimation:
            print(f"{constraint_:<11} {label:<28} {n:7d} {wall:9.2f} {rate:10,.0f} {cpu_us:15.0f} {failed:7d}")


if __name__ == "__main__":
    main()
