"""The report of the evaluation, ``report.md``: every table beside the published numbers, and the figures."""

from __future__ import annotations

import math
import os

import numpy as np

from bendsense.apps.evaluation.metrics import coverage, pooled_z
from bendsense.apps.evaluation.protocol import (
    CAMERA_ANGLE_STD_RAD,
    CAMERA_MARKERS,
    CAMERA_POINT_STD_M,
    CONTACT_MODES,
    FORCE_RANGES_N,
    MAX_CONTACT_N,
    MISMATCH,
    OBJECTIVE_NAMES,
    SIGMA_LEVELS,
)
from bendsense.apps.evaluation.published import PAPER

__all__ = ["report"]


def _f(value, digits=2) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def _pct(fraction) -> str:
    """A fraction as a percentage with one decimal, "–" if unknown."""
    return "–" if fraction is None or not np.isfinite(fraction) else f"{100 * fraction:.1f} %"


def _pm(pair, digits=2) -> str:
    return f"{_f(pair[0], digits)} ± {_f(pair[1], digits)}"


def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)



def report(res, names: dict, command: str) -> str:
    """The text of ``report.md`` for ``res`` (:class:`~.run.ReproduceResult`), the figures' files by ``names``.

    One section after the other, each written by its own function: the introduction,
    Table I with Fig. 8, the identification, Fig. 9, Fig. 10, Table II, the calibration of
    the uncertainty and the timing.

    Parameters
    ----------
    res : ReproduceResult
        The numbers of the run.
    names : dict
        File name of each figure, by figure key.
    command : str
        The command line that made the report, quoted in it.
    """
    sections = (
        _introduction(res, command),
        _table_i(res, names),
        _identification(res, names),
        _fig9(res, names),
        _fig10(res, names),
        _table_ii(res),
        _uncertainty(res, names),
        _model_error(res, names),
        _timing(res),
    )
    return "\n".join(line for section in sections for line in section)


def _introduction(res, command: str) -> list:
    """The title, the command and how the experiments were simulated."""
    from bendsense import __version__

    return [
        "# The paper's evaluation on simulated data",
        "",
        f"Written by `{command}` (bendsense {__version__}, seed {res.seed}"
        f"{', quick' if res.quick else ''}) in {res.wall_time_s:.1f} s on a machine with {os.cpu_count()} CPUs. "
        "Every number below comes from simulated experiments (`bendsense.sim`), beside the numbers the paper "
        "published for its prototype. How the experiments are simulated and scored is in the docstring of "
        "`bendsense.apps.evaluation`; in short:",
        "",
        "- **Unknown material.** The simulated actuator has other free-bending and stiffness parameters than the "
        "nominal config the evaluation starts from (the paper's prototype with its placeholders); the estimator "
        "only uses what it identifies from simulated measurements (section *Identification*).",
        f"- **Unmodelled physics.** The base turns toward the bending by {MISMATCH['base_rotation_rad_per_rad']:g} "
        "rad per rad of free bending angle (the cross-section deformation the paper blames for its 0.3 N errors); "
        "neither the PCC reconstruction nor the beam model knows it.",
        f"- **Sensor.** Coil physics (nonlinear signal vs shift, fitted by polynomials of degree n), per-channel "
        f"offsets, {MISMATCH['noise_counts']:g} counts of Gaussian noise, a 12-bit ADC.",
        f"- **Camera.** Free-bending angles with {math.degrees(CAMERA_ANGLE_STD_RAD):g}° noise; loaded shapes as "
        f"{CAMERA_MARKERS} markers with {CAMERA_POINT_STD_M * 1e3:g} mm noise per coordinate (stiffness fit only).",
    ]


