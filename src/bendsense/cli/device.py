"""Commands of the device area: ``devices``, ``record``, ``sim-device`` (see bendsense.cli)."""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import click
from click.core import ParameterSource

from bendsense import output as outputs
from bendsense.cli import _signals
from bendsense.cli._common import (
    SEED,
    ContactLocation,
    Directory,
    Finite,
    InterspersedCommand,
    PressureKpa,
    checked_calibration,
    constraint_option,
    contact_locations,
    live_bandwidth_option,
    live_contact,
    live_contact_option,
    load_option,
    log_no_parameter_covariance,
    make_calibration_option,
    make_config_option,
    make_overwrite_option,
    objective_option,
    quiet,
    require_prior,
    say,
)
from bendsense.cli.sim import grasp_options, model_error_options, model_errors, noise_option

log = logging.getLogger("bendsense")


@click.command("devices")
def devices():
    """List the serial ports of this machine (device, VID:PID, serial number, description)."""
    from bendsense.device.ports import format_ports, list_ports

    click.echo(format_ports(list_ports()))


def _losses(stats) -> str:
    """What a recording did not keep, for its last line: ``; 4 skipped; 2 malformed; 5 lost (3 dropped by ...)``."""
    parts = (f"{stats.skipped} skipped (another channel count or pressure lines than the session's)"
             if stats.skipped else "", f"{stats.malformed} malformed" if stats.malformed else "",
             f"{stats.lost} lost ({stats.tx_drops} dropped by the firmware)" if stats.lost or stats.tx_drops else "")
    return "".join(f"; {part}" for part in parts if part)


def _status_line(stats, est=None) -> str:
    line = (
        f"{stats.records} frames  skipped {stats.skipped}  lost {stats.lost}  crc {stats.crc_errors}  "
        f"malformed {stats.malformed}  "
        f"queue drops {stats.queue_drops}  firmware drops {stats.tx_drops}  reconnects {stats.reconnects}  "
        f"{stats.elapsed_s:.1f} s"
    )
    if est is not None:
        from bendsense.results import flagged_counts

        line += (f"  | estimated {est.frames} ({est.rate_hz:.0f}/s)  backlog {est.backlog}  "
                 f"{flagged_counts(est.status_counts)}")
    return line


#: ``--adapt`` of ``record --estimate``, ``live`` and ``control``.
adapt_option = click.option(
    "--adapt", is_flag=True,
    help="Learn the free-bending model K0(P) from the free frames as they arrive (bendsense.adapt in a worker "
         "process, from the config's prior; the config is swapped between blocks); a last line says what was "
         "learned, and the adapted config goes to OUT/config.yaml with its provenance (record, control -o).")


def finish_adapt(processor, output=None, *, wait: bool = True) -> str:
    """``--adapt``'s end: the last update, one line of what was learned, the adapted config to ``output/config.yaml``.

    Parameters
    ----------
    processor : LiveProcessor
        The processor; nothing to do without ``adapt``.
    output : Path, optional
        The session directory (None: nothing written).
    wait : bool, default True
        False for a command that was interrupted or stopped: no last update and nothing
        printed; the latest finished update's config is written all the same.

    Returns
    -------
    str
        Where the adapted config went, for the line that ends an interrupted command
        ("" without ``adapt``, or when nothing was learned or written).
    """
    from bendsense.config import save_config

    adaptation = getattr(processor, "adaptation", None)
    if adaptation is None:
        return ""
    config = adaptation.close(wait)
    if wait:
        say(adaptation.summary(), err=True)
    if config is None or output is None or not output.is_dir():
        return ""
    save_config(config, output / "config.yaml")
    written = f"adapted config ({adaptation.updates} update(s)) written to {output / 'config.yaml'}"
    if wait:
        say(written, err=True)
    return written


