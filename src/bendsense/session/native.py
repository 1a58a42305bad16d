"""Native session directory (DESIGN.md section 3): crash-safe recording of device frames.

A session is a directory::

    meta.yaml    format name and version, device HELLO, channel count, ADC bits, record
                 dtype, start time, config snapshot; written atomically (rewritten at close
                 with the end time and the counters)
    frames.bin   append-only fixed-size little-endian records, no header
    events.log   one line per event: ISO-8601 UTC time, a space, the text

The record (:func:`record_dtype`) is ``host_ns``, the SAMPLE's fields of
:data:`bendsense.wire.frames.SAMPLE_FIELDS` and the ADC counts; today, in this order and packed::

    host_ns      <i8      host clock, time.monotonic_ns() when the bytes were read [ns]
    t_us         <u8      device clock, unwrapped (u32 wraps removed by the driver) [us]
    seq          <u2      device sequence number, raw (wraps at 65536)
    status       u1       status bits of the SAMPLE
    tx_drops     <u2      the firmware's cumulative count of frames it could not send
                          (version 2; wraps at 65536)
    pressure_pa  <i4      pressure [Pa]; 0x7FFFFFFF = no reading
    adc          (N,)<u2  raw counts (a line-dialect or imported session may use <f8)
    pressures_pa (K,)<i4  several pressure lines only (meta.yaml n_lines = K > 1): each
                          line's pressure, NO_PRESSURE = no reading; pressure_pa is line 0
                          (bendsense.session.records)

``meta.yaml`` lists the dtype as ``[name, numpy dtype string]`` pairs, so a reader never
guesses the layout; further fields (from an imported CSV) follow the standard ones and
are read back into ``Session.extra``. ``meta["start_host_ns"]`` pairs the monotonic host
clock with ``meta["start_time_utc"]``.

Writes go straight to the OS (unbuffered), so a killed recorder loses nothing it had
written; ``os.fsync`` runs at least once a second against power loss. ``meta.yaml``
says ``finished: false`` until a clean stop rewrites it with ``finished: true`` and the
record count ``n_records``.

A full disk (or a file-size limit, a quota) stops the writer, never the session: the
writer cuts ``frames.bin`` back to its last whole record, keeps every frame written
before, and raises an :class:`~bendsense.errors.OutputError` that says how many frames
it kept. A hidden reserve file (:data:`RESERVE_BYTES`, removed at close) is given back
to the file system first, so that the final ``meta.yaml`` still fits and the session
ends finished.

The reader compares ``frames.bin`` with ``meta.yaml`` and tells the truth:

- the record dtype must be the format's (standard fields with their types, ``adc``
  with ``n_channels`` values) and its size ``record_size``; raw counts must fit
  ``adc_bits``: an edited dtype is an error, never garbage;
- a finished session must hold exactly ``n_records`` whole records: fewer is an
  error with the numbers (``745 of 1,500 records present; 755 lost``);
- an unfinished session (killed, crashed, still recording) is read with a warning
  that says so; its torn last record (a partial write) is ignored and counted in
  ``meta["torn_bytes"]``.

Version 1 (no ``tx_drops``, no ``finished`` flag: a session without ``n_records`` is
unfinished) is read as before.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import functools
import logging
import os
import threading
import time
from pathlib import Path

import numpy as np
import yaml

from bendsense import validation as check
from bendsense._io import check_regular_file, open_regular, read_yaml
from bendsense.errors import OutputError, SessionError
from bendsense.session.csvfile import read_session_csv, write_session_csv
from bendsense.session.records import (
    LINES_FIELD,
    SESSION_COLUMNS,
    records_extra,
    records_to_session,
)
from bendsense.validation import short
from bendsense.wire.frames import MAX_LINES, NO_PRESSURE, SAMPLE_FIELDS

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "NO_PRESSURE",
    "record_dtype",
    "sample_records",
    "records_extra",
    "dtype_to_list",
    "dtype_from_list",
    "is_session_dir",
    "SessionWriter",
    "read_session_meta",
    "read_records",
    "records_to_session",
    "read_session_dir",
    "export_session_csv",
    "import_session_csv",
]

log = logging.getLogger("bendsense.session")

FORMAT = "bendsense-session"
FORMAT_VERSION = 2
READ_VERSIONS = (1, 2)
META = "meta.yaml"
FRAMES = "frames.bin"
EVENTS = "events.log"
HOST_FIELD = ("host_ns", "<i8")  # the host's clock when it read the frame: first in every record
ADC_TYPES = ("<u2", "<f4", "<f8")


def _field_types() -> dict:
    """The fixed type of each standard scalar field."""
    return dict([HOST_FIELD, *((f.name, f.dtype) for f in SAMPLE_FIELDS)])


def _standard_fields(version: int) -> list:
    """The fields every record of ``version`` has, oldest first (the order of messages)."""
    fields = [(HOST_FIELD[0], 1), *((f.name, f.since) for f in SAMPLE_FIELDS), ("adc", 1)]
    return [name for name, since in sorted(fields, key=lambda f: f[1]) if since <= version]


STANDARD_FIELDS = tuple(_standard_fields(1))  # the fields of version 1
FIELD_TYPES = _field_types()


def utc_now_iso(t: float | None = None) -> str:
    """ISO-8601 UTC time with microseconds and a ``Z`` suffix."""
    t = time.time() if t is None else t
    return _dt.datetime.fromtimestamp(t, _dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def record_dtype(n_channels: int, adc_dtype: str = "<u2", extra_fields=(), n_lines: int = 1) -> np.dtype:
    """Structured dtype of one ``frames.bin`` record (packed, little-endian).

    ``host_ns``, the fields of :data:`bendsense.wire.frames.SAMPLE_FIELDS`, ``adc``, with
    several pressure lines ``pressures_pa`` (``(n_lines,)<i4``), then ``extra_fields``.

    Parameters
    ----------
    n_channels : int
        Number of ADC channels N (1..64).
    adc_dtype : str
        dtype of the ADC values: ``"<u2"`` for raw counts, ``"<f4"``/``"<f8"`` for
        sessions whose signals are not raw counts.
    extra_fields : sequence of (name, dtype str)
        Further per-frame columns appended after the standard ones.
    n_lines : int, default 1
        Pressure lines of the board (1..255); more than one adds ``pressures_pa``
        (``pressure_pa`` then holds line 0). One line gives today's record, unchanged.
    """
    n = int(n_channels)
    if not 1 <= n <= 64:
        raise SessionError(f"n_channels: expected 1..64, got {n_channels!r}")
    if isinstance(n_lines, bool) or not isinstance(n_lines, (int, np.integer)) or not 1 <= n_lines <= MAX_LINES:
        raise SessionError(f"n_lines: expected 1..{MAX_LINES} pressure lines, got {n_lines!r}")
    return _record_dtype(n, adc_dtype, tuple((str(name), dt) for name, dt in extra_fields), int(n_lines), SAMPLE_FIELDS)


@functools.lru_cache(maxsize=64)
def _record_dtype(n: int, adc_dtype: str, extra_fields: tuple, n_lines: int, sample_fields: tuple) -> np.dtype:
    """:func:`record_dtype` of checked arguments and the wire's fields, made once (a live loop asks every block)."""
    lines = [(LINES_FIELD, np.dtype("<i4"), (int(n_lines),))] if n_lines > 1 else []
    fields = [
        HOST_FIELD,
        *((f.name, f.dtype) for f in sample_fields),
        ("adc", np.dtype(adc_dtype).newbyteorder("<"), (n,)),
        *lines,
        *[(name, np.dtype(dt).newbyteorder("<")) for name, dt in extra_fields],
    ]
    return np.dtype(fields)


