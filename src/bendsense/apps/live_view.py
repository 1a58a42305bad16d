"""The live view of ``bendsense live``: shape, tip force, channel levels and a scrolling force plot, blitted.

An application around the library's live core, in two halves so that the numbers can be
tested without a display:

- the model, :class:`bendsense.pipeline.LiveProcessor`: every frame received, in
  blocks, → shapes (paper eq. 1–7) and warm-started tip forces (eq. 18 and 21);
- the view, :class:`LiveView`: the shape with the force arrow, the channel levels, and
  Fx, Fy with their ±2σ bands and the pressure over the last seconds (when the
  processor tracks the force, the tracked Fx, Fy with their ±2σ bands over the
  per-frame forces drawn as points, and the arrow shows the tracked force); matplotlib
  artists updated in place and redrawn with blitting (``copy_from_bbox`` /
  ``restore_region`` / ``draw_artist`` / ``blit``), so a frame costs a few artists, not
  a full figure draw. The status line shows the estimation rate, the backlog and the
  counts of frames per status (extrapolated, not converged, misfit). A contact load
  (``--load contact --contact-s-m X``) draws the contact point on the shape with its ±2σ
  arc along the body, the arrow from it, and s_c in the force text.

:func:`run_live` ties them to a :class:`~bendsense.device.driver.Driver`: it takes every
reading from the driver's queue, processes what arrived as one block (and publishes it on
LSL if asked), draws the newest frame at most ``max_fps`` times a second, and measures
the end-to-end latency per drawn frame (bytes read by the driver → shape and force →
artists drawn) and the rates.

A gripper (:class:`~bendsense.pipeline.gripper.GripperProcessor`) is shown by
:class:`GripperView`: one :class:`LiveView` per finger, each in its own panel (a
matplotlib subfigure) of one figure, the finger's name over its shape and its own status
line;
:func:`run_live` takes either processor.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from bendsense.pipeline import LiveFrame, LiveProcessor
from bendsense.results import flagged_counts
from bendsense.status import Status

__all__ = ["LiveView", "GripperView", "LiveStats", "run_live", "status_line"]

MM = 1e3
_BLUE = (0.122, 0.467, 0.706, 1.0)  # matplotlib's C0 and C3
_RED = (0.839, 0.153, 0.157, 1.0)


# --------------------------------------------------------------------------- view


class LiveView:
    """The live figure: shape with the tip-force arrow, and a bar chart of the channels.

    Parameters
    ----------
    processor : LiveProcessor
        Gives the geometry (sensor length) and the calibrated signal range.
    figure : matplotlib.figure.Figure, optional
        Draw into this figure; default a new one (through pyplot when ``headless`` is
        false, so that it gets a window).
    headless : bool
        A figure on the Agg canvas without pyplot (no window; for ``--save``).
    scale_m_per_n : float
        Arrow length per newton of force [m/N].
    text_interval_s : float
        Shortest time between redraws of the texts [s]; in between, their last pixels
        are restored (numbers changing faster cannot be read anyway, and glyph
        rendering is the most expensive part of a frame).
    window_s : float
        Time shown by the scrolling force and pressure plot [s].
    force_range_n, pressure_range_kpa : float
        Initial limits of the force [N] (symmetric) and pressure [kPa] axes; they grow
        (with one full redraw) when the data leave them.
    max_points : int
        Most points drawn per curve (the history is thinned to this).
    """

    def __init__(
        self,
        processor: LiveProcessor,
        figure=None,
        *,
        headless=False,
        scale_m_per_n=0.2,
        text_interval_s=0.1,
        window_s=10.0,
        force_range_n=0.3,
        pressure_range_kpa=120.0,
        max_points=1500,
    ):
        self.processor = processor
        self.window_s = float(window_s)
        self.force_range_n = float(force_range_n)
        self.pressure_range_kpa = float(pressure_range_kpa)
        self.max_points = int(max_points)
        self._history = []  # blocks of (t_s, fx, fy, sx, sy, p_kpa, tracked fx, fy, sx, sy), oldest first
        self.tracked = bool(getattr(processor, "track", False))
        self.contact = getattr(processor, "options", {}).get("load") == "contact"
        self.scale_m_per_n = float(scale_m_per_n)
        self.text_interval_s = float(text_interval_s)
        self._text_regions = {}
        self._next_text = 0.0
        if figure is None:
            if headless:
                from matplotlib.backends.backend_agg import FigureCanvasAgg
                from matplotlib.figure import Figure

                figure = Figure(figsize=(12, 7))
                FigureCanvasAgg(figure)
            else:
                import matplotlib.pyplot as plt

                figure = plt.figure(figsize=(12, 7))
        self.figure = figure
        self._build()
        self._background = None
        self.canvas.mpl_connect("draw_event", self._on_draw)

    @property
    def canvas(self):
        """The figure's canvas."""
        return self.figure.canvas

    def _build(self) -> None:
        from matplotlib.collections import PolyCollection
        from matplotlib.patches import FancyArrowPatch

        fig = self.figure
        cal = self.processor.calibration
        length = self.processor.config.sensor.length_m * MM
        grid = fig.add_gridspec(2, 2, width_ratios=(1, 1.35), height_ratios=(1, 1), left=0.06, right=0.93,
                                bottom=0.08, top=0.9, wspace=0.22, hspace=0.42)
        ax = self.ax_shape = fig.add_subplot(grid[:, 0])
        ax.set_xlim(-0.45 * length, 1.05 * length)
        ax.set_ylim(-0.3 * length, 1.1 * length)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.grid(True, alpha=0.3)
        ax.plot([0.0], [0.0], "ks", markersize=7, label="base")
        ax.set_title("shape and contact force (base frame)" if self.contact else "shape and tip force (base frame)",
                     fontsize="medium")
        (self.shape_line,) = ax.plot(
            [], [], "-", color="C0", linewidth=2.5, label="reconstructed shape (dashed: extrapolated)", animated=True
        )
        (self.tip_marker,) = ax.plot([], [], "o", color="C0", markersize=6, animated=True)
        self.arrow = FancyArrowPatch(
            (0, 0), (0, 0), arrowstyle="-|>", mutation_scale=18, color="C3", linewidth=2, animated=True
        )
        ax.add_patch(self.arrow)
        what = "contact force" if self.contact else "tip force"
        ax.plot([], [], "-", color="C3", linewidth=2, label=f"{what} ({self.scale_m_per_n * MM:g} mm per N)")
        # the contact point and its ±2σ arc along the body (a contact load only; empty otherwise)
        (self.contact_arc,) = ax.plot([], [], "-", color="C1", linewidth=7, alpha=0.35, solid_capstyle="butt",
                                      animated=True)
        (self.contact_marker,) = ax.plot([], [], "D", color="C1", markeredgecolor="k", markersize=7, animated=True,
                                         label="contact ± 2σ along the body" if self.contact else None)
        ax.legend(loc="lower right", fontsize="small")
        self.force_text = ax.text(
            0.02,
            0.98,
            "",
            transform=ax.transAxes,
            va="top",
            ha="left",
            family="monospace",
            fontsize="small",
            animated=True,
        )

        # channel levels: ΔA per channel over the calibrated range of its parity
        bx = self.ax_bars = fig.add_subplot(grid[0, 1])
        n = cal.n_channels
        x = np.arange(1, n + 1)
        odd = (x % 2) == 1
        lo = np.where(odd, cal.delta_a_range_odd[0], cal.delta_a_range_even[0])
        hi = np.where(odd, cal.delta_a_range_odd[1], cal.delta_a_range_even[1])
        self._range = (lo, hi)
        bx.bar(x, hi - lo, bottom=lo, width=0.85, color="0.88", edgecolor="0.7", label="calibrated range")
        # one collection for all channels: one draw call per frame instead of N patches
        self._bar_x = x.astype(float)
        self.bars = PolyCollection(self._bar_verts(np.zeros(n)), facecolors="C0", linewidths=0, animated=True)
        bx.add_collection(self.bars, autolim=False)
        self._bar_outside = np.zeros(n, dtype=bool)
        bx.bar([np.nan], [np.nan], color="C0", label="ΔA in range")
        bx.bar([np.nan], [np.nan], color="C3", label="ΔA outside (extrapolated)")
        span = float(np.max(hi) - np.min(lo)) or 1.0
        bx.set_ylim(float(np.min(lo)) - 0.15 * span, float(np.max(hi)) + 0.3 * span)
        bx.set_xlim(0.3, n + 0.7)
        bx.set_xticks(x[:: max(1, n // 16)])
        bx.axhline(0.0, color="k", linewidth=0.6)
        bx.set_xlabel("channel i")
        bx.set_ylabel("signal ΔA = A − A0 [counts]")
        bx.set_title("channel levels", fontsize="medium")
        bx.legend(loc="upper left", fontsize="small", ncols=3)
        bx.grid(True, axis="y", alpha=0.3)
        self._build_series(grid[1, 1])
        self.status_text = fig.text(0.5, 0.975, "", ha="center", va="top", fontsize="medium", animated=True)
        self.texts = [self.force_text, self.status_text]
        self.artists = [*self.texts, self.bars, self.shape_line, self.contact_arc, self.tip_marker, self.contact_marker,
                        self.arrow, *self.series_artists]

    def _build_series(self, cell) -> None:
        """Fx, Fy with their ±2σ bands and the pressure over the last ``window_s`` (now at 0)."""
        from matplotlib.collections import PolyCollection

        fig = self.figure
        tx = self.ax_series = fig.add_subplot(cell)
        tx.set_xlim(-self.window_s, 0.0)
        tx.set_ylim(-self.force_range_n, self.force_range_n)
        tx.set_xlabel("time [s] (0 = newest frame)")
        tx.set_ylabel("tip force [N]")
        tx.set_title("tracked force (±2σ band) over the per-frame points, and pressure" if self.tracked
                     else "force (±2σ band) and pressure", fontsize="medium")
        tx.axhline(0.0, color="k", linewidth=0.6)
        tx.grid(True, alpha=0.3)
        px = self.ax_pressure = tx.twinx()
        px.set_ylim(0.0, self.pressure_range_kpa)
        px.set_ylabel("pressure [kPa]", color="0.35")
        px.tick_params(axis="y", colors="0.35")
        self.bands = []  # of the tracked force when tracked, else of the per-frame one
        self.force_lines = []  # the per-frame forces: points under a track, else lines
        self.track_lines = []
        for color, label in (("C0", "Fx"), ("C3", "Fy")):
            band = PolyCollection([np.zeros((0, 2))], facecolors=color, alpha=0.2, linewidths=0, animated=True)
            tx.add_collection(band, autolim=False)
            style = dict(linestyle="none", marker=".", markersize=2.5, alpha=0.5) if self.tracked else {}
            (line,) = tx.plot([], [], color=color, linewidth=1.4, animated=True, **style,
                              label=label + (" per frame" if self.tracked else ""))
            self.bands.append(band)
            self.force_lines.append(line)
            if self.tracked:
                (tline,) = tx.plot([], [], "-", color=color, linewidth=1.6, label=f"{label} tracked", animated=True)
                self.track_lines.append(tline)
        (self.pressure_line,) = px.plot([], [], "-", color="0.45", linewidth=1.0, label="pressure", animated=True)
        tx.fill_between([], [], [], color="0.6", alpha=0.3, label="±2σ")
        handles = [*tx.get_legend_handles_labels()[0], self.pressure_line]
        tx.legend(handles=handles, loc="upper left", fontsize="small", ncols=4, markerscale=3)
        self.series_artists = [*self.bands, *self.force_lines, *self.track_lines, self.pressure_line]

    def _bar_verts(self, values, half_width=0.25):
        x = self._bar_x[:, None]
        v = np.asarray(values, dtype=float)[:, None]
        xs = np.hstack([x - half_width, x + half_width, x + half_width, x - half_width])
        ys = np.hstack([np.zeros_like(v), np.zeros_like(v), v, v])
        return np.stack([xs, ys], axis=-1)

    @property
    def bar_heights(self) -> np.ndarray:
        """The displayed ΔA per channel [signal units]."""
        return np.array([path.vertices[2, 1] for path in self.bars.get_paths()])

    def _on_draw(self, event) -> None:
        # a full draw (first show, resize) invalidates the saved pixels
        if event is not None and event.canvas is not self.canvas:
            return
        self._background = self.canvas.copy_from_bbox(self.figure.bbox)
        self._text_regions = {}
        self._draw_artists()

    def _draw_artists(self) -> None:
        fig, canvas = self.figure.figure, self.canvas  # the root figure draws (also a gripper's finger panel's)
        now = time.monotonic()
        refresh = now >= self._next_text or len(self._text_regions) != len(self.texts)
        # texts first: restoring their saved pixels must not cover the shape drawn later
        for text in self.texts:
            if refresh:
                fig.draw_artist(text)
                self._text_regions[text] = canvas.copy_from_bbox(text.get_window_extent().padded(2))
            else:
                canvas.restore_region(self._text_regions[text])
        if refresh:
            self._next_text = now + self.text_interval_s
        for artist in self.artists[len(self.texts) :]:
            fig.draw_artist(artist)

    def add_block(self, block) -> None:
        """Append the frames of a :class:`~bendsense.pipeline.LiveBlock` to the force and pressure history.

        Parameters
        ----------
        block : LiveBlock
            The newly processed frames.
        """
        t = np.where(np.isfinite(block.t_s), block.t_s, np.asarray(block.host_ns) * 1e-9)
        f, sd = block.force_n, block.std_n
        self._history.append(np.column_stack([t, f, sd, block.pressure_pa * 1e-3, block.track_force_n,
                                              block.track_std_n]))
        newest = t[-1]
        while len(self._history) > 1 and self._history[0][-1, 0] < newest - self.window_s:
            self._history.pop(0)

    def _set_series(self) -> None:
        """Put the history into the time-series artists; grow the axes when the data leave them."""
        if not self._history:
            return
        h = np.concatenate(self._history)
        t_now = h[-1, 0]
        h = h[h[:, 0] >= t_now - self.window_s]
        if len(h) > self.max_points:  # thin to what the pixels can show
            h = h[:: int(math.ceil(len(h) / self.max_points))]
        x = h[:, 0] - t_now
        for j, (line, band) in enumerate(zip(self.force_lines, self.bands)):
            f, sd = h[:, 1 + j], h[:, 3 + j]
            line.set_data(x, f)
            if self.tracked:  # the band is the tracked force's
                f, sd = h[:, 6 + j], h[:, 8 + j]
                self.track_lines[j].set_data(x, f)
            ok = np.isfinite(f) & np.isfinite(sd)
            lo, hi = f - 2 * sd, f + 2 * sd
            # one polygon per run of finite values (a gap where there is no estimate)
            runs = np.split(np.flatnonzero(ok), np.flatnonzero(np.diff(np.flatnonzero(ok)) > 1) + 1)
            band.set_verts([np.column_stack([np.r_[x[r], x[r][::-1]], np.r_[lo[r], hi[r][::-1]]])
                            for r in runs if r.size > 1])
        self.pressure_line.set_data(x, h[:, 5])
        # grow the limits (and redraw everything once) when the data leave them
        f = h[:, 1:3]
        f = f[np.isfinite(f)]
        top = float(np.max(np.abs(f))) if f.size else 0.0
        p = h[:, 5][np.isfinite(h[:, 5])]
        grown = False
        if top > self.force_range_n:
            self.force_range_n = 1.5 * top
            self.ax_series.set_ylim(-self.force_range_n, self.force_range_n)
            grown = True
        if p.size and p.max() > self.pressure_range_kpa:
            self.pressure_range_kpa = 1.25 * float(p.max())
            self.ax_pressure.set_ylim(0.0, self.pressure_range_kpa)
            grown = True
        if grown:
            self._background = None

    def set_frame(self, frame: LiveFrame, status: str = "") -> None:
        """Update the artists' data from a frame (no drawing).

        Parameters
        ----------
        frame : LiveFrame
            The frame to show.
        status : str, default ""
            The status line under the figure.
        """
        shape = frame.shape
        pos = np.asarray(shape.positions_m) * MM
        self.shape_line.set_data(pos[:, 0], pos[:, 1])
        self.shape_line.set_linestyle("--" if bool(np.any(shape.extrapolated)) else "-")
        tip = pos[-1]
        self.tip_marker.set_data([tip[0]], [tip[1]])
        at, contact_text = self._set_contact(frame, tip)  # where the force acts
        force, std = frame.force_n, frame.std_n
        tracked = frame.track_force_n is not None and np.all(np.isfinite(frame.track_force_n))
        if np.all(np.isfinite(force)) or tracked:
            shown = frame.track_force_n if tracked else force  # the arrow: the tracked force
            end = at + shown * self.scale_m_per_n * MM
            self.arrow.set_positions(tuple(at), tuple(end))
            self.arrow.set_visible(True)
            text = (
                f"F  = ({force[0]:+.3f}, {force[1]:+.3f}) N\n"
                f"±σ = ({std[0]:.3f}, {std[1]:.3f}) N\n"
                f"|F| = {math.hypot(*force):.3f} N"
            ) if np.all(np.isfinite(force)) else "F: no estimate of this frame"
            if tracked:
                ts = frame.track_std_n
                text += (f"\ntracked F = ({shown[0]:+.3f}, {shown[1]:+.3f}) N\n"
                         f"       ±σ = ({ts[0]:.3f}, {ts[1]:.3f}) N")
        else:
            self.arrow.set_visible(False)
            if frame.estimate is None:
                text = "F: no pressure reading" if not math.isfinite(frame.pressure_pa) else "F: not estimated"
            elif frame.estimate.status == Status.PRESSURE_OUT_OF_RANGE:
                text = "F: pressure out of range"
            else:
                text = "F: not converged"
        text += contact_text
        p = frame.pressure_pa
        text += f"\nP  = {p * 1e-3:.1f} kPa" if math.isfinite(p) else "\nP  = —"
        self.force_text.set_text(text)
        lo, hi = self._range
        da = frame.delta_a
        outside = (da < lo) | (da > hi)
        self.bars.set_verts(self._bar_verts(da))
        if not np.array_equal(outside, self._bar_outside):
            self.bars.set_facecolors(np.where(outside[:, None], _RED, _BLUE))
            self._bar_outside = outside
        self.status_text.set_text(status)

    def _set_contact(self, frame: LiveFrame, tip):
        """The contact point and its ±2σ arc of a contact load (mm); the point where the arrow starts, and a text."""
        est = frame.estimate
        s_c = float(np.asarray(est.contact_s_m)) if self.contact and est is not None else math.nan
        if not math.isfinite(s_c):
            self.contact_marker.set_data([], [])
            self.contact_arc.set_data([], [])
            return tip, ""
        from bendsense.results.contact import arc_on_shape, point_on_shape

        shape = frame.shape
        sd = float(np.asarray(est.contact_std_m))
        point = point_on_shape(shape.s_m, shape.positions_m, s_c) * MM
        arc = arc_on_shape(shape.s_m, shape.positions_m, s_c - 2 * sd, s_c + 2 * sd) * MM
        self.contact_marker.set_data([point[0]], [point[1]])
        self.contact_marker.set_markerfacecolor("C1" if math.isfinite(sd) else "none")
        self.contact_arc.set_data(arc[:, 0], arc[:, 1])
        spread = "known" if sd == 0 else (f"± {sd * MM:.1f} mm" if math.isfinite(sd) else "unresolved")
        return point, f"\ns_c = {s_c * MM:.1f} mm ({spread})"

    def update(self, frame: LiveFrame, status: str = "") -> None:
        """Show a frame: update the artists and blit them over the saved background.

        Parameters
        ----------
        frame : LiveFrame
            The frame to show.
        status : str, default ""
            The status line under the figure.
        """
        self.set_frame(frame, status)
        self._set_series()
        canvas = self.canvas
        if self._background is None:
            canvas.draw()  # the draw_event handler saves the background and draws the artists
        else:
            canvas.restore_region(self._background)
            self._draw_artists()
        canvas.blit(self.figure.bbox)
        canvas.flush_events()

    def update_block(self, block, status: str = "") -> None:
        """Add a block's frames to the history and show its newest frame.

        Parameters
        ----------
        block : LiveBlock
            The newly processed frames.
        status : str, default ""
            The status line under the figure.
        """
        self.add_block(block)
        self.update(block.frame(-1), status)

    def save(self, path, dpi: int = 120, overwrite: bool = True) -> None:
        """Write the figure with the current frame (atomically; :func:`bendsense.output.write_file`).

        Parameters
        ----------
        path : path
            Figure file; its suffix gives the format.
        dpi : int, default 120
            Resolution of a raster figure [dots per inch].
        overwrite : bool, default True
            Replace an existing figure bendsense wrote.
        """
        _save(self.figure, [self], path, dpi, overwrite)


def _save(figure, views, path, dpi, overwrite) -> None:
    """Write ``figure`` with the current frame of its ``views`` (atomically; :func:`bendsense.output.write_file`)."""
    from pathlib import Path

    from bendsense import output

    path = Path(path)
    fmt = path.suffix[1:].lower() or "png"
    artists = [a for view in views for a in view.artists]
    for artist in artists:  # animated artists are left out of a normal draw; show them for the file
        artist.set_animated(False)
    try:
        with output.write_file(path, overwrite=overwrite, writer="bendsense live") as tmp:
            figure.savefig(tmp, format=fmt, dpi=dpi, metadata=output.figure_metadata(fmt))
    finally:
        for artist in artists:
            artist.set_animated(True)
        for view in views:
            view._background = None


class GripperView:
    """The live figure of a gripper: a :class:`LiveView` panel per finger, stacked in one figure.

    Parameters
    ----------
    processor : GripperProcessor
        Gives the fingers and each finger's processor.
    figure : matplotlib.figure.Figure, optional
        Draw into this figure; default a new one (through pyplot unless ``headless``).
    headless : bool
        A figure on the Agg canvas without pyplot (no window; for ``--save``).
    **options
        Options of each finger's :class:`LiveView` (``scale_m_per_n``, ``window_s``, ...);
        ``text_interval_s`` defaults to 0.1 s per finger (the texts' glyphs are the
        expensive part of a redraw: three panels redrawn at ~45 fps, not ~15).

    Attributes
    ----------
    views : dict of str to LiveView
        Each finger's panel.
    """

    def __init__(self, processor, figure=None, *, headless=False, **options):
        k = len(processor.fingers)
        options.setdefault("text_interval_s", 0.1 * k)
        if figure is None:
            size = (12, 5.4 * k)
            if headless:
                from matplotlib.backends.backend_agg import FigureCanvasAgg
                from matplotlib.figure import Figure

                figure = Figure(figsize=size)
                FigureCanvasAgg(figure)
            else:
                import matplotlib.pyplot as plt

                figure = plt.figure(figsize=size)
        self.figure = figure
        panels = figure.subfigures(k, 1, squeeze=False)[:, 0]
        self.views = {name: LiveView(processor.processors[name], panel, **options)
                      for name, panel in zip(processor.fingers, panels)}
        for name, view in self.views.items():  # the finger's name over its shape
            view.ax_shape.set_title(f"{name}: {view.ax_shape.get_title()}", fontsize="medium", fontweight="bold")

    @property
    def canvas(self):
        """The figure's canvas."""
        return self.figure.canvas

    def add_block(self, blocks) -> None:
        """Append each finger's frames to its panel's history.

        Parameters
        ----------
        blocks : dict of str to LiveBlock
            The newly processed frames per finger.
        """
        for name, block in blocks.items():
            self.views[name].add_block(block)

    def update(self, frames, status=None) -> None:
        """Show each finger's frame in its panel.

        Parameters
        ----------
        frames : dict of str to LiveFrame
            The frame to show per finger.
        status : dict of str to str, optional
            Each panel's status line.
        """
        for name, frame in frames.items():
            self.views[name].update(frame, (status or {}).get(name, name))

    def save(self, path, dpi: int = 120, overwrite: bool = True) -> None:
        """Write the figure with every finger's current frame (atomically; :func:`bendsense.output.write_file`).

        Parameters
        ----------
        path : path
            Figure file; its suffix gives the format.
        dpi : int, default 120
            Resolution of a raster figure [dots per inch].
        overwrite : bool, default True
            Replace an existing figure bendsense wrote.
        """
        _save(self.figure, list(self.views.values()), path, dpi, overwrite)


# --------------------------------------------------------------------------- loop


@dataclass(frozen=True)
class LiveStats:
    """What a live run did and how fast.

    Attributes
    ----------
    frames : int
        Frames displayed (redraws).
    received : int
        Samples the driver received meanwhile.
    estimated : int
        Frames processed (shape and force): every frame received, in blocks.
    failures : int
        Force estimates that did not converge.
    elapsed_s : float
        Wall time of the loop [s].
    fps : float
        Displayed frames per second [1/s].
    latency_ms : tuple of float
        End-to-end latency per displayed frame, median and 95th percentile [ms]: bytes
        read by the driver → shape and force → artists drawn.
    process_ms : float
        Median reconstruction + estimation time per frame [ms].
    draw_ms : float
        Median time to update and blit the artists per frame [ms].
    """

    frames: int
    received: int
    failures: int
    elapsed_s: float
    fps: float
    latency_ms: tuple
    process_ms: float
    draw_ms: float
    estimated: int = 0
    estimate_hz: float = math.nan

    def summary(self) -> str:
        """One line for the terminal."""
        rate = self.estimate_hz
        return (
            f"{self.frames} frames shown ({self.received} received) in {self.elapsed_s:.1f} s: "
            f"{self.fps:.1f} fps, latency median {self.latency_ms[0]:.1f} ms (p95 {self.latency_ms[1]:.1f} ms), "
            f"process {self.process_ms:.2f} ms, draw {self.draw_ms:.2f} ms per frame; "
            f"{self.estimated} frames estimated ({rate:.0f}/s)"
            + (f", {self.failures} estimates not converged" if self.failures else "")
        )


def status_line(block, processor, rate_hz: float, fps: float, lost: int, backlog: int = 0) -> str:
    """The status line of the live view: frame, rates, backlog and the counts per status.

    Parameters
    ----------
    block : LiveFrame
        The latest processed block of frames.
    processor : LiveProcessor
        The processor, for its status counts.
    rate_hz : float
        Frames estimated per second [Hz].
    fps : float
        Figure updates per second [Hz].
    lost : int
        Frames lost on the wire so far.
    backlog : int, default 0
        Frames received and not yet processed.
    """
    return (
        f"seq {int(block.seq[-1])}   estimated {rate_hz:.0f} frames/s   {fps:.0f} fps   backlog {backlog}   "
        f"lost {lost}   {flagged_counts(processor.status_counts, '   ')}"
    )


def run_live(
    driver,
    processor,
    view=None,
    *,
    duration_s=None,
    max_fps=60.0,
    is_open=None,
    on_frame=None,
    outlets=None,
    max_block=512,
) -> LiveStats:
    """Process every reading of ``driver`` in blocks and show the newest, until ``duration_s`` or the view closes.

    Parameters
    ----------
    driver : Driver
        An open, streaming driver with a queue (:meth:`~bendsense.device.driver.Driver.get_batch`).
    processor : LiveProcessor or GripperProcessor
        The model (a gripper's: a block per finger).
    view : LiveView or GripperView, optional
        None: process only (for benchmarks of the model alone).
    duration_s : float, optional
        Run time [s]; None: until ``is_open()`` turns false.
    max_fps : float
        Upper bound of the display rate [1/s]; frames arriving in between are processed
        (and published) but only the newest is drawn. A :class:`GripperView` of k
        panels is redrawn at most ``max_fps / k`` times a second (a redraw costs k
        panels' artists; the processing of every frame comes first).
    is_open : callable, optional
        Returns False when the window was closed.
    on_frame : callable, optional
        Called with the newest :class:`LiveFrame` after each redraw (a gripper: a dict
        of the fingers' newest frames).
    outlets : LslOutlets or GripperOutlets, optional
        Publish every processed block on LSL.
    max_block : int
        Most frames processed in one block.

    Returns
    -------
    LiveStats

    Raises
    ------
    DeviceError
        If the device fails (from ``driver.error``).
    """
    from bendsense.errors import DeviceError

    min_period = 1.0 / max_fps if max_fps else 0.0
    if isinstance(view, GripperView):  # k panels per redraw: at most max_fps / k redraws, to keep up with the board
        min_period *= len(view.views)
    latencies, process, draw = [], [], []
    samples0 = driver.stats.samples
    frames0 = processor.frames
    recent = []  # (monotonic time, frames) of the last second
    start = time.monotonic()
    end = None if duration_s is None else start + duration_s
    next_draw = start
    pending = None  # newest block not drawn yet
    while True:
        now = time.monotonic()
        if end is not None and now >= end:
            break
        if is_open is not None and not is_open():
            break
        if driver.error is not None:
            raise DeviceError(driver.error)
        readings = driver.get_batch(timeout=0.005, max_items=max_block)
        if readings:
            block = processor.process_readings(readings)  # a gripper's: a block per finger
            if outlets is not None:
                outlets.push(block)
            parts = list(block.values()) if isinstance(block, dict) else [block]
            process.append(sum(b.process_s for b in parts) / len(readings))
            recent.append((time.monotonic(), len(readings)))
            if view is not None:
                view.add_block(block)
            pending = block
        elif view is not None:
            view.canvas.flush_events()
        if pending is None or time.monotonic() < next_draw:
            continue
        t_draw = time.perf_counter()
        frame = pending.frame(-1) if not isinstance(pending, dict) else {k: b.frame(-1) for k, b in pending.items()}
        if view is not None:
            t_now = time.monotonic()
            recent = [(t, n) for t, n in recent if t >= t_now - 1.0]
            fps = len(latencies) / (t_now - start) if t_now > start else 0.0
            view.update(frame, _status(pending, processor, sum(n for _, n in recent), fps, driver))
        done_ns = time.monotonic_ns()
        draw.append(time.perf_counter() - t_draw)
        newest = frame if not isinstance(frame, dict) else next(iter(frame.values()))
        latencies.append((done_ns - newest.host_ns) * 1e-6)
        if on_frame is not None:
            on_frame(frame)
        pending = None
        next_draw = time.monotonic() + min_period
    return _stats(time.monotonic() - start, latencies, process, draw, driver.stats.samples - samples0,
                  processor.frames - frames0, processor.failures)


def _status(pending, processor, rate_hz, fps, driver):
    """The status line of the view; a gripper's: one per finger panel, with the finger's own counts."""
    lost, backlog = driver.stats.lost, driver.queued
    if isinstance(pending, dict):
        return {k: status_line(b, processor.processors[k], rate_hz, fps, lost, backlog) for k, b in pending.items()}
    return status_line(pending, processor, rate_hz, fps, lost, backlog)


def _stats(elapsed, latencies, process, draw, received, estimated, failures) -> LiveStats:
    """:class:`LiveStats` from the times a run measured per frame [s] (latencies [ms])."""
    n = len(latencies)
    lat = (float(np.median(latencies)), float(np.percentile(latencies, 95))) if n else (math.nan, math.nan)
    return LiveStats(
        frames=n,
        received=received,
        failures=failures,
        elapsed_s=elapsed,
        fps=n / elapsed if elapsed > 0 else 0.0,
        latency_ms=lat,
        process_ms=float(np.median(process)) * 1e3 if process else math.nan,
        draw_ms=float(np.median(draw)) * 1e3 if n else math.nan,
        estimated=estimated,
        estimate_hz=estimated / elapsed if elapsed > 0 else 0.0,
    )
