"""Force estimation on cold, independent frames: the compiled core against the paper's method, in one run.

The workload (issue 11, DESIGN.md section 5): independent frames with random pressures
15–120 kPa and tip loads up to 0.25 N in any direction, shuffled, as the sensor sees them
(``S_i = d φ(L_i)`` of the beam model's shape, shift noise of ~1.5 counts, a cubic
calibration with noise and residuals for the propagated σ). Prints one table:

- one frame, cold (no ``initial``), force + σ: median and 99th percentile latency;
- one frame, warm (``initial=`` the previous estimate along a smooth series): median;
- a batch of cold frames and a smooth series (all numba threads, one process);
- ``process`` end to end (session CSVs of independent frames → results) on 2 workers;
- the paper's method (shooting + Nelder–Mead) on a few of the same cold frames: its
  latency, the speed-up and the largest force difference.

Latencies are wall time per call of ``estimate_force`` (inputs prepared beforehand);
the first call (compilation or cache load) is excluded and reported apart.

    python benchmarks/bench_cold.py [--frames 2000] [--batch 20000] [--paper-frames 3] [--quick]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bendsense import load_config  # noqa: E402
from bendsense.calibration import Calibration  # noqa: E402
from bendsense.estimation import estimate_force  # noqa: E402
from bendsense.mechanics.actuator import FreeBendingModel  # noqa: E402
from bendsense.mechanics.beam import solve_beam  # noqa: E402
from bendsense.shape.pcc import shifts_to_curvatures  # noqa: E402
from bendsense.sim.sensor import shifts_from_shape  # noqa: E402

CFG = load_config()
MODEL = FreeBendingModel.from_config(CFG)
L = CFG.actuator.length_m
SENSOR = CFG.sensor


def calibration():
    """A cubic calibration with 1.5 counts of noise and fit residuals (so σ is propagated, with its error model)."""
    from bendsense.calibration import strip_shifts

    c_odd, c_even = np.array([0.0, 2.0e-6, 0.0, 4.0e-13]), np.array([0.0, -1.8e-6, 0.0, -3.0e-13])
    radii = np.linspace(0.04, 0.4, 12)
    shifts = strip_shifts(np.concatenate(([0.0], 1.0 / radii)), SENSOR.lengths_m, SENSOR.strip_gap_m)
    rng = np.random.default_rng(1)
    delta = shifts / np.where(np.arange(16) % 2 == 0, 2.0e-6, -1.8e-6) + rng.normal(0.0, 2.0, shifts.shape)
    return Calibration(offset=np.full(16, 2000.0), coefficients_odd=c_odd, coefficients_even=c_even, degree=3,
                       delta_a_range_odd=(-2e3, 2e3), delta_a_range_even=(-2e3, 2e3), noise_std=np.full(16, 1.5),
                       fit_delta_a=delta, fit_shifts_m=shifts)


def cold_frames(n, seed=0, noise_m=3e-6):
    """Curvatures (n, N), pressures (n,) and true forces (n, 2) of independent, shuffled frames."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(15e3, 120e3, n)
    a = rng.uniform(0.0, 2.0 * np.pi, n)
    r = 0.25 * np.sqrt(rng.uniform(0.0, 1.0, n))
    force = np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
    s = np.linspace(0.0, L, 135)
    sol = solve_beam(L, CFG.stiffness.ei_nm2(p), MODEL.tip_curvature_per_m(p), force, CFG.weight_per_length_n_per_m,
                     0.0, s, warn=False)
    shifts = shifts_from_shape(s, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    shifts = shifts + noise_m * rng.standard_normal(shifts.shape)
    keep = sol.success
    return shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m)[keep], p[keep], force[keep]


def smooth_series(n, rate_hz=1000.0, noise_m=1e-6):
    t = np.arange(n) / rate_hz
    p = 70e3 + 50e3 * np.sin(2 * np.pi * 0.13 * t)
    force = np.stack([0.2 * np.sin(2 * np.pi * 0.31 * t), 0.15 * np.cos(2 * np.pi * 0.17 * t)], -1)
    s = np.linspace(0.0, L, 135)
    sol = solve_beam(L, CFG.stiffness.ei_nm2(p), MODEL.tip_curvature_per_m(p), force, CFG.weight_per_length_n_per_m,
                     0.0, s, warn=False)
    shifts = shifts_from_shape(s, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    shifts = shifts + noise_m * np.random.default_rng(2).standard_normal(shifts.shape)
    return shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m), p


def per_frame(kappa, p, cal, warm=False):
    times = np.empty(len(p))
    prev = None
    for i in range(len(p)):
        kw = {"initial": prev} if warm and prev is not None and bool(prev.success) else {}
        t0 = time.perf_counter()
        prev = estimate_force(kappa[i], p[i], CFG, calibration=cal, **kw)
        times[i] = time.perf_counter() - t0
    return times


