"""What the machine can hold: simulated frames and worker processes are refused before any work that would not fit.

The sizes were measured with ``/usr/bin/time`` (:data:`BASE_BYTES`; per frame,
:data:`bendsense.sim.scenarios.BYTES_PER_FRAME`); the memory available is the kernel's
estimate (``MemAvailable``), where the platform tells it.
"""

from __future__ import annotations

import os

from bendsense.errors import ArgumentError

__all__ = ["BASE_BYTES", "available_memory_bytes", "check_fits", "check_workers", "size_text"]

BASE_BYTES = 300e6  # the process before the first frame: numpy, scipy, numba and the kernels


def available_memory_bytes() -> float | None:
    """Memory this machine can give a new allocation now (Linux ``MemAvailable``) [bytes]; None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def size_text(nbytes: float) -> str:
    """``nbytes`` for a message: ``52.8 TB``, ``2.9 GB``, ``300 MB``, ``12 kB``.

    Parameters
    ----------
    nbytes : float
        A size [bytes].
    """
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 1e3:.3g} kB"


def check_fits(field: str, what: str, n_frames: int, bytes_per_frame: float, rate_hz: float) -> None:
    """Refuse ``n_frames`` held in memory at once that would not fit this machine's free memory, before any work.

    For a session simulated (or recorded and estimated) whole in memory at ``rate_hz``
    [Hz]: the message names the option ``field``, the memory needed, the memory
    available and the longest session that fits.

    Parameters
    ----------
    field : str
        The option that sets the size, for the message (``--seconds``).
    what : str
        What would be held, for the message.
    n_frames : int
        Frames held at once.
    bytes_per_frame : float
        Memory per frame [bytes].
    rate_hz : float
        Frames per second, to say the longest session that fits [Hz].

    Raises
    ------
    ArgumentError
        When ``n_frames`` × ``bytes_per_frame`` (and the process itself) exceed the memory available.
    """
    available = available_memory_bytes()
    need = BASE_BYTES + n_frames * bytes_per_frame
    if available is None or need <= available:
        return
    most = max(available - BASE_BYTES, 0.0) / bytes_per_frame / rate_hz
    raise ArgumentError(f"{field}: {what} would hold {n_frames:,} frames in memory, about {size_text(need)}; "
                        f"this machine has {size_text(available)} available (at most {most:,.0f} s at {rate_hz:g} Hz)")


def check_workers(workers: int) -> None:
    """Refuse more local worker processes than this machine's free memory holds, before any work (one line).

    Parameters
    ----------
    workers : int
        Worker processes to start.

    Raises
    ------
    ArgumentError
        When ``workers`` processes of :data:`BASE_BYTES` each exceed the memory available.
    """
    available = available_memory_bytes()
    if available is not None and workers * BASE_BYTES > available:
        raise ArgumentError(f"workers (--workers): {workers:,} worker processes would need about "
                            f"{size_text(workers * BASE_BYTES)} ({size_text(BASE_BYTES)} each: numpy, scipy, numba "
                            f"and the kernels); this machine has {size_text(available)} available (at most "
                            f"{int(available // BASE_BYTES):,} workers)")
