"""Chained steps: ``load``, ``reconstruct``, ``adapt``, ``estimate``, ``track``, ``save``, ``mcap``, ``export``.

Each step returns a function of the pipeline state; the group runs them in the
order given on the command line::

    bendsense load run.csv --calibration cal.yaml reconstruct estimate --constraint normal track save out/
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import click

from bendsense import output
from bendsense.cli import _signals
from bendsense.cli._common import (
    ANGLE_SOURCES,
    METHODS,
    Directory,
    Finite,
    InterspersedCommand,
    PressureKpa,
    bandwidth_option,
    chain_contact_option,
    config_option,
    constraint_option,
    contact_locations,
    data_warnings_logged,
    finger_contact,
    load_option,
    log_no_parameter_covariance,
    make_calibration_option,
    objective_option,
    overwrite_option,
    require_prior,
    say,
    step_io,
    window_option,
)
from bendsense.cli.gripper import finger_parts, is_gripper, per_finger
from bendsense.errors import BendsenseError, SessionError

log = logging.getLogger("bendsense")

RESULTS_FILES = ("results.csv", "shape.npz", "config.yaml")  # what 'save' writes into its directory (the last: after
# 'adapt')
DEFAULT_WINDOW_S = 0.05  # the window of the model check over frames (bendsense.check_windows) [s]


class _Interrupted(click.ClickException):
    """A stop signal on its way from the steps to :meth:`PipelineGroup.main` (past click's own handling)."""


class PipelineGroup(click.Group):
    """A chained group that runs pipeline steps in order and turns user errors into one line.

    Every command of ``bendsense`` runs inside :meth:`invoke`, so the commands leave
    these errors to it and catch only what needs a message of their own.
    """

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """Run the command line; every user mistake is one ``Error:`` line on stderr.

        click prints a usage block and a hint above the error of a bad option; here
        the error stays one line (``Error: Invalid value for '--seed': ...``), with
        exit code 2 for usage errors and 1 for the others.

        Parameters
        ----------
        args : list of str, optional
            The command line; None reads ``sys.argv``.
        prog_name, complete_var : str, optional
            As for :meth:`click.Group.main`.
        standalone_mode : bool, default True
            Exit with the exit code instead of returning (click's meaning).
        **extra
            Passed to :meth:`click.Group.main`.
        """
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        with _signals.installed():  # until the last line is out: a second Ctrl-C does not cut it short
            try:
                rv = super().main(args, prog_name, complete_var, False, **extra)
            except _Interrupted as err:
                click.echo(_signals.message(err.__cause__), err=True)
                sys.exit(_signals.exit_code())
            except click.ClickException as err:
                click.echo(f"Error: {' '.join(err.format_message().split())}", err=True)
                sys.exit(err.exit_code)
            except click.Abort as err:
                if isinstance(err.__context__, KeyboardInterrupt):  # a stop signal outside the chain's steps
                    click.echo(_signals.message(err.__context__), err=True)
                    sys.exit(_signals.exit_code())
                click.echo("Aborted!", err=True)
                sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)

    def invoke(self, ctx):
        """Invoke the chain; a user mistake becomes one ``Error:`` line and exit code 1.

        Parameters
        ----------
        ctx : click.Context
            The command line's context.
        """
        try:
            with _signals.interrupting(returned=False):  # an error after a stop signal: its KeyboardInterrupt, turned
                return super().invoke(ctx)  # into another error by a call under the command
        except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM (_signals): one line, exit 130 / 143 in main
            raise _Interrupted("interrupted") from err
        except BendsenseError as err:
            raise click.ClickException(str(err)) from None
        except FileExistsError as err:  # outputs that need --overwrite; the library's message says so
            raise click.ClickException(str(err)) from None
        except FileNotFoundError as err:
            raise click.ClickException(f"{err.filename}: no such file or directory") from None
        except PermissionError as err:
            raise click.ClickException(f"{err.filename}: permission denied") from None
        except OSError as err:  # the file system says no (a full disk, a file-size limit, ...): one line
            if err.errno is None:
                raise
            where = next((str(n) for n in (err.filename, err.filename2) if n is not None), None)
            text = output.reason(err)
            raise click.ClickException(f"{where}: {text}" if where else text) from None


