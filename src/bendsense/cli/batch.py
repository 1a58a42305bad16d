"""Commands of the batch area: ``process`` (many sessions) and ``plot`` (figures).

``plot`` is also the last step of a processing chain
(``bendsense load run.csv ... reconstruct estimate save out/ plot fig.png``).
"""

from __future__ import annotations

import concurrent.futures
import logging
import os
import re
import threading
import time
from pathlib import Path

import click

from bendsense import output
from bendsense.choices import TRACK_MODES
from bendsense.cli._common import (
    METHODS,
    Directory,
    InterspersedCommand,
    PressureKpa,
    bandwidth_option,
    check_figure_suffix,
    check_load,
    config_option,
    constraint_option,
    contact_option,
    load_option,
    log_no_parameter_covariance,
    make_calibration_option,
    objective_option,
    overwrite_option,
    quiet,
    require_prior,
    say,
    step_io,
    window_option,
)

log = logging.getLogger("bendsense")


WORKER_WAIT_S = 10.0  # how long --scheduler waits for a worker, at the start or when all have left [s]


def _quiet_dask_logs() -> None:
    """Silence Dask's, tornado's and asyncio's loggers, with their children that Dask sets a level on.

    Their connections close under a cluster's feet (a scheduler gone, Ctrl-C) with
    tracebacks, where the batch says what happened in one line.
    """
    quiet_loggers = ("distributed", "tornado", "asyncio")
    for name in [*quiet_loggers, *logging.root.manager.loggerDict]:
        if name.split(".")[0] in quiet_loggers:
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _dask_executor(address: str):
    """Connect to a Dask scheduler; returns (client, executor)."""
    try:
        import dask
        from dask.distributed import Client
        from distributed.comm.registry import backends
    except ImportError:
        raise click.ClickException(
            "--scheduler needs Dask distributed, which is not installed: pip install bendsense[distributed]"
        ) from None
    from bendsense.validation import short

    if re.match(r"https?://", address):  # the dashboard's address, pasted from the browser
        raise click.BadParameter(f"expected the scheduler's tcp://HOST:PORT, got {short(address)} (a web address: "
                                 "the dashboard's, not the scheduler's)", param_hint="--scheduler")
    if not re.fullmatch(r"(?:[a-z][a-z0-9+]*://)?[^\s/:]+:[0-9]{1,5}", address):
        raise click.BadParameter(f"expected tcp://HOST:PORT, got {short(address)}", param_hint="--scheduler")
    scheme = address.split("://")[0] if "://" in address else "tcp"
    if scheme not in backends:
        raise click.BadParameter(f"expected tcp://HOST:PORT, got {short(address)} (Dask knows no {scheme}://; it knows "
                                 f"{', '.join(s + '://' for s in sorted(backends))})", param_hint="--scheduler")
    if scheme in ("tls", "wss") and not dask.config.get("distributed.comm.tls.client.cert", None):
        raise click.BadParameter(f"{short(address)}: {scheme}:// needs Dask's TLS configuration (a client "
                                 "certificate: distributed.comm.tls.client.cert)", param_hint="--scheduler")
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as err:
        raise click.ClickException(f"--scheduler {short(address)}: cannot connect: {err}") from None
    try:  # a scheduler without workers would hold the tasks for ever
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        client.close()
        raise click.ClickException(f"--scheduler {short(address)}: no worker joined it in {WORKER_WAIT_S:g} s (start "
                                   f"one: dask worker {short(address)})") from None
    return client, client.get_executor()


class _WorkerWatch:
    """Cancels a batch's tasks when its Dask scheduler has had no worker for ``WORKER_WAIT_S``.

    The tasks would wait for ever; :attr:`gone` then says why they were cancelled.
    """

    def __init__(self, client, executor):
        self.client, self.executor, self.gone = client, executor, False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bendsense-worker-watch", daemon=True)
        self._thread.start()

    def _run(self):
        since = None
        while not self._stop.wait(min(1.0, WORKER_WAIT_S / 4)):
            try:
                workers = len(self.client.scheduler_info().get("workers", ()))
            except Exception:  # noqa: BLE001 - a lost connection cancels the tasks itself
                continue
            since = None if workers else since or time.monotonic()
            if since is not None and time.monotonic() - since >= WORKER_WAIT_S:
                self.gone = True
                self.executor.shutdown(wait=False)  # cancels the tasks: the batch stops, its finished sessions kept
                return

    def close(self):
        self._stop.set()
        self._thread.join(timeout=2.0)  # (a call to a scheduler gone may hang; the thread is a daemon)


