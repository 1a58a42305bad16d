"""Commands ``live`` (shape and force of a board, live) and ``demo`` (the whole chain, simulated)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from bendsense.cli import _signals
from bendsense.cli._common import (
    SEED,
    Directory,
    Finite,
    InterspersedCommand,
    PressureKpa,
    check_figure_suffix,
    config_option,
    constraint_option,
    data_warnings_logged,
    live_bandwidth_option,
    live_contact_option,
    load_option,
    make_calibration_option,
    objective_option,
    overwrite_option,
    quiet,
    say,
)
from bendsense.cli.device import adapt_option

_NO_CALIBRATION = (
    "live needs a sensor calibration: --calibration CAL.yaml (make one with "
    "'bendsense calibrate MANIFEST.yaml -o CAL.yaml', or run 'bendsense demo' and use "
    "bendsense-demo/calibration/calibration.yaml for the simulated board)"
)


@click.command("live", cls=InterspersedCommand)
@click.argument("port")
@config_option
@make_calibration_option("Calibration YAML written by 'bendsense calibrate' (required).")
@constraint_option
@objective_option
@click.option(
    "--save",
    "save_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Run headless (no window) and write the last frame to this image, e.g. live.png.",
)
@click.option(
    "--seconds",
    type=Finite(min=0, min_open=True),
    help="Run time [s] (default: until the window is closed; 3 s with --save).",
)
@click.option("--pressure-kpa", type=PressureKpa(), help="Pressure for frames without a pressure reading [kPa].")
@live_bandwidth_option
@load_option
@live_contact_option
@click.option(
    "--scale",
    "scale_mm_per_n",
    type=Finite(min=0, min_open=True),
    default=200.0,
    show_default=True,
    help="Force arrow length [mm per N].",
)
@click.option(
    "--max-fps",
    type=Finite(min=0, min_open=True),
    default=60.0,
    show_default=True,
    help="Upper bound of the display rate [1/s].",
)
@click.option("--baud", type=click.IntRange(50, 12_000_000), default=None,
              help="Baud rate, 50..12000000 (default 921600; USB CDC ignores it).")
@click.option("--no-start", is_flag=True, help="Do not send START (free-running board).")
@click.option("--overwrite", is_flag=True, help="Replace an existing --save image.")
@adapt_option
@click.option("--lsl", is_flag=True, help="Publish bendsense-force and bendsense-shape on LSL (extra 'lsl').")
@click.option(
    "--lsl-wait",
    type=Finite(min=0),
    default=5.0,
    show_default=True,
    help="With --lsl: wait this long for a consumer (e.g. LabRecorder) before starting the board [s].",
)
def live(
    port,
    config_path,
    calibration_paths,
    constraint,
    objective,
    save_path,
    seconds,
    pressure_kpa,
    bandwidth_hz,
    load,
    contact_s_m,
    scale_mm_per_n,
    max_fps,
    baud,
    no_start,
    overwrite,
    adapt,
    lsl,
    lsl_wait,
):
    """Show the shape, the tip force (arrow, value and ±σ), the channel levels and a force plot of PORT, live.

    PORT is a serial port (/dev/ttyACM0, COM3), a pseudo-terminal path (from
    'bendsense sim-device') or a pyserial URL. Every frame received is reconstructed
    and its force estimated (in blocks, warm-started from the previous block) and
    tracked causally (a Kalman filter, --bandwidth-hz); the newest is drawn, with the
    tracked Fx, Fy (±2σ) over the per-frame points and the pressure of the last 10 s,
    the estimation rate and the counts of extrapolated, not converged and misfit frames.
    --lsl publishes every frame on Lab Streaming Layer. At the end, the achieved frame
    rate and the end-to-end latency per frame (bytes read to artists drawn) are printed.
    --load contact --contact-s-m X estimates the force of a contact at the known arc
    length X, drawn there on the shape. A gripper config (--config with fingers:) shows
    a panel per finger (its streams: bendsense-force-<finger>, bendsense-shape-<finger>).
    Ctrl-C or SIGTERM stops it with one line and exit status 130 or 143 (no --save image
    then). --adapt learns the actuator's free bending from its free frames as they arrive
    (docs/grasping.md, "A finger that is not the config's").
    """
    if not calibration_paths:
        raise click.ClickException(_NO_CALIBRATION)
    check_figure_suffix(save_path, "--save")
    if save_path is not None:
        from bendsense import output

        # the image is checked (suffix, existing file, --overwrite) and locked before the port is opened
        target = output.file(save_path, overwrite=overwrite, suffixes=output.FIGURE)
        inputs = [*(p for _, p in calibration_paths), config_path]
        click.get_current_context().with_resource(output.reserve([target], inputs))
        import matplotlib

        matplotlib.use("Agg")
        if seconds is None:
            seconds = 3.0
    from bendsense.apps.live_view import run_live
    from bendsense.cli._common import calibration_paths as resolve_calibrations
    from bendsense.cli.device import finish_adapt, live_load, make_outlets, make_processor, wait_for_consumer
    from bendsense.config import load_config
    from bendsense.device.driver import DEFAULT_BAUDRATE, Driver

    # the library's errors (bad options included) become one line in PipelineGroup
    if lsl:  # a missing extra is a one-line error before anything is opened
        from bendsense.errors import require_extra

        require_extra("pylsl", "lsl", "--lsl")
    config = load_config(config_path)
    processor = make_processor(config, resolve_calibrations(calibration_paths, config), constraint, objective,
                               pressure_kpa, bandwidth_hz=bandwidth_hz, load=live_load(load, contact_s_m, config),
                               adapt=adapt, config_path=config_path)
    if save_path is not None:
        view, is_open = _view_class(processor)(processor, headless=True, scale_m_per_n=scale_mm_per_n * 1e-3), None
    else:
        view, is_open = _window(processor, scale_mm_per_n * 1e-3)
    with Driver(port, baudrate=baud or DEFAULT_BAUDRATE) as driver:
        outlets = make_outlets(processor, driver, port) if lsl else None
        if outlets is not None:
            wait_for_consumer(outlets, lsl_wait)
        if not no_start:
            driver.start()
        try:
            with _signals.interrupting():  # a signal's KeyboardInterrupt that a draw or a kernel turned into its error
                stats = run_live(driver, processor, view, duration_s=seconds, max_fps=max_fps, outlets=outlets,
                                 is_open=lambda: not _signals.stopping() and (is_open is None or is_open()))
        except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM: one line by the group, exit 130 / 143
            if save_path is not None:
                _signals.note(err, f"no figure saved ({save_path} is written when --seconds ends)")
            raise
        finally:
            if outlets is not None:
                outlets.close()
    if save_path is not None:
        if stats.frames == 0:
            raise click.ClickException(f"{port}: no frames received; nothing to save")
        view.save(save_path, overwrite=overwrite)
    if stats is not None:
        say(stats.summary())
    finish_adapt(processor)
    if save_path is not None:
        say(f"wrote {save_path}")


def _view_class(processor):
    """The live view of a processor: :class:`LiveView`, a gripper's :class:`GripperView` (a panel per finger)."""
    from bendsense.apps.live_view import GripperView, LiveView

    return GripperView if hasattr(processor, "processors") else LiveView


