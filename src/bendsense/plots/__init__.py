"""Figures: shapes, shapes against ground truth, force errors, time series, calibration, summaries.

Every function draws on ``ax`` when given (a new figure otherwise) and returns
the axes, or the figure for multi-panel plots. Lengths are shown in mm, forces
in N, curvatures in 1/m, pressures in kPa, times in s; data go in SI units
(DESIGN.md section 2). The styles follow the paper's figures: reconstructed
shapes over several frames (Fig. 8), solid reconstruction against dotted ground
truth (Fig. 8, 9(b)), force error over pressure × load (Fig. 10).

Inputs are duck-typed: anything with ``positions_m`` (``Shape``, ``BeamSolution``,
``Results``) or a positions array (..., M, 2) [m] is a shape.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from bendsense import validation as check
from bendsense.errors import ArgumentError

__all__ = [
    "plot_shapes",
    "plot_shape_comparison",
    "plot_force",
    "plot_force_error_map",
    "plot_time_series",
    "plot_calibration",
    "plot_results",
    "results_from_state",
]

MM = 1e3
KPA = 1e-3


def _new_axes(ax, **kwargs):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(layout="constrained", **kwargs)
    return ax


def _positions(obj) -> np.ndarray:
    """Positions as (frames, M, 2) [m] from a shape-like object or an array."""
    try:
        pos = np.asarray(getattr(obj, "positions_m", obj), dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"positions_m: expected a Shape, BeamSolution, Results or numbers of shape (..., M, 2), "
                            f"got {type(obj).__name__}") from None
    if pos.ndim < 2 or pos.shape[-1] != 2:
        raise ArgumentError(f"positions_m: expected shape (..., M, 2), got {pos.shape}")
    return pos.reshape(-1, pos.shape[-2], 2)


def _flags(obj, frames: int):
    """Frames drawn dashed (frames,) and the legend's explanation of them."""
    flags, label = getattr(obj, "extrapolated", None), EXTRAPOLATED_LABEL
    if flags is None and hasattr(obj, "columns") and "status" in obj.columns:
        flags = np.asarray(obj.columns["status"]) == "extrapolated"
    if flags is None and hasattr(obj, "success"):  # a BeamSolution: the frames that did not converge
        flags, label = ~np.asarray(obj.success, dtype=bool), NOT_CONVERGED_LABEL
    if flags is None:
        return np.zeros(frames, dtype=bool), label
    return np.broadcast_to(np.asarray(flags, dtype=bool).reshape(-1) if np.ndim(flags) else flags, (frames,)), label


def _pick(n: int, frames, max_frames: int) -> np.ndarray:
    """The frames drawn: ``frames`` (an index, a slice or indices of the ``n``), else up to ``max_frames`` spread."""
    if frames is not None:
        try:
            idx = np.atleast_1d(np.arange(n)[frames])
        except (IndexError, TypeError, ValueError):
            raise ArgumentError(f"frames: expected an index, a slice or indices of the {n} frames, got "
                                f"{frames!r:.60}") from None
        if idx.size == 0:
            raise ArgumentError(f"frames: selects no frame of the {n}, got {frames!r:.60}")
        return idx
    check.integer("max_frames", max_frames, minimum=1)
    if n <= max_frames:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_frames).round().astype(int))


def _colormap(cmap: str):
    """The matplotlib colour map named ``cmap``."""
    import matplotlib

    try:
        return matplotlib.colormaps[cmap]
    except (KeyError, TypeError):
        raise ArgumentError(f"cmap: {cmap!r:.60} is not a matplotlib colour map (e.g. 'viridis'; "
                            "matplotlib.colormaps lists them)") from None


def _colors(n: int, cmap: str = "viridis"):
    cm = _colormap(cmap)
    return [cm(x) for x in (np.linspace(0.0, 0.9, n) if n > 1 else [0.0])]