@click.command("process", cls=InterspersedCommand)
@click.argument("paths", metavar="SESSION_OR_DIR...", nargs=-1, required=True,
                type=click.Path(exists=True, path_type=Path))
@make_calibration_option(required=True)
@click.option("-o", "--output", "out_dir", required=True, type=Directory(),
              help="Root output directory; each session's results go to OUT/<session name>/.")
@config_option
@click.option("--workers", type=click.IntRange(0), help="Local worker processes (default: one per CPU; 0: no pool).")
@click.option("--scheduler", metavar="tcp://HOST:PORT",
              help="Run on a Dask distributed scheduler instead (needs bendsense[distributed]).")
@constraint_option
@click.option("--method", type=click.Choice(METHODS), help="Estimator (default: from the config).")
@objective_option
@click.option("--pressure-kpa", type=PressureKpa(), help="Constant pressure for frames without a reading [kPa].")
@click.option("--no-estimate", is_flag=True, help="Reconstruct shapes only, no force estimate.")
@click.option("--adapt", "adapt", is_flag=True,
              help="Each session first updates the config's prior with its own free frames (bendsense.adapt, as "
                   "the chain's 'adapt'); its config goes to OUT/NAME/config.yaml.")
@window_option
@click.option("--track", "track_mode", type=click.Choice(TRACK_MODES),
              help="Track each session's force over time, as the chain's 'track' step: 'smooth' (offline, RTS "
                   "smoother) or 'filter' (causal, Kalman filter); default: no track.")