def _require(state: dict, key: str, step: str, hint: str) -> object:
    if state.get(key) is None:
        raise click.UsageError(f"'{step}' needs {hint} earlier in the chain")
    return state[key]


def run_steps(steps) -> dict:
    """Run the chained steps (functions of the state dict) in order.

    Every output of every step is checked and locked first (:func:`bendsense.output.reserve`),
    against the inputs of all steps, so that a bad output path stops the command before
    any work and nothing is half-done. What a step reads after an earlier step wrote it
    (``save out plot out -o fig.png``) is the chain's own product, not an input.

    Parameters
    ----------
    steps : list of callable
        The chain's steps, each taking and returning the state dict.
    """
    steps = [step for step in steps if step is not None]
    loads = [step for step in steps if getattr(step, "loads", None) is not None]
    if len(loads) > 1:  # a second load would replace the first session without a word
        raise click.UsageError(f"'load' given {len(loads)} times ({', '.join(str(s.loads) for s in loads)}); "
                               "a chain processes one session: use 'bendsense process SESSION... -o OUT' for several")
    # two steps writing one file (save out, then export out/results.csv): refused before any work
    output.check_steps((getattr(step, "step_name", None) or "step", getattr(step, "outputs", ())) for step in steps)
    targets, inputs, written = [], [], set()
    for step in steps:
        inputs += [p for p in getattr(step, "inputs", ()) if output.resolve(p) not in written]
        targets += getattr(step, "outputs", ())
        written.update(output.resolve(t.path) for t in getattr(step, "outputs", ()))
    state: dict = {}
    with output.reserve(targets, inputs):
        for i, step in enumerate(steps):
            state = step(state) or state
            if i == 0:  # the session is loaded: what later steps need of it is checked before any work
                for later in steps[1:]:
                    if hasattr(later, "precheck"):
                        later.precheck(state)
    return state


@click.command("load", cls=InterspersedCommand)
@click.argument("session_path", metavar="SESSION", type=click.Path(exists=True, path_type=Path))
@config_option
@make_calibration_option()
@click.option("--pressure-kpa", type=PressureKpa(), help="Constant pressure for frames without a reading [kPa].")
def load(session_path, config_path, calibration_paths, pressure_kpa):
    """Load a session (session CSV or native session directory).

    With a gripper's config (fingers:), the session is the whole board: each later
    step runs on every finger's part (its channels and pressure line), 'save OUT'
    writes OUT/<finger>/results.csv and shape.npz, 'mcap' the topics
    /bendsense/<finger>/..., 'plot' a panel per finger and the grasp.
    """
    given = [p for _, p in calibration_paths]

    def step(state):
        from bendsense.calibration import Calibration
        from bendsense.cli._common import calibration_paths as calibration_paths_for
        from bendsense.config import GripperConfig, load_config
        from bendsense.pipeline import warn_pressure_fallback
        from bendsense.session import read_session

        session = read_session(session_path)
        if len(session) == 0:
            stats = session.meta.get("stats")
            skipped = stats.get("skipped") if isinstance(stats, dict) else None
            why = (f": {skipped} samples were skipped at record time (another channel count or pressure lines than "
                   f"meta.yaml's; see events.log)" if isinstance(skipped, int) and skipped > 0 else "")
            raise SessionError(f"{session_path}: no frames (an empty recording){why}")
        if pressure_kpa is not None:
            warn_pressure_fallback(session, "--pressure-kpa")
            session = session.with_pressure(pressure_kpa * 1e3)
        config = load_config(config_path)
        calibration_path = calibration_paths_for(calibration_paths, config)
        if isinstance(config, GripperConfig):
            from bendsense.cli.gripper import load_fingers

            return load_fingers(state, session, config, calibration_path, session_path.stem)
        state.update(
            session=session,
            config=config,
            calibration=Calibration.load(calibration_path) if calibration_path else None,
            calibration_path=calibration_path,
            config_path=config_path,
            name=session_path.stem,
        )
        log.info("loaded %s: %d frames, %d channels", session_path, len(session), session.n_channels)
        return state

    step.loads = session_path
    return step_io(step, inputs=[session_path, config_path, *given])


