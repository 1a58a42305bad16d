"""The session CSV (DESIGN.md section 3): the interchange format, read and written.

A header row with ``t_s``, an optional pressure column (``pressure_pa`` or
``pressure_kpa``) and the signal columns ``ch1..chN``; ``#`` lines before the header
are metadata; any other column is kept and passed through. A board with several
pressure lines has ``line0_pressure_pa``, ``line1_pressure_pa``, ... (each may be
``_kpa`` instead) in place of ``pressure_pa``: ``Session.pressure_pa`` is then
``(frames, n_lines)``.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from pathlib import Path

import numpy as np

from bendsense import validation as check
from bendsense._io import check_csv_header, read_text
from bendsense.errors import SessionError
from bendsense.estimation.plausibility import check_pressure_column, check_time_column
from bendsense.session.base import Session
from bendsense.session.cells import parse_column, write_columns
from bendsense.session.records import check_line_pressure
from bendsense.validation import key as _name
from bendsense.validation import short

__all__ = ["KIND", "read_session_csv", "write_session_csv"]

_FIRST_LINE = "# written by bendsense (a session CSV, docs/formats.md)\n"  # output.MARK; no key, no metadata
#: a session CSV's mark and name: ``overwrite`` replaces a session CSV only (:class:`bendsense.output.Target`)
KIND = (b"(a session CSV", "session CSV")

_CHANNEL = re.compile(r"ch([1-9][0-9]*)$")
_LINE = re.compile(r"line(0|[1-9][0-9]*)_pressure_(pa|kpa)$")


def _is_pressure(column: str) -> bool:
    return column.startswith("pressure") or _LINE.match(column) is not None


def _parse_float(text: str, line: int, column: str) -> float:
    if not text and _is_pressure(column):
        return math.nan  # an empty pressure cell: no reading (docs/formats.md)
    try:
        value = float(text)
    except ValueError:
        raise SessionError(f"line {line}, column {column}: expected a number, got {short(text)}") from None
    return value


def read_session_csv(path: str | os.PathLike) -> Session:
    """Read a session CSV (DESIGN.md section 3).

    Parameters
    ----------
    path : str or path-like
        The session CSV file.

    Raises
    ------
    SessionError
        If the file is malformed; the message gives the line number and the column.
    """
    path = check.path("path", path)
    text = read_text(path, "session CSV", SessionError)
    try:
        return _parse_session_csv(text, str(path))
    except SessionError as err:
        raise SessionError(f"{path}: {err}") from None


def _parse_session_csv(text: str, source: str) -> Session:
    lines = text.splitlines()
    meta: dict[str, str] = {}
    start = 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        body = lines[start][1:].strip()
        if ":" in body:
            key, value = body.split(":", 1)
            meta[key.strip()] = value.strip()
        start += 1
    if start == len(lines):
        raise SessionError("no header row (expected t_s, ch1..chN)")
    rows = csv.reader(io.StringIO("\n".join(lines[start:])))
    header = [h.strip() for h in next(rows)]
    header_line = start + 1
    check_csv_header(header, header_line, SessionError)
    seen = set()
    for h in header:
        if not h:
            raise SessionError(f"line {header_line}: empty column name in header")
        if h in seen:
            raise SessionError(f"line {header_line}, column {_name(h)}: duplicate column")
        seen.add(h)
    if "t_s" not in seen:
        raise SessionError(f"line {header_line}: missing required column t_s")
    if "pressure_pa" in seen and "pressure_kpa" in seen:
        raise SessionError(f"line {header_line}: give pressure_pa or pressure_kpa, not both")
    line_cols = _line_columns(header, header_line)
    zero = [h for h in header if re.fullmatch(r"ch0[0-9]*", h)]
    if zero:
        raise SessionError(f"line {header_line}, column {zero[0]}: signal columns are numbered from 1 "
                           "without leading zeros (ch1..chN)")
    channels = sorted((int(m.group(1)), h) for h in header if (m := _CHANNEL.match(h)))
    if not channels:
        raise SessionError(f"line {header_line}: no signal columns (expected ch1..chN)")
    numbers = [n for n, _ in channels]
    if numbers != list(range(1, len(numbers) + 1)):
        missing = sorted(set(range(1, max(numbers) + 1)) - set(numbers))
        raise SessionError(f"line {header_line}: signal columns must be ch1..chN; missing ch{missing[0]}")

    body = lines[start + 1:]
    if '"' in text:
        # quoted cells (a comma or a line break inside a cell): the csv module's rows
        data = list(rows)
    else:
        # without quotes a row is its line split at the commas, as csv reads it, and a
        # line a row: several times faster than the csv module on long sessions
        data = [line.split(",") for line in body]
    width = len(header)
    row_lines = []
    for offset, row in enumerate(data):
        if len(row) == width and not row[0].startswith("#"):
            row_lines.append(header_line + 1 + offset)
            continue
        line = header_line + 1 + offset
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        if row[0].startswith("#"):
            raise SessionError(f"line {line}: comment lines are only allowed before the header")
        raise SessionError(f"line {line}: expected {width} columns, got {len(row)}")
    if len(row_lines) < len(data):
        data = [row for row in data if len(row) == width]
    if not data:
        raise SessionError("no data rows")
    cells = dict(zip(header, zip(*data)))

    numeric = {"t_s", "pressure_pa", "pressure_kpa", *line_cols, *(h for _, h in channels)}
    values = {}
    first = None  # (row, column) of the first cell that is not finite, in reading order
    for h in (h for h in header if h in numeric):  # the file's order: the same message at every run
        try:
            # float() strips the surrounding white space itself and rounds correctly
            arr = np.array(list(map(float, cells[h])))
        except ValueError:
            arr = np.array([_parse_float(c.strip(), row_lines[i], h) for i, c in enumerate(cells[h])])
        # a missing pressure reading may be NaN (never ±inf); time and signals must be finite
        wrong = np.flatnonzero(np.isinf(arr) if _is_pressure(h) else ~np.isfinite(arr))
        if wrong.size and (first is None or wrong[0] < first[0]):
            first = (int(wrong[0]), h)
        values[h] = arr
    if first is not None:
        bad, h = first
        raise SessionError(f"line {row_lines[bad]}, column {h}: must be finite, got {short(cells[h][bad].strip())}")
    t = values["t_s"]
    pressure = _pressure(values, line_cols, header_line, t.shape)
    check_time_column(t, source, row_lines)
    signals = np.column_stack([values[h] for _, h in channels])
    extra = {h: parse_column([c.strip() for c in cells[h]]) for h in header if h not in numeric}
    seq = extra.pop("seq").astype(np.int64) if "seq" in extra and extra["seq"].dtype.kind in "iu" else None
    if pressure.ndim == 2:
        meta["n_lines"] = pressure.shape[1]  # the columns say it, whatever a "# n_lines:" line said
    return Session(t, signals, pressure, seq=seq, meta=meta, extra=extra, source=source)


def _line_columns(header: list, header_line: int) -> list:
    """The ``line<k>_pressure_pa|kpa`` columns of ``header`` in line order, checked (none: [])."""
    found = {}
    for h in header:
        m = _LINE.match(h)
        if m:
            k = int(m.group(1))
            if k in found:
                raise SessionError(f"line {header_line}: pressure line {k} given twice ({found[k]} and {h})")
            found[k] = h
    if not found:
        return []
    given = [h for h in ("pressure_pa", "pressure_kpa") if h in header]
    if given:
        raise SessionError(f"line {header_line}: give {given[0]} (one pressure line) or line<k>_pressure_pa columns "
                           f"(several), not both ({given[0]} and {found[min(found)]})")
    missing = sorted(set(range(max(found) + 1)) - set(found))
    if missing:
        raise SessionError(f"line {header_line}: pressure line columns must be line0..line{max(found)}; missing "
                           f"line{missing[0]}_pressure_pa")
    return [found[k] for k in range(len(found))]


def _pressure(values: dict, lines: list, header_line: int, shape: tuple) -> np.ndarray:
    """The session's pressure [Pa] from its pressure column or line columns, checked for their unit."""
    for name in ("pressure_pa", "pressure_kpa"):
        if name in values:
            check_pressure_column(name, values[name], header_line, at_rest=True)
    if lines:
        cols = []
        for h in lines:
            unit = "pressure_kpa" if h.endswith("_kpa") else "pressure_pa"
            check_line_pressure(h, unit, values[h], header_line)
            cols.append(values[h] * (1e3 if unit == "pressure_kpa" else 1.0))
        return np.column_stack(cols)
    if "pressure_pa" in values:
        return values["pressure_pa"]
    if "pressure_kpa" in values:
        return values["pressure_kpa"] * 1e3
    return np.full(shape, np.nan)


