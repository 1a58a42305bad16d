"""A block of driver readings as the arrays the live processors take (one finger or a whole board).

:func:`reading_columns` is the one conversion of :class:`~bendsense.device.driver.Reading`
s into per-frame arrays: the board's signals, its pressure lines, the frame times from the
first reading a processor saw, and the columns a recording of these readings has beside
its own. :meth:`bendsense.pipeline.LiveProcessor.process_readings` (one actuator) and
:meth:`bendsense.pipeline.gripper.GripperProcessor.process_readings` (a gripper, which then
splits the board per finger) both read readings through it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from bendsense.wire.frames import BAD_READING

__all__ = ["ReadingColumns", "ReadingClock", "reading_columns", "sample_lines"]


class ReadingColumns(NamedTuple):
    """Per-frame arrays of a block of readings (a named tuple: a live loop makes one per block).

    Attributes
    ----------
    signals : ndarray, shape (n, N)
        Raw ADC counts of the board's N channels [counts].
    pressure_pa : ndarray, shape (n,)
        Pressure of line 0 [Pa] (the SAMPLE's ``pressure_pa``); NaN: no reading.
    pressures_pa : ndarray, shape (n, n_lines)
        Pressure of every line the frames carry [Pa] (a version-1 frame: line 0 only);
        NaN: no reading, or a line a frame does not carry.
    t_s : ndarray, shape (n,)
        Device clock from the time origin [s].
    seq : list of int
        Raw sequence numbers.
    host_ns : list of int
        Arrival time of each frame on the host clock [ns].
    extra : Mapping of str to ndarray
        The columns a recording of the readings has beside its own
        (:func:`bendsense.session.native.records_extra`), made when first read.
    """

    signals: np.ndarray
    pressure_pa: np.ndarray
    pressures_pa: np.ndarray
    t_s: np.ndarray
    seq: list
    host_ns: list
    extra: Mapping


def sample_lines(sample) -> tuple:
    """The pressures of a SAMPLE's lines [Pa], None for no reading: ``pressures_pa``, else line 0 alone.

    Parameters
    ----------
    sample : Sample
        A decoded SAMPLE frame (version 1 carries one line, ``pressure_pa``).
    """
    lines = tuple(getattr(sample, "pressures_pa", ()) or ())
    return lines if lines else (sample.pressure_pa,)


def reading_columns(readings, t0_us: int, host0_ns: int | None) -> ReadingColumns:
    """The arrays of a block of readings.

    Parameters
    ----------
    readings : list of Reading
        Driver readings, oldest first.
    t0_us : int
        Device clock of the time origin [us] (the first reading the processor saw).
    host0_ns : int or None
        Host clock of that reading [ns] (the ``host_s`` column's origin).

    Returns
    -------
    ReadingColumns
    """
    readings = list(readings)
    n = len(readings)
    samples = [r.sample for r in readings]
    signals = np.array([s.adc for s in samples], dtype=float).reshape(n, -1)
    flagged = [i for i, s in enumerate(samples) if s.status & BAD_READING]
    if flagged:  # readings the board flags (clipped, unsettled): no shape, as the offline run (an empty index: 1 µs)
        signals[flagged] = np.nan
    lines = [sample_lines(s) for s in samples]
    width = max(map(len, lines)) if n else 1
    if any(len(x) < width for x in lines):  # frames of fewer lines: no reading of the others
        lines = [x + (None,) * (width - len(x)) for x in lines]
    # a float array takes None as NaN: no reading; the device clock in whole microseconds, exact in a float64
    return ReadingColumns(
        signals=signals,
        pressure_pa=np.array([s.pressure_pa for s in samples], dtype=float),
        pressures_pa=np.array(lines, dtype=float).reshape(n, width),
        t_s=(np.array([r.device_us for r in readings], dtype=float) - t0_us) * 1e-6,
        seq=[s.seq for s in samples],
        host_ns=[r.host_ns for r in readings],
        extra=_RecordColumns(readings, signals.shape[1], host0_ns),
    )


class _RecordColumns(Mapping):
    """The columns a recording of the readings has beside its own, made when first read.

    :func:`bendsense.session.native.records_extra` of the records the recorder writes of
    these readings. Only a block that is saved reads them (``record --estimate``); a
    control loop never does.
    """

    def __init__(self, readings, channels, host0_ns):
        self._readings, self._channels, self._host0_ns, self._columns = readings, channels, host0_ns, None

    def _made(self) -> dict:
        if self._columns is None:
            from bendsense.session.native import record_dtype, records_extra, sample_records

            readings = self._readings
            records = sample_records(record_dtype(max(self._channels, 1), "<f8"), [r.sample for r in readings],
                                     [r.host_ns for r in readings], [max(r.device_us, 0) for r in readings])
            self._columns = records_extra(records, self._host0_ns)
        return self._columns

    def __getitem__(self, name):
        return self._made()[name]

    def __iter__(self):
        return iter(self._made())

    def __len__(self) -> int:
        return len(self._made())


class ReadingClock:
    """The time origin of a live processor's readings: the first reading it saw since it was made or reset."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        """Forget the origin: the next block's first reading is ``t_s = 0``."""
        self.t0_us = None
        self.host0_ns = None

    def columns(self, readings) -> ReadingColumns:
        """:func:`reading_columns` of a block of readings, timed from the origin (set by the first block).

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.
        """
        readings = list(readings)
        if self.t0_us is None and readings:
            self.t0_us = readings[0].device_us
            self.host0_ns = readings[0].host_ns
        return reading_columns(readings, 0 if self.t0_us is None else self.t0_us, self.host0_ns)
