"""The simulated board's truth file: one CSV row per SAMPLE frame, written as the frames go out.

``sim-device --truth FILE.csv`` writes it so that any client of the simulated board can be
scored. A comment line marks the file as bendsense's, then the header and one row per
frame: ``seq, t_us`` (as in the frame), then per finger ``<finger>_fx_n, <finger>_fy_n,
<finger>_contact_s_m`` and per pressure line ``line<k>_setpoint_pa, line<k>_pressure_pa``
(a single actuator: ``fx_n, fy_n, contact_s_m, setpoint_pa, pressure_pa``, no prefix).
Rows are flushed to the file after every burst of frames, so the file is readable while
the board runs and after it is killed (at most the last line is cut short).
"""

from __future__ import annotations

import math
from pathlib import Path

__all__ = ["KIND", "TruthWriter", "scenario_truth", "truth_columns"]

_HEADER = "# bendsense sim-device truth: the simulator's force, contact and pressures per frame\n"
#: the truth file's mark and name: ``--overwrite`` replaces a truth file only (:class:`bendsense.output.Target`)
KIND = (_HEADER[:28].encode(), "sim-device truth file")

_PER_FINGER = ("fx_n", "fy_n", "contact_s_m")
_PER_LINE = ("setpoint_pa", "pressure_pa")


def truth_columns(fingers=None, n_lines: int = 1) -> list[str]:
    """The truth file's columns.

    Parameters
    ----------
    fingers : sequence of str, optional
        The fingers' names; None: a single actuator (no prefixes).
    n_lines : int
        Pressure lines (a gripper only).

    Returns
    -------
    list of str
        ``seq, t_us`` and the truth columns.
    """
    if fingers is None:
        return ["seq", "t_us", *_PER_FINGER, *_PER_LINE]
    names = [f"{f}_{c}" for f in fingers for c in _PER_FINGER]
    return ["seq", "t_us", *names, *(f"line{k}_{c}" for k in range(n_lines) for c in _PER_LINE)]


def _text(value) -> str:
    if isinstance(value, int):
        return str(value)
    value = float(value)
    return repr(value) if math.isfinite(value) else "nan"


class TruthWriter:
    """Append the truth of each frame to a CSV file, in place.

    Parameters
    ----------
    path : path
        The file (created or truncated; the caller checks the path first).
    columns : list of str
        From :func:`truth_columns`.
    """

    def __init__(self, path, columns):
        self.path = Path(path)
        self.columns = list(columns)
        self._values = self.columns[2:]
        self._fh = open(self.path, "w", encoding="utf-8", newline="")  # noqa: SIM115 (closed by close())
        self._fh.write(_HEADER)
        self._fh.write(",".join(self.columns) + "\n")
        self._fh.flush()
        self.rows = 0

    def write(self, seq: int, t_us: int, truth: dict) -> None:
        """Add the row of one frame (buffered until :meth:`flush`).

        Parameters
        ----------
        seq, t_us : int
            The frame's sequence number and device clock.
        truth : dict
            A value for every truth column (missing ones are written as nan).
        """
        values = [_text(truth.get(c, math.nan)) for c in self._values]
        self._fh.write(f"{seq},{t_us}," + ",".join(values) + "\n")
        self.rows += 1

    def flush(self) -> None:
        """Hand the buffered rows to the operating system."""
        if not self._fh.closed:
            self._fh.flush()

    def close(self) -> None:
        """Flush and close the file."""
        if not self._fh.closed:
            self._fh.flush()
            self._fh.close()


def scenario_truth(frames):
    """The single actuator's time-varying stream with its truth as the truth file's columns.

    Parameters
    ----------
    frames : iterator
        Of ``(pressure_pa, counts, truth)`` from
        :func:`~bendsense.sim.scenarios.time_varying_frames` with ``truth=True``.

    Yields
    ------
    tuple
        ``(pressure_pa, counts, row)``: ``row`` holds ``fx_n, fy_n, contact_s_m`` and the
        scenario's pressure as both ``setpoint_pa`` and ``pressure_pa`` (it has no regulator).
    """
    for pressure, counts, truth in frames:
        row = {"fx_n": truth["fx_n"], "fy_n": truth["fy_n"], "contact_s_m": truth["contact_s_m"],
               "setpoint_pa": pressure, "pressure_pa": pressure}
        yield pressure, counts, row
