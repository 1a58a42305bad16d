"""The ``control`` command: hold a contact force with a loop on the tracked estimate (bendsense.control)."""

from __future__ import annotations

import logging
import sys

import click

from bendsense import output as outputs
from bendsense.cli import _signals
from bendsense.cli._common import (
    CONSTRAINTS,
    Directory,
    Finite,
    InterspersedCommand,
    PressureKpa,
    live_contact_option,
    load_option,
    make_bandwidth_option,
    make_calibration_option,
    make_config_option,
    make_overwrite_option,
    quiet,
)
from bendsense.cli._common import calibration_paths as calibration_paths_of
from bendsense.cli.device import adapt_option, finish_adapt

log = logging.getLogger("bendsense")



def _controllers(config, finger, target, max_pressure_pa, tuning, load_options, bandwidth_hz):
    """The controller(s): one per controlled finger, on its line (a single actuator: line 0).

    ``tuning`` names the kind (``model``: :class:`bendsense.control.ModelController`, ``pi``:
    :class:`bendsense.control.PIController`) and its options; the model's is told the track's
    ``bandwidth_hz`` (its lag). A target beyond what a finger can press with at the pressure
    limit (at its known contact location, else its tip: :func:`bendsense.control.force_limit_n`)
    is refused here, before the board is driven.
    """
    from bendsense.config import GripperConfig
    from bendsense.control import Grasp, ModelController, PIController, force_limit_n
    from bendsense.errors import ArgumentError, BendsenseError

    kind, options_of_kind = tuning["controller"], {k: v for k, v in tuning.items() if k != "controller"}

    def one(cfg, options, **kw):
        bound = force_limit_n(cfg, max_pressure_pa, options.get("contact_s_m"))
        try:
            if kind == "model":
                return ModelController(target, cfg, max_pressure_pa=max_pressure_pa, max_force_n=bound,
                                       contact_s_m=options.get("contact_s_m"), track_bandwidth_hz=bandwidth_hz,
                                       **kw, **options_of_kind)
            return PIController(target, max_pressure_pa=max_pressure_pa, tip_s_m=cfg.actuator.length_m,
                                max_force_n=bound, **kw, **options_of_kind)
        except ArgumentError as err:
            raise click.BadParameter(str(err).removeprefix("target_force_n: "),
                                     param_hint="'--target-force-n'") from None

    if not isinstance(config, GripperConfig):
        if finger:
            raise click.BadParameter("names a finger of a gripper config (--config with fingers:); this config is "
                                     "a single actuator", param_hint="'--finger'")
        return one(config, load_options)
    try:
        for name in finger:
            config.finger(name)  # an unknown name: its error
    except BendsenseError as err:
        raise click.BadParameter(str(err), param_hint="'--finger'") from None
    chosen = [f for f in config.fingers if f.name in finger] if finger else config.fingers  # each once, in order
    each = [one(f.config, load_options["finger_options"][f.name], line=f.pressure_line, finger=f.name) for f in chosen]
    try:
        return Grasp(each)
    except BendsenseError as err:
        text = str(err).removeprefix("controllers: ")
        if finger:
            raise click.BadParameter(text, param_hint="'--finger'") from None
        raise click.ClickException(f"the config's fingers: {text} (--finger NAME)") from None


def _processor(config, calibrations, constraint, bandwidth_hz, load, adapt, config_path):
    """The live processor (a gripper's: one LiveProcessor per finger), its kernels ready.

    A constraint that leaves the load of a finger at rest undetermined is refused here,
    before the board is driven: every frame at rest would be ``not_identifiable``, and the
    loop would stop at its first 10 ms.
    """
    from bendsense.cli.device import make_processor
    from bendsense.status import Status

    processor = make_processor(config, calibrations, constraint, None, None, bandwidth_hz=bandwidth_hz, load=load,
                               adapt=adapt, config_path=config_path)
    fingers = getattr(processor, "processors", {None: processor})
    if any(p.rest_status() == Status.NOT_IDENTIFIABLE for p in fingers.values()):
        raise click.BadParameter(f"{constraint} leaves the load of a finger at rest (straight, no pressure) "
                                 "undetermined: every frame at rest would be not_identifiable and the loop would stop "
                                 "at once; use normal (a frictionless contact) or follower",
                                 param_hint="'--constraint'")
    return processor


