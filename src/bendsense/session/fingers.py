"""A gripper's board, finger by finger: each finger's channels, pressure line and calibration.

A gripper is its fingers (DESIGN section 2b): a board session or a live block of
readings is split into one single-actuator session (or block) per finger, which the
existing single-actuator code then processes unchanged. A finger's part of the board:

- its signals: the board's columns ``channels − 1``, in the finger's order;
- its pressure: its ``pressure_line`` of the board's lines (``pressure_pa`` of shape
  ``(frames, n_lines)``), or the one pressure of a one-line board (line 0);
- the same ``t_s``, ``seq`` and ``meta``;
- the extra columns shared by the board (those without a finger's prefix) and its own
  truth columns, with the ``<finger>_`` prefix removed (``thumb_fx_n`` → ``fx_n``; its
  own column wins over a shared one of the same name); other fingers' columns are
  left out.
"""

from __future__ import annotations

import functools

import numpy as np

from bendsense import validation as check
from bendsense.config import Finger, GripperConfig
from bendsense.errors import ArgumentError, ConfigError, SessionError
from bendsense.session import Session

__all__ = ["split_session", "split_signals", "split_extra", "finger_columns", "calibrations", "check_calibration"]


def _gripper(gripper) -> GripperConfig:
    return check.instance("gripper", gripper, GripperConfig, "bendsense.load_config(path) of a config with fingers:")


@functools.lru_cache(maxsize=256)
def _board_columns(channels: tuple):
    """The board columns of a finger's channels (``channels − 1``): a slice where they are consecutive, else indices.

    A slice takes the finger's part of a block as a view; a list of indices would be
    converted to an array at every block (~4 µs a finger).
    """
    columns = np.array(channels, dtype=np.intp) - 1
    if columns.size and np.array_equal(columns, np.arange(columns[0], columns[0] + columns.size)):
        return slice(int(columns[0]), int(columns[-1]) + 1)
    columns.setflags(write=False)
    return columns


def _lines(pressure: np.ndarray) -> int:
    """The number of pressure lines of a ``(frames,)`` or ``(frames, n_lines)`` pressure array."""
    return 1 if pressure.ndim == 1 else pressure.shape[1]


def _line(pressure: np.ndarray, finger: Finger) -> np.ndarray:
    """The finger's pressure, 1-D (frames,)."""
    return pressure if pressure.ndim == 1 else pressure[:, finger.pressure_line]


def check_board(n_channels: int, n_lines: int | None, gripper: GripperConfig, source: str, error) -> None:
    """A board of ``n_channels`` and ``n_lines`` holds every finger's channels and line, or one ``error``.

    The error's message begins with ``source``; ``n_lines`` None: not known (a board's
    HELLO announces its channels, not its lines).
    """
    for i, finger in enumerate(gripper.fingers):
        high = max(finger.channels)
        if high > n_channels:
            raise error(f"{source}: {n_channels} channel{'s' if n_channels != 1 else ''}, but finger {finger.name} "
                        f"reads channel {high} (fingers[{i}].channels of the config)")
    for i, finger in enumerate(gripper.fingers):
        if n_lines is not None and finger.pressure_line >= n_lines:
            raise error(f"{source}: {n_lines} pressure line{'s' if n_lines != 1 else ''}, but finger {finger.name} "
                        f"is on line {finger.pressure_line} (fingers[{i}].pressure_line of the config, 0-based)")


def finger_columns(columns, gripper: GripperConfig) -> dict:
    """``{column: finger name or None}``: which finger an extra column belongs to (None: shared by the board).

    A column ``<finger>_<rest>`` belongs to that finger (the longest matching finger name
    wins, so ``index_fx_n`` is finger ``index``'s even beside a finger ``in``).

    Parameters
    ----------
    columns : iterable of str
        Column names.
    gripper : GripperConfig
        The fingers.
    """
    names = sorted(_gripper(gripper).names, key=len, reverse=True)
    out = {}
    for column in columns:
        out[column] = next((n for n in names if column.startswith(n + "_") and len(column) > len(n) + 1), None)
    return out


def split_extra(extra: dict, gripper: GripperConfig) -> dict:
    """Each finger's extra columns: the shared ones and its own, its prefix removed.

    Parameters
    ----------
    extra : dict of str to ndarray
        The board's extra columns (``Session.extra``), in file order.
    gripper : GripperConfig
        The fingers.

    Returns
    -------
    dict
        ``{finger name: {column: values}}``.
    """
    owners = finger_columns(extra, gripper)
    out = {}
    for name in gripper.names:
        columns = {c: v for c, v in extra.items() if owners[c] is None}
        own = {c[len(name) + 1:]: v for c, v in extra.items() if owners[c] == name}
        out[name] = {**columns, **own}
    return out