def plot_shapes(
    shape_or_positions,
    ax=None,
    *,
    frames=None,
    max_frames: int = 8,
    labels=None,
    cmap: str = "viridis",
    legend: bool = True,
    **line_kwargs,
):
    """Plot reconstructed shapes of several frames in the base frame (paper Fig. 8 style).

    Parameters
    ----------
    shape_or_positions : Shape, BeamSolution, Results or array_like, shape (..., M, 2)
        Shapes; positions in [m] (drawn in mm).
    ax : matplotlib.axes.Axes, optional
        Where to draw; default a new figure.
    frames : int, slice or sequence of int, optional
        Frames to draw; default up to ``max_frames`` evenly spaced frames.
    max_frames : int
        Most frames drawn by default.
    labels : sequence of str, optional
        One legend label per drawn frame; default ``t = … s`` for ``Results``, else
        ``frame i``.
    cmap : str
        Colour map; the frames go from its dark to its light end in order.
    legend : bool
        Draw a legend when there is more than one line; False with many frames: a colour
        bar of the frames (their times where known) says what the colours mean.
    **line_kwargs
        Passed to ``Axes.plot``.

    Returns
    -------
    matplotlib.axes.Axes

    Notes
    -----
    Frames flagged ``extrapolated`` (signals outside the calibrated range) are dashed.
    ``x`` points toward the centre of curvature, ``y`` along the base tangent
    (DESIGN.md section 2); the base is the black square, the tips are dots.
    """
    pos = _positions(shape_or_positions)
    idx = _pick(len(pos), frames, max_frames)
    colors = _colors(len(idx), cmap)
    flags, dashed = _flags(shape_or_positions, len(pos))
    if labels is None:
        columns = getattr(shape_or_positions, "columns", None)
        if columns is not None and "t_s" in columns:
            labels = [f"t = {columns['t_s'][i]:.2f} s" for i in idx]
        else:
            labels = [f"frame {i}" for i in idx]
    labels = list(labels)
    if len(labels) != len(idx):
        raise ArgumentError(f"labels: expected {len(idx)} labels (one per drawn frame), got {len(labels)}")
    ax = _new_axes(ax, figsize=(5, 5))
    for i, color, label in zip(idx, colors, labels, strict=True):
        p = pos[i] * MM
        style = dict(color=color, linewidth=1.8, linestyle="--" if flags[i] else "-", label=label)
        style.update(line_kwargs)
        ax.plot(p[:, 0], p[:, 1], **style)
        ax.plot(p[-1, 0], p[-1, 1], "o", color=style["color"], markersize=4)
    ax.plot([0.0], [0.0], "ks", markersize=6)
    _shape_axes(ax)
    if np.any(flags[idx]):
        # explained in the legend: a dashed shape is not a measurement like the others
        ax.plot([], [], "--", color="0.3", linewidth=1.8, label=dashed)
    if legend and (len(idx) > 1 or np.any(flags[idx])):
        ax.legend(fontsize="small", loc="best")
    elif not legend and len(idx) > 8:  # too many for a legend: the colours' meaning on a bar
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import ListedColormap, Normalize

        columns = getattr(shape_or_positions, "columns", None)
        times = columns is not None and "t_s" in columns
        where = np.asarray(columns["t_s"], dtype=float)[idx] if times else idx.astype(float)
        bar = ax.figure.colorbar(ScalarMappable(Normalize(where[0], where[-1]), ListedColormap(colors)), ax=ax,
                                 shrink=0.8)
        bar.set_label("t [s]" if times else "frame")
    return ax


EXTRAPOLATED_LABEL = "dashed: extrapolated\n(a signal outside the calibrated range)"
NOT_CONVERGED_LABEL = "dashed: not converged"


def _shape_axes(ax):
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)