@click.command("reconstruct", cls=InterspersedCommand)
@click.option("--points", type=click.IntRange(2, 10000), default=101, show_default=True,
              help="Arc-length samples of the shape along the sensor.")
def reconstruct(points):
    """Reconstruct curvatures and the continuous shape (PCC) of every frame."""

    def step(state):
        from bendsense.pipeline import process

        session = _require(state, "session", "reconstruct", "'load SESSION'")
        calibration = _require(state, "calibration", "reconstruct", "'load ... --calibration CAL.yaml'")
        processed = process(session, state["config"], calibration, estimate=False, points=points,
                            calibration_source=str(state.get("calibration_path") or ""))
        counts = processed.counts()
        if counts.extrapolated:
            log.warning("%d of %d frames outside the calibrated signal range (status 'extrapolated')",
                        counts.extrapolated, len(session))
        if counts.no_shape:
            log.warning("%d of %d frames have no shape (status 'no_shape'): a signal that is not finite, or a "
                        "reading the board flags (input_status: ADC overrun, lock-in saturated, multiplexer settling)",
                        counts.no_shape, len(session))
        if counts.implausible_shape:  # a unit or calibration mistake, not a bend
            log.warning("%d of %d frames: the tip turns by more than a full turn (status 'implausible_shape'): check "
                        "the calibration and the config's sensor", counts.implausible_shape, len(session))
        state["shape"] = processed.shape
        return state

    return per_finger(step)


@click.command("adapt", cls=InterspersedCommand)
def adapt():
    """Learn the actuator's free bending from the session's own free frames (bendsense.adapt).

    The frames with no load (the force estimate ok and inside its 2-sigma ellipse of
    zero, a shape no tip load made) update the config's prior (its
    parameter_covariance): a Bayesian update, the posterior's values and covariance.
    The later steps use the adapted config; 'save OUT' writes it to OUT/config.yaml,
    its provenance (session, frames used, date) in parameter_covariance.source. Give it
    after 'reconstruct', before 'estimate'. A session without free frames teaches
    nothing: a warning says why and the config stays the prior.
    """

    def step(state):
        from bendsense.identify.sessions import adapt as adapt_config

        if is_gripper(state):
            raise click.UsageError("'adapt' takes one actuator's config, not a gripper's (a config with fingers)")
        shape = _require(state, "shape", "adapt", "'reconstruct'")
        if state.get("estimate") is not None:  # it would not use the adapted config: results and config.yaml disagree
            raise click.UsageError("'adapt' goes before 'estimate' (the estimate made would not use the adapted "
                                   "config): ... reconstruct adapt estimate ...")
        if state.get("adapted"):  # the same frames twice would shrink σ for nothing learned
            raise click.UsageError("'adapt' once in a chain: a second would learn from the same frames again")
        require_prior(state["config"], state.get("config_path"))
        session = state["session"]
        with data_warnings_logged(state.setdefault("said", set())):
            result = adapt_config(shape, session.pressure_pa, state["config"], calibration=state["calibration"],
                                  t_s=session.t_s, source=state.get("name"))
        if result.refused:
            log.warning("%s", result.report)
        else:
            say(result.report)
        state.update(config=result.config, adapted=True)
        return state

    return step


