"""Play a recorded session back as a board on a pseudo-terminal (BrainFlow's playback board).

:class:`ReplayDevice` is the simulated board of :mod:`bendsense.device.simdevice` whose
frames come from a :class:`~bendsense.session.Session` (a native session directory or a
session CSV): each SAMPLE carries the recorded counts, pressure, status bits, the
firmware's count of frames it could not send, sequence number and device clock, and is
sent at the recorded time (divided by ``speed``). A replayed session recorded again with
``bendsense record`` therefore has the same frames: signals, pressure, status,
``tx_drops``, ``seq`` (with the original gaps) and ``t_s`` (a session with several
pressure lines, a gripper's board, is sent as SAMPLE version 2, one pressure per line,
and records again with all its lines). With ``loop``, the recording starts over after
its last frame, the clock, the sequence numbers and the drop count going on from where
they ended (a board that never stops); without it, the board sends nothing
after the last frame but keeps the port open (:attr:`~SimulatedDevice.finished` is set),
as BrainFlow's playback board sleeps at the end of its file: a client that records the
replay ends when it chooses, not with a disconnected port.
"""

from __future__ import annotations

import numpy as np

from bendsense.device.simdevice import Firmware, SimulatedDevice, max_rate_hz
from bendsense.errors import SessionError
from bendsense.validation import short
from bendsense.wire.frames import MAX_LINES

__all__ = ["ReplayDevice", "replay_frames"]

_FIRMWARE = Firmware(name="bendsense-replay 1")


def replay_frames(session) -> dict:
    """The wire fields of every frame of ``session``, checked for the binary protocol.

    Parameters
    ----------
    session : Session
        The recording; its signals must be ADC counts (integers in 0..65535).

    Returns
    -------
    dict
        ``adc`` (frames, N) int, ``pressure_pa`` (frames,) or (frames, n_lines) float
        (NaN: no reading),
        ``t_us`` (frames,) int (device clock from 0 [us]), ``seq`` (frames,) int
        (unwrapped), ``status`` (frames,) int, ``tx_drops`` (frames,) int (the firmware's
        count of frames it could not send, as recorded; 0 without the column).

    Raises
    ------
    SessionError
        If the session is empty, has signals that are not counts, a pressure beyond the
        wire's i32 or more than 255 pressure lines, or a clock that runs backwards.
    """
    n = len(session)
    where = session.source or "session"
    if n == 0:
        raise SessionError(f"{where}: no frames to replay")
    sig = session.signals
    counts = np.isfinite(sig) & (sig == np.round(sig)) & (sig >= 0) & (sig <= 65535)
    if not counts.all():
        frame, ch = np.argwhere(~counts)[0]
        raise SessionError(
            f"{where}: frame {frame}, ch{ch + 1}: expected ADC counts (integers 0..65535) to replay, "
            f"got {short(sig[frame, ch])}"
        )
    if not 1 <= session.n_channels <= 64:
        raise SessionError(f"{where}: expected 1..64 channels to replay, got {session.n_channels}")
    p = session.pressure_pa
    if session.n_lines > MAX_LINES:
        raise SessionError(f"{where}: {session.n_lines} pressure lines; a SAMPLE carries at most {MAX_LINES}")
    wide = np.isfinite(p) & ~((p >= -(2**31)) & (p < 2**31 - 1))  # the wire's i32, 0x7FFFFFFF: no reading
    if wide.any():
        at = tuple(int(i) for i in np.argwhere(wide)[0])
        name = f"line {at[1]} pressure_pa" if len(at) == 2 else "pressure_pa"
        raise SessionError(f"{where}: frame {at[0]}, {name}: {p[at]:g} Pa does not fit the wire format's "
                           "32-bit pressure field")
    t_us = np.round((session.t_s - session.t_s[0]) * 1e6).astype(np.int64)
    back = np.flatnonzero(np.diff(t_us) < 0)
    if back.size:
        raise SessionError(f"{where}: frame {back[0] + 1}: t_s runs backwards; cannot replay")
    seq = np.arange(n, dtype=np.int64) if session.seq is None else np.asarray(session.seq, dtype=np.int64)
    status, drops = (np.nan_to_num(np.asarray(session.extra.get(name, np.zeros(n)), dtype=float)).astype(np.int64)
                     for name in ("status", "tx_drops"))
    return {"adc": sig.astype(np.int64), "pressure_pa": session.pressure_pa, "t_us": t_us, "seq": seq,
            "status": status & 0xFF, "tx_drops": drops}