def make_processor(config, calibration_path, constraint, objective, pressure_kpa, estimate=True, bandwidth_hz=None,
                   load=None, adapt=False, config_path=None):
    """The :class:`~bendsense.pipeline.LiveProcessor` of ``record`` and ``live``, its kernels ready.

    The kernels compile (first run after an install) or load here, before a port opens
    (:meth:`~bendsense.pipeline.LiveProcessor.warm_up`). A gripper config gives a
    :class:`~bendsense.pipeline.gripper.GripperProcessor` (a processor per finger).

    Parameters
    ----------
    config : Config or GripperConfig
        Sensor and actuator configuration (a gripper's: its fingers').
    calibration_path : path, or what :func:`bendsense.session.fingers.calibrations` takes
        Calibration YAML (a gripper: one for every finger, or a mapping finger name →
        calibration).
    constraint, objective : str or None
        Force estimate options; None takes the config's.
    pressure_kpa : float or None
        Constant pressure for a board without a pressure reading [kPa].
    estimate : bool, default True
        Estimate the tip forces (and track them causally, :class:`bendsense.tracking.Tracker`);
        False reconstructs shapes only.
    bandwidth_hz : float or None
        Bandwidth of the track [Hz]; None: the tracker's default.
    load : dict, optional
        The load options (:func:`~bendsense.cli._common.live_contact`): a contact at a
        known location; None or empty: the tip.
    adapt : bool, default False
        ``--adapt``: learn the free-bending model as frames arrive (a single actuator only,
        its config with a prior).
    config_path : path, optional
        The config's file, named when ``adapt`` finds no prior in it.
    """
    from bendsense.config import GripperConfig
    from bendsense.pipeline import LiveProcessor
    from bendsense.pipeline.gripper import GripperProcessor

    gripper = isinstance(config, GripperConfig)
    if adapt and gripper:
        raise click.BadParameter("learns a single actuator's model: give a single actuator's config (a gripper's "
                                 "fingers: bendsense process --adapt on each finger's recording)",
                                 param_hint="'--adapt'")
    if adapt:
        require_prior(config, config_path)
    processor = (GripperProcessor if gripper else LiveProcessor)(
        calibration_path if gripper else checked_calibration(calibration_path, config),
        config,
        constraint=constraint,
        objective=objective,
        pressure_pa=None if pressure_kpa is None else pressure_kpa * 1e3,
        estimate=estimate,
        bandwidth_hz=bandwidth_hz,
        **(load or {}),
        **({"adapt": True} if adapt else {}),
    )
    import warnings

    from bendsense.errors import NoParameterCovarianceWarning

    # the warm-up's estimate gives the library's once-per-process warning: said as one WARNING line instead
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoParameterCovarianceWarning)
        processor.warm_up()
    if estimate:  # a gripper: said once, of the first finger that declares none
        log_no_parameter_covariance(next((f.config for f in config.fingers if f.config.parameter_covariance is None),
                                         None) if gripper else config)
    return processor


def live_load(load: str, contact_s_m, config) -> dict:
    """The load options of ``record --estimate``, ``live``, ``control`` (:func:`~bendsense.cli._common.live_contact`).

    A gripper's locations are per finger (``--contact-s-m NAME=S_C``, a plain S_C for every
    finger not named; :func:`~bendsense.cli._common.contact_locations`), each checked
    against its finger's length.

    Parameters
    ----------
    load : str
        ``--load``.
    contact_s_m : tuple of (str or None, float)
        ``--contact-s-m`` (:class:`~bendsense.cli._common.ContactSpec`).
    config : Config or GripperConfig
        The actuator (or the fingers) whose length bounds it.

    Returns
    -------
    dict
        A single actuator's options of :class:`~bendsense.pipeline.LiveProcessor`; a
        gripper's ``{"finger_options": {finger: options}}`` of
        :class:`~bendsense.pipeline.gripper.GripperProcessor`.
    """
    from bendsense.config import GripperConfig

    locations = contact_locations(contact_s_m, config, load)
    if not isinstance(config, GripperConfig):
        return live_contact(load, locations, config)
    options = {}
    for finger in config.fingers:
        try:
            options[finger.name] = live_contact(load, locations[finger.name], finger.config)
        except click.BadParameter as err:
            raise click.BadParameter(f"finger {finger.name}: {err.message}", param_hint="'--contact-s-m'") from None
    return {"finger_options": options}


