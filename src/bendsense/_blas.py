"""bendsense's own linear algebra runs on one BLAS thread.

Its matrices are small (a calibration's polynomial fits, a sensor's 16 × 16 covariances,
an identification's few parameters), where a threaded BLAS only costs: its threads
spin-wait for work, and beside another busy process on a 2-core machine a call that
takes milliseconds alone took minutes. The command line sets ``OPENBLAS_NUM_THREADS=1``
before numpy loads; a notebook does not, so the functions that do the library's numpy
linear algebra (calibration fits, error models, identification) run inside
:func:`one_thread`, which limits the BLAS libraries of the process (threadpoolctl) for
the duration of the outermost such call and restores the user's setting after it.

The per-frame estimation kernels use no BLAS (their small systems are solved in
compiled code), so the hot path pays nothing for this.
"""

from __future__ import annotations

import functools
import threading

__all__ = ["one_thread"]

_lock = threading.RLock()
_depth = 0
_limiter = None


def one_thread(func):
    """Decorate ``func`` to run with the process's BLAS libraries limited to one thread.

    Nested calls limit once (the outermost call); concurrent calls from several threads
    share the limit until the last one returns.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        _enter()
        try:
            return func(*args, **kwargs)
        finally:
            _exit()

    return wrapper


def _enter() -> None:
    global _depth, _limiter
    with _lock:
        if _depth == 0:
            import scipy.linalg  # noqa: F401 (loads scipy's BLAS, so that it is limited too)
            from threadpoolctl import threadpool_limits

            _limiter = threadpool_limits(limits=1, user_api="blas")
        _depth += 1


def _exit() -> None:
    global _depth, _limiter
    with _lock:
        _depth -= 1
        if _depth == 0:
            _limiter.restore_original_limits()
            _limiter = None