@click.command("estimate", cls=InterspersedCommand)
@constraint_option
@click.option("--method", type=click.Choice(METHODS), help="Estimator (default: from the config).")
@objective_option
@click.option("--push-only", is_flag=True, default=None, help="Contact forces only push (u >= 0).")
@click.option("--tip-angle-source", type=click.Choice(ANGLE_SOURCES),
              help="Tip angle of the normal/follower constraints (default: from the config).")
@window_option
@load_option
@chain_contact_option
def estimate(constraint, method, objective, push_only, tip_angle_source, window_s, load, contact_s_m):
    """Estimate the tip force of every frame from its shape and pressure.

    The frames are then checked in windows of --window-s (default 50 ms): a window
    whose mean residual its covariance does not explain (p < 0.001) makes its frames
    'model_misfit' (force kept; column window_p_value of results.csv).

    --load contact: one point force at arc length s_c along the actuator. With
    --contact-s-m X the force of every frame at the known location X (a gripper: NAME=X per
    finger, repeatable; a plain X for every finger not named); without it the
    location is estimated, one per quasi-static window of --window-s, with its σ
    (bendsense.estimate_contact; 'contact_unresolved' where the data cannot place it).
    results.csv adds contact_s_m and contact_std_m after fy_std_n.
    """

    def step(state):
        import warnings

        from bendsense.errors import NoParameterCovarianceWarning
        from bendsense.pipeline import process
        from bendsense.status import Status

        shape = _require(state, "shape", "estimate", "'reconstruct'")
        session = state["session"]
        config = state["config"]
        where = finger_contact(contact_s_m, state, load)
        # a bad option combination (e.g. --push-only with no constraint) is an
        # ArgumentError, one line through PipelineGroup
        window = DEFAULT_WINDOW_S if window_s is None else window_s
        with warnings.catch_warnings(), data_warnings_logged(state.setdefault("said", set())):
            # said below as one WARNING line per chain, not as a Python warning
            warnings.simplefilter("ignore", NoParameterCovarianceWarning)
            processed = process(session, config, state["calibration"], shape=shape, constraint=constraint,
                                method=method, objective=objective, push_only=push_only,
                                tip_angle_source=tip_angle_source, load=load, contact_s_m=where,
                                calibration_source=str(state.get("calibration_path") or ""), window_s=window)
        if processed.estimate.uncertainty != "none":
            log_no_parameter_covariance(config)
        counts = processed.counts()
        if counts.out_of_range:
            lo, hi = config.actuator.pressure_range_pa
            log.warning("%d of %d frames have a pressure outside actuator.pressure_range_pa %g..%g kPa: no force "
                        "(status '%s')", counts.out_of_range, len(session), lo / 1e3, hi / 1e3,
                        Status.PRESSURE_OUT_OF_RANGE.word)
        if counts.not_converged:
            log.warning("%d of %d frames did not converge (status 'not_converged')", counts.not_converged,
                        len(session))
        if counts.model_misfit:
            log.warning("%d of %d frames: the model does not explain the shape, per frame or over its %g ms window "
                        "(status 'model_misfit', force kept)", counts.model_misfit, len(session), window * 1e3)
        if counts.implausible_force:
            log.warning("%d of %d frames: a force beyond what the actuator can carry (status 'implausible_force', "
                        "force kept): check the units of the config's stiffness and the calibration",
                        counts.implausible_force, len(session))
        if counts.not_identifiable:
            log.warning("%d of %d frames: the shape does not determine the load along one direction (status "
                        "'not_identifiable', σ inf along it; e.g. an axial load on a nearly straight actuator)",
                        counts.not_identifiable, len(session))
        if counts.contact_unresolved:
            log.warning("%d of %d frames: the data cannot place the contact (status 'contact_unresolved', "
                        "contact_std_m inf, force kept)", counts.contact_unresolved, len(session))
        if not counts.ok and len(session):
            log.warning("no frame of %d has status 'ok': no force to use (results.csv's status column says why)",
                        len(session))
        state.update(estimate=processed.estimate, window_s=window, track=None)
        return state

    def precheck(state):
        import numpy as np

        if state.get("config") is not None:  # a bad location stops the chain before any work
            finger_contact(contact_s_m, state, load)
        session = state.get("session")
        if session is not None and not is_gripper(state) and state.get("finger") is None:
            from bendsense.estimation.plausibility import check_one_line

            try:  # a board of several lines read with one actuator's config: before any work
                check_one_line(session)
            except SessionError as err:
                raise click.ClickException(str(err)) from None
        if session is not None and not session.has_pressure:
            missing = int(np.count_nonzero(~np.isfinite(session.pressure_pa)))
            raise click.UsageError(f"{session.source or 'the session'}: {missing} of {len(session)} frames without "
                                   "pressure: give 'load ... --pressure-kpa P'")

    step.precheck = precheck
    fingers = per_finger(step)

    def board(check):  # a gripper's locations (finger names, lengths) are checked on the board, then per finger
        def run(state):
            if is_gripper(state):
                contact_locations(contact_s_m, state["gripper"], load)
            return check(state)
        return run

    run = board(fingers)
    run.precheck = board(fingers.precheck)
    return run


