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

__all__ = ["STOP_SIGNALS", "deferred"]

#: SIGINT, SIGTERM, SIGHUP, SIGQUIT (those the platform has)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                     if hasattr(signal, name))


@contextlib.contextmanager
def deferred():
    """Hold the stop signals off while the block runs; then raise the first that came again.

    In the main thread (signals reach no other), each stop signal that is not ignored is
    only noted while the block runs; after it, the previous handlers come back and the
    first signal noted is raised again, so that its own handler acts on it (a
    :class:`KeyboardInterrupt`, an exit status). Elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted = []
    previous = {}
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) not in (signal.SIG_IGN, None):
            previous[signum] = signal.signal(signum, lambda s, frame: noted.append(s))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if noted:
            signal.raise_signal(noted[0])