def _table_i(res, names: dict) -> list:
    """Table I (paper V-B) beside the paper's values, and Fig. 8."""
    paper_i = PAPER["table_i"]
    t1 = res.table_i
    radii = t1["radius_m"]
    lines = [
        "",
        "## Table I: shape reconstruction on the validation strips (paper section V-B)",
        "",
        "κ_recon is the curvature of the arc closest to the reconstructed shape (paper eq. 19), the mean over "
        "the frames of a strip; δκ = |κ_recon − κ_val| / κ_val; (δp)_max is the largest distance between the "
        "reconstructed and the actual strip relative to the sensor length (eq. 20), the mean over the frames. "
        "*All*: mean ± sample standard deviation over the strips. Paper values in parentheses.",
        "",
    ]
    header = ["n", "quantity"] + [f"{r * 1e3:.2f} mm" for r in radii] + ["All"]
    rows = [["", "κ_val [1/m]"] + [f"{k:.2f}" for k in t1["kappa_val_per_m"]] + [""]]
    for n in (1, 2, 3):
        ours, paper = t1[n], paper_i[n]
        rows.append([f"{n}", "κ_recon [1/m]"] + [f"{a:.2f} ({b:.2f})" for a, b in
                                                 zip(ours["kappa_recon_per_m"], paper["kappa_recon_per_m"])] + ["–"])
        rows.append(["", "δκ [%]"] + [f"{a:.2f} ({b:.2f})" for a, b in zip(ours["dkappa_pct"], paper["dkappa_pct"])]
                    + [f"{_pm(ours['dkappa_all_pct'])} ({_pm(paper['dkappa_all_pct'])})"])
        rows.append(["", "(δp)_max [%]"]
                    + [f"{a:.2f} ({b:.2f})" for a, b in zip(ours["dp_max_pct"], paper["dp_max_pct"])]
                    + [f"{_pm(ours['dp_max_all_pct'])} ({_pm(paper['dp_max_all_pct'])})"])
    lines += [_table(header, rows), ""]
    lines += [
        "## Fig. 8: reconstructed vs actual validation shapes (n = 3)",
        "",
        f"![Fig. 8 analogue]({names['fig8']})",
        "",
    ]
    return lines


def _identification(res, names: dict) -> list:
    """The identified parameters (paper V-C) against the true and the nominal ones."""
    ident = res.identification
    lines = [
        "## Identification (paper section V-C)",
        "",
        "μ̄, μ_s and the prebend from the free-bending angles (actuator on its side, 0–120 kPa); EI per pressure "
        "level from two randomly chosen loaded combinations per pressure (camera markers), then γ0, γ1 by linear "
        "regression (paper eq. 15), with `bendsense.identify`. Standard errors from the fits. The camera also "
        "sees the unmodelled base rotation, which the identified parameters absorb in part; at small angles μ̄ "
        f"and μ_s act alike (fitted correlation {_f(ident['correlation_mu_mus'], 3)}).",
        "",
    ]
    rows = []
    for key, label in (
        ("shear_modulus_pa", "μ̄ [MPa]"),
        ("sensor_stiffness_nm_per_rad", "μ_s [10⁻³ N·m/rad]"),
        ("prebend_angle_rad", "prebend [deg]"),
        ("ei0_nm2", "γ0 = ei0 [10⁻³ N·m²]"),
        ("ei1_nm2_per_pa", "γ1 = ei1 [10⁻⁵ N·m²/kPa]"),
    ):
        scale = {"shear_modulus_pa": 1e-6, "sensor_stiffness_nm_per_rad": 1e3, "prebend_angle_rad": 180 / math.pi,
                 "ei0_nm2": 1e3, "ei1_nm2_per_pa": 1e8}[key]
        true, nom, got = ident["true"][key], ident["nominal"][key], ident["identified"][key]
        se = ident["stderr"].get(key, math.nan)
        rel = (got - true) / true * 100 if true else math.nan
        rows.append([label, f"{true * scale:.4g}", f"{nom * scale:.4g}", f"{got * scale:.4g} ± {se * scale:.2g}",
                     _f(rel, 1)])
    lines += [_table(["parameter", "true (simulated)", "nominal (start)", "identified ± s.e.", "error [%]"], rows), ""]
    lines += [f"![identification]({names['identification']})", ""]
    return lines


def _fig9(res, names: dict) -> list:
    """Fig. 9: the static model and the sensor against the true shapes."""
    st = res.static
    lines = [
        "## Fig. 9: static model and sensor against the true shapes (paper section V-C)",
        "",
        "Max distance between the predicted and the true shape along the sensor line, relative to the actuator "
        "length L, averaged across the tip loads 0–0.3 N at each pressure. Model: beam (eq. 13–17) with the "
        "identified K0(P) and EI(P), gravity and the known load. Sensor: PCC reconstruction with n = 3. "
        f"The paper reports both below {PAPER['fig9_model_max_pct']:g} % (model) and "
        f"{PAPER['fig9_sensor_max_pct']:g} % (sensor).",
        "",
    ]
    rows = [[f"{p * 1e-3:g}", _f(m), _f(s)] for p, m, s in
            zip(st["pressure_pa"], st["model_error_pct"], st["sensor_error_pct"])]
    rows.append(["max", _f(np.nanmax(st["model_error_pct"])), _f(np.nanmax(st["sensor_error_pct"]))])
    lines += [_table(["pressure [kPa]", "model [% of L]", "sensor [% of L]"], rows), ""]
    if st["model_failed"]:
        lines += [f"The beam model found no stable equilibrium for {st['model_failed']} combination(s).", ""]
    lines += [f"![Fig. 9 analogue]({names['fig9']})", ""]
    return lines