def results_paths(output: Path, config):
    """Where ``record --estimate`` writes: ``SESSION/results.csv``, a gripper's ``SESSION/<finger>/results.csv``.

    Parameters
    ----------
    output : Path
        The session directory.
    config : Config, GripperConfig or None
        The config estimated with.
    """
    from bendsense.config import GripperConfig

    if isinstance(config, GripperConfig):
        return {name: output / name / "results.csv" for name in config.names}
    return output / "results.csv"


def wait_for_consumer(outlets, timeout_s: float) -> None:
    """Wait up to ``timeout_s`` for an LSL consumer, so that it receives the first frames too.

    Parameters
    ----------
    outlets : LslOutlets
        The LSL outlets.
    timeout_s : float
        Longest wait [s]; 0 or less does not wait.
    """
    end = time.monotonic() + max(0.0, timeout_s)
    if not quiet() and timeout_s > 0:
        names = [f"bendsense-force-{name}" for name in outlets.outlets] if hasattr(outlets, "outlets") else []
        click.echo(f"waiting up to {timeout_s:g} s for an LSL consumer of {', '.join(names) or 'bendsense-force'} ...",
                   err=True)
    while time.monotonic() < end and not outlets.have_consumers():
        time.sleep(0.05)


def make_outlets(processor, driver, port):
    """The LSL outlets of ``--lsl`` (nominal rate: the board's HELLO, else irregular).

    Parameters
    ----------
    processor : LiveProcessor or GripperProcessor
        Gives the channel count and the estimate options for the streams' metadata (a
        gripper: :class:`~bendsense.interop.lsl.GripperOutlets`, two streams per finger).
    driver : Driver
        The board's driver (its HELLO gives the nominal rate).
    port : str
        The board's port, part of the streams' source id.
    """
    from bendsense.interop.lsl import GripperOutlets, LslOutlets

    rate = 0.0 if driver.hello is None else float(driver.hello.rate_hz)
    fingers = getattr(processor, "processors", None)  # a gripper's: the fingers share the options
    first = processor if fingers is None else next(iter(fingers.values()))
    meta = {"constraint": first.constraint, "method": first.method, "objective": first.objective}
    contact = first.options.get("load") == "contact"
    if contact:
        meta.update(load="contact", contact_s_m=f"{first.options['contact_s_m']:g} (known)")
    if first.tracker is not None:
        meta["track"] = f"filter, bandwidth {first.tracker.bandwidth_hz:g} Hz"
    if fingers is not None:  # each finger's streams tell its own location
        return GripperOutlets({name: p.config.sensor.n_segments for name, p in fingers.items()}, rate,
                              source_id=f"bendsense {port}", meta=meta, tracked=first.track, contact=contact,
                              finger_meta={name: {"contact_s_m": f"{p.options['contact_s_m']:g} (known)"}
                                           for name, p in fingers.items() if contact})
    return LslOutlets(processor.config.sensor.n_segments, rate, source_id=f"bendsense {port}", meta=meta,
                      tracked=processor.track, contact=contact)


@click.command("record", cls=InterspersedCommand)
@click.argument("port")
@click.option(
    "-o", "--output", required=True, type=Directory(), help="Session directory."
)
@click.option("--seconds", type=Finite(min=0, min_open=True), help="Recording time [s] (default: until Ctrl-C).")
@make_overwrite_option("Replace an existing session.")
@click.option("--baud", type=click.IntRange(50, 12_000_000), default=None,
              help="Baud rate, 50..12000000 (default 921600; USB CDC ignores it).")
@click.option("--dialect", type=click.Choice(["binary", "line"]), default="binary", show_default=True)
@click.option("--channels", type=int, help="Line dialect: number of channels (columns ch1..chN).")
@click.option("--columns", help="Line dialect: comma-separated column layout, e.g. seq,t_us,pressure_pa,ch1,...")
@click.option("--no-handshake", is_flag=True, help="Do not wait for the board's HELLO.")
@click.option("--no-start", is_flag=True, help="Do not send START (free-running board).")
@click.option("--hello-timeout", type=Finite(min=0, min_open=True), default=2.0, show_default=True,
              help="HELLO wait [s].")
