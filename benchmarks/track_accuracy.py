"""What tracking gains over the per-frame estimates on two 2 kHz ramp-and-hold setups (used by bench_track.py).

Each setup: several independent sensors (seeds), one 2 s ramp-and-hold series each at
30 kPa (two holds joined by 0.3 s ramps, tests/tracking/test_tracking.py's profile), 1.5 counts of
noise. Every series is estimated twice, from its noisy signals and from the same
signals without noise, so that a frame's error splits into

- its **calibration part** (the noise-free estimate − truth: the fitted calibration's
  error, one bias shared by neighbouring frames, which no averaging removes), and
- its **noise part** (the noisy estimate − the noise-free one: what the tracker averages).

Rows: the per-frame RMS error and its two parts; the tracked RMS error / the per-frame
one (total: what a user sees); the tracked error against the noise-free estimates / the
noise part (the tracker's own figure: how much of the noise it removes); the ±2σ coverage
of the truth over the whole series (Fx, Fy). Setups:

- ``forward model``: tests/forward_model.py's hidden nonlinear sensors (scipy solve_bvp
  beam), calibrations fitted by ``Calibration.fit`` at its default degree 3 from 100
  frames per strip (the calibration error as large as the noise), and at degree 5 from
  1,000 frames per strip (the noise dominates: tests/tracking/test_tracking.py's setup);
- ``simulated board``: bendsense.sim (``bendsense simulate calibration`` then
  ``bendsense calibrate``; the series from ``SimulatedActuator.frames`` of the same board).
"""

import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import bendsense  # noqa: E402
from bendsense import estimate_force, reconstruct, track  # noqa: E402
from bendsense.calibration import Calibration  # noqa: E402

RATE_HZ = 2000.0
PRESSURE_PA = 30e3
CFG = dataclasses.replace(bendsense.load_config(), parameter_covariance=None)
KNOTS_T = [0, 0.3, 0.9, 1.2, 1.8, 2.0]
KNOTS_F = np.array([[0, 0], [0.06, -0.08], [0.06, -0.08], [-0.03, -0.1], [-0.03, -0.1], [0, 0]])


def profile():
    """Times (B,) and true forces (B, 2) of the ramp-and-hold."""
    t = np.arange(int(KNOTS_T[-1] * RATE_HZ)) / RATE_HZ
    return t, np.stack([np.interp(t, KNOTS_T, KNOTS_F[:, c]) for c in range(2)], axis=1)


def forward_model_runs(seeds, degree=3, frames=100):
    """(truth, [(noisy estimate, noise-free estimate)]) with the hidden sensors of tests/forward_model.py."""
    from forward_model import HiddenSensor, forward

    t, truth = profile()
    s_path = np.concatenate([np.linspace(a, b, 11)[:-1] for a, b in zip(KNOTS_T[:-1], KNOTS_T[1:])] + [[KNOTS_T[-1]]])
    f_path = np.stack([np.interp(s_path, KNOTS_T, KNOTS_F[:, c]) for c in range(2)], axis=1)
    exact = np.array([forward(CFG, PRESSURE_PA, f).shifts_m for f in f_path])
    shifts = np.stack([np.interp(t, s_path, exact[:, j]) for j in range(exact.shape[1])], axis=1)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            hidden = HiddenSensor(noise_counts=1.5, seed=seed)
            cal = Calibration.fit(hidden.write_calibration(Path(tmp) / f"s{seed}", CFG, frames=frames), degree=degree)
            rng = np.random.default_rng(100 + seed)
            pair = [estimate_force(reconstruct(sig, cal, CFG.sensor), PRESSURE_PA, CFG, calibration=cal)
                    for sig in (hidden.signals(shifts, rng), hidden.signals(shifts))]
            runs.append(tuple(pair))
    return truth, runs


def board_runs(seeds):
    """(truth, [(noisy estimate, noise-free estimate)]) on bendsense.sim's board, calibrated as the CLI does."""
    from bendsense.sim.actuator import SimulatedActuator
    from bendsense.sim.scenarios import simulate

    t, truth = profile()
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            out = simulate("calibration", Path(tmp) / f"s{seed}", CFG, seed=seed, noise_counts=1.5)
            cal = Calibration.fit(out / "manifest.yaml")
            sim = SimulatedActuator.from_config(CFG, noise_counts=1.5, seed=seed)
            pressure = np.full(t.size, PRESSURE_PA)
            rng = np.random.default_rng(100 + seed)
            pair = []
            for noise in (True, False):
                counts = sim.frames(pressure, truth, noise=noise, rng=rng).counts
                pair.append(estimate_force(reconstruct(counts, cal, CFG.sensor), PRESSURE_PA, CFG, calibration=cal))
            runs.append(tuple(pair))
    return truth, runs


def rows(name, truth, runs):
    """The accuracy rows (what, measured, target) of one setup."""
    t, _ = profile()
    rms = lambda e: float(np.sqrt(np.nanmean(np.square(e))))  # noqa: E731
    frame = np.concatenate([noisy.force_n - truth for noisy, _ in runs])
    cal_part = np.concatenate([clean.force_n - truth for _, clean in runs])
    noise_part = frame - cal_part
    out = [(f"per-frame RMS error, {name}", f"{rms(frame) * 1e3:.2f} mN = calibration {rms(cal_part) * 1e3:.2f} "
            f"(+) noise {rms(noise_part) * 1e3:.2f} mN", "")]
    for mode in ("smooth", "filter"):
        tracks = [track(noisy, t, mode=mode) for noisy, _ in runs]
        tracked = np.concatenate([tr.force_n for tr in tracks])
        clean = np.concatenate([c.force_n for _, c in runs])
        std = np.concatenate([tr.std_n for tr in tracks])
        truths = np.tile(truth, (len(runs), 1))
        cover = np.mean(np.abs(tracked - truths) <= 2 * std, axis=0) * 100
        bw = ", ".join(f"{tr.bandwidth_hz:.3g}" for tr in tracks)
        out += [(f"{mode}: tracked / per-frame RMS (total), {name}",
                 f"{rms(tracked - truths) / rms(frame):.2f} ({rms(tracked - truths) * 1e3:.2f} mN), B = {bw} Hz",
                 "≤ 0.45 where noise dominates"),
                (f"{mode}: tracked vs noise-free / noise part (the tracker's own), {name}",
                 f"{rms(tracked - clean) / rms(noise_part):.2f}", "≤ 0.45"),
                (f"{mode}: ±2σ coverage (Fx, Fy), {name}", f"{cover[0]:.1f} / {cover[1]:.1f} %", "85–99 %")]
    return out


def accuracy_rows(seeds=(1, 2, 3)):
    """The rows of both setups."""
    return (rows("forward model, degree 3", *forward_model_runs(seeds))
            + rows("forward model, degree 5 from 1,000 frames/strip", *forward_model_runs(seeds, 5, 1000))
            + rows("simulated board", *board_runs(seeds)))


if __name__ == "__main__":
    for what, measured, target in accuracy_rows():
        print(f"{what:<80}{measured:<60}{target}")