def plot_shape_comparison(
    shapes,
    truth,
    ax=None,
    *,
    model=None,
    labels=None,
    names=("sensor", "model", "ground truth"),
    cmap: str = "viridis",
):
    """Plot shapes against the ground truth (paper Fig. 8 and 9(b) style).

    Solid lines are the reconstructed shapes, dashed lines the model's prediction
    (optional), dotted lines with dots the ground truth; one colour per case.

    Parameters
    ----------
    shapes : Shape or array_like, shape (K, M, 2)
        Reconstructed shapes of K cases [m].
    truth : Shape, BeamSolution or array_like, shape (K, M', 2)
        Ground-truth shapes of the same cases (e.g. camera markers) [m].
    ax : matplotlib.axes.Axes, optional
    model : Shape, BeamSolution or array_like, shape (K, M'', 2), optional
        Shapes predicted by a model (e.g. the beam model with the known load) [m].
    labels : sequence of str, optional
        One label per case (e.g. ``"0.1 N"``); default ``case k``.
    names : tuple of str
        Legend names of the reconstructed, model and ground-truth line styles.
    cmap : str
        Colour map of the cases.

    Returns
    -------
    matplotlib.axes.Axes
    """
    from matplotlib.lines import Line2D

    ax = _new_axes(ax, figsize=(5, 5))
    est = _positions(shapes)
    tru = _positions(truth)
    mod = None if model is None else _positions(model)
    k = len(est)
    for name, other in (("truth", tru), ("model", mod)):
        if other is not None and len(other) != k:
            raise ArgumentError(f"{name}: expected {k} shapes (one per reconstructed shape), got {len(other)}")
    labels = [f"case {i}" for i in range(k)] if labels is None else list(labels)
    if len(labels) != k:
        raise ArgumentError(f"labels: expected {k} labels, got {len(labels)}")
    colors = _colors(k, cmap)
    for i in range(k):
        c = colors[i]
        ax.plot(est[i, :, 0] * MM, est[i, :, 1] * MM, "-", color=c, linewidth=1.8)
        if mod is not None:
            ax.plot(mod[i, :, 0] * MM, mod[i, :, 1] * MM, "--", color=c, linewidth=1.4)
        ax.plot(tru[i, :, 0] * MM, tru[i, :, 1] * MM, ":", color=c, linewidth=1.6, marker="o", markersize=3)
    ax.plot([0.0], [0.0], "ks", markersize=6)
    _shape_axes(ax)
    handles = [Line2D([], [], color=c, linewidth=6, label=lab) for c, lab in zip(colors, labels, strict=True)]
    handles.append(Line2D([], [], color="k", linestyle="-", label=names[0]))
    if mod is not None:
        handles.append(Line2D([], [], color="k", linestyle="--", label=names[1]))
    handles.append(Line2D([], [], color="k", linestyle=":", marker="o", markersize=3, label=names[2]))
    ax.legend(handles=handles, fontsize="small", loc="best")
    return ax


def plot_force(estimate, ax=None, *, shape=None, t_s=None, scale_mm_per_n: float = 100.0):
    """Plot a force estimate (:class:`~bendsense.estimation.ForceEstimate`).

    Parameters
    ----------
    estimate : ForceEstimate
        One frame or a batch.
    ax : matplotlib.axes.Axes, optional
    shape : Shape or BeamSolution, optional
        One frame: the shape drawn under the force arrow.
    t_s : array_like, optional
        A batch: the time of each frame [s] (default the frame index).
    scale_mm_per_n : float
        One frame: arrow length [mm per N].

    Returns
    -------
    matplotlib.axes.Axes
        One frame: the force as an arrow at the model's tip, in mm, titled with its
        value and σ; a contact load (``load="contact"``) with ``shape`` given: the arrow at
        the shape's point at ``contact_s_m``, drawn with its ±2σ arc, and s_c in the title.
        A batch: Fx and Fy against time with their ±2σ bands.
    """
    if not (hasattr(estimate, "force_n") and hasattr(estimate, "std_n")):  # a ForceEstimate (it imports plots)
        raise ArgumentError(f"estimate: expected a ForceEstimate (bendsense.estimate_force), got "
                            f"{type(estimate).__name__}")
    force = np.asarray(estimate.force_n, dtype=float)
    if force.ndim == 1:
        ax = _new_axes(ax, figsize=(5, 5))
        if shape is not None:
            p = _positions(shape)[0] * MM
            ax.plot(p[:, 0], p[:, 1], "-", color="0.4")
        tip = np.zeros(2) if estimate.tip_position_m is None else np.asarray(estimate.tip_position_m) * MM
        contact = getattr(estimate, "load", "tip") == "contact" and estimate.contact_s_m is not None
        s_c = float(np.asarray(estimate.contact_s_m)) if contact else float("nan")
        if shape is not None and np.isfinite(s_c):  # the force acts at the contact: the arrow starts there
            from bendsense.plots.contact import draw_contacts

            p = _positions(shape)[:1]
            draw_contacts(ax, np.asarray(shape.s_m), p, [s_c], [float(np.asarray(estimate.contact_std_m))])
            from bendsense.results.contact import point_on_shape

            tip = point_on_shape(shape.s_m, p[0], s_c) * MM
        head = tip + scale_mm_per_n * force
        ax.annotate("", xy=head, xytext=tip, arrowprops={"arrowstyle": "->", "color": "C3"})
        ax.plot([0.0, tip[0], head[0]], [0.0, tip[1], head[1]], alpha=0.0)  # the arrow inside the limits
        ax.plot([0.0], [0.0], "ks", markersize=6)
        _shape_axes(ax)
        std = np.asarray(estimate.std_n, dtype=float)
        parts = [f"{f:.3g}" + (f" ± {s:.2g}" if np.isfinite(s) else "") for f, s in zip(force, std, strict=True)]
        title = f"F = ({parts[0]}, {parts[1]}) N"
        if np.isfinite(s_c):
            sd = float(np.asarray(estimate.contact_std_m))
            title += f" at s_c = {s_c * MM:.1f}" + (f" ± {sd * MM:.1f} mm" if 0 < sd < np.inf else
                                                     " mm (unresolved)" if sd == np.inf else " mm")
        ax.set_title(title, fontsize="medium")
        return ax
    ax = _new_axes(ax, figsize=(7, 4))
    force = force.reshape(-1, 2)
    std = np.asarray(estimate.std_n, dtype=float).reshape(-1, 2)
    t = np.arange(len(force)) if t_s is None else np.asarray(t_s, dtype=float).reshape(-1)
    _force_panel(ax, t, force, std)
    ax.set_xlabel("t [s]" if t_s is not None else "frame")
    return ax


