"""Batch processing of many recorded sessions on any ``concurrent.futures.Executor``.

:func:`process_sessions` finds the sessions under the given paths, runs the
pipeline (read → reconstruct → estimate → write results) on each of them in
parallel and returns a :class:`BatchReport`. One session per task: a task gets
only paths and small picklable objects (``Config``, ``Calibration``), so the same
code runs on a local process pool and on a Dask cluster::

    from dask.distributed import Client
    report = process_sessions(["runs/"], "out/", calibration=cal,
                              executor=Client("tcp://host:8786").get_executor())

A failing session (a malformed file, a channel count that does not match the
calibration, frames without pressure) is reported with its reason; the others
finish. Outputs that exist are skipped unless ``overwrite``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import errno
import logging
import os
import time
import warnings
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

from bendsense import output
from bendsense._io import check_regular_file
from bendsense.choices import Options
from bendsense.errors import ArgumentError, BendsenseError, DataWarning, OutputError, SessionError
from bendsense.stop_signals import worker_pool

# the output's file system refuses every further session: stop, instead of failing each one
_FATAL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS})

__all__ = ["SessionOutcome", "BatchReport", "discover_sessions", "process_session", "process_sessions"]

STATUSES = ("ok", "skipped", "failed")

log = logging.getLogger("bendsense.batch")


@dataclass(frozen=True, kw_only=True)
class SessionOutcome:
    """What happened to one session of a batch.

    Attributes
    ----------
    name : str
        Session name; its results are in ``out_dir / name``.
    source : str
        Path of the session CSV or native session directory.
    status : str
        ``ok``, ``skipped`` (output exists, no ``overwrite``) or ``failed``.
    frames : int
        Frames processed (0 unless ``ok``).
    seconds : float
        Time spent on the session in its worker, reading to writing [s].
    reason : str
        Why the session failed or was skipped; for ``ok`` sessions a note on frames flagged ``extrapolated``,
        ``not_converged``, ``model_misfit``, ``not_identifiable`` or out of range (empty if none).
    extrapolated : int
        Frames whose signals lay outside the calibrated range.
    not_converged : int
        Frames whose force estimate did not converge.
    model_misfit : int
        Frames whose model shape stays far from the measured one (status ``model_misfit``).
    not_identifiable : int
        Frames whose shape does not determine the load along one direction (status ``not_identifiable``).
    out_of_range : int
        Frames whose pressure lay outside ``actuator.pressure_range_pa`` (no force).
    frames_lost : int
        Frames missing from a native session (gaps in the device's sequence numbers).
    tx_drops : int
        Of those, frames the firmware reported it could not send (``tx_drops``).
    out_dir : str
        Results directory of the session.
    warnings : tuple of str
        What the data could not carry, said while the session was processed (the
        :class:`~bendsense.errors.DataWarning` s: pressures that look like kPa, an unfinished
        recording, ...), whole; the note (``reason``) ends with them, cut to the table's width.
    """

    name: str
    source: str
    status: str
    frames: int = 0
    seconds: float = 0.0
    reason: str = ""
    extrapolated: int = 0
    not_converged: int = 0
    model_misfit: int = 0
    not_identifiable: int = 0
    out_of_range: int = 0
    frames_lost: int = 0
    tx_drops: int = 0
    out_dir: str = ""
    warnings: tuple = ()

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ArgumentError(f"status: must be one of {', '.join(STATUSES)}, got {self.status!r}")


@dataclass(frozen=True, kw_only=True)
class BatchReport:
    """Outcome of :func:`process_sessions`.

    Attributes
    ----------
    sessions : tuple of SessionOutcome
        One row per session, in discovery order.
    out_dir : str
        Root output directory.
    wall_s : float
        Wall-clock time of the whole batch [s].
    workers : str
        Description of the executor that ran it.
    """

    sessions: tuple = field(default_factory=tuple)
    out_dir: str = ""
    wall_s: float = 0.0
    workers: str = ""

    def _count(self, status: str) -> int:
        return sum(1 for s in self.sessions if s.status == status)

    @property
    def n_ok(self) -> int:
        """Sessions processed."""
        return self._count("ok")

    @property
    def n_skipped(self) -> int:
        """Sessions skipped because their output exists."""
        return self._count("skipped")

    @property
    def n_failed(self) -> int:
        """Sessions that failed."""
        return self._count("failed")

    @property
    def failed(self) -> tuple:
        """The failed sessions' rows."""
        return tuple(s for s in self.sessions if s.status == "failed")

    @property
    def ok(self) -> bool:
        """True when no session failed."""
        return self.n_failed == 0

    @property
    def frames(self) -> int:
        """Frames processed over all sessions."""
        return sum(s.frames for s in self.sessions)

    @property
    def frames_per_s(self) -> float:
        """Throughput: frames processed per second of wall-clock time [1/s]."""
        return self.frames / self.wall_s if self.wall_s > 0 else float("nan")

    def to_dict(self) -> dict:
        """Plain dict (for JSON/YAML), with the totals."""
        return {
            "out_dir": self.out_dir,
            "workers": self.workers,
            "wall_s": self.wall_s,
            "frames": self.frames,
            "frames_per_s": self.frames_per_s,
            "ok": self.n_ok,
            "skipped": self.n_skipped,
            "failed": self.n_failed,
            "sessions": [asdict(s) for s in self.sessions],
        }

    def table(self, *, max_reason: int = 100) -> str:
        """Text summary: one line per session, then the totals.

        Parameters
        ----------
        max_reason : int, default 100
            Longest reason shown per session, in characters.
        """
        width = max([len("session")] + [len(s.name) for s in self.sessions])
        lines = [f"{'session':<{width}}  {'status':<7} {'frames':>8} {'time [s]':>9}  note"]
        for s in self.sessions:
            # the row names the session: its path in the note shrinks to the file's name, keeping the reason in view
            reason = " ".join((s.reason.replace(s.source, Path(s.source).name) if s.source else s.reason).split())
            if len(reason) > max_reason:
                reason = reason[: max_reason - 3] + "..."
            frames = f"{s.frames:8d}" if s.status == "ok" else f"{'-':>8}"
            seconds = f"{s.seconds:9.2f}" if s.status != "skipped" else f"{'-':>9}"
            lines.append(f"{s.name:<{width}}  {s.status:<7} {frames} {seconds}  {reason}".rstrip())
        lines.append(
            f"{len(self.sessions)} session{'s' * (len(self.sessions) != 1)}: {self.n_ok} ok, {self.n_skipped} "
            f"skipped, {self.n_failed} failed; "
            f"{self.frames} frames in {self.wall_s:.2f} s ({self.frames_per_s:,.0f} frames/s"
            f"{', ' + self.workers if self.workers else ''})"
        )
        lost = sum(s.frames_lost for s in self.sessions)
        if lost:
            drops = sum(s.tx_drops for s in self.sessions)
            lines.append(f"{lost} frames lost in the recordings ({drops} dropped by the firmware)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()


# --- discovery ----------------------------------------------------------------------------


def _is_session_dir(path: Path) -> bool:
    from bendsense.session.native import is_session_dir

    return is_session_dir(path)


def _inside(path: Path, root: Path | None) -> bool:
    if root is None:
        return False
    try:
        path.resolve().relative_to(root)
    except ValueError:
        return False
    return True


def _search(directory: Path, recursive: bool, exclude: Path | None) -> list[Path]:
    found = []
    for child in sorted(directory.iterdir()):
        if child.name.startswith(".") or _inside(child, exclude):
            continue
        if child.is_dir():
            if _is_session_dir(child):
                found.append(child)
            elif recursive:
                found.extend(_search(child, recursive, exclude))
        elif child.suffix.lower() == ".csv":
            found.append(child)
    return found


def discover_sessions(paths, *, recursive: bool = False, exclude=None) -> list[Path]:
    """Find the sessions under ``paths``.

    Each path is one of

    - a session CSV (any file given explicitly is read as one);
    - a native session directory (holds ``meta.yaml`` or ``frames.bin``);
    - a directory holding sessions: its ``*.csv`` files and session directories,
      one level deep, or at any depth with ``recursive`` (the search does not
      descend into session directories, and skips hidden entries).

    Parameters
    ----------
    paths : path or sequence of paths
        Where to look.
    recursive : bool
        Search directories at any depth.
    exclude : path, optional
        A directory whose contents are never sessions (the output directory, so that
        results written there are not taken for input on the next run).

    Returns
    -------
    list of Path
        In the order given, each directory's entries sorted by name; duplicates removed.

    Raises
    ------
    SessionError
        If a path does not exist, or a session found is neither a regular file nor a
        directory (a FIFO, a device).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    root = Path(exclude).resolve() if exclude is not None else None
    found: list[Path] = []
    for p in map(Path, paths):
        if not p.exists():
            raise SessionError(f"{p}: no such session file or directory")
        if p.is_dir() and not _is_session_dir(p):
            found.extend(_search(p, recursive, root))
        else:
            found.append(p)
    seen, unique = set(), []
    for p in found:
        if not p.is_dir():  # a FIFO or a device would block or never end: refused before any work
            check_regular_file(p, "session (a session CSV or a native session directory)", SessionError)
        key = p.resolve()
        if key not in seen:
            seen.add(key)
            unique.append(p)
    return unique


def session_names(paths) -> list[str]:
    """Output names for sessions: the file stem or directory name, made unique.

    Sessions with the same name get, in turn: a file its suffix (``rec.csv`` beside the
    directory ``rec``: ``rec_csv``, ``rec``); their parent directories' names prepended
    where those differ (``a/run.csv``, ``b/run.csv``: ``a_run``, ``b_run``); then a counter.
    """
    paths = [Path(p) for p in paths]
    names = [p.stem if p.is_file() else p.name for p in paths]

    def tell_apart(make):  # each group of one name renamed by make(i) where that tells its members apart
        for name in [n for n, c in Counter(names).items() if c > 1]:
            group = [i for i, n in enumerate(names) if n == name]
            renamed = [make(i) for i in group]
            if len(set(renamed)) > 1:
                for i, new in zip(group, renamed):
                    names[i] = new

    tell_apart(lambda i: paths[i].name.replace(".", "_") if paths[i].is_file() else names[i])
    base = list(names)
    for depth in range(1, 9):
        if len(set(names)) == len(names):
            break
        parents = [[q.name for q in p.resolve().parents[:depth][::-1] if q.name] for p in paths]
        tell_apart(lambda i, parents=parents: "_".join([*parents[i], base[i]]))
    counts = Counter(names)
    seen: Counter = Counter()
    for i, n in enumerate(names):
        if counts[n] > 1:
            seen[n] += 1
            names[i] = f"{n}_{seen[n]}"
    return names


# --- one session (runs in a worker) -------------------------------------------------------


def process_session(path, out_dir, *, config, calibration, options: Options | None = None, overwrite: bool = False,
                    name: str | None = None) -> SessionOutcome:
    """Process one session and write its results; never raises for a bad session.

    Reads ``path`` (:func:`bendsense.session.read_session`), reconstructs the shapes (paper eq. 1–7)
    and estimates the tip forces (paper eq. 18) unless ``estimate`` is False
    (:func:`bendsense.pipeline.process`), and writes ``results.csv`` and ``shape.npz`` into ``out_dir``
    (:func:`bendsense.results.write_results`): the task :func:`process_sessions` sends to its executor.

    Parameters
    ----------
    path : str or path-like
        The session: a native session directory or a session CSV.
    out_dir : str or path-like
        Output directory of its results.
    config : Config
        Sensor and actuator configuration.
    calibration : Calibration
        Signal → shift calibration of the sensor.
    options : Options, optional
        What to do to the session (:class:`bendsense.choices.Options`: the
        estimate's options, a fallback pressure, tracking, the load model, adapting
        first, which writes ``config.yaml``); None: the defaults.
    overwrite : bool, default False
        Replace a previous bendsense output in ``out_dir``.
    name : str, optional
        Name of the session in the outcome (default: the file or directory name).

    Returns
    -------
    SessionOutcome
        ``failed`` with the error message as reason for a user-level error (:class:`~bendsense.errors.BendsenseError`,
        ``OSError``, ``ValueError``); an unexpected exception is reported with its type. Warnings raised on the way
        (e.g. solver non-convergence) are not propagated: the frames they concern are counted in ``extrapolated``
        and ``not_converged``.

    Raises
    ------
    OutputError
        Only when the output's file system refuses any further write (no space left, quota exceeded, read-only):
        not this session's fault, so the batch stops.
    """
    path, out_dir = Path(path), Path(out_dir)
    name = name or (path.stem if path.is_file() else path.name)
    row = {"name": name, "source": str(path), "out_dir": str(out_dir)}
    start = time.perf_counter()
    try:
        # per-frame problems become the frame's status column; what the data cannot carry joins the note
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("ignore")
            warnings.simplefilter("always", DataWarning)
            counts, lost, tx_drops, pressure_ignored = _run(path, out_dir, config, calibration,
                                                            options or Options(), overwrite)
    except (BendsenseError, OSError) as err:
        if isinstance(err, OutputError) and err.errno in _FATAL_ERRNOS:
            raise  # a full disk is not this session's fault: process_sessions stops
        return SessionOutcome(status="failed", reason=str(err), seconds=time.perf_counter() - start, **row)
    except Exception as err:  # noqa: BLE001 - isolate any failure to its session
        reason = f"{type(err).__name__}: {err}"
        return SessionOutcome(status="failed", reason=reason, seconds=time.perf_counter() - start, **row)
    said = list(dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, DataWarning)))
    return _outcome(counts, lost, tx_drops, pressure_ignored, time.perf_counter() - start, row, said)


def _outcome(counts, lost, tx_drops, pressure_ignored, seconds, row, said=()) -> SessionOutcome:
    """The outcome of a processed session: its counts, and a note of each kind of flagged frame."""
    frames = counts.frames
    # a session processed is listed ok; one without a frame to use says so first
    notes = [] if counts.ok or not frames else [f"no frame ok (0 of {frames})"]
    notes += [f"{n} of {frames} frames {what}" for n, what in (
        (counts.extrapolated, "extrapolated"), (counts.not_converged, "not converged"),
        (counts.model_misfit, "model_misfit"), (counts.not_identifiable, "not identifiable"),
        (counts.implausible_force, "implausible_force"), (counts.contact_unresolved, "contact_unresolved"),
        (counts.out_of_range, "pressure out of range"), (counts.implausible_shape, "implausible_shape"),
        (counts.no_shape, "no_shape")) if n]
    if lost or tx_drops:
        notes.append(f"{lost} frames lost ({tx_drops} dropped by the firmware)")
    if pressure_ignored:
        notes.append("the fallback pressure ignored (every frame has a pressure reading)")
    notes.extend(said)
    return SessionOutcome(status="ok", frames=frames, seconds=seconds, reason=", ".join(notes), warnings=tuple(said),
                          extrapolated=counts.extrapolated, not_converged=counts.not_converged,
                          model_misfit=counts.model_misfit, not_identifiable=counts.not_identifiable,
                          out_of_range=counts.out_of_range, frames_lost=lost, tx_drops=tx_drops, **row)


def _run(path, out_dir, config, calibration, options: Options, overwrite: bool):
    import numpy as np

    from bendsense.batch.fingers import read_noted, run_gripper
    from bendsense.config import save_config
    from bendsense.identify.sessions import adapt_session
    from bendsense.pipeline import process

    if isinstance(calibration, dict):  # a gripper: each finger's part of the board (bendsense.batch.fingers)
        return run_gripper(path, out_dir, config, calibration, options, overwrite)  # (adapt: refused before)
    output.check([output.directory(out_dir, overwrite=overwrite)], [path])
    session = read_noted(path)
    # (a worker's log line would be lost in the console: the session's report row says it)
    ignored = options.pressure_pa is not None and bool(np.isfinite(session.pressure_pa).all())
    adapted = options.adapt and adapt_session(session, config, calibration, options.pressure_pa)
    if adapted and adapted.refused:  # the session's row says so (its note)
        warnings.warn(f"adapt learned nothing, the config's prior used: {adapted.why}", DataWarning, stacklevel=2)
    processed = process(session, config if not adapted else adapted.config, calibration, **options.process_keywords())
    session = processed.session
    processed.write(out_dir, overwrite=overwrite, inputs=[path], source=path)  # the columns process() made
    if adapted:
        save_config(adapted.config, out_dir / "config.yaml")
    return (processed.counts(), int(session.meta.get("frames_lost", 0)), int(session.meta.get("tx_drops", 0)),
            ignored)


# --- many sessions ------------------------------------------------------------------------


def _executor_name(executor) -> str:
    workers = getattr(executor, "_max_workers", None)
    kind = type(executor).__name__
    return f"{kind}({workers} worker{'s' if workers != 1 else ''})" if workers else kind


def _started_quietly():
    """Block the group's stop signals in this thread while workers start: they inherit the mask and ignore them.

    A Ctrl-C meanwhile stays pending and is delivered here when the block ends.
    """
    import threading

    from bendsense.stop_signals import GROUP_SIGNALS, blocked

    if threading.current_thread() is not threading.main_thread():
        return contextlib.nullcontext()
    return blocked(GROUP_SIGNALS)


def _stop_pool(pool: cf.ProcessPoolExecutor) -> None:
    """Kill the pool's worker processes now (an interrupted batch), then shut the pool down."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for proc in processes:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            proc.kill()
    # waits for the pool's manager thread, which sees the workers gone at once; left running, it would race
    # the interpreter's exit (a traceback from concurrent.futures' exit hook)
    pool.shutdown(wait=True, cancel_futures=True)


def _imported() -> None:
    """A local pool worker's first task (:func:`_own_pool`): the modules a session needs imported; no kernel loaded."""
    import bendsense.pipeline  # noqa: F401


def warm_up(config, calibration, options: Options | None = None) -> None:
    """Compile or load the kernels a batch uses, in one worker, before the others load them.

    :func:`process_sessions` runs it as the first task and waits for it (the other workers meanwhile start and
    import, nothing more): on a cold cache (the first run after an install) that worker compiles the kernels
    once, announced on stderr, and writes numba's cache; the other workers then only load it, instead of all
    compiling the same kernels at once. Runs
    :func:`bendsense.pipeline.process` on 100 flat frames (a worker's per-frame kernel) at the middle of the
    pressure range, with the batch's options (``track``: the tracker's kernels too).

    Parameters
    ----------
    config : Config or GripperConfig
        The batch's config.
    calibration : Calibration or dict
        Its calibration, or a gripper's per finger.
    options : Options, optional
        The batch's options (:class:`bendsense.choices.Options`).
    """
    import numpy as np

    from bendsense.batch.fingers import warm_up_finger
    from bendsense.pipeline import process
    from bendsense.session import Session

    config, calibration = warm_up_finger(config, calibration)  # a gripper: its first finger's kernels
    lo, hi = config.actuator.pressure_range_pa
    frames = 100  # more than one warm-started block: the parallel batch kernels, as for any real session
    flat = np.tile(np.asarray(calibration.offset, dtype=float), (frames, 1))
    session = Session(0.01 * np.arange(frames), flat, np.full(frames, 0.5 * (lo + hi)), source="warm-up")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            options = options or Options()
            process(session, config, calibration, constraint=options.constraint, method=options.method,
                    objective=options.objective, estimate=options.estimate,
                    track=options.track if options.estimate else None)
        except (BendsenseError, ValueError) as err:  # a mismatch every session reports itself, under its name
            log.debug("warm-up skipped: %s", err)


def process_sessions(
    paths, out_dir, *, config=None, calibration, executor: cf.Executor | None = None, workers: int | None = None,
    constraint: str | None = None, method: str | None = None, objective: str | None = None, overwrite: bool = False,
    pressure_pa: float | None = None, estimate: bool = True, recursive: bool = False, progress: bool = True,
    track: str | None = None, bandwidth_hz: float | None = None, window_s: float = 0.05, load: str = "tip",
    contact_s_m: float | None = None, adapt: bool = False,
) -> BatchReport:
    """Process many sessions in parallel and write one results directory per session.

    Parameters
    ----------
    paths : path or sequence of paths
        Session CSV files, native session directories, or directories holding them
        (searched one level deep, or at any depth with ``recursive``; see
        :func:`discover_sessions`).
    out_dir : path
        Root output directory; session ``name`` goes to ``out_dir / name``
        (``results.csv``, ``shape.npz``; DESIGN.md section 3). Names are the file stem or
        directory name, made unique (:func:`session_names`).
    config : Config, GripperConfig or path, optional
        Sensor, actuator and estimation settings; default the paper's prototype. A gripper:
        each board session's fingers go to ``out_dir / name / <finger>`` (:mod:`bendsense.batch.fingers`).
    calibration : Calibration, path or dict
        Sensor calibration (a ``Calibration`` or its YAML file); a gripper's as
        :func:`bendsense.session.fingers.calibrations` takes it.
    executor : concurrent.futures.Executor, optional
        Where the sessions run, one task each: e.g. a ``ProcessPoolExecutor``, or a Dask
        cluster's ``Client(...).get_executor()``. It is not shut down. Default: a local
        ``ProcessPoolExecutor`` with ``workers`` processes, shut down at the end.
    workers : int, optional
        Processes of the default pool (default: ``os.cpu_count()``); ``0`` runs the
        sessions one after the other in this process (no executor).
    constraint, method, objective : str, optional
        Force constraint, estimator and objective (default: from ``config.estimation``).
    overwrite : bool
        Reprocess sessions whose output directory exists (default: skip them); a session's directory that holds
        files bendsense did not write is never replaced (that session fails, naming them).
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa].
    estimate : bool
        Estimate the tip forces (False: shapes only).
    recursive : bool
        Search directories at any depth.
    progress : bool
        Show a tqdm progress bar (on stderr).
    track : {"smooth", "filter"}, optional
        Track each session's forces over time (:func:`bendsense.track`); None: not.
    bandwidth_hz : float, optional
        Bandwidth of the track [Hz]; None: chosen per session.
    window_s : float, default 0.05
        Window of the model check over frames (:func:`bendsense.check_windows`) [s].
    load, contact_s_m : str, float, optional
        The load model (``"tip"``, ``"contact"``), a known contact location [m]
        (:mod:`bendsense.estimation.load_models`).
    adapt : bool
        Each session first adapts the config to its own free frames (:func:`process_session`).

    Returns
    -------
    BatchReport
        One row per session (``ok``, ``skipped`` or ``failed`` with the reason) and the
        totals; ``report.table()`` formats it.

    Raises
    ------
    SessionError
        If a path does not exist or no session is found.
    ConfigError
        If the config or the calibration file is invalid.
    OutputError
        If ``out_dir`` may not be written (the working directory or one of its
        ancestors, an input, or another run is writing there; :mod:`bendsense.output`),
        or its file system fills up (or is read-only, or over quota) on the way: the
        batch stops, the sessions written before are kept, and the message says how
        many.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    given = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    inputs = [*given, *(p for p in (config, calibration) if isinstance(p, (str, os.PathLike)))]
    options = Options(constraint=constraint, method=method, objective=objective, pressure_pa=pressure_pa,
                      estimate=estimate, track=track, bandwidth_hz=bandwidth_hz, window_s=window_s, load=load,
                      contact_s_m=contact_s_m, adapt=adapt)
    # the root collects one results directory per session; it is never replaced
    with output.reserve([output.collection(out_dir)], inputs):
        sessions, names, rows, todo = _sessions(given, out_dir, recursive, overwrite)
        if executor is None and workers:  # a pool of ours: each worker holds the process's libraries and kernels
            from bendsense.sim.memory import check_workers

            check_workers(min(workers, len(todo)))
        with _own_pool(executor, workers, len(todo)) as own:  # its workers start while the calibration is prepared
            config, calibration = _prepared(config, calibration, estimate)
            created = _start_collection(out_dir)
            task = dict(config=config, calibration=calibration, options=options, overwrite=overwrite)
            tasks = [(i, sessions[i], names[i]) for i in todo]
            description = _run_tasks(tasks, rows, out_dir, task, executor=executor, own=own, workers=workers,
                                     progress=progress)
            if created and not any(row is not None and row.status == "ok" for row in rows):  # all failed: no empty root
                _drop_collection(out_dir)
        return BatchReport(sessions=tuple(rows), out_dir=str(out_dir), wall_s=time.perf_counter() - start,
                           workers=description)


def _sessions(given, out_dir: Path, recursive: bool, overwrite: bool):
    """The sessions found, their names, the report's rows (those already done filled in) and the indices to do."""
    sessions = discover_sessions(given, recursive=recursive, exclude=out_dir)
    if not sessions:
        raise SessionError(f"no sessions (*.csv files or session directories) found in {', '.join(map(str, given))}")
    names = session_names(sessions)
    return (sessions, names, *_plan(sessions, names, out_dir, overwrite))


def _prepared(config, calibration, estimate: bool):
    """The config (loaded from a path if given one) and the calibration, or a gripper's per finger (errors made)."""
    from bendsense.batch.fingers import prepare
    from bendsense.config import Config, GripperConfig, load_config

    if not isinstance(config, (Config, GripperConfig)):
        config = load_config(config)
    # one calibration, or a gripper's per finger; each with its error model made once when estimating
    return config, prepare(config, calibration, estimate)


def _start_collection(out_dir: Path) -> bool:
    """Create ``out_dir`` (the collection of the results directories) with its manifest; nothing left on failure.

    Returns whether this run created the directory.
    """
    created = not out_dir.exists()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        output._clear_litter(out_dir / output.MANIFEST_NAME)  # a killed run's copy of it, written aside, not renamed
        output.add_to_manifest(out_dir, [], writer="bendsense process")
    except OSError as err:
        if created:  # nothing of ours is left behind
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        if isinstance(err, OutputError):
            raise
        raise output.write_error(out_dir, err) from None
    return created


def _drop_collection(out_dir: Path) -> None:
    """Remove the collection :func:`_start_collection` created, while it holds nothing but its manifest."""
    manifest = out_dir / output.MANIFEST_NAME
    with contextlib.suppress(OSError):
        if [p.name for p in out_dir.iterdir()] == [manifest.name]:
            manifest.unlink()
            out_dir.rmdir()


def _plan(sessions, names, out_dir: Path, overwrite: bool) -> tuple[list, list]:
    """Rows of the sessions skipped or refused before any work, and the indices of those to process."""
    rows: list[SessionOutcome | None] = [None] * len(sessions)
    todo = []
    for i, (path, name) in enumerate(zip(sessions, names, strict=True)):
        target = out_dir / name
        other = _other_source(target, path)
        if other is not None:  # a name made from this batch's sessions may be another batch's: never theirs
            rows[i] = SessionOutcome(
                name=name, source=str(path), status="failed", out_dir=str(target),
                reason=f"output {name} holds the results of another session, {other}; nothing was done (process "
                       "the two in one run, which names their outputs apart, or give another output directory)")
        elif target.exists() and not overwrite:
            rows[i] = SessionOutcome(
                name=name,
                source=str(path),
                status="skipped",
                reason="output exists (--overwrite, or overwrite=True, reprocesses it)",
                out_dir=str(target),
            )
        elif overwrite and target.exists():
            try:  # before any work: never over files bendsense did not write
                output.check([output.directory(target, overwrite=True)], [path])
            except OutputError as err:
                rows[i] = SessionOutcome(name=name, source=str(path), status="failed", reason=str(err),
                                         out_dir=str(target))
                continue
            todo.append(i)
        else:
            todo.append(i)
    for row in rows:  # whole, as a session that fails in the run is said (the table cuts its notes)
        if row is not None and row.status == "failed":
            log.warning("%s: failed: %s", row.name, row.reason)
    return rows, todo


def _other_source(target: Path, path: Path) -> str | None:
    """The session whose results ``target`` holds where its manifest names one other than ``path``; else None."""
    recorded = output.recorded_source(target) if target.is_dir() else None
    return recorded if recorded is not None and recorded != str(output.resolve(path)) else None


@contextlib.contextmanager
def _own_pool(executor, workers, sessions: int):
    """The local pool of a batch given no executor, its workers started; None in-process or with nothing to do.

    Each worker is given a task that only imports (:func:`_imported`): all start at once, beside the parent's
    work before the batch (the calibration's error model), and none loads a kernel (:func:`warm_up` does that
    first, in one of them). Shut down on the way out; killed at once on an error or an interrupt.
    """
    if executor is not None or workers == 0 or sessions == 0:
        yield None
        return
    started = min(workers or os.cpu_count() or 1, sessions)
    pool = worker_pool(started)
    try:
        # a spawn pool starts a worker per task given while none is idle: all of them here, with the signals blocked
        with _started_quietly():
            for _ in range(started):
                pool.submit(_imported)
        yield pool
    except BaseException:
        _stop_pool(pool)
        raise
    finally:
        pool.shutdown(cancel_futures=True)


def _run_tasks(tasks, rows: list, out_dir: Path, task: dict, *, executor, own, workers, progress) -> str:
    """Process the sessions of ``tasks`` ((row index, path, name)) into ``rows``; a description of the workers.

    Interrupted (Ctrl-C, SIGTERM: a KeyboardInterrupt), the local pool's workers are
    killed at once and an external executor's queued tasks cancelled; every session
    finished so far is complete on disk (each is written aside and swapped in), the
    others have no output, and the KeyboardInterrupt goes on up with a note of how many
    finished (a rerun skips them).
    """
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    bar = tqdm(total=len(tasks), unit="session", desc="process", disable=not progress or not tasks, leave=False)
    done: set = set()

    def finish(i, row):
        rows[i] = row
        done.add(i)
        bar.update(1)
        if row.status == "ok":
            output.add_to_manifest(out_dir, [f"{row.name}/"])
        if row.status == "failed" or row.warnings:  # whole, above the progress bar (the table cuts its notes)
            with contextlib.nullcontext() if bar.disable else logging_redirect_tqdm():
                for text in [f"failed: {row.reason}"] if row.status == "failed" else row.warnings:
                    log.warning("%s: %s", row.name, text)

    futures: dict = {}
    earlier = {i: _identity(out_dir / name) for i, _, name in tasks}  # outputs --overwrite replaces
    try:
        if executor is None and workers == 0:
            import numba

            description = f"in-process, {numba.get_num_threads()} numba threads"
            for i, path, name in tasks:
                finish(i, process_session(path, out_dir / name, name=name, **task))
        else:
            executor = own if executor is None else executor
            description = _executor_name(executor) if executor is not None else ""
            if own is not None:
                description = description[:-1] + ", 1 numba thread each)"
            if tasks:
                # compile once: one worker compiles the kernels (or loads them) before any other runs a session, and
                # the others find its cache. Not here: numba's threads in this process would break a forking pool.
                executor.submit(warm_up, task["config"], task["calibration"], task["options"]).result()
            for i, path, name in tasks:  # absolute: a worker may run in another directory (a Dask cluster's)
                future = executor.submit(process_session, Path(path).absolute(), (out_dir / name).absolute(),
                                         name=name, **task)
                futures[future] = (i, path, name)
            for future in cf.as_completed(futures):
                i, path, name = futures[future]
                try:
                    row = future.result()
                except OutputError as err:
                    if err.errno in _FATAL_ERRNOS:
                        raise
                    row = SessionOutcome(name=name, source=str(path), status="failed", reason=str(err),
                                         out_dir=str(out_dir / name))
                except cf.CancelledError:  # the executor cancelled its tasks (a Dask scheduler gone): not the session's
                    raise
                except Exception as err:  # noqa: BLE001 - a worker died or the task could not be sent
                    row = SessionOutcome(
                        name=name,
                        source=str(path),
                        status="failed",
                        reason=f"worker error: {type(err).__name__}: {err}",
                        out_dir=str(out_dir / name),
                    )
                finish(i, row)
    except OutputError as err:
        if err.errno not in _FATAL_ERRNOS:
            raise
        written = sum(1 for row in rows if row is not None and row.status == "ok")
        raise OutputError(f"{err}; processing stopped ({written} of {len(rows)} sessions written before)",
                          errno=err.errno) from None
    except (KeyboardInterrupt, cf.CancelledError) as err:  # stopped, or the executor cancelled the tasks (Dask)
        if own is not None:
            _stop_pool(own)
            own = None
        for future in futures:
            future.cancel()
        err.__notes__ = [*getattr(err, "__notes__", []), _stopped(tasks, rows, done, out_dir, earlier)]
        raise
    finally:
        bar.close()
        if own is not None:
            own.shutdown(cancel_futures=True)
    return description


def _stopped(tasks, rows: list, done: set, out_dir: Path, earlier: dict) -> str:
    """What a batch that stopped (interrupted, or its tasks cancelled) kept, in words.

    Sessions swapped in late are counted and added to the manifest, the unfinished ones' litter cleared.
    """
    # a worker may have swapped a session in just before it was killed: complete, so counted
    late = [name for i, _, name in tasks if i not in done and _identity(out_dir / name) not in (None, earlier[i])]
    if late:
        output.add_to_manifest(out_dir, [f"{name}/" for name in late])
    _clear_unfinished(out_dir, [name for i, _, name in tasks if i not in done and name not in late])
    ok = sum(1 for i, _, _ in tasks if i in done and rows[i].status == "ok") + len(late)
    if any(earlier.values()):  # --overwrite: the sessions not redone keep what an earlier run wrote
        return (f"{ok} of {len(tasks)} sessions redone in {out_dir} (each complete); the others keep their earlier "
                "output (the same command again redoes them all)")
    return (f"{ok} of {len(tasks)} sessions finished in {out_dir} (each complete); the rest have no output: run the "
            "same command again to process them (finished sessions are skipped)")


def _identity(path: Path):
    """Which directory ``path`` is (device, inode), None if none: a session's is swapped in whole, a new one."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


def _clear_unfinished(out_dir: Path, names) -> None:
    """Remove the hidden working copies that killed workers left of the sessions they did not finish."""
    for name in names:
        target = output.resolve(out_dir / name)
        with contextlib.suppress(OSError):
            output._clear_litter(target)
            lock = output._lock_path(target)
            fd = output._try_lock(lock) if lock.exists() else None
            if fd is not None:  # a dead worker's: nobody holds it
                os.unlink(lock)
                os.close(fd)
