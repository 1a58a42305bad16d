"""The processing pipeline: signals and pressure → shapes → tip forces, for a session or live.

Two entry points share the same option fallbacks and checks:

- :func:`process` runs a whole :class:`~bendsense.session.Session` at once: it checks the
  session against the calibration and the config, reconstructs the shapes (PCC, paper
  eq. 1–7, one batched call) and estimates the tip forces (eq. 18 and 21, one batched
  :func:`~bendsense.estimation.estimate_force` call), and returns :class:`Processed`,
  the :class:`~bendsense.results.Results` of ``results.csv`` with the objects they came
  from. It is the chain of ``bendsense load ... reconstruct estimate``, of every session
  of ``bendsense process`` (:mod:`bendsense.batch`) and of the demo.
- :class:`LiveProcessor` (:mod:`bendsense.pipeline.live`) is the core of ``bendsense
  record --estimate``, ``live``, ``control`` and the ``--lsl`` streams: a block of frames
  as they arrive, through one compiled call, into a :class:`LiveBlock` whose
  :meth:`~LiveBlock.columns` are those of ``results.csv``.

Both take the constraint, method and objective given, else the config's
(:func:`estimation_options`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ArgumentError, SessionError
from bendsense.estimation import estimation_options
from bendsense.results import Results
from bendsense.status import Status

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
    implausible_shape : int
        Frames whose tip turned by more than a full turn (status ``implausible_shape``: a unit
        or calibration mistake); their estimate is not counted above.
    no_shape : int
        Frames with non-finite signals, or readings their board flags (status ``no_shape``);
        their estimate is not counted above.
    ok : int
        Frames whose status is ``ok`` (a shape and, where estimated, a force to use). A
        gripper's counts (:mod:`bendsense.batch.fingers`) sum it over the fingers.
    """

    frames: int
    extrapolated: int = 0
    out_of_range: int = 0
    not_converged: int = 0
    model_misfit: int = 0
    not_identifiable: int = 0
    implausible_force: int = 0
    contact_unresolved: int = 0
    implausible_shape: int = 0
    no_shape: int = 0
    ok: int = 0


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
        """Frames flagged, by reason (:class:`FrameCounts`)."""
        from bendsense.estimation.plausibility import pressure_outside
        from bendsense.results import frame_codes

        n = len(self.session)
        extrapolated = int(np.count_nonzero(np.broadcast_to(np.asarray(self.shape.extrapolated), (n,))))
        codes = frame_codes(self.shape, self.estimate)
        # a shape that is nonsense is the frame's status: its estimate (which fails on it) is not counted as well
        implausible_shape, no_shape = codes == Status.IMPLAUSIBLE_SHAPE, codes == Status.NO_SHAPE
        shapes = {"implausible_shape": int(implausible_shape.sum()), "no_shape": int(no_shape.sum()),
                  "ok": int(np.count_nonzero(codes == Status.OK))}
        if self.estimate is None:
            return FrameCounts(frames=n, extrapolated=extrapolated, **shapes)
        outside = pressure_outside(self.session.pressure_pa, self.config)
        failed = ~np.asarray(self.estimate.success, dtype=bool) & ~outside & ~implausible_shape & ~no_shape
        own = np.broadcast_to(np.asarray(self.estimate.status), (n,))
        misfit = failed & (own == Status.MODEL_MISFIT)
        implausible = failed & (own == Status.IMPLAUSIBLE_FORCE)
        return FrameCounts(frames=n, extrapolated=extrapolated, out_of_range=int(outside.sum()),
                           not_converged=int(np.count_nonzero(failed & ~misfit & ~implausible)),
                           model_misfit=int(misfit.sum()), implausible_force=int(implausible.sum()),
                           not_identifiable=int(np.count_nonzero(codes == Status.NOT_IDENTIFIABLE)),
                           contact_unresolved=int(np.count_nonzero(codes == Status.CONTACT_UNRESOLVED)), **shapes)


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
        Points of each shape along the sensor, 2..10000 (default :func:`~bendsense.reconstruct`'s).
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

    points = _checked_options(options, points, estimate)
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


# the options of estimate_force that process passes on (the others are its own arguments)
_ESTIMATE_OPTIONS = frozenset(("direction", "follower_angle_rad", "initial_force_n", "initial", "warm_start",
                               "noise_std", "strict", "s_m", "n_points", "xtol_n", "max_iter"))


def _checked_options(options, points, estimate):
    """``points`` checked (None, or 2..10000 sample points), after the ``options`` passed on to estimate_force."""
    from bendsense import validation as check

    check.boolean("estimate", estimate)
    unknown = sorted(set(options) - _ESTIMATE_OPTIONS)
    if unknown:
        raise ArgumentError(f"{unknown[0]}: not an option of process (its own, or estimate_force's: "
                            f"{', '.join(sorted(_ESTIMATE_OPTIONS))})")
    return None if points is None else check.integer("points", points, minimum=2, maximum=10000)


def _estimate(session, shape, config, calibration, window_s, options):
    """The force estimate of the session's frames under the load model of ``options`` (its noise model gives std_n).

    A frame without a finite shape (a signal that is not finite or overflows its curvature, a
    reading its board flags) has no force: status ``no_shape``, as its row in results.csv says.
    """
    from bendsense._batched import expand_frames, take_frames
    from bendsense.estimation import _NO_SHAPE_MESSAGE
    from bendsense.estimation.load_models import estimate_load

    options["constraint"], options["method"], options["objective"] = estimation_options(
        config, options["constraint"], options["method"], options["objective"])
    n = len(session)
    has = np.isfinite(np.reshape(shape.curvature_per_m, (n, -1))).all(axis=1)
    if not has.any():
        raise SessionError(f"{_source(session)}: no frame has a finite shape (every frame's signals are beyond the "
                           "calibration's reach: check the calibration and the session's channels)")
    part = shape if has.all() else take_frames(shape, np.flatnonzero(has), n)
    est = estimate_load(part, session.pressure_pa[has], config, t_s=session.t_s[has], window_s=window_s,
                        calibration=calibration, **options)
    return est if has.all() else expand_frames(est, has, message=_NO_SHAPE_MESSAGE, status=Status.NO_SHAPE)


def _shapes(session, config, calibration, points, shape):
    """The session's shapes (those given, checked, else reconstructed) and the time spent [s]."""
    from bendsense.shape.pcc import reconstruct

    if shape is not None:
        from bendsense import validation as check
        from bendsense.shape.pcc import Shape

        check.instance("shape", shape, Shape, "bendsense.reconstruct")
        if np.shape(shape.tip_angle_rad)[:1] != (len(session),):
            raise ArgumentError(f"shape: expected the shapes of the session's {len(session)} frames, got batch "
                                f"shape {np.shape(shape.tip_angle_rad)}")
        return shape, 0.0
    s_m = None if points is None else np.linspace(0.0, config.sensor.length_m, int(points))
    t0 = time.perf_counter()
    shape = reconstruct(_readings_kept(session), calibration, config.sensor, s_m=s_m)
    return shape, time.perf_counter() - t0


def _readings_kept(session) -> np.ndarray:
    """The session's signals, NaN in the frames its board flagged (a native session's status bits): no shape there.

    :data:`~bendsense.wire.frames.BAD_READING` (ADC overrun, lock-in saturated,
    multiplexer settling), as the live path reads them. A CSV's ``status`` column is the
    user's own: not read.
    """
    from bendsense.wire.frames import BAD_READING

    status = session.extra.get("status") if "record_dtype" in session.meta else None
    if status is None:
        return session.signals
    flagged = (np.asarray(status).astype(np.int64) & int(BAD_READING)) != 0
    return np.where(flagged[:, None], np.nan, session.signals) if flagged.any() else session.signals


def _over_time(est, session, window_s, mode, bandwidth_hz):
    """The estimate window-checked (:func:`bendsense.check_windows`), and its track (None without ``mode``)."""
    from bendsense.tracking import check_windows, track

    est = check_windows(est, session.t_s, window_s=window_s, pressure_pa=session.pressure_pa)
    if mode is None:
        return est, None
    return est, track(est, session.t_s, mode=mode, bandwidth_hz=bandwidth_hz, window_s=window_s,
                      pressure_pa=session.pressure_pa)


# as frames arrive (imported last: the live module uses the options above)
from bendsense.pipeline.live import LIVE_MAX_ITER, LiveBlock, LiveFrame, LiveProcessor  # noqa: E402
