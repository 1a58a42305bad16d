"""The contact location where a user looks: the load option of the chain, the columns, the point on the shape.

A force estimate with ``load="contact"`` (DESIGN.md section 2b) carries the contact's
arc length ``contact_s_m`` and its standard deviation ``contact_std_m`` (0 for a known
location, ``inf`` where the data cannot resolve it: status ``contact_unresolved``).
This module is what the outputs share about it (the estimate of a load model for the
chain, ``process`` and the live path: :func:`bendsense.estimation.load_models.estimate_load`):

- :func:`contact_columns`: the columns ``contact_s_m, contact_std_m`` of ``results.csv``
  (after ``fy_std_n``; absent for a tip load, so tip outputs stay as they were);
- :func:`point_on_shape` and :func:`arc_on_shape`: the contact point and its ±2σ arc on a
  drawn shape (the MCAP topic ``/bendsense/contact``, the figures and the live view).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CONTACT_COLUMNS", "contact_columns", "is_contact", "point_on_shape", "arc_on_shape", "resolved"]

#: the columns of ``results.csv`` after ``fy_std_n`` for a contact load
CONTACT_COLUMNS = ("contact_s_m", "contact_std_m")


def is_contact(estimate) -> bool:
    """True when ``estimate`` (a ForceEstimate, or None) is of the contact load model.

    Parameters
    ----------
    estimate : ForceEstimate or None
        A force estimate.
    """
    return estimate is not None and getattr(estimate, "load", "tip") == "contact"


def contact_columns(frames: int, estimate) -> dict:
    """The columns ``contact_s_m, contact_std_m`` of ``results.csv``: empty for a tip load.

    Parameters
    ----------
    frames : int
        Frames of the results.
    estimate : ForceEstimate or None
        The force estimate; its ``contact_s_m`` and ``contact_std_m`` [m] when its
        ``load`` is ``"contact"`` (NaN where a frame has none).

    Returns
    -------
    dict of str to ndarray, shape (frames,)
    """
    if not is_contact(estimate):
        return {}
    out = {}
    for name in CONTACT_COLUMNS:
        value = getattr(estimate, name, None)
        out[name] = (np.full(frames, np.nan) if value is None
                     else np.broadcast_to(np.asarray(value, dtype=float), (frames,)).copy())
    return out


def resolved(contact_s_m, contact_std_m) -> np.ndarray:
    """Frames whose contact location is resolved: a finite ``contact_s_m`` with a finite σ.

    Parameters
    ----------
    contact_s_m, contact_std_m : array_like, shape (...)
        The contact's arc length and its standard deviation [m] (σ ``inf``: unresolved).
    """
    s, std = np.asarray(contact_s_m, dtype=float), np.asarray(contact_std_m, dtype=float)
    return np.isfinite(s) & np.isfinite(std)


def point_on_shape(s_m, positions_m, at_s_m) -> np.ndarray:
    """Points of shapes at arc lengths ``at_s_m``: linear between samples, along the end tangent beyond.

    Parameters
    ----------
    s_m : array_like, shape (M,)
        Arc length of the shape's samples [m], increasing from the base.
    positions_m : array_like, shape (..., M, 2)
        The shapes' points [m].
    at_s_m : array_like, shape (...)
        The arc length of each shape's point [m] (broadcast over the shapes); NaN gives
        NaN. Beyond the last sample (a contact between the sensor's end and the
        actuator's tip) the point continues straight along the shape's end tangent.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    s = np.asarray(s_m, dtype=float)
    pos = np.asarray(positions_m, dtype=float)
    batch = pos.shape[:-2]
    at = np.broadcast_to(np.asarray(at_s_m, dtype=float), batch).reshape(-1)
    p = pos.reshape(-1, s.size, 2)
    out = np.full((at.size, 2), np.nan)
    ok = np.isfinite(at)
    if s.size < 2 or not ok.any():
        return out.reshape(*batch, 2)
    k = np.clip(np.searchsorted(s, at[ok]) - 1, 0, s.size - 2)  # the sample interval (the end ones extended)
    frac = (at[ok] - s[k]) / (s[k + 1] - s[k])
    rows = np.flatnonzero(ok) if p.shape[0] > 1 else np.zeros(int(ok.sum()), dtype=int)
    a, b = p[rows, k], p[rows, k + 1]
    point = a + frac[:, None] * (b - a)
    beyond = at[ok] > s[-1]
    if beyond.any() and s.size >= 3:  # along the tangent at the end: the last chord turned by half its turn
        chords = p[rows[beyond], -2:] - p[rows[beyond], -3:-1]
        angle = np.arctan2(chords[..., 1], chords[..., 0])
        end = angle[:, 1] + 0.5 * np.angle(np.exp(1j * (angle[:, 1] - angle[:, 0])))
        point[beyond] = p[rows[beyond], -1] + (at[ok][beyond] - s[-1])[:, None] * np.column_stack(
            [np.cos(end), np.sin(end)])
    out[ok] = point
    return out.reshape(*batch, 2)


def arc_on_shape(s_m, positions_m, s_lo: float, s_hi: float, points: int = 24) -> np.ndarray:
    """The stretch of one shape between two arc lengths (the ±2σ arc of a contact), clipped to [0, ``s_end``].

    Parameters
    ----------
    s_m : array_like, shape (M,)
        Arc length of the shape's samples [m].
    positions_m : array_like, shape (M, 2)
        One shape's points [m].
    s_lo, s_hi : float
        The ends of the stretch [m]; clipped to 0 and to the larger of the last sample
        and ``s_hi`` within the last tangent (:func:`point_on_shape`).
    points : int, default 24
        Points along the stretch (besides the samples inside it).

    Returns
    -------
    ndarray, shape (K, 2)
        Empty (0, 2) when an end is not finite.
    """
    if not (np.isfinite(s_lo) and np.isfinite(s_hi)) or s_hi < s_lo:
        return np.empty((0, 2))
    s = np.asarray(s_m, dtype=float)
    lo = max(float(s_lo), float(s[0]))
    hi = max(float(s_hi), lo)
    at = np.unique(np.concatenate([np.linspace(lo, hi, int(points)), s[(s > lo) & (s < hi)]]))
    return point_on_shape(s, np.broadcast_to(positions_m, (at.size, *np.shape(positions_m))), at)