def sample_records(dtype: np.dtype, samples, host_ns, t_us) -> np.ndarray:
    """Records of ``dtype`` holding ``samples``, as the recorder writes them.

    Every field of :data:`bendsense.wire.frames.SAMPLE_FIELDS` is the sample's attribute of
    the same name, except two: ``t_us`` is the device clock given here, unwrapped, and
    ``pressure_pa`` is rounded to whole pascals, with :data:`NO_PRESSURE` for None (no
    reading). Further fields of ``dtype`` are left zero, and so is a field the sample has no
    attribute for (a reading made up by hand, without ``status`` or ``tx_drops``). A
    ``dtype`` with several pressure lines takes each sample's ``pressures_pa`` (a sample
    without them, or with fewer, gives its ``pressure_pa`` as line 0 and no reading for
    the others; a sample with more lines than the session has is refused).

    Parameters
    ----------
    dtype : numpy.dtype
        A record dtype (:func:`record_dtype`).
    samples : sequence of Sample
        Decoded SAMPLE frames (:class:`bendsense.wire.frames.Sample`), all with as many
        channels as ``dtype``.
    host_ns : sequence of int, length len(samples)
        Host clock when each sample's bytes were read [ns].
    t_us : sequence of int, length len(samples)
        Device clock of each sample with the u32 wraps removed [us].

    Returns
    -------
    ndarray of dtype, shape (len(samples),)
    """
    rec = np.zeros(len(samples), dtype=dtype)
    rec["host_ns"] = host_ns
    rec["t_us"] = t_us
    for f in SAMPLE_FIELDS:
        if f.name not in ("t_us", "pressure_pa"):
            rec[f.name] = [getattr(s, f.name, 0) for s in samples]
    rec["pressure_pa"] = [NO_PRESSURE if s.pressure_pa is None else round(s.pressure_pa) for s in samples]
    rec["adc"] = np.array([s.adc for s in samples])
    if LINES_FIELD in dtype.names:
        rec[LINES_FIELD] = _line_records(dtype, samples)
        rec["pressure_pa"] = rec[LINES_FIELD][:, 0]
    return rec


