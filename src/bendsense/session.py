"""Sessions: a recording of sensor signals and pressure, frame by frame.

The interchange format is the session CSV of DESIGN.md section 3: a header row with
``t_s``, an optional pressure column (``pressure_pa`` or ``pressure_kpa``) and the
signal columns ``ch1..chN``; ``#`` lines before the header are metadata; any other
column is kept and passed through. Native session directories written by the
recorder are read by :func:`read_session` as well.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bendsense._io import check_csv_header, read_text
from bendsense.errors import SessionError
from bendsense.plausibility import check_pressure_column, check_time_column
from bendsense.validation import key as _name
from bendsense.validation import short

__all__ = ["Session", "read_session", "read_session_csv", "write_session_csv"]

_CHANNEL = re.compile(r"ch([1-9][0-9]*)$")


@dataclass(frozen=True, eq=False)
class Session:
    """Recorded frames of one session.

    Parameters
    ----------
    t_s : ndarray, shape (frames,)
        Time of each frame [s].
    signals : ndarray, shape (frames, N)
        Signal value of each receiver channel (ADC counts or volts, as recorded).
    pressure_pa : ndarray, shape (frames,)
        Actuation (gauge) pressure [Pa]; NaN where there is no reading.
    seq : ndarray of int, shape (frames,), optional
        Device sequence number, unwrapped, where known.
    meta : dict
        Metadata: the ``# key: value`` lines of a CSV, or ``meta.yaml`` of a native session.
    extra : dict of str to ndarray
        Further per-frame columns, kept in file order and passed through (e.g. the
        ground truth ``fx_n``, ``fy_n`` of a simulated session).
    source : str
        Where the session was read from.
    """

    t_s: np.ndarray
    signals: np.ndarray
    pressure_pa: np.ndarray
    seq: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    source: str = ""

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=float)
        sig = np.asarray(self.signals, dtype=float)
        if t.ndim != 1:
            raise SessionError(f"t_s: expected shape (frames,), got {t.shape}")
        if sig.ndim != 2 or sig.shape[0] != t.size:
            raise SessionError(f"signals: expected shape ({t.size}, N), got {sig.shape}")
        p = np.broadcast_to(np.asarray(self.pressure_pa, dtype=float), t.shape).copy()
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "signals", sig)
        object.__setattr__(self, "pressure_pa", p)
        if self.seq is not None:
            seq = np.asarray(self.seq, dtype=np.int64)
            if seq.shape != t.shape:
                raise SessionError(f"seq: expected shape {t.shape}, got {seq.shape}")
            object.__setattr__(self, "seq", seq)
        extra = {}
        for name, values in self.extra.items():
            values = np.asarray(values)
            if values.shape != t.shape:
                raise SessionError(f"extra column {short(name)}: expected shape {t.shape}, got {values.shape}")
            extra[name] = values
        object.__setattr__(self, "extra", extra)

    def __len__(self) -> int:
        return self.t_s.size

    @property
    def n_channels(self) -> int:
        """Number of signal channels N."""
        return self.signals.shape[1]

    @property
    def has_pressure(self) -> bool:
        """True when every frame has a pressure reading."""
        return bool(np.all(np.isfinite(self.pressure_pa)))

    def with_pressure(self, pressure_pa: float) -> Session:
        """A copy whose frames without a pressure reading get ``pressure_pa`` [Pa]."""
        p = np.where(np.isfinite(self.pressure_pa), self.pressure_pa, float(pressure_pa))
        return Session(self.t_s, self.signals, p, self.seq, dict(self.meta), dict(self.extra), self.source)

    def select(self, index) -> Session:
        """A new session with the frames picked by ``index`` (slice, mask or indices)."""
        seq = None if self.seq is None else self.seq[index]
        extra = {k: v[index] for k, v in self.extra.items()}
        return Session(
            self.t_s[index], self.signals[index], self.pressure_pa[index], seq, dict(self.meta), extra, self.source
        )


def _parse_float(text: str, line: int, column: str) -> float:
    if not text and column.startswith("pressure"):
        return math.nan  # an empty pressure cell: no reading (docs/formats.md)
    try:
        value = float(text)
    except ValueError:
        raise SessionError(f"line {line}, column {column}: expected a number, got {short(text)}") from None
    return value


def read_session_csv(path: str | os.PathLike) -> Session:
    """Read a session CSV (DESIGN.md section 3).

    Raises
    ------
    SessionError
        If the file is malformed; the message gives the line number and the column.
    """
    path = Path(path)
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

    numeric = {"t_s", "pressure_pa", "pressure_kpa", *(h for _, h in channels)}
    values = {}
    for h in numeric & seen:
        try:
            # float() strips the surrounding white space itself and rounds correctly
            arr = np.array(list(map(float, cells[h])))
        except ValueError:
            arr = np.array([_parse_float(c.strip(), row_lines[i], h) for i, c in enumerate(cells[h])])
        # a missing pressure reading may be NaN (never ±inf); time and signals must be finite
        wrong = np.isinf(arr) if h.startswith("pressure") else ~np.isfinite(arr)
        if wrong.any():
            bad = int(np.flatnonzero(wrong)[0])
            raise SessionError(f"line {row_lines[bad]}, column {h}: must be finite, got {short(cells[h][bad].strip())}")
        values[h] = arr
    t = values["t_s"]
    for name in ("pressure_pa", "pressure_kpa"):
        if name in values:
            check_pressure_column(name, values[name], header_line)
    check_time_column(t, source)
    if "pressure_pa" in values:
        pressure = values["pressure_pa"]
    elif "pressure_kpa" in values:
        pressure = values["pressure_kpa"] * 1e3
    else:
        pressure = np.full(t.shape, np.nan)
    signals = np.column_stack([values[h] for _, h in channels])
    extra = {h: _column_array([c.strip() for c in cells[h]]) for h in header if h not in numeric}
    seq = extra.pop("seq").astype(np.int64) if "seq" in extra and extra["seq"].dtype.kind in "iu" else None
    return Session(t, signals, pressure, seq=seq, meta=meta, extra=extra, source=source)


def _column_array(cells: list[str]) -> np.ndarray:
    """Numbers where every cell is numeric (ints kept as ints), else strings."""
    try:
        ints = [int(c) for c in cells]
        return np.array(ints, dtype=np.int64)
    except ValueError:
        pass
    try:
        return np.array([float(c) for c in cells])
    except ValueError:
        return np.array(cells, dtype=object)


def _format(value) -> str:
    if isinstance(value, (float, np.floating)):
        return "nan" if math.isnan(value) else repr(float(value))
    return str(value)


def write_session_csv(session: Session, path: str | os.PathLike, *, overwrite: bool = True) -> None:
    """Write ``session`` as a session CSV, atomically (temporary file, then rename).

    Floats are written with ``repr`` so that reading the file back gives the same
    numbers bit for bit. Pressure is written as ``pressure_pa`` when any frame has
    a reading.
    """
    from bendsense import output

    path = Path(path)
    source = session.source if session.source and Path(session.source).exists() else None
    output.check([output.file(path, overwrite=overwrite)], [source])
    header = ["t_s"]
    cols = [session.t_s]
    if np.any(np.isfinite(session.pressure_pa)):
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
        output.write_file(path, overwrite=overwrite, inputs=[source], writer="bendsense export") as tmp,
        open(tmp, "w", encoding="utf-8", newline="") as fh,
    ):
        fh.write("# written by bendsense (a session CSV, docs/formats.md)\n")  # output.MARK; no key, no metadata
        for key, value in session.meta.items():
            if isinstance(value, (str, int, float)):
                fh.write(f"# {key}: {value}\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        cells = [_column_cells(c) for c in cols]
        if any(c is None for c in cells):
            for row in zip(*cols):
                writer.writerow([_format(v) for v in row])
        elif len(cells[0]):
            # the rows as csv.writer writes them when no cell needs quotes
            fh.write("\n".join(map(",".join, zip(*cells))))
            fh.write("\n")


_NEEDS_QUOTES = re.compile(r'[,"\r\n]')


def _column_cells(values):
    """:func:`_format` of every cell of a column, or None if one needs the csv module's quotes."""
    values = np.asarray(values)
    if values.dtype.kind in "fiub":
        # Python floats and ints format as the numpy scalars do, faster
        return list(map(_format, values.tolist()))
    cells = [_format(v) for v in values]
    return None if any(_NEEDS_QUOTES.search(c) for c in cells) else cells


def read_session(path: str | os.PathLike) -> Session:
    """Read a session: a native session directory or a session CSV."""
    path = Path(path)
    if path.is_dir():
        from bendsense.sessiondir import read_session_dir

        return read_session_dir(path)
    if not path.exists():
        raise SessionError(f"{path}: no such file or session directory")
    return read_session_csv(path)
