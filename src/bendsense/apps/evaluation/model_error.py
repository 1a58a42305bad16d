"""The "model error" section of the evaluation: bendsense on an actuator that is not its model.

The simulated board (:class:`~bendsense.sim.actuator.SimulatedActuator`, bendsense's own
beam run forwards) records 2 kHz ramp-and-hold series while the true actuator departs
from the config: ``k0_error`` = +5 %, ``ei_error`` = +15 %, ``base_rotation_rad_per_rad``
= 0.05 (about 5° at 100° of bending). Each series is estimated with the config stripped
of its parameter covariance (the error undeclared: what the window check must catch)
and with the shipped config and its parameter prior (what the σ must cover), then
window-checked (:func:`bendsense.check_windows`) and tracked (:func:`bendsense.track`).

The simulator is bendsense's own model, so this section checks the checks against
bendsense's physics; the same table against an independent forward model (scipy's
``solve_bvp``, hidden nonlinear sensors) is ``tools/model_error.py`` and
docs/model-error.md.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from bendsense.status import Status

__all__ = ["MODEL_ERROR_CASES", "model_error_evaluation", "fig_model_error"]

#: Rows of the section: label and the simulator's mismatch options.
MODEL_ERROR_CASES = {
    "control": ("nothing (control)", {}),
    "k0": ("K0 +5 %", {"k0_error": 0.05}),
    "ei": ("EI +15 %", {"ei_error": 0.15}),
    "base": ("base rotates 0.05 rad/rad", {"base_rotation_rad_per_rad": 0.05}),
}
RATE_HZ = 2000.0
RAMP_FRAMES, HOLD_FRAMES = 100, 400
HOLDS = ((40e3, (0.12, -0.05)), (70e3, (-0.08, -0.15)), (100e3, (0.15, 0.1)))  # pressure [Pa], load [N]


def _series():
    """Time [s], pressure [Pa] and true load [N] of the ramp-and-hold series (holds × 600 frames)."""
    up = np.arange(RAMP_FRAMES) / RAMP_FRAMES
    alpha = np.concatenate([up, np.ones(HOLD_FRAMES), 1.0 - (np.arange(RAMP_FRAMES) + 1) / RAMP_FRAMES])
    p = np.concatenate([np.full(alpha.size, pj) for pj, _ in HOLDS])
    force = np.concatenate([alpha[:, None] * np.asarray(fj) for _, fj in HOLDS])
    hold = np.tile(alpha == 1.0, len(HOLDS))
    return np.arange(p.size) / RATE_HZ, p, force, hold


def model_error_evaluation(calibration, config, seed: int) -> dict:
    """Per-frame, window-checked and tracked forces on the simulated board under each mismatch.

    Parameters
    ----------
    calibration : Calibration
        The calibration of the simulated sensor of ``seed`` (degree 3).
    config : Config
        The shipped config (its parameter prior is used for the "declared by the prior" columns).
    seed : int
        Seed of the simulated sensor and its noise.

    Returns
    -------
    dict
        Per case key (:data:`MODEL_ERROR_CASES`): ``label``, ``windows`` (fraction of the hold
        windows flagged, their count), ``coverage_frame`` (±2σ coverage Fx/Fy, per frame,
        undeclared), ``coverage_track`` (tracked, with the prior), ``flagged_track``; and
        ``series``: the K0 case's arrays for the figure.
    """
    from bendsense.estimation import estimate_force
    from bendsense.shape.pcc import reconstruct
    from bendsense.sim.actuator import SimulatedActuator
    from bendsense.sim.sensor import VirtualSensor
    from bendsense.tracking import check_windows, track

    t, p, force, hold = _series()
    bare = config.replace(parameter_covariance=None)
    out = {}
    for key, (label, mismatch) in MODEL_ERROR_CASES.items():
        sensor = VirtualSensor.from_config(config, noise_counts=1.5, seed=seed)
        sim = SimulatedActuator.from_config(bare, sensor=sensor, **mismatch)
        frames = sim.frames(p, force, rng=np.random.default_rng([seed, 22]))
        shape = reconstruct(frames.counts, calibration, config.sensor)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plain = check_windows(estimate_force(shape, p, bare, calibration=calibration), t, pressure_pa=p)
            prior = check_windows(estimate_force(shape, p, config, calibration=calibration), t, pressure_pa=p)
        tracked = track(prior, t, pressure_pa=p)
        tracked_plain = track(plain, t, pressure_pa=p)
        window = np.arange(t.size) // RAMP_FRAMES
        held = [w for w in np.unique(window) if hold[window == w].all()]
        wp = np.array([np.nanmedian(plain.window_p_value[window == w]) for w in held])
        out[key] = {
            "label": label,
            "windows": (float(np.mean(wp < 1e-3)), len(held)),
            "coverage_frame": np.mean(np.abs(plain.force_n - force) <= 2 * plain.std_n, axis=0),
            "coverage_track": np.mean(np.abs(tracked.force_n - force) <= 2 * tracked.std_n, axis=0),
            "flagged_track": float(np.mean(np.asarray(tracked.status) != Status.OK)),
        }
        if key == "k0":
            out["series"] = {"t_s": t, "force_n": force, "frame_n": plain.force_n, "frame_std_n": plain.std_n,
                             "track_n": tracked_plain.force_n, "track_std_n": tracked_plain.std_n,
                             "flagged": np.asarray(plain.window_p_value) < 1e-3}
    return out


def fig_model_error(path, series) -> Path:
    """Per-frame and tracked force under K0 +5 %, ±2σ bands, the windows the check flags shaded.

    Parameters
    ----------
    path : path
        PNG to write.
    series : dict
        ``model_error_evaluation(...)["series"]``.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 5), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    t = series["t_s"]
    for k, ax in enumerate(axes):
        ax.plot(t, series["frame_n"][:, k], ".", ms=1, color="0.6", label="per frame")
        f, s = series["track_n"][:, k], series["track_std_n"][:, k]
        ax.plot(t, f, color="C0", label="tracked (RTS smoother)")
        ax.fill_between(t, f - 2 * s, f + 2 * s, color="C0", alpha=0.25, label="tracked ±2σ")
        ax.plot(t, series["force_n"][:, k], color="k", lw=1, ls="--", label="true")
        flagged = series["flagged"]
        ax.fill_between(t, 0, 1, where=flagged, transform=ax.get_xaxis_transform(), color="C3", alpha=0.12,
                        label="window flagged (model_misfit)")
        ax.set_ylabel(("Fx", "Fy")[k] + " [N]")
    axes[0].legend(fontsize=7, ncol=3, loc="upper right")
    axes[1].set_xlabel("t [s]")
    fig.suptitle("K0 +5 %, error undeclared: per-frame vs tracked force (simulated board, 1.5 counts)")
    fig.savefig(path, dpi=100)
    return Path(path)
