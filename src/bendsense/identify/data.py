"""The measurements :mod:`bendsense.identify` fits: its two CSV formats, read and checked.

:func:`read_free_bending_csv` gives pressures and bending angles, :func:`read_stiffness_csv`
the loaded shapes (:class:`StiffnessData`); the columns of both are described in
:mod:`bendsense.identify`, which re-exports these names.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from bendsense._io import check_csv_header, read_text
from bendsense.errors import ArgumentError, SessionError
from bendsense.estimation.plausibility import check_pressure_column
from bendsense.validation import key as _name
from bendsense.validation import short

__all__ = ["StiffnessData", "read_free_bending_csv", "read_stiffness_csv"]


def _read_table(path) -> tuple[list[str], np.ndarray]:
    """Header and float rows of a CSV; ``#`` lines before the header are skipped, empty cells are NaN."""
    lines = read_text(path, "CSV table", SessionError).splitlines()
    start = 0
    while start < len(lines) and (not lines[start].strip() or lines[start].lstrip().startswith("#")):
        start += 1
    if start == len(lines):
        raise SessionError(f"{path}: no header row")
    reader = csv.reader(lines[start:])
    header = [h.strip() for h in next(reader)]
    try:
        check_csv_header(header, start + 1, SessionError)
    except SessionError as err:
        raise SessionError(f"{path}: {err}") from None
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise SessionError(f"{path}: duplicate columns {', '.join(_name(d) for d in dup[:8])}")
    rows = []
    for lineno, cells in enumerate(reader, start=start + 2):
        if not cells or all(not c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise SessionError(f"{path}: line {lineno}: expected {len(header)} values, got {len(cells)}")
        row = []
        for name, cell in zip(header, cells, strict=True):
            text = cell.strip()
            try:
                row.append(float(text) if text else math.nan)
            except ValueError:
                raise SessionError(f"{path}: line {lineno}: column {name}: not a number: {short(text)}") from None
        rows.append(row)
    if not rows:
        raise SessionError(f"{path}: no data rows")
    return header, np.asarray(rows, dtype=float)


def _column(path, header, data, names: Mapping[str, float], what: str, required: bool = True):
    """The one present column of ``names`` (name → factor to SI), converted; None if absent and optional."""
    present = [n for n in names if n in header]
    if len(present) > 1:
        raise SessionError(f"{path}: give one {what} column, got {', '.join(present)}")
    if not present:
        if required:
            raise SessionError(f"{path}: missing {what} column ({' or '.join(names)}){_session_hint(header)}")
        return None
    name = present[0]
    values = data[:, header.index(name)] * names[name]
    return values, name


def _session_hint(header) -> str:
    """A hint where the table is a session's signals, which identify reads with ``--session`` and a calibration."""
    return (" (a session CSV of coil signals: identify reads it with --session SESSION --calibration CAL)"
            if "ch1" in header else "")


def _require_finite(path, name, values):
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise SessionError(f"{path}: column {name}: missing or non-finite value in data row {bad[0] + 1}")


_PRESSURE = {"pressure_pa": 1.0, "pressure_kpa": 1e3}


def _check_pressure_unit(path, name, pressure_pa):
    """KPa numbers in a pressure_pa column (and Pa in pressure_kpa) are refused, after the layout checks."""
    try:
        check_pressure_column(name, pressure_pa / _PRESSURE[name], 1)
    except SessionError as err:
        raise SessionError(f"{path}: {err}") from None


def read_free_bending_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read free-bending data (module docstring): pressures [Pa] and total bending angles [rad].

    Parameters
    ----------
    path : str or path-like
        CSV file with a pressure column and a bending angle column.

    Raises
    ------
    SessionError
        If the file is missing, malformed, or lacks a column; the message names it.
    """
    header, data = _read_table(path)
    pressure, pname = _column(path, header, data, _PRESSURE, "pressure")
    angle, aname = _column(
        path, header, data, {"bending_angle_rad": 1.0, "bending_angle_deg": math.pi / 180}, "bending angle"
    )
    _require_finite(path, pname, pressure)
    _require_finite(path, aname, angle)
    _check_pressure_unit(path, pname, pressure)
    top = float(np.abs(angle).max())
    if aname == "bending_angle_rad" and top > 2.0 * math.pi:
        raise SessionError(f"{path}: column bending_angle_rad: angles up to {top:g} rad (over a full turn); "
                           "looks like degrees: name the column bending_angle_deg")
    if top > 2.0 * math.pi:  # no bending actuator winds more than a full turn
        row = int(np.argmax(np.abs(angle)))
        raise SessionError(f"{path}: line {row + 2}, column {aname}: a bending angle of {top * 180 / math.pi:g}° "
                           "is more than a full turn; no bending actuator winds that far")
    return pressure, angle


@dataclass(frozen=True, eq=False)
class StiffnessData:
    """Loaded shapes for the stiffness fit, one row per measurement.

    Attributes
    ----------
    pressure_pa : ndarray, shape (n,)
        Gauge pressure [Pa].
    force_n : ndarray, shape (n, 2)
        Known tip force in the base frame [N].
    s_m : ndarray, shape (n, M)
        Arc length of each measured point from the base [m]; NaN where absent.
    positions_m : ndarray, shape (n, M, 2)
        Measured points [m]; NaN where absent.
    """

    pressure_pa: np.ndarray
    force_n: np.ndarray
    s_m: np.ndarray
    positions_m: np.ndarray

    def __post_init__(self):
        p = np.asarray(self.pressure_pa, dtype=float)
        f = np.asarray(self.force_n, dtype=float)
        s = np.asarray(self.s_m, dtype=float)
        r = np.asarray(self.positions_m, dtype=float)
        n = p.shape[0] if p.ndim == 1 else -1
        if p.ndim != 1 or n == 0:
            raise ArgumentError(f"pressure_pa: expected shape (n,) with n >= 1, got {p.shape}")
        if f.shape != (n, 2):
            raise ArgumentError(f"force_n: expected shape ({n}, 2), got {f.shape}")
        if s.ndim != 2 or s.shape[0] != n:
            raise ArgumentError(f"s_m: expected shape ({n}, M), got {s.shape}")
        if r.shape != (*s.shape, 2):
            raise ArgumentError(f"positions_m: expected shape {(*s.shape, 2)}, got {r.shape}")
        for name, arr in (("pressure_pa", p), ("force_n", f)):
            if not np.all(np.isfinite(arr)):
                raise ArgumentError(f"{name}: must be finite")
        seen = np.isfinite(s) & np.all(np.isfinite(r), axis=-1)
        if not np.all(seen.any(axis=1)):
            raise ArgumentError(f"positions_m: row {int(np.argmin(seen.any(axis=1)))} has no measured point")
        for name, arr in (("pressure_pa", p), ("force_n", f), ("s_m", s), ("positions_m", r)):
            object.__setattr__(self, name, arr)

    @property
    def observed(self) -> np.ndarray:
        """Mask (n, M) of the points measured in each row."""
        return np.isfinite(self.s_m) & np.all(np.isfinite(self.positions_m), axis=-1)

    @classmethod
    def from_tip(cls, pressure_pa, force_n, tip_position_m, length_m: float) -> StiffnessData:
        """Data with the tip position r(L) [m] only.

        Parameters
        ----------
        pressure_pa : array_like, shape (K,)
            Pressure of each loaded shape [Pa].
        force_n : array_like, shape (K, 2)
            Tip force of each loaded shape in the base frame [N].
        tip_position_m : array_like, shape (K, 2)
            Measured tip position r(L) [m].
        length_m : float
            Actuator length L [m].
        """
        tip = np.asarray(tip_position_m, dtype=float)
        n = tip.shape[0]
        return cls(np.asarray(pressure_pa, dtype=float), force_n, np.full((n, 1), float(length_m)), tip[:, None, :])


def read_stiffness_csv(path: str | os.PathLike, length_m: float) -> StiffnessData:
    """Read loaded shapes for the stiffness fit (module docstring); ``length_m`` places the tip columns.

    Parameters
    ----------
    path : str or path-like
        CSV file of loaded shapes.
    length_m : float
        Actuator length L [m]: the arc length of the tip columns.

    Raises
    ------
    SessionError
        If the file is missing, malformed, lacks a column or has no measured points.
    """
    header, data = _read_table(path)
    pressure, pname = _column(path, header, data, _PRESSURE, "pressure")
    _require_finite(path, pname, pressure)
    forces = []
    for name in ("fx_n", "fy_n"):
        if name not in header:
            raise SessionError(f"{path}: missing column {name}{_session_hint(header)}")
        forces.append(data[:, header.index(name)])
        _require_finite(path, name, forces[-1])
    s_cols, pos_cols = [], []
    if "tip_x_m" in header or "tip_y_m" in header:
        for name in ("tip_x_m", "tip_y_m"):
            if name not in header:
                raise SessionError(f"{path}: missing column {name} (tip columns come in pairs)")
        s_cols.append(np.full(len(data), float(length_m)))
        pos_cols.append(np.stack([data[:, header.index("tip_x_m")], data[:, header.index("tip_y_m")]], axis=-1))
    i = 1
    while f"s{i}_m" in header or f"x{i}_m" in header or f"y{i}_m" in header:
        names = (f"s{i}_m", f"x{i}_m", f"y{i}_m")
        missing = [n for n in names if n not in header]
        if missing:
            raise SessionError(f"{path}: missing column {', '.join(missing)} (shape point {i} needs s, x and y)")
        s = data[:, header.index(names[0])]
        if np.any(np.isfinite(s) & ((s < 0) | (s > length_m * (1 + 1e-9)))):
            raise SessionError(f"{path}: column {names[0]}: arc lengths must lie in [0, {length_m:g}] m")
        s_cols.append(s)
        pos_cols.append(np.stack([data[:, header.index(names[1])], data[:, header.index(names[2])]], axis=-1))
        i += 1
    if not s_cols:
        raise SessionError(f"{path}: no measured points: give tip_x_m, tip_y_m or s1_m, x1_m, y1_m, ...")
    try:
        result = StiffnessData(pressure, np.stack(forces, axis=-1), np.stack(s_cols, axis=1),
                               np.stack(pos_cols, axis=1))
    except ArgumentError as err:
        raise SessionError(f"{path}: {err}") from None
    _check_pressure_unit(path, pname, pressure)
    reach = np.hypot(result.positions_m[..., 0], result.positions_m[..., 1])
    if np.nanmax(reach, initial=0.0) > 1.05 * length_m:
        raise SessionError(f"{path}: measured points up to {np.nanmax(reach):g} m from the base, farther than the "
                           f"actuator is long ({length_m:g} m); looks like millimetres")
    return result

