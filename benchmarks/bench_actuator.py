"""Free-bending model: direct solve, interpolant build and evaluation, accuracy.

Run: ``python benchmarks/bench_actuator.py``. Prints one table for the paper's
prototype (``bendsense.load_config()``).
"""

import math
import time

import numpy as np

import bendsense
from bendsense.mechanics import actuator
from bendsense.mechanics.actuator import FreeBendingModel


def best_time(fn, repeat=7, number=None):
    """Best wall time per call [s] over ``repeat`` rounds of ``number`` calls."""
    if number is None:
        number = 1
        while True:
            t0 = time.perf_counter()
            for _ in range(number):
                fn()
            if time.perf_counter() - t0 > 0.05:
                break
            number *= 2
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def main():
    config = bendsense.load_config()
    model = FreeBendingModel.from_config(config)
    rng = np.random.default_rng(0)
    p_max = model.pressure_max_pa

    rows = []
    t = best_time(lambda: model.solve(60e3))
    rows.append(("direct solve, 1 pressure", f"{t * 1e6:10.1f} µs", "bracketed Newton, eq. 8-12"))
    batch = rng.uniform(0, p_max, 10_000)
    t = best_time(lambda: model.solve(batch), repeat=3)
    rows.append(("direct solve, 10,000 pressures", f"{t / batch.size * 1e6:10.2f} µs/frame", "vectorised"))

    def build():
        actuator._hermite_table.cache_clear()
        FreeBendingModel.from_config(config)

    t = best_time(build, repeat=5)
    rows.append(("interpolant build (uncached)", f"{t * 1e3:10.2f} ms", f"{len(model._table.coef)} intervals"))
    t = best_time(lambda: FreeBendingModel.from_config(config))
    rows.append(("model construction (cached)", f"{t * 1e6:10.1f} µs", "per parameter set"))

    t = best_time(lambda: model.bending_angle_rad(60e3))
    rows.append(("interpolant, 1 frame (float)", f"{t * 1e6:10.2f} µs", ""))
    one = np.array([60e3])
    t = best_time(lambda: model.bending_angle_rad(one))
    rows.append(("interpolant, 1 frame (array)", f"{t * 1e6:10.2f} µs", ""))
    t = best_time(lambda: model.bending_angle_rad(batch))
    rows.append(("interpolant, 10,000 frames", f"{t / batch.size * 1e9:10.1f} ns/frame", f"{t * 1e6:.0f} µs total"))
    t = best_time(lambda: model.tip_curvature_per_m(batch))
    rows.append(("K0, 10,000 frames", f"{t / batch.size * 1e9:10.1f} ns/frame", ""))

    test = rng.uniform(0, p_max, 200_000)
    err = np.max(np.abs(model.bending_angle_rad(test) - model.solve(test)))
    rows.append(("max interpolant error", f"{err:10.2e} rad", "200,000 random pressures vs direct"))

    theta = np.degrees(model.solve([20e3, 60e3, 120e3]))
    rows.append(("theta0 at 20/60/120 kPa", f"{theta[0]:.2f}/{theta[1]:.2f}/{theta[2]:.2f}°", "DESIGN: 25/80/176°"))

    width = max(len(r[0]) for r in rows)
    print(f"free-bending model, paper prototype, pressure_max_pa = {p_max:g}")
    print(f"{'what':{width}s}  {'value':>22s}  note")
    print("-" * (width + 50))
    for what, value, note in rows:
        print(f"{what:{width}s}  {value:>22s}  {note}")


if __name__ == "__main__":
    main()
