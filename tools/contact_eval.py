"""Contact anywhere along the finger: bendsense's location and force on data it did not make.

Measures the DESIGN.md section 5 contact rows of ``bendsense.estimate_contact`` (50 ms
windows at 2 kHz, 1.5 counts): the median |s_c error| and the ±2σ coverage of s_c over
the windows of a contact hold (s_c ≥ 0.6 L, normal force ≥ 0.1 N), the ±2σ coverage of
the force (each component) over their frames, how often such a window is chosen as a
contact, and how often a tip-load window keeps the tip model. Run from the repository
root::

    python tools/contact_eval.py [--quick] [--seeds 32] [--holds 8] [--prior]

The data are made by the independent forward model of ``tests/forward_model.py`` (scipy
``solve_bvp`` split at s_c; never bendsense's beam), read through hidden nonlinear
sensors (``HiddenSensor``, one per seed) whose calibration ``Calibration.fit`` fits from
their own noisy strip recordings (tools/model_error.py's sensors). Each sensor records a
2 kHz series of holds, alternating a contact hold and a tip hold: at a pressure drawn in
30–110 kPa the load ramps from 0 in 50 ms, holds 200 ms and ramps back in 50 ms; the
pressure then steps to the next hold's. A contact hold has s_c drawn in [0.6 L, 0.95 L]
(inside the last coil) and a force of 0.1–0.3 N normal to the free actuator's tangent at
s_c, pushing it outward (away from the centre of curvature, as a grasped object does); a
tip hold has a tip force of up to 0.25 N in any direction (tools/model_error.py's loads).
Along a ramp the coil angles are interpolated between 9 Chebyshev–Lobatto nodes of the
load fraction (tools/model_error.py). Scored windows lie wholly in a hold; a contact
window that keeps the tip model counts with s_c = L and as not covered.

The estimate is told the config the data were made with, without its parameter prior
(the actuator is the config's, as after ``bendsense identify``); ``--prior`` keeps the
shipped prior (an actuator not identified: the location is then mostly unresolved).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.interpolate import BarycentricInterpolator

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tools"))

from forward_model import forward, free_bending_k0  # noqa: E402
from model_error import RATE_HZ, calibration, fractions, lobatto  # noqa: E402

import bendsense  # noqa: E402
from bendsense.shape.pcc import reconstruct  # noqa: E402

NOISE_COUNTS = 1.5
WINDOW_S = 0.05
S_RANGE = (0.6, 0.95)  # contact holds: s_c / L
FORCE_RANGE_N = (0.1, 0.3)  # contact holds: |F| normal to the tangent
PRESSURE_PA = (30e3, 110e3)
TIP_MAX_N = 0.25
CACHE = ROOT / ".cache" / "contact_eval"


@dataclasses.dataclass(frozen=True)
class Hold:
    """One hold: its pressure [Pa], force (2,) [N] and contact location [m] (L for a tip load)."""

    pressure_pa: float
    force_n: np.ndarray
    contact_s_m: float
    tip: bool


def holds(config, seed, n_holds, s_range=S_RANGE, force_range_n=FORCE_RANGE_N):
    """The holds of sensor ``seed``: contact and tip holds alternating, contact first."""
    rng = np.random.default_rng(2300 + seed + (0 if s_range == S_RANGE and force_range_n == FORCE_RANGE_N else 7919))
    L = config.actuator.length_m
    out = []
    for j in range(n_holds):
        p = float(rng.uniform(*PRESSURE_PA))
        if j % 2 == 0:
            sc = float(rng.uniform(*s_range) * L)
            phi = free_bending_k0(config, p) * sc  # the free arc's tangent angle at s_c
            mag = float(rng.uniform(*force_range_n))
            # outward normal: −(cos φ, −sin φ) (the inward one points to the centre of curvature)
            out.append(Hold(p, mag * np.array([-np.cos(phi), np.sin(phi)]), sc, False))
        else:
            a, r = rng.uniform(0.0, 2.0 * np.pi), TIP_MAX_N * np.sqrt(rng.uniform())
            out.append(Hold(p, np.array([r * np.cos(a), r * np.sin(a)]), L, True))
    return out


def ramp_angles(config, hold, use_cache=True):
    """True coil angles (NODES, N) [rad] at the Lobatto load fractions of one hold (cached)."""
    key = hashlib.sha1(repr((float(hold.pressure_pa), np.round(hold.force_n, 15).tolist(),
                             round(hold.contact_s_m, 15), lobatto().size)).encode()).hexdigest()
    path = CACHE / f"{key}.npz"
    if use_cache and path.exists():
        with np.load(path) as z:
            return z["angles"]
    angles = np.array([forward(config, hold.pressure_pa, a * hold.force_n, contact_s_m=hold.contact_s_m).angles_rad
                       for a in lobatto()])
    if use_cache:
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez(path, angles=angles)
    return angles


@dataclasses.dataclass(frozen=True)
class Series:
    """One sensor's series: truth per frame."""

    t_s: np.ndarray
    pressure_pa: np.ndarray
    force_n: np.ndarray  # (B, 2)
    contact_s_m: np.ndarray  # (B,)
    angles_rad: np.ndarray  # (B, N)
    hold: np.ndarray  # (B,) index of the hold
    held: np.ndarray  # (B,) bool: the load is constant (not on a ramp)
    tip: np.ndarray  # (B,) bool: a tip hold


