"""Metrics of the evaluation: how close shapes and forces come to the truth, and how well σ covers it.

Reusable on any data with a truth: :func:`shape_accuracy` (paper eq. 19–20, Table I),
:func:`static_model_errors` (Fig. 9), :func:`tip_load_errors` (Fig. 10),
:func:`contact_errors` (Table II), and the statistics they share: :func:`mean_std` and
the ±kσ coverage of errors in units of their σ (:func:`coverage`, :func:`pooled_z`).
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.apps.evaluation.protocol import (
    CONTACT_MODES,
    FORCE_RANGES_N,
    MAX_CONTACT_N,
    MAX_TIP_LOAD_N,
    combinations,
)
from bendsense.config import Config

__all__ = [
    "mean_std",
    "coverage",
    "pooled_z",
    "shape_accuracy",
    "static_model_errors",
    "tip_load_errors",
    "contact_errors",
]


def mean_std(values) -> tuple:
    """Mean and sample standard deviation of the finite ``values`` (NaN where there are too few).

    Parameters
    ----------
    values : array_like
        The values; NaN and inf are left out.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (math.nan, math.nan)
    return (float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan)


def coverage(z, k: float = 2.0) -> float:
    """Fraction of the finite ``z`` (errors in units of their σ) with |z| ≤ k.

    Parameters
    ----------
    z : array_like
        Errors in units of their σ; non-finite values are left out.
    k : float, default 2.0
        Half-width of the band, in σ.
    """
    z = np.asarray(z, dtype=float).ravel()
    z = z[~np.isnan(z)]
    return float(np.mean(np.abs(z) <= k)) if z.size else math.nan


def pooled_z(tip, contact) -> np.ndarray:
    """Every tested z of one objective: the tip loads' F̂y and each contact mode's F̂x, F̂y.

    Parameters
    ----------
    tip : dict
        The result of :func:`tip_load_errors` for the objective.
    contact : dict
        The result of :func:`contact_errors` for the objective.
    """
    parts = [np.asarray(tip["z"]).ravel()]
    parts += [np.asarray(contact[label]["z"]).ravel() for label, _, _ in CONTACT_MODES]
    return np.concatenate(parts)


def shape_accuracy(calibration, strips, sensor, s_m) -> dict:
    """Table I for one calibration: κ_recon, δκ and (δp)_max of each validation strip.

    Parameters
    ----------
    calibration : Calibration
        Signal → shift calibration (paper eq. 1–2).
    strips : sequence of (signals (frames, N), κ_val [1/m])
        The recordings of the validation strips and their true curvatures.
    sensor : SensorConfig
        Segment lengths and strip gap.
    s_m : ndarray, shape (M,)
        Arc lengths of the compared points on ``[0, L_sensor]`` [m].

    Returns
    -------
    dict
        ``kappa_recon_per_m`` (strips,): mean over the frames of κ_recon (paper eq. 19);
        ``dkappa_pct``: ``|κ_recon − κ_val| / κ_val · 100``; ``dp_max_pct``: mean over the
        frames of (δp)_max (paper eq. 20, relative to the sensor length); ``shapes``:
        the reconstructed positions of each strip's first frame (strips, M, 2) [m].
    """
    from bendsense.shape.pcc import fit_arc_curvature, max_position_error, reconstruct

    length = float(np.sum(sensor.lengths_m))
    kappa, dkappa, dp, shapes = [], [], [], []
    for signals, kappa_val in strips:
        shape = reconstruct(signals, calibration, sensor, s_m)
        k = fit_arc_curvature(shape.positions_m, s_m)
        kappa.append(float(np.mean(k)))
        dkappa.append(abs(kappa[-1] - kappa_val) / kappa_val * 100.0)
        dp.append(float(np.mean(max_position_error(shape.positions_m, s_m, kappa_val, length))))
        shapes.append(shape.positions_m[0])
    return {
        "kappa_recon_per_m": np.array(kappa),
        "dkappa_pct": np.array(dkappa),
        "dp_max_pct": np.array(dp),
        "dkappa_all_pct": mean_std(dkappa),
        "dp_max_all_pct": mean_std(dp),
        "shapes": np.array(shapes),
    }


