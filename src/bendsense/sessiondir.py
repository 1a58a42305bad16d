"""Native session directory (DESIGN.md section 3): crash-safe recording of device frames.

A session is a directory::

    meta.yaml    format name and version, device HELLO, channel count, ADC bits, record
                 dtype, start time, config snapshot; written atomically (rewritten at close
                 with the end time and the counters)
    frames.bin   append-only fixed-size little-endian records, no header
    events.log   one line per event: ISO-8601 UTC time, a space, the text

The record (:func:`record_dtype`) is, in this order and packed::

    host_ns      <i8      host clock, time.monotonic_ns() when the bytes were read [ns]
    t_us         <u8      device clock, unwrapped (u32 wraps removed by the driver) [us]
    seq          <u2      device sequence number, raw (wraps at 65536)
    status       u1       status bits of the SAMPLE
    pressure_pa  <i4      pressure [Pa]; 0x7FFFFFFF = no reading
    adc          (N,)<u2  raw counts (a line-dialect or imported session may use <f8)

``meta.yaml`` lists the dtype as ``[name, numpy dtype string]`` pairs, so a reader never
guesses the layout; further fields (from an imported CSV) follow the standard ones and
are read back into ``Session.extra``. ``meta["start_host_ns"]`` pairs the monotonic host
clock with ``meta["start_time_utc"]``.

Writes go straight to the OS (unbuffered), so a killed recorder loses nothing it had
written; ``os.fsync`` runs at least once a second against power loss. A torn last
record (a partial write) is ignored by the reader and reported in ``meta["torn_bytes"]``.
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
import threading
import time
from pathlib import Path

import numpy as np
import yaml

from bendsense._io import load_yaml
from bendsense.errors import SessionError

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "NO_PRESSURE",
    "record_dtype",
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

log = logging.getLogger("bendsense.sessiondir")

FORMAT = "bendsense-session"
FORMAT_VERSION = 1
NO_PRESSURE = 0x7FFFFFFF
META = "meta.yaml"
FRAMES = "frames.bin"
EVENTS = "events.log"
STANDARD_FIELDS = ("host_ns", "t_us", "seq", "status", "pressure_pa", "adc")


def utc_now_iso(t: float | None = None) -> str:
    """ISO-8601 UTC time with microseconds and a ``Z`` suffix."""
    t = time.time() if t is None else t
    return _dt.datetime.fromtimestamp(t, _dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def record_dtype(n_channels: int, adc_dtype: str = "<u2", extra_fields=()) -> np.dtype:
    """Structured dtype of one ``frames.bin`` record (packed, little-endian).

    Parameters
    ----------
    n_channels : int
        Number of ADC channels N (1..64).
    adc_dtype : str
        dtype of the ADC values: ``"<u2"`` for raw counts, ``"<f4"``/``"<f8"`` for
        sessions whose signals are not raw counts.
    extra_fields : sequence of (name, dtype str)
        Further per-frame columns appended after the standard ones.
    """
    n = int(n_channels)
    if not 1 <= n <= 64:
        raise SessionError(f"n_channels: expected 1..64, got {n_channels!r}")
    fields = [
        ("host_ns", "<i8"),
        ("t_us", "<u8"),
        ("seq", "<u2"),
        ("status", "u1"),
        ("pressure_pa", "<i4"),
        ("adc", np.dtype(adc_dtype).newbyteorder("<"), (n,)),
        *[(str(name), np.dtype(dt).newbyteorder("<")) for name, dt in extra_fields],
    ]
    return np.dtype(fields)


def dtype_to_list(dtype: np.dtype) -> list:
    """``[[name, dtype string], ...]`` for ``meta.yaml``; sub-arrays as ``"(N,)<u2"``."""
    out = []
    for name in dtype.names:
        ft = dtype.fields[name][0]
        if ft.subdtype is not None:
            base, shape = ft.subdtype
            out.append([name, f"{tuple(shape)}{base.str}".replace(" ", "")])
        else:
            out.append([name, ft.str])
    return out


def dtype_from_list(pairs) -> np.dtype:
    """Inverse of :func:`dtype_to_list`; raises :class:`SessionError` on a bad list."""
    try:
        dt = np.dtype([(str(name), str(spec)) for name, spec in pairs])
    except (TypeError, ValueError) as err:
        raise SessionError(f"meta.yaml record_dtype: invalid ({err}); got {pairs!r}") from None
    missing = [f for f in STANDARD_FIELDS if f not in dt.names]
    if missing:
        raise SessionError(f"meta.yaml record_dtype: missing fields {missing}")
    return dt


def is_session_dir(path) -> bool:
    """Tell whether ``path`` is a directory holding ``meta.yaml`` or ``frames.bin``."""
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


class SessionWriter:
    """Append records to a native session directory.

    Parameters
    ----------
    path : path
        Session directory; created. An existing session is refused unless ``overwrite``.
    n_channels : int
        Number of ADC channels N.
    adc_bits : int, optional
        ADC resolution (from the HELLO).
    device : dict, optional
        Device description for ``meta.yaml`` (HELLO fields, port, ...).
    config : Config or dict, optional
        Config snapshot stored in ``meta.yaml``.
    meta : dict, optional
        Further metadata.
    adc_dtype : str
        dtype of the ADC values (see :func:`record_dtype`).
    extra_fields : sequence of (name, dtype str)
        Further per-frame columns.
    overwrite : bool
        Replace an existing session (only what bendsense wrote there, see
        :mod:`bendsense.output`; a directory with other files is refused).
    fsync_interval_s : float
        Longest time between ``os.fsync`` calls while writing [s].
    inputs : iterable of paths
        Inputs of the command, never to be written over.
    writer : str
        Who writes, for the output manifest.
    extra_files : sequence of str
        Further files written into the session directory by others (e.g. the
        ``results.csv`` of ``record --estimate``), listed in the manifest as bendsense's.

    Notes
    -----
    :meth:`write` and :meth:`event` may be called from different threads.
    """

    def __init__(
        self,
        path,
        n_channels: int,
        *,
        adc_bits: int | None = None,
        device: dict | None = None,
        config=None,
        meta: dict | None = None,
        adc_dtype: str = "<u2",
        extra_fields=(),
        overwrite: bool = False,
        fsync_interval_s: float = 0.5,
        inputs=(),
        writer: str = "bendsense record",
        extra_files=(),
    ):
        from bendsense import output

        self.path = Path(path)
        self.dtype = record_dtype(n_channels, adc_dtype, extra_fields)
        self.n_channels = int(n_channels)
        self.fsync_interval_s = float(fsync_interval_s)
        # written in place (a recording must survive being killed): the output layer checks
        # and locks the directory, removes an earlier session there (only what bendsense
        # wrote) and writes the manifest before any data
        self._output = output.begin_in_place(
            self.path, [META, FRAMES, EVENTS, *extra_files], overwrite=overwrite, inputs=inputs, writer=writer
        )
        try:
            self._start(config, adc_bits, device, meta)
        except BaseException:
            self._output.close()
            raise

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
            "record_dtype": dtype_to_list(self.dtype),
            "record_size": self.dtype.itemsize,
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
        self._fd = os.open(self.path / FRAMES, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o666)
        self._events = open(self.path / EVENTS, "a", encoding="utf-8", buffering=1)
        self._last_sync = time.monotonic()
        self.n_records = 0
        self.closed = False

    def _write_meta(self) -> None:
        from bendsense import output

        text = yaml.safe_dump(self.meta, sort_keys=False, allow_unicode=True)
        output.write_text(self.path / META, text, overwrite=True)

    def empty(self, n: int) -> np.ndarray:
        """``n`` zeroed records of this session's dtype (pressure set to "no reading")."""
        rec = np.zeros(n, dtype=self.dtype)
        rec["pressure_pa"] = NO_PRESSURE
        return rec

    def write(self, records: np.ndarray) -> None:
        """Append structured ``records`` (this session's dtype) to ``frames.bin``."""
        records = np.asarray(records)
        if records.dtype != self.dtype:
            raise SessionError(f"records: expected dtype {self.dtype}, got {records.dtype}")
        data = records.tobytes()
        with self._lock:
            view = memoryview(data)
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
            self.n_records += len(records)
        self.maybe_sync()

    def event(self, text: str, when: float | None = None) -> None:
        """Append one line to ``events.log`` (``when``: wall-clock time [s], default now)."""
        line = " ".join(str(text).split())  # one event, one line
        with self._lock:
            if not self.closed:
                self._events.write(f"{utc_now_iso(when)} {line}\n")

    def maybe_sync(self) -> None:
        """``fsync`` if the last one is older than ``fsync_interval_s``."""
        if time.monotonic() - self._last_sync >= self.fsync_interval_s:
            self.sync()

    def sync(self) -> None:
        """Flush and ``fsync`` both data files."""
        with self._lock:
            if self.closed:
                return
            self._events.flush()
            os.fsync(self._events.fileno())
            os.fsync(self._fd)
            self._last_sync = time.monotonic()

    def close(self, meta_update: dict | None = None) -> None:
        """Sync, close, and rewrite ``meta.yaml`` with the end time, record count and ``meta_update``."""
        if self.closed:
            return
        self.sync()
        with self._lock:
            self.closed = True
            os.close(self._fd)
            self._events.close()
        self.meta["end_time_utc"] = utc_now_iso()
        self.meta["n_records"] = self.n_records
        if meta_update:
            self.meta.update(_plain(meta_update))
        try:
            self._write_meta()
        finally:
            self._output.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# --------------------------------------------------------------------------- reading