@make_config_option("Config YAML to snapshot into meta.yaml (and to estimate with).")
@make_calibration_option("Calibration YAML (needed by --estimate and --lsl).")
@click.option("--estimate", is_flag=True, help="Shape and force of every frame as it arrives, to SESSION/results.csv.")
@constraint_option
@objective_option
@click.option("--pressure-kpa", type=PressureKpa(), help="Pressure for frames without a pressure reading [kPa].")
@live_bandwidth_option
@load_option
@live_contact_option
@adapt_option
@click.option("--lsl", is_flag=True, help="Publish bendsense-force and bendsense-shape on LSL (extra 'lsl').")
@click.option(
    "--lsl-wait",
    type=Finite(min=0),
    default=5.0,
    show_default=True,
    help="With --lsl: wait this long for a consumer (e.g. LabRecorder) before starting the board [s].",
)
@click.option("--quiet-status", is_flag=True, help="No live status line.")
def record(
    port, output, seconds, overwrite, baud, dialect, channels, columns, no_handshake, no_start, hello_timeout,
    config_path, calibration_paths, estimate, constraint, objective, pressure_kpa, bandwidth_hz, load,
    contact_s_m, adapt, lsl, lsl_wait, quiet_status,
):
    """Record the board on PORT to a native session directory.

    PORT is a serial port (/dev/ttyACM0, COM3), a pseudo-terminal path or any
    pyserial URL (rfc2217://HOST:PORT, socket://HOST:PORT, loop://, ...). A live
    status line on stderr counts frames, gaps, errors and firmware drops; Ctrl-C (or
    SIGTERM) stops the recording and leaves a complete session marked finished:
    every frame received is kept (synced to disk), one line says how many, and
    the exit status is 130 (Ctrl-C) or 143 (SIGTERM). A new recording goes to a
    new directory (or --overwrite).

    With --estimate (and --calibration), every frame is reconstructed and its force
    estimated as it arrives, in blocks on a background thread, and appended to
    SESSION/results.csv (the columns of 'estimate track --filter save'; synced at least
    every 0.5 s, so a killed recording keeps its results up to the last second). The
    force is tracked causally (a Kalman filter, --bandwidth-hz), frame by frame as in
    'track --filter'. --load contact --contact-s-m X estimates the force of a contact
    at the known arc length X (results.csv adds contact_s_m, contact_std_m). The status line adds
    the estimation rate and backlog. --lsl publishes the shapes and forces on Lab
    Streaming Layer (waiting up to --lsl-wait seconds for a consumer before the board
    starts, so that LabRecorder gets every frame).

    With a gripper config (--config with fingers:), each finger's frames go to
    SESSION/<finger>/results.csv and its streams are bendsense-force-<finger> and
    bendsense-shape-<finger>; --calibration NAME=CAL.yaml (repeated) gives each finger's
    calibration, a plain --calibration CAL.yaml every finger's.
    """
    from bendsense.cli._common import calibration_paths as resolve_calibrations
    from bendsense.config import load_config
    from bendsense.device.driver import DEFAULT_BAUDRATE, Driver
    from bendsense.device.recorder import Recorder
    from bendsense.errors import BendsenseError

    if dialect == "line" and channels is None and columns is None:
        raise click.BadParameter("the line dialect needs --channels or --columns", param_hint="--channels")
    if (estimate or lsl) and not calibration_paths:
        raise click.BadParameter(f"{'--estimate' if estimate else '--lsl'} needs --calibration CAL.yaml",
                                 param_hint="--calibration")
    if adapt and not estimate:
        raise click.BadParameter("needs --estimate", param_hint="'--adapt'")
    if not lsl and click.get_current_context().get_parameter_source("lsl_wait") == ParameterSource.COMMANDLINE:
        raise click.BadParameter("waits for an LSL consumer: it needs --lsl", param_hint="'--lsl-wait'")
    if (load != "tip" or contact_s_m) and not (estimate or lsl):
        raise click.BadParameter("a load model needs --estimate (or --lsl)",
                                 param_hint="'--load'" if load != "tip" else "'--contact-s-m'")
    cols = [c.strip() for c in columns.split(",")] if columns else None
    show = not quiet_status and not quiet()
    # the session directory is checked and locked before the port is opened, until the command ends
    target = outputs.recording(output, overwrite=overwrite)
    click.get_current_context().with_resource(outputs.reserve([target], [config_path]))
    estimator = None
    drawn = []  # a status line on stderr, which an error ends first

    def progress(stats):
        if show:
            sys.stderr.write("\r" + _status_line(stats, estimator and estimator.stats) + "   ")
            sys.stderr.flush()
            drawn[:] = [True]

    try:
        config = load_config(config_path) if config_path else None
        results_path = results_paths(output, config)
        processor = None
        if estimate or lsl:
            if lsl:  # a missing extra is a one-line error before anything is opened
                from bendsense.errors import require_extra

                require_extra("pylsl", "lsl", "--lsl")
            est_config = config or load_config()
            calibration = resolve_calibrations(calibration_paths, est_config)
            processor = make_processor(est_config, calibration, constraint, objective, pressure_kpa,
                                       bandwidth_hz=bandwidth_hz, load=live_load(load, contact_s_m, est_config),
                                       adapt=adapt, config_path=config_path)
        driver = Driver(port, baudrate=baud or DEFAULT_BAUDRATE, dialect=dialect, columns=cols, n_channels=channels,
                        handshake=not no_handshake, hello_timeout_s=hello_timeout)
        with driver:
            if processor is not None:
                from bendsense.device.estimator import LiveEstimator

                outlets = make_outlets(processor, driver, port) if lsl else None
                if outlets is not None:
                    wait_for_consumer(outlets, lsl_wait)
                estimator = LiveEstimator(processor, outlets=outlets,
                                          results_path=results_path if estimate else None)
            recorder = Recorder(driver, output, overwrite=overwrite, config=config,
                                meta={"command": "bendsense record"},
                                on_records=None if estimator is None else estimator.put,
                                extra_files=_manifest_names(results_path, output) if estimate else [])
            if not no_start:
                driver.start()
            interrupted = None
            try:
                stats = recorder.run(seconds, on_progress=progress)
            except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM: the recorder has closed the session
                stats, interrupted = recorder.stats, err
            finally:  # interrupted: what is still queued is not estimated (it stays in frames.bin)
                est_stats = None if estimator is None else estimator.close(None if interrupted is None else 0.5)
    except BendsenseError:
        if drawn:  # end the status line before the error
            sys.stderr.write("\n")
        raise
    if show:
        sys.stderr.write("\r" + _status_line(stats, est_stats) + "   \n")
    losses = _losses(stats)
    where = _results_where(results_path, output)
    if estimate and est_stats.frames:
        estimated = f"{est_stats.frames} frames estimated to {where}"
    elif estimate:  # as 'save' and 'process', which refuse a session without frames
        estimated = "no frames to estimate: no results.csv written"
    if interrupted is not None:  # one line, by the group: what was kept, exit 130 / 143
        kept = f"kept {stats.records} frames in {output} (synced to disk, session marked finished){losses}"
        if estimate:  # the frames still queued are in frames.bin, not estimated
            kept += f"; {est_stats.frames} of them estimated to {where}"
        _signals.note(interrupted, "; ".join(filter(None, (kept, finish_adapt(processor, output, wait=False)))))
        raise interrupted
    say(f"done: {stats.records} frames written to {output}{losses}", err=True)
    if stats.records == 0 and not stats.skipped:
        log.warning("%s: no sample frames arrived; the recording %s holds none (is the board streaming samples?)",
                    port, output)
    if estimate:
        say(estimated, err=True)
    finish_adapt(processor, output)


