"""Benchmark of the simulator's coil physics and virtual sensor (python benchmarks/bench_sim.py)."""

import time

import numpy as np

from bendsense.config import load_config
from bendsense.sim import CoilArrayModel, VirtualSensor, calibration_shifts, coil_mutual_inductance
from bendsense.sim.coils import _coil_spline, loop_mutual_inductance


def rate(fn, n_items, repeat=5):
    fn()  # warm up
    best = min(_timed(fn) for _ in range(repeat))
    return n_items / best, best


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main():
    sensor = load_config().sensor
    rng = np.random.default_rng(0)

    _coil_spline.cache_clear()
    t0 = time.perf_counter()
    model = CoilArrayModel.from_config(sensor)
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    CoilArrayModel.from_config(sensor)
    warm = time.perf_counter() - t0

    n_loop = 100_000
    a = rng.uniform(1e-3, 3e-3, n_loop)
    b = rng.uniform(1e-3, 3e-3, n_loop)
    rho = rng.uniform(0, 20e-3, n_loop)
    loop_rate, _ = rate(lambda: loop_mutual_inductance(a, b, 1e-3, rho), n_loop, repeat=3)
    n_coil = 200
    rho_coil = rng.uniform(0, 20e-3, n_coil)
    coil = model.receiver_coil
    coil_rate, _ = rate(lambda: coil_mutual_inductance(coil, coil, 1e-3, rho_coil), n_coil, repeat=3)
    spline_rate, _ = rate(lambda: model.coil_mutual_inductance(rho), n_loop)

    n_frames = 100_000
    shifts = rng.uniform(-3.5e-3, 3.5e-3, (n_frames, sensor.n_segments))
    virtual = VirtualSensor.from_config(sensor, model=model, seed=0)
    signal_rate, _ = rate(lambda: model.signal(shifts), n_frames)
    direct_rate, _ = rate(lambda: model.direct(shifts[:10_000]), 10_000, repeat=3)
    measure_rate, _ = rate(lambda: virtual.measure(shifts), n_frames)
    one = shifts[:1]
    single_rate, _ = rate(lambda: [virtual.measure(one) for _ in range(2000)], 2000)

    rows = [
        ("coil model build (cold / cached)", f"{cold:.2f} s / {warm * 1e3:.0f} ms"),
        ("filament-loop M, vectorised", f"{loop_rate:,.0f} evaluations/s"),
        (f"coil–coil M ({coil.n_turns}×{coil.n_turns} turn pairs), exact", f"{coil_rate:,.0f} evaluations/s"),
        ("coil–coil M from the pair spline", f"{spline_rate:,.0f} evaluations/s"),
        ("receiver signals, table (16 ch)", f"{signal_rate:,.0f} frames/s"),
        ("receiver signals, direct sum (16 ch)", f"{direct_rate:,.0f} frames/s"),
        ("virtual sensor → ADC counts, batched (16 ch)", f"{measure_rate:,.0f} frames/s"),
        ("virtual sensor → ADC counts, one frame per call", f"{single_rate:,.0f} frames/s"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'what':<{width}}  result")
    print(f"{'-' * width}  {'-' * 28}")
    for name, value in rows:
        print(f"{name:<{width}}  {value}")

    ranges = model.monotonic_range_m()
    print()
    print(f"monotonic range over all channels: [{ranges[:, 0].max() * 1e3:.3f}, {ranges[:, 1].min() * 1e3:.3f}] mm")
    print(f"gain: {virtual.gain_counts[0]:.1f} counts per normalized unit (M_ref = {model.mutual_ref_h * 1e9:.1f} nH)")
    flat = virtual.signal(np.zeros(sensor.n_segments))
    for radius in (0.040, 0.400):
        delta = virtual.signal(calibration_shifts(sensor, radius)) - flat
        counts = virtual.signal(calibration_shifts(sensor, radius))
        print(
            f"R = {radius * 1e3:.0f} mm: ΔA from {delta[0]:+.0f} (ch1) / {delta[1]:+.0f} (ch2) "
            f"to {delta[-2]:+.0f} (ch15) / {delta[-1]:+.0f} (ch16) counts; "
            f"counts {counts.min():.0f}…{counts.max():.0f}"
        )


if __name__ == "__main__":
    main()
