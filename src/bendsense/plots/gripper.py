"""The summary figure of a gripper: a panel per finger and the grasp over time.

Each finger's column shows its shapes with the tip path (above) and its force over time
with the ±2σ band (below), drawn as the single-actuator summary draws them
(:func:`bendsense.plots.plot_shapes`); the bottom row is the grasp: the total force
(the sum of the fingers' force magnitudes, each in its own base frame) with each
finger's, and each finger's contact location over time.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from bendsense.plots import MM, _colors, _force_panel, plot_shapes

__all__ = ["plot_gripper", "grasp_force"]


def grasp_force(results) -> tuple:
    """A finger's force magnitude |F| and its σ per frame (tracked where the results hold a track) [N].

    Parameters
    ----------
    results : Results
        One finger's results (with forces).

    Returns
    -------
    magnitude, std : ndarray, shape (frames,)
        |F| and σ_|F| = sqrt(Σ (F_k σ_k)²) / |F| (the components' σ, uncorrelated).
    """
    key = "_track" if results.has_track else ""
    f = np.column_stack([results[f"fx{key}_n"], results[f"fy{key}_n"]]).astype(float)
    s = np.column_stack([results[f"fx{key}_std_n"], results[f"fy{key}_std_n"]]).astype(float)
    magnitude = np.hypot(f[:, 0], f[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.sqrt(np.sum((f * s) ** 2, axis=1)) / magnitude
    return magnitude, np.where(magnitude > 0, std, np.hypot(s[:, 0], s[:, 1]))


def _finger_column(fig, grid, col, name, results, max_shapes):
    ax_s = fig.add_subplot(grid[0, col])
    tip = np.column_stack([results["tip_x_m"], results["tip_y_m"]]).astype(float) * MM
    ax_s.plot(tip[:, 0], tip[:, 1], color="0.6", linewidth=0.8, zorder=0)
    plot_shapes(results, ax_s, max_frames=max_shapes, legend=False)
    ax_s.set_title(name, fontsize="medium")
    ax_f = fig.add_subplot(grid[1, col])
    t = np.asarray(results["t_s"], dtype=float)
    if results.has_forces:
        force = np.column_stack([results["fx_n"], results["fy_n"]]).astype(float)
        std = np.column_stack([results["fx_std_n"], results["fy_std_n"]]).astype(float)
        tracked = None
        if results.has_track:
            tracked = (np.column_stack([results["fx_track_n"], results["fy_track_n"]]).astype(float),
                       np.column_stack([results["fx_track_std_n"], results["fy_track_std_n"]]).astype(float))
        _force_panel(ax_f, t, force, std, status=np.asarray(results["status"]), tracked=tracked,
                     contact="contact_s_m" in results.columns)
        if col:  # the first finger's legend tells them all
            ax_f.get_legend().remove()
    else:
        ax_f.text(0.5, 0.5, "no force estimate", ha="center", va="center", transform=ax_f.transAxes)
    ax_f.set_xlabel("t [s]")
    return ax_f


def _grasp_panels(fig, grid, results: dict, lengths_m: dict):
    half = (max(len(results), 2) + 1) // 2
    ax_g = fig.add_subplot(grid[2, :half])
    ax_c = fig.add_subplot(grid[2, half:])
    colors = _colors(len(results), "tab10")
    total, total_var, located = None, None, False
    for color, (name, r) in zip(colors, results.items(), strict=True):
        t = np.asarray(r["t_s"], dtype=float)
        if r.has_forces:
            magnitude, std = grasp_force(r)
            ax_g.plot(t, magnitude, color=color, linewidth=1.0, label=f"{name} |F|")
            total = magnitude if total is None else total + magnitude
            total_var = std**2 if total_var is None else total_var + std**2
        if r.has_contact:
            s_c, s_std = (np.asarray(r[k], dtype=float) for k in ("contact_s_m", "contact_std_m"))
            shown = np.where(np.isfinite(s_std), s_c, np.nan) * MM  # an unresolved location is no measurement
            located |= bool(np.isfinite(shown).any())
            ax_c.plot(t, shown, color=color, label=f"{name} s_c")
            ax_c.fill_between(t, shown - 2 * s_std * MM, shown + 2 * s_std * MM, color=color, alpha=0.2, linewidth=0)
        else:  # a tip load: the contact is the tip
            located = True
            length = lengths_m.get(name, float(r.s_m[-1]))
            ax_c.plot(t, np.full(t.shape, length * MM), color=color, linestyle=":", label=f"{name} (tip load)")
    ax_c.set_xlim(float(t[0]), float(t[-1]) if t[-1] > t[0] else float(t[0]) + 1.0)
    if not located:
        ax_c.text(0.5, 0.5, "no contact located", ha="center", va="center", transform=ax_c.transAxes)
    if total is not None:
        band = np.where(np.isfinite(total_var), 2 * np.sqrt(total_var), np.nan)
        ax_g.plot(t, total, color="k", linewidth=1.6, label="total")
        # a sum of magnitudes is never below 0: its band stops there (it reached -0.3 N for a barely held grasp)
        ax_g.fill_between(t, np.maximum(total - band, 0.0), total + band, color="k", alpha=0.15, linewidth=0,
                          label="total ± 2σ")
        values, bands = total[np.isfinite(total)], band[np.isfinite(band)]
        if values.size:  # the forces set the limits: a band far wider than them (a barely determined frame) is cut
            pad = max(0.1 * float(np.ptp(values)), float(np.median(bands)) if bands.size else 0.0, 1e-3)
            ax_g.set_ylim(min(0.0, float(values.min())) - pad, float(values.max()) + pad)
    else:
        ax_g.text(0.5, 0.5, "no force estimate", ha="center", va="center", transform=ax_g.transAxes)
    ax_g.set_title("grasp: force of each finger and total (sum of |F|)", fontsize="medium", loc="left")
    ax_g.set_xlabel("t [s]")
    ax_g.set_ylabel("force [N]")
    ax_c.set_title("contact location along each finger", fontsize="medium", loc="left")
    ax_c.set_xlabel("t [s]")
    ax_c.set_ylabel("s_c [mm]")
    for ax in (ax_g, ax_c):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small", ncols=2, loc="best")


def plot_gripper(results, path=None, *, max_shapes: int = 6, dpi: int = 150, title: str | None = None,
                 overwrite: bool = True, lengths_m=None, inputs=()):
    """Summary figure of a gripper: a column per finger (shapes, force) and the grasp (total force, contacts).

    Parameters
    ----------
    results : dict or path
        ``{finger name: Results}`` in the gripper's order, or a gripper's results
        directory (``OUT/<finger>/results.csv``: :func:`bendsense.results.gripper.read_gripper_results`).
    path : path, optional
        Write the figure there (format from the suffix), atomically.
    max_shapes : int
        Frames whose shape is drawn per finger.
    dpi : int
        Resolution of raster formats.
    title : str, optional
        Figure title; default the fingers and the frame count.
    overwrite : bool
        Replace an existing file at ``path``.
    lengths_m : dict, optional
        Each finger's actuator length L [m], where a tip load acts; default its sensor's end.
    inputs : iterable of paths
        Inputs never to be written over.

    Returns
    -------
    matplotlib.figure.Figure
    """
    source = results if isinstance(results, (str, os.PathLike)) else None
    if source is not None:
        from bendsense.results.gripper import read_gripper_results

        results = read_gripper_results(source)
    k = len(results)
    size = (max(4.2 * k, 9.0), 10.0)
    if path is not None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=size, layout="constrained")
    else:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=size, layout="constrained")
    grid = fig.add_gridspec(3, max(k, 2), height_ratios=(1.2, 0.9, 0.9))
    for col, (name, r) in enumerate(results.items()):
        _finger_column(fig, grid, col, name, r, max_shapes)
    _grasp_panels(fig, grid, results, dict(lengths_m or {}))
    frames = len(next(iter(results.values()))["t_s"])
    if title is None:
        name = Path(source).name + ": " if source is not None else ""
        title = f"{name}gripper of {k} finger{'s' if k != 1 else ''} ({', '.join(results)}), {frames} frames"
    fig.suptitle(title)
    if path is not None:
        from bendsense import output

        path = Path(path)
        fmt = path.suffix[1:].lower() or "png"
        with output.write_file(path, overwrite=overwrite, inputs=[*([source] if source else []), *inputs],
                               writer="bendsense plot") as tmp:
            fig.savefig(tmp, format=fmt, dpi=dpi, metadata=output.figure_metadata(fmt))
    return fig