def _grid(pressure_pa, load_n, error):
    """Error on a pressure × load grid: (pressures (P,), loads (L,), mean (P, L), std (P, L))."""
    p = np.asarray(pressure_pa, dtype=float).ravel()
    f = np.asarray(load_n, dtype=float).ravel()
    e = np.asarray(error, dtype=float)
    if e.shape == (p.size, f.size) and not (e.ndim == 1 and p.size == f.size == e.size):
        return p, f, e, np.full(e.shape, np.nan)
    e = e.ravel()
    if e.size == 0:
        raise ArgumentError("error: no samples to draw (empty pressure_pa, load_n and error)")
    if not p.size == f.size == e.size:
        raise ArgumentError(
            "error: expected shape (len(pressure_pa), len(load_n)) for a grid, or three arrays of equal "
            f"length for samples; got pressure {p.shape}, load {f.shape}, error {np.shape(error)}"
        )
    pu, pi = np.unique(p, return_inverse=True)
    fu, fi = np.unique(f, return_inverse=True)
    mean = np.full((pu.size, fu.size), np.nan)
    std = np.full((pu.size, fu.size), np.nan)
    for a in range(pu.size):
        for b in range(fu.size):
            cell = e[(pi == a) & (fi == b)]
            cell = cell[np.isfinite(cell)]
            if cell.size:
                mean[a, b] = cell.mean()
                std[a, b] = cell.std(ddof=1) if cell.size > 1 else np.nan
    return pu, fu, mean, std