@bandwidth_option
@load_option
@contact_option
@click.option("-r", "--recursive", is_flag=True, help="Search directories at any depth (default: one level).")
@overwrite_option
@click.option("--no-progress", is_flag=True, help="No progress bar.")
def process(paths, calibration_paths, out_dir, config_path, workers, scheduler, constraint, method, objective,
            pressure_kpa, no_estimate, adapt, window_s, track_mode, bandwidth_hz, load, contact_s_m, recursive,
            overwrite, no_progress):
    """Process many sessions in parallel: reconstruct, estimate and save each one.

    Every SESSION_OR_DIR is a session CSV, a native session directory, or a
    directory holding several (its *.csv files and session directories, one level
    deep; with --recursive at any depth). Session NAME goes to OUT/NAME/results.csv
    and shape.npz; existing outputs are skipped unless --overwrite. A session that
    fails is reported with its reason while the others finish; the exit code is 1
    if any failed. Prints a summary table at the end. Each session's frames are
    model-checked in windows (--window-s, as the chain's 'estimate'); --track adds
    the tracked force (as the chain's 'track' step); --adapt first updates the
    config's prior with each session's own free frames (as the chain's 'adapt') and
    writes that session's config to OUT/NAME/config.yaml. With a gripper's config
    (fingers:) each session is a whole board: its fingers go to
    OUT/NAME/<finger>/results.csv and shape.npz (--calibration NAME=CAL.yaml per
    finger, or one for every finger).

    Ctrl-C or SIGTERM stops the run at once and its workers with it: each session
    finished so far is complete, the others have no output, one line says how many
    finished, and the exit code is 130 (Ctrl-C) or 143 (SIGTERM). Running the same
    command again skips the finished sessions and processes the rest. The kernels
    are compiled (first run after an install) or loaded once, by one worker,
    before the others start.

    \b
    Example:
        bendsense process runs/ --calibration cal.yaml -o out/ --workers 2
        bendsense process runs/ --calibration cal.yaml -o out/ --scheduler tcp://10.0.0.5:8786
    """  # noqa: D301
    calibration_paths_given = calibration_paths

    def step(state):
        from bendsense.batch import process_sessions
        from bendsense.cli._common import calibration_paths

        if scheduler and workers is not None:
            raise click.UsageError("give --workers or --scheduler, not both")
        if no_estimate and (track_mode or bandwidth_hz is not None):
            raise click.UsageError("--track and --bandwidth-hz need the force estimate: not with --no-estimate")
        if bandwidth_hz is not None and not track_mode:
            raise click.UsageError("--bandwidth-hz is the bandwidth of the track: give --track smooth|filter")
        if no_estimate and adapt:
            raise click.UsageError("--adapt learns what the force estimate uses: not with --no-estimate")
        if no_estimate and (load != "tip" or contact_s_m is not None):
            raise click.UsageError("--load and --contact-s-m are options of the force estimate: not with --no-estimate")
        from bendsense.config import load_config

        config = load_config(config_path)  # (a gripper's config: each board session's fingers)
        calibration = calibration_paths(calibration_paths_given, config)
        actuators = [f.config for f in config.fingers] if hasattr(config, "fingers") else [config]
        if adapt and hasattr(config, "fingers"):
            raise click.BadParameter("needs one actuator's config with a prior (parameter_covariance) to update",
                                     param_hint="--adapt")
        if adapt:
            require_prior(config, config_path)
        if contact_s_m is not None:  # a location beyond the actuator is refused here, not once per session
            for actuator in actuators:
                check_load(load, contact_s_m, actuator)
        if not no_estimate and config_path is not None:  # the workers' warnings are silenced: say it here, once
            log_no_parameter_covariance(next((a for a in actuators if a.parameter_covariance is None), None))
        client = executor = watch = None
        if scheduler:
            client, executor = _dask_executor(scheduler)
            _quiet_dask_logs()  # a lost scheduler is one line of ours, not their tracebacks
            watch = _WorkerWatch(client, executor)
        try:
            report = process_sessions(
                paths,
                out_dir,
                config=config,
                calibration=calibration,
                executor=executor,
                workers=workers,
                constraint=constraint,
                method=method,
                objective=objective,
                overwrite=overwrite,
                pressure_pa=None if pressure_kpa is None else pressure_kpa * 1e3,
                estimate=not no_estimate,
                recursive=recursive,
                progress=not no_progress and not quiet(),
                track=track_mode,
                bandwidth_hz=bandwidth_hz,
                window_s=0.05 if window_s is None else window_s,
                load=load,
                contact_s_m=contact_s_m,
                adapt=adapt,
            )
        except concurrent.futures.CancelledError as err:  # the scheduler dropped the client, or has no worker left
            why = (f"no worker left on the scheduler for {WORKER_WAIT_S:g} s" if watch.gone else
                   "the connection to the scheduler was lost")
            kept = "; ".join(getattr(err, "__notes__", ()))  # how many sessions finished (process_sessions)
            raise click.ClickException(f"--scheduler {scheduler}: {why} and its tasks cancelled; {kept}") from None
        finally:
            if watch is not None:
                watch.close()
            if client is not None:
                client.close()
        say(report.table())
        state["batch_report"] = report
        if not report.ok:
            click.echo(f"Error: {report.n_failed} of {len(report.sessions)} sessions failed", err=True)
            click.get_current_context().exit(1)
        return state

    return step_io(step, outputs=[output.collection(out_dir)],
                   inputs=[*paths, *(p for _, p in calibration_paths), config_path])


@click.command("plot", cls=InterspersedCommand)
@click.argument("target", metavar="FIG | RESULTS_DIR", type=click.Path(path_type=Path))
@click.option("-o", "--output", "figure_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Figure file to write when TARGET is a results directory.")
@click.option("--shapes", type=click.IntRange(1, 100), default=8, show_default=True,
              help="Number of frames whose shape is drawn.")
@click.option("--dpi", type=click.IntRange(20, 1200), default=150, show_default=True,
              help="Resolution of raster formats.")