def series(config, seed, n_holds, use_cache=True, **ranges):
    """The true series of sensor ``seed``: ``n_holds`` × 600 frames at 2 kHz (``ranges``: of :func:`holds`)."""
    alpha = fractions()
    nodes = lobatto()
    hs = holds(config, seed, n_holds, **ranges)
    ang = [BarycentricInterpolator(nodes, ramp_angles(config, h, use_cache))(alpha) for h in hs]
    n = alpha.size
    B = n * len(hs)
    return Series(t_s=np.arange(B) / RATE_HZ, pressure_pa=np.repeat([h.pressure_pa for h in hs], n),
                  force_n=np.concatenate([alpha[:, None] * h.force_n for h in hs]),
                  contact_s_m=np.repeat([h.contact_s_m for h in hs], n), angles_rad=np.concatenate(ang),
                  hold=np.repeat(np.arange(len(hs)), n), held=np.tile(alpha == 1.0, len(hs)),
                  tip=np.repeat([h.tip for h in hs], n))


def estimate(truth, config, est_config, seed, noise_counts=NOISE_COUNTS):
    """The series through the hidden sensor ``seed``, reconstructed and ``estimate_contact``-ed.

    Also its wall time and, for reference, the estimate at the true location
    (``estimate_force(load="contact", contact_s_m=truth)``).
    """
    sensor, cal = calibration(config, seed, noise_counts)
    rng = np.random.default_rng([seed, int(noise_counts * 100), 23])
    signals = sensor.signals(config.sensor.strip_gap_m * truth.angles_rad, rng)
    shape = reconstruct(signals, cal, config.sensor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        est = bendsense.estimate_contact(shape, truth.pressure_pa, est_config, calibration=cal, t_s=truth.t_s,
                                         window_s=WINDOW_S)
        wall = time.perf_counter() - t0
        known = bendsense.estimate_force(shape, truth.pressure_pa, est_config, load="contact",
                                         contact_s_m=truth.contact_s_m, calibration=cal)
        return est, wall, known


def windows(truth):
    """Boundaries (W + 1,) of the windows ``estimate_contact`` cut the series into."""
    from bendsense.estimation.contact import contact_windows

    return contact_windows(truth.t_s, truth.pressure_pa, WINDOW_S, truth.t_s.size)


def score(results, config):
    """The section 5 numbers from ``results``: a list of (truth, estimate, window boundaries)."""
    L = config.actuator.length_m
    err, cover, chosen, unresolved, tip_kept, f_cover, f_err, k_cover = [], [], [], [], [], [], [], []
    resolved_cover = []
    for truth, est, bounds, known in results:
        s_hat = np.asarray(est.contact_s_m, dtype=float)
        s_std = np.asarray(est.contact_std_m, dtype=float)
        for a, b in zip(bounds[:-1], bounds[1:]):
            if not truth.held[a:b].all() or truth.hold[a] != truth.hold[b - 1]:
                continue  # scored windows lie wholly in one hold
            if truth.tip[a]:
                tip_kept.append(np.isnan(s_hat[a]))
                continue
            contact = np.isfinite(s_hat[a])
            e = (s_hat[a] if contact else L) - truth.contact_s_m[a]
            chosen.append(contact)
            unresolved.append(contact and np.isinf(s_std[a]))
            err.append(abs(e))
            cover.append(contact and np.isfinite(s_std[a]) and abs(e) <= 2.0 * s_std[a])  # unresolved: not covered
            if contact and np.isfinite(s_std[a]):
                resolved_cover.append(abs(e) <= 2.0 * s_std[a])
            z = np.abs(est.force_n[a:b] - truth.force_n[a:b]) / est.std_n[a:b]
            f_cover.append(np.where(np.isfinite(z), z, np.inf) <= 2.0)
            zk = np.abs(known.force_n[a:b] - truth.force_n[a:b]) / known.std_n[a:b]
            k_cover.append(np.where(np.isfinite(zk), zk, np.inf) <= 2.0)
            f_err.append(np.hypot(*(est.force_n[a:b] - truth.force_n[a:b]).T))
    f_cover = np.concatenate(f_cover) if f_cover else np.zeros((0, 2))
    k_cover = np.concatenate(k_cover) if k_cover else np.zeros((0, 2))
    return {
        "contact_windows": len(err),
        "median_error_m": float(np.median(err)) if err else np.nan,
        "s_coverage": float(np.mean(cover)) if cover else np.nan,
        "s_coverage_resolved": float(np.mean(resolved_cover)) if resolved_cover else np.nan,
        "chosen_contact": float(np.mean(chosen)) if chosen else np.nan,
        "unresolved": float(np.mean(unresolved)) if unresolved else np.nan,
        "force_coverage": f_cover.mean(axis=0) if f_cover.size else np.full(2, np.nan),
        "known_force_coverage": k_cover.mean(axis=0) if k_cover.size else np.full(2, np.nan),
        "force_error_n": float(np.median(np.concatenate(f_err))) if f_err else np.nan,
        "tip_windows": len(tip_kept),
        "tip_kept": float(np.mean(tip_kept)) if tip_kept else np.nan,
    }


def _sensor(config, est_config, n_holds, use_cache, noise_counts, ranges, seed):
    """One sensor's series, estimated.

    Returns ((truth, estimate, window boundaries, known-location estimate), wall time per 100-frame window [s]).
    """
    truth = series(config, seed, n_holds, use_cache, **ranges)
    est, wall, known = estimate(truth, config, est_config, seed, noise_counts)
    return (truth, est, windows(truth), known), wall / (truth.t_s.size / (WINDOW_S * RATE_HZ))


def run(config, seeds, n_holds, *, prior=False, use_cache=True, noise_counts=NOISE_COUNTS, executor=None, **ranges):
    """Estimate every sensor's series and score them: (scores, wall time per 100-frame window [s]).

    ``ranges``: ``s_range`` (s_c / L) and ``force_range_n`` of the contact holds (:func:`holds`).
    ``executor``: a ``concurrent.futures.Executor`` to run the sensors on (default: one after another here).
    """
    est_config = config if prior else config.replace(parameter_covariance=None)
    one = functools.partial(_sensor, config, est_config, n_holds, use_cache, noise_counts, ranges)
    done = list((map if executor is None else executor.map)(one, seeds))
    return score([r for r, _ in done], config), float(np.median([w for _, w in done]))


def window_time(config, repeats=20):
    """Median wall time [s] of ``estimate_contact`` on one 100-frame window (warm), one sensor's hold."""
    truth = series(config, 0, 1)
    sensor, cal = calibration(config, 0, NOISE_COUNTS)
    rng = np.random.default_rng(5)
    sl = slice(200, 300)
    shape = reconstruct(sensor.signals(config.sensor.strip_gap_m * truth.angles_rad[sl], rng), cal, config.sensor)
    cfg = config.replace(parameter_covariance=None)
    times = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(repeats + 1):
            t0 = time.perf_counter()
            bendsense.estimate_contact(shape, truth.pressure_pa[sl], cfg, calibration=cal, t_s=truth.t_s[sl])
            times.append(time.perf_counter() - t0)
    return float(np.median(times[1:]))


def table(scores, window_s_time):
    """The section 5 contact rows as a markdown table."""
    fc = scores["force_coverage"]
    rows = [
        ("median absolute s_c error, contact windows (s_c ≥ 0.6 L, ≥ 0.1 N)", "≤ 8 mm",
         f"{1e3 * scores['median_error_m']:.1f} mm"),
        ("±2σ coverage of s_c (a window that kept the tip model or is unresolved: not covered)", "≥ 85 %",
         f"{100 * scores['s_coverage']:.0f} %"),
        ("±2σ coverage of the force, Fx / Fy", "≥ 85 %", f"{100 * fc[0]:.0f} / {100 * fc[1]:.0f} %"),
        ("(reference) ±2σ coverage of the force at the true location, Fx / Fy", "88–99 %",
         f"{100 * scores['known_force_coverage'][0]:.0f} / {100 * scores['known_force_coverage'][1]:.0f} %"),
        ("contact windows chosen as contact", "—", f"{100 * scores['chosen_contact']:.0f} %"),
        ("contact windows contact_unresolved", "—", f"{100 * scores['unresolved']:.0f} %"),
        ("tip windows keeping the tip model", "≥ 90 %", f"{100 * scores['tip_kept']:.0f} %"),
        ("median force error magnitude, contact frames", "—", f"{1e3 * scores['force_error_n']:.1f} mN"),
        ("a 100-frame window (warm)", "≤ 20 ms", f"{1e3 * window_s_time:.1f} ms"),
    ]
    lines = ["| what | target | measured |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines)


HARD = {"s_range": (0.3, 0.6), "force_range_n": (0.02, 0.1)}  # beyond the targets: nearer the base, lighter


def hard_table(scores):
    """The same measures for contacts at 0.3–0.6 L of 0.02–0.1 N (no target: where the model choice fails)."""
    fc = scores["force_coverage"]
    return "\n".join([
        "| contacts at 0.3–0.6 L, 0.02–0.1 N | measured |", "|---|---|",
        f"| chosen as contact | {100 * scores['chosen_contact']:.0f} % |",
        f"| contact_unresolved | {100 * scores['unresolved']:.0f} % |",
        f"| median absolute s_c error (a window that kept the tip model counts at L) | "
        f"{1e3 * scores['median_error_m']:.1f} mm |",
        f"| ±2σ coverage of s_c, of the windows located (chosen as contact and resolved) | "
        f"{100 * scores['s_coverage_resolved']:.0f} % |",
        f"| ±2σ coverage of the force, Fx / Fy | {100 * fc[0]:.0f} / {100 * fc[1]:.0f} % |",
        f"| tip windows keeping the tip model (same series) | {100 * scores['tip_kept']:.0f} % |",
    ])


def main(argv=None):
    """Print the table; return the scores."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="16 sensors × 8 holds (the test's sample) instead of 32 × 8")
    ap.add_argument("--seeds", type=int, default=None, help="number of independent sensors")
    ap.add_argument("--holds", type=int, default=None, help="holds per sensor (600 frames each; half contact)")
    ap.add_argument("--prior", action="store_true", help="keep the shipped parameter prior (not identified)")
    ap.add_argument("--no-cache", action="store_true", help="solve every forward problem again")
    ap.add_argument("--noise-counts", type=float, default=NOISE_COUNTS,
                    help=f"the hidden sensors' noise [counts] (default {NOISE_COUNTS}: ~0.6 mrad per coil; "
                         "8: ~3.2 mrad, the simulated board's; 16.5: ~6.6 mrad)")
    args = ap.parse_args(argv)
    n_seeds = args.seeds or (16 if args.quick else 32)
    n_holds = args.holds or 8
    config = bendsense.load_config()
    start = time.perf_counter()
    scores, _ = run(config, range(n_seeds), n_holds, prior=args.prior, use_cache=not args.no_cache,
                    noise_counts=args.noise_counts)
    wt = window_time(config)
    print(f"# contact along the finger: {n_seeds} sensors × {n_holds} holds × 600 frames at 2 kHz, "
          f"{args.noise_counts:g} counts, {WINDOW_S * 1e3:g} ms windows, "
          f"{'shipped prior' if args.prior else 'no prior'}; "
          f"{scores['contact_windows']} contact windows, {scores['tip_windows']} tip windows\n")
    print(table(scores, wt))
    hard, _ = run(config, range(n_seeds), n_holds, prior=args.prior, use_cache=not args.no_cache,
                  noise_counts=args.noise_counts, **HARD)
    print(f"\n## Beyond the targets: {hard['contact_windows']} windows of contacts nearer the base and lighter\n")
    print(hard_table(hard))
    print(f"\n{time.perf_counter() - start:.0f} s")
    return scores


if __name__ == "__main__":
    main()
