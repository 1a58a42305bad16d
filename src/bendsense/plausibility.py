"""Plausibility at the edges: input outside the physically meaningful range never gives an ``ok`` force.

Two kinds of checks live here, both applied where data enter the library:

- **per frame**: a frame whose pressure lies outside the actuator's working range
  (``config.actuator.pressure_range_pa``, default 0..200 kPa) gets no force and the
  status ``pressure_out_of_range`` (:func:`pressure_range_step`, the first step of
  :func:`bendsense.estimation.estimate_force`);
- **per column**: a pressure column whose numbers are a thousand times off its unit
  (kPa numbers in ``pressure_pa``, Pa numbers in ``pressure_kpa``) is refused by the
  session reader with a message that names the probable mistake
  (:func:`check_pressure_column`).
"""

from __future__ import annotations

import dataclasses
import functools
import logging

import numpy as np

from bendsense.errors import ArgumentError, SessionError
from bendsense.validation import float_array

__all__ = [
    "OUT_OF_RANGE",
    "pressure_outside",
    "pressure_range_step",
    "check_pressure_column",
    "check_time_column",
    "check_channels",
]

log = logging.getLogger("bendsense")

OUT_OF_RANGE = "pressure_out_of_range"
"""Status (and message prefix) of a frame whose pressure lies outside the actuator's range."""


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
    if isinstance(pressure_pa, float):  # one frame (the live path)
        return np.bool_(lo > pressure_pa or pressure_pa > hi)
    p = float_array("pressure_pa", pressure_pa)
    with np.errstate(invalid="ignore"):
        return np.isfinite(p) & ((p < lo) | (p > hi))


def _kpa(value: float) -> str:
    return f"{value / 1e3:g} kPa"


def pressure_range_step(estimate):
    """Wrap ``estimate_force``: frames outside the actuator's pressure range get no force.

    Those frames are estimated at the nearest end of the range (so that a batch keeps
    its shape and a time series its warm start) and then marked: ``force_n``,
    ``std_n``, ``covariance_n2``, ``residual_m`` NaN, ``success`` False and the message
    ``"pressure_out_of_range: ..."``. With ``strict=True`` they raise
    :class:`~bendsense.errors.ArgumentError` instead.

    Parameters
    ----------
    estimate : callable
        ``estimate_force`` or a function with its signature.
    """
    from bendsense.config import Config, load_config

    @functools.wraps(estimate)
    def estimate_force(shape, pressure_pa, config=None, *args, **options):
        if config is None:
            config = load_config()
        elif not isinstance(config, Config):
            raise ArgumentError(f"config: expected a Config (bendsense.load_config(path)), got "
                                f"{type(config).__name__}")
        outside = pressure_outside(pressure_pa, config)
        if not outside.any():
            return estimate(shape, pressure_pa, config, *args, **options)
        lo, hi = config.actuator.pressure_range_pa
        p = np.asarray(pressure_pa, dtype=float)
        first = float(p[outside].flat[0])
        text = (f"{int(outside.sum())} of {outside.size} pressure(s) outside actuator.pressure_range_pa "
                f"{lo / 1e3:g}..{hi / 1e3:g} kPa (first: {_kpa(first)})")
        if options.get("strict"):
            raise ArgumentError(f"pressure_pa: {text}")
        result = estimate(shape, np.clip(p, lo, hi), config, *args, **options)
        return _mark(result, outside, p, lo, hi)

    return estimate_force


def _mark(result, outside, p, lo, hi):
    """``result`` with the frames where ``outside`` is true set to no force and the status."""
    batch = result.batch_shape
    mask = np.broadcast_to(outside, batch)
    p = np.broadcast_to(p, batch)
    nan2 = mask[..., None]
    message = np.array(np.broadcast_to(np.asarray(result.message, dtype=object), batch), dtype=object)
    for index in zip(*np.nonzero(mask)) if batch else [()]:
        message[index] = (f"{OUT_OF_RANGE}: {_kpa(float(p[index]))} outside {lo / 1e3:g}..{hi / 1e3:g} kPa "
                          "(actuator.pressure_range_pa)")
    chi2 = result.chi2_per_dof
    return dataclasses.replace(
        result,
        force_n=np.where(nan2, np.nan, result.force_n),
        std_n=np.where(nan2, np.nan, result.std_n),
        covariance_n2=np.where(mask[..., None, None], np.nan, result.covariance_n2),
        residual_m=np.where(mask, np.nan, result.residual_m),
        success=np.where(mask, False, result.success),
        message=message.astype(str) if batch else str(message[()]),
        chi2_per_dof=None if chi2 is None else np.where(mask, np.nan, chi2),
        p_value=None if result.p_value is None else np.where(mask, np.nan, result.p_value),
        covariance_parts_n2=None if result.covariance_parts_n2 is None else np.where(
            mask[..., None, None, None], np.nan, result.covariance_parts_n2),
    )


def check_pressure_column(name: str, values: np.ndarray, line, error=SessionError) -> None:
    """Refuse a pressure column whose numbers are a thousand times off its unit.

    ``line``: the header line of a CSV column, or the place of a record field (e.g.
    ``"run/frames.bin"``) for the message.

    ``pressure_pa`` whose largest reading is between 1 Pa and 1 kPa holds kilopascals
    (a soft actuator at under 1 kPa does not bend; a column of zeros is an
    unpressurised session and passes); ``pressure_kpa`` with a reading over
    1,000 kPa (1 MPa) holds pascals.

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
    """
    where = f"line {line}, column" if isinstance(line, int) else f"{line}, field"
    finite = values[np.isfinite(values)]
    if not finite.size:
        return
    top = float(finite.max())
    if name == "pressure_pa" and 1.0 <= top < 1e3:
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
        raise error(f"{where(k)}, column t_s: must be finite, got {t[k]!r}")
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
