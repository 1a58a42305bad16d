"""Figures of a contact load: the contact point on the drawn shapes with its ±2σ arc, and s_c over time.

Used by the summary figure (:func:`bendsense.plots.plot_results`) when the results hold
``contact_s_m, contact_std_m`` (``estimate --load contact``); the live view draws the
same point and arc (:class:`bendsense.apps.live_view.LiveView`).
"""

from __future__ import annotations

import numpy as np

from bendsense.results.contact import arc_on_shape, point_on_shape

__all__ = ["draw_contacts", "plot_contact_series", "CONTACT_COLOR"]

MM = 1e3
CONTACT_COLOR = "C1"


def draw_contacts(ax, s_m, positions_m, contact_s_m, contact_std_m, colors=None, *, label: bool = True) -> list:
    """The contact point of each drawn shape (a diamond) and its ±2σ arc along the body (a thick band).

    A frame whose location is not resolved (σ inf) gets a hollow diamond at its best
    estimate and no arc (never drawn as a confident point); a frame without a location
    gets nothing.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The shape axes (mm).
    s_m : array_like, shape (M,)
        Arc length of the shapes' samples [m].
    positions_m : array_like, shape (K, M, 2)
        The drawn shapes [m].
    contact_s_m, contact_std_m : array_like, shape (K,)
        Their contact locations and standard deviations [m].
    colors : sequence, optional
        One colour per shape (the diamonds' edges); default :data:`CONTACT_COLOR`.
    label : bool, default True
        Add legend entries (a point with its arc; an unresolved point).

    Returns
    -------
    list of matplotlib artists
    """
    pos = np.asarray(positions_m, dtype=float)
    s_c = np.asarray(contact_s_m, dtype=float).reshape(-1)
    std = np.asarray(contact_std_m, dtype=float).reshape(-1)
    colors = [CONTACT_COLOR] * len(s_c) if colors is None else list(colors)
    point = point_on_shape(s_m, pos, s_c) * MM
    artists, first_arc, first_open = [], label, label
    for k in range(len(s_c)):
        if not np.isfinite(point[k]).all():
            continue
        if np.isfinite(std[k]):
            arc = arc_on_shape(s_m, pos[k], s_c[k] - 2 * std[k], s_c[k] + 2 * std[k]) * MM
            if len(arc) > 1:
                (line,) = ax.plot(arc[:, 0], arc[:, 1], "-", color=CONTACT_COLOR, linewidth=7, alpha=0.35,
                                  solid_capstyle="butt", zorder=2.5)
                artists.append(line)
            (dot,) = ax.plot(*point[k], "D", markersize=6, markerfacecolor=CONTACT_COLOR, markeredgecolor=colors[k],
                             markeredgewidth=1.2, zorder=3, label="contact ± 2σ along the body" if first_arc else None)
            first_arc = False
        else:
            (dot,) = ax.plot(*point[k], "D", markersize=6, markerfacecolor="none", markeredgecolor=CONTACT_COLOR,
                             markeredgewidth=1.2, zorder=3, label="contact unresolved (σ inf)" if first_open else None)
            first_open = False
        artists.append(dot)
    return artists


def plot_contact_series(ax, t, contact_s_m, contact_std_m, *, length_m: float | None = None,
                        sensor_end_m: float | None = None, force_n=None):
    """The contact location over time [mm] with its ±2σ band; unresolved frames as hollow points.

    Frames of a window that kept the tip model (a force, no location: ``contact_s_m``
    NaN) are ticked grey at the top of the panel. The lines of the tip and of the
    sensor's end are drawn when they fall within the locations' range.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    t : array_like, shape (frames,)
        Frame time [s].
    contact_s_m, contact_std_m : array_like, shape (frames,)
        The contact's arc length from the base and its standard deviation [m] (σ inf:
        unresolved, the location drawn hollow and without a band).
    length_m : float, optional
        The actuator's length L (a dashed line: the tip).
    sensor_end_m : float, optional
        The sensor's end (a dotted line: beyond it no coil sees the shape).
    force_n : array_like, shape (frames, 2), optional
        The frames' forces: a frame with a force and no location kept the tip model.

    Returns
    -------
    matplotlib.axes.Axes
    """
    t = np.asarray(t, dtype=float)
    s = np.asarray(contact_s_m, dtype=float) * MM
    sd = np.asarray(contact_std_m, dtype=float) * MM
    ok = np.isfinite(s) & np.isfinite(sd)
    shown = np.where(ok, s, np.nan)
    ax.fill_between(t, shown - 2 * sd, shown + 2 * sd, color=CONTACT_COLOR, alpha=0.25, linewidth=0,
                    label="s_c ± 2σ")
    known = bool(ok.any()) and bool((sd[ok] == 0).all())  # a location given, not estimated
    ax.plot(t, shown, "-", color=CONTACT_COLOR, linewidth=1.4, label="contact s_c (known)" if known else "contact s_c")
    unresolved = np.flatnonzero(np.isfinite(s) & ~np.isfinite(sd))
    if unresolved.size:  # (thinned: hundreds of overlapping circles are one thick bar)
        unresolved = unresolved[::-(-unresolved.size // 40)]
        ax.plot(t[unresolved], s[unresolved], "o", markerfacecolor="none", markeredgecolor=CONTACT_COLOR,
                markersize=3.5, linestyle="none", label="unresolved (σ inf)")
    tip_kept = ~np.isfinite(s) & np.isfinite(sd) if force_n is None else (
        ~np.isfinite(s) & np.isfinite(np.asarray(force_n, dtype=float)).all(axis=-1))
    if tip_kept.any():
        ax.plot(t[tip_kept], np.ones(int(tip_kept.sum())), "|", color="0.45", markersize=8,
                transform=ax.get_xaxis_transform(), label="tip model kept")
    values = s[np.isfinite(s)]
    lo, hi = (0.0, 1.05 * length_m * MM) if length_m is not None else (0.0, 1.0)
    if values.size:  # the locations set the limits (a band far wider than them is cut), within [0, L]
        band = sd[ok]
        pad = max(0.1 * float(np.ptp(values)), float(np.median(band)) if band.size else 0.0, 2.0)
        lo, hi = max(float(values.min()) - pad, 0.0), float(values.max()) + pad
        if length_m is not None:
            hi = min(hi, 1.05 * length_m * MM)
    ax.set_ylim(lo, hi)
    for at, style, label in ((length_m, "--", "tip (L)"), (sensor_end_m, ":", "sensor end")):
        if at is not None and lo <= at * MM <= hi:
            ax.axhline(at * MM, color="0.4", linestyle=style, linewidth=0.8, label=label)
    ax.set_ylabel("contact s_c [mm]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", ncols=5, loc="lower right", bbox_to_anchor=(1.0, 1.0), frameon=False,
              borderaxespad=0.2)
    return ax