def _window(processor, scale_m_per_n):
    """An interactive window, or a one-line error when there is no display."""
    import matplotlib
    import matplotlib.pyplot as plt

    backend = matplotlib.get_backend().lower()
    if backend in ("agg", "pdf", "ps", "svg", "cairo", "template") or backend.startswith("module://matplotlib_inline"):
        raise click.ClickException(
            f"no interactive matplotlib backend (got {backend!r}, no display?): use --save FILE.png"
        )
    view = _view_class(processor)(processor, scale_m_per_n=scale_m_per_n)
    plt.show(block=False)
    plt.pause(0.05)
    number = view.figure.number
    return view, lambda: plt.fignum_exists(number)


@click.command("demo", cls=InterspersedCommand)
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=Directory(),
    default="bendsense-demo",
    show_default=True,
    help="Output directory.",
)
@click.option("--seconds", type=Finite(min=0, min_open=True), default=5.0, show_default=True,
              help="Recording time [s].")
@click.option(
    "--rate",
    "rate_hz",
    type=Finite(min=0, min_open=True),
    default=100.0,
    show_default=True,
    help="Frame rate of the simulated board [Hz].",
)
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the virtual sensor.")
@overwrite_option
def demo(out_dir, seconds, rate_hz, seed, overwrite):
    """Run the whole chain on a simulated board, no hardware needed, and check it against the truth.

    Starts a simulated board (the virtual sensor under pressure ramps and an
    intermittent contact force) on a pseudo-terminal, records it with the real driver
    and recorder, calibrates the virtual sensor, reconstructs the shape and estimates
    the tip force of every frame, and writes DIR/session, DIR/results, DIR/demo.png
    with a summary of the force error against the simulated truth.
    """
    from bendsense.device.simdevice import max_rate_hz

    if rate_hz > max_rate_hz(16):  # the demo's board: 16 channels
        raise click.BadParameter(f"expected at most {max_rate_hz(16):,} Hz (what a USB full-speed link carries "
                                 f"for 16 channels), got {rate_hz:g}", param_hint="--rate")
    from bendsense import output
    from bendsense.apps.demo import run_demo
    from bendsense.sim.memory import check_fits
    from bendsense.sim.scenarios import BYTES_PER_FRAME

    # the session is estimated whole in memory, as the time-varying scenario it streams is simulated
    check_fits("--seconds", "demo", round(seconds * rate_hz), BYTES_PER_FRAME["time-varying"], rate_hz)

    target = output.directory(out_dir, overwrite=overwrite)

    silent = quiet()

    bar = None

    def echo(line):
        nonlocal bar
        if bar is not None:  # the recording is over: clear its bar before the next step
            bar.close()
            bar = None
        if not silent:
            click.echo(line, err=True)
            sys.stderr.flush()

    def progress(done, total):
        nonlocal bar
        if silent:
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="frame", desc="recording", file=sys.stderr, leave=False)
        bar.update(done - bar.n)

    try:
        with output.reserve([target]), data_warnings_logged():  # checked and locked before the board starts
            result = run_demo(
                out_dir, seconds=seconds, rate_hz=rate_hz, seed=seed, overwrite=overwrite, echo=echo, progress=progress
            )
    finally:
        if bar is not None:
            bar.close()
    say(result.summary())


COMMANDS = [live, demo]