def _rate_hz(t_us: np.ndarray) -> float:
    """Nominal frame rate [Hz]: the median frame interval's inverse (500 Hz for one frame)."""
    dt = np.diff(t_us)
    dt = dt[dt > 0]
    return 1e6 / float(np.median(dt)) if dt.size else 500.0


class ReplayDevice(SimulatedDevice):
    """A recorded session served as a board on a pseudo-terminal, with its original timing.

    Parameters
    ----------
    session : Session or path
        The recording (a :class:`~bendsense.session.Session`, a native session directory
        or a session CSV).
    speed : float
        Playback speed: 2 plays twice as fast (the device clock in the frames stays the
        recorded one).
    loop : bool
        Start over after the last frame, forever.
    adc_bits : int, optional
        Reported in HELLO; default the recording's (``meta["adc_bits"]``), else the
        smallest that holds its counts.
    autostart : bool
        Stream without waiting for START.
    **options
        Further options of :class:`~bendsense.device.simdevice.SimulatedDevice`
        (``faults``: dropped, corrupted, truncated frames).

    Notes
    -----
    HELLO reports the recording's median frame rate (rounded) and its channel count.
    A HELLO or TEXT frame sent while streaming takes the next sequence number, as the
    firmware's do, and the replayed frames after it are numbered on from there.
    """

    def __init__(self, session, *, speed: float = 1.0, loop: bool = False, adc_bits: int | None = None,
                 autostart: bool = False, **options):
        from bendsense.session import Session, read_session

        if not isinstance(session, Session):
            session = read_session(session)
        if not speed > 0:
            raise SessionError(f"speed: expected > 0, got {speed!r}")
        frames = replay_frames(session)
        adc = frames["adc"]
        if adc_bits is None:
            adc_bits = session.meta.get("adc_bits") or max(1, int(adc.max()).bit_length())
        self._frames = frames
        self.speed = float(speed)
        self.loop = bool(loop)
        self.n_frames = len(adc)
        rate = _rate_hz(frames["t_us"])
        if rate > max_rate_hz(session.n_channels):
            raise SessionError(f"{session.source or 'session'}: frames {1e6 / rate:g} us apart ({rate:,.0f} Hz), more "
                               f"than a USB full-speed link carries for {session.n_channels} channels "
                               f"({max_rate_hz(session.n_channels):,} Hz); cannot replay (is t_s in seconds?)")
        period_us = round(1e6 / rate)
        self._span_us = int(frames["t_us"][-1]) + period_us  # one pass of the clock
        self._span_seq = int(frames["seq"][-1] - frames["seq"][0]) + 1
        self._seq_shift = 0
        self._sent_k = 0
        super().__init__(self._source, rate_hz=_rate_hz(frames["t_us"]), n_channels=session.n_channels,
                         adc_bits=int(adc_bits), autostart=autostart,
                         max_frames=None if loop else self.n_frames, firmware=_FIRMWARE, **options)

    def _source(self, k: int):
        i = k % self.n_frames
        p = self._frames["pressure_pa"][i]
        if p.ndim:  # several lines: a tuple, which encode_sample sends as SAMPLE version 2
            return tuple(None if not np.isfinite(v) else float(v) for v in p), self._frames["adc"][i]
        return (None if not np.isfinite(p) else float(p)), self._frames["adc"][i]

    def _t_us(self, k: int) -> int:
        passes, i = divmod(k, self.n_frames)
        return int(self._frames["t_us"][i]) + passes * self._span_us

    def _offset_s(self, k: int) -> float:
        return self._t_us(k) * 1e-6 / self.speed

    def _recorded_seq(self, k: int) -> int:
        passes, i = divmod(k, self.n_frames)
        return int(self._frames["seq"][i]) + passes * self._span_seq + self._seq_shift

    def _sample_header(self, k: int) -> tuple:
        self._sent_k = k + 1
        passes, i = divmod(k, self.n_frames)
        # the recorded firmware's drops go on counting over the passes, as a board's counter would
        recorded = self._frames["tx_drops"]
        drops = int(recorded[i]) + passes * int(recorded[-1] - recorded[0])
        return self._recorded_seq(k) & 0xFFFF, self._t_us(k), int(self._frames["status"][i]), drops

    def _next_seq(self) -> int:
        # HELLO/TEXT: before the first sample, the number just before it; later, the next one
        if self._sent_k == 0:
            return (self._recorded_seq(0) - 1) & 0xFFFF
        seq = self._recorded_seq(self._sent_k - 1) + 1
        self._seq_shift += 1
        return seq & 0xFFFF