def _fig10(res, names: dict) -> list:
    """Fig. 10: tip-load estimation with the vertical constraint, for both objectives."""
    tips = res.tip_load
    objectives = list(tips)
    lines = [
        "## Fig. 10: tip-load estimation (paper section V-D1)",
        "",
        "The vertical constraint Fx = 0; error |F̂y − Fy| in % of the largest load, 0.3 N, over every frame, for "
        "both objectives: the coil angles S/d the sensor measures (the default) and the PCC positions of paper "
        "eq. 18. Coverage: the fraction of the frames whose true Fy lies within ±2σ of the estimate.",
        "",
        _table(
            ["loads"] + [f"{OBJECTIVE_NAMES[o]}: mean ± std [%]" for o in objectives] + ["paper [%]"]
            + [f"±2σ coverage, {o}" for o in objectives],
            [
                ["0–0.3 N"] + [_pm(tips[o]["all_pct"]) for o in objectives] + [_pm(PAPER["fig10_all_pct"])]
                + [_pct(tips[o]["coverage"]) for o in objectives],
                ["0–0.2 N"] + [_pm(tips[o]["low_pct"]) for o in objectives] + [_pm(PAPER["fig10_0_to_0p2_pct"])]
                + [_pct(coverage(tips[o]["z"][tips[o]["load_n"] <= 0.2 + 1e-9])) for o in objectives],
            ],
        ),
        "",
    ]
    failed = {o: tips[o]["failed"] for o in objectives if tips[o]["failed"]}
    lines += _failed_note(failed)
    lines += [f"![Fig. 10 analogue]({names['fig10']})", ""]
    return lines


def _table_ii(res) -> list:
    """Table II: contact forces without and with the normal constraint, beside the paper's."""
    objectives = list(res.tip_load)
    lines = [
        "## Table II: contact force estimation (paper section V-D2)",
        "",
        f"Mean errors in % of the largest contact force ({MAX_CONTACT_N:g} N) per range of the true contact force; "
        f"{res.extra['contact_configs']} random configurations × {res.extra['contact_frames']} frames. F̂c is the "
        "magnitude of the estimated force. The paper's constrained mode takes the tip angle from the free-bending "
        "model; the last mode takes it from the reconstructed shape. Coverage: the fraction of the components "
        "F̂x, F̂y (those the constraint leaves free) whose truth lies within ±2σ.",
        "",
    ]
    labels = [label for label, _, _ in CONTACT_MODES]
    shorts = ("none", "normal (model)", "normal (shape)")
    header = (["force range [N]", "frames"] + [f"{short} {c}" for short in shorts for c in ("F̂x", "F̂y", "F̂c")]
              + [f"{short} ±2σ" for short in shorts])
    ranges = [f"{lo:g}–{hi:g}" for lo, hi in FORCE_RANGES_N] + ["mean of full range"]
    for objective in objectives:
        contact = res.contact[objective]
        counts = contact[labels[0]]["counts"]
        rows = []
        for i, name in enumerate(ranges):
            row = [name, str(counts[i]) if i < len(counts) else str(sum(counts))]
            for label in labels:
                row += [_f(contact[label][c][i]) for c in ("fx", "fy", "fc")]
            row += [_pct(contact[label]["coverage"][i]) for label in labels]
            rows.append(row)
        lines += [f"Here, {OBJECTIVE_NAMES[objective]}:", "", _table(header, rows), ""]
    p2 = PAPER["table_ii"]
    rows = [[name] + [f"{p2[m][c][i]:.2f}" for m in ("none", "normal") for c in ("fx", "fy", "fc")]
            for i, name in enumerate(ranges)]
    lines += ["Paper (12 configurations):", "",
              _table(["force range [N]"] + [f"{m} {c}" for m in ("none", "normal") for c in ("F̂x", "F̂y", "F̂c")], rows),
              ""]
    first = res.contact[objectives[0]]
    mean, worst = first["tip_angle_offset_deg"]
    lines += [
        "The paper's constraint direction is normal to the free-motion tip angle of the model; a contact force "
        f"turns the tip away from it (here by {mean:.1f}° on average, up to {worst:.1f}°, including the model's "
        "error in free bending), so the constrained estimate is forced along a wrong direction, more so the "
        "larger the force. With the tip angle from the reconstructed shape the mean F̂c error "
        f"({OBJECTIVE_NAMES[objectives[0]]}) is {_f(first[labels[2]]['fc'][-1])} % instead of "
        f"{_f(first[labels[1]]['fc'][-1])} % (unconstrained: {_f(first[labels[0]]['fc'][-1])} %).",
        "",
    ]
    failed = {f"{o}, {label}": res.contact[o][label]["failed"] for o in objectives for label in labels
              if res.contact[o][label]["failed"]}
    lines += _failed_note(failed)
    return lines


