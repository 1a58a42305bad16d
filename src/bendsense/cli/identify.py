"""The ``identify`` command: fit the free-bending or stiffness model to measurements."""

from __future__ import annotations

import datetime
from pathlib import Path

import click

from bendsense import output as outputs
from bendsense.choices import BEAM_METHODS
from bendsense.cli._common import (
    Finite,
    InterspersedCommand,
    PressureKpa,
    check_figure_suffix,
    config_option,
    data_warnings_logged,
    make_calibration_option,
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
    if len(out) == len(_NAMES[kind]):  # a fit of nothing would write variance 0 over the prior's
        raise click.BadParameter(f"holds every parameter of {kind} ({', '.join(_NAMES[kind])}): nothing is left to "
                                 "fit; free at least one", param_hint="--fix")
    return out


@click.command("identify", cls=InterspersedCommand)
@click.argument("kind", type=click.Choice(KINDS))
@click.argument("data", metavar="[DATA.csv]", required=False,
                type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--session",
    "session_path",
    type=click.Path(exists=True, path_type=Path),
    help="Identify from a session recorded with bendsense (native directory or session CSV) instead of "
    "DATA.csv: free-bending from a free pressure sweep, stiffness from hanging weights (columns fx_n, fy_n "
    "or mass_kg). Needs --calibration.",
)
@click.option(
    "--port",
    help="free-bending: drive a free sweep on the board on PORT through SETPOINT frames (line 0: a slow staircase "
    "up and down the config's pressure range, capped by --max-pressure-kpa, holding at each step), record it to "
    "OUTPUT's stem + '-sweep/' (a native session: 'identify free-bending --session' fits it again) and fit it. "
    "Set-point 0 goes to the line whatever ends the sweep (as in 'bendsense control'). Needs --calibration.",
)
@click.option(
    "--turned-session",
    "turned_path",
    type=click.Path(exists=True, path_type=Path),
    help="stiffness without weights: a second free sweep of the same finger and sensor with the rig turned "
    "(--session: the sweep in the config's mount). The weight sags the finger one way in one mount and the other "
    "way in the other: the two fit EI(P) and the free bending together, as an update of the config's prior "
    "(docs/identify.md, \"Stiffness without weights\"). Both sweeps must be free: nothing touches the finger.",
)
@click.option("--turned-gravity", type=(Finite(), Finite()), metavar="X Y",
              help="With --turned-session: gravity's direction in the finger's base frame in the turned mount "
                   "(default: opposite to the config's gravity.direction, the rig upside down).")
@click.option("--max-pressure-kpa", type=PressureKpa(min=0),
              help="With --port: the sweep's highest set-point [kPa] (default 100, or the end of the config's "
                   "pressure range if lower).")
@click.option("--seconds", type=Finite(min=0, min_open=True),
              help="With --port: the sweep's length, up and down [s] (default 20).")
@make_calibration_option("With --session or --port: the sensor's calibration YAML (bendsense calibrate)")
@config_option
@click.option("--finger", metavar="NAME",
              help="With a gripper's config (fingers:) and --session (a board session): identify this finger from "
                   "its part of the board; OUTPUT is the gripper's config with the finger's fitted values.")
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
@click.option("--plot", "--figure", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Save a figure of the fit (with --session, free-bending: the frames used and rejected, "
              "the fitted and the prior model).")
@overwrite_option
def identify(
    kind, data, session_path, port, turned_path, turned_gravity, max_pressure_kpa, seconds, calibration_paths,
    config_path, finger, output, fix_items, pressure_tolerance_kpa, unweighted, method, plot_path, overwrite
):
    """Fit the free-bending or stiffness model to DATA.csv or a session (paper section V-C).

    free-bending: DATA.csv has the columns pressure_pa (or pressure_kpa) and
    bending_angle_rad (or bending_angle_deg); fits shear_modulus_pa,
    sensor_stiffness_nm_per_rad and prebend_angle_rad.

    stiffness: DATA.csv has the columns pressure_pa (or pressure_kpa), fx_n, fy_n, and
    tip_x_m, tip_y_m and/or shape points s1_m, x1_m, y1_m, s2_m, ...; fits EI per
    pressure level, then ei0_nm2 and ei1_nm2_per_pa. Identify free bending first: the
    stiffness fit uses K0(P) of the config's free-bending model.

    --session S --calibration C (instead of DATA.csv): free-bending from a free
    pressure sweep recorded with bendsense (the frames with no contact are chosen by
    the force estimator: status ok and the force inside its 2-sigma ellipse, iterated
    with the fit); stiffness from hanging weights (known tip force in the columns
    fx_n, fy_n, or mass_kg hanging under gravity).

    free-bending --port PORT --calibration C: drive the free sweep on the board, record it
    to OUTPUT's stem + '-sweep/' and fit it as --session does (docs/identify.md, "On a
    live board"). Stiffness needs known loads: hanging weights, --session; or no weights:
    --session UP --turned-session DOWN, free sweeps in two mounts.

    Writes the config (--config, or the paper's) with the fitted values and their
    covariance to OUTPUT, with a comment line saying what it was identified from.
    """
    fix = _parse_fix(kind, fix_items)
    check_figure_suffix(plot_path, "--plot")
    _check_sources(kind, data, session_path, port, calibration_paths, max_pressure_kpa, seconds)
    _check_turned(kind, session_path, turned_path, turned_gravity, finger, fix, plot_path)
    sweep_path = None if port is None else output.with_name(output.stem + "-sweep")
    source = next(s for s in (data, session_path, sweep_path) if s is not None)

    def step(state):
        from bendsense.cli.gripper import identify_inputs
        from bendsense.config import load_config, save_config
        from bendsense.identify import (
            check_fixed,
            fit_free_bending,
            fit_stiffness,
            read_free_bending_csv,
            read_stiffness_csv,
        )

        config = load_config(config_path)  # (its errors name the config, not the data)
        if port is not None and hasattr(config, "fingers"):
            raise click.BadParameter("drives one actuator on line 0: give its own config (a gripper's finger: "
                                     "record its sweep, then --session with --finger)", param_hint="--port")
        # the actuator identified, and how its fit becomes the config written (a gripper: one finger of it)
        config, inputs, written = identify_inputs(config, finger, session_path or sweep_path, calibration_paths)
        # a held value no actuator of this geometry can have: named before any data is read
        check_fixed(fix, config, field="--fix")
        if port is not None:
            _sweep(port, config, calibration_paths, max_pressure_kpa, seconds, sweep_path, output, overwrite)
        try:
            with data_warnings_logged():  # one WARNING: line each, before an error
                if turned_path is not None:
                    fit = _gravity_sessions(inputs, config, turned_path, turned_gravity)
                elif kind == "free-bending" and data is None:
                    fit = _free_bending_session(inputs, config, fix)
                elif kind == "free-bending":
                    pressure, angle = read_free_bending_csv(data)
                    fit = fit_free_bending(pressure, angle, config, fix=fix)
                else:
                    options = {"fix": fix, "pressure_tolerance_pa": pressure_tolerance_kpa * 1e3,
                               "weighted": not unweighted, "method": method}
                    if data is not None:
                        fit = fit_stiffness(read_stiffness_csv(data, config.actuator.length_m), config, **options)
                    else:
                        fit = _stiffness_session(inputs, config, options)
                failed = _failure(fit)  # never a config from a fit that failed: it would pose as identified
                new_config = None if failed else written(fit.to_config(config))
        except BendsenseError as err:
            raise click.ClickException(f"{source}: {err}" if str(source) not in str(err) else str(err)) from None
        say(fit.report())
        if failed is not None:
            raise click.ClickException(f"{source}: the {kind} fit failed ({failed}); no config written")
        ax = None
        if plot_path is not None:  # drawn before anything is written: a failure leaves no config
            import matplotlib

            matplotlib.use("Agg")
            ax = fit.plot(config=config) if kind == "free-bending" else fit.plot()
        when = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        save_config(new_config, output, overwrite=overwrite,
                    note=f"{kind} identified by bendsense from {source} ({when})")
        say(f"wrote {output}")
        if ax is not None:
            save_figure(ax.figure, plot_path, overwrite=overwrite)
        state["config"] = new_config
        return state

    targets = [outputs.file(output, overwrite=overwrite, suffixes=outputs.YAML)]
    if sweep_path is not None:
        targets.append(outputs.recording(sweep_path, overwrite=overwrite))
    if plot_path is not None:
        targets.append(outputs.file(plot_path, overwrite=overwrite, suffixes=outputs.FIGURE))
    inputs = [data, session_path, turned_path, *(p for _, p in calibration_paths), config_path]
    return step_io(step, outputs=targets, inputs=inputs)


def _check_sources(kind, data, session_path, port, calibration_paths, max_pressure_kpa, seconds) -> None:
    """DATA.csv, or --session or --port with --calibration: one of them, named when wrong."""
    given = [name for name, value in (("DATA.csv", data), ("--session", session_path), ("--port", port))
             if value is not None]
    if len(given) > 1:
        raise click.BadParameter(f"give {' or '.join(given)}, not {'both' if len(given) == 2 else 'all three'}",
                                 param_hint=given[-1])
    if not given:
        raise click.UsageError("give DATA.csv, or --session SESSION (or free-bending: --port PORT) with "
                               "--calibration CAL.yaml")
    if port is not None and kind != "free-bending":
        raise click.BadParameter("stiffness needs known loads: record hanging weights and give --session (a free "
                                 "sweep has none)", param_hint="--port")
    for flag, value in (("--max-pressure-kpa", max_pressure_kpa), ("--seconds", seconds)):
        if value is not None and port is None:
            raise click.BadParameter("only with --port (the sweep it drives)", param_hint=flag)
    if data is None and not calibration_paths:
        raise click.BadParameter(f"required with {given[0]} (the sensor's calibration YAML, from bendsense calibrate)",
                                 param_hint="--calibration")
    if data is not None and calibration_paths:
        raise click.BadParameter("only with --session or --port (DATA.csv holds measured angles or shapes already)",
                                 param_hint="--calibration")


def _check_turned(kind, session_path, turned_path, turned_gravity, finger, fix, plot_path) -> None:
    """--turned-session and --turned-gravity with their company, named when wrong."""
    if turned_path is None:
        if turned_gravity is not None:
            raise click.BadParameter("only with --turned-session", param_hint="--turned-gravity")
        return
    for wrong, flag, why in ((kind != "stiffness", "--turned-session", "identifies stiffness (identify stiffness)"),
                             (session_path is None, "--turned-session", "needs --session (the sweep in the config's "
                                                                        "mount)"),
                             (finger is not None, "--finger", "not with --turned-session (one actuator's sweeps)"),
                             (bool(fix), "--fix", "not with --turned-session (it updates the config's prior)"),
                             (plot_path is not None, "--plot", "not with --turned-session")):
        if wrong:
            raise click.BadParameter(why, param_hint=flag)


def _failure(fit) -> str | None:
    """Why a fit failed (a config of it would pose as identified); None for a fit that did not.

    A stiffness fit fails where a level's beam fit does or EI is not positive; a free-bending
    fit where its data determine no value of a parameter (its standard error not finite).

    A free-bending fit that stops with a parameter at its bound is a result (the data do
    not support that parameter), not a failure.
    """
    import math

    from bendsense.identify import NOT_IDENTIFIABLE, FreeBendingFit, StiffnessFit

    if isinstance(fit, StiffnessFit):
        return None if fit.success else fit.message
    if isinstance(fit, FreeBendingFit) and not all(math.isfinite(fit.stderr[n]) for n in fit.free):
        return NOT_IDENTIFIABLE
    return None


def _gravity_sessions(inputs, config, turned_path, turned):
    """EI(P) and the free bending from free sweeps in two mounts (:mod:`bendsense.identify.gravity`)."""
    from bendsense.identify.gravity import identify_gravity
    from bendsense.session import read_session

    session, calibration = inputs()
    return identify_gravity([session, read_session(turned_path)], config, calibration, turned=turned)


#: the sweep's default length, up and down [s]
SWEEP_SECONDS = 20.0


def _sweep(port, config, calibration_paths, max_pressure_kpa, seconds, path, output, overwrite) -> None:
    """Drive and record the free sweep of ``identify free-bending --port`` (:class:`bendsense.control.Sweep`).

    The control loop runs it (:func:`bendsense.cli.control.drive`): set-point 0 on the
    line whatever ends it, one line when it stops early, and nothing written to OUTPUT.
    """
    from bendsense.calibration import Calibration
    from bendsense.cli._common import calibration_paths as for_config
    from bendsense.cli.control import drive, pressure_limit
    from bendsense.control import ControlRecording, Sweep
    from bendsense.device.driver import Driver
    from bendsense.pipeline import LiveProcessor

    top = pressure_limit(config, max_pressure_kpa)
    low = max(float(config.actuator.pressure_range_pa[0]), 0.0)
    sweep = Sweep(low, top, SWEEP_SECONDS if seconds is None else seconds)
    processor = LiveProcessor(Calibration.load(for_config(calibration_paths, config)), config, estimate=False)
    processor.warm_up()
    meta = {"command": "bendsense identify free-bending --port",
            "sweep": {"line": sweep.line, "low_pa": low, "high_pa": top, "seconds": sweep.seconds,
                      "levels": sweep.levels}}
    where = f"the frames so far are in {path}; nothing written to {output}"
    with Driver(port) as driver:
        recording = ControlRecording(driver, path, overwrite=overwrite, config=config, meta=meta)
        say(f"sweeping line {sweep.line} from {low / 1e3:g} to {top / 1e3:g} kPa and back over {sweep.seconds:g} s "
            f"(recorded to {path}); Ctrl-C stops")
        # the board's clock ends the sweep; the host's is the backstop for a board whose clock does not run
        result = drive(driver, processor, sweep, "the sweep", where, max_pressure_pa=top, stop=sweep.done,
                       seconds=2.0 * sweep.seconds + 5.0, recording=recording)
    if not sweep.done.is_set():
        raise click.ClickException(f"the sweep did not finish ({result.outcome}); {where}")
    say(f"sweep: {result.frames} frames recorded to {path}")


def _free_bending_session(inputs, config, fix):
    """The free-bending fit of a free sweep (:func:`bendsense.identify.sessions.fit_free_bending_session`)."""
    from bendsense.identify.sessions import fit_free_bending_session

    session, calibration = inputs()
    return fit_free_bending_session(session, calibration, config, fix=fix)


def _stiffness_session(inputs, config, options):
    """The stiffness fit of a session of hanging weights."""
    from bendsense.identify.weights import fit_stiffness_session

    session, calibration = inputs()
    return fit_stiffness_session(session, calibration, config, **options)


COMMANDS = [identify]
