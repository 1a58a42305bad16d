"""Shape reconstruction speed: signals → ΔA → S → κ → PCC shape (paper eq. 1–7).

Prints single-frame latency of ``bendsense.reconstruct`` and batched throughput, with
the DESIGN.md section 5 targets (≤ 50 µs per frame, ≥ 1e6 frames/s batched), as wall
time and as CPU time of this process (the fairer number on a shared machine). The
batched run includes the calibration, the range check, curvatures, tip pose and the
shape at ``--batch-points`` points; the kernel runs in blocks of 4096 frames.

    python benchmarks/bench_reconstruct.py [--frames 100000] [--points 50]
"""

import argparse
import time

import numpy as np

from bendsense import load_config
from bendsense.calibration import Calibration
from bendsense.shape.pcc import forward_kinematics, reconstruct, shifts_to_curvatures, tip_pose


def synthetic_calibration(sensor):
    n = sensor.n_segments
    return Calibration(
        offset=np.linspace(2000.0, 2300.0, n),
        coefficients_odd=[0.0, 8e-6, 1e-9, 2e-12],
        coefficients_even=[0.0, -7e-6, 1e-9, -2e-12],
        degree=3,
        delta_a_range_odd=(-100.0, 700.0),
        delta_a_range_even=(-700.0, 100.0),
        noise_std=np.full(n, 0.5),
        sensor=sensor,
    )


def best_of(fn, repeat, number, clock=time.perf_counter):
    best = np.inf
    for _ in range(repeat):
        t0 = clock()
        for _ in range(number):
            fn()
        best = min(best, (clock() - t0) / number)
    return best


def both(fn, repeat, number):
    """(wall, CPU) seconds per call: CPU time is the fairer number on a shared machine."""
    return best_of(fn, repeat, number), best_of(fn, repeat, number, time.process_time)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--points", type=int, default=50)
    parser.add_argument("--batch-points", type=int, default=11, help="shape points per frame in the batch run")
    args = parser.parse_args()

    sensor = load_config().sensor
    cal = synthetic_calibration(sensor)
    rng = np.random.default_rng(0)
    s_single = np.linspace(0.0, sensor.length_m, args.points)
    s_batch = np.linspace(0.0, sensor.length_m, args.batch_points)
    one = cal.offset + np.where(np.arange(16) % 2 == 0, 300.0, -300.0) + rng.normal(0, 1, 16)
    many = one + rng.normal(0, 20, (args.frames, 16))
    reconstruct(one, cal, sensor, s_single)  # warm caches (geometry of s_m, lazy imports)

    rows = []
    wall, cpu = both(lambda: reconstruct(one, cal, sensor, s_single), 5, 2000)
    rows.append(
        (
            f"reconstruct, 1 frame, {args.points} points",
            f"{wall * 1e6:.1f} µs",
            f"{cpu * 1e6:.1f} µs",
            "<= 50 µs",
            cpu <= 50e-6,
        )
    )
    wall, cpu = both(lambda: reconstruct(many, cal, sensor, s_batch), 5, 1)
    rows.append(
        (
            f"reconstruct, {args.frames} frames, {args.batch_points} points",
            f"{args.frames / wall:.3g}/s",
            f"{args.frames / cpu:.3g}/s",
            ">= 1e6/s",
            args.frames / cpu >= 1e6,
        )
    )

    def curvature_and_tip():
        kappa = shifts_to_curvatures(cal.shifts_m(many), sensor.lengths_m, sensor.strip_gap_m)
        return tip_pose(kappa, sensor.lengths_m)

    wall, cpu = both(curvature_and_tip, 5, 1)
    rows.append(
        (
            f"curvatures + tip pose, {args.frames} frames",
            f"{args.frames / wall:.3g}/s",
            f"{args.frames / cpu:.3g}/s",
            "",
            None,
        )
    )
    kappa = shifts_to_curvatures(cal.shifts_m(many), sensor.lengths_m, sensor.strip_gap_m)
    wall, cpu = both(lambda: forward_kinematics(kappa, sensor.lengths_m, s_single), 5, 1)
    rows.append(
        (
            f"forward kinematics, {args.frames} frames, {args.points} points",
            f"{args.frames / wall:.3g}/s",
            f"{args.frames / cpu:.3g}/s",
            "",
            None,
        )
    )

    width = max(len(r[0]) for r in rows)
    print(f"{'what':<{width}}  {'wall':>12}  {'CPU':>12}  {'target':>9}  met (CPU)")
    for what, wall, cpu, target, ok in rows:
        print(f"{what:<{width}}  {wall:>12}  {cpu:>12}  {target:>9}  {'' if ok is None else ('yes' if ok else 'NO')}")


if __name__ == "__main__":
    main()