def static_model_errors(tips, truth, calibration, model_config: Config) -> dict:
    """Fig. 9: max position errors of the static model and of the sensor against the truth.

    Parameters
    ----------
    tips : Session
        The tip-load recording (``pressure_pa``, ``load_n``, ``fx_n``, ``fy_n``).
    truth : mapping
        ``s_m`` (M,) on the sensor line and ``positions_m`` (frames, M, 2) of the true
        shapes [m].
    calibration : Calibration
        For the sensor reconstruction.
    model_config : Config
        The identified model: free bending, EI(P), gravity.

    Returns
    -------
    dict
        Per pressure level (``pressure_pa`` (P,)): ``model_error_pct``, ``sensor_error_pct``
        (max over the sensor line of the distance to the true shape, relative to the
        actuator length, averaged across loads); per combination (``config_pressure_pa``,
        ``config_load_n``): ``config_model_error_pct``, ``config_sensor_error_pct``, and the
        shapes (``model_positions_m``, ``sensor_positions_m``, ``truth_positions_m``).
    """
    from bendsense.mechanics.actuator import FreeBendingModel
    from bendsense.mechanics.beam import solve_beam
    from bendsense.shape.pcc import reconstruct

    s = np.asarray(truth["s_m"])
    true_pos = np.asarray(truth["positions_m"])
    length = model_config.actuator.length_m
    pressure = np.asarray(tips.pressure_pa)
    load = np.asarray(tips.extra["load_n"])
    first, config_of = combinations(pressure, load)
    p_c, load_c = pressure[first], load[first]
    force = np.stack([tips.extra["fx_n"][first], tips.extra["fy_n"][first]], axis=-1)
    free = FreeBendingModel.from_config(model_config)
    model = solve_beam(
        length,
        model_config.stiffness.ei_nm2(p_c),
        free.tip_curvature_per_m(p_c),
        force,
        model_config.weight_per_length_n_per_m,
        s_m=s,
        warn=False,
    )
    model_err = np.max(np.linalg.norm(model.positions_m - true_pos[first], axis=-1), axis=-1) / length * 100.0
    model_err = np.where(model.success, model_err, np.nan)
    shape = reconstruct(tips.signals, calibration, model_config.sensor, s)
    frame_err = np.max(np.linalg.norm(shape.positions_m - true_pos, axis=-1), axis=-1) / length * 100.0
    sensor_err = np.array([frame_err[config_of == c].mean() for c in range(first.size)])
    levels = np.unique(p_c)
    return {
        "pressure_pa": levels,
        "model_error_pct": np.array([np.nanmean(model_err[p_c == p]) if np.any(np.isfinite(model_err[p_c == p]))
                                     else np.nan for p in levels]),
        "sensor_error_pct": np.array([sensor_err[p_c == p].mean() for p in levels]),
        "config_pressure_pa": p_c,
        "config_load_n": load_c,
        "config_model_error_pct": model_err,
        "config_sensor_error_pct": sensor_err,
        "model_positions_m": model.positions_m,
        "sensor_positions_m": shape.positions_m[first],
        "truth_positions_m": true_pos[first],
        "model_failed": int(np.count_nonzero(~np.asarray(model.success))),
    }


def tip_load_errors(shape, tips, calibration, model_config: Config, objective: str = "angles") -> dict:
    """Fig. 10: tip-load estimates with the vertical constraint, errors in % of 0.3 N.

    Returns ``pressure_pa``, ``load_n``, ``error_pct`` per frame (NaN where the estimate
    failed), ``all_pct`` and ``low_pct`` (mean, std over all frames and over loads of
    0–0.2 N), ``z`` (the error of F̂y in units of its σ), ``coverage`` (fraction of the
    frames with |z| ≤ 2), ``failed`` and the :class:`~bendsense.estimation.ForceEstimate`.

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes of the tip-load frames.
    tips : Session
        The tip-load session, with truth columns ``fy_n`` and ``load_n`` [N].
    calibration : Calibration
        The sensor calibration (its noise model gives σ).
    model_config : Config
        The identified model of the actuator.
    objective : str, default "angles"
        Force estimate objective, ``"angles"`` or ``"positions"``.
    """
    from bendsense.estimation import estimate_force

    est = estimate_force(shape, tips.pressure_pa, model_config, constraint="vertical", calibration=calibration,
                         objective=objective)
    load = np.asarray(tips.extra["load_n"])
    diff = est.force_n[:, 1] - np.asarray(tips.extra["fy_n"])
    err = np.abs(diff) / MAX_TIP_LOAD_N * 100.0
    z = diff / est.std_n[:, 1]
    return {
        "pressure_pa": np.asarray(tips.pressure_pa),
        "load_n": load,
        "error_pct": err,
        "all_pct": mean_std(err),
        "low_pct": mean_std(err[load <= 0.2 + 1e-9]),
        "z": z,
        "coverage": coverage(z),
        "failed": int(np.count_nonzero(~np.asarray(est.success))),
        "estimate": est,
    }


