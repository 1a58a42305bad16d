"""Every frame of a recording estimated as it arrives, on a background thread.

:class:`LiveEstimator` takes the readings the recorder has written (:meth:`put`, never
blocking the recording), processes whatever has queued up as one block with
:class:`~bendsense.pipeline.LiveProcessor` (shapes and warm-started force estimates),
appends the block's rows to ``results.csv`` (:class:`ResultsAppender`) and publishes it
on LSL (:class:`~bendsense.interop.lsl.LslOutlets`), if asked. The backlog (frames
queued, not yet processed) and the processing rate are in :attr:`LiveEstimator.stats`.

A gripper's processor (:class:`~bendsense.pipeline.gripper.GripperProcessor`) gives a block
per finger: each goes to its finger's ``results.csv`` (``SESSION/<finger>/results.csv``)
and its finger's streams (:class:`~bendsense.interop.lsl.GripperOutlets`).
"""

from __future__ import annotations

import collections
import logging
import os
import queue
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from bendsense.errors import BendsenseError, OutputError, SessionError

__all__ = ["LiveEstimator", "EstimatorStats", "ResultsAppender"]

log = logging.getLogger("bendsense.device.estimator")


class ResultsAppender:
    """Append the rows of :class:`~bendsense.pipeline.LiveBlock` s to a ``results.csv``, crash-safely.

    The file is created (or emptied) with the first block, which also writes the
    header: inside a recording, that is after the session directory was set up by the
    output layer (:func:`bendsense.output.begin_in_place`, which lists this file in the
    directory's manifest and decides about ``--overwrite``). Every block's rows go to
    the file in one unbuffered write of whole lines (a killed process leaves no torn row
    behind what it had written), and ``os.fsync`` runs at least every
    ``fsync_interval_s``. A write the file system refuses (a full disk) is cut back to
    the rows before it and raises :class:`~bendsense.errors.OutputError`.

    Parameters
    ----------
    path : path
        The CSV file.
    fsync_interval_s : float
        Longest time between ``fsync`` calls while writing [s].
    """

    def __init__(self, path, *, fsync_interval_s: float = 0.5):
        self.path = Path(path)
        self.fsync_interval_s = float(fsync_interval_s)
        self._fd = None
        self._size = 0  # bytes of whole rows in the file
        self._header = None
        self._last_sync = time.monotonic()
        self.rows = 0

    def write(self, block) -> None:
        """Append the rows of ``block``.

        Parameters
        ----------
        block : LiveBlock
            The processed frames to append.
        """
        from bendsense.session.cells import column_cells

        columns = block.columns()
        names = list(columns)
        text = []
        if self._header is None:
            self._header = names
            text.append(",".join(names))
        elif names != self._header:
            raise SessionError(f"{self.path}: a block with columns {names} after {self._header}")
        cells = [column_cells(v) for v in columns.values()]
        text.extend(",".join(row) for row in zip(*cells))
        data = memoryview(("\n".join(text) + "\n").encode("utf-8"))
        try:
            if self._fd is None:
                self.path.parent.mkdir(exist_ok=True)  # a gripper's finger directory, inside the session
                self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
                self._size = 0
            while data:
                data = data[os.write(self._fd, data):]
            self._size = os.fstat(self._fd).st_size
            self.rows += len(block)
            if time.monotonic() - self._last_sync >= self.fsync_interval_s:
                self.sync()
        except OSError as err:
            raise self._refused(err) from None

    def _refused(self, err: OSError) -> OutputError:
        from bendsense import output

        if self._fd is not None:
            try:  # no torn row: back to the rows written whole
                os.ftruncate(self._fd, self._size)
                os.fsync(self._fd)
            except OSError:
                pass
        return output.write_error(self.path, err, f"estimation stopped; {self.rows:,} rows kept")

    def sync(self) -> None:
        """``fsync`` the file."""
        if self._fd is not None:
            os.fsync(self._fd)
        self._last_sync = time.monotonic()

    def close(self) -> None:
        """Sync and close (idempotent)."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            try:
                os.fsync(fd)
            except OSError as err:
                raise self._refused(err) from None
            finally:
                os.close(fd)


@dataclass(frozen=True)
class EstimatorStats:
    """What a :class:`LiveEstimator` did so far (a snapshot).

    Attributes
    ----------
    frames : int
        Frames processed (shape and force).
    backlog : int
        Frames received but not processed yet.
    rate_hz : float
        Frames processed per second over the last second [1/s].
    failures : int
        Force estimates that did not converge.
    status_counts : dict
        Frames per status (``ok``, ``extrapolated``, ``not converged``, ...).
    """

    frames: int
    backlog: int
    rate_hz: float
    failures: int
    status_counts: dict = field(default_factory=dict)


class LiveEstimator:
    """Process every reading, in blocks, on a background thread.

    Parameters
    ----------
    processor : LiveProcessor or GripperProcessor
        Shapes and forces of a block of frames (a gripper's: a block per finger).
    results_path : path or mapping of str to path, optional
        ``results.csv`` to append every processed block to (created at the first block);
        for a gripper, one per finger name (its directory is made when the file is).
    outlets : LslOutlets or GripperOutlets, optional
        Publish every block on LSL.
    max_block : int
        Most frames processed in one block.
    fsync_interval_s : float
        Longest time between ``fsync`` calls of ``results.csv`` [s].
    on_block : callable, optional
        Called with each :class:`~bendsense.pipeline.LiveBlock` (on the thread; a
        gripper's: the dict of its fingers' blocks).
    """

    def __init__(self, processor, *, results_path=None, outlets=None, max_block=512, fsync_interval_s=0.5,
                 on_block=None):
        self.processor = processor
        if results_path is None:
            self.writers = {}
        elif isinstance(results_path, Mapping):  # a gripper: a results.csv per finger
            self.writers = {name: ResultsAppender(path, fsync_interval_s=fsync_interval_s)
                            for name, path in results_path.items()}
        else:
            self.writers = {None: ResultsAppender(results_path, fsync_interval_s=fsync_interval_s)}
        self.outlets = outlets
        self.max_block = int(max_block)
        self.on_block = on_block
        self.error: BaseException | None = None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._backlog = 0
        self._done = collections.deque()  # (monotonic time, frames) of recent blocks
        self._stop = threading.Event()
        self._abandon = threading.Event()  # stop at the next block, backlog or not (an interrupted close)
        self._thread = threading.Thread(target=self._run, name="bendsense-estimator", daemon=True)
        self._thread.start()

    @property
    def stats(self) -> EstimatorStats:
        """Counters so far."""
        now = time.monotonic()
        with self._lock:
            while self._done and self._done[0][0] < now - 1.0:
                self._done.popleft()
            recent = sum(n for _, n in self._done)
            backlog = self._backlog
        p = self.processor
        return EstimatorStats(frames=p.frames, backlog=backlog, rate_hz=float(recent), failures=p.failures,
                              status_counts=dict(p.status_counts))

    def put(self, readings) -> None:
        """Queue readings (:class:`~bendsense.device.driver.Reading`) for processing; never blocks.

        Parameters
        ----------
        readings : list of Reading
            Readings as the recorder wrote them.
        """
        if self.error is not None:  # stops the recording: its frames would get no results
            raise self.error
        readings = list(readings)
        if readings:
            with self._lock:
                self._backlog += len(readings)
            self._queue.put(readings)

    def _take(self, timeout: float) -> list:
        try:
            out = self._queue.get(timeout=timeout)
        except queue.Empty:
            return []
        while len(out) < self.max_block:
            try:
                out += self._queue.get_nowait()
            except queue.Empty:
                break
        return out

    def _run(self) -> None:
        pending = []
        try:
            while True:
                if not pending:
                    pending = self._take(0.1)
                if not pending:
                    if self._stop.is_set():
                        return
                    continue
                if self._abandon.is_set():
                    return
                readings, pending = pending[: self.max_block], pending[self.max_block:]
                block = self.processor.process_readings(readings)
                for name, part in (block.items() if isinstance(block, dict) else ((None, block),)):
                    if name in self.writers:
                        self.writers[name].write(part)
                if self.outlets is not None:
                    self.outlets.push(block)
                if self.on_block is not None:
                    self.on_block(block)
                with self._lock:
                    self._backlog -= len(readings)
                    self._done.append((time.monotonic(), len(readings)))
        except BaseException as err:  # kept for close() to re-raise
            if not isinstance(err, BendsenseError):  # a user-level error is one line, where it is re-raised
                log.exception("live estimation failed")
            self.error = err

    def close(self, timeout_s: float | None = None) -> EstimatorStats:
        """Process what is queued, then stop; close ``results.csv``; re-raise a failure of the thread.

        Parameters
        ----------
        timeout_s : float, optional
            Longest wait for the backlog [s]; None: until it is done. What is left then is
            not processed (``results.csv`` ends with whole rows of the frames before it);
            the block being processed is finished first.
        """
        self._stop.set()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            self._abandon.set()
            self._thread.join()
        for writer in self.writers.values():
            writer.close()
        if self.outlets is not None:
            self.outlets.close()
        if self.error is not None:
            raise self.error
        return self.stats