def _results_where(results_path, output: Path) -> str:
    """``SESSION/results.csv``, or a gripper's ``SESSION/<finger>/results.csv (fingers a, b)``, for messages."""
    if isinstance(results_path, Path):
        return str(results_path)
    return f"{output / '<finger>' / 'results.csv'} (fingers {', '.join(results_path)})"


def _manifest_names(results_path, output: Path) -> list:
    """The results files of ``record --estimate`` as the session's manifest lists them (relative POSIX paths)."""
    paths = [results_path] if isinstance(results_path, Path) else list(results_path.values())
    return [p.relative_to(output).as_posix() for p in paths]


@click.command("sim-device", cls=InterspersedCommand)
@click.option("--rate", "rate_hz", type=Finite(min=0, min_open=True), default=500.0, show_default=True,
              help="Frame rate [Hz]; at most what a USB full-speed link carries (~22,900 Hz for 16 channels): "
                   "a faster board would only queue frames it cannot send.")
@click.option("--seconds", type=Finite(min=0, min_open=True), help="Run time [s] (default: until Ctrl-C).")
@click.option("--drop", type=Finite(0, 1), default=0.0, show_default=True, help="Probability of a dropped frame.")
@click.option("--corrupt", type=Finite(0, 1), default=0.0, show_default=True, help="Probability of a corrupted frame.")
@click.option("--truncate", type=Finite(0, 1), default=0.0, show_default=True, help="Probability of a truncated frame.")
@click.option("--seed", type=SEED, help="Seed of the fault injection.")
@click.option("--channels", type=int, default=16, show_default=True, help="Number of channels.")
@click.option("--adc-bits", type=int, default=12, show_default=True, help="ADC resolution [bit].")
@click.option(
    "--source",
    type=click.Choice(["sensor", "ramp"]),
    default="sensor",
    show_default=True,
    help="sensor: the virtual sensor (bendsense.sim); ramp: counts that encode the frame index.",
)
@click.option("--autostart", is_flag=True, help="Stream without waiting for START.")
@click.option(
    "--replay",
    "replay_path",
    metavar="SESSION",
    type=click.Path(exists=True, path_type=Path),
    help="Play a recording back (native session directory or session CSV) with its original timing.",
)
@click.option("--speed", type=Finite(min=0, min_open=True), default=1.0, show_default=True,
              help="Replay speed (2: twice as fast).")
