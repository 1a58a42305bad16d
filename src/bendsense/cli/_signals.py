"""Stopping a command: Ctrl-C, SIGTERM, a closed terminal and Ctrl-backslash end every command the same way.

installed() (entered once by the ``bendsense`` group) makes each of
:data:`bendsense.stop_signals.STOP_SIGNALS` raise :class:`KeyboardInterrupt` in the main
thread, so that every ``finally`` and every output writer cleans up on the way out
(outputs are written whole or not at all, :mod:`bendsense.output`). Only the first
raises: the command is stopping, and a second Ctrl-C a moment later must not cut its
cleanup short (the control loop's set-point 0 on every line, the line that says what
was kept); it is noted, and SIGKILL remains for a command that must die at once. The
group then prints one line, ``Interrupted (SIGINT): ...`` with what the command kept,
and exits 128 + the first signal's number, as a shell reports a command killed by it:
130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP, 131 for SIGQUIT.

A layer that knows what it kept says so on the exception on its way up
(:func:`note`): ``record`` its fsync'ed frames, ``process`` how many sessions
finished.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading

from bendsense.stop_signals import STOP_SIGNALS, handled

__all__ = ["installed", "stopping", "interrupting", "note", "exit_code", "message", "exit_quietly"]

_received: list[int] = []  # the stop signals seen, first first
_AGAIN_S = 0.01  # a signal that came inside a foreign callback comes again this much later [s]


def _raise(signum, frame):
    if _in_callback(frame):
        # an exception raised in a ctypes callback is printed and dropped, and the command would go on: the
        # signal is sent again once the callback has (most likely) returned
        again = threading.Timer(_AGAIN_S, os.kill, (os.getpid(), signum))
        again.daemon = True  # (a process that ends meanwhile does not wait for it)
        again.start()
        return
    _received.append(signum)
    if len(_received) == 1:  # a later one while the command stops is only noted
        raise KeyboardInterrupt


def _in_callback(frame) -> bool:
    """Whether ``frame`` runs inside llvmlite's callbacks from compiled code (numba compiling or loading a kernel)."""
    while frame is not None:
        if "llvmlite" in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def installed():
    """The stop signals raise KeyboardInterrupt in the main thread while the block runs (the first only).

    A signal ignored at start (a job started in the background by a shell) stays
    ignored; the previous handlers come back when the block ends.
    """
    _received.clear()
    with handled(_raise, lambda signum, current: current is not signal.SIG_IGN):
        yield


def stopping() -> bool:
    """Whether a stop signal has come (the command is stopping, whatever became of its KeyboardInterrupt)."""
    return bool(_received)


@contextlib.contextmanager
def interrupting(*, returned: bool = True):
    """The block ends with KeyboardInterrupt when a stop signal came, whatever became of the signal's own.

    A call under the block may turn the KeyboardInterrupt the signal raised inside it into
    its own error (numba unboxing a typed list reports ``TypeError: can't unbox ...``;
    matplotlib in the middle of a draw ``ValueError: Invalid affine transformation
    matrix``) or swallow it (an exception in a finaliser is only printed): the signal
    stopped the command all the same.

    Parameters
    ----------
    returned : bool, default True
        Also when the block returns after a signal (one swallowed under it); False: only an
        error the block raises after a signal is the interrupt (a command that handled its
        interrupt and returned keeps its result).
    """
    try:
        yield
    except Exception as err:
        if not _received:
            raise
        raise KeyboardInterrupt from err
    if returned and _received:
        raise KeyboardInterrupt


def note(err: BaseException, text: str) -> None:
    """Add what an interrupted command kept to the KeyboardInterrupt ``err`` (shown in its one line)."""
    err.__notes__ = [*getattr(err, "__notes__", []), text]


def signum() -> int:
    """The signal that stopped the command (SIGINT if none was seen: a KeyboardInterrupt raised otherwise)."""
    return _received[0] if _received else signal.SIGINT


def exit_code() -> int:
    """128 + the signal number: 130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP, 131 for SIGQUIT."""
    return 128 + int(signum())


def message(err: BaseException | None) -> str:
    """The one line of an interrupted command: the signal, then what was kept."""
    notes = [n for n in getattr(err, "__notes__", []) if n]
    kept = "; ".join(notes) if notes else "no output left half-written"
    return f"Interrupted ({signal.Signals(signum()).name}): {kept}"


def exit_quietly(code) -> None:
    """From now on a stop signal ends the process at once with ``code`` (the command has finished).

    After the command's last line, the interpreter still takes a moment to exit (threads,
    worker pools, finalisers); a second Ctrl-C then must not kill it by the signal and
    change its exit status. For the console script only (:func:`bendsense.cli.run`):
    never in a process that goes on.
    """
    import os

    status = code if isinstance(code, int) else (0 if code is None else 1)
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, lambda *_: os._exit(status))
