"""The signals that stop a long run, declared once, and a shield for what must finish after one.

:data:`STOP_SIGNALS`: Ctrl-C (SIGINT), ``kill`` or a service manager (SIGTERM), the
terminal or the ssh session closing (SIGHUP), Ctrl-backslash (SIGQUIT). The command line
(:mod:`bendsense.cli._signals`) and the control loop (:func:`bendsense.control.run`) turn
each into :class:`KeyboardInterrupt`. :func:`deferred` holds them off while a block that
must finish runs (the control loop's set-point 0 on every line and its report), then
acts on the first that came. A worker process (:func:`worker_pool`) takes none of them:
its parent stops it, and it ends with its parent (:func:`exit_with_parent`).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time

__all__ = ["STOP_SIGNALS", "GROUP_SIGNALS", "handled", "deferred", "blocked", "worker_pool", "worker_init",
           "exit_with_parent"]

#: SIGINT, SIGTERM, SIGHUP, SIGQUIT (those the platform has)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                     if hasattr(signal, name))
#: The stop signals a terminal sends a command's whole process group (Ctrl-C, a closed terminal,
#: Ctrl-backslash): a command's helper processes ignore them, the command stops them itself.
GROUP_SIGNALS = tuple(s for s in STOP_SIGNALS if s != getattr(signal, "SIGTERM", None))


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


# --------------------------------------------------------------------------- worker processes


@contextlib.contextmanager
def blocked(signals):
    """Block ``signals`` in this thread while the block runs: processes started meanwhile inherit the mask.

    A signal that comes meanwhile stays pending and is delivered here when the block ends.
    Where the platform has no signal masks, the block runs as it is.

    Parameters
    ----------
    signals : iterable of int
        The signals to block (e.g. :data:`GROUP_SIGNALS`).
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, set(signals))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def worker_pool(workers: int, *, nice: int = 0):
    """A process pool whose workers use one BLAS thread and one numba thread each.

    Parallelism comes either from the worker processes (here) or from the compiled
    kernels' threads (in-process), never both: two levels of threads on few cores only
    oversubscribe them. The workers are spawned (not forked) so that they import numpy
    afresh with these variables, even if this process has numpy loaded already. They
    ignore the group's stop signals (Ctrl-C, a closed terminal, Ctrl-backslash) and exit with this
    process (:func:`worker_init`).

    Parameters
    ----------
    workers : int
        Worker processes.
    nice : int, default 0
        Added to the workers' niceness: a background worker (live ``--adapt``) yields the
        cores to the loop and, on a test machine, the simulated board.
    """
    import concurrent.futures as cf
    import multiprocessing

    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    if os.name == "posix":  # multiprocessing's resource tracker inherits the mask: the group's stop signals must
        from multiprocessing import resource_tracker  # not kill it (relaunched, with a warning and tracebacks)

        with blocked(GROUP_SIGNALS):
            resource_tracker.ensure_running()
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=worker_init, initargs=(os.getpid(), nice))


def worker_init(parent_pid: int | None = None, nice: int = 0) -> None:
    """Pool worker initializer: one numba thread, Ctrl-C left to the parent, and exit with the parent.

    One numba thread because the processes are the parallelism. The group's stop signals
    (:data:`GROUP_SIGNALS`: Ctrl-C, a closed terminal and Ctrl-backslash reach the whole
    process group) are ignored: the parent stops the workers itself, so that
    no worker prints a traceback or leaves half a session behind on its own. A worker
    whose parent died (SIGKILL, a crash) exits at once: it must not go on using the
    CPU nor write results for a run that is over (:func:`exit_with_parent`).

    Parameters
    ----------
    parent_pid : int, optional
        The parent's process id (None: the worker does not watch its parent).
    nice : int, default 0
        Added to the worker's niceness (:func:`worker_pool`).
    """
    import numba

    for signum in GROUP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):  # the parent blocked them while starting us (blocked)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, GROUP_SIGNALS)
    if parent_pid is not None:
        exit_with_parent(parent_pid)
    numba.set_num_threads(1)
    if nice:
        os.nice(nice)


def exit_with_parent(parent_pid: int, poll_s: float = 0.5) -> None:
    """End this process as soon as the process ``parent_pid`` (its parent) ends.

    On Linux the kernel does it: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, which also stops a
    worker inside a compiled kernel. Elsewhere (or if prctl fails) a daemon thread
    compares ``os.getppid()`` with ``parent_pid`` every ``poll_s`` seconds and calls
    ``os._exit`` when the parent is gone (the worker is then re-parented).

    Parameters
    ----------
    parent_pid : int
        The parent's process id.
    poll_s : float, default 0.5
        How often the fallback thread looks [s].
    """
    if sys.platform.startswith("linux") and _pdeathsig():
        if os.getppid() != parent_pid:  # the parent died before the prctl took effect
            os._exit(1)
        return

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)

    if os.getppid() != parent_pid:
        os._exit(1)
    threading.Thread(target=watch, name="bendsense-parent-watch", daemon=True).start()


def _pdeathsig() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False if that is not possible."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        pr_set_pdeathsig = 1
        return libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