@click.option("--loop", is_flag=True, help="Replay: start over after the last frame, until stopped.")
@click.option("--contact-s-m", "contact_s_m", type=ContactLocation(),
              help="sensor: where the simulated touches land: an arc length s_c [m] along the body (0 < s_c <= L), "
                   "or 'along-body' (each touch somewhere else: 0.5, 0.7, 0.85, 1.0, 0.6, 0.9 L); default the tip.")
@grasp_options
@model_error_options
@noise_option
@click.option("--truth", "truth_path", metavar="FILE.csv", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the simulator's truth of every frame as it is sent: seq, t_us, then per finger "
                   "<finger>_fx_n, <finger>_fy_n, <finger>_contact_s_m and per line line<k>_setpoint_pa, "
                   "line<k>_pressure_pa (one actuator: fx_n, fy_n, contact_s_m, setpoint_pa, pressure_pa).")
@click.option("--watchdog-ms", type=Finite(min=0),
              help="--source sensor: the host-silence watchdog [ms] (default 1000; 0: none). A host that holds a "
                   "line at a non-zero set-point and then sends no frame (SETPOINT, HEARTBEAT, any) for this long "
                   "gets set-point 0 on every line and a TEXT frame saying so; its next non-zero SETPOINT re-arms it.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --truth file that bendsense wrote.")
