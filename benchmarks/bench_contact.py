"""Contact along the finger (issue 23, DESIGN.md section 5): the contact rows, as one printed table.

- one frame, cold, at a known contact point (``estimate_force(load="contact",
  contact_s_m=X)``) against one frame, cold, of a tip load, in the same run, frames
  interleaved: median and 99th percentile latency and their ratio (target ≤ 2×);

The workload is bench_cold's: independent, shuffled frames with random pressures 15–120
kPa and forces up to 0.25 N in any direction, shifts of the beam model with ~1.5 counts
of noise, a cubic calibration with noise and residuals (so σ is propagated); the contact
frames put the force at s_c uniform in 0.5–1 L. Latencies are wall time per call
(inputs prepared beforehand; the first calls, compilation or cache load, excluded).

    python benchmarks/bench_contact.py [--frames 2000] [--quick]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from bench_cold import CFG, MODEL, SENSOR, L, calibration  # noqa: E402

from bendsense.beam import solve_beam  # noqa: E402
from bendsense.estimation import estimate_force  # noqa: E402
from bendsense.pcc import shifts_to_curvatures  # noqa: E402
from bendsense.sim.sensor import shifts_from_shape  # noqa: E402


def frames(n, seed=0, noise_m=3e-6, contact=True):
    """Curvatures (n, N), pressures (n,), forces (n, 2) and contact points (n,) of independent frames."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(15e3, 120e3, n)
    a = rng.uniform(0.0, 2.0 * np.pi, n)
    r = 0.25 * np.sqrt(rng.uniform(0.0, 1.0, n))
    force = np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
    sc = rng.uniform(0.5, 1.0, n) * L if contact else np.full(n, L)
    s = np.linspace(0.0, L, 135)
    sol = solve_beam(L, CFG.stiffness.ei_nm2(p), MODEL.tip_curvature_per_m(p), force, CFG.weight_per_length_n_per_m,
                     0.0, s, warn=False, contact_s_m=sc)
    shifts = shifts_from_shape(s, sol.angle_rad, SENSOR.lengths_m, SENSOR.strip_gap_m)
    shifts = shifts + noise_m * rng.standard_normal(shifts.shape)
    keep = sol.success
    kappa = shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m)
    return kappa[keep], p[keep], force[keep], sc[keep]


def known_location_rows(n_frames, cal):
    """Rows: one cold frame of a tip load and one at a known contact point, interleaved in one run."""
    kt, pt, _, _ = frames(n_frames, seed=0, contact=False)
    kc, pc, fc, sc = frames(n_frames, seed=1)
    n = min(len(pt), len(pc))
    estimate_force(kt[0], pt[0], CFG, calibration=cal)  # compile or load the cache
    estimate_force(kc[0], pc[0], CFG, calibration=cal, load="contact", contact_s_m=sc[0])
    tip, contact, err = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        estimate_force(kt[i], pt[i], CFG, calibration=cal)
        t1 = time.perf_counter()
        est = estimate_force(kc[i], pc[i], CFG, calibration=cal, load="contact", contact_s_m=sc[i])
        t2 = time.perf_counter()
        tip[i], contact[i] = t1 - t0, t2 - t1
        err[i] = np.abs(est.force_n - fc[i]).max() if est.success else np.nan
    tip, contact = tip * 1e6, contact * 1e6
    ratio = np.median(contact) / np.median(tip)
    return [
        ("one frame, cold, tip load (force + σ)",
         f"median {np.median(tip):.0f} µs, p99 {np.percentile(tip, 99):.0f} µs", "≤ 50 µs, ≤ 500 µs"),
        ("one frame, cold, known contact 0.5–1 L (force + σ)",
         f"median {np.median(contact):.0f} µs, p99 {np.percentile(contact, 99):.0f} µs", ""),
        ("known contact / tip load, cold (medians)", f"{ratio:.2f}×", "≤ 2×"),
        ("known contact: success, force error vs truth (median; synthetic noise)",
         f"{np.count_nonzero(np.isfinite(err))}/{n}, {np.nanmedian(err) * 1e3:.2f} mN", ""),
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=2000, help="cold frames of each kind, timed one by one")
    ap.add_argument("--quick", action="store_true", help="small sizes (seconds), for the docs test")
    args = ap.parse_args()
    if args.quick:
        args.frames = 200
    cal = calibration()
    rows = known_location_rows(args.frames, cal)
    width = max(len(r[0]) for r in rows)
    print(f"{'what':{width}s}  {'measured':42s}  target")
    for what, got, target in rows:
        print(f"{what:{width}s}  {got:42s}  {target}")


if __name__ == "__main__":
    main()