def _line_records(dtype: np.dtype, samples) -> np.ndarray:
    """The ``pressures_pa`` field of ``samples`` (NO_PRESSURE for no reading)."""
    n_lines = dtype.fields[LINES_FIELD][0].shape[0]
    out = np.full((len(samples), n_lines), NO_PRESSURE, dtype=np.int64)
    for i, s in enumerate(samples):
        lines = getattr(s, "pressures_pa", ()) or (s.pressure_pa,)
        if len(lines) > n_lines:
            raise SessionError(f"samples: sample {i} has {len(lines)} pressure lines, the session {n_lines}")
        out[i, : len(lines)] = [NO_PRESSURE if v is None else round(v) for v in lines]
    return out


def dtype_to_list(dtype: np.dtype) -> list:
    """``[[name, dtype string], ...]`` for ``meta.yaml``; sub-arrays as ``"(N,)<u2"``.

    Parameters
    ----------
    dtype : numpy.dtype
        A structured record dtype.
    """
    out = []
    for name in dtype.names:
        ft = dtype.fields[name][0]
        if ft.subdtype is not None:
            base, shape = ft.subdtype
            out.append([name, f"{tuple(shape)}{base.str}".replace(" ", "")])
        else:
            out.append([name, ft.str])
    return out


def dtype_from_list(pairs, *, version: int = FORMAT_VERSION, n_channels: int | None = None) -> np.dtype:
    """Inverse of :func:`dtype_to_list`, checked against the format.

    Raises :class:`SessionError` on a malformed list, a missing standard field, a
    standard field of another type, or an ``adc`` of another length than ``n_channels``.

    Parameters
    ----------
    pairs : list
        ``[[name, dtype string], ...]`` as read from ``meta.yaml``.
    version : int, default 2
        Format version of the session (version 1 has no ``tx_drops``).
    n_channels : int, optional
        Channel count the ``adc`` field must have.
    """
    where = "meta.yaml record_dtype"
    try:
        dt = np.dtype([(str(name), str(spec)) for name, spec in pairs])
    except (TypeError, ValueError) as err:
        raise SessionError(f"{where}: invalid ({' '.join(str(err).split())[:80]}); got {short(pairs)}") from None
    loose = [name for name in dt.names if dt.fields[name][0].hasobject or dt.fields[name][0].base.kind not in "biuf"]
    if loose:
        raise SessionError(f"{where}: field {loose[0]}: expected a number type (integer, float or bool), got "
                           f"{dt.fields[loose[0]][0].str}")
    standard = _standard_fields(version)
    missing = [f for f in standard if f not in dt.names]
    if missing:
        raise SessionError(f"{where}: missing fields {missing}")
    for name, want in _field_types().items():
        if name in dt.names and name in standard and dt.fields[name][0].str != np.dtype(want).str:
            raise SessionError(f"{where}: field {name}: expected {want}, got {dt.fields[name][0].str} "
                               "(an edited record dtype?)")
    adc = dt.fields["adc"][0]
    base, shape = (adc.subdtype if adc.subdtype is not None else (adc, ()))
    if base.str not in ADC_TYPES or len(shape) != 1:
        got = dict((str(k), v) for k, v in pairs).get("adc")
        raise SessionError(f"{where}: field adc: expected (N,) of {', '.join(ADC_TYPES)}, got {short(got)}")
    if n_channels is not None and shape[0] != n_channels:
        raise SessionError(f"{where}: field adc: expected {n_channels} values (n_channels), got {shape[0]}")
    if LINES_FIELD in dt.names:
        lines = dt.fields[LINES_FIELD][0]
        if lines.subdtype is None or lines.subdtype[0].str != "<i4" or len(lines.shape) != 1 \
                or not 2 <= lines.shape[0] <= MAX_LINES:
            raise SessionError(f"{where}: field {LINES_FIELD}: expected (n_lines,)<i4 with 2..{MAX_LINES} lines, got "
                               f"{short(dict((str(k), v) for k, v in pairs).get(LINES_FIELD))}")
    return dt


