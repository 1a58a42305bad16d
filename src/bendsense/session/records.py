"""From a native session's records to a :class:`~bendsense.session.Session`, and pressure lines.

The record layout itself (:func:`bendsense.session.native.record_dtype`) and the
directory (:class:`~bendsense.session.native.SessionWriter`, the reader) are
:mod:`bendsense.session.native`, which re-exports the names here; this module turns
records into a session's columns: the device clock (:func:`device_time_us`), the extra
columns (:func:`records_extra`), the pressure lines (:func:`records_pressure`) and the
whole :func:`records_to_session`.

**Several pressure lines.** A board with more than one pressure line (SAMPLE version 2)
is recorded with one more record field, ``pressures_pa`` of ``(n_lines,)<i4`` after
``adc`` (``pressure_pa`` keeps line 0, as the wire's offset 12 does), and
``meta["n_lines"]``; a one-line session has neither, byte for byte as before. In a
:class:`~bendsense.session.Session` the lines are the columns of ``pressure_pa``
``(frames, n_lines)``, and in a session CSV the columns ``line<k>_pressure_pa`` (or
``line<k>_pressure_kpa``), k = 0..n_lines-1 (:func:`line_columns`).
"""

from __future__ import annotations

import logging

import numpy as np

from bendsense.errors import SessionError
from bendsense.estimation.plausibility import check_pressure_column, check_time_column
from bendsense.session.base import Session
from bendsense.wire.frames import MAX_LINES, NO_PRESSURE

__all__ = [
    "LINES_FIELD",
    "SESSION_COLUMNS",
    "line_columns",
    "check_line_pressure",
    "records_pressure",
    "records_extra",
    "device_time_us",
    "records_to_session",
]

# the same logger as bendsense.session.native (logging configurations name it)
log = logging.getLogger("bendsense.session")

FRAMES = "frames.bin"
LINES_FIELD = "pressures_pa"
"""Record field of a session with several pressure lines: ``(n_lines,)<i4``, NO_PRESSURE = no reading."""
# record fields that become the Session's own columns (t_s, seq, pressure_pa, signals) or
# host_s and status; every other field goes to Session.extra under its own name
SESSION_COLUMNS = ("host_ns", "t_us", "seq", "status", "pressure_pa", "adc", LINES_FIELD)


def line_columns(n_lines: int, unit: str = "pa") -> list:
    """The session CSV's pressure columns of ``n_lines`` lines: ``line0_pressure_pa``, ...

    Parameters
    ----------
    n_lines : int
        Number of pressure lines (2..255 for a gripper's board).
    unit : {"pa", "kpa"}, default "pa"
        The columns' unit.
    """
    if not 1 <= int(n_lines) <= MAX_LINES:
        raise SessionError(f"n_lines: expected 1..{MAX_LINES}, got {n_lines!r}")
    return [f"line{k}_pressure_{unit}" for k in range(int(n_lines))]


def check_line_pressure(column: str, unit_name: str, values: np.ndarray, where) -> None:
    """:func:`bendsense.estimation.plausibility.check_pressure_column` for one line's column, named as it is.

    Parameters
    ----------
    column : str
        The column (``line1_pressure_pa``) or record field (``pressures_pa[1]``) name.
    unit_name : str
        ``pressure_pa`` or ``pressure_kpa``: the unit the values are in.
    values : ndarray
        The line's values.
    where : int or str
        The CSV header line, or the place of the record field.
    """
    try:
        check_pressure_column(unit_name, values, where, at_rest=True)
    except SessionError as err:
        text = str(err).replace(f"column {unit_name}", f"column {column}").replace(
            f"field {unit_name}", f"field {column}").replace("name the column pressure_pa",
                                                              f"name the column {column.replace('_kpa', '_pa')}")
        raise SessionError(text) from None


def records_pressure(records: np.ndarray, where: str = "session") -> np.ndarray:
    """The pressure of native records [Pa] (NaN: no reading): (frames,), or (frames, n_lines) with several lines.

    Parameters
    ----------
    records : ndarray
        Structured records of ``frames.bin``.
    where : str, default "session"
        The session, for the messages.
    """
    if LINES_FIELD in records.dtype.names:
        p = np.asarray(records[LINES_FIELD]).reshape(len(records), -1)
        head = records["pressure_pa"]
        differ = np.flatnonzero(head != p[:, 0]) if p.size else np.zeros(0, int)
        if differ.size:
            k = int(differ[0])
            raise SessionError(f"{where}/{FRAMES}: record {k}: pressure_pa ({int(head[k])}) differs from line 0 of "
                               f"{LINES_FIELD} ({int(p[k, 0])}); the records are damaged")
        pressure = np.where(p == NO_PRESSURE, np.nan, p.astype(float))
        finite = pressure[np.isfinite(pressure)]
        # one board sends every line in one unit: a line at rest beside a pressurised one (a line the control
        # loop holds at 0) is no column of kilopascals
        if not (finite.size and finite.max() >= 1e3):
            for k in range(pressure.shape[1]):
                check_line_pressure(f"{LINES_FIELD}[{k}]", "pressure_pa", pressure[:, k], f"{where}/{FRAMES}")
        return pressure[:, 0] if pressure.shape[1] == 1 else pressure
    p = records["pressure_pa"]
    pressure = np.where(p == NO_PRESSURE, np.nan, p.astype(float))
    check_pressure_column("pressure_pa", pressure, f"{where}/{FRAMES}", at_rest=True)
    return pressure