def plot_force_error_map(
    pressure_pa,
    load_n,
    error,
    ax=None,
    *,
    kind: str = "bars",
    error_label: str = "force error [N]",
    cmap: str | None = None,
):
    """Plot the force error over actuation pressure × tip load (paper Fig. 10 style).

    Parameters
    ----------
    pressure_pa : array_like
        Pressures [Pa]: the grid's P values, or one per sample.
    load_n : array_like
        Tip loads [N]: the grid's L values, or one per sample.
    error : array_like, shape (P, L) or like ``pressure_pa``
        Error of each pressure-load cell, or of each sample (then averaged per cell,
        with the standard deviation as error bars); in the unit of ``error_label``
        (e.g. N, or % of the largest load). NaN cells are left empty.
    ax : matplotlib.axes.Axes, optional
    kind : {"bars", "heatmap"}
        Grouped bars per pressure with one bar per load (legend), or a heat map with a
        colour bar and the value written in each cell.
    error_label : str
        Label of the error axis / colour bar, with its unit.
    cmap : str, optional
        Colour map; default ``viridis`` for the bars' loads and the heat map of
        one-signed errors, ``RdBu_r`` centred on 0 for signed errors.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if kind not in ("bars", "heatmap"):
        raise ArgumentError(f"kind: must be 'bars' or 'heatmap', got {kind!r}")
    if cmap is not None:
        _colormap(cmap)
    pu, fu, mean, std = _grid(pressure_pa, load_n, error)
    ax = _new_axes(ax, figsize=(7, 4))
    if kind == "bars":
        n = fu.size
        width = 0.8 / n
        x = np.arange(pu.size)
        for b, color in zip(range(n), _colors(n, cmap or "viridis"), strict=True):
            yerr = std[:, b] if np.any(np.isfinite(std[:, b])) else None
            ax.bar(x - 0.4 + (b + 0.5) * width, mean[:, b], width, yerr=yerr, capsize=2,
                   color=color, label=f"{fu[b]:g} N", error_kw={"elinewidth": 0.8})
        ax.set_xticks(x, [f"{v * KPA:g}" for v in pu])
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel(error_label)
        ax.axhline(0.0, color="k", linewidth=0.6)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(title="tip load", fontsize="small", title_fontsize="small", ncols=min(n, 4))
        return ax
    finite = mean[np.isfinite(mean)]
    signed = finite.size and finite.min() < 0 < finite.max()
    if signed:
        bound = float(np.abs(finite).max())
        vmin, vmax, cmap = -bound, bound, cmap or "RdBu_r"
    else:
        vmin = vmax = None
        cmap = cmap or "viridis"
    image = ax.imshow(np.ma.masked_invalid(mean.T), origin="lower", aspect="auto", cmap=_colormap(cmap),
                      vmin=vmin, vmax=vmax, interpolation="nearest")
    ax.set_xticks(np.arange(pu.size), [f"{v * KPA:g}" for v in pu])
    ax.set_yticks(np.arange(fu.size), [f"{v:g}" for v in fu])
    ax.set_xlabel("pressure [kPa]")
    ax.set_ylabel("tip load [N]")
    ax.figure.colorbar(image, ax=ax, label=error_label)
    if mean.size <= 300:
        norm = image.norm
        for a in range(pu.size):
            for b in range(fu.size):
                v = mean[a, b]
                if np.isfinite(v):
                    dark = image.cmap(norm(v))[:3]
                    light = 0.299 * dark[0] + 0.587 * dark[1] + 0.114 * dark[2] > 0.5
                    ax.text(a, b, f"{v:.3g}", ha="center", va="center", fontsize="x-small",
                            color="k" if light else "w")
    return ax


def _as_results(results):
    """``results`` as :class:`~bendsense.results.Results`: read from its directory where it is a path."""
    from bendsense.results import Results, read_results

    if isinstance(results, (str, os.PathLike)):
        return read_results(results)
    if not isinstance(results, Results):
        raise ArgumentError(f"results: expected Results (bendsense.read_results) or a results directory, got "
                            f"{type(results).__name__}")
    return results


def plot_time_series(results, ax=None, *, cax=None, cmap: str = "viridis", pressure: bool = True):
    """Plot tip force (with ±2σ band) and segment curvatures over time (two panels).

    Parameters
    ----------
    results : Results or path
        Results as read by :func:`bendsense.results.read_results`, or their directory.
    ax : sequence of two matplotlib.axes.Axes, optional
        Force and curvature axes; default a new figure with two panels sharing time.
    cax : matplotlib.axes.Axes, optional
        Axes for the segments' colour bar; default: a slot beside the curvature panel
        (in a new figure), or space taken from the curvature axes (with ``ax``).
    cmap : str
        Colour map of the segments (base: dark, tip: light).
    pressure : bool
        Draw the pressure [kPa] on a second axis of the force panel.

    Returns
    -------
    matplotlib.figure.Figure

    Notes
    -----
    The force panel's legend sits above it, where it covers no data.
    Frames whose status is not ``ok`` (``extrapolated``, ``not converged``) are marked
    with grey ticks at the bottom of the force panel. Results with a tracked force
    (``fx_track_n``, ...) show it as lines with their ±2σ bands over the per-frame
    forces drawn as points, and tick the frames whose ``track_status`` is not ``ok``.
    """
    import matplotlib as mpl

    from bendsense.tracking.gaps import broken_at_gaps

    results = _as_results(results)
    if ax is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(8, 6), layout="constrained")
        # the colour bar gets its own column so that both panels keep the same width
        grid = fig.add_gridspec(2, 2, width_ratios=(1, 0.025))
        ax_f = fig.add_subplot(grid[0, 0])
        ax_k = fig.add_subplot(grid[1, 0], sharex=ax_f)
        cax = fig.add_subplot(grid[1, 1]) if cax is None else cax
        ax_f.tick_params(labelbottom=False)
    else:
        ax_f, ax_k = ax
        fig = ax_f.figure
    times = np.asarray(results["t_s"], dtype=float)
    t, kappa = broken_at_gaps(times, results.curvature_per_m)  # lines stop at a gap in the frames, not bridge it
    if results.has_forces:
        force = np.stack([np.asarray(results[f"f{c}_n"], dtype=float) for c in "xy"], axis=-1)
        std = np.stack([np.asarray(results[f"f{c}_std_n"], dtype=float) for c in "xy"], axis=-1)
        status = np.asarray(results["status"]) if "status" in results.columns else None
        kpa = (np.asarray(results["pressure_pa"], dtype=float) * 1e-3
               if pressure and "pressure_pa" in results.columns else None)
        tracked = None
        if getattr(results, "has_track", False):
            tracked = tuple(np.stack([np.asarray(results[f"f{c}_track{s}_n"], dtype=float) for c in "xy"], axis=-1)
                            for s in ("", "_std"))
            status = np.asarray(results["track_status"])
        _force_panel(ax_f, times, force, std, status=status, pressure_kpa=kpa, tracked=tracked,
                     contact="contact_s_m" in results.columns)
    else:
        ax_f.set_ylabel("tip force [N]")
        ax_f.text(0.5, 0.5, "no force estimate", transform=ax_f.transAxes, ha="center", va="center", color="0.4")
    n = kappa.shape[1]
    colors = _colors(n, cmap)
    for i in range(n):
        ax_k.plot(t, kappa[:, i], color=colors[i], linewidth=1.0)
    # one discrete colour per segment, so that the colour bar reads as a legend of the N lines
    norm = mpl.colors.BoundaryNorm(np.arange(0.5, n + 1.5), n)
    mappable = mpl.cm.ScalarMappable(norm=norm, cmap=mpl.colors.ListedColormap(colors))
    if cax is None:
        bar = fig.colorbar(mappable, ax=ax_k, label="segment i", pad=0.01)
    else:
        bar = fig.colorbar(mappable, cax=cax, label="segment i")
    step = max(1, n // 4)
    bar.set_ticks(sorted({1, n, *range(step, n + 1, step)}))
    ax_k.set_ylabel("curvature κ_i [1/m]")
    ax_k.set_xlabel("time [s]")
    ax_k.grid(True, alpha=0.3)
    return fig


def _force_panel(ax, t, force, std, *, status=None, pressure_kpa=None, tracked=None, contact=False):
    """Fx, Fy (frames, 2) [N] against ``t`` with their ±2σ bands; frames not ``ok`` ticked; pressure on the right.

    A component with an infinite σ (not identifiable: the shape does not determine it)
    is left out, not drawn at the value where the fit stopped. With ``tracked`` (the
    tracked force and its σ, each (frames, 2)), the band is the tracked force's and the
    per-frame forces are points under it; the tracked line and band leave out the frames
    whose ``status`` (then the track's) is not ``ok``. ``contact``: the load is a contact
    along the body, not at the tip.
    """
    from matplotlib.legend_handler import HandlerTuple

    from bendsense.tracking.gaps import broken_at_gaps, gaps

    if status is not None:  # (the rows a gap gets below: nothing to tick)
        status = np.insert(np.asarray(status), gaps(t), "ok")
    # lines and bands stop at a gap in the frames, not bridge it
    t, force, std, pressure_kpa, *tracked = broken_at_gaps(t, force, std, pressure_kpa, *(tracked or (None,)))
    tracked = None if tracked[0] is None else tuple(tracked)
    ax.set_ylabel("contact force [N]" if contact else "tip force [N]")
    handles, labels, dots = [], [], []
    drawn, bands = [force], []
    for i, (color, label) in enumerate((("C0", "F_x"), ("C3", "F_y"))):
        f, band = np.where(np.isinf(std[:, i]), np.nan, force[:, i]), 2.0 * std[:, i]
        points = None
        if tracked is not None:  # over the band, under the tracked line
            (points,) = ax.plot(t, f, ".", color=color, markersize=2.5, alpha=0.5, markeredgewidth=0, zorder=2.2,
                                label=f"{label} per frame")
            # a frame whose tracked status is not ok (the ticks) is left out: a smoother carried through frames
            # that do not determine the force swings there (half a newton, sigma tens of newtons) and tells nothing
            kept = np.ones(t.size, dtype=bool) if status is None else status == "ok"
            f = np.where(np.isinf(tracked[1][:, i]) | ~kept, np.nan, tracked[0][:, i])
            band = np.where(kept, 2.0 * tracked[1][:, i], np.nan)
            label += " tracked"
        drawn.append(f)
        bands.append(band)
        (line,) = ax.plot(t, f, color=color, linewidth=1.4, label=label, zorder=2.4)
        fill = ax.fill_between(t, f - band, f + band, color=color, alpha=0.2, linewidth=0, label=f"{label} ± 2σ")
        handles.append((line, fill))
        labels.append(f"{label} ± 2σ")
        if points is not None:
            dots.append(points)
    if dots:  # one legend entry for the points of both components, side by side, large enough to see
        from matplotlib.lines import Line2D

        dots = tuple(Line2D([], [], linestyle="none", marker=".", markersize=8, color=d.get_color(), alpha=0.6)
                     for d in dots)
        handles.append(dots)
        labels.append("per frame")
    if status is not None and np.any(status != "ok"):
        bad = status != "ok"
        (ticks,) = ax.plot(t[bad], np.zeros(bad.sum()), "|", color="0.5", transform=ax.get_xaxis_transform(),
                           markersize=8, label="status not ok")
        handles.append(ticks)
        labels.append("status not ok")
    ax.axhline(0.0, color="k", linewidth=0.5)
    ax.grid(True, alpha=0.3)
    values = np.concatenate([np.ravel(v) for v in drawn])
    values, bands = values[np.isfinite(values)], np.concatenate(bands)
    bands = bands[np.isfinite(bands)]
    if values.size:  # the forces set the limits: a band far wider than them (a barely determined component) is cut
        pad = max(0.1 * float(np.ptp(values)), float(np.median(bands)) if bands.size else 0.0, 1e-3)
        ax.set_ylim(float(values.min()) - pad, float(values.max()) + pad)
    if pressure_kpa is not None and np.any(np.isfinite(pressure_kpa)):
        px = ax.twinx()
        (pline,) = px.plot(t, pressure_kpa, color="0.45", linewidth=1.0, label="pressure")
        px.set_ylabel("pressure [kPa]", color="0.35")
        px.tick_params(axis="y", colors="0.35")
        px.set_ylim(0.0, 1.05 * float(np.nanmax(pressure_kpa)) or 1.0)
        ax.set_zorder(px.get_zorder() + 1)  # forces over the pressure
        ax.patch.set_visible(False)
        handles.append(pline)
        labels.append("pressure (right axis)")
    # above the panel, where it covers no data
    ax.legend(handles, labels, fontsize="small", ncols=2, loc="lower right", bbox_to_anchor=(1.0, 1.0),
              frameon=False, borderaxespad=0.2,
              handler_map={dots: HandlerTuple(ndivide=None)} if dots else None)


def plot_calibration(calibration, data=None, ax=None):
    """Plot the calibration fit S(ΔA) with its data and residuals (delegates to ``Calibration.plot``).

    Parameters
    ----------
    calibration : Calibration
        A fitted calibration (paper eq. 2); its own fit data are drawn when stored.
    data : tuple (delta_a, shifts_m), optional
        Further points to check the fit against, e.g. validation strips: signal
        changes ΔA (K, N) [signal units] and true shifts S (K, N) [m]; drawn as black
        crosses, with their residuals.
    ax : matplotlib.axes.Axes, optional
        Draw only the fit panel on this axes; default a new figure with the fit and
        residual panels.

    Returns
    -------
    matplotlib.figure.Figure or matplotlib.axes.Axes
        The figure for the two-panel plot, the axes when ``ax`` was given.
    """
    from bendsense.calibration import Calibration

    if not isinstance(calibration, Calibration):
        raise ArgumentError(f"calibration: expected a Calibration (Calibration.load(path)), got "
                            f"{type(calibration).__name__}")
    axes = calibration.plot(ax=ax)
    fit_ax = axes if ax is not None else axes[0]
    if data is not None:
        delta, shifts = (np.asarray(a, dtype=float) for a in data)
        if delta.shape != shifts.shape:
            raise ArgumentError(f"data: delta_a {delta.shape} and shifts_m {shifts.shape} must have the same shape")
        fit_ax.plot(delta.ravel(), shifts.ravel() * MM, "kx", markersize=5, label="check data")
        fit_ax.legend()
        if ax is None:
            resid = (calibration.shifts_from_delta(delta) - shifts) * 1e6
            axes[1].plot(delta.ravel(), resid.ravel(), "kx", markersize=5)
    if ax is not None:
        return fit_ax
    fig = fit_ax.figure
    fig.set_layout_engine("constrained")
    return fig


def results_from_state(session, shape, estimate=None, track=None):
    """In-memory :class:`~bendsense.results.Results` of a pipeline state (for plots).

    Parameters
    ----------
    session : Session
        The processed session.
    shape : Shape
        Its reconstructed shapes.
    estimate : ForceEstimate, optional
        Its force estimates.
    track : Track, optional
        Its tracked forces (:func:`bendsense.track`).
    """
    from bendsense.results import Results

    return Results.from_state(session, shape, estimate, track)


def plot_results(
    results,
    path=None,
    *,
    max_shapes: int = 8,
    dpi: int = 150,
    title: str | None = None,
    overwrite: bool = True,
    estimated: str | None = None,
    length_m: float | None = None,
):
    """Summary figure of processed frames: shapes and tip path, tip forces, curvatures over time.

    Parameters
    ----------
    results : Results or path
        A results directory (``results.csv``, ``shape.npz``) or its :class:`Results`.
    path : path, optional
        Write the figure there (format from the suffix: .png, .pdf, .svg, ...),
        atomically; the figure is then not registered with pyplot (no window, no
        leak in loops).
    max_shapes : int
        Frames whose shape is drawn, evenly spaced in time.
    dpi : int
        Resolution of raster formats.
    title : str, optional
        Figure title; default the results directory's name, the frame count and what
        was estimated.
    estimated : str, optional
        How the forces were estimated, for the default title (e.g. ``"constraint
        normal, method fast"``).
    overwrite : bool
        Replace an existing file at ``path`` (False: :class:`~bendsense.errors.OutputExistsError`).
    length_m : float, optional
        The actuator's length L, marked in the contact panel (results of a contact load).

    Returns
    -------
    matplotlib.figure.Figure
        Left: shapes of ``max_shapes`` frames and the tip path (grey); right: tip force
        with ±2σ band (top) and segment curvatures (bottom) over time. Results of a
        contact load (``contact_s_m``) add the contact point with its ±2σ arc on each
        drawn shape and a panel of s_c over time with its ±2σ band
        (:mod:`bendsense.plots.contact`).
    """
    source = results if isinstance(results, (str, os.PathLike)) else None
    check.integer("max_shapes", max_shapes, minimum=1)
    results = _as_results(results)
    if path is not None:
        from matplotlib.figure import Figure

        path = Path(path)
        fig = Figure(figsize=(12, 6.5), layout="constrained")
        fmt = path.suffix[1:].lower() or "png"
        supported = fig.canvas.get_supported_filetypes()
        if fmt not in supported:
            raise ArgumentError(f"{path}: unknown figure format {fmt!r}; use one of {', '.join(sorted(supported))}")
    else:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(12, 6.5), layout="constrained")
    contact = results.has_contact
    if contact:
        fig.set_size_inches(12, 8.5)
    grid = fig.add_gridspec(3 if contact else 2, 3, width_ratios=(1, 1.6, 0.04),
                            height_ratios=(1, 0.7, 1) if contact else None)
    ax_s = fig.add_subplot(grid[:, 0])
    ax_f = fig.add_subplot(grid[0, 1])
    ax_k = fig.add_subplot(grid[-1, 1], sharex=ax_f)
    cax = fig.add_subplot(grid[-1, 2])
    tip = np.column_stack([results["tip_x_m"], results["tip_y_m"]]).astype(float) * MM
    ax_s.plot(tip[:, 0], tip[:, 1], color="0.6", linewidth=0.8, zorder=0, label="tip path")
    plot_shapes(results, ax_s, max_frames=max_shapes, legend=False)
    if contact:
        from bendsense.plots.contact import draw_contacts, plot_contact_series

        idx = _pick(len(results.positions_m), None, max_shapes)
        draw_contacts(ax_s, results.s_m, results.positions_m[idx], results["contact_s_m"][idx],
                      results["contact_std_m"][idx], _colors(len(idx)))
        ax_c = fig.add_subplot(grid[1, 1], sharex=ax_f)
        plot_contact_series(ax_c, results["t_s"], results["contact_s_m"], results["contact_std_m"],
                            length_m=length_m, sensor_end_m=float(results.s_m[-1]),
                            force_n=np.column_stack([results["fx_n"], results["fy_n"]]))
        ax_c.tick_params(labelbottom=False)
    # below the panel, where it covers no shape
    ax_s.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.09), ncols=2, frameon=False)
    ax_s.set_title("shapes", fontsize="medium")
    plot_time_series(results, (ax_f, ax_k), cax=cax)
    ax_f.set_title("contact force (base frame)" if contact else "tip force (base frame)", fontsize="medium", loc="left")
    if contact:
        ax_f.set_ylabel("contact force [N]")
    ax_f.tick_params(labelbottom=False)
    frames = len(results["t_s"])
    if title is None:
        name = Path(source).name if source is not None else "results"
        if results.has_forces:
            forces = "contact forces" if contact else "tip forces"
            what = (f"shapes and {forces}, tracked" if results.has_track else f"shapes and {forces}") + (
                f" ({estimated})" if estimated else "")
        else:
            what = "shapes only (no force estimate)"
        title = f"{name}: {what} of {frames} frames"
    fig.suptitle(title)
    if path is not None:
        from bendsense import output

        with output.write_file(path, overwrite=overwrite, inputs=[source], writer="bendsense plot") as tmp:
            fig.savefig(tmp, format=fmt, dpi=dpi, metadata=output.figure_metadata(fmt))
    return fig