def write_session_csv(session: Session, path: str | os.PathLike, *, overwrite: bool = True) -> None:
    """Write ``session`` as a session CSV, atomically (temporary file, then rename).

    Floats are written with ``repr`` so that reading the file back gives the same
    numbers bit for bit. Pressure is written as ``pressure_pa`` when any frame has
    a reading; several pressure lines as ``line0_pressure_pa, line1_pressure_pa, ...``
    (always, ``nan`` where a line has no reading).

    Parameters
    ----------
    session : Session
        The session to write.
    path : str or path-like
        Output CSV file.
    overwrite : bool, default True
        Replace an existing file; False refuses one.
    """
    from bendsense import output

    check.instance("session", session, Session, "bendsense.read_session(path)")
    path = check.path("path", path)
    source = session.source if session.source and Path(session.source).exists() else None
    output.check([output.file(path, overwrite=overwrite, replaces=KIND)], [source])
    header = ["t_s"]
    cols = [session.t_s]
    if session.pressure_pa.ndim == 2:
        header += [f"line{k}_pressure_pa" for k in range(session.n_lines)]
        cols += list(session.pressure_pa.T)
    elif np.any(np.isfinite(session.pressure_pa)):
        header.append("pressure_pa")
        cols.append(session.pressure_pa)
    header += [f"ch{i + 1}" for i in range(session.n_channels)]
    cols += list(session.signals.T)
    if session.seq is not None:
        header.append("seq")
        cols.append(session.seq)
    for name, values in session.extra.items():
        header.append(name)
        cols.append(values)
    with (
        output.write_file(path, overwrite=overwrite, inputs=[source], writer="bendsense export", replaces=KIND) as tmp,
        open(tmp, "w", encoding="utf-8", newline="") as fh,
    ):
        fh.write(_FIRST_LINE)
        for key, value in session.meta.items():
            if isinstance(value, (str, int, float)):
                fh.write(f"# {key}: {value}\n")
        write_columns(fh, header, cols)
