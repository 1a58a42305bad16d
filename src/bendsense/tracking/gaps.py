"""Gaps in a series of frames: where the board stopped sending, or frames were lost.

A gap is an interval over :data:`GAP_FACTOR` times the median one. The window check and
the track start a new segment after one (:mod:`bendsense.tracking.windows`); the plots
stop their lines there (:func:`broken_at_gaps`) instead of bridging it.
"""

from __future__ import annotations

import numpy as np

GAP_FACTOR = 3.0  # an interval over this many times the median one is a gap


def reference_interval(t_s):
    """The median interval between frames [s] (inf for fewer than two frames).

    Parameters
    ----------
    t_s : ndarray, shape (B,)
        Frame times [s].
    """
    return float(np.median(np.diff(t_s))) if t_s.size > 1 else np.inf


def gaps(t_s) -> np.ndarray:
    """The frames (indices into ``t_s``) that follow a gap: an interval over ``GAP_FACTOR`` × the median one.

    Parameters
    ----------
    t_s : array_like, shape (B,)
        Frame times [s]; fewer than three frames have no gap.
    """
    t = np.asarray(t_s, dtype=float)
    if t.size < 3:
        return np.empty(0, dtype=int)
    return np.flatnonzero(np.diff(t) > GAP_FACTOR * reference_interval(t)) + 1


def broken_at_gaps(t_s, *columns):
    """``t_s`` and each column with a NaN row in every gap (:func:`gaps`), for lines that stop there.

    Parameters
    ----------
    t_s : array_like, shape (B,)
        Frame times [s].
    *columns : array_like, shape (B, ...), or None
        Values per frame (None passes as None).

    Returns
    -------
    tuple of ndarray
        The times, a gap's row at its middle, then each column as floats, NaN in the gaps'
        rows. Without a gap, the times as floats and the columns as given.
    """
    t = np.asarray(t_s, dtype=float)
    at = gaps(t)
    if at.size == 0:
        return (t, *columns)
    return (np.insert(t, at, 0.5 * (t[at - 1] + t[at])),
            *(None if c is None else np.insert(np.asarray(c, dtype=float), at, np.nan, axis=0) for c in columns))