def _uncertainty(res, names: dict) -> list:
    """The calibration of the uncertainty: observed against nominal coverage at 1σ, 2σ, 3σ."""
    tips = res.tip_load
    objectives = list(tips)
    zs = {o: pooled_z(tips[o], res.contact[o]) for o in objectives}
    return [
        "## Calibration of the uncertainty",
        "",
        "How often the truth lies within ±kσ of the estimate, against the Gaussian's nominal probability, over "
        "every tested force component (the tip loads' F̂y and the contact modes' F̂x, F̂y; "
        f"{', '.join(f'{o}: {np.count_nonzero(np.isfinite(zs[o]))}' for o in objectives)} components). The σ "
        "is the estimator's complete budget: sensor noise, calibration error and the identified parameters' "
        "covariance (docs/theory.md). " + _miss_note(res.identification),
        "",
        _table(["level", "nominal"] + [f"observed, {OBJECTIVE_NAMES[o]}" for o in objectives],
               [[f"±{k:g}σ", _pct(math.erf(k / math.sqrt(2.0)))]
                + [_pct(coverage(zs[o], k)) for o in objectives] for k in SIGMA_LEVELS]),
        "",
        f"![calibration of the uncertainty]({names['coverage']})",
        "",
    ]


def _model_error(res, names: dict) -> list:
    """Model error: the window check and the parameter prior on the simulated board's mismatches."""
    rows = res.model_error
    if not rows:
        return []
    return [
        "## Model error",
        "",
        "The simulated board records a 2 kHz ramp-and-hold series (3 holds of 200 ms, 50 ms ramps, 1.5 counts) "
        "while the true actuator departs from the config. The simulator is bendsense's own model run forwards, "
        "so this checks the checks against bendsense's physics; the same table on an independent forward model "
        "is `python tools/model_error.py` (docs/model-error.md). *Undeclared*: the config without its parameter "
        "covariance; *prior*: the shipped config with its prior, then window-checked and tracked (RTS smoother).",
        "",
        _table(["truth departs from the model by", "hold windows flagged (undeclared)",
                "±2σ coverage Fx/Fy, per frame (undeclared)", "±2σ coverage Fx/Fy, tracked (prior)",
                "tracked frames flagged (prior)"],
               [[r["label"], f"{_pct(r['windows'][0])} of {r['windows'][1]}",
                 f"{_pct(r['coverage_frame'][0])} / {_pct(r['coverage_frame'][1])}",
                 f"{_pct(r['coverage_track'][0])} / {_pct(r['coverage_track'][1])}", _pct(r["flagged_track"])]
                for r in rows.values()]),
        "",
        "EI alone scales a load's shape much like the load itself (only gravity tells them apart): a check of "
        "the shape hardly sees it, and a declared covariance (the prior) is what covers it. Whether a window sees "
        "K0 +5 % depends on the sensor's resolution in angle: the simulated board's sensor spans fewer counts "
        "over the same bending than the independent model's (docs/model-error.md).",
        "",
        f"![per-frame and tracked force under K0 +5 %]({names['model_error']})",
        "",
    ]


