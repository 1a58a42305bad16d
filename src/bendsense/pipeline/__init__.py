"""The processing pipeline: signals and pressure → shapes → tip forces, for a session or live.

Two entry points share the same option fallbacks and checks:

- :func:`process` runs a whole :class:`~bendsense.session.Session` at once: it checks the
  session against the calibration and the config, reconstructs the shapes (PCC, paper
  eq. 1–7, one batched call) and estimates the tip forces (eq. 18 and 21, one batched
  :func:`~bendsense.estimation.estimate_force` call), and returns :class:`Processed`,
  the :class:`~bendsense.results.Results` of ``results.csv`` with the objects they came
  from. It is the chain of ``bendsense load ... reconstruct estimate``, of every session
  of ``bendsense process`` (:mod:`bendsense.batch`) and of the demo.
- :class:`LiveProcessor` is the core of ``bendsense record --estimate``, ``live`` and the
  ``--lsl`` streams. It turns a block of frames (raw signals and pressure) into their
  shapes and tip forces, warm-started from the last good estimate of the previous block,
  and returns a :class:`LiveBlock` whose :meth:`~LiveBlock.columns` are those of
  ``results.csv``. A single frame is a block of one; there is no second, one-frame code
  path.

Both take the constraint, method and objective given, else the config's
(:func:`estimation_options`).

The block is what keeps up with fast boards: a warm-started batch costs a fraction of a
millisecond per frame (``docs/performance.md``), so a receiver that processes what
arrived since its last call (a few to a few hundred frames) keeps up with a 2 kHz board
on one core.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from bendsense._batched import concat_frames, expand_frames, put_frames, take_frames
from bendsense.choices import OBJECTIVES
from bendsense.errors import ArgumentError, ConfigError, DataWarning, SessionError
from bendsense.pipeline.readings import ReadingClock
from bendsense.results import Results
from bendsense.status import WORDS, Status, words

log = logging.getLogger("bendsense")

__all__ = [
    "FrameCounts",
    "LiveBlock",
    "LiveFrame",
    "LiveProcessor",
    "LIVE_MAX_ITER",
    "Processed",
    "estimation_options",
    "process",
    "warn_pressure_fallback",
]

#: Iteration limit of a live force estimate. A warm-started frame converges in a few
#: iterations; one that cannot (an unconstrained axial force on the straight actuator
#: does not change its shape) must not stall the stream for 100 beam solves.
LIVE_MAX_ITER = 20


def estimation_options(config, constraint=None, method=None, objective=None) -> tuple[str, str, str]:
    """The constraint, method and objective of a force estimate: those given, else the config's.

    Parameters
    ----------
    config : Config
        Its ``estimation`` section gives the defaults.
    constraint, method, objective : str, optional
        Force constraint (:data:`bendsense.choices.CONSTRAINTS`), estimator
        (:data:`~bendsense.choices.METHODS`) and what the fit compares
        (:data:`~bendsense.choices.OBJECTIVES`); None: the config's. The paper's method
        fits the positions (paper eq. 18), so its default objective is ``positions``.

    Returns
    -------
    tuple of str
        ``(constraint, method, objective)``.

    Raises
    ------
    ArgumentError
        For an objective that is not one of :data:`~bendsense.choices.OBJECTIVES`.
    """
    est = config.estimation
    constraint = est.constraint if constraint is None else constraint
    method = est.method if method is None else method
    if objective is None:
        objective = "positions" if method == "paper" else est.objective
    if objective not in OBJECTIVES:
        raise ArgumentError(f"objective: must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    return constraint, method, objective


# --------------------------------------------------------------------------- a whole session


@dataclass(frozen=True)
class FrameCounts:
    """How many frames of a processed session are flagged, by reason.

    Attributes
    ----------
    frames : int
        Frames processed.
    extrapolated : int
        Frames whose signals lay outside the calibrated range (whatever their status).
    out_of_range : int
        Frames whose pressure lay outside ``actuator.pressure_range_pa`` (no force).
    not_converged : int
        Frames whose force estimate failed, other than those out of range or ``model_misfit``.
    model_misfit : int
        Frames whose model shape stays far from the measured one (status ``model_misfit``).
    not_identifiable : int
        Frames whose shape does not determine the load along one direction (status
        ``not_identifiable``; e.g. an axial load on a nearly straight actuator).
    implausible_force : int
        Frames whose force is beyond what the actuator can carry (status
        ``implausible_force``, force kept).
    contact_unresolved : int
        Frames of a contact load whose location the data cannot place (status
        ``contact_unresolved``, force kept, ``contact_std_m`` inf).
    """

    frames: int
    extrapolated: int = 0
    out_of_range: int = 0
    not_converged: int = 0
    model_misfit: int = 0
    not_identifiable: int = 0
    implausible_force: int = 0
    contact_unresolved: int = 0


@dataclass(frozen=True, eq=False)
class Processed(Results):
    """The results of :func:`process`: the columns of ``results.csv``, and what they were made from.

    Attributes
    ----------
    columns, s_m, positions_m, extra_names
        Those of :class:`~bendsense.results.Results` (``results.csv`` and ``shape.npz``).
    session : Session
        The session processed (with the constant pressure filled in, if one was given).
    shape : Shape
        Reconstructed shapes, batch axis over the session's frames.
    estimate : ForceEstimate or None
        Tip forces of the same frames, window-checked (:func:`bendsense.check_windows`);
        None when not estimated.
    track : Track or None
        Tracked forces of the same frames (:func:`bendsense.track`); None when not tracked.
    config : Config
        The config used.
    reconstruct_s, estimate_s : float
        Wall time of the reconstruction and of the force estimate (0 when not done here) [s].
    """

    session: object = None
    shape: object = None
    estimate: object = None
    track: object = None
    config: object = dataclasses.field(default=None, repr=False)
    reconstruct_s: float = 0.0
    estimate_s: float = 0.0

    def counts(self) -> FrameCounts:
        """Frames flagged: extrapolated, pressure out of range, not converged, model_misfit, not identifiable."""
        from bendsense.estimation.plausibility import pressure_outside
        from bendsense.results import frame_codes

        n = len(self.session)
        extrapolated = int(np.count_nonzero(np.broadcast_to(np.asarray(self.shape.extrapolated), (n,))))
        if self.estimate is None:
            return FrameCounts(frames=n, extrapolated=extrapolated)
        outside = pressure_outside(self.session.pressure_pa, self.config)
        failed = ~np.asarray(self.estimate.success, dtype=bool) & ~outside
        own = np.broadcast_to(np.asarray(self.estimate.status), (n,))
        misfit = failed & (own == Status.MODEL_MISFIT)
        implausible = failed & (own == Status.IMPLAUSIBLE_FORCE)
        codes = frame_codes(self.shape, self.estimate)
        return FrameCounts(frames=n, extrapolated=extrapolated, out_of_range=int(outside.sum()),
                           not_converged=int(np.count_nonzero(failed & ~misfit & ~implausible)),
                           model_misfit=int(misfit.sum()), implausible_force=int(implausible.sum()),
                           not_identifiable=int(np.count_nonzero(codes == Status.NOT_IDENTIFIABLE)),
                           contact_unresolved=int(np.count_nonzero(codes == Status.CONTACT_UNRESOLVED)))


def _source(session) -> str:
    return session.source or "the session"


def warn_pressure_fallback(session, name: str = "pressure_pa") -> None:
    """Warn (one log line) when a fallback pressure ``name`` does not apply to every frame of ``session``.

    The fallback fills only frames without a pressure reading: given for a session
    whose frames all have one, it changes nothing, and a user who meant it to replace
    the recorded pressure must be told.

    Parameters
    ----------
    session : Session
        The session.
    name : str, default "pressure_pa"
        The argument or option, for the message (``"--pressure-kpa"``).
    """
    has = np.isfinite(session.pressure_pa)
    n = int(has.sum())
    if n == len(session):
        log.warning("%s ignored: every frame of %s has a pressure reading (the fallback fills only frames "
                    "without one)", name, _source(session))
    elif n:
        log.warning("%s fills the %d of %d frames of %s without a pressure reading; the other %d keep their "
                    "reading", name, len(session) - n, len(session), _source(session), n)


def process(session, config=None, calibration=None, *, constraint=None, objective=None, method=None,
            pressure_pa=None, estimate: bool = True, points: int | None = None, shape=None,
            push_only: bool | None = None, tip_angle_source: str | None = None, calibration_source: str = "",
            window_s: float = 0.05, track: str | None = None, bandwidth_hz: float | None = None,
            load: str = "tip", contact_s_m: float | None = None, **options) -> Processed:
    """Reconstruct the shapes and estimate the tip forces of every frame of a session.

    Parameters
    ----------
    session : Session or path
        Signals and pressure of the frames (:func:`bendsense.read_session`), or the path
        of a session CSV or native session directory to read. Its ``t_s`` must increase
        strictly (docs/formats.md, "Time").
    config : Config or path, optional
        Sensor, actuator and estimation settings (or the config YAML); default the
        paper's prototype.
    calibration : Calibration or path
        Signal → shift calibration (paper eq. 1–2), or its YAML; required.
    constraint, objective, method : str, optional
        Force constraint, what the fit compares and the estimator; None: the config's
        (:func:`estimation_options`).
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa].
    estimate : bool
        Estimate the tip forces (False: shapes only).
    points : int, optional
        Points of each shape along the sensor (default that of
        :func:`bendsense.shape.pcc.reconstruct`).
    shape : Shape, optional
        The shapes of these frames, reconstructed earlier (the ``reconstruct`` step of a
        command line chain, or another estimate of the same session); None: reconstructed
        here.
    push_only : bool, optional
        Contact forces only push (default ``config.estimation.push_only``).
    tip_angle_source : str, optional
        Tip angle of the ``normal`` and ``follower`` constraints (default the config's).
    calibration_source : str
        Where the calibration came from (its file), named in messages.
    window_s : float, default 0.05
        Window of the model check over frames (:func:`bendsense.check_windows`, run on
        every estimate) and of the track's [s].
    track : {"smooth", "filter"}, optional
        Track the forces over time (:func:`bendsense.track`, that mode); None: no track.
    bandwidth_hz : float, optional
        Bandwidth of the track [Hz]; None: chosen from the session (:func:`bendsense.track`).
    load, contact_s_m : {"tip", "contact"}, float, optional
        The load model (default ``"tip"``); ``"contact"`` with ``contact_s_m`` a known location [m], without it
        one located per window of ``window_s`` (:func:`bendsense.estimation.load_models.estimate_load`).
    **options
        Further options of :func:`bendsense.estimation.estimate_force` (``max_iter``, ...).

    Returns
    -------
    Processed
        The columns of ``results.csv`` (:class:`~bendsense.results.Results`), with the
        session, the shapes and the estimate. Frames whose pressure lies outside
        ``actuator.pressure_range_pa`` have no force (status ``pressure_out_of_range``).

    Raises
    ------
    SessionError
        If the session has no frames, time that does not increase, its channels do not
        match the calibration and the sensor, or (with ``estimate``) frames have no
        pressure and none is given.
    ArgumentError
        For a bad option or an argument of the wrong type (the message names it).
    """
    from bendsense import validation as check
    from bendsense.estimation.plausibility import check_channels, check_one_line, check_time_column
    from bendsense.session.inputs import process_inputs

    session, config, calibration, calibration_source = process_inputs(session, config, calibration,
                                                                      calibration_source)
    check_one_line(session)
    if len(session) == 0:
        raise SessionError(f"{_source(session)}: no frames")
    check_time_column(session.t_s, _source(session), error=ArgumentError if not session.source else SessionError)
    if pressure_pa is not None:
        pressure_pa = check.number("pressure_pa", pressure_pa)
        warn_pressure_fallback(session)
        session = session.with_pressure(pressure_pa)
    check_channels(session, calibration, config.sensor, calibration_source=calibration_source)
    if estimate and not session.has_pressure:
        missing = int(np.count_nonzero(~np.isfinite(session.pressure_pa)))
        raise SessionError(f"{_source(session)}: {missing} of {len(session)} frames have no pressure reading "
                           "(give pressure_pa, or --pressure-kpa on the command line)")
    shape, reconstruct_s = _shapes(session, config, calibration, points, shape)
    est, tracked, estimate_s = None, None, 0.0
    if track is not None and not estimate:
        raise ArgumentError("track: needs the force estimate (estimate=True)")
    if estimate:
        t0 = time.perf_counter()
        est = _estimate(session, shape, config, calibration, window_s, dict(
            options, constraint=constraint, method=method, objective=objective, push_only=push_only,
            tip_angle_source=tip_angle_source, load=load, contact_s_m=contact_s_m))
        est, tracked = _over_time(est, session, window_s, track, bandwidth_hz)
        estimate_s = time.perf_counter() - t0
    results = Results.from_state(session, shape, est, tracked)
    return Processed(**{f.name: getattr(results, f.name) for f in dataclasses.fields(Results)}, session=session,
                     shape=shape, estimate=est, track=tracked, config=config, reconstruct_s=reconstruct_s,
                     estimate_s=estimate_s)


def _estimate(session, shape, config, calibration, window_s, options):
    """The force estimate of the session's frames under the load model of ``options`` (its noise model gives std_n)."""
    from bendsense.estimation.load_models import estimate_load

    options["constraint"], options["method"], options["objective"] = estimation_options(
        config, options["constraint"], options["method"], options["objective"])
    return estimate_load(shape, session.pressure_pa, config, t_s=session.t_s, window_s=window_s,
                         calibration=calibration, **options)


def _shapes(session, config, calibration, points, shape):
    """The session's shapes (those given, checked, else reconstructed) and the time spent [s]."""
    from bendsense.shape.pcc import reconstruct

    if shape is not None:
        if np.shape(shape.tip_angle_rad)[:1] != (len(session),):
            raise ArgumentError(f"shape: expected the shapes of the session's {len(session)} frames, got batch "
                                f"shape {np.shape(shape.tip_angle_rad)}")
        return shape, 0.0
    s_m = None if points is None else np.linspace(0.0, config.sensor.length_m, int(points))
    t0 = time.perf_counter()
    shape = reconstruct(session.signals, calibration, config.sensor, s_m=s_m)
    return shape, time.perf_counter() - t0


def _over_time(est, session, window_s, mode, bandwidth_hz):
    """The estimate window-checked (:func:`bendsense.check_windows`), and its track (None without ``mode``)."""
    from bendsense.tracking import check_windows, track

    est = check_windows(est, session.t_s, window_s=window_s, pressure_pa=session.pressure_pa)
    if mode is None:
        return est, None
    return est, track(est, session.t_s, mode=mode, bandwidth_hz=bandwidth_hz, window_s=window_s,
                      pressure_pa=session.pressure_pa)


# --------------------------------------------------------------------------- as frames arrive


@dataclass(frozen=True, eq=False)
class LiveFrame:
    """One processed frame (a view of one frame of a :class:`LiveBlock`).

    Attributes
    ----------
    seq : int
        Device sequence number (raw, wraps at 65536); -1 if unknown.
    t_s : float
        Device clock [s] (from the first frame the processor saw, when given readings).
    host_ns : int
        Host clock when the frame's bytes were read (``time.monotonic_ns()``) [ns].
    pressure_pa : float
        Pressure [Pa]; NaN without a reading (no force estimate then).
    delta_a : ndarray, shape (N,)
        Offset-free signals ΔA = A − A0 (paper eq. 1) [signal units].
    shape : Shape
        Reconstructed shape of the frame (single frame, no batch axis).
    estimate : ForceEstimate or None
        Tip force of the frame; None without pressure or with estimation off.
    process_s : float
        Wall time of reconstruction and estimation of its block, per frame [s].
    status : str
        The frame's ``status`` in ``results.csv``.
    track_force_n, track_std_n : ndarray, shape (2,) or None
        The causally tracked force and its standard deviation [N] (``fx_track_n``, ...);
        None when the processor does not track.
    """

    seq: int
    t_s: float
    host_ns: int
    pressure_pa: float
    delta_a: np.ndarray
    shape: object
    estimate: object
    process_s: float
    status: str = "ok"
    track_force_n: np.ndarray | None = None
    track_std_n: np.ndarray | None = None

    @property
    def force_n(self) -> np.ndarray:
        """Tip force (Fx, Fy) [N]; NaN when not estimated or not converged."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.force_n, dtype=float)

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviation of (Fx, Fy) [N]; NaN when not estimated."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.std_n, dtype=float)


@dataclass(frozen=True, eq=False)
class LiveBlock:
    """Shapes and force estimates of a block of consecutive frames.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Frame time [s].
    seq : ndarray of int, shape (n,)
        Raw sequence numbers (-1 unknown).
    host_ns : ndarray of int, shape (n,)
        Arrival time of each frame on the host clock (``time.monotonic_ns()``) [ns].
    pressure_pa : ndarray, shape (n,)
        Pressure used [Pa] (the reading, else the processor's fallback); NaN: none.
    signals : ndarray, shape (n, N)
        Raw signals A [signal units].
    shape : Shape
        Shapes, batch axis n.
    estimate : ForceEstimate or None
        Forces, batch axis n; None when estimation is off or no frame has a pressure.
    estimated : bool
        Whether the processor estimates forces (the force columns are then present,
        NaN where there is no estimate).
    process_s : float
        Wall time of the block's reconstruction and estimation [s].
    offset : ndarray, shape (N,)
        The calibration's offsets A0 (for ΔA).
    track : Track or None
        The causally tracked forces of the block (:class:`bendsense.tracking.Tracker`); None when
        the processor does not track or no frame of the block has a force estimate.
    tracked : bool
        Whether the processor tracks the forces (the tracked columns are then present,
        NaN where there is no track).
    load : str
        The processor's load model (``"contact"``: the columns ``contact_s_m, contact_std_m``).
    extra : dict of str to ndarray, shape (n,)
        Per-frame columns the recorded session has beside its own (``Session.extra``:
        ``host_s``, ``status``, ``tx_drops`` of a recording), written after ``status``
        as ``save`` writes them.
    """

    t_s: np.ndarray
    seq: np.ndarray
    host_ns: np.ndarray
    pressure_pa: np.ndarray
    signals: np.ndarray
    shape: object
    estimate: object
    estimated: bool
    process_s: float
    offset: np.ndarray = dataclasses.field(default=None, repr=False)
    track: object = None
    tracked: bool = False
    load: str = "tip"
    extra: dict = dataclasses.field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return self.t_s.size

    @property
    def track_force_n(self) -> np.ndarray:
        """Tracked tip forces (n, 2) [N]; NaN where not tracked."""
        if self.track is None:
            return np.full((len(self), 2), np.nan)
        return np.asarray(self.track.force_n, dtype=float).reshape(len(self), 2)

    @property
    def track_std_n(self) -> np.ndarray:
        """Standard deviations of the tracked forces (n, 2) [N]; NaN where not tracked."""
        if self.track is None:
            return np.full((len(self), 2), np.nan)
        return np.asarray(self.track.std_n, dtype=float).reshape(len(self), 2)

    @property
    def force_n(self) -> np.ndarray:
        """Tip forces (n, 2) [N]; NaN where not estimated or not converged."""
        if self.estimate is None:
            return np.full((len(self), 2), np.nan)
        return np.asarray(self.estimate.force_n, dtype=float).reshape(len(self), 2)

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviations of the forces (n, 2) [N]; NaN where not estimated."""
        if self.estimate is None:
            return np.full((len(self), 2), np.nan)
        return np.asarray(self.estimate.std_n, dtype=float).reshape(len(self), 2)

    @functools.cached_property
    def status(self) -> np.ndarray:
        """Per-frame status codes (n,) of int8 (:class:`bendsense.status.Status`).

        Those of :func:`bendsense.results.frame_codes`, and ``NO_PRESSURE`` for frames
        without pressure when forces are estimated. Their words are results.csv's ``status``.
        Worked out once per block (the processor counts them, the loop reads them).
        """
        from bendsense.results import frame_codes

        status = frame_codes(self.shape, self.estimate)
        if self.estimated:
            status[~np.isfinite(self.pressure_pa)] = Status.NO_PRESSURE
        return status

    def columns(self) -> dict:
        """The columns of ``results.csv`` for these frames (those of ``bendsense ... save``)."""
        from bendsense.results import TRACK_COLUMNS, WINDOW_COLUMN, Results, tracked_columns
        from bendsense.results.contact import CONTACT_COLUMNS
        from bendsense.session import Session

        session = Session(self.t_s, self.signals, self.pressure_pa, extra=self.extra)
        results = Results.from_state(session, self.shape, self.estimate, self.track)
        columns = results.columns
        status = self.status
        if self.estimated and self.estimate is None:  # no frame with pressure: NaN forces, in save's order
            extra = {name: columns.pop(name) for name in results.extra_names}
            columns.pop("status")
            nan = np.full(len(self), np.nan)
            contact = CONTACT_COLUMNS if self.load == "contact" else ()
            columns.update({name: nan for name in ("fx_n", "fy_n", "fx_std_n", "fy_std_n", *contact, "residual_m")})
            columns["status"] = None
            if self.tracked:
                columns.update({name: nan for name in TRACK_COLUMNS[:4]})
                columns.update({"track_status": words(status), WINDOW_COLUMN: nan})
            columns.update(extra)
        elif self.track is not None:  # the frames without pressure: that status, not the estimate's
            columns.update(tracked_columns(len(self), self.estimate, self.track, status))
        columns["status"] = words(status)
        return columns

    def frame(self, i: int = -1) -> LiveFrame:
        """Frame ``i`` of the block as a :class:`LiveFrame`.

        Parameters
        ----------
        i : int, default -1
            Index of the frame in the block (-1: the newest).
        """
        n = len(self)
        i = range(n)[i]
        est = None
        if self.estimate is not None and np.isfinite(self.pressure_pa[i]):
            est = take_frames(self.estimate, i, n)
        return LiveFrame(seq=int(self.seq[i]), t_s=float(self.t_s[i]), host_ns=int(self.host_ns[i]),
                         pressure_pa=float(self.pressure_pa[i]), delta_a=self.signals[i] - self.offset,
                         shape=take_frames(self.shape, i, n), estimate=est, process_s=self.process_s / n,
                         status=Status(self.status[i]).word,
                         track_force_n=self.track_force_n[i] if self.tracked else None,
                         track_std_n=self.track_std_n[i] if self.tracked else None)


class LiveProcessor:
    """Turn frames into shapes and tip forces as they arrive, a block at a time, warm-started.

    Parameters
    ----------
    calibration : Calibration
        Signal → shift calibration (paper eq. 1–2).
    config : Config, optional
        Sensor, actuator and estimation options; default the paper's prototype.
    constraint : str, optional
        Force constraint (:data:`bendsense.estimation.CONSTRAINTS`); default
        ``config.estimation.constraint``.
    method : str, optional
        Estimator; default ``config.estimation.method``.
    objective : str, optional
        What the fit compares (:data:`bendsense.estimation.OBJECTIVES`); default
        ``config.estimation.objective``.
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa]; without it such frames get a
        shape only (status ``no_pressure``).
    n_points : int
        Points of each shape along the sensor.
    estimate : bool
        Estimate the force (False: shapes only).
    track : bool, default True
        Track the forces causally (:class:`bendsense.tracking.Tracker`, a Kalman filter over the
        per-frame estimates, its state kept across blocks): :attr:`LiveBlock.track`.
    bandwidth_hz : float, optional
        Bandwidth of the track [Hz]; None: the tracker's default.
    window_s : float, default 0.05
        Window of the streaming model check [s].
    adapt : bool, default False
        Learn the free-bending model from the stream's free frames as it runs
        (:class:`~bendsense.estimation.live_adapt.LiveAdaptation`, :attr:`adaptation`).
    **options
        Further options of :func:`bendsense.estimation.estimate_force` (``push_only``,
        ``tip_angle_source``, ...). ``max_iter`` defaults to :data:`LIVE_MAX_ITER`.

    Attributes
    ----------
    config : Config
        The config of the next block (with ``adapt``: the latest adapted one).
    adaptation : LiveAdaptation or None
        What ``adapt`` learned (None without it).
    frames : int
        Frames processed.
    failures : int
        Frames whose force estimate did not converge.
    estimated : int
        Frames whose force was estimated (those with a pressure).
    status_counts : dict of str to int
        Frames per status (``ok``, ``extrapolated``, ``not_converged``, ...), and
        ``window_misfit``: frames tracked while the latest completed window failed the
        window test (``window_p_value`` < 0.001).
    """

    def __init__(self, calibration, config=None, *, constraint=None, method=None, objective=None, pressure_pa=None,
                 n_points=41, estimate=True, track=True, bandwidth_hz=None, window_s=0.05, adapt=False, **options):
        from bendsense.config import load_config
        from bendsense.estimation.live_adapt import LiveAdaptation

        self.config = load_config() if config is None else config
        sensor = self.config.sensor
        if calibration.n_channels != sensor.n_segments:
            raise ConfigError(
                f"calibration.n_channels: expected {sensor.n_segments} (sensor.n_segments), "
                f"got {calibration.n_channels}"
            )
        self.calibration = calibration
        self.constraint, self.method, self.objective = estimation_options(self.config, constraint, method, objective)
        self.pressure_pa = None if pressure_pa is None else float(pressure_pa)
        self._fallback_told = False
        self.s_m = np.linspace(0.0, sensor.length_m, int(n_points))
        self.estimate = bool(estimate)
        self.track = self.estimate and bool(track)
        self._track_options = {"bandwidth_hz": bandwidth_hz, "window_s": window_s}
        self.tracker = self._new_tracker()
        self._track_t = -math.inf  # the latest frame time tracked [s]
        self.options = {"max_iter": LIVE_MAX_ITER, **options}
        self.frames = 0
        self.failures = 0
        self.estimated = 0
        self.status_counts: dict[str, int] = {}
        self._previous = None
        self._clock = ReadingClock()
        self.adaptation = LiveAdaptation(calibration, self.config) if adapt else None

    def _new_tracker(self):
        if not self.track:
            return None
        from bendsense.tracking import Tracker

        return Tracker(mode="filter", **self._track_options)

    def reset(self) -> None:
        """Forget the warm start, the track and the time origin (e.g. after a reconnect)."""
        self._previous = None
        self._clock.reset()
        self.tracker = self._new_tracker()
        self._track_t = -math.inf

    def _track(self, est, t, p):
        """The block's causal track; a clock that jumps back (a device reset) restarts the track there."""
        n = t.size
        if not (t[0] < self._track_t or (n > 1 and (np.diff(t) < 0).any())):  # the usual block: forward in time
            self._track_t = float(t[-1])
            return self.tracker.update(est, t, p)
        back = np.flatnonzero(np.diff(np.concatenate(([self._track_t], t))) < 0)
        parts = []
        for lo, hi in zip(np.concatenate(([0], back)), np.concatenate((back, [n]))):
            if lo in back:
                log.info("the frame clock went back %.6g s: the track restarts", (t[lo - 1] if lo else
                                                                                  self._track_t) - t[lo])
                self.tracker = self._new_tracker()
            if hi > lo:
                parts.append(self.tracker.update(take_frames(est, slice(lo, hi), n), t[lo:hi], p[lo:hi]))
        self._track_t = float(t[-1])
        return parts[0] if len(parts) == 1 else concat_frames(parts)

    def warm_up(self) -> None:
        """Compile or load the kernels before the first frame arrives, then forget the frames used.

        On the first run after an install the kernels compile (shown on stderr as it goes):
        a recording must not spend that time with a board streaming into a full queue. A
        block of one frame and one of two (a cold frame and a warm-started series: a live
        block never needs the batch kernel of large batches) of the flat calibration
        signals, at the middle of the actuator's pressure range.
        """
        lo, hi = self.config.actuator.pressure_range_pa
        flat = np.asarray(self.calibration.offset, dtype=float)
        for n in (1, 2):
            self.process_block(np.tile(flat, (n, 1)), np.full(n, 0.5 * (lo + hi)), t_s=np.arange(n) * 1e-3)
        self._forget()
        if self.adaptation is not None:  # its worker started and warmed
            self.adaptation.start()

    def rest_status(self) -> Status:
        """The status of a frame of the actuator at rest (the flat calibration signals, no pressure), then forgotten.

        ``NOT_IDENTIFIABLE``: the constraint leaves the load of a straight actuator undetermined (both
        components free, or a fixed direction along it), so a force loop could not start from rest.
        """
        flat = np.asarray(self.calibration.offset, dtype=float)
        block = self.process_block(flat[None, :], np.zeros(1), t_s=np.zeros(1))
        self._forget()
        return Status(block.status[0])

    def _forget(self) -> None:
        self.reset()
        self.frames = self.failures = self.estimated = 0
        self.status_counts = {}
        if self.adaptation is not None:
            self.adaptation.clear()

    def _estimate(self, shape, p, n):
        """The block's force estimates (None without a pressure or with ``estimate=False``), warm-started."""
        from bendsense.estimation import estimate_force

        has_p = np.isfinite(p)
        if not (self.estimate and has_p.any()):
            return None
        warm = {"initial": self._previous} if self._previous is not None else {}
        sub = shape if has_p.all() else take_frames(shape, has_p, n)
        kwargs = {"constraint": self.constraint, "method": self.method, "objective": self.objective,
                  "calibration": self.calibration, **self.options}
        with warnings.catch_warnings():  # a block of a stream is no session: its pressures are not judged
            warnings.simplefilter("ignore", DataWarning)
            est = estimate_force(sub, p[has_p], self.config, **warm, **kwargs)
        m = int(has_p.sum())
        failed = np.flatnonzero(~np.asarray(est.success).reshape(-1))
        if warm and failed.size:
            # a start far from a frame (a fast change) can fail where its own start converges: retry those cold
            retry = estimate_force(take_frames(sub, failed, m), p[has_p][failed], self.config, **kwargs)
            est = put_frames(est, failed, retry, m)
        ok = np.flatnonzero(np.asarray(est.success).reshape(-1))
        if ok.size:  # a failed frame has NaN forces: it cannot seed the next block
            self._previous = est if m == 1 else take_frames(est, int(ok[-1]), m)
        self.failures += int(np.count_nonzero(~np.asarray(est.success)))
        self.estimated += m
        return est if m == n else expand_frames(est, has_p)

    def process_block(self, signals, pressure_pa=None, *, t_s=None, seq=None, host_ns=None,
                      extra=None) -> LiveBlock:
        """Process a block of consecutive frames.

        Parameters
        ----------
        signals : array_like, shape (n, N)
            Raw signals A [signal units].
        pressure_pa : array_like, shape (n,) or None
            Pressure per frame [Pa]; NaN or None: no reading (the fallback pressure, if
            any, is used).
        t_s, seq, host_ns : array_like, shape (n,), optional
            Frame time [s], sequence numbers, arrival time [ns]; default NaN, -1, now.
        extra : dict of str to array_like, shape (n,), optional
            Further per-frame columns for ``results.csv`` (:attr:`LiveBlock.extra`).

        Returns
        -------
        LiveBlock
        """
        from bendsense import _jit
        from bendsense.shape.pcc import reconstruct

        t_start = time.perf_counter()
        a = np.asarray(signals, dtype=float)
        if a.ndim != 2:
            raise ArgumentError(f"signals: expected shape (n, N), got {a.shape}")
        n = a.shape[0]
        p = np.full(n, np.nan) if pressure_pa is None else np.broadcast_to(
            np.asarray(pressure_pa, dtype=float), (n,)).copy()
        if self.pressure_pa is not None:
            has = np.isfinite(p)
            if has.any() and not self._fallback_told:
                # once: a fallback that the board's own readings override must not pass silently
                log.warning("the fallback pressure %g kPa is ignored for frames with a pressure reading (the board "
                            "sends one); it fills only frames without", self.pressure_pa / 1e3)
                self._fallback_told = True
            p[~has] = self.pressure_pa
        with _jit.serial(n):  # a block of thousands (a loop seconds behind): the kernels warm_up compiled
            shape = reconstruct(a, self.calibration, self.config.sensor, s_m=self.s_m)
            est = self._estimate(shape, p, n)
        t_s = np.full(n, np.nan) if t_s is None else np.asarray(t_s, dtype=float)
        host_ns = np.asarray(np.full(n, time.monotonic_ns()) if host_ns is None else host_ns, dtype=np.int64)
        track, t = None, np.where(np.isfinite(t_s), t_s, host_ns * 1e-9)  # frames without a device time: the host's
        if self.tracker is not None and est is not None:
            track = self._track(est, t, p)
        if self.adaptation is not None:  # an update that finished: its config from the next block on
            self.config = self.adaptation.add(shape, p, t) or self.config
        block = LiveBlock(
            t_s=t_s,
            seq=np.full(n, -1, dtype=np.int64) if seq is None else np.asarray(seq, dtype=np.int64),
            host_ns=host_ns, pressure_pa=p, signals=a, shape=shape, estimate=est, estimated=self.estimate,
            process_s=time.perf_counter() - t_start,
            offset=np.asarray(self.calibration.offset, dtype=float),
            track=track,
            tracked=self.track,
            load=self.options.get("load", "tip"),
            extra={} if extra is None else {k: np.asarray(v) for k, v in extra.items()},
        )
        self.frames += n
        status = block.status
        if n == 1 or (status == status[0]).all():  # the usual block: one status
            word = str(WORDS[status[0]])
            self.status_counts[word] = self.status_counts.get(word, 0) + n
        else:
            codes, counts = np.unique(status, return_counts=True)
            for word, count in zip(words(codes), counts):
                self.status_counts[word] = self.status_counts.get(word, 0) + int(count)
        if track is not None:
            from bendsense.estimation._kernels import MISFIT_P
            from bendsense.results import WINDOW_MISFIT

            misfits = int(np.count_nonzero(np.asarray(track.window_p_value) < MISFIT_P))
            self.status_counts[WINDOW_MISFIT] = self.status_counts.get(WINDOW_MISFIT, 0) + misfits
        return block

    def process_readings(self, readings) -> LiveBlock:
        """Process driver readings (:class:`~bendsense.device.driver.Reading`), in arrival order.

        ``t_s`` is the device clock from the first reading this processor saw, and the
        block's :attr:`~LiveBlock.extra` the columns a recording of these readings has
        beside its own (``host_s`` from that first reading, ``status``, ``tx_drops``;
        :func:`bendsense.session.native.records_extra`), as the recorded session gives
        them to ``save``.

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.
        """
        c = self._clock.columns(readings)
        return self.process_block(c.signals, c.pressure_pa, t_s=c.t_s, seq=c.seq, host_ns=c.host_ns, extra=c.extra)

    def process_signals(self, signals, pressure_pa=None, *, seq=-1, t_s=math.nan, host_ns=None) -> LiveFrame:
        """Process one frame given as raw signals A (N,) and the pressure [Pa] (a block of one).

        Parameters
        ----------
        signals : array_like, shape (N,)
            Raw signals A [signal units].
        pressure_pa : float, optional
            Actuation pressure [Pa]; None or NaN takes the processor's constant pressure, if it has one.
        seq : int, default -1
            Sequence number of the frame.
        t_s : float, default nan
            Time of the frame [s].
        host_ns : int, optional
            Host clock when the frame arrived [ns].
        """
        p = None if pressure_pa is None else [pressure_pa]
        return self.process_block(np.asarray(signals, dtype=float)[None], p, t_s=[t_s], seq=[seq],
                                  host_ns=[time.monotonic_ns() if host_ns is None else host_ns]).frame(0)

    def process(self, reading) -> LiveFrame:
        """Process one :class:`~bendsense.device.driver.Reading`.

        Parameters
        ----------
        reading : Reading
            One driver reading.
        """
        return self.process_readings([reading]).frame(0)

    def process_many(self, readings) -> LiveFrame:
        """Process readings as one block; the newest frame as a :class:`LiveFrame`.

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.
        """
        return self.process_readings(readings).frame(-1)
