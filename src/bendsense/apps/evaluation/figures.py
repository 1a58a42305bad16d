"""The figures of the evaluation report: analogues of the paper's Fig. 8, 9 and 10, identification and coverage.

Each function draws one figure from the numbers of a stage (:mod:`.metrics`,
:mod:`.protocol`) with :mod:`bendsense.plots` and writes it as a PNG.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from bendsense.apps.evaluation.metrics import coverage
from bendsense.apps.evaluation.protocol import CAMERA_MARKERS, FIG9B_PRESSURE_PA, OBJECTIVE_NAMES, SIGMA_LEVELS
from bendsense.apps.evaluation.published import PAPER

__all__ = ["fig8_validation_shapes", "fig9_static_model", "fig10_tip_load_error", "fig_coverage",
           "fig_identification"]

_DPI = 100


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=_DPI)
    return path


def fig8_validation_shapes(path, table, radii, kappa_val, s_m) -> Path:
    """Fig. 8: the validation strips reconstructed with n = 3 against the actual arcs (camera markers).

    Parameters
    ----------
    path : path
        Figure file to write.
    table : dict
        Table I: per degree, the reconstructed validation shapes under ``"shapes"`` [m].
    radii : array_like
        Validation radii, for the labels [m].
    kappa_val : array_like
        Actual curvature of each validation strip [1/m].
    s_m : ndarray
        Arc lengths of the shapes [m].
    """
    from bendsense.plots import plot_shape_comparison
    from bendsense.shape.pcc import arc_positions

    fig = _figure(figsize=(7.6, 5.4))
    ax = fig.add_subplot()
    # the actual strips at marker spacing: dots on every point would hide the lines
    plot_shape_comparison(
        table[3]["shapes"],
        arc_positions(np.asarray(kappa_val), np.linspace(0.0, s_m[-1], CAMERA_MARKERS + 1)),
        ax,
        labels=[f"R = {r * 1e3:.2f} mm" for r in radii],
        names=("reconstructed (n = 3)", "model", "actual strip"),
    )
    legend = ax.get_legend()
    ax.legend(handles=legend.legend_handles, fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0))
    ax.set_title("Validation strips: reconstructed (n = 3) vs actual shapes", fontsize="medium")
    return _save(fig, path)


def fig9_static_model(path, static) -> Path:
    """Fig. 9: (a) max position error of the model and the sensor per pressure, (b) the shapes at 40 kPa.

    Parameters
    ----------
    path : path
        Figure file to write.
    static : dict
        The result of :func:`~bendsense.apps.evaluation.metrics.static_model_errors`.
    """
    from bendsense.plots import plot_shape_comparison

    fig = _figure(figsize=(11.0, 5.0))
    ax_a, ax_b = fig.subplots(1, 2, width_ratios=(1.2, 1.0))
    p = static["pressure_pa"] * 1e-3
    ax_a.plot(p, static["model_error_pct"], "o-", label="static model (identified)")
    ax_a.plot(p, static["sensor_error_pct"], "s-", label="sensor reconstruction (n = 3)")
    ax_a.axhline(PAPER["fig9_model_max_pct"], color="C0", linestyle=":", linewidth=1,
                 label=f"paper: model below {PAPER['fig9_model_max_pct']:g} %")
    ax_a.axhline(PAPER["fig9_sensor_max_pct"], color="C1", linestyle="--", linewidth=1,
                 label=f"paper: sensor below {PAPER['fig9_sensor_max_pct']:g} %")
    ax_a.set_xlabel("pressure [kPa]")
    ax_a.set_ylabel("max position error [% of L], mean over tip loads")
    ax_a.set_ylim(bottom=0)
    ax_a.grid(True, alpha=0.3)
    ax_a.legend(fontsize="small")
    ax_a.set_title("(a) max position error vs pressure", fontsize="medium")
    pick = np.flatnonzero(np.isclose(static["config_pressure_pa"], FIG9B_PRESSURE_PA))
    if pick.size == 0:  # a plan without 40 kPa: the lowest pressure above it
        level = static["pressure_pa"][np.argmin(np.abs(static["pressure_pa"] - FIG9B_PRESSURE_PA))]
        pick = np.flatnonzero(static["config_pressure_pa"] == level)
    pick = pick[np.argsort(static["config_load_n"][pick])]
    level_kpa = static["config_pressure_pa"][pick[0]] * 1e-3
    truth = static["truth_positions_m"][pick]
    markers = np.linspace(0, truth.shape[1] - 1, CAMERA_MARKERS + 1).round().astype(int)
    plot_shape_comparison(
        static["sensor_positions_m"][pick],
        truth[:, markers],
        ax_b,
        model=static["model_positions_m"][pick],
        labels=[f"{f:.1f} N" for f in static["config_load_n"][pick]],
        names=("sensor", "model", "truth"),
    )
    ax_b.set_title(f"(b) shapes at {level_kpa:g} kPa, tip loads 0–0.3 N", fontsize="medium")
    return _save(fig, path)


def fig10_tip_load_error(path, tips) -> Path:
    """Fig. 10: the tip-load error over pressure and load, one panel per objective.

    Parameters
    ----------
    path : path
        Figure file to write.
    tips : dict
        Per objective, the result of :func:`~bendsense.apps.evaluation.metrics.tip_load_errors`.
    """
    from bendsense.plots import plot_force_error_map

    fig = _figure(figsize=(8.0, 7.0))
    axes = fig.subplots(len(tips), 1, sharex=True, sharey=True)
    for ax, (objective, tip) in zip(axes, tips.items(), strict=True):
        plot_force_error_map(tip["pressure_pa"], tip["load_n"], tip["error_pct"], ax,
                             error_label="|F̂y − Fy| [% of 0.3 N]")
        mean, std = tip["all_pct"]
        ax.set_title(f"{OBJECTIVE_NAMES[objective]}: {mean:.2f} % ± {std:.2f} %, ±2σ covers "
                     f"{tip['coverage']:.0%} of the frames", fontsize="medium")
        ax.label_outer()
    pm, ps = PAPER["fig10_all_pct"]
    fig.suptitle(f"Tip-load estimation error, vertical constraint (paper {pm:g} % ± {ps:g} %)")
    return _save(fig, path)


def fig_coverage(path, zs) -> Path:
    """Nominal against observed coverage of |z| ≤ k (k from 0 to 3.5), one curve per objective.

    Parameters
    ----------
    path : path
        Figure file to write.
    zs : dict
        Per objective, the pooled errors in units of σ (:func:`~bendsense.apps.evaluation.metrics.pooled_z`).
    """
    fig = _figure(figsize=(5.6, 5.0))
    ax = fig.add_subplot()
    k = np.linspace(0.0, 3.5, 141)
    nominal = np.array([math.erf(v / math.sqrt(2.0)) for v in k])
    ax.plot([0, 1], [0, 1], "k--", lw=1, label="calibrated (Gaussian)")
    for i, (objective, z) in enumerate(zs.items()):
        ax.plot(nominal, [coverage(z, v) for v in k], color=f"C{i}", label=OBJECTIVE_NAMES[objective])
        marks = [math.erf(v / math.sqrt(2.0)) for v in SIGMA_LEVELS]
        ax.plot(marks, [coverage(z, v) for v in SIGMA_LEVELS], "o", color=f"C{i}")
    for v in SIGMA_LEVELS:
        nom = math.erf(v / math.sqrt(2.0))
        ax.annotate(f"{v:g}σ", (nom, nom), textcoords="offset points", xytext=(6, -12), fontsize="small")
    ax.set_xlabel("nominal coverage of ±kσ")
    ax.set_ylabel("observed coverage (tip loads and contact, F̂x and F̂y)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title("Calibration of the force uncertainty", fontsize="medium")
    return _save(fig, path)



def fig_identification(path, ident, nominal, true, identified) -> Path:
    """Identification: (a) free bending angle and (b) EI per pressure, identified against true and nominal.

    Parameters
    ----------
    path : path
        Figure file to write.
    ident : dict
        The identification's data (:func:`~bendsense.apps.evaluation.protocol.identify_parameters`).
    nominal, true, identified : Config
        The nominal, the simulated (true) and the identified actuator models.
    """
    from bendsense.mechanics.actuator import FreeBendingModel

    fig = _figure(figsize=(11.0, 4.4))
    ax_a, ax_b = fig.subplots(1, 2)
    p = np.linspace(0.0, 125e3, 126)
    models = (("identified", identified, "-"), ("true", true, "--"), ("nominal", nominal, ":"))
    ax_a.plot(ident["free_pressure_pa"] * 1e-3, np.degrees(ident["free_angle_rad"]), "k.", markersize=5,
              label="measured (camera)")
    for name, config, style in models:
        ax_a.plot(p * 1e-3, np.degrees(FreeBendingModel.from_config(config).bending_angle_rad(p)), style,
                  label=f"{name} model")
    ax_a.set_xlabel("pressure [kPa]")
    ax_a.set_ylabel("free bending angle θ [deg]")
    ax_a.grid(True, alpha=0.3)
    ax_a.legend(fontsize="small")
    ax_a.set_title("(a) free bending (paper eq. 8–12)", fontsize="medium")
    ax_b.errorbar(ident["ei_pressure_pa"] * 1e-3, ident["ei_nm2"] * 1e3, yerr=ident["ei_stderr_nm2"] * 1e3,
                  fmt="k.", capsize=2, label="EI per pressure level")
    for name, config, style in models:
        ax_b.plot(p * 1e-3, config.stiffness.ei_nm2(p) * 1e3, style, label=f"{name} γ0 + γ1 P")
    ax_b.set_xlabel("pressure [kPa]")
    ax_b.set_ylabel("flexural rigidity EI [10⁻³ N·m²]")
    ax_b.grid(True, alpha=0.3)
    ax_b.legend(fontsize="small")
    ax_b.set_title("(b) stiffness (paper eq. 15)", fontsize="medium")
    return _save(fig, path)