def _timing(res) -> list:
    """The time of each stage, beside the paper's."""
    tm = res.timings
    lines = [
        "## Timing",
        "",
        f"Measured in this run on a machine with {os.cpu_count()} CPUs (shared; load average "
        f"{res.extra['load_average']}). The paper's numbers are from MATLAB on an Intel i7-11800H laptop.",
        "",
        _table(
            ["stage", "here", "paper"],
            [
                ["calibration fit, n = 3 (10 strips + flat, incl. reading the CSVs)",
                 _duration(tm['calibration_s']), "–"],
                ["shape reconstruction, one frame", f"{_duration(tm['reconstruction_single_s'])} "
                 f"({1 / tm['reconstruction_single_s']:,.0f} Hz)",
                 f"≥ {PAPER['reconstruction_hz']:g} Hz (hardware bound)"],
                ["shape reconstruction, batched, per frame",
                 f"{_duration(tm['reconstruction_batched_s_per_frame'])} "
                 f"({1 / tm['reconstruction_batched_s_per_frame']:,.0f} frames/s)", "–"],
                ["identification (free bending + stiffness)", _duration(tm['identification_s']), "–"],
                ["force estimate, unconstrained, fast, one frame", _duration(tm['force_fast_none_single_s']),
                 f"{PAPER['force_none_s']:g} s"],
                ["force estimate, unconstrained, fast, batched per frame",
                 _duration(tm['force_fast_none_batched_s_per_frame']), "–"],
                ["force estimate, normal constraint, fast, one frame",
                 _duration(tm['force_fast_normal_single_s']),
                 f"{PAPER['force_constrained_s']:g} s"],
                ["force estimate, normal constraint, fast, batched per frame",
                 _duration(tm['force_fast_normal_batched_s_per_frame']), "–"],
                _paper_row(tm, "none", "unconstrained, paper's method (shooting + Nelder–Mead)",
                           PAPER["force_none_s"]),
                _paper_row(tm, "normal", "normal constraint, paper's method (shooting + SLSQP)",
                           PAPER["force_constrained_s"]),
                ["whole evaluation (simulation, all stages, figures)", _duration(res.wall_time_s), "–"],
            ],
        ),
        "",
    ]
    if tm["force_paper_none_frames"] or tm["force_paper_normal_frames"]:
        diff = np.nanmax([tm["force_paper_none_max_diff_n"], tm["force_paper_normal_max_diff_n"]])
        ratio = [tm[f"force_paper_{k}_s"] / tm[f"force_fast_{k}_single_s"] for k in ("none", "normal")
                 if tm[f"force_paper_{k}_frames"]]
        lines += [
            f"On the frames timed with both, the fast method and the paper's agree to {diff:.1e} N; the fast one "
            f"is {min(ratio):,.0f}–{max(ratio):,.0f} times faster per frame. The paper's method here runs "
            "the shooting reference solver of `bendsense.mechanics.beam` in every objective evaluation, and its time "
            "per frame varies a lot between frames.",
            "",
        ]
    return lines


def _failed_note(failed: dict) -> list:
    """A note on the frames left out of a table (``failed``: case → frames), if any."""
    if not failed:
        return []
    return ["Frames without a converged estimate (left out): "
            + ", ".join(f"{case}: {n}" for case, n in failed.items()) + ".", ""]


def _miss_note(ident) -> str:
    """Why the coverage may fall short: how far the identified parameters are from the truth, in their s.e."""
    z = {key: (ident["identified"][key] - ident["true"][key]) / se
         for key, se in ident["stderr"].items() if key in ident["true"] and se and np.isfinite(se) and se > 0}
    if not z:
        return ""
    key = max(z, key=lambda k: abs(z[k]))
    return (f"The budget covers what it is told: here the simulated rig has effects the model lacks (the base "
            f"rotation), which the identification absorbs into biased parameters; the worst, {key}, lies "
            f"{abs(z[key]):.1f} standard errors from the truth. Coverage well below nominal means such a "
            "model-form error, which no parameter covariance describes.")


def _duration(seconds) -> str:
    """A time in s, ms or µs with three significant digits (a fast stage is never printed as 0)."""
    for unit, scale in (("s", 1.0), ("ms", 1e3), ("µs", 1e6)):
        if seconds * scale >= 1.0 or unit == "µs":
            value = seconds * scale
            return f"{value:.3g} {unit}" if value < 1000.0 else f"{value:,.0f} {unit}"


def _paper_row(tm, key, what, paper_s):
    frames = tm[f"force_paper_{key}_frames"]
    if not frames:
        return [f"force estimate, {what}", "not timed (--quick)", f"{paper_s:g} s"]
    return [f"force estimate, {what}, mean of {frames} frame(s)", _duration(tm[f'force_paper_{key}_s']),
            f"{paper_s:g} s"]