def _locations(load_options):
    """The known contact location(s) of the load options, for the session's meta (a gripper's: per finger)."""
    if "finger_options" in load_options:
        locations = {name: o.get("contact_s_m") for name, o in load_options["finger_options"].items()}
        return None if all(v is None for v in locations.values()) else locations
    return load_options.get("contact_s_m")


def pressure_limit(config, max_pressure_kpa):
    """The pressure limit [Pa]: given (within the config's pressure range), else 100 kPa or the range's end if lower.

    Parameters
    ----------
    config : Config or GripperConfig
        Its actuators' ``pressure_range_pa`` bound the limit (a gripper: the lowest end).
    max_pressure_kpa : float or None
        ``--max-pressure-kpa``; beyond the config's range: a ``click.BadParameter``.
    """
    from bendsense.config import GripperConfig
    from bendsense.control import DEFAULT_MAX_PRESSURE_PA

    configs = [f.config for f in config.fingers] if isinstance(config, GripperConfig) else [config]
    top = min(c.actuator.pressure_range_pa[1] for c in configs)
    if max_pressure_kpa is None:
        return min(DEFAULT_MAX_PRESSURE_PA, top)
    if not max_pressure_kpa > 0:
        raise click.BadParameter(f"expected a pressure limit > 0 kPa, got {max_pressure_kpa:g}",
                                 param_hint="'--max-pressure-kpa'")
    if max_pressure_kpa * 1e3 > top:
        raise click.BadParameter(f"{max_pressure_kpa:g} kPa is beyond the config's actuator.pressure_range_pa (up to "
                                 f"{top / 1e3:g} kPa), where the actuator model ends: the loop would stop at the "
                                 "first reading beyond it", param_hint="'--max-pressure-kpa'")
    return max_pressure_kpa * 1e3


def _summary(result, controller) -> str:
    """What the loop did, in one paragraph for stderr."""
    from bendsense.control import Grasp, zero_report

    each = controller.controllers if isinstance(controller, Grasp) else (controller,)
    parts = []
    for c in each:
        nf = c.last
        force = "no force" if nf is None else f"N = {nf.force_n[-1] * 1e3:.1f} ± {nf.std_n[-1] * 1e3:.1f} mN"
        name = "" if c.finger is None else f"{c.finger}: "
        parts.append(f"{name}{force} (target {c.target_force_n * 1e3:.4g} mN, set-point {c.output_pa / 1e3:.1f} kPa)")
    held = ""
    if result.held:
        held = (f"; line{'s' if len(result.held) > 1 else ''} {', '.join(str(k) for k in result.held)} not "
                "controlled: held at set-point 0")
    return (f"{result.frames} frames in {result.blocks} blocks ({result.per_frame_s * 1e6:.0f} µs per frame); "
            + "; ".join(parts) + f"; highest set-point {result.max_setpoint_pa / 1e3:.1f} kPa{held}; "
            f"{zero_report(result)} {result.zero_latency_s * 1e3:.2f} ms after the stop")


@click.command("control", cls=InterspersedCommand)
@click.argument("port")
@make_calibration_option("Calibration YAML written by 'bendsense calibrate'", required=True)
@click.option("--target-force-n", required=True, type=Finite(min=0),
              help="Contact normal force to hold [N] (F · n at the contact; positive: the finger presses).")
@click.option("--finger", multiple=True,
              help="A gripper's finger to control; repeat it for several (default: every finger, each on its own "
                   "line).")
@click.option("--max-pressure-kpa", type=PressureKpa(min=0), default=None,
              help="Highest set-point ever sent [kPa] (default 100, or the end of the config's pressure range "
                   "if lower).")
@click.option("-o", "--output", type=Directory(),
              help="Record the session here: the board's native session, control.csv and the results.")
@make_overwrite_option("Replace an existing session.")
@make_config_option("Config YAML (a gripper: with fingers:; default: the paper's prototype).")
@click.option("--seconds", type=Finite(min=0, min_open=True), help="Run time [s] (default: until Ctrl-C).")
@load_option
@live_contact_option
@click.option("--constraint", type=click.Choice(CONSTRAINTS), default="normal", show_default=True,
              help="Force constraint: normal (a frictionless contact: F along n) or any other of 'estimate'.")
