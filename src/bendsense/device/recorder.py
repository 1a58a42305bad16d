"""Record a device to a native session directory (:mod:`bendsense.session.native`), crash-safely.

The recorder drains the driver's queue in batches, appends the batches to
``frames.bin`` (unbuffered, so a killed recorder loses nothing it had written;
``fsync`` at least every ``fsync_interval_s``) and writes every driver event (gaps, CRC
errors, reconnects, queue drops, firmware TEXT) to ``events.log``. When the device
fails, the session is closed cleanly and the :class:`~bendsense.errors.DeviceError`
propagates. When the disk fills (or a file-size limit or quota is reached), the
recording stops: every frame written so far is kept, the session is closed and readable,
and the :class:`~bendsense.errors.OutputError` (which says how many frames were kept)
propagates.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import asdict, dataclass

from bendsense import output
from bendsense.errors import DeviceError, OutputError
from bendsense.session.native import SessionWriter, record_dtype, sample_records

__all__ = ["Recorder", "RecorderStats"]

log = logging.getLogger("bendsense.device.recorder")


@dataclass(frozen=True)
class RecorderStats:
    """Counters of a recording (a snapshot).

    Attributes
    ----------
    records : int
        Frames written to ``frames.bin``.
    skipped : int
        Samples not written because their channel count, or their number of pressure
        lines, differed from the session's (the first SAMPLE fixes both).
    lost, crc_errors, malformed, queue_drops, reconnects : int
        The driver's counters (see :class:`bendsense.device.driver.DeviceStats`).
    tx_drops : int
        Frames the firmware could not send during the recording (from the SAMPLEs'
        cumulative ``tx_drops`` counter).
    elapsed_s : float
        Time since the recording started [s].
    """

    records: int
    skipped: int
    lost: int
    crc_errors: int
    malformed: int
    queue_drops: int
    reconnects: int
    elapsed_s: float
    tx_drops: int = 0


def _n_lines(sample) -> int:
    """Pressure lines of a SAMPLE: those of a version-2 frame, else one."""
    return len(getattr(sample, "pressures_pa", ())) or 1


class Recorder:
    """Write the readings of a :class:`~bendsense.device.driver.Driver` to a session directory.

    Parameters
    ----------
    driver : Driver
        An open driver (with a queue).
    path : path
        Session directory to create.
    overwrite : bool
        Replace an earlier session there (only what bendsense wrote; see
        :mod:`bendsense.output`); otherwise :class:`~bendsense.errors.OutputExistsError`.
    config : Config or dict, optional
        Config snapshot for ``meta.yaml``.
    meta : dict, optional
        Further metadata for ``meta.yaml``.
    fsync_interval_s : float
        Longest time between ``fsync`` calls [s] (DESIGN.md: at most 1 s).
    on_records : callable, optional
        Called with the list of readings just written to ``frames.bin`` (on the
        recording thread; e.g. :meth:`bendsense.device.estimator.LiveEstimator.put`).
    extra_files : sequence of str
        Files others write into the session directory (``results.csv``), for its manifest.

    Notes
    -----
    The session is created as soon as the channel count is known (from the HELLO, the
    line layout or the first sample). The first sample gives the number of pressure
    lines: a board that sends SAMPLE version 2 with several lines is recorded with all
    of them (``meta.yaml`` ``n_lines``, see :mod:`bendsense.session.records`). Use :meth:`run` in the current thread, or
    :meth:`start` / :meth:`stop` for a background thread.
    """

    def __init__(self, driver, path, *, overwrite=False, config=None, meta=None, fsync_interval_s=0.5,
                 on_records=None, extra_files=()):
        self.driver = driver
        self.on_records = on_records
        self.extra_files = tuple(extra_files)
        self.path = path
        self.overwrite = bool(overwrite)
        self.config = config
        self.meta = dict(meta or {})
        self.fsync_interval_s = float(fsync_interval_s)
        # before the device is read: an output that may not be written stops us here
        output.check([output.recording(path, overwrite=self.overwrite)])
        self._writer = None
        self._early_events = list(driver.events)  # e.g. the HELLO of the handshake
        self._lock = threading.Lock()
        self._skipped = 0
        self._told = False  # the first sample of another channel count has been said
        self._lines_known = False
        self._tx_last = None  # the firmware's cumulative tx_drops counter at the last sample
        self._tx_drops = 0
        self._t0 = time.monotonic()
        self._stop = threading.Event()
        self._thread = None
        self.error: BaseException | None = None
        driver.add_listener(self._on_event)
        if driver.n_channels is not None:
            self._ensure_writer(driver.n_channels)

    # ------------------------------------------------------------------ state

    @property
    def stats(self) -> RecorderStats:
        """Snapshot of the counters."""
        d = self.driver.stats
        return RecorderStats(
            records=0 if self._writer is None else self._writer.n_records,
            skipped=self._skipped,
            lost=d.lost,
            crc_errors=d.crc_errors,
            malformed=d.malformed,
            queue_drops=d.queue_drops,
            reconnects=d.reconnects,
            elapsed_s=time.monotonic() - self._t0,
            tx_drops=self._tx_drops,
        )

    def _ensure_writer(self, n_channels: int) -> SessionWriter:
        with self._lock:
            if self._writer is None:
                drv = self.driver
                device = {"port": drv.port, "dialect": drv.dialect}
                if drv.hello is not None:
                    device.update(drv.hello.to_dict())
                if drv.dialect == "line":
                    device["columns"] = list(drv.decoder.columns)
                self._writer = SessionWriter(
                    self.path,
                    record_dtype(n_channels, "<u2" if drv.dialect == "binary" else "<f8"),
                    adc_bits=None if drv.hello is None else drv.hello.adc_bits,
                    device=device,
                    config=self.config,
                    meta=self.meta,
                    overwrite=self.overwrite,
                    extra_files=self.extra_files,
                )
                self._writer.fsync_interval_s = self.fsync_interval_s
                for ev in self._early_events:
                    self._writer.event(f"{ev.kind}: {ev.text}", ev.time_s)
                self._early_events = []
            return self._writer

    def _on_event(self, ev) -> None:
        # called from the reader thread
        with self._lock:
            writer = self._writer
            if writer is None:
                self._early_events.append(ev)
                return
        writer.event(f"{ev.kind}: {ev.text}", ev.time_s)

    def _write(self, batch) -> None:
        writer = self._writer or self._ensure_writer(batch[0].sample.n_channels)
        if writer.n_records == 0 and not self._lines_known:  # the board's pressure lines, from its first SAMPLE
            writer.set_lines(_n_lines(batch[0].sample))
            self._lines_known = True
        n, n_lines = writer.n_channels, writer.n_lines
        keep = [r for r in batch if r.sample.n_channels == n and _n_lines(r.sample) == n_lines]
        if len(keep) != len(batch):
            bad = len(batch) - len(keep)
            self._skipped += bad
            other = [r.sample.n_channels for r in batch if r.sample.n_channels != n]
            channels = len(other)
            if channels:
                writer.event(f"skipped: {channels} sample(s) with a channel count other than {n}")
                self._tell_channels(n, other[0])
            if bad - channels:
                writer.event(f"skipped: {bad - channels} sample(s) with a number of pressure lines other than "
                             f"{n_lines}")
        if not keep:
            return
        rec = sample_records(
            writer.dtype, [r.sample for r in keep], [r.host_ns for r in keep], [max(r.device_us, 0) for r in keep]
        )
        drops = [r.sample.tx_drops for r in keep]
        last = drops[0] if self._tx_last is None else self._tx_last
        for value in drops:  # the u16 counter wraps
            self._tx_drops += (value - last) & 0xFFFF
            last = value
        self._tx_last = last
        writer.write(rec)
        if self.on_records is not None:
            self.on_records(keep)

    def _tell_channels(self, n, got) -> None:
        """One line, once per recording, when samples carry another channel count than the session's."""
        if self._told:
            return
        self._told = True
        hello = self.driver.hello
        fixed = (f"the board's HELLO announces {n} channels" if hello is not None and hello.n_channels == n
                 else f"the recording's first sample had {n} channels")
        log.warning("%s: %s, but its samples carry %d: they are skipped, not recorded (count in the summary)",
                    self.driver.port, fixed, got)

    def write(self, readings) -> None:
        """Append driver readings to the session: what :meth:`run` does with each batch it drains.

        For a caller that drains the driver itself (:func:`bendsense.control.run`); the
        session is created with the first readings if the channel count was not known.

        Parameters
        ----------
        readings : list of Reading
            The readings, oldest first.
        """
        if readings:
            self._write(readings)

    # ------------------------------------------------------------------ running

    def run(self, duration_s: float | None = None, *, on_progress=None, progress_interval_s: float = 0.5):
        """Record until ``duration_s`` elapsed, :meth:`stop` is called or the device fails.

        Parameters
        ----------
        duration_s : float, optional
            Recording time [s]; None: until stopped.
        on_progress : callable, optional
            Called with a :class:`RecorderStats` every ``progress_interval_s``.

        Returns
        -------
        RecorderStats

        Raises
        ------
        DeviceError
            If the device disconnects and does not come back; the session written so
            far is closed and readable.
        OutputError
            If the file system refuses a write (a full disk, ...); the frames written
            before are kept, the session is closed and readable.
        """
        self._t0 = time.monotonic()
        end = None if duration_s is None else self._t0 + duration_s
        next_progress = self._t0 + progress_interval_s
        outcome = "stopped"
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if end is not None and now >= end:
                    outcome = "duration reached"
                    break
                wait = 0.1 if end is None else min(0.1, end - now)
                batch = self.driver.get_batch(timeout=max(wait, 0.0))
                if batch:
                    self._write(batch)
                elif self._writer is not None:
                    self._writer.maybe_sync()
                if on_progress is not None and now >= next_progress:
                    on_progress(self.stats)
                    next_progress = now + progress_interval_s
        except DeviceError as err:
            outcome = f"device error: {err}"
            raise
        except OutputError as err:
            outcome = f"output error: {err}"
            raise
        except KeyboardInterrupt:
            outcome = "interrupted"
            raise
        finally:
            self.close(outcome)
        if self._writer is not None and self._writer.failed is not None:
            raise self._writer.failed  # refused at the last sync
        return self.stats

    def close(self, outcome: str = "stopped") -> None:
        """Write the final counters to ``meta.yaml`` and close the session (idempotent).

        Parameters
        ----------
        outcome : str, default "stopped"
            How the recording ended, for ``meta.yaml``.
        """
        with self._lock:
            writer = self._writer
        if writer is None:
            log.warning("%s: no frames received; no session written", self.path)
            return
        if writer.closed:
            return
        stats = self.stats
        writer.event(f"end: {outcome}")
        writer.close({"stats": asdict(stats), "outcome": outcome})

    def start(self, duration_s: float | None = None) -> Recorder:
        """Run :meth:`run` on a background thread.

        Parameters
        ----------
        duration_s : float, optional
            Stop after this long [s]; None records until :meth:`stop`.
        """

        def target():
            try:
                self.run(duration_s)
            except BaseException as err:  # kept for stop() to re-raise
                self.error = err

        self._thread = threading.Thread(target=target, name="bendsense-recorder", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> RecorderStats:
        """Stop the background recording, wait for it and re-raise its error, if any.

        Parameters
        ----------
        timeout_s : float, default 5.0
            Longest wait for the recording thread [s].
        """
        self._stop.set()
        self._join(timeout_s)
        if self.error is not None:
            raise self.error
        return self.stats

    def _join(self, timeout_s: float) -> None:
        """Wait for the recording thread, also one whose ``start()`` a Ctrl-C interrupted while it was starting."""
        if self._thread is None:
            return
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                self._thread.join(max(0.0, deadline - time.monotonic()))
                return
            except RuntimeError:  # "cannot join thread before it is started": it is starting, or never will
                if time.monotonic() >= deadline:
                    return
                time.sleep(0.001)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._join(5.0)
        self.close()
