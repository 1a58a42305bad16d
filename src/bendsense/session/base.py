"""The :class:`Session` object: recorded frames in memory, whatever file they came from.

Every format of :mod:`bendsense.session` reads into a :class:`Session` and writes from
one; this module holds the object alone, so that the format modules can build it
without importing the package that dispatches to them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bendsense._batched import brief_repr
from bendsense.errors import SessionError
from bendsense.validation import float_array, short

__all__ = ["Session"]


@dataclass(frozen=True, eq=False)
class Session:
    """Recorded frames of one session.

    Parameters
    ----------
    t_s : ndarray, shape (frames,)
        Time of each frame [s].
    signals : ndarray, shape (frames, N)
        Signal value of each receiver channel (ADC counts or volts, as recorded).
    pressure_pa : ndarray, shape (frames,) or (frames, n_lines)
        Actuation (gauge) pressure [Pa]; NaN where there is no reading. A board with
        several pressure lines (a gripper) gives one column per line, ``(frames,
        n_lines)`` with ``n_lines > 1``, and ``meta["n_lines"]`` says how many (a
        square array, as many lines as frames, is read as lines only when ``meta``
        says so beforehand); one line is always ``(frames,)`` (a ``(frames, 1)`` array
        is taken as that).
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

    __repr__ = brief_repr  # a line or two, not every value of every frame

    t_s: np.ndarray
    signals: np.ndarray
    pressure_pa: np.ndarray
    seq: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    source: str = ""

    def __post_init__(self):
        t = float_array("t_s", self.t_s, error=SessionError)
        sig = float_array("signals", self.signals, error=SessionError)
        if t.ndim != 1:
            raise SessionError(f"t_s: expected shape (frames,), got {t.shape}")
        if sig.ndim != 2 or sig.shape[0] != t.size:
            raise SessionError(f"signals: expected shape ({t.size}, N) (frames of t_s, channels), got {sig.shape}")
        p = _pressure(self.pressure_pa, t.size, self.meta)
        if p.ndim == 2 and isinstance(self.meta, dict):  # several lines: meta says how many, as meta.yaml does
            object.__setattr__(self, "meta", {**self.meta, "n_lines": p.shape[1]})
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "signals", sig)
        object.__setattr__(self, "pressure_pa", p)
        if self.seq is not None:
            try:
                seq = np.asarray(self.seq, dtype=np.int64)
            except (TypeError, ValueError):
                raise SessionError(f"seq: expected integers, got {short(self.seq)}") from None
            if seq.shape != t.shape:
                raise SessionError(f"seq: expected shape {t.shape}, got {seq.shape}")
            object.__setattr__(self, "seq", seq)
        if not isinstance(self.meta, dict) or not isinstance(self.extra, dict):
            bad = "meta" if not isinstance(self.meta, dict) else "extra"
            raise SessionError(f"{bad}: expected a dict, got {type(getattr(self, bad)).__name__}")
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
    def n_lines(self) -> int:
        """Number of pressure lines: 1, or the columns of a ``(frames, n_lines)`` ``pressure_pa``."""
        return 1 if self.pressure_pa.ndim == 1 else self.pressure_pa.shape[1]

    def line_pressure_pa(self, line: int) -> np.ndarray:
        """The pressure of one line [Pa], shape (frames,) (line 0 of a one-line session is ``pressure_pa``).

        Parameters
        ----------
        line : int
            Pressure line, 0-based, below :attr:`n_lines`.
        """
        if isinstance(line, bool) or not isinstance(line, (int, np.integer)) or not 0 <= line < self.n_lines:
            lines = "line 0" if self.n_lines == 1 else f"lines 0..{self.n_lines - 1}"
            raise SessionError(f"line: {short(line)} is not a pressure line of {self.source or 'the session'} "
                               f"(it has {lines})")
        return self.pressure_pa if self.pressure_pa.ndim == 1 else self.pressure_pa[:, line]

    @property
    def has_pressure(self) -> bool:
        """True when every frame has a pressure reading."""
        return bool(np.all(np.isfinite(self.pressure_pa)))

    def with_pressure(self, pressure_pa: float) -> Session:
        """A copy whose frames without a pressure reading get ``pressure_pa`` [Pa].

        Parameters
        ----------
        pressure_pa : float
            The constant pressure [Pa].
        """
        from bendsense.validation import number

        fill = number("pressure_pa", pressure_pa, error=SessionError)
        p = np.where(np.isfinite(self.pressure_pa), self.pressure_pa, fill)
        return Session(self.t_s, self.signals, p, self.seq, dict(self.meta), dict(self.extra), self.source)

    def select(self, index) -> Session:
        """A new session with the frames picked by ``index`` (slice, mask or indices).

        Parameters
        ----------
        index : slice, array_like of bool or of int
            The frames to keep.
        """
        try:
            t_s = self.t_s[index]
        except (IndexError, TypeError, ValueError) as err:
            raise SessionError(f"index: expected a slice, a boolean mask of {len(self)} frames or frame numbers "
                               f"below {len(self)}, got {short(index)} ({err})") from None
        seq = None if self.seq is None else self.seq[index]
        extra = {k: v[index] for k, v in self.extra.items()}
        p = self.pressure_pa[index]
        p = np.atleast_1d(p) if self.pressure_pa.ndim == 1 else p.reshape(-1, self.n_lines)
        return Session(
            np.atleast_1d(t_s), self.signals[index].reshape(-1, self.n_channels),
            p, None if seq is None else np.atleast_1d(seq), dict(self.meta),
            {k: np.atleast_1d(v) for k, v in extra.items()}, self.source,
        )


def _pressure(pressure_pa, frames: int, meta) -> np.ndarray:
    """``pressure_pa`` as ``(frames,)``, or ``(frames, n_lines)`` for several lines; checked.

    A square array (as many lines as frames) is ambiguous, and read as lines only when
    ``meta["n_lines"]`` says so.
    """
    p = float_array("pressure_pa", pressure_pa, error=SessionError)
    if p.ndim == 2 and p.shape[0] == frames and p.shape[1] == 1:
        return p[:, 0].copy()
    declared = p.ndim == 2 and isinstance(meta, dict) and str(meta.get("n_lines")) == str(p.shape[1])
    if p.ndim == 2 and p.shape[0] == frames and (p.shape[1] != frames or declared):
        return p.copy()  # one column per pressure line
    if p.shape not in ((), (1,), (frames,)):
        hint = (f"; a pressure per line with as many lines as frames needs meta n_lines: {p.shape[1]}"
                if p.ndim == 2 and p.shape == (frames, frames) else f" (several pressure lines: ({frames}, n_lines))")
        raise SessionError(f"pressure_pa: expected one number or shape ({frames},) (frames of t_s), got shape "
                           f"{p.shape}{hint}")
    return np.broadcast_to(p, (frames,)).copy()