def _layout(dtype) -> tuple:
    """``(n_channels, adc_dtype, extra_fields, n_lines)`` of a dtype :func:`record_dtype` made; else SessionError."""
    dt = dtype if isinstance(dtype, np.dtype) else None
    adc = None if dt is None or dt.names is None or "adc" not in dt.names else dt.fields["adc"][0]
    if adc is None or adc.subdtype is None or len(adc.shape) != 1:
        raise SessionError(f"dtype: expected a record dtype (record_dtype(n_channels, ...)), got {short(dtype)}")
    lines = dt.fields[LINES_FIELD][0].shape[0] if LINES_FIELD in dt.names else 1
    standard = {HOST_FIELD[0], *(f.name for f in SAMPLE_FIELDS), "adc", LINES_FIELD}
    extra = tuple((name, dt.fields[name][0].str) for name in dt.names if name not in standard)
    layout = (adc.shape[0], adc.base.str, extra, lines)
    if record_dtype(*layout) != dt:
        raise SessionError(f"dtype: expected a record dtype (record_dtype(n_channels, ...)), got {short(dtype)}")
    return layout


def is_session_dir(path) -> bool:
    """Tell whether ``path`` is a directory holding ``meta.yaml`` or ``frames.bin``.

    Parameters
    ----------
    path : str or path-like
        Any path.
    """
    p = Path(path)
    return p.is_dir() and ((p / META).exists() or (p / FRAMES).exists())


