"""The ``reproduce`` command: the paper's evaluation on simulated data, as a report."""

from __future__ import annotations

import click

from bendsense import output
from bendsense.cli._common import SEED, Directory, InterspersedCommand, overwrite_option, quiet, say, step_io


@click.command("reproduce", cls=InterspersedCommand)
@click.option(
    "-o",
    "--output",
    "out_dir",
    metavar="REPORT_DIR",
    required=True,
    type=Directory(),
    help="Report directory: report.md and PNG figures (created).",
)
@click.option("--seed", type=SEED, default=0, show_default=True,
              help="Seed of the simulated sensor, noise and loads.")
@click.option("--quick", is_flag=True, help="Fewer frames and configurations (every table and figure; for tests).")
@overwrite_option
def reproduce(out_dir, seed, quick, overwrite):
    """Run the paper's evaluation (section V) on simulated experiments.

    Simulates calibration and validation strips, free bending, tip loads and contact
    forces on an actuator whose parameters the estimator does not know (with unmodelled
    base rotation and sensor noise), then calibrates (n = 1, 2, 3), reconstructs,
    identifies the model, estimates forces, and writes REPORT_DIR/report.md with the
    analogues of Table I, Fig. 8, Fig. 9, Fig. 10 and Table II beside the paper's numbers,
    and the time of each stage.
    """

    def step(state):
        from bendsense.apps.evaluation import reproduce as run

        command = f"bendsense reproduce -o {out_dir.as_posix()} --seed {seed}" + (" --quick" if quick else "")
        result = run(
            out_dir,
            seed=seed,
            quick=quick,
            overwrite=overwrite,
            progress=None if quiet() else (lambda text: click.echo(text, err=True)),
            command=command,
        )
        t1 = result.table_i[3]
        tip = result.tip_load
        errors = "; ".join(f"{objective} {t['all_pct'][0]:.1f} % +- {t['all_pct'][1]:.1f} % (2-sigma covers "
                           f"{100 * t['coverage']:.0f} %)" for objective, t in tip.items())
        say(
            f"n = 3: dkappa {t1['dkappa_all_pct'][0]:.2f} %, (dp)max {t1['dp_max_all_pct'][0]:.2f} %; "
            f"tip-load error of 0.3 N: {errors}"
        )
        say(f"wrote {result.report_path} and {len(result.figures)} figures in {result.wall_time_s:.1f} s")
        return state

    return step_io(step, outputs=[output.directory(out_dir, overwrite=overwrite)])


COMMANDS = [reproduce]
