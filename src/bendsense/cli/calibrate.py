"""The ``calibrate`` command: fit the sensor calibration from a manifest of recordings."""

from __future__ import annotations

from pathlib import Path

import click

from bendsense import output as outputs
from bendsense.choices import CALIBRATION_DEGREES, CALIBRATION_WEIGHTINGS
from bendsense.cli._common import (
    InterspersedCommand,
    check_figure_suffix,
    make_config_option,
    make_overwrite_option,
    save_figure,
    say,
    step_io,
)

_DEGREES = f"{CALIBRATION_DEGREES[0]}..{CALIBRATION_DEGREES[-1]}"


def _degree(ctx, param, value):
    if value is None:
        return 3
    text = str(value).strip().lower()
    if text == "auto":
        return "auto"
    if text.isdigit() and int(text) in CALIBRATION_DEGREES:
        return int(text)
    raise click.BadParameter(f"expected {_DEGREES} or 'auto', got {value!r}", ctx=ctx, param=param)


@click.command("calibrate", cls=InterspersedCommand)
@click.argument("manifest", metavar="MANIFEST.yaml", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Calibration YAML to write.",
)
@make_config_option("Config YAML with the sensor (default: the paper's prototype, built in).")
@click.option(
    "--degree",
    default="3",
    show_default=True,
    callback=_degree,
    metavar=f"{_DEGREES}|auto",
    help="Polynomial degree n of f_odd/f_even; 'auto' picks it by leave-one-strip-out cross-validation.",
)
@click.option(
    "--weighting",
    type=click.Choice(CALIBRATION_WEIGHTINGS),
    default="none",
    show_default=True,
    help="'none': the paper's least squares; 'shift': balance small and large shifts.",
)
@click.option(
    "--sleeve/--no-sleeve",
    default=None,
    help="kappa_cal = 1/(R + c) (strip radius without the sleeve) or 1/R; default: from the config.",
)
@click.option("--finger", metavar="NAME",
              help="With a gripper's config (fingers:): fit this finger's sensor from board recordings (its "
                   "channels); the calibration records the finger.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path), help="Save a fit plot.")
@make_overwrite_option("Replace an existing output file.")
def calibrate(manifest, output, config_path, degree, weighting, sleeve, finger, plot_path, overwrite):
    """Fit the signal-to-shift calibration (paper eq. 1-2) from MANIFEST.yaml.

    The manifest names the flat recording and one session CSV per calibration strip
    (paths relative to the manifest):

    \b
        flat: flat.csv
        strips:
          - {radius_m: 0.040, recording: r040.csv}
          - {radius_mm: 50, recording: r050.csv}

    A gripper (--config G.yaml with fingers:): --finger NAME fits that finger's
    sensor from recordings of the whole board (its channels are taken).
    """  # noqa: D301 (click's \b keeps the example's line breaks)
    check_figure_suffix(plot_path, "--plot")

    def step(state):
        from bendsense.calibration import Calibration
        from bendsense.config import GripperConfig, load_config

        config = load_config(config_path)
        options = {"degree": degree, "weighting": weighting, "sleeve": sleeve}
        if isinstance(config, GripperConfig):
            if finger is None:
                raise click.UsageError(f"{config_path} is a gripper config (fingers {', '.join(config.names)}): "
                                       f"give --finger NAME, the finger to calibrate")
            cal = Calibration.fit(manifest, finger=config.finger(finger), **options)
        else:
            if finger is not None:
                raise click.BadParameter("a finger needs a gripper's config (--config G.yaml with fingers:)",
                                         param_hint="'--finger'")
            cal = Calibration.fit(manifest, config.sensor, **options)
        figure = None
        if plot_path is not None:  # drawn before anything is written: a failure leaves no calibration
            import matplotlib

            matplotlib.use("Agg")
            figure = cal.plot()[0].figure
        cal.save(output, overwrite=overwrite)
        say(cal.report())
        say(f"wrote {output}")
        if figure is not None:
            save_figure(figure, plot_path, overwrite=overwrite)
        state["calibration"] = cal
        return state

    targets = [outputs.file(output, overwrite=overwrite, suffixes=outputs.YAML)]
    if plot_path is not None:
        targets.append(outputs.file(plot_path, overwrite=overwrite, suffixes=outputs.FIGURE))
    return step_io(step, outputs=targets, inputs=[manifest, config_path, *_recordings(manifest)])


def _recordings(manifest: Path) -> list:
    """The recordings a calibration manifest names (inputs never to be written over); [] if unreadable."""
    from bendsense.calibration import read_manifest
    from bendsense.errors import BendsenseError

    try:
        found = read_manifest(manifest)
    except BendsenseError:  # the fit reports it, with its message
        return []
    return [found.flat, *(path for _, path in found.strips)]


COMMANDS = [calibrate]