@click.command("track", cls=InterspersedCommand)
@click.option("--smooth/--filter", "smooth", default=True, show_default=True,
              help="Rauch-Tung-Striebel smoother (offline: every frame uses the whole session) or Kalman filter "
                   "(causal: the frame and those before, as 'record --estimate' and 'live').")
@bandwidth_option
@click.option("--window-s", type=Finite(min=0, min_open=True), default=None,
              help="Window of the model check over frames [s]; default: that of 'estimate' (0.05).")
def track(smooth, bandwidth_hz, window_s):
    """Track the tip force over time: a filter or smoother over the per-frame estimates.

    Only the sensor-noise part of each frame's covariance averages down; the
    calibration and model-parameter parts are a bias shared by neighbouring frames
    and are carried through whole, so the tracked σ never falls below them. Frames
    without a force are predicted over; gaps and pressure steps restart the track.
    Adds fx_track_n, fy_track_n, fx_track_std_n, fy_track_std_n and track_status to
    results.csv (after status), the tracked force to the summary figure and
    /bendsense/wrench_tracked to the MCAP file.
    """

    def step(state):
        import numpy as np

        from bendsense.tracking import track as track_forces

        est = _require(state, "estimate", "track", "'estimate'")
        session = state["session"]
        window = state.get("window_s", DEFAULT_WINDOW_S) if window_s is None else window_s
        with data_warnings_logged(state.setdefault("said", set())):
            tracked = track_forces(est, session.t_s, mode="smooth" if smooth else "filter",
                                   bandwidth_hz=bandwidth_hz, window_s=window, pressure_pa=session.pressure_pa)
        log.info("tracked %d frames (%s, bandwidth %.3g Hz)", len(session), tracked.mode, tracked.bandwidth_hz)
        if not np.isfinite(tracked.force_n).any():  # a track of nothing must not pass silently
            log.warning("no tracked force: no frame has a force with a noise covariance (a calibration without "
                        "its flat-recording noise gives no σ, and a track weighs frames by it)")
        state["track"] = tracked
        return state

    return per_finger(step)


