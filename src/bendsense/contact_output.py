"""The contact location where a user looks: the load option of the chain, the columns, the point on the shape.

A force estimate with ``load="contact"`` (DESIGN.md section 2b) carries the contact's
arc length ``contact_s_m`` and its standard deviation ``contact_std_m`` (0 for a known
location, ``inf`` where the data cannot resolve it: status ``contact_unresolved``).
This module is what the outputs share about it:

- :func:`estimate_load`: the per-frame estimate of the chain, of ``process`` and of the
  live path for a load model (the tip, a contact at a known location, or a contact
  located by :func:`bendsense.estimate_contact` over quasi-static windows);
- :func:`contact_columns`: the columns ``contact_s_m, contact_std_m`` of ``results.csv``
  (after ``fy_std_n``; absent for a tip load, so tip outputs stay as they were);
- :func:`point_on_shape` and :func:`arc_on_shape`: the contact point and its ±2σ arc on a
  drawn shape (the MCAP topic ``/bendsense/contact``, the figures and the live view).
"""

from __future__ import annotations

import numpy as np

from bendsense.errors import ArgumentError

__all__ = ["CONTACT_COLUMNS", "LOADS", "contact_columns", "is_contact", "check_contact_s_m", "estimate_load",
           "point_on_shape", "arc_on_shape", "resolved"]

#: the load models of ``estimate --load`` (:func:`bendsense.estimate_force`'s ``load``)
LOADS = ("tip", "contact")
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


def check_contact_s_m(value, config, name: str = "contact_s_m") -> float:
    """A known contact location: a finite number with 0 < s_c <= L (``config.actuator.length_m``).

    Parameters
    ----------
    value : object
        The location given [m].
    config : Config
        The actuator's length L bounds it.
    name : str, default "contact_s_m"
        The argument or option, for the message (``"--contact-s-m"``).

    Raises
    ------
    ArgumentError
        Naming ``name``, for anything else.
    """
    from bendsense import validation as check

    s = check.number(name, value)
    length = float(config.actuator.length_m)
    if not 0.0 < s <= length:
        raise ArgumentError(f"{name}: expected 0 < s_c <= L = {length:g} m (actuator.length_m, arc length from the "
                            f"base), got {s:g}")
    return s


def estimate_load(shape, pressure_pa, config, *, load: str = "tip", contact_s_m=None, t_s=None,
                  window_s: float = 0.05, **options):
    """The force estimate of a load model: at the tip, at a known contact, or at a contact located per window.

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes, batch axis over frames.
    pressure_pa : array_like
        Pressure of each frame [Pa].
    config : Config
        Sensor, actuator and estimation settings.
    load : {"tip", "contact"}, default "tip"
        The load model (DESIGN.md section 2b).
    contact_s_m : float, optional
        A known contact location [m] (0 < s_c <= L), with ``load="contact"``: every
        frame's force at it (:func:`bendsense.estimate_force`). None with
        ``load="contact"``: the location is estimated, one per quasi-static window of
        ``window_s`` (:func:`bendsense.estimate_contact`), which needs ``t_s``.
    t_s : array_like, shape (frames,), optional
        Frame times [s] (the windows of an unknown location).
    window_s : float, default 0.05
        The window of an unknown location [s].
    **options
        Further options of :func:`bendsense.estimate_force` (``constraint``, ``method``,
        ``calibration``, ...).

    Returns
    -------
    ForceEstimate
        With ``load``; for a contact ``contact_s_m`` and ``contact_std_m`` per frame.
    """
    from bendsense.estimation import estimate_force

    if load not in LOADS:
        raise ArgumentError(f"load: expected one of {', '.join(LOADS)}, got {load!r}")
    if load == "tip":
        if contact_s_m is not None:
            raise ArgumentError("contact_s_m: a contact location needs load='contact' (a tip load acts at s = L)")
        return estimate_force(shape, pressure_pa, config, **options)
    if contact_s_m is not None:
        s_c = check_contact_s_m(contact_s_m, config)
        return estimate_force(shape, pressure_pa, config, load="contact", contact_s_m=s_c, **options)
    import bendsense

    if t_s is None:
        raise ArgumentError("t_s: an unknown contact location is estimated over windows of frames: give the frame "
                            "times (or a known contact_s_m)")
    return bendsense.estimate_contact(shape, pressure_pa, config, t_s=t_s, window_s=window_s, **options)


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
