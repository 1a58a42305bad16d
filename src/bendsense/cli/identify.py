"""The ``identify`` command: fit the free-bending or stiffness model to measurements."""

from __future__ import annotations

from pathlib import Path

import click

from bendsense import output as outputs
from bendsense.choices import BEAM_METHODS
from bendsense.cli._common import (
    InterspersedCommand,
    PressureKpa,
    check_figure_suffix,
    config_option,
    overwrite_option,
    save_figure,
    say,
    step_io,
)
from bendsense.errors import BendsenseError

KINDS = ("free-bending", "stiffness")
# short names accepted by --fix, besides the config field names
_ALIASES = {
    "free-bending": {"mu": "shear_modulus_pa", "mu_s": "sensor_stiffness_nm_per_rad", "prebend": "prebend_angle_rad"},
    "stiffness": {"ei0": "ei0_nm2", "ei1": "ei1_nm2_per_pa"},
}
_NAMES = {
    "free-bending": ("shear_modulus_pa", "sensor_stiffness_nm_per_rad", "prebend_angle_rad"),
    "stiffness": ("ei0_nm2", "ei1_nm2_per_pa"),
}


def _parse_fix(kind: str, items) -> dict:
    """``NAME`` or ``NAME=VALUE`` items of --fix as {config field: value or None}."""
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        name = _ALIASES[kind].get(name.strip(), name.strip())
        if name not in _NAMES[kind]:
            allowed = ", ".join([*_NAMES[kind], *_ALIASES[kind]])
            raise click.BadParameter(f"unknown parameter {item!r} for {kind}; allowed: {allowed}", param_hint="--fix")
        if value.strip():
            from bendsense.validation import parse_number

            out[name] = parse_number(f"--fix {name}", value.strip())
        else:
            out[name] = None
    return out


@click.command("identify", cls=InterspersedCommand)
@click.argument("kind", type=click.Choice(KINDS))
@click.argument("data", metavar="DATA.csv", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@config_option
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Config YAML to write: the input config with the fitted values.",
)
@click.option(
    "--fix",
    "fix_items",
    multiple=True,
    metavar="NAME[=VALUE]",
    help="Hold a parameter (repeatable): at the config's value, or at VALUE in SI units. "
    "free-bending: shear_modulus_pa (mu), sensor_stiffness_nm_per_rad (mu_s), prebend_angle_rad (prebend); "
    "stiffness: ei0_nm2 (ei0), ei1_nm2_per_pa (ei1).",
)
@click.option(
    "--pressure-tolerance-kpa",
    type=PressureKpa(min=0),
    default=1.0,
    show_default=True,
    help="stiffness: rows whose pressures differ by at most this form one level [kPa].",
)
@click.option(
    "--unweighted", is_flag=True, help="stiffness: ordinary instead of weighted regression of EI over pressure."
)
@click.option(
    "--method",
    type=click.Choice(BEAM_METHODS),
    default="fast",
    show_default=True,
    help="stiffness: beam solver ('shooting' is the paper's method).",
)
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path), help="Save a plot of the fit.")
@overwrite_option
def identify(
    kind, data, config_path, output, fix_items, pressure_tolerance_kpa, unweighted, method, plot_path, overwrite
):
    """Fit the free-bending or stiffness model to DATA.csv (paper section V-C).

    free-bending: DATA.csv has the columns pressure_pa (or pressure_kpa) and
    bending_angle_rad (or bending_angle_deg); fits shear_modulus_pa,
    sensor_stiffness_nm_per_rad and prebend_angle_rad.

    stiffness: DATA.csv has the columns pressure_pa (or pressure_kpa), fx_n, fy_n, and
    tip_x_m, tip_y_m and/or shape points s1_m, x1_m, y1_m, s2_m, ...; fits EI per
    pressure level, then ei0_nm2 and ei1_nm2_per_pa. Identify free bending first: the
    stiffness fit uses K0(P) of the config's free-bending model.

    Writes the config (--config, or the paper's) with the fitted values to OUTPUT.
    """
    fix = _parse_fix(kind, fix_items)
    check_figure_suffix(plot_path, "--plot")

    def step(state):
        from bendsense.config import load_config, save_config
        from bendsense.identify import (
            check_fixed,
            fit_free_bending,
            fit_stiffness,
            read_free_bending_csv,
            read_stiffness_csv,
        )

        config = load_config(config_path)  # (its errors name the config, not the data)
        # a held value no actuator of this geometry can have: named before any data is read
        check_fixed(fix, config, field="--fix")
        try:
            if kind == "free-bending":
                pressure, angle = read_free_bending_csv(data)
                fit = fit_free_bending(pressure, angle, config, fix=fix)
            else:
                table = read_stiffness_csv(data, config.actuator.length_m)
                fit = fit_stiffness(
                    table,
                    config,
                    fix=fix,
                    pressure_tolerance_pa=pressure_tolerance_kpa * 1e3,
                    weighted=not unweighted,
                    method=method,
                )
            new_config = fit.to_config(config)
        except BendsenseError as err:
            raise click.ClickException(f"{data}: {err}" if str(data) not in str(err) else str(err)) from None
        say(fit.report())
        ax = None
        if plot_path is not None:  # drawn before anything is written: a failure leaves no config
            import matplotlib

            matplotlib.use("Agg")
            ax = fit.plot(config=config) if kind == "free-bending" else fit.plot()
        save_config(new_config, output, overwrite=overwrite)
        say(f"wrote {output}")
        if ax is not None:
            save_figure(ax.figure, plot_path, overwrite=overwrite)
        state["config"] = new_config
        return state

    targets = [outputs.file(output, overwrite=overwrite, suffixes=outputs.YAML)]
    if plot_path is not None:
        targets.append(outputs.file(plot_path, overwrite=overwrite, suffixes=outputs.FIGURE))
    return step_io(step, outputs=targets, inputs=[data, config_path])


COMMANDS = [identify]
