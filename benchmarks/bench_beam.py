"""Benchmark of the curved-beam solver: latency, batch throughput, speed-up and accuracy.

Run ``python benchmarks/bench_beam.py [--batch 10000]``. Problems are drawn from the
paper's workspace (0–120 kPa, natural bend 0–3 rad, tip loads within ±0.3 N, gravity
on the upright rig); accuracy is measured against the exact elastica of a straight
cantilever under a perpendicular tip load (Bisshopp & Drucker 1945).
"""

import argparse
import math
import os
import time
import warnings

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

from bendsense.mechanics.beam import DEFAULT_NODES, BeamConvergenceWarning, FastOptions, solve, solve_beam

L = 0.134
W = 0.03927 * 9.81 / L
GRAVITY = np.array([0.0, -W])


def workspace(n, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0.0, 120e3, n)
    ei = 2.53e-3 + 1.25e-8 * p
    k0 = 3.0 * p / 120e3 / L
    force = rng.uniform(-0.3, 0.3, (n, 2))
    return ei, k0, force


def best_time(fn, repeat=5, number=1):
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t) / number)
    return best


def exact_tip(alpha):
    def parts(theta):
        k = math.sin(math.pi / 4 + theta / 2)
        return k * k, math.asin(1.0 / (math.sqrt(2.0) * k))

    def gap(theta):
        m, psi0 = parts(theta)
        return ellipk(m) - ellipkinc(psi0, m) - math.sqrt(alpha)

    theta = brentq(gap, 1e-12, math.pi / 2 - 1e-12, xtol=1e-15, rtol=1e-15)
    m, psi0 = parts(theta)
    x = 1.0 - 2.0 / math.sqrt(alpha) * (ellipe(m) - ellipeinc(psi0, m))
    return np.array([x, math.sqrt(2.0 * math.sin(theta) / alpha)]) * L


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=10_000, help="frames in the batched runs")
    parser.add_argument("--shooting-frames", type=int, default=20, help="frames timed with the shooting method")
    args = parser.parse_args()
    warnings.simplefilter("ignore", BeamConvergenceWarning)
    rows = []

    def row(what, value, unit, note=""):
        rows.append((what, value, unit, note))

    ei, k0, force = workspace(max(args.batch, args.shooting_frames))
    s_m = np.linspace(0.0, L, 101)

    # single frames: a gentle load (convex: direct Newton) and a frame of the workspace
    one = (L, float(ei[0]), float(k0[0]))
    t_cold = best_time(lambda: solve_beam(*one, force[0], GRAVITY), number=20)
    ref = solve_beam(*one, force[0], GRAVITY)
    nudged = force[0] + 1e-3
    t_warm = best_time(lambda: solve_beam(*one, nudged, GRAVITY, initial=ref), number=200)
    t_warm_sens = best_time(lambda: solve_beam(*one, nudged, GRAVITY, initial=ref, sensitivities=True), number=200)
    sens = FastOptions(sensitivities=True)
    t_core = best_time(lambda: solve(*one, nudged, GRAVITY, 0.0, s_m, initial=ref.state, options=sens), number=200)
    shoot_times = []
    for i in range(args.shooting_frames):
        t = time.perf_counter()
        solve_beam(L, ei[i], k0[i], force[i], GRAVITY, method="shooting")
        shoot_times.append(time.perf_counter() - t)
    fast_times = [
        best_time(lambda i=i: solve_beam(L, ei[i], k0[i], force[i], GRAVITY), repeat=3)
        for i in range(args.shooting_frames)
    ]
    t_shoot = float(np.mean(shoot_times))
    row("single frame, fast, cold (from the free arc)", t_cold * 1e6, "µs")
    row("single frame, fast, warm start", t_warm * 1e6, "µs", "solve_beam")
    row("single frame, fast, warm + sensitivities", t_warm_sens * 1e6, "µs", "solve_beam")
    row("single frame, fast core, warm + sensitivities", t_core * 1e6, "µs", "beam.solve, no validation")
    row("single frame, shooting (paper's method)", t_shoot * 1e6, "µs", f"mean of {args.shooting_frames} frames")
    row("speed-up fast cold / shooting", t_shoot / float(np.mean(fast_times)), "×", "same frames")
    row("speed-up fast warm+sens / shooting", t_shoot / t_warm_sens, "×")

    B = args.batch
    sl = slice(0, B)
    cold = solve_beam(L, ei[sl], k0[sl], force[sl], GRAVITY)
    t_bcold = best_time(lambda: solve_beam(L, ei[sl], k0[sl], force[sl], GRAVITY), repeat=3)
    t_bwarm = best_time(lambda: solve_beam(L, ei[sl], k0[sl], force[sl] + 1e-3, GRAVITY, initial=cold), repeat=3)
    t_bsens = best_time(
        lambda: solve_beam(L, ei[sl], k0[sl], force[sl] + 1e-3, GRAVITY, initial=cold, sensitivities=True), repeat=3
    )
    row(f"batch of {B}, fast, cold", B / t_bcold, "solves/s", f"{cold.success.mean():.1%} succeed")
    row(f"batch of {B}, fast, warm start", B / t_bwarm, "solves/s")
    row(f"batch of {B}, fast, warm + sensitivities", B / t_bsens, "solves/s")
    row("speed-up fast batched cold / shooting", t_shoot * B / t_bcold, "×")

    # agreement with the shooting method on the same frames
    n_cmp = args.shooting_frames
    fast = solve_beam(L, ei[:n_cmp], k0[:n_cmp], force[:n_cmp], GRAVITY)
    shoot = solve_beam(L, ei[:n_cmp], k0[:n_cmp], force[:n_cmp], GRAVITY, method="shooting")
    both = fast.success & shoot.success
    diff = np.linalg.norm(fast.tip_position_m - shoot.tip_position_m, axis=-1)[both].max()
    row("tip difference fast vs shooting", diff / L, "× L", f"max over {both.sum()} frames")

    for alpha in (0.25, 1.0, 3.0, 10.0):
        tip = exact_tip(alpha)
        for method in ("fast", "shooting"):
            sol = solve_beam(L, 2.53e-3, 0.0, (alpha * 2.53e-3 / L**2, 0.0), method=method)
            err = np.linalg.norm(sol.tip_position_m - tip)
            row(f"tip error vs exact elastica, α = {alpha:g}, {method}", err / L, "× L", "target ≤ 1e-6")

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"bendsense beam benchmark (fast: {DEFAULT_NODES} Chebyshev nodes; load average {load:.1f}")
    print(f"on {os.cpu_count()} CPUs: timings are wall clock, best of several runs)")
    width = max(len(r[0]) for r in rows)
    print(f"{'quantity':<{width}}  {'value':>12}  unit       note")
    print("-" * (width + 40))
    for what, value, unit, note in rows:
        text = f"{value:12.3g}" if abs(value) < 1e-2 or abs(value) >= 1e5 else f"{value:12.1f}"
        print(f"{what:<{width}}  {text}  {unit:<9}  {note}")


if __name__ == "__main__":
    main()