def _plain(obj):
    """YAML-safe copy (numpy scalars and tuples to built-ins)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    return obj


RESERVE_BYTES = 64 * 1024
"""Space a writer holds back (a hidden file in the session directory) for its final ``meta.yaml``."""
_RESERVE = ".meta.yaml.bendsense-tmp-reserve"  # bendsense's own litter: never a foreign file


class SessionWriter:
    """Append records to a native session directory.

    Parameters
    ----------
    path : path
        Session directory; created. An existing session is refused unless ``overwrite``.
    dtype : numpy.dtype
        The record layout, as :func:`record_dtype` makes it: the channels N, the dtype of
        the ADC values, further per-frame columns and the pressure lines (more than one is
        recorded in ``meta.yaml`` as ``n_lines``; :meth:`set_lines` changes them before
        the first record).
    adc_bits : int, optional
        ADC resolution (from the HELLO).
    device : dict, optional
        Device description for ``meta.yaml`` (HELLO fields, port, ...).
    config : Config or dict, optional
        Config snapshot stored in ``meta.yaml``.
    meta : dict, optional
        Further metadata.
    overwrite : bool
        Replace an existing session (only what bendsense wrote there, see
        :mod:`bendsense.output`; a directory with other files is refused).
    inputs : iterable of paths
        Inputs of the command, never to be written over.
    writer : str
        Who writes, for the output manifest.
    extra_files : sequence of str
        Further files written into the session directory by others (e.g. the
        ``results.csv`` of ``record --estimate``), listed in the manifest as bendsense's.

    Attributes
    ----------
    fsync_interval_s : float
        Longest time between ``os.fsync`` calls while writing [s] (0.5).

    Notes
    -----
    :meth:`write` and :meth:`event` may be called from different threads.
    """

    fsync_interval_s = 0.5

    def __init__(
        self,
        path,
        dtype: np.dtype,
        *,
        adc_bits: int | None = None,
        device: dict | None = None,
        config=None,
        meta: dict | None = None,
        overwrite: bool = False,
        inputs=(),
        writer: str = "bendsense record",
        extra_files=(),
    ):
        from bendsense import output

        n_channels, adc_dtype, extra_fields, n_lines = _layout(dtype)
        self.path = Path(path)
        self.dtype = dtype
        self._layout = (adc_dtype, extra_fields)
        self.n_channels = int(n_channels)
        self.n_lines = int(n_lines)
        # written in place (a recording must survive being killed): the output layer checks
        # and locks the directory, removes an earlier session there (only what bendsense
        # wrote) and writes the manifest before any data
        self._output = output.begin_in_place(
            self.path, [META, FRAMES, EVENTS, *extra_files], overwrite=overwrite, inputs=inputs, writer=writer
        )
        self.failed = None  # the OutputError that stopped the writer (a full disk, ...)
        try:
            try:
                self._start(config, adc_bits, device, meta)
            except OSError as err:
                if isinstance(err, OutputError):
                    raise
                where = err.filename if err.filename is not None else self.path
                raise output.write_error(where, err, "nothing recorded") from None
        except BaseException:
            self._abandon()
            raise

    def _abandon(self) -> None:
        """Undo a start that failed: close what is open, remove what was written (nothing recorded)."""
        for name in ("_fd", "_events"):
            handle = self.__dict__.pop(name, None)
            with contextlib.suppress(OSError):
                os.close(handle) if isinstance(handle, int) else handle is not None and handle.close()
        self._release_reserve()
        self._output.abandon()

    def _start(self, config, adc_bits, device, meta) -> None:
        if config is not None and hasattr(config, "to_dict"):
            config = config.to_dict()
        now_ns = time.monotonic_ns()
        self.meta = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "start_time_utc": utc_now_iso(),
            "start_host_ns": now_ns,
            "n_channels": self.n_channels,
            "adc_bits": adc_bits,
            **({"n_lines": self.n_lines} if self.n_lines > 1 else {}),
            "record_dtype": dtype_to_list(self.dtype),
            "record_size": self.dtype.itemsize,
            "finished": False,  # true once close() ran: a clean stop
            "clocks": {
                "host_ns": "time.monotonic_ns() of the host when the frame was read [ns]",
                "t_us": "device clock, unwrapped [us]",
            },
            "device": _plain(device or {}),
            **_plain(meta or {}),
        }
        if config is not None:
            self.meta["config"] = _plain(config)
        self._write_meta()
        self._lock = threading.Lock()
        self._hold_reserve()
        self._fd = os.open(self.path / FRAMES, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o666)
        self._events = open(self.path / EVENTS, "a", encoding="utf-8", buffering=1)
        self._last_sync = time.monotonic()
        self.n_records = 0
        self.closed = False

    def _write_meta(self) -> None:
        from bendsense import output

        text = yaml.safe_dump(self.meta, sort_keys=False, allow_unicode=True)
        output.write_text(self.path / META, text, overwrite=True)

    def _hold_reserve(self) -> None:
        """Hold back the space of the final ``meta.yaml`` (allocated, not sparse), where the file system allows."""
        size = RESERVE_BYTES + 4 * len(yaml.safe_dump(self.meta, sort_keys=False, allow_unicode=True).encode())
        fd = os.open(self.path / _RESERVE, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            try:
                os.posix_fallocate(fd, 0, size)
            except (AttributeError, OSError) as err:
                if isinstance(err, OSError) and err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                    raise
                os.write(fd, bytes(size))  # a file system without fallocate
        except OSError as err:
            # no room (or a file-size limit below it): record without; the first refused write says so
            log.debug("%s: no reserve for meta.yaml (%s)", self.path, err)
            self._release_reserve()
        finally:
            os.close(fd)

    def _release_reserve(self) -> None:
        with contextlib.suppress(OSError):
            os.unlink(self.path / _RESERVE)

    def _fail(self, err: OSError):
        """Stop writing after the file system refused ``err``: keep every whole record, free the reserve."""
        from bendsense import output

        with contextlib.suppress(OSError):
            self._count_whole_records()
            os.fsync(self._fd)
        self._release_reserve()
        self.failed = output.write_error(
            self.path / FRAMES, err, f"recording stopped; {self.n_records:,} frames kept (the session is readable)")
        return self.failed

    def _count_whole_records(self) -> None:
        """Set ``n_records`` from what ``frames.bin`` holds, a torn last record cut off (no whole one).

        The file, not the running count, is the truth: a full disk stops a write part way, and a
        signal handler that raised between a write and its count (Ctrl-C of the writing thread)
        leaves whole records uncounted.
        """
        size = self.dtype.itemsize
        end = os.fstat(self._fd).st_size
        if end % size:
            os.ftruncate(self._fd, end - end % size)
        self.n_records = end // size

    def set_lines(self, n_lines: int) -> None:
        """Record ``n_lines`` pressure lines: the record dtype and ``meta.yaml`` change; only before the first record.

        A recorder learns a board's lines from its first SAMPLE, after the session was
        created from the HELLO.

        Parameters
        ----------
        n_lines : int
            Pressure lines (1..255).
        """
        if n_lines == self.n_lines:
            return
        dtype = record_dtype(self.n_channels, self._layout[0], self._layout[1], n_lines)
        with self._lock:
            if self.n_records:
                raise SessionError(f"{self.path}: n_lines: the session already holds {self.n_records} records of "
                                   f"{self.n_lines} pressure line(s)")
            self.dtype, self.n_lines = dtype, int(n_lines)
            meta = {k: v for k, v in self.meta.items() if k != "n_lines"}
            self.meta = {}
            for key, value in meta.items():
                if key == "record_dtype" and self.n_lines > 1:
                    self.meta["n_lines"] = self.n_lines
                self.meta[key] = value
            self.meta.update(record_dtype=dtype_to_list(dtype), record_size=dtype.itemsize)
            self._write_meta()

    def empty(self, n: int) -> np.ndarray:
        """``n`` zeroed records of this session's dtype (pressure set to "no reading").

        Parameters
        ----------
        n : int
            Number of records.
        """
        rec = np.zeros(n, dtype=self.dtype)
        rec["pressure_pa"] = NO_PRESSURE
        return rec

    def write(self, records: np.ndarray) -> None:
        """Append structured ``records`` (this session's dtype) to ``frames.bin``.

        Parameters
        ----------
        records : ndarray
            Structured records of this session's dtype.
        """
        records = np.asarray(records)
        if records.dtype != self.dtype:
            raise SessionError(f"records: expected dtype {self.dtype}, got {records.dtype}")
        data = records.tobytes()
        with self._lock:
            if self.failed is not None:
                raise self.failed
            try:
                view = memoryview(data)
                while view:
                    written = os.write(self._fd, view)
                    view = view[written:]
            except OSError as err:
                raise self._fail(err) from None
            self.n_records += len(records)
        self.maybe_sync()

    def event(self, text: str, when: float | None = None) -> None:
        """Append one line to ``events.log`` (``when``: wall-clock time [s], default now).

        Parameters
        ----------
        text : str
            The event, one line.
        when : float, optional
            Wall-clock time of the event [s]; None is now.
        """
        line = " ".join(str(text).split())  # one event, one line
        with self._lock:
            if not self.closed:
                try:  # called from the driver's thread too: a full disk stops the next write, not the driver
                    self._events.write(f"{utc_now_iso(when)} {line}\n")
                except OSError as err:
                    if self.failed is None:
                        self._fail(err)

    def maybe_sync(self) -> None:
        """``fsync`` if the last one is older than ``fsync_interval_s``."""
        if time.monotonic() - self._last_sync >= self.fsync_interval_s:
            self.sync()

    def sync(self) -> None:
        """Flush and ``fsync`` both data files."""
        with self._lock:
            if self.closed:
                return
            try:
                self._events.flush()
                os.fsync(self._events.fileno())
                os.fsync(self._fd)
            except OSError as err:
                if self.failed is None:
                    raise self._fail(err) from None
            self._last_sync = time.monotonic()

    def close(self, meta_update: dict | None = None) -> None:
        """Sync, close, and rewrite ``meta.yaml`` with the end time, record count and ``meta_update``.

        Parameters
        ----------
        meta_update : dict, optional
            Further metadata for ``meta.yaml``.
        """
        if self.closed:
            return
        try:
            self.sync()
        except OSError:
            pass  # self.failed says it; the frames written are kept and counted
        with self._lock:
            self.closed = True
            with contextlib.suppress(OSError):
                self._count_whole_records()
            os.close(self._fd)
            try:
                self._events.close()
            except OSError:
                pass  # a last event line the full disk refused
        self._release_reserve()
        self.meta["end_time_utc"] = utc_now_iso()
        self.meta["n_records"] = self.n_records
        self.meta["finished"] = True
        if meta_update:
            self.meta.update(_plain(meta_update))
        try:
            self._write_meta()
        except OSError as err:
            if self.failed is None:
                raise
            # meta.yaml stays "unfinished": the reader reads every whole record and says so
            log.warning("%s: meta.yaml not updated at the end (%s)", self.path, err)
        finally:
            self._output.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# --------------------------------------------------------------------------- reading


def read_session_meta(path) -> dict:
    """``meta.yaml`` of a session directory, checked for format name, version and field types.

    Parameters
    ----------
    path : str or path-like
        The session directory.
    """
    path = Path(path)
    if not (path / META).exists():
        csvs = sorted(p.name for p in path.glob("*.csv")) if path.is_dir() else []
        hint = f"; it holds {csvs[0]}: give {path / csvs[0]}" if len(csvs) == 1 else ""
        raise SessionError(f"{path}: not a session directory (no {META}){hint}")
    where = path / META
    meta = read_yaml(where, "session meta.yaml", lambda data: data, SessionError)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise SessionError(f"{where}: format: expected {FORMAT!r}, got {short(got)}")
    if meta.get("version") not in READ_VERSIONS:
        raise SessionError(f"{where}: version: expected {' or '.join(map(str, READ_VERSIONS))}, "
                           f"got {short(meta.get('version'))}")
    if "record_dtype" not in meta:
        raise SessionError(f"{where}: missing record_dtype")
    if not isinstance(meta["record_dtype"], list):
        raise SessionError(f"{where}: record_dtype: expected a list of [name, dtype] pairs, "
                           f"got {short(meta['record_dtype'])}")
    checks = {"n_channels": (1, 64), "adc_bits": (1, 16), "record_size": (1, None), "n_records": (0, None),
              "n_lines": (1, MAX_LINES)}
    try:
        for key, (lo, hi) in checks.items():
            if meta.get(key) is not None:
                check.integer(key, meta[key], minimum=lo, maximum=hi, error=SessionError)
        if "finished" in meta:
            check.boolean("finished", meta["finished"], error=SessionError)
    except SessionError as err:
        raise SessionError(f"{where}: {err}") from None
    return meta


def read_records(path) -> tuple[np.ndarray, dict]:
    """Raw records of ``frames.bin`` and the metadata, checked against each other.

    Sets ``meta["n_records"]`` (records present), ``meta["records_recorded"]`` (what
    a finished session's ``meta.yaml`` says, else None), ``meta["finished"]`` and
    ``meta["torn_bytes"]``.

    Parameters
    ----------
    path : str or path-like
        The session directory.

    Raises
    ------
    SessionError
        If the record dtype is not the format's or disagrees with ``record_size``,
        ``n_channels`` or ``adc_bits``, or a finished session does not hold exactly
        the records it recorded (the message gives the numbers).
    """
    path = Path(path)
    meta = read_session_meta(path)
    version = meta["version"]
    where = path / META
    try:
        dtype = dtype_from_list(meta["record_dtype"], version=version, n_channels=meta.get("n_channels"))
    except SessionError as err:
        raise SessionError(f"{path}: {err}") from None
    lines = dtype.fields[LINES_FIELD][0].shape[0] if LINES_FIELD in dtype.names else 1
    if meta.get("n_lines", 1) != lines:
        raise SessionError(f"{where}: n_lines is {meta.get('n_lines', 1)}, but record_dtype holds {lines} pressure "
                           "line(s) (an edited meta.yaml?)")
    size = dtype.itemsize
    if meta.get("record_size") is not None and meta["record_size"] != size:
        raise SessionError(f"{where}: record_size is {meta['record_size']} bytes, but record_dtype gives "
                           f"{size}-byte records (an edited record dtype?)")
    frames = path / FRAMES
    try:
        nbytes = check_regular_file(frames, "frames.bin of a session", SessionError).st_size
    except SessionError:
        if frames.exists() or frames.is_symlink():
            raise
        nbytes = 0
    n, torn = divmod(nbytes, size)
    # version 1 has no flag: its writer added n_records at a clean stop only
    finished = bool(meta.get("finished", "n_records" in meta)) if version >= 2 else "n_records" in meta
    recorded = meta.get("n_records") if finished else None
    if finished and recorded is None:
        raise SessionError(f"{where}: finished, but no n_records")
    if finished and n < recorded:
        extra = f", and a torn record of {torn} bytes" if torn else ""
        raise SessionError(f"{frames}: {n:,} of {recorded:,} records present; {recorded - n:,} lost{extra} "
                           "(frames.bin was cut short after the recording)")
    if finished and n > recorded:
        raise SessionError(f"{frames}: {n:,} records present, but meta.yaml recorded {recorded:,} "
                           f"({n - recorded:,} more; frames.bin from another recording?)")
    if finished and torn:
        raise SessionError(f"{frames}: {torn} stray bytes after the {n:,} records of {size} bytes "
                           "(frames.bin was damaged after the recording)")
    if not finished:
        note = f"; a torn last record ({torn} of {size} bytes) ignored" if torn else ""
        log.warning("%s: unfinished recording (no clean stop: killed, crashed or still recording); %s records "
                    "present%s", path, f"{n:,}", note)
    if n:
        with open_regular(frames, "frames.bin of a session", SessionError) as fh:
            try:
                records = np.fromfile(fh, dtype=dtype, count=n)
            except MemoryError:  # an unfinished recording has no n_records to hold its size to
                raise SessionError(f"{frames}: {n:,} records of {size} bytes ({n * size / 2**30:.1f} GiB) do not fit "
                                   "in this machine's memory") from None
    else:
        records = np.zeros(0, dtype=dtype)
    bits = meta.get("adc_bits")
    if n and bits and records.dtype.fields["adc"][0].base.kind == "u":
        top = int(records["adc"].max())
        if top >= 2**bits:
            raise SessionError(f"{frames}: ADC counts up to {top:,} do not fit adc_bits {bits} "
                               "(an edited record dtype or adc_bits?)")
    meta.update(torn_bytes=torn, n_records=n, records_recorded=recorded, finished=finished)
    return records, meta


def read_session_dir(path):
    """Read a native session directory into a :class:`~bendsense.session.Session`.

    Parameters
    ----------
    path : str or path-like
        The session directory.

    Raises
    ------
    SessionError
        If ``meta.yaml`` is missing, of another format or version, or has a bad dtype.
    """
    records, meta = read_records(path)
    return records_to_session(records, meta, source=str(path))


def export_session_csv(session_dir, csv_path, *, overwrite: bool = False) -> None:
    """Write a native session as a session CSV (via :func:`bendsense.session.write_session_csv`).

    Parameters
    ----------
    session_dir : str or path-like
        The native session directory.
    csv_path : str or path-like
        Output CSV file.
    overwrite : bool, default False
        Replace an existing file.
    """
    write_session_csv(read_session_dir(session_dir), csv_path, overwrite=overwrite)


def import_session_csv(csv_path, session_dir, *, overwrite: bool = False) -> None:
    """Write a session CSV as a native session directory.

    Time is stored in whole microseconds (``t_s[0]`` kept as ``meta["t_offset_s"]``) and
    pressure in whole pascals; signals are stored as ``<u2`` when they are all counts
    in 0..65535, else as ``<f8``. Several pressure lines (``line<k>_pressure_pa``
    columns) are stored as ``pressures_pa`` with ``n_lines``. Numeric extra columns become further record fields;
    text columns are dropped (and logged). Columns named after a field of
    :data:`bendsense.wire.frames.SAMPLE_FIELDS` (an exported native session's ``status``,
    ``tx_drops``) go back into that field.

    Parameters
    ----------
    csv_path : str or path-like
        The session CSV file.
    session_dir : str or path-like
        Output session directory.
    overwrite : bool, default False
        Replace a previous bendsense session there.
    """
    s = read_session_csv(csv_path)
    sig = s.signals
    counts = bool(np.all((sig == np.round(sig)) & (sig >= 0) & (sig <= 65535)))
    extra_cols = {}
    for name, values in s.extra.items():
        if name in ("host_s", "adc") or name in _field_types():
            continue
        if values.dtype.kind in "iub":
            extra_cols[name] = (values, "<i8")
        elif values.dtype.kind == "f":
            extra_cols[name] = (values, "<f8")
        else:
            log.warning("%s: text column %r is not stored in a native session", csv_path, name)
    n = len(s)
    writer = SessionWriter(
        session_dir,
        record_dtype(s.n_channels, "<u2" if counts else "<f8", [(k, dt) for k, (_, dt) in extra_cols.items()],
                     s.n_lines),
        meta={"imported_from": str(csv_path), "t_offset_s": float(s.t_s[0]) if n else 0.0, "csv_meta": s.meta},
        overwrite=overwrite,
        inputs=[csv_path],
        writer="bendsense import",
    )
    try:
        rec = writer.empty(n)
        rec["t_us"] = np.round((s.t_s - s.t_s[0]) * 1e6).astype(np.int64) if n else 0
        host_s = s.extra.get("host_s")
        host = s.t_s - s.t_s[0] if host_s is None else np.asarray(host_s, float) - float(host_s[0])
        rec["host_ns"] = np.round(host * 1e9).astype(np.int64)
        rec["seq"] = (np.arange(n) if s.seq is None else s.seq) % 65536
        status = s.extra.get("status")
        if status is not None and status.dtype.kind in "iuf":
            rec["status"] = status.astype(np.int64) & 0xFF
        elif status is not None:  # e.g. the text status of a results.csv: no device status bits
            log.warning("%s: text column 'status' is not stored in a native session", csv_path)
        for f in SAMPLE_FIELDS:  # the others (tx_drops) when they are integers, wrapped to their type
            values = s.extra.get(f.name)
            if f.name not in SESSION_COLUMNS and values is not None and values.dtype.kind in "iu":
                rec[f.name] = values.astype(np.int64).astype(f.dtype)
        p = s.pressure_pa
        p = np.where(np.isfinite(p), np.round(np.nan_to_num(p)), NO_PRESSURE).astype(np.int64)
        if p.ndim == 2:  # several pressure lines: pressure_pa holds line 0, as on the wire
            rec[LINES_FIELD] = p
            p = p[:, 0]
        rec["pressure_pa"] = p
        rec["adc"] = sig
        for name, (values, _) in extra_cols.items():
            rec[name] = values
        writer.write(rec)
    finally:
        writer.close()