@click.command("save", cls=InterspersedCommand)
@click.argument("out_dir", type=Directory())
@overwrite_option
def save(out_dir, overwrite):
    """Write results.csv and shape.npz into OUT_DIR (a gripper: OUT_DIR/<finger>/ for each finger).

    After 'adapt' also config.yaml: the adapted config, its provenance in
    parameter_covariance.source.
    """

    def step(state):
        from bendsense.results import write_results

        if is_gripper(state):  # OUT/<finger>/results.csv and shape.npz, one manifest
            from bendsense.results.gripper import write_gripper_results

            write_gripper_results(out_dir, finger_parts(state, "save"), overwrite=overwrite)
            state["out_dir"] = out_dir
            say(f"wrote {out_dir}/<finger>/results.csv and shape.npz for fingers {', '.join(state['fingers'])} "
                f"({len(state['session'])} frames)")
            return state
        shape = _require(state, "shape", "save", "'reconstruct'")
        write_results(out_dir, state["session"], shape, state.get("estimate"), track=state.get("track"),
                      overwrite=overwrite)
        state["out_dir"] = out_dir
        if state.get("adapted"):
            from bendsense.config import save_config

            save_config(state["config"], out_dir / "config.yaml")
        written = " and config.yaml" if state.get("adapted") else ""
        say(f"wrote {out_dir}/results.csv, shape.npz{written} ({len(state['session'])} frames)")
        return state

    return step_io(step, outputs=[output.directory(out_dir, overwrite=overwrite, files=RESULTS_FILES)])


@click.command("mcap", cls=InterspersedCommand)
@click.argument("mcap_path", metavar="FILE.mcap", type=click.Path(dir_okay=False, path_type=Path))
@overwrite_option
def mcap(mcap_path, overwrite):
    """Write the session and its results as ROS 2 messages to FILE.mcap (extra 'ros').

    Topics /bendsense/wrench (geometry_msgs/msg/WrenchStamped, after 'estimate'),
    /bendsense/force_std, /bendsense/wrench_tracked and /bendsense/force_tracked_std
    (after 'track'), /bendsense/status, /bendsense/shape (nav_msgs/msg/Path) and
    /bendsense/pressure (sensor_msgs/msg/FluidPressure), stamped with the session's time.
    A gripper: the same topics per finger, /bendsense/<finger>/wrench, ... .
    """
    from bendsense.interop.ros2 import require_ros, write_mcap

    require_ros()  # a missing extra stops the command line before any step ran

    def step(state):
        if is_gripper(state):  # one file, topics /bendsense/<finger>/...
            from bendsense.interop.ros2 import write_mcap_fingers

            write_mcap_fingers(mcap_path, finger_parts(state, "mcap"), overwrite=overwrite)
            say(f"wrote {mcap_path} ({len(state['session'])} frames, fingers {', '.join(state['fingers'])})")
            return state
        shape = _require(state, "shape", "mcap", "'reconstruct'")
        write_mcap(mcap_path, state["session"], shape, state.get("estimate"), track=state.get("track"),
                   overwrite=overwrite)
        say(f"wrote {mcap_path} ({len(state['session'])} frames)")
        return state

    return step_io(step, outputs=[output.file(mcap_path, overwrite=overwrite, suffixes=(".mcap",))])


@click.command("export", cls=InterspersedCommand)
@click.argument("csv_path", metavar="FILE.csv", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--finger", metavar="NAME",
              help="A gripper: export this finger's part of the board (its channels and pressure line) as a "
                   "single actuator's session; default: the whole board.")
@overwrite_option
def export(csv_path, finger, overwrite):
    """Export the loaded session as a session CSV."""

    def step(state):
        from bendsense.session import write_session_csv

        session = _require(state, "session", "export", "'load SESSION'")
        if finger is not None:
            if not is_gripper(state):
                raise click.BadParameter("a finger needs a gripper's config ('load ... --config G.yaml' with "
                                         "fingers:)", param_hint="'--finger'")
            session = state["fingers"][state["gripper"].finger(finger).name]["session"]
        write_session_csv(session, csv_path, overwrite=overwrite)
        say(f"wrote {csv_path} ({len(session)} frames)")
        return state

    from bendsense.session.csvfile import KIND

    return step_io(step, outputs=[output.file(csv_path, overwrite=overwrite, suffixes=output.CSV, replaces=KIND)])


COMMANDS = [load, reconstruct, adapt, estimate, track, save, mcap, export]