def split_session(session: Session, gripper: GripperConfig) -> dict:
    """The board session ``session`` as one single-actuator session per finger.

    Parameters
    ----------
    session : Session
        The whole board: ``signals`` (frames, N_board), ``pressure_pa`` (frames,) for one
        line or (frames, n_lines).
    gripper : GripperConfig
        The fingers: channels and pressure line of each.

    Returns
    -------
    dict
        ``{finger name: Session}`` in the gripper's order; each session has the
        finger's channels (``signals[:, channels − 1]``), its line's pressure (1-D),
        the same ``t_s``, ``seq`` and ``meta``, and its extra columns
        (:func:`split_extra`).

    Raises
    ------
    SessionError
        The session has fewer channels than a finger reads, or fewer pressure lines
        than a finger's line; the message names the finger, the channel or line and
        the session's source.
    """
    gripper = _gripper(gripper)
    check.instance("session", session, Session, "bendsense.read_session(path)")
    pressure = np.asarray(session.pressure_pa)
    check_board(session.n_channels, _lines(pressure), gripper, session.source or "session", SessionError)
    extras = split_extra(session.extra, gripper)
    out = {}
    for finger in gripper.fingers:
        out[finger.name] = Session(
            session.t_s, session.signals[:, finger.columns], _line(pressure, finger).copy(),
            None if session.seq is None else session.seq.copy(), dict(session.meta), extras[finger.name],
            session.source,
        )
    return out


def split_signals(signals, pressure_pa, gripper: GripperConfig) -> dict:
    """A live block of the board's readings as each finger's ``(signals, pressure_pa)``.

    Parameters
    ----------
    signals : array_like, shape (frames, N_board)
        The board's signals.
    pressure_pa : array_like, shape (frames,) or (frames, n_lines)
        The pressure of each frame: one line (every finger on line 0) or each line's [Pa].
    gripper : GripperConfig
        The fingers.

    Returns
    -------
    dict
        ``{finger name: (signals (frames, n_segments), pressure_pa (frames,))}``: views of
        the board's arrays where a finger's channels are consecutive.
    """
    gripper = _gripper(gripper)
    signals = check.float_array("signals", signals)
    pressure = check.float_array("pressure_pa", pressure_pa)
    if signals.ndim != 2:
        raise ArgumentError(f"signals: expected shape (frames, N_board), got {signals.shape}")
    frames = signals.shape[0]
    if pressure.ndim not in (1, 2) or pressure.shape[0] != frames:
        raise ArgumentError(f"pressure_pa: expected shape ({frames},) or ({frames}, n_lines) (frames of signals), "
                            f"got {pressure.shape}")
    check_board(signals.shape[1], _lines(pressure), gripper, "signals", ArgumentError)
    return finger_parts(signals, pressure, gripper)


def finger_parts(signals: np.ndarray, pressure: np.ndarray, gripper: GripperConfig) -> dict:
    """:func:`split_signals` of float arrays already checked against the gripper (a live loop's later blocks)."""
    return {f.name: (signals[:, _board_columns(f.channels)], _line(pressure, f)) for f in gripper.fingers}


def check_calibration(calibration, finger: Finger, source: str = "") -> None:
    """``calibration`` fits ``finger``: the same channel count, and fitted for it or for any actuator.

    Parameters
    ----------
    calibration : Calibration
        The calibration.
    finger : Finger
        The finger it is meant for.
    source : str, optional
        Where it came from (a file), for the message.
    """
    where = f"calibration {source}" if source else "calibration"
    if calibration.finger is not None and calibration.finger != finger.name:
        raise ConfigError(f"{where}: fitted for finger {calibration.finger}, given for finger {finger.name} (each "
                          f"finger's channels need their own calibration: --calibration {finger.name}=CAL.yaml)")
    n = finger.config.sensor.n_segments
    if calibration.n_channels != n:
        raise ConfigError(f"{where}: {calibration.n_channels} channels, finger {finger.name}'s sensor has {n} "
                          f"segments")


def calibrations(gripper: GripperConfig, given) -> dict:
    """Each finger's calibration, from one for every finger or one per finger.

    Parameters
    ----------
    gripper : GripperConfig
        The fingers.
    given : Calibration, path or dict
        One calibration (or its YAML file) for every finger (they share one sensor
        design), or ``{finger name: Calibration or path}``; in a mapping, the key
        ``None`` gives the calibration of every finger not named.

    Returns
    -------
    dict
        ``{finger name: Calibration}`` in the gripper's order.

    Raises
    ------
    ConfigError
        An unknown finger name, a finger without a calibration, a calibration fitted
        for another finger or with another channel count (each one clear line).
    """
    from bendsense.calibration import Calibration

    gripper = _gripper(gripper)
    mapping = dict(given) if isinstance(given, dict) else {None: given}
    unknown = [str(n) for n in mapping if n is not None and n not in gripper.names]
    if unknown:
        raise ConfigError(f"calibration for finger {', '.join(unknown)}: not a finger of this gripper; its fingers: "
                          f"{', '.join(gripper.names)}")
    missing = [n for n in gripper.names if n not in mapping and None not in mapping]
    if missing:
        raise ConfigError(f"no calibration for finger{'s' if len(missing) > 1 else ''} {', '.join(missing)} (give "
                          f"{' '.join(f'--calibration {n}=CAL.yaml' for n in missing)}, or one --calibration CAL.yaml "
                          f"for every finger)")
    loaded, out = {}, {}
    for finger in gripper.fingers:
        key = finger.name if finger.name in mapping else None
        if key not in loaded:
            value = mapping[key]
            if isinstance(value, Calibration):
                loaded[key] = (value, "")
            else:
                path = check.path(f"calibration of finger {finger.name}" if key else "calibration", value,
                                  error=ConfigError)
                loaded[key] = (Calibration.load(path), str(path))
        calibration, source = loaded[key]
        check_calibration(calibration, finger, source)
        out[finger.name] = calibration
    return out