@click.option("--controller", "controller_kind", type=click.Choice(["model", "pi"]), default="model",
              show_default=True,
              help="model: the finger's pressing curve from its config as feed-forward, a model-mismatch observer "
                   "(no overshoot at the touch; bendsense.control.ModelController); pi: a PI on the force.")
@click.option("--approach-kpa-per-s", type=Finite(min=0, min_open=True), default=None,
              help="model: set-point ramp before the touch [kPa/s] (default 3000 kPa/(N s) times the target, "
                   "250 kPa/s at least, the slew limit at most).")
@click.option("--kp-kpa-per-n", type=Finite(min=0), default=None,
              help="pi: proportional gain [kPa/N] (default 50: bendsense.control.DEFAULT_KP_PA_PER_N).")
@click.option("--ki-kpa-per-n-s", type=Finite(min=0), default=None,
              help="pi: integral gain [kPa/(N s)] (default 3000: bendsense.control.DEFAULT_KI_PA_PER_N_S).")
@click.option("--max-rate-kpa-per-s", type=Finite(min=0, min_open=True), default=None,
              help="Slew limit of the set-point [kPa/s] (default 500).")
@make_bandwidth_option("30 Hz (bendsense.control.TRACK_BANDWIDTH_HZ); above 5 Hz: the loop needs a faster track "
                       "than live's 5 Hz, whose lag it would act on", minimum_hz=5.0)
@click.option("--silence-s", type=Finite(min=0, min_open=True), default=None,
              help="Stop when no frame arrives for this long [s] (default 0.1, or 10 frame periods of a slower "
                   "board).")
@click.option("--baud", type=click.IntRange(50, 12_000_000), default=None,
              help="Baud rate, 50..12000000 (default 921600; USB CDC ignores it).")
@click.option("--hello-timeout", type=Finite(min=0, min_open=True), default=2.0, show_default=True,
              help="HELLO wait [s].")
@adapt_option
def control(port, calibration_paths, target_force_n, finger, max_pressure_kpa, output, overwrite, config_path, seconds,
            load, contact_s_m, constraint, controller_kind, approach_kpa_per_s, kp_kpa_per_n, ki_kpa_per_n_s,
            max_rate_kpa_per_s, bandwidth_hz, silence_s, baud, hello_timeout, adapt):
    """Hold a contact force: a loop on the tracked contact normal force, at the board's frame rate.

    Every frame from the board on PORT is reconstructed, its force estimated and tracked
    (a causal Kalman filter, --bandwidth-hz), and the contact normal force N = F · n (n the
    finger's normal at the contact, from the estimated shape; --load contact
    --contact-s-m X: a contact at the known arc length X, else the tip) drives a
    controller whose output, clipped to [0, --max-pressure-kpa], goes to the board as a
    SETPOINT: by default one that knows the finger (--controller model: it approaches,
    takes the touch pressure, and follows the config's pressing curve to the target, with
    a model-mismatch observer; no overshoot at the touch), or a PI with anti-windup
    (--controller pi, --kp-kpa-per-n, --ki-kpa-per-n-s). With a gripper config every finger is controlled on its own
    pressure line (--finger NAME, repeatable: only those; the other lines are held at set-point 0).
    A target beyond what a finger can press with at the pressure limit is refused.

    Set-point 0 goes to every pressure line (the config's, every line driven, every line
    the board reported) when the loop ends, whatever ends it: --seconds, Ctrl-C, SIGTERM,
    the terminal closing (SIGHUP) or Ctrl-backslash (exit 130, 143, 129, 131; a second signal
    while the zeros go out waits for them), an error, more than 10 frames lost within 1 s,
    no frame for 0.1 s (--silence-s), a pressure on any line beyond --max-pressure-kpa
    (+5 kPa) or above every set-point sent to it for 0.25 s (+5 kPa: a board that does
    not follow its set-points), or a controlled finger without a force or model_misfit /
    not_identifiable for 10 ms (a safety stop: one line, exit 1). Then it watches the
    reported pressures fall for up to 0.5 s. The last line says line by line whether
    set-point 0 was sent and whether the pressure fell; one that could not be sent, or a
    pressure that did not fall, exits 1. -o SESSION records everything
    (docs/formats.md, "Control session"). docs/grasping.md walks through a grasp on the
    simulated board and lists every stop.

    --adapt learns the finger's free bending from its free frames (the approach, the
    rests) as the loop runs and swaps the config between blocks (docs/grasping.md, "A
    finger that is not the config's").

    While it runs it sends a HEARTBEAT every 50 ms, so that a board with a host-silence
    watchdog (sim-device --watchdog-ms) lets go of every line when this command is killed.
    """
    from bendsense.cli.device import live_load
    from bendsense.config import load_config
    from bendsense.control import TRACK_BANDWIDTH_HZ
    from bendsense.device.driver import DEFAULT_BAUDRATE, Driver

    ctx = click.get_current_context()
    if overwrite and output is None:
        raise click.BadParameter("replaces the session of -o SESSION: give -o", param_hint="'--overwrite'")
    if output is not None:  # checked and locked before anything opens, until the command ends
        ctx.with_resource(outputs.reserve([outputs.recording(output, overwrite=overwrite)],
                                          [config_path, *(p for _, p in calibration_paths)]))
    config = load_config(config_path)
    calibrations = calibration_paths_of(calibration_paths, config)
    pmax = pressure_limit(config, max_pressure_kpa)
    tuning = _tuning(controller_kind, approach_kpa_per_s, kp_kpa_per_n, ki_kpa_per_n_s, max_rate_kpa_per_s)
    load_options = live_load(load, contact_s_m, config)
    bandwidth_hz = bandwidth_hz or TRACK_BANDWIDTH_HZ
    controller = _controllers(config, finger, target_force_n, pmax, tuning, load_options, bandwidth_hz)
    processor = _processor(config, calibrations, constraint, bandwidth_hz, load_options, adapt, config_path)
    meta = {"command": "bendsense control",
            "control": {"target_force_n": target_force_n, "max_pressure_pa": pmax, **tuning,
                        "fingers": [f for f in controller.fingers if f is not None], "load": load,
                        "constraint": constraint,
                        "contact_s_m": _locations(load_options), "bandwidth_hz": bandwidth_hz}}
    with Driver(port, baudrate=baud or DEFAULT_BAUDRATE, hello_timeout_s=hello_timeout) as driver:
        _check_board(driver, config, port, processor)
        _run(driver, processor, controller, config, pmax, seconds, output, overwrite, meta, silence_s)


