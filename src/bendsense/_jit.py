"""Calling the compiled kernels as a user sees it: announced compilation, no numba warnings.

The kernels are compiled by numba on first use and cached on disk next to their modules
(``cache=True``), so only the first run after an install (or a change of the source)
compiles, and says so in one line on stderr. Later processes load the cache in well
under a second. numba's compile-time hints (performance, deprecation) are for
developers and never reach a user.

Threads: the batch kernels run their ``prange`` loops on numba's ``workqueue`` layer,
which is safe across ``fork`` (a process pool created after an estimate, e.g. by a
user's ``ProcessPoolExecutor``) where GNU OpenMP is not; it may not be entered by two
threads at once, so the calls are serialised by a lock (concurrent callers would only
oversubscribe the cores). ``NUMBA_THREADING_LAYER`` in the environment takes precedence.
"""

import os
import sys
import threading
import warnings

import numba

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

_announced = False
_lock = threading.Lock()
_ready = set()  # dispatchers called in this process (numba's .signatures is slow to ask)


def _cached(dispatcher) -> bool:
    """Whether ``dispatcher`` has a cache index on disk (a compiled version of its source)."""
    try:
        return os.path.exists(dispatcher._cache._cache_file._index_path)
    except AttributeError:  # numba internals moved: assume cached, stay quiet
        return True


def call(dispatcher, *args):
    """``dispatcher(*args)``; the first call in a process compiles or loads it quietly."""
    with _lock:
        return _call(dispatcher, args)


def _call(dispatcher, args):
    if dispatcher in _ready:
        return dispatcher(*args)
    _ready.add(dispatcher)
    global _announced
    if not _announced and not _cached(dispatcher):
        _announced = True
        sys.stderr.write("bendsense: compiling the estimation kernels (first run after install, about a minute; "
                         "cached for later runs)\n")
        sys.stderr.flush()
    from numba.core.errors import NumbaWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaWarning)
        return dispatcher(*args)
