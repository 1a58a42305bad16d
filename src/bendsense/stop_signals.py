"""The signals that stop a long run, declared once, and a shield for what must finish after one.

:data:`STOP_SIGNALS`: Ctrl-C (SIGINT), ``kill`` or a service manager (SIGTERM), the
terminal or the ssh session closing (SIGHUP), Ctrl-backslash (SIGQUIT). The command line
(:mod:`bendsense.cli._signals`) and the control loop (:func:`bendsense.control.run`) turn
each into :class:`KeyboardInterrupt`. :func:`deferred` holds them off while a block that
must finish runs (the control loop's set-point 0 on every line and its report), then
acts on the first that came.
"""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["STOP_SIGNALS", "handled", "deferred"]

#: SIGINT, SIGTERM, SIGHUP, SIGQUIT (those the platform has)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                     if hasattr(signal, name))


@contextlib.contextmanager
def handled(handler, taken=lambda signum, current: current not in (signal.SIG_IGN, None)):
    """``handler(signum, frame)`` for each stop signal that ``taken(signum, its current handler)`` accepts.

    In the main thread only (signals reach no other; elsewhere the block runs as it is);
    while the block runs; by default every stop signal not ignored (a job a shell started
    in the background keeps ignoring them). The previous handlers come back after it.

    Parameters
    ----------
    handler : callable
        The handler, as for :func:`signal.signal`.
    taken : callable, optional
        ``taken(signum, current) -> bool``: whether to replace the signal's current handler.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, handler) for signum in STOP_SIGNALS
                if taken(signum, signal.getsignal(signum))}
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)


@contextlib.contextmanager
def deferred():
    """Hold the stop signals off while the block runs; then raise the first that came again.

    Each stop signal that is not ignored is only noted while the block runs (:func:`handled`);
    after it, the previous handlers are back and the first signal noted is raised again, so
    that its own handler acts on it (a :class:`KeyboardInterrupt`, an exit status).
    """
    noted = []
    with handled(lambda signum, frame: noted.append(signum)):
        yield
    if noted:
        signal.raise_signal(noted[0])