def _check_board(driver, config, port, processor) -> None:
    """Every finger's channels (or the actuator's) on the board its HELLO announces; else one line, never driven."""
    from bendsense.config import GripperConfig
    from bendsense.session.fingers import check_board

    if driver.n_channels is None:  # no HELLO: the first block's check
        return
    if isinstance(config, GripperConfig):
        check_board(driver.n_channels, None, config, f"{port} (the board's HELLO)", click.ClickException)
    elif driver.n_channels != processor.calibration.n_channels:
        raise click.ClickException(f"{port} (the board's HELLO): {driver.n_channels} channels, but the calibration "
                                   f"reads {processor.calibration.n_channels} (a gripper's board: give its config "
                                   "with fingers: as --config)")


def _tuning(kind, approach_kpa_per_s, kp_kpa_per_n, ki_kpa_per_n_s, max_rate_kpa_per_s) -> dict:
    """The controller's kind and options [SI units], its defaults filled in; an option of the other kind is refused."""
    from bendsense.control import (
        DEFAULT_KI_PA_PER_N_S,
        DEFAULT_KP_PA_PER_N,
        DEFAULT_MAX_RATE_PA_PER_S,
    )

    given = {"--approach-kpa-per-s": approach_kpa_per_s, "--kp-kpa-per-n": kp_kpa_per_n,
             "--ki-kpa-per-n-s": ki_kpa_per_n_s}
    other = ("--kp-kpa-per-n", "--ki-kpa-per-n-s") if kind == "model" else ("--approach-kpa-per-s",)
    for name in other:
        if given[name] is not None:
            raise click.BadParameter(f"is an option of --controller {'pi' if kind == 'model' else 'model'}",
                                     param_hint=f"'{name}'")
    rate = DEFAULT_MAX_RATE_PA_PER_S if max_rate_kpa_per_s is None else max_rate_kpa_per_s * 1e3
    if kind == "model":
        approach = None if approach_kpa_per_s is None else approach_kpa_per_s * 1e3
        if approach is not None and approach > rate:
            raise click.BadParameter(f"{approach_kpa_per_s:g} kPa/s is faster than the set-point's slew limit "
                                     f"(--max-rate-kpa-per-s, {rate / 1e3:g} kPa/s)",
                                     param_hint="'--approach-kpa-per-s'")
        return {"controller": "model", "approach_rate_pa_per_s": approach, "max_rate_pa_per_s": rate}
    return {"controller": "pi", "kp_pa_per_n": DEFAULT_KP_PA_PER_N if kp_kpa_per_n is None else kp_kpa_per_n * 1e3,
            "ki_pa_per_n_s": DEFAULT_KI_PA_PER_N_S if ki_kpa_per_n_s is None else ki_kpa_per_n_s * 1e3,
            "max_rate_pa_per_s": rate}