def sim_device(
    rate_hz, seconds, drop, corrupt, truncate, seed, channels, adc_bits, source, autostart, replay_path, speed, loop,
    contact_s_m, truth_path, watchdog_ms, overwrite, ei_error, k0_error, base_rotation, hysteresis_kpa, noise_counts,
    **grasp,
):
    """Run a simulated sensor board on a pseudo-terminal and print its port path.

    Open the printed path with 'bendsense record PATH -o SESSION' or 'live'. Runs
    until Ctrl-C (or SIGTERM) or for --seconds. With --replay SESSION the board sends
    the recorded frames (counts, pressure, status, sequence numbers and device clock)
    at their recorded times; after the last one (unless --loop) it says so on stderr
    and keeps the port open and silent, like BrainFlow's playback board, so that a
    client ends its recording when it chooses instead of seeing the board unplugged.

    The single actuator (no --fingers, no --object) plays the time-varying scenario
    (a pressure ramp with touches at the tip) until the host sends a SETPOINT on line 0;
    from then on the actuator is free and its pressure regulator (a first-order lag with
    limits) follows the host. With --fingers K the board is a simulated gripper whose
    fingers close on an object (--object rigid or compliant): one regulator per finger
    follows the scenario's closing profile until the host sends that line a SETPOINT.
    --object without --fingers: the single actuator presses the object. The watchdog sets
    every line to 0 when a host that drove one falls silent for --watchdog-ms ('bendsense
    control' sends a HEARTBEAT every 50 ms).

    --ei-error, --k0-error, --base-rotation, --hysteresis-kpa: the simulated actuator
    (every finger) departs from the config the host uses, as in 'bendsense simulate';
    --truth records its true force and pressures.
    """
    errors = model_errors(ei_error, k0_error, base_rotation, hysteresis_kpa)
    if noise_counts is not None:  # the sensor's, with the model errors to every simulated finger
        errors["noise_counts"] = noise_counts
    if not speed > 0:
        raise click.BadParameter(f"expected > 0, got {speed:g}", param_hint="--speed")
    if replay_path is not None:
        from bendsense.device.replay import ReplayDevice

        ctx = click.get_current_context()
        for name, flag in (("rate_hz", "--rate"), ("channels", "--channels"), ("adc_bits", "--adc-bits"),
                           ("source", "--source"), ("contact_s_m", "--contact-s-m")):
            if ctx.get_parameter_source(name) is click.core.ParameterSource.COMMANDLINE:
                raise click.UsageError(f"{flag} does not apply to --replay: the recording gives it "
                                       "(--speed changes the pace)")
        for name in ("truth_path", "watchdog_ms", "ei_error", "k0_error", "base_rotation", "hysteresis_kpa",
                     "noise_counts", *grasp):
            if ctx.get_parameter_source(name) is click.core.ParameterSource.COMMANDLINE:
                flag = {"truth_path": "--truth", "object_kind": "--object"}.get(name, "--" + name.replace("_", "-"))
                raise click.UsageError(f"{flag} does not apply to --replay: a recording is played back, not "
                                       "simulated")

        from bendsense.device.simdevice import Faults

        faults = Faults(drop=drop, corrupt=corrupt, truncate=truncate, seed=seed)
        dev = ReplayDevice(replay_path, speed=speed, loop=loop, faults=faults, autostart=autostart)
        return _serve(dev, seconds, replay=True)
    if speed != 1.0 or loop:
        raise click.BadParameter("--speed and --loop need --replay SESSION", param_hint="--speed/--loop")
    if not 1 <= channels <= 64:
        raise click.BadParameter(f"expected 1..64, got {channels}", param_hint="--channels")
    if not 1 <= adc_bits <= 16:
        raise click.BadParameter(f"expected 1..16, got {adc_bits}", param_hint="--adc-bits")
    from bendsense.device.simdevice import max_rate_hz

    wide = channels if grasp["fingers"] is None else 16 * grasp["fingers"]
    lines = grasp["fingers"] or 0
    if rate_hz > max_rate_hz(wide, lines):
        raise click.BadParameter(f"expected at most {max_rate_hz(wide, lines):,} Hz (what a USB full-speed link "
                                 f"carries for {wide} channels), got {rate_hz:g}", param_hint="--rate")
    if source == "ramp":
        for flag, value in (("--contact-s-m", contact_s_m), ("--truth", truth_path),
                            ("--fingers/--object", grasp["fingers"] or grasp["object_kind"]),
                            ("--watchdog-ms", watchdog_ms), ("--ei-error", ei_error), ("--k0-error", k0_error),
                            ("--base-rotation", base_rotation), ("--hysteresis-kpa", hysteresis_kpa),
                            ("--noise-counts", noise_counts)):
            if value is not None:
                raise click.BadParameter("applies to --source sensor only, not ramp", param_hint=flag)
    _check_grasp_flags(grasp, contact_s_m, channels)
    from bendsense.sim.truth import KIND

    targets = [] if truth_path is None else [outputs.file(truth_path, overwrite=overwrite, replaces=KIND)]
    with outputs.reserve(targets):  # checked before any work, locked while the board runs
        _sim_board(click.get_current_context().params, grasp, errors)


