"""Force estimation speed: the fast solver against the paper's method, in one run.

Prints one table (DESIGN.md section 5 targets):

- single-frame latency, warm-started from the previous frame's estimate
  (``initial=``), of ``fast`` and ``paper`` for the free and the constrained
  (``normal``) case, and their ratio (target ≤ 1 ms, ≥ 300×);
- batch throughput of ``fast`` single-process and on a ``ProcessPoolExecutor`` with
  ``--workers`` workers over chunks of a ``--frames`` batch (target ≥ 10,000 frames/s
  on 2 cores);
- the agreement of the two methods on the frames the paper's method solved.

Frames are a smooth time series of PCC shapes (the sensor's view, ``S_i = d φ(L_i)``)
of the model actuator under known loads at 20–120 kPa. Latencies are medians, with
CPU time of this process beside wall time (the fairer number on a shared machine).
BLAS threads are pinned to one per process: the systems are tiny and threaded BLAS
only adds contention.

    python benchmarks/bench_estimation.py [--frames 20000] [--workers 2] [--paper-frames 3]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import dataclasses
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from bendsense import load_config  # noqa: E402
from bendsense.estimation import constraint_basis, estimate_force  # noqa: E402
from bendsense.mechanics.actuator import FreeBendingModel  # noqa: E402
from bendsense.mechanics.beam import solve_beam  # noqa: E402
from bendsense.shape.pcc import shifts_to_curvatures  # noqa: E402
from bendsense.sim.sensor import shifts_from_shape  # noqa: E402


def series(config, frames, constraint, seed=0, rate_hz=100.0):
    """Curvatures (frames, N), pressures and true forces of a smooth loading series."""
    model = FreeBendingModel.from_config(config)
    t = np.arange(frames) / rate_hz
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, 3)
    p = 70e3 + 50e3 * np.sin(2 * np.pi * 0.13 * t + ph[0])
    if constraint == "none":
        force = np.stack([0.2 * np.sin(2 * np.pi * 0.31 * t + ph[1]), 0.15 * np.cos(2 * np.pi * 0.17 * t + ph[2])], -1)
    else:
        d, _ = constraint_basis(constraint, model.tip_angle_rad(p))
        force = d[..., 0] * (0.15 + 0.1 * np.sin(2 * np.pi * 0.23 * t + ph[1]))[:, None]
    L = config.actuator.length_m
    s = np.linspace(0.0, L, 135)
    sol = solve_beam(L, config.stiffness.ei_nm2(p), model.tip_curvature_per_m(p), force,
                     config.weight_per_length_n_per_m, 0.0, s, warn=False)
    sensor = config.sensor
    shifts = shifts_from_shape(s, sol.angle_rad, sensor.lengths_m, sensor.strip_gap_m)
    return shifts_to_curvatures(shifts, sensor.lengths_m, sensor.strip_gap_m), p, force


def latency(kappa, p, config, constraint, method, n):
    """Median wall and CPU time per frame, each warm-started from the previous estimate."""
    prev = estimate_force(kappa[0], p[0], config, constraint=constraint, method=method)
    wall, cpu, forces = [], [], []
    for i in range(1, n + 1):
        w0, c0 = time.perf_counter(), time.process_time()
        prev = estimate_force(kappa[i], p[i], config, constraint=constraint, method=method, initial=prev)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
        forces.append(prev.force_n)
    return float(np.median(wall)), float(np.median(cpu)), np.array(forces)


def _chunk(args):
    kappa, p = args
    est = estimate_force(kappa, p, load_config(), objective="positions")  # as main()
    return est.force_n, est.success


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--latency-frames", type=int, default=300)
    ap.add_argument("--paper-frames", type=int, default=3)
    args = ap.parse_args()
    config = load_config()
    # both methods on the paper's objective (PCC positions, eq. 18): the same answer, compared
    config = config.replace(estimation=dataclasses.replace(config.estimation, objective="positions"))
    rows = []
    agree = []
    ratios = {}
    for constraint in ("none", "normal"):
        kappa, p, _ = series(config, max(args.latency_frames, args.paper_frames) + 1, constraint, seed=1)
        fw, fc, ff = latency(kappa, p, config, constraint, "fast", args.latency_frames)
        pw, pc, pf = latency(kappa, p, config, constraint, "paper", args.paper_frames)
        agree.append(np.abs(pf - ff[: args.paper_frames]).max())
        ratios[constraint] = pc / fc
        rows.append((f"one frame, {constraint}, fast (warm)", f"{fw * 1e3:.3f} ms", f"{fc * 1e3:.3f} ms", "≤ 1 ms"))
        rows.append((f"one frame, {constraint}, paper", f"{pw * 1e3:.1f} ms", f"{pc * 1e3:.1f} ms",
                     "0.42 s / 1.38 s (MATLAB)"))
        rows.append((f"  paper / fast, {constraint}", f"{pw / fw:.0f}×", f"{pc / fc:.0f}×", "≥ 300×"))

    kappa, p, force = series(config, args.frames, "none", seed=2)
    w0, c0 = time.perf_counter(), time.process_time()
    est = estimate_force(kappa, p, config)
    w1, c1 = time.perf_counter() - w0, time.process_time() - c0
    rows.append((f"batch {args.frames}, 1 process", f"{args.frames / w1:,.0f} /s", f"{args.frames / c1:,.0f} /s", ""))
    chunks = np.array_split(np.arange(args.frames), 8 * args.workers)
    with ProcessPoolExecutor(args.workers) as pool:
        list(pool.map(_chunk, [(kappa[:64], p[:64])] * args.workers))  # start the workers, warm caches
        w0 = time.perf_counter()
        out = list(pool.map(_chunk, [(kappa[c], p[c]) for c in chunks]))
        w2 = time.perf_counter() - w0
    pooled = np.concatenate([f for f, _ in out])
    ok = np.concatenate([s for _, s in out])
    rows.append((f"batch {args.frames}, {args.workers} workers", f"{args.frames / w2:,.0f} /s", "", "≥ 10,000 /s"))

    print(f"force estimation benchmark ({os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}; wall and CPU time of this process)")
    print(f"{'what':40s} {'wall':>14s} {'cpu':>14s}   target")
    for what, a, b, target in rows:
        print(f"{what:40s} {a:>14s} {b:>14s}   {target}")
    print(f"paper vs fast, largest difference on {args.paper_frames} frames per case: {max(agree):.2e} N")
    print(f"batch: {est.success.mean() * 100:.2f} % converged (pool {ok.mean() * 100:.2f} %), mean "
          f"{est.iterations.mean():.2f} beam solves per frame; pool vs single process "
          f"{np.nanmax(np.abs(pooled - est.force_n)):.1e} N; PCC bias against the true load: median "
          f"{np.nanmedian(np.abs(est.force_n - force)):.1e} N")


if __name__ == "__main__":
    main()