def read_session_meta(path) -> dict:
    """``meta.yaml`` of a session directory, checked for format name and version."""
    path = Path(path)
    if not (path / META).exists():
        raise SessionError(f"{path}: not a session directory (no {META})")
    meta = load_yaml(path / META, "session meta.yaml", lambda data: data, SessionError)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise SessionError(f"{path / META}: format: expected {FORMAT!r}, got {got!r}")
    if meta.get("version") != FORMAT_VERSION:
        raise SessionError(f"{path / META}: version: expected {FORMAT_VERSION}, got {meta.get('version')!r}")
    if "record_dtype" not in meta:
        raise SessionError(f"{path / META}: missing record_dtype")
    return meta


def read_records(path) -> tuple[np.ndarray, dict]:
    """Raw records of ``frames.bin`` and the metadata.

    A partial last record (a torn write) is ignored; its size goes to
    ``meta["torn_bytes"]`` (0 when the file is whole) and is logged.
    """
    path = Path(path)
    meta = read_session_meta(path)
    dtype = dtype_from_list(meta["record_dtype"])
    try:
        data = (path / FRAMES).read_bytes()
    except FileNotFoundError:
        data = b""
    n, torn = divmod(len(data), dtype.itemsize)
    if torn:
        log.warning("%s: ignoring a torn last record (%d of %d bytes)", path / FRAMES, torn, dtype.itemsize)
    meta["torn_bytes"] = torn
    meta["n_records"] = n
    return np.frombuffer(data, dtype=dtype, count=n), meta