@overwrite_option
def plot(target, figure_path, shapes, dpi, overwrite):
    """Plot a summary figure: shapes and tip path, tip forces, curvatures over time.

    Works in two ways:

    \b
      bendsense plot RESULTS_DIR -o FIG.png
          standalone: plot a results directory written by 'save' or 'process';
      bendsense load run.csv --calibration cal.yaml reconstruct estimate save out/ plot FIG.png
          in a chain: plot the shapes (and forces) computed earlier in the chain.

    With -o the argument is always a results directory; without it, it is the
    figure file and a 'reconstruct' step must come earlier in the chain. The
    format follows the file suffix (.png, .pdf, .svg, ...). Existing figures are
    replaced only with --overwrite.
    """  # noqa: D301
    # os.path.isdir, not Path.is_dir: a name too long for the file system is refused by the output checks
    target_is_dir = os.path.isdir(target)
    if figure_path is not None:
        check_figure_suffix(figure_path, "-o/--output")
    elif not target_is_dir:
        check_figure_suffix(target, "FIG")

    def step(state):
        import matplotlib

        matplotlib.use("Agg")  # files only: never open a window, work without a display
        from bendsense.plots import plot_results, results_from_state

        estimated = None
        if _plot_gripper(state, target, figure_path, shapes, dpi, overwrite):
            return state
        if figure_path is not None:
            if not target.is_dir():
                raise click.BadParameter(f"{target}: {'not a' if target.exists() else 'no such'} results directory",
                                         param_hint="RESULTS_DIR")
            source, out = target, figure_path
        elif state.get("shape") is not None:
            source = results_from_state(state["session"], state["shape"], state.get("estimate"), state.get("track"))
            out = target
            est = state.get("estimate")
            if est is not None:
                estimated = f"constraint {est.constraint}, method {est.method}, objective {est.objective}"
            if state.get("track") is not None:
                tracked = state["track"]
                estimated += f"; tracked: {tracked.mode}, {tracked.bandwidth_hz:.3g} Hz"
        elif target.is_dir():
            raise click.UsageError(f"give the figure file: 'plot {target} -o FIG.png'")
        else:
            raise click.UsageError(
                "'plot FIG' needs 'reconstruct' earlier in the chain; "
                "to plot a results directory use 'plot RESULTS_DIR -o FIG.png'"
            )
        config = state.get("config")
        plot_results(source, out, max_shapes=shapes, dpi=dpi, overwrite=overwrite, estimated=estimated,
                     length_m=None if config is None else config.actuator.length_m)
        say(f"wrote {out}")
        return state

    # the figure is checked (suffix, existing file, --overwrite) before any step runs
    if figure_path is not None:
        return step_io(step, outputs=[output.file(figure_path, overwrite=overwrite, suffixes=output.FIGURE)],
                       inputs=[target])
    if target_is_dir:  # not a figure: the step says how to plot a results directory
        return step
    return step_io(step, outputs=[output.file(target, overwrite=overwrite, suffixes=output.FIGURE)])


def _plot_gripper(state, target, figure_path, shapes, dpi, overwrite) -> bool:
    """``plot`` of a gripper (a panel per finger and the grasp): its chain, or its results directory."""
    from bendsense.cli.gripper import finger_parts, is_gripper
    from bendsense.plots.gripper import plot_gripper
    from bendsense.results.gripper import is_gripper_results

    if figure_path is not None and is_gripper_results(target):
        plot_gripper(target, figure_path, max_shapes=shapes, dpi=dpi, overwrite=overwrite)
        say(f"wrote {figure_path}")
        return True
    if figure_path is not None or not is_gripper(state):
        return False
    from bendsense.plots import results_from_state

    results = {name: results_from_state(*part) for name, part in finger_parts(state, "plot").items()}
    lengths = {f.name: f.config.actuator.length_m for f in state["gripper"].fingers}
    plot_gripper(results, target, max_shapes=shapes, dpi=dpi, overwrite=overwrite, lengths_m=lengths)
    say(f"wrote {target}")
    return True


COMMANDS = [process, plot]