def _check_grasp_flags(grasp, contact_s_m, channels) -> None:
    """Refuse the single actuator's options that a simulated grasp does not take."""
    if grasp["fingers"] is None and grasp["object_kind"] is None:
        return
    ctx = click.get_current_context()
    if contact_s_m is not None:
        raise click.BadParameter("applies to the time-varying scenario; give the object's contact with "
                                 "--object-s-m", param_hint="--contact-s-m")
    if grasp["fingers"] is not None and ctx.get_parameter_source("channels") is click.core.ParameterSource.COMMANDLINE:
        raise click.BadParameter("does not apply to --fingers: each finger has 16 channels", param_hint="--channels")
    if grasp["fingers"] is None and channels != 16:
        raise click.BadParameter(f"--object simulates the paper's 16-channel sensor, got {channels}",
                                 param_hint="--channels")


def _sim_board(given: dict, grasp: dict, errors: dict) -> None:
    """Build the simulated board's source (and truth file) and serve it (``given``: sim-device's options, by name)."""
    from bendsense.cli.sim import grasp_board
    from bendsense.device.simdevice import DEFAULT_WATCHDOG_MS, Faults, SimulatedDevice, ramp_source, scripted_board
    from bendsense.sim.truth import TruthWriter, truth_columns

    rate_hz, seed, adc_bits, channels = given["rate_hz"], given["seed"], given["adc_bits"], given["channels"]
    truth_path, watchdog_ms = given["truth_path"], given["watchdog_ms"]
    board = grasp_board(grasp, rate_hz=rate_hz, seed=seed, adc_bits=adc_bits, errors=errors)
    columns = truth_columns()
    if board is not None:
        src, channels = board, board.n_channels
        columns = truth_columns(board.truth_fingers, board.n_lines)
    elif given["source"] == "ramp":
        src = ramp_source(channels, adc_bits)
    else:
        src = scripted_board(n_channels=channels, adc_bits=adc_bits, rate_hz=rate_hz, seed=seed,
                             contact_s_m=given["contact_s_m"], truth=truth_path is not None, **errors)
    truth = None if truth_path is None else TruthWriter(truth_path, columns)
    dev = SimulatedDevice(
        src,
        rate_hz=rate_hz,
        n_channels=channels,
        adc_bits=adc_bits,
        faults=Faults(drop=given["drop"], corrupt=given["corrupt"], truncate=given["truncate"], seed=seed),
        autostart=given["autostart"],
        truth=truth,
        watchdog_ms=DEFAULT_WATCHDOG_MS if watchdog_ms is None else watchdog_ms,
    )
    try:
        _serve(dev, given["seconds"])
    finally:
        if truth is not None:
            truth.close()


def _serve(dev, seconds, *, replay: bool = False) -> None:
    """Print the board's port, run it until --seconds pass or Ctrl-C (or SIGTERM), and print its counts.

    A board ends early when its device fails; a replay that has sent its last frame
    says so once and stays open and silent (a real board unplugged is what a client
    reports as an error: a finished replay is not one).
    """
    click.echo(dev.port)
    sys.stdout.flush()
    end = None if seconds is None else time.monotonic() + seconds
    announced = False
    try:
        with dev:  # Ctrl-C and SIGTERM raise KeyboardInterrupt (bendsense.cli._signals)
            while end is None or time.monotonic() < end:
                if dev.finished.is_set():
                    if not replay or dev.stats.disconnected:
                        break
                    if not announced:
                        until = "Ctrl-C" if end is None else "Ctrl-C or the end of --seconds"
                        click.echo(f"replay finished: {dev.stats.sent} frames sent; the port stays open, "
                                   f"without data, until {until}", err=True)
                        announced = True
                time.sleep(0.05)
    except KeyboardInterrupt:
        pass
    s = dev.stats
    click.echo(
        f"generated {s.generated}  sent {s.sent}  dropped {s.dropped}  corrupted {s.corrupted}  "
        f"truncated {s.truncated}  tx overflow {s.tx_overflow}" + (f"  setpoints {s.setpoints}" if s.setpoints else "")
        + (f"  watchdog trips {s.watchdog_trips}" if s.watchdog_trips else ""),
        err=True,
    )


COMMANDS = [devices, record, sim_device]