def process_end_to_end(kappa, p, cal, sessions, workers):
    """Session CSVs of independent frames (signals through the calibration) → ``process`` → results."""
    from bendsense.batch import process_sessions

    shifts = SENSOR.strip_gap_m * np.cumsum(kappa * SENSOR.lengths_m, axis=-1)
    signals = cal.offset + cal.delta_from_shifts(shifts) if hasattr(cal, "delta_from_shifts") else None
    if signals is None:  # invert the monotone cubic per channel by Newton
        coef = np.where((np.arange(16) % 2 == 0)[:, None], cal.coefficients_odd, cal.coefficients_even)
        x = shifts / coef[:, 1]
        for _ in range(30):
            f = sum(coef[:, j] * x**j for j in range(4)) - shifts
            df = sum(j * coef[:, j] * x ** (j - 1) for j in range(1, 4))
            x = x - f / df
        signals = cal.offset + x
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cal_path = tmp / "cal.yaml"
        cal.save(cal_path)
        chunks = np.array_split(np.arange(len(p)), sessions)
        paths = []
        for j, idx in enumerate(chunks):
            path = tmp / f"s{j:03d}.csv"
            cols = ",".join(f"ch{i + 1}" for i in range(16))
            rows = np.column_stack([idx * 1e-3, p[idx], signals[idx]])
            np.savetxt(path, rows, delimiter=",", header=f"t_s,pressure_pa,{cols}", comments="", fmt="%.17g")
            paths.append(path)
        t0 = time.perf_counter()
        summary = process_sessions(paths, tmp / "out", calibration=cal_path, workers=workers, progress=False)
        wall = time.perf_counter() - t0
    return len(p) / wall, summary


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=2000, help="cold frames timed one by one")
    ap.add_argument("--batch", type=int, default=20000, help="frames of the batch runs")
    ap.add_argument("--sessions", type=int, default=20, help="sessions of the process run")
    ap.add_argument("--process-repeat", type=int, default=1,
                    help="the process run takes the batch's frames this many times (as many times the sessions): "
                         "its fixed cost (starting the workers) spread over more frames")
    ap.add_argument("--paper-frames", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="small sizes (seconds), for the docs test")
    args = ap.parse_args()
    if args.quick:
        args.frames, args.batch, args.sessions, args.paper_frames = 200, 2000, 2, 1
    import numba

    cal = calibration()
    kappa, p, truth = cold_frames(max(args.batch, args.frames), seed=0)
    t0 = time.perf_counter()
    estimate_force(kappa[:2], p[:2], CFG, calibration=cal)
    estimate_force(kappa[0], p[0], CFG, calibration=cal)
    first = time.perf_counter() - t0
    rows = []
    cold = per_frame(kappa[: args.frames], p[: args.frames], cal) * 1e6
    rows.append(("one frame, cold (force + σ)",
                 f"median {np.median(cold):.0f} µs, p99 {np.percentile(cold, 99):.0f} µs", "≤ 50 µs, ≤ 500 µs"))
    ks, ps = smooth_series(args.frames)
    warm = per_frame(ks, ps, cal, warm=True) * 1e6
    rows.append(("one frame, warm (initial=previous)", f"median {np.median(warm):.0f} µs, "
                 f"p99 {np.percentile(warm, 99):.0f} µs", "≤ 20 µs"))
    kb, pb = kappa[: args.batch], p[: args.batch]
    t0 = time.perf_counter()
    est = estimate_force(kb, pb, CFG, calibration=cal)
    rate = len(pb) / (time.perf_counter() - t0)
    err = np.abs(est.force_n - truth[: args.batch])[est.success]
    rows.append((f"batch of {len(pb)} cold frames ({numba.get_num_threads()} threads)", f"{rate:,.0f} frames/s",
                 "≥ 50,000 /s"))
    ks, ps = smooth_series(args.batch)
    t0 = time.perf_counter()
    estimate_force(ks, ps, CFG, calibration=cal)
    rate_s = len(ps) / (time.perf_counter() - t0)
    rows.append((f"smooth series of {len(ps)} frames", f"{rate_s:,.0f} frames/s", "≥ 200,000 /s"))
    reps = max(1, args.process_repeat)
    rate_p, summary = process_end_to_end(np.tile(kb, (reps, 1)), np.tile(pb, reps), cal, args.sessions * reps,
                                         workers=2)
    rows.append((f"process, {args.sessions * reps} sessions of {len(pb) * reps // (args.sessions * reps):,} "
                 "independent frames", f"{rate_p:,.0f} frames/s ({summary.workers})", "≥ 20,000 /s"))
    npap = args.paper_frames
    t_paper, diff = [], []
    for i in range(npap):
        t0 = time.perf_counter()
        ep = estimate_force(kappa[i], p[i], CFG, method="paper", calibration=cal)
        t_paper.append(time.perf_counter() - t0)
        ef = estimate_force(kappa[i], p[i], CFG, calibration=cal, objective="positions")  # the paper's objective
        diff.append(float(np.max(np.abs(ep.force_n - ef.force_n))))
    paper_us = np.median(t_paper) * 1e6
    rows.append((f"paper's method, one cold frame ({npap} frames)", f"median {paper_us / 1e6:.2f} s", "baseline"))
    rows.append(("speed-up, one cold frame (median)", f"{paper_us / np.median(cold):,.0f}×", "≥ 5,000×"))
    rows.append(("largest |F_fast − F_paper|", f"{max(diff):.1e} N", "≤ 1e-4 N"))
    rows.append(("first call (compile or cache load)", f"{first:.2f} s", ""))
    ok = np.count_nonzero(est.success)
    rows.append(("cold batch: success, force error vs truth (RMS; synthetic error model)", f"{ok}/{len(pb)}, "
                 f"{np.sqrt(np.mean(err**2)) * 1e3:.2f} mN", ""))
    width = max(len(r[0]) for r in rows)
    print(f"{'what':{width}s}  {'measured':42s}  target")
    for what, got, target in rows:
        print(f"{what:{width}s}  {got:42s}  {target}")


if __name__ == "__main__":
    main()