def _run(driver, processor, controller, config, pmax, seconds, output, overwrite, meta, silence_s):
    """Record (with -o), start the board, run the loop; one line for how it ended, saying what became of every line.

    A safety stop, an error of the device, a set-point 0 that could not be sent or a line
    whose pressure did not fall after it is one ``Error:`` line and exit 1; Ctrl-C, SIGTERM,
    SIGHUP, SIGQUIT one ``Interrupted`` line (130, 143, 129, 131).
    """
    from bendsense.control import ControlRecording, Safety

    fingers = getattr(config, "names", None)
    recording = None if output is None else ControlRecording(driver, output, overwrite=overwrite, config=config,
                                                             meta=meta, fingers=fingers)
    n_lines = getattr(config, "n_lines", 1)
    if not quiet():
        click.echo(f"holding {controller.target_force_n * 1e3:.4g} mN (pressure limit {pmax / 1e3:g} kPa); "
                   "Ctrl-C stops", err=True)
    where = "" if output is None else f"the session is in {output}"
    result = drive(driver, processor, controller, "control", where, output, max_pressure_pa=pmax, seconds=seconds,
                   n_lines=n_lines, recording=recording, safety=Safety(silence_s=silence_s))
    if not quiet():
        click.echo(_summary(result, controller), err=True)
    finish_adapt(processor, output)
    if not quiet() and output is not None:
        click.echo(f"session written to {output}", err=True)


def drive(driver, processor, controller, name: str, where: str = "", adapt_output=None, **options):
    """Start the board and run the loop (:func:`bendsense.control.run`); one line for how it ended.

    A safety stop, an error of the device, a set-point 0 that could not be sent or a line
    whose pressure did not fall after it is one ``Error:`` line (``NAME stopped: why; what
    became of every line; WHERE``) and exit 1; Ctrl-C, SIGTERM, SIGHUP, SIGQUIT one
    ``Interrupted`` line (130, 143, 129, 131) saying the same.

    Parameters
    ----------
    driver, processor, controller
        As :func:`bendsense.control.run`.
    name : str
        What runs, for the messages (``control``, ``the sweep``).
    where : str
        Where its recording is, for the messages ("" without one).
    adapt_output : Path, optional
        With ``--adapt``: the session directory that gets the adapted config however the
        loop ends (:func:`bendsense.cli.device.finish_adapt`; a stop writes the latest one).
    **options
        Passed to :func:`bendsense.control.run`.

    Returns
    -------
    ControlResult
    """
    from bendsense.control import run, zero_report
    from bendsense.errors import BendsenseError

    driver.start()
    try:
        result = run(driver, processor, controller, **options)
    except KeyboardInterrupt as err:
        _signals.note(err, "; ".join(filter(None, (_zeros_of(err), where,
                                                   finish_adapt(processor, adapt_output, wait=False)))))
        raise
    except BendsenseError as err:  # a safety stop (ControlStop) or the device failing under the loop
        sys.stderr.flush()
        raise click.ClickException("; ".join(filter(None, (f"{name} stopped: {getattr(err, 'reason', err)}",
                                                           _zeros_of(err), where,
                                                           finish_adapt(processor, adapt_output, wait=False))))
                                   ) from None
    if result.unsent or result.high:
        raise click.ClickException("; ".join(filter(None, (f"{name} ended ({result.outcome}) but "
                                                           f"{zero_report(result)}", where))))
    return result


def _zeros_of(err) -> str:
    """What became of every line's set-point 0, from the result the loop attached to ``err``."""
    from bendsense.control import zero_report

    result = getattr(err, "result", None)
    return "set-point 0 was never sent (the loop did not start)" if result is None else zero_report(result)


COMMANDS = [control]
