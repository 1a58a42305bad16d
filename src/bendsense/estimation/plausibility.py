"""Plausibility at the edges: input outside the physically meaningful range never gives an ``ok`` force.

The kinds of checks live here, both applied where data enter the library:

- **per frame**: a frame whose pressure lies outside the actuator's working range
  (``config.actuator.pressure_range_pa``, default 0..200 kPa) gets no force and the
  status ``pressure_out_of_range`` (:func:`pressure_range_step`, the first step of
  :func:`bendsense.estimation.estimate_force`);
- **per column**: a pressure column whose numbers are a thousand times off its unit
  (Pa numbers in ``pressure_kpa``; kPa numbers in the ``pressure_pa`` column of
  free-bending data) is refused by the reader with a message that names the probable
  mistake (:func:`check_pressure_column`); a session's ``pressure_pa`` below 1 kPa is a
  session at rest, and ``estimate_force`` warns when such pressures would lie inside the
  actuator's working range in kPa (:func:`warn_kpa_as_pa`);
- **per frame, the force**: a fitted force beyond what the actuator can carry
  (:func:`force_bound_n`) is no measurement: status ``implausible_force``
  (:func:`force_bound_step`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import warnings

import numpy as np

from bendsense.errors import ArgumentError, DataWarning, SessionError
from bendsense.mechanics.bounds import max_curvature_per_m
from bendsense.status import Status
from bendsense.validation import float_array, short

__all__ = [
    "pressure_outside",
    "pressure_range",
    "mark_out_of_range",
    "check_pressure_column",
    "warn_kpa_as_pa",
    "check_time_column",
    "check_channels",
    "check_one_line",
    "force_bound_n",
    "force_bound",
]

log = logging.getLogger("bendsense")

#: Below this a soft pneumatic actuator hardly bends [Pa]: pressures all under it are a session at rest, or kPa.
REST_PA = 1e3

_ONE_FRAME = (float, np.float64)  # the pressure of one frame as a number (a per-frame caller's)


def pressure_outside(pressure_pa, config) -> np.ndarray:
    """True for each finite pressure outside ``config.actuator.pressure_range_pa`` [Pa].

    Parameters
    ----------
    pressure_pa : float or array_like
        Actuation pressures [Pa]; NaN (no reading) is never outside.
    config : Config
        Its ``actuator.pressure_range_pa`` gives the range [Pa].
    """
    lo, hi = config.actuator.pressure_range_pa
    p = float_array("pressure_pa", pressure_pa)
    with np.errstate(invalid="ignore"):
        return np.isfinite(p) & ((p < lo) | (p > hi))


def _kpa(value: float) -> str:
    return f"{value / 1e3:g} kPa"


def pressure_range(pressure_pa, config, strict: bool = False):
    """The pressures an estimate runs at, and the frames outside the actuator's range (a step of ``estimate_force``).

    Frames outside ``actuator.pressure_range_pa`` are estimated at the nearest end of the
    range (so that a batch keeps its shape and a time series its warm start) and then
    marked by :func:`mark_out_of_range`; with ``strict=True`` they raise instead. Warns
    when the pressures look like kPa given as Pa (:func:`warn_kpa_as_pa`).

    Parameters
    ----------
    pressure_pa : float or array_like
        The frames' pressures [Pa].
    config : Config
        Its ``actuator.pressure_range_pa`` [Pa].
    strict : bool
        Raise for a pressure outside the range.

    Returns
    -------
    pressure_pa, outside
        The pressures to estimate at (clipped to the range where needed), and the bool
        mask of the frames outside it (shape of ``pressure_pa``).

    Raises
    ------
    ArgumentError
        With ``strict=True``, for a pressure outside the range.
    """
    if type(pressure_pa) in _ONE_FRAME:  # one frame: two comparisons, not ~6 µs of array calls (NaN is never outside)
        lo, hi = config.actuator.pressure_range_pa
        if not (pressure_pa < lo or pressure_pa > hi):
            return pressure_pa, np.False_
    outside = pressure_outside(pressure_pa, config)
    warn_kpa_as_pa(pressure_pa, config)
    if not outside.any():
        return pressure_pa, outside
    lo, hi = config.actuator.pressure_range_pa
    p = np.asarray(pressure_pa, dtype=float)
    if strict:
        raise ArgumentError(f"pressure_pa: {int(outside.sum())} of {outside.size} pressure(s) outside "
                            f"actuator.pressure_range_pa {lo / 1e3:g}..{hi / 1e3:g} kPa "
                            f"(first: {_kpa(float(p[outside].flat[0]))})")
    return np.clip(p, lo, hi), outside


def warn_kpa_as_pa(pressure_pa, config) -> None:
    """A :class:`~bendsense.errors.DataWarning` when the pressures look like kPa given as Pa.

    Every finite pressure below :data:`REST_PA` (the actuator hardly bends: at rest),
    none negative, most of them positive, and the positive ones inside
    ``config.actuator.pressure_range_pa`` read as kPa: a session at rest reads zeros or
    noise around zero (negative readings among it); kPa numbers of a working actuator
    read 20–120, and a ramp of them starts from a vented zero. One frame, and a block of
    a live stream (:class:`bendsense.pipeline.LiveProcessor`, which silences it), are not
    judged: a ramp from rest starts with a few pascals.

    Parameters
    ----------
    pressure_pa : float or array_like
        The pressures given to ``estimate_force`` [Pa].
    config : Config
        Its ``actuator.pressure_range_pa`` is the working range [Pa].
    """
    p = np.asarray(pressure_pa, dtype=float)
    p = p[np.isfinite(p)]
    positive = p[p > 0]
    lo, hi = config.actuator.pressure_range_pa
    if p.size < 2 or (p < 0).any() or 2 * positive.size <= p.size or not p.max() < REST_PA \
            or not lo <= positive.min() * 1e3 <= p.max() * 1e3 <= hi:
        return
    warnings.warn(f"pressure_pa: every pressure is below {REST_PA / 1e3:g} kPa (largest {p.max():g} Pa), where the "
                  f"actuator hardly bends, but read as kPa they lie inside actuator.pressure_range_pa "
                  f"{lo / 1e3:g}..{hi / 1e3:g} kPa: pressures in kPa given as Pa? (multiply by 1000, or name the "
                  "column pressure_kpa)", DataWarning, stacklevel=4)  # the caller of estimate_force


def mark_out_of_range(result, outside, pressure_pa, config):
    """``result`` with the frames where ``outside`` is true set to no force and ``PRESSURE_OUT_OF_RANGE``.

    ``force_n``, ``std_n``, ``covariance_n2``, ``residual_m`` NaN, ``success`` False and
    the message ``"pressure_out_of_range: ..."`` (:func:`pressure_range`).

    Parameters
    ----------
    result : ForceEstimate
        The estimate at the clipped pressures.
    outside : ndarray of bool
        The frames outside the range (:func:`pressure_range`).
    pressure_pa : float or array_like
        The frames' own pressures [Pa].
    config : Config
        Its ``actuator.pressure_range_pa``.
    """
    if outside is np.False_ or not outside.any():  # np.False_: one frame inside (pressure_range), ~1.5 µs less
        return result
    lo, hi = config.actuator.pressure_range_pa
    p = np.asarray(pressure_pa, dtype=float)
    batch = result.batch_shape
    mask = np.broadcast_to(outside, batch)
    p = np.broadcast_to(p, batch)
    nan2 = mask[..., None]
    message = np.array(np.broadcast_to(np.asarray(result.message, dtype=object), batch), dtype=object)
    for index in zip(*np.nonzero(mask)) if batch else [()]:
        message[index] = (f"{Status.PRESSURE_OUT_OF_RANGE.word}: {_kpa(float(p[index]))} outside "
                          f"{lo / 1e3:g}..{hi / 1e3:g} kPa "
                          "(actuator.pressure_range_pa)")
    chi2 = result.chi2_per_dof
    return dataclasses.replace(
        result,
        force_n=np.where(nan2, np.nan, result.force_n),
        std_n=np.where(nan2, np.nan, result.std_n),
        covariance_n2=np.where(mask[..., None, None], np.nan, result.covariance_n2),
        residual_m=np.where(mask, np.nan, result.residual_m),
        success=np.where(mask, False, result.success),
        status=np.where(mask, Status.PRESSURE_OUT_OF_RANGE, result.status).astype(np.int8),
        message=message.astype(str) if batch else str(message[()]),
        chi2_per_dof=None if chi2 is None else np.where(mask, np.nan, chi2),
        p_value=None if result.p_value is None else np.where(mask, np.nan, result.p_value),
        covariance_parts_n2=None if result.covariance_parts_n2 is None else np.where(
            mask[..., None, None, None], np.nan, result.covariance_parts_n2),
        # no window test on a frame the model was not made for
        residual_rad=None if result.residual_rad is None else np.where(mask[..., None], np.nan, result.residual_rad),
    )


def check_pressure_column(name: str, values: np.ndarray, line, error=SessionError, *, at_rest: bool = False) -> None:
    """Refuse a pressure column whose numbers are a thousand times off its unit.

    ``line``: the header line of a CSV column, or the place of a record field (e.g.
    ``"run/frames.bin"``) for the message.

    ``pressure_kpa`` with a reading over 1,000 kPa (1 MPa) holds pascals. Without
    ``at_rest``, ``pressure_pa`` whose largest reading is between 1 Pa and 1 kPa holds
    kilopascals (a soft actuator at under 1 kPa does not bend: free-bending data); a
    session may be at rest (``at_rest=True``: its readings pass, and ``estimate_force``
    judges them against the config, :func:`warn_kpa_as_pa`).

    Parameters
    ----------
    name : str
        Column name, ``pressure_pa`` or ``pressure_kpa``.
    values : ndarray
        The column's values, in the column's unit [Pa or kPa].
    line : int or str
        Where the column is, for the message (see above).
    error : type, default SessionError
        The exception class to raise.
    at_rest : bool, default False
        Pascals all below 1 kPa may be a session at rest.
    """
    where = f"line {line}, column" if isinstance(line, int) else f"{line}, field"
    finite = values[np.isfinite(values)]
    if not finite.size:
        return
    top = float(finite.max())
    if name == "pressure_pa" and 1.0 <= top < REST_PA and not at_rest:
        raise error(f"{where} pressure_pa: every reading is below 1 kPa (largest {top:g}); "
                    "looks like kilopascals" + (": name the column pressure_kpa" if isinstance(line, int) else ""))
    top = float(np.abs(finite).max())
    if name == "pressure_kpa" and top > 1e3:
        raise error(f"{where} pressure_kpa: readings up to {top:g} kPa (over 1 MPa); "
                    "looks like pascals: name the column pressure_pa")


def check_time_column(t_s: np.ndarray, source: str, rows=None, error=SessionError) -> None:
    """Refuse time stamps that are not finite or do not increase strictly from frame to frame.

    A session whose ``t_s`` runs backwards, repeats or is out of order (rows sorted
    by another column, two recordings pasted together, a clock reset) would be
    tracked, windowed and plotted as if nothing were wrong; which order is right
    cannot be guessed, so it is refused with the first offending rows (docs/formats.md,
    "Time").

    Parameters
    ----------
    t_s : ndarray, shape (frames,)
        Time stamps [s].
    source : str
        The session's file, for the message (not repeated when a reader adds it).
    rows : sequence of int, optional
        The CSV line of each frame; None: frames are named by their 0-based index.
    error : type, default SessionError
        The exception class to raise.
    """
    t = np.asarray(t_s, dtype=float)
    where = (lambda k: f"line {rows[k]}") if rows is not None else (lambda k: f"frame {k}")
    finite = np.isfinite(t)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise error(f"{where(k)}, column t_s: must be finite, got {short(t[k])}")
    if t.size < 2:
        return
    bad = np.flatnonzero(np.diff(t) <= 0) + 1
    if not bad.size:
        return
    k = int(bad[0])
    how = "repeats" if t[k] == t[k - 1] else "runs backwards"
    also = ""
    if bad.size > 1:
        more = ", ".join(where(int(j)).split()[-1] for j in bad[1:4])
        noun = "line" if rows is not None else "frame"
        noun += "s" if bad.size > 2 else ""
        also = f"; {bad.size} rows out of order in all (also {noun} {more}"
        also += ", ...)" if bad.size > 4 else ")"
    raise error(f"{where(k)}, column t_s: time {how} ({t[k]:.9g} s after {t[k - 1]:.9g} s on "
                f"{where(k - 1)}){also}; t_s must increase from row to row")


def check_channels(session, calibration, sensor, *, calibration_source: str = "") -> None:
    """Refuse a session, calibration and sensor whose channel counts differ (one line naming them).

    Parameters
    ----------
    session : Session
        The session (its signals' channel count).
    calibration : Calibration or None
        The calibration (its channel count), if any.
    sensor : SensorConfig
        The sensor (its segment count).
    calibration_source : str, default ""
        The calibration's file, for the message.
    """
    cal = f"the calibration {calibration_source}" if calibration_source else "the calibration"
    if calibration.n_channels != sensor.n_segments:
        raise SessionError(f"{cal} has {calibration.n_channels} channels, but the config's sensor has "
                           f"{sensor.n_segments} segments (sensor.n_segments)")
    if session.n_channels != calibration.n_channels:
        where = session.source or "the session"
        raise SessionError(f"{where}: {session.n_channels} signal channels (ch1..ch{session.n_channels}), "
                           f"but {cal} has {calibration.n_channels}")


def check_one_line(session) -> None:
    """Refuse a board session of several pressure lines for a single actuator (one line naming it).

    A single-actuator config reads one pressure per frame; a gripper's board records one
    per line (``Session.pressure_pa`` of shape ``(frames, n_lines)``), split per finger by a
    gripper config (:func:`bendsense.session.fingers.split_session`).

    Parameters
    ----------
    session : Session
        The session.
    """
    p = np.asarray(session.pressure_pa)
    if p.ndim > 1:
        raise SessionError(f"{session.source or 'the session'}: {p.shape[1]} pressure lines per frame (a gripper's "
                           f"board), but the config is a single actuator: give a gripper config (--config G.yaml "
                           f"with fingers:, each finger's channels and pressure_line)")


# --- per frame: a force the actuator cannot carry -------------------------------------------

FORCE_MARGIN = 10.0
"""Factor of :func:`force_bound_n` over the force that bends the actuator by the sensor's range."""


def force_bound_n(pressure_pa, config):
    """The largest tip force a measured shape of this actuator can come from [N].

    ``F_max(P) = FORCE_MARGIN · EI(P) · κ_max / L``, with ``κ_max`` the largest
    curvature the sensor can measure (:func:`max_curvature_per_m`) and ``FORCE_MARGIN``
    = 10. Why: in equilibrium ``EI (κ(s) − K0) = −M_z(s)`` (DESIGN section 2), and the
    moment of a tip force F about a point of the beam is ``|F|`` times that point's
    distance from the force's line of action. Every curvature of a shape the sensor
    measured, the natural one K0 included, is within ``κ_max``, so
    ``|F| · h ≤ 2 EI κ_max`` with ``h`` the largest distance of the beam from the line of
    action. A factor 10 leaves ``h`` down to L/5: only an actuator lying along its own
    load line is left out, and there the load is compression (it buckles at
    ``π² EI / 4L²``, far below the bound) or tension, which no shape shows (such a
    frame is ``not_identifiable``: its force is where the fit stopped, not a
    measurement). For the paper's prototype ``F_max`` is 74 N at 0 kPa and 147 N at
    200 kPa, beyond anything a 13 cm silicone finger holds; forces beyond it come from
    a unit slip (an EI in N·mm², a calibration a thousand times off), not from a load.

    Parameters
    ----------
    pressure_pa : float or array_like
        Gauge pressures [Pa].
    config : Config
        The actuator (``stiffness``, ``actuator.length_m``) and its sensor.

    Returns
    -------
    float or ndarray
        ``F_max`` at each pressure [N] (NaN where the pressure is).
    """
    return _force_scale(config) * config.stiffness.ei_nm2(np.asarray(pressure_pa, dtype=float))


def _force_scale(config) -> float:
    """``FORCE_MARGIN · κ_max / L`` [1/m²]."""
    return FORCE_MARGIN * max_curvature_per_m(config.sensor) / config.actuator.length_m


def force_bound(result, pressure_pa, config, strict: bool = False, *, ei_nm2=None):
    """``result`` with a frame whose force is beyond :func:`force_bound_n` not ok (a step of ``estimate_force``).

    The force is kept (as with ``model_misfit``) but a frame that succeeded gets
    ``success`` False, status ``IMPLAUSIBLE_FORCE`` and the message ``"implausible_force:
    ..."``; with ``strict=True`` such a frame raises :class:`~bendsense.errors.ConvergenceError`.

    Parameters
    ----------
    result : ForceEstimate
        The estimate.
    pressure_pa : float or array_like
        The frames' pressures [Pa].
    config : Config
        The actuator's stiffness and the sensor's range.
    strict : bool
        Raise for such a frame.
    ei_nm2 : ndarray, shape (B,), optional
        EI(P) of the frames, flattened, where the caller has it (an estimate's frames): not computed again.
    """
    force = np.asarray(result.force_n, dtype=float)
    if force.shape == (2,) and type(pressure_pa) in _ONE_FRAME:  # one frame: plain floats, not ~13 µs of arrays
        magnitude = math.hypot(force[0], force[1])
        if not (result.success and math.isfinite(magnitude) and magnitude > (
                force_bound_n(pressure_pa, config) if ei_nm2 is None else _force_scale(config) * ei_nm2[0])):
            return result
    magnitude = np.hypot(force[..., 0], force[..., 1])
    p = np.broadcast_to(np.asarray(pressure_pa, dtype=float), magnitude.shape)
    top = force_bound_n(p, config) if ei_nm2 is None else _force_scale(config) * np.reshape(ei_nm2, magnitude.shape)
    with np.errstate(invalid="ignore"):  # a failed frame keeps its own reason
        over = np.isfinite(magnitude) & (magnitude > top) & np.broadcast_to(result.success, magnitude.shape)
    if not over.any():
        return result
    if strict:
        from bendsense.errors import ConvergenceError

        first = np.argwhere(np.atleast_1d(over))[0]
        m, t = np.atleast_1d(magnitude)[tuple(first)], np.atleast_1d(top)[tuple(first)]
        raise ConvergenceError(f"{int(np.count_nonzero(over))} frame(s) {Status.IMPLAUSIBLE_FORCE.word}: "
                               f"|F| = {m:.3g} N beyond the {t:.3g} N this actuator can carry")
    return _mark_force(result, over, magnitude, top, p)


def _mark_force(result, over, magnitude, top, p):
    """``result`` with the frames where ``over`` is true flagged ``implausible_force`` (force kept)."""
    batch = result.batch_shape
    message = np.array(np.broadcast_to(np.asarray(result.message, dtype=object), batch), dtype=object)
    for index in zip(*np.nonzero(over)) if batch else [()]:
        message[index] = (f"{Status.IMPLAUSIBLE_FORCE.word}: |F| = {float(magnitude[index]):.3g} N is beyond the "
                          f"{float(top[index]):.3g} N this actuator can carry at {float(p[index]) / 1e3:g} kPa "
                          f"({FORCE_MARGIN:g} EI(P) κ_max / L): check the units of the config's stiffness and the "
                          "calibration")
    return dataclasses.replace(result, success=np.where(over, False, result.success),
                               status=np.where(over, Status.IMPLAUSIBLE_FORCE, result.status).astype(np.int8),
                               message=message.astype(str) if batch else str(message[()]))