def contact_errors(shape, contact, calibration, model_config: Config, objective: str = "angles") -> dict:
    """Table II: contact-force errors with and without the normal constraint (eq. 21).

    Errors ``|F̂x − Fx|``, ``|F̂y − Fy|`` and ``| ‖F̂‖ − f_c |`` in % of
    :data:`MAX_CONTACT_N`, averaged per range of the true ``f_c`` and over all frames.
    Returns, per mode label of :data:`CONTACT_MODES`: ``fx``, ``fy``, ``fc`` (5 values:
    the four ranges of :data:`FORCE_RANGES_N`, then the full range), ``coverage`` (the
    fraction of the components F̂x, F̂y within ±2σ, likewise), ``z`` (frames, 2), ``counts``
    (frames per range), ``failed`` and ``seconds_per_frame``; and ``tip_angle_offset_deg``: mean
    and max of |φ_free(P) − φ_L|, how far the free-motion tip angle of the model (which
    sets the paper's constraint direction) is from the true loaded tip angle [deg].

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes of the contact frames.
    contact : Session
        The contact session, with the true contact force in its extra columns [N].
    calibration : Calibration
        The sensor calibration (its noise model gives σ).
    model_config : Config
        The identified model of the actuator.
    objective : str, default "angles"
        Force estimate objective, ``"angles"`` or ``"positions"``.
    """
    from bendsense.estimation import estimate_force
    from bendsense.mechanics.actuator import FreeBendingModel

    true_f = np.stack([contact.extra["fx_n"], contact.extra["fy_n"]], axis=-1)
    fc = np.asarray(contact.extra["fc_n"])
    bins = [(fc >= lo) & (fc < hi if i < len(FORCE_RANGES_N) - 1 else fc <= hi)
            for i, (lo, hi) in enumerate(FORCE_RANGES_N)]
    out = {}
    for label, constraint, opts in CONTACT_MODES:
        est = estimate_force(shape, contact.pressure_pa, model_config, constraint=constraint,
                             calibration=calibration, objective=objective, **opts)
        # a component the constraint fixes exactly (σ = 0 and no error) is not a claim to test
        z = np.where(est.std_n > 0, (est.force_n - true_f) / np.where(est.std_n > 0, est.std_n, 1.0), np.nan)
        errors = {
            "fx": np.abs(est.force_n[:, 0] - true_f[:, 0]),
            "fy": np.abs(est.force_n[:, 1] - true_f[:, 1]),
            "fc": np.abs(np.linalg.norm(est.force_n, axis=-1) - fc),
        }
        row = {"counts": [int(np.count_nonzero(b)) for b in bins]}
        for key, e in errors.items():
            e = e / MAX_CONTACT_N * 100.0
            row[key] = [mean_std(e[b])[0] for b in bins] + [mean_std(e)[0]]
        row["coverage"] = [coverage(z[b]) for b in bins] + [coverage(z)]
        row["z"] = z
        row["failed"] = int(np.count_nonzero(~np.asarray(est.success)))
        row["seconds_per_frame"] = est.wall_time_s / len(fc)
        out[label] = row
    free_tip = FreeBendingModel.from_config(model_config).tip_angle_rad(np.asarray(contact.pressure_pa))
    offset = np.degrees(np.abs(free_tip - np.asarray(contact.extra["tip_angle_rad"])))
    out["tip_angle_offset_deg"] = (float(offset.mean()), float(offset.max()))
    return out