def _unwrap16(seq: np.ndarray) -> np.ndarray:
    seq = seq.astype(np.int64)
    if seq.size == 0:
        return seq
    steps = np.diff(seq) % 65536
    return seq[0] + np.concatenate([[0], np.cumsum(steps)])


def records_to_session(records: np.ndarray, meta: dict, source: str = ""):
    """Build a :class:`bendsense.session.Session` from raw records.

    ``t_s`` is the unwrapped device clock relative to the first frame (plus
    ``meta["t_offset_s"]`` of an imported CSV); ``extra`` holds ``host_s`` (host clock
    relative to the first frame [s]), ``status`` and any further record fields.
    """
    from bendsense.session import Session

    n_ch = records.dtype.fields["adc"][0].shape[0]
    t_us = records["t_us"].astype(np.int64)
    t0 = float(meta.get("t_offset_s") or 0.0)
    t_s = t0 + (t_us - (t_us[0] if t_us.size else 0)) * 1e-6
    p = records["pressure_pa"]
    pressure = np.where(p == NO_PRESSURE, np.nan, p.astype(float))
    host = records["host_ns"]
    extra = {
        "host_s": (host - (host[0] if host.size else 0)) * 1e-9,
        "status": records["status"].astype(np.int64),
    }
    for name in records.dtype.names:
        if name not in STANDARD_FIELDS:
            extra[name] = np.array(records[name])
    signals = np.array(records["adc"], dtype=float).reshape(len(records), n_ch)
    return Session(t_s, signals, pressure, seq=_unwrap16(records["seq"]), meta=meta, extra=extra, source=source)


def read_session_dir(path):
    """Read a native session directory into a :class:`bendsense.session.Session`.

    Raises
    ------
    SessionError
        If ``meta.yaml`` is missing, of another format or version, or has a bad dtype.
    """
    records, meta = read_records(path)
    return records_to_session(records, meta, source=str(path))


def export_session_csv(session_dir, csv_path, *, overwrite: bool = False) -> None:
    """Write a native session as a session CSV (via :func:`bendsense.session.write_session_csv`)."""
    from bendsense.session import write_session_csv

    write_session_csv(read_session_dir(session_dir), csv_path, overwrite=overwrite)


def import_session_csv(csv_path, session_dir, *, overwrite: bool = False) -> None:
    """Write a session CSV as a native session directory.

    Time is stored in whole microseconds (``t_s[0]`` kept as ``meta["t_offset_s"]``) and
    pressure in whole pascals; signals are stored as ``<u2`` when they are all counts
    in 0..65535, else as ``<f8``. Numeric extra columns become further record fields;
    text columns are dropped (and logged).
    """
    from bendsense.session import read_session_csv

    s = read_session_csv(csv_path)
    sig = s.signals
    counts = bool(np.all((sig == np.round(sig)) & (sig >= 0) & (sig <= 65535)))
    extra_cols = {}
    for name, values in s.extra.items():
        if name in ("host_s", "status") or name in STANDARD_FIELDS:
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
        s.n_channels,
        adc_dtype="<u2" if counts else "<f8",
        extra_fields=[(k, dt) for k, (_, dt) in extra_cols.items()],
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
        if "status" in s.extra:
            rec["status"] = np.asarray(s.extra["status"]).astype(np.int64) & 0xFF
        p = s.pressure_pa
        rec["pressure_pa"] = np.where(np.isfinite(p), np.round(np.nan_to_num(p)), NO_PRESSURE).astype(np.int64)
        rec["adc"] = sig
        for name, (values, _) in extra_cols.items():
            rec[name] = values
        writer.write(rec)
    finally:
        writer.close()
