"""A control session on disk: the board's native session, the per-frame control log and the results.

``bendsense control ... -o SESSION`` writes one directory:

- the native session of the board (``meta.yaml``, ``frames.bin``, ``events.log``:
  :class:`bendsense.device.recorder.Recorder`, every frame as it arrived, crash-safe;
  ``meta.yaml`` keeps the controller's settings under ``control``), readable by every
  command that takes a session;
- ``control.csv``: a row per frame (module :mod:`bendsense.control.record`, columns in
  docs/formats.md, "Control log"): ``t_s, seq, host_s``, per controlled finger the normal
  force, its σ, the contact location, the target and the status, then per pressure line
  the set-point sent after the frame's block and the line's measured pressure
  (``line<k>_setpoint_pa, line<k>_pressure_pa``; a single actuator: ``setpoint_pa,
  pressure_pa`` and no finger prefixes, as the simulator's truth file);
- the force results of every frame, as ``record --estimate`` writes them:
  ``results.csv`` (one actuator) or ``<finger>/results.csv`` (a gripper).

Rows are appended block by block in whole lines and synced at least every 0.5 s
(:class:`bendsense.device.estimator.ResultsAppender`), so a killed loop keeps what it
had written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["ControlRecording", "CONTROL_LOG", "control_files"]

#: the per-frame control log in a control session
CONTROL_LOG = "control.csv"


def control_files(fingers) -> list:
    """The files a control session writes beside the native session's own.

    Parameters
    ----------
    fingers : sequence of str or None
        The gripper's fingers (None: a single actuator: ``results.csv``).
    """
    results = ["results.csv"] if fingers is None else [f"{name}/results.csv" for name in fingers]
    return [CONTROL_LOG, *results]


class _Rows:
    """Columns in the shape :class:`~bendsense.device.estimator.ResultsAppender` takes (a block's ``columns()``)."""

    def __init__(self, columns: dict, n: int):
        self._columns = columns
        self._n = n

    def columns(self) -> dict:
        return self._columns

    def __len__(self) -> int:
        return self._n


class ControlRecording:
    """Record a control session: the readings, the control log and the results (module docstring).

    Parameters
    ----------
    driver : Driver
        The open board.
    path : path
        The session directory (checked and locked by the caller; see :mod:`bendsense.output`).
    overwrite : bool
        Replace an earlier session there.
    config : Config or GripperConfig, optional
        Snapshot for ``meta.yaml``.
    meta : dict, optional
        Further metadata (the controller's settings).
    fingers : sequence of str or None
        A gripper's fingers (their results go to ``<finger>/results.csv``); None: one actuator.
    """

    def __init__(self, driver, path, *, overwrite=False, config=None, meta=None, fingers=None):
        from bendsense.device.estimator import ResultsAppender
        from bendsense.device.recorder import Recorder

        self.path = Path(path)
        self.fingers = None if fingers is None else tuple(fingers)
        self.recorder = Recorder(driver, self.path, overwrite=overwrite, config=config, meta=meta,
                                 extra_files=control_files(self.fingers))
        self.log = ResultsAppender(self.path / CONTROL_LOG)
        names = [None] if self.fingers is None else list(self.fingers)
        self.results = {name: ResultsAppender(self.path / ("results.csv" if name is None else f"{name}/results.csv"))
                        for name in names}
        self._host0_ns = None

    def write_readings(self, readings) -> None:
        """Append the readings to the native session.

        Parameters
        ----------
        readings : list of Reading
            The driver's readings of the block.
        """
        self.recorder.write(readings)

    def write_block(self, readings, block, setpoints: dict, lines, controller) -> None:
        """Append the block's control-log rows and force results.

        Parameters
        ----------
        readings : list of Reading
            The driver's readings of the block.
        block : LiveBlock or dict of str to LiveBlock
            The processor's result.
        setpoints : dict of int to float
            The set-points sent after the block [Pa] (every line the loop drives).
        lines : sequence of int
            The board's pressure lines, for the columns.
        controller : callable
            The controller; its ``columns()`` (if it has one) joins the log.
        """
        blocks = block if isinstance(block, dict) else {None: block}
        first = next(iter(blocks.values()))
        n = len(first)
        if self._host0_ns is None:
            self._host0_ns = int(readings[0].host_ns)
        cols = {"t_s": first.t_s, "seq": first.seq,
                "host_s": (np.asarray(first.host_ns, dtype=np.int64) - self._host0_ns) * 1e-9}
        own = getattr(controller, "columns", None)
        if own is not None:
            cols.update(own())
        measured = line_pressures(readings, lines)
        single = self.fingers is None and tuple(lines) == (0,)  # one actuator: no prefixes (as the truth file)
        for k in lines:
            prefix = "" if single else f"line{k}_"
            cols[f"{prefix}setpoint_pa"] = np.full(n, setpoints.get(k, np.nan))
            cols[f"{prefix}pressure_pa"] = measured[k]
        self.log.write(_Rows(cols, n))
        for name, appender in self.results.items():
            if name is not None:
                (self.path / name).mkdir(exist_ok=True)
            appender.write(blocks[name])

    def close(self, outcome: str) -> None:
        """Close the files and the session (``meta.yaml`` gets ``outcome``); idempotent.

        Parameters
        ----------
        outcome : str
            How the loop ended.
        """
        try:
            for appender in (self.log, *self.results.values()):
                appender.close()
        finally:
            self.recorder.close(outcome)


def line_pressures(readings, lines) -> dict:
    """The measured pressure of every line in each reading [Pa] (NaN: no reading).

    Parameters
    ----------
    readings : list of Reading
        Driver readings.
    lines : sequence of int
        The lines.
    """
    out = {k: np.full(len(readings), np.nan) for k in lines}
    for i, r in enumerate(readings):
        values = getattr(r.sample, "pressures_pa", ()) or (r.sample.pressure_pa,)
        for k in lines:
            v = values[k] if k < len(values) else None
            if v is not None:
                out[k][i] = v
    return out