def _unwrap16(seq: np.ndarray) -> np.ndarray:
    seq = seq.astype(np.int64)
    if seq.size == 0:
        return seq
    steps = np.diff(seq) % 65536
    return seq[0] + np.concatenate([[0], np.cumsum(steps)])


def records_extra(records: np.ndarray, host0_ns: int | None = None) -> dict:
    """The ``Session.extra`` columns of native records, in order.

    ``host_s`` (host clock relative to ``host0_ns`` [s]), ``status`` (the status bits)
    and every record field without a column of its own (``tx_drops``, ...), under its
    name. :func:`records_to_session` gives a recording these; ``record --estimate``
    gives its live ``results.csv`` the same, so that its columns are those of ``save``.

    Parameters
    ----------
    records : ndarray
        Structured records (:func:`record_dtype`).
    host0_ns : int, optional
        Host clock of the session's first frame [ns]; default: that of the first record.
    """
    host = records["host_ns"]
    if host0_ns is None:
        host0_ns = host[0] if host.size else 0
    extra = {
        "host_s": (host - host0_ns) * 1e-9,
        "status": records["status"].astype(np.int64),
    }
    for name in records.dtype.names:
        if name not in SESSION_COLUMNS:
            extra[name] = np.array(records[name])
    return extra


def device_time_us(records: np.ndarray, source: str = "session") -> np.ndarray:
    """The device clock of ``records`` [us], with resets bridged by the host clock (and a warning).

    The driver removes the u32 wraps of ``t_us`` as it records (a wrap every 71.6 min
    is normal), but a board that resets or reconnects restarts its clock: ``t_us``
    jumps back or stands still. Such a recording is legitimate, so it is kept: at
    each step that does not advance, the interval is taken from the host clock
    (``host_ns``, monotonic; the typical device step when the host's is 0, as for
    frames read in one burst), and the device clock goes on from there. The warning
    names the frames (0-based) where it happened.

    Parameters
    ----------
    records : ndarray
        Structured records with ``t_us`` and ``host_ns``.
    source : str, default "session"
        The session, for the warning.
    """
    t_us = records["t_us"].astype(np.int64)
    if t_us.size < 2:
        return t_us
    step = np.diff(t_us)
    bad = np.flatnonzero(step <= 0)
    if not bad.size:
        return t_us
    forward = step[step > 0]
    typical = int(np.median(forward)) if forward.size else 1
    host_us = np.diff(records["host_ns"].astype(np.int64)) // 1000
    bridged = step.copy()
    bridged[bad] = np.where(host_us[bad] > 0, host_us[bad], typical)
    first = int(bad[0]) + 1
    frames = ", ".join(str(int(k) + 1) for k in bad[:5]) + (", ..." if bad.size > 5 else "")
    log.warning("%s: the device clock (t_us) goes back or stands still at %d frame(s) (frame %s: %d us after %d us; a "
                "board reset?); time from there on continues from the host clock (frames %s)", source, bad.size,
                first, int(t_us[first]), int(t_us[first - 1]), frames)
    return t_us[0] + np.concatenate([[0], np.cumsum(bridged)])


def records_to_session(records: np.ndarray, meta: dict, source: str = ""):
    """Build a :class:`~bendsense.session.Session` from raw records.

    ``t_s`` is the unwrapped device clock relative to the first frame (plus
    ``meta["t_offset_s"]`` of an imported CSV), with clock resets bridged by the host
    clock (:func:`device_time_us`); ``extra`` holds ``host_s`` (host clock
    relative to the first frame [s]), ``status`` and any further record fields
    (``tx_drops``: the firmware's cumulative counter; any field of
    :data:`bendsense.wire.frames.SAMPLE_FIELDS` beyond ``SESSION_COLUMNS`` under its own name,
    as recorded). ``meta["frames_lost"]`` counts
    the sequence gaps and ``meta["tx_drops"]`` the frames the firmware could not send
    during the session (0 for version 1, which has no counter).

    Parameters
    ----------
    records : ndarray
        Structured records of ``frames.bin``.
    meta : dict
        The session's metadata (:func:`read_records`).
    source : str, default ""
        Where the records came from, kept as ``Session.source``.
    """
    n_ch = records.dtype.fields["adc"][0].shape[0]
    t_us = device_time_us(records, source or "session")
    t0 = float(meta.get("t_offset_s") or 0.0)
    t_s = t0 + (t_us - (t_us[0] if t_us.size else 0)) * 1e-6
    pressure = records_pressure(records, source or "session")
    extra = records_extra(records)
    signals = np.array(records["adc"], dtype=float).reshape(len(records), n_ch)
    seq = _unwrap16(records["seq"])
    meta = dict(meta)
    meta["frames_lost"] = int(np.maximum(np.diff(seq) - 1, 0).sum())  # the gaps; a repeated seq is no loss
    drops = _unwrap16(records["tx_drops"]) if "tx_drops" in records.dtype.names else np.zeros(0, np.int64)
    meta["tx_drops"] = int(drops[-1] - drops[0]) if drops.size else 0
    check_time_column(t_s, f"{source or 'session'}/{FRAMES}")
    return Session(t_s, signals, pressure, seq=seq, meta=meta, extra=extra, source=source)
