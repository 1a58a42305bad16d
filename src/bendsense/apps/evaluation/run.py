"""The entry point of the evaluation: :func:`reproduce` runs every stage and writes the report.

The stages (:mod:`.protocol`) simulate the experiments, calibrate, identify and time;
the metrics (:mod:`.metrics`) score shapes and forces against the truth; the figures
(:mod:`.figures`) and the report (:mod:`.report`) present them beside the published
numbers (:mod:`.published`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bendsense import output
from bendsense.apps.evaluation.figures import (
    fig8_validation_shapes,
    fig9_static_model,
    fig10_tip_load_error,
    fig_coverage,
    fig_identification,
)
from bendsense.apps.evaluation.metrics import (
    contact_errors,
    pooled_z,
    shape_accuracy,
    static_model_errors,
    tip_load_errors,
)
from bendsense.apps.evaluation.model_error import fig_model_error, model_error_evaluation
from bendsense.apps.evaluation.protocol import (
    OBJECTIVE_NAMES,
    Plan,
    calibrate_degrees,
    identify_parameters,
    parameters,
    simulate_experiments,
    time_stages,
    timed,
    true_config,
)
from bendsense.apps.evaluation.report import report

__all__ = ["ReproduceResult", "reproduce", "FIGURE_NAMES"]

#: The figures of the report, by key.
FIGURE_NAMES = {
    "fig8": "fig8_validation_shapes.png",
    "fig9": "fig9_static_model.png",
    "fig10": "fig10_tip_load_error.png",
    "coverage": "coverage_calibration.png",
    "identification": "identification.png",
    "model_error": "model_error.png",
}


@dataclass(frozen=True, kw_only=True, eq=False)
class ReproduceResult:
    """Numbers of one :func:`reproduce` run.

    Attributes
    ----------
    table_i : dict
        Per degree n (1, 2, 3): ``kappa_recon_per_m``, ``dkappa_pct``, ``dp_max_pct``
        (arrays over the validation strips) and ``dkappa_all_pct``, ``dp_max_all_pct``
        (mean, sample std); plus ``radius_m`` and ``kappa_val_per_m``.
    static : dict
        ``pressure_pa`` (P,), ``model_error_pct`` (P,), ``sensor_error_pct`` (P,):
        max position error relative to L, averaged across loads (Fig. 9(a)).
    tip_load : dict
        Per objective (:data:`OBJECTIVE_NAMES`): :func:`tip_load_errors` (``error_pct``,
        ``all_pct``, ``low_pct``, ``z``, ``coverage``, ``failed``, ...).
    contact : dict
        Per objective: :func:`contact_errors`, per mode label ``fx``, ``fy``, ``fc`` mean
        errors [%] and ``coverage`` per force range then the full range, ``counts``, ``failed``.
    identification : dict
        ``true``, ``nominal``, ``identified``: parameter dicts (``shear_modulus_pa``,
        ``sensor_stiffness_nm_per_rad``, ``prebend_angle_rad``, ``ei0_nm2``,
        ``ei1_nm2_per_pa``); ``stderr`` of the identified ones; per-pressure EI.
    timings : dict
        Stage name → seconds (see the report).
    report_path : Path
        ``report.md``.
    figures : tuple of Path
        The PNG figures.
    wall_time_s : float
        Run time of the whole evaluation [s].
    """

    table_i: dict
    static: dict
    tip_load: dict
    contact: dict
    identification: dict
    timings: dict
    report_path: Path
    figures: tuple
    wall_time_s: float
    seed: int = 0
    quick: bool = False
    model_error: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict, repr=False)


def reproduce(
    out_dir,
    *,
    seed: int = 0,
    quick: bool = False,
    overwrite: bool = False,
    progress: Callable[[str], None] | None = None,
    command: str | None = None,
) -> ReproduceResult:
    """Run the paper's evaluation on simulated experiments and write the report.

    Parameters
    ----------
    out_dir : path
        Report directory: ``report.md`` and the PNG figures. Written to a hidden sibling
        first and swapped in at the end (:func:`bendsense.output.write_dir`).
    seed : int
        Seed of the simulated sensor, noise, random configurations and camera noise.
    quick : bool
        :meth:`Plan.quick` (for tests: fewer frames and configurations, every table and
        figure) instead of :meth:`Plan.full`.
    overwrite : bool
        Replace a previous report in ``out_dir`` (never files bendsense did not write).
    progress : callable, optional
        Called with one line of text at the start of each stage.
    command : str, optional
        The command line to quote in the report.

    Returns
    -------
    ReproduceResult

    Raises
    ------
    OutputExistsError
        If ``out_dir`` exists, is not empty and ``overwrite`` is false (a ``FileExistsError``).
    OutputError
        If ``out_dir`` holds files bendsense did not write, or may not be written over.
    """
    t_start = time.perf_counter()
    out = Path(out_dir)
    output.check([output.directory(out, overwrite=overwrite)])
    say = progress or (lambda text: None)
    plan = Plan.quick() if quick else Plan.full()
    with output.write_dir(out, overwrite=overwrite, writer="bendsense reproduce") as work:
        numbers = _evaluate(work / "data", seed, plan, say)
        shutil.rmtree(work / "data")

        say("figures and report ...")
        figures = _figures(work, numbers)
        result = ReproduceResult(
            table_i=numbers["table_i"],
            static=numbers["static"],
            tip_load=numbers["tip_load"],
            contact=numbers["contact"],
            identification=numbers["identification"],
            timings=numbers["timings"],
            model_error={k: v for k, v in numbers["model_error"].items() if k != "series"},
            report_path=out / "report.md",
            figures=tuple(out / f.name for f in figures),
            wall_time_s=math.nan,
            seed=seed,
            quick=quick,
            extra={
                "contact_configs": plan.contact_configs,
                "contact_frames": plan.contact_frames,
                "load_average": ", ".join(f"{v:.1f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "?",
            },
        )
        result = dataclasses.replace(result, wall_time_s=time.perf_counter() - t_start)
        if command is None:
            command = f"bendsense reproduce -o {out.name} --seed {seed}" + (" --quick" if quick else "")
        (work / "report.md").write_text(report(result, FIGURE_NAMES, command) + "\n", encoding="utf-8")
    return result


def _evaluate(data: Path, seed: int, plan: Plan, say) -> dict:
    """Every stage of the protocol, simulating into ``data``: the numbers of the tables and figures."""
    from bendsense.config import load_config
    from bendsense.session import read_session_csv
    from bendsense.shape.pcc import reconstruct

    nominal = load_config()
    true = true_config(nominal)
    sensor = nominal.sensor
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2000,)))
    timings = {}
    say("simulating the experiments (calibration, validation, free bending, tip loads, contact) ...")
    paths, timings["simulation_s"] = timed(simulate_experiments, data, true, seed, plan)

    say("calibration, n = 1, 2, 3 ...")
    cals, seconds = calibrate_degrees(paths["calibration"] / "manifest.yaml", sensor)
    timings["calibration_s"] = seconds[3]

    say("reconstruction of the validation strips (Table I, Fig. 8) ...")
    table_i, s_val = _table_i(paths["validation"], cals, sensor)

    say("identification: free bending, stiffness ...")
    free = read_session_csv(paths["free-bending"] / "tip_loads.csv")
    tips = read_session_csv(paths["tip-loads"] / "tip_loads.csv")
    with np.load(paths["tip-loads"] / "truth.npz") as npz:
        tip_truth = {k: npz[k] for k in npz.files}
    (model_config, ident_info), timings["identification_s"] = timed(
        identify_parameters, free, tips, tip_truth, nominal, rng
    )

    say("static model and sensor vs truth (Fig. 9) ...")
    static = static_model_errors(tips, tip_truth, cals[3], model_config)

    say("tip-load estimation (Fig. 10), both objectives ...")
    tip_shape = reconstruct(tips.signals, cals[3], sensor)
    tip = {obj: tip_load_errors(tip_shape, tips, cals[3], model_config, obj) for obj in OBJECTIVE_NAMES}

    say("contact force estimation (Table II) ...")
    contact = read_session_csv(paths["contact"] / "contact.csv")
    contact_shape = reconstruct(contact.signals, cals[3], sensor)
    table_ii = {obj: contact_errors(contact_shape, contact, cals[3], model_config, obj) for obj in OBJECTIVE_NAMES}

    say("model error (K0, EI, base rotation) over 2 kHz ramp-and-hold series ...")
    model_error, timings["model_error_s"] = timed(model_error_evaluation, cals[3], nominal, seed)

    say("timing ...")
    timings.update(time_stages(tips, contact_shape, contact, cals[3], model_config, plan, say))
    identification = {
        "true": parameters(true),
        "nominal": parameters(nominal),
        "identified": parameters(model_config),
        **ident_info,
    }
    return {"table_i": table_i, "s_val": s_val, "static": static, "tip_load": tip, "contact": table_ii,
            "identification": identification, "timings": timings, "configs": (nominal, true, model_config),
            "model_error": model_error}


def _table_i(validation: Path, cals: dict, sensor) -> tuple:
    """Table I for each calibration degree (:func:`shape_accuracy`), and the arc lengths it compares [m]."""
    import yaml

    from bendsense.session import read_session_csv

    index = yaml.safe_load((validation / "validation.yaml").read_text(encoding="utf-8"))
    strips = [(read_session_csv(validation / s["recording"]).signals, float(s["kappa_true_per_m"]))
              for s in index["strips"]]
    s_val = np.linspace(0.0, float(np.sum(sensor.lengths_m)), 133)
    table_i = {n: shape_accuracy(cals[n], strips, sensor, s_val) for n in (1, 2, 3)}
    table_i["radius_m"] = np.array([float(s["radius_m"]) for s in index["strips"]])
    table_i["kappa_val_per_m"] = np.array([k for _, k in strips])
    return table_i, s_val


def _figures(work: Path, numbers: dict) -> tuple:
    """Draw the figures of :data:`FIGURE_NAMES` into ``work``; their paths."""
    table_i, tip, table_ii = numbers["table_i"], numbers["tip_load"], numbers["contact"]
    nominal, true, model_config = numbers["configs"]
    return (
        fig8_validation_shapes(work / FIGURE_NAMES["fig8"], table_i, table_i["radius_m"], table_i["kappa_val_per_m"],
                               numbers["s_val"]),
        fig9_static_model(work / FIGURE_NAMES["fig9"], numbers["static"]),
        fig10_tip_load_error(work / FIGURE_NAMES["fig10"], tip),
        fig_coverage(work / FIGURE_NAMES["coverage"], {o: pooled_z(tip[o], table_ii[o]) for o in OBJECTIVE_NAMES}),
        fig_identification(work / FIGURE_NAMES["identification"], numbers["identification"], nominal, true,
                           model_config),
        fig_model_error(work / FIGURE_NAMES["model_error"], numbers["model_error"]["series"]),
    )
