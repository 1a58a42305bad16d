"""Live view of the sensor: shape, tip force and channel levels, redrawn by blitting.

Two halves, so that the numbers can be tested without a display:

- the model, :class:`LiveProcessor`: one :class:`~bendsense.device.driver.Reading` →
  :class:`LiveFrame` (signals → calibration → PCC shape, paper eq. 1–7; shape and
  pressure → tip force, eq. 18 and 21). Every frame's force estimate is warm-started
  from the previous frame's force and beam state, which is what makes it fast enough
  for every displayed frame;
- the view, :class:`LiveView`: matplotlib artists updated in place and redrawn with
  blitting (``copy_from_bbox`` / ``restore_region`` / ``draw_artist`` / ``blit``), so a
  frame costs a few artists, not a full figure draw.

:func:`run_live` ties them to a :class:`~bendsense.device.driver.Driver`: it takes the
newest reading (:meth:`Driver.latest`, lossy: a slow display skips frames, it never
lags behind), processes and draws it, and measures the end-to-end latency per frame
(bytes read by the driver → shape and force → artists drawn) and the frame rate.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ConfigError

__all__ = ["LiveFrame", "LiveProcessor", "LiveView", "LiveStats", "run_live", "LIVE_MAX_ITER"]

MM = 1e3
_BLUE = (0.122, 0.467, 0.706, 1.0)  # matplotlib's C0 and C3
_RED = (0.839, 0.153, 0.157, 1.0)
#: Iteration limit of a live force estimate. A warm-started frame converges in a few
#: iterations; one that cannot (an unconstrained axial force on the straight actuator
#: does not change its shape) must not stall the display for 100 beam solves.
LIVE_MAX_ITER = 20


# --------------------------------------------------------------------------- model


@dataclass(frozen=True, eq=False)
class LiveFrame:
    """One processed frame.

    Attributes
    ----------
    seq : int
        Device sequence number (raw, wraps at 65536); -1 if unknown.
    t_s : float
        Device clock [s].
    host_ns : int
        Host clock when the frame's bytes were read (``time.monotonic_ns()``) [ns].
    pressure_pa : float
        Pressure [Pa]; NaN without a reading (no force estimate then).
    delta_a : ndarray, shape (N,)
        Offset-free signals ΔA = A − A0 (paper eq. 1) [signal units].
    shape : Shape
        Reconstructed shape of the frame (single frame, no batch axis).
    estimate : ForceEstimate or None
        Tip force of the frame; None without pressure or with estimation off.
    process_s : float
        Wall time of reconstruction and estimation [s].
    """

    seq: int
    t_s: float
    host_ns: int
    pressure_pa: float
    delta_a: np.ndarray
    shape: object
    estimate: object
    process_s: float

    @property
    def force_n(self) -> np.ndarray:
        """Tip force (Fx, Fy) [N]; NaN when not estimated or not converged."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.force_n, dtype=float)

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviation of (Fx, Fy) [N]; NaN when not estimated."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.std_n, dtype=float)


class LiveProcessor:
    """Turn readings into shapes and tip forces, one frame at a time, warm-started.

    Parameters
    ----------
    calibration : Calibration
        Signal → shift calibration (paper eq. 1–2).
    config : Config, optional
        Sensor, actuator and estimation options; default the paper's prototype.
    constraint : str, optional
        Force constraint (:data:`bendsense.estimation.CONSTRAINTS`); default
        ``config.estimation.constraint``.
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa]; without it such frames get a
        shape only.
    n_points : int
        Points of the displayed shape along the sensor.
    estimate : bool
        Estimate the force (False: shapes only).
    **options
        Further options of :func:`bendsense.estimation.estimate_force` (``push_only``,
        ``tip_angle_source``, ...). ``max_iter`` defaults to :data:`LIVE_MAX_ITER`.

    Attributes
    ----------
    frames : int
        Frames processed.
    failures : int
        Frames whose force estimate did not converge.
    """

    def __init__(
        self, calibration, config=None, *, constraint=None, pressure_pa=None, n_points=41, estimate=True, **options
    ):
        from bendsense.config import load_config

        self.config = load_config() if config is None else config
        sensor = self.config.sensor
        if calibration.n_channels != sensor.n_segments:
            raise ConfigError(
                f"calibration.n_channels: expected {sensor.n_segments} (sensor.n_segments), "
                f"got {calibration.n_channels}"
            )
        self.calibration = calibration
        self.constraint = self.config.estimation.constraint if constraint is None else constraint
        self.pressure_pa = None if pressure_pa is None else float(pressure_pa)
        self.s_m = np.linspace(0.0, sensor.length_m, int(n_points))
        self.estimate = bool(estimate)
        self.options = {"max_iter": LIVE_MAX_ITER, **options}
        self.frames = 0
        self.failures = 0
        self.estimated = 0
        self._previous = None

    def reset(self) -> None:
        """Forget the warm start (e.g. after a reconnect)."""
        self._previous = None

    def process_signals(self, signals, pressure_pa=None, *, seq=-1, t_s=math.nan, host_ns=None) -> LiveFrame:
        """Process one frame given as raw signals A (N,) and the pressure [Pa]."""
        from bendsense.estimation import estimate_force
        from bendsense.pcc import reconstruct

        t0 = time.perf_counter()
        host_ns = time.monotonic_ns() if host_ns is None else host_ns
        a = np.asarray(signals, dtype=float)
        shape = reconstruct(a, self.calibration, self.config.sensor, s_m=self.s_m)
        p = self.pressure_pa if pressure_pa is None or not math.isfinite(pressure_pa) else float(pressure_pa)
        est = None
        if self.estimate and p is not None:
            prev = self._previous
            # a failed frame has NaN forces: it cannot seed the next one
            warm = {"initial": prev} if prev is not None and bool(prev.success) else {}
            est = estimate_force(
                shape, p, self.config, constraint=self.constraint, calibration=self.calibration, **warm, **self.options
            )
            self._previous = est
            self.estimated += 1
            if not bool(est.success):
                self.failures += 1
        self.frames += 1
        return LiveFrame(
            seq=int(seq),
            t_s=float(t_s),
            host_ns=int(host_ns),
            pressure_pa=math.nan if p is None else p,
            delta_a=a - self.calibration.offset,
            shape=shape,
            estimate=est,
            process_s=time.perf_counter() - t0,
        )

    def process_many(self, readings) -> LiveFrame:
        """Estimate every reading of a list in one batched call; the newest as a :class:`LiveFrame`.

        Frames along the list are warm-started from each other and the first from the
        previous estimate, so that the force is estimated at the sensor's rate however
        often the view is drawn.
        """
        from bendsense.estimation import estimate_force
        from bendsense.pcc import reconstruct

        ps = [r.sample.pressure_pa for r in readings]
        ps = [self.pressure_pa if p is None or not math.isfinite(p) else float(p) for p in ps]
        if len(readings) == 1 or not self.estimate or any(p is None for p in ps):
            for r in readings[:-1]:
                self.process(r)
            return self.process(readings[-1])
        t0 = time.perf_counter()
        a = np.array([r.sample.adc for r in readings], dtype=float)
        shape = reconstruct(a, self.calibration, self.config.sensor, s_m=self.s_m)
        prev = self._previous
        warm = {"initial": prev} if prev is not None and bool(prev.success) else {}
        est = estimate_force(shape, np.array(ps), self.config, constraint=self.constraint,
                             calibration=self.calibration, **warm, **self.options)
        last = _frame_of(est, -1)
        self._previous = last
        self.estimated += len(readings)
        self.failures += int(np.count_nonzero(~np.asarray(est.success)))
        self.frames += len(readings)
        reading = readings[-1]
        sample = reading.sample
        return LiveFrame(
            seq=int(sample.seq),
            t_s=reading.device_us * 1e-6,
            host_ns=int(reading.host_ns),
            pressure_pa=ps[-1],
            delta_a=a[-1] - self.calibration.offset,
            shape=reconstruct(a[-1], self.calibration, self.config.sensor, s_m=self.s_m),
            estimate=last,
            process_s=time.perf_counter() - t0,
        )

    def process(self, reading) -> LiveFrame:
        """Process a :class:`~bendsense.device.driver.Reading`."""
        sample = reading.sample
        return self.process_signals(
            sample.adc, sample.pressure_pa, seq=sample.seq, t_s=reading.device_us * 1e-6, host_ns=reading.host_ns
        )


def _frame_of(est, i):
    """Frame ``i`` of a batched :class:`~bendsense.estimation.ForceEstimate`."""
    import dataclasses

    fields = ("force_n", "std_n", "covariance_n2", "residual_m", "success", "message", "iterations",
              "tip_position_m", "state", "guess_n", "chi2_per_dof")
    return dataclasses.replace(est, **{f: np.asarray(getattr(est, f))[i] for f in fields
                                       if getattr(est, f) is not None})


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
    """

    def __init__(
        self, processor: LiveProcessor, figure=None, *, headless=False, scale_m_per_n=0.2, text_interval_s=0.1
    ):
        self.processor = processor
        self.scale_m_per_n = float(scale_m_per_n)
        self.text_interval_s = float(text_interval_s)
        self._text_regions = {}
        self._next_text = 0.0
        if figure is None:
            if headless:
                from matplotlib.backends.backend_agg import FigureCanvasAgg
                from matplotlib.figure import Figure

                figure = Figure(figsize=(11, 5.5))
                FigureCanvasAgg(figure)
            else:
                import matplotlib.pyplot as plt

                figure = plt.figure(figsize=(11, 5.5))
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
        grid = fig.add_gridspec(1, 2, width_ratios=(1, 1.25), left=0.06, right=0.98, bottom=0.1, top=0.9, wspace=0.2)
        ax = self.ax_shape = fig.add_subplot(grid[0, 0])
        ax.set_xlim(-0.45 * length, 1.05 * length)
        ax.set_ylim(-0.3 * length, 1.1 * length)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.grid(True, alpha=0.3)
        ax.plot([0.0], [0.0], "ks", markersize=7, label="base")
        ax.set_title("shape and tip force (base frame)", fontsize="medium")
        (self.shape_line,) = ax.plot(
            [], [], "-", color="C0", linewidth=2.5, label="reconstructed shape (dashed: extrapolated)", animated=True
        )
        (self.tip_marker,) = ax.plot([], [], "o", color="C0", markersize=6, animated=True)
        self.arrow = FancyArrowPatch(
            (0, 0), (0, 0), arrowstyle="-|>", mutation_scale=18, color="C3", linewidth=2, animated=True
        )
        ax.add_patch(self.arrow)
        ax.plot([], [], "-", color="C3", linewidth=2, label=f"tip force ({self.scale_m_per_n * MM:g} mm per N)")
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
        self.status_text = fig.text(0.5, 0.97, "", ha="center", va="top", fontsize="medium", animated=True)
        self.texts = [self.force_text, self.status_text]
        self.artists = [*self.texts, self.bars, self.shape_line, self.tip_marker, self.arrow]

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
        fig, canvas = self.figure, self.canvas
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

    def set_frame(self, frame: LiveFrame, status: str = "") -> None:
        """Update the artists' data from a frame (no drawing)."""
        shape = frame.shape
        pos = np.asarray(shape.positions_m) * MM
        self.shape_line.set_data(pos[:, 0], pos[:, 1])
        self.shape_line.set_linestyle("--" if bool(np.any(shape.extrapolated)) else "-")
        tip = pos[-1]
        self.tip_marker.set_data([tip[0]], [tip[1]])
        force, std = frame.force_n, frame.std_n
        if np.all(np.isfinite(force)):
            end = tip + force * self.scale_m_per_n * MM
            self.arrow.set_positions(tuple(tip), tuple(end))
            self.arrow.set_visible(True)
            text = (
                f"F  = ({force[0]:+.3f}, {force[1]:+.3f}) N\n"
                f"±σ = ({std[0]:.3f}, {std[1]:.3f}) N\n"
                f"|F| = {math.hypot(*force):.3f} N"
            )
        else:
            self.arrow.set_visible(False)
            if frame.estimate is None:
                text = "F: no pressure reading" if not math.isfinite(frame.pressure_pa) else "F: not estimated"
            else:
                text = "F: not converged"
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

    def update(self, frame: LiveFrame, status: str = "") -> None:
        """Show a frame: update the artists and blit them over the saved background."""
        self.set_frame(frame, status)
        canvas = self.canvas
        if self._background is None:
            canvas.draw()  # the draw_event handler saves the background and draws the artists
        else:
            canvas.restore_region(self._background)
            self._draw_artists()
        canvas.blit(self.figure.bbox)
        canvas.flush_events()

    def save(self, path, dpi: int = 120, overwrite: bool = True) -> None:
        """Write the figure with the current frame (atomically; :func:`bendsense.output.write_file`)."""
        from pathlib import Path

        from bendsense import output

        path = Path(path)
        fmt = path.suffix[1:].lower() or "png"
        # animated artists are left out of a normal draw; show them for the file
        for artist in self.artists:
            artist.set_animated(False)
        try:
            with output.write_file(path, overwrite=overwrite, writer="bendsense live") as tmp:
                self.figure.savefig(tmp, format=fmt, dpi=dpi)
        finally:
            for artist in self.artists:
                artist.set_animated(True)
            self._background = None


# --------------------------------------------------------------------------- loop


@dataclass(frozen=True)
class LiveStats:
    """What a live run did and how fast.

    Attributes
    ----------
    frames : int
        Frames processed and displayed.
    received : int
        Samples the driver received meanwhile (the rest were skipped: the view shows
        the newest frame only).
    failures : int
        Force estimates that did not converge.
    elapsed_s : float
        Wall time of the loop [s].
    fps : float
        Displayed frames per second [1/s].
    latency_ms : tuple of float
        End-to-end latency per frame, median and 95th percentile [ms]: bytes read by
        the driver → shape and force → artists drawn.
    process_ms : float
        Median reconstruction + estimation time per frame [ms].
    draw_ms : float
        Median time to update and blit the artists per frame [ms].
    estimated : int
        Frames whose force was estimated (every received frame with a pressure).
    estimate_hz : float
        Achieved estimation rate [1/s].
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
        return (
            f"{self.frames} frames shown ({self.received} received) in {self.elapsed_s:.1f} s: "
            f"{self.fps:.1f} fps, latency median {self.latency_ms[0]:.1f} ms (p95 {self.latency_ms[1]:.1f} ms), "
            f"process {self.process_ms:.2f} ms, draw {self.draw_ms:.2f} ms per frame; "
            f"{self.estimated} frames estimated ({self.estimate_hz:.0f} estimates/s)"
            + (f", {self.failures} estimates not converged" if self.failures else "")
        )


def run_live(
    driver,
    processor: LiveProcessor,
    view: LiveView | None = None,
    *,
    duration_s=None,
    max_fps=60.0,
    is_open=None,
    on_frame=None,
) -> LiveStats:
    """Show the newest reading of ``driver`` until ``duration_s`` passed or the view closes.

    Parameters
    ----------
    driver : Driver
        An open, streaming driver (:meth:`~bendsense.device.driver.Driver.latest` is used).
    processor : LiveProcessor
    view : LiveView, optional
        None: process only (for benchmarks of the model alone).
    duration_s : float, optional
        Run time [s]; None: until ``is_open()`` turns false.
    max_fps : float
        Upper bound of the display rate [1/s]; the loop idles when no new frame came.
    is_open : callable, optional
        Returns False when the window was closed.
    on_frame : callable, optional
        Called with each :class:`LiveFrame` after it was drawn.

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
    latencies, process, draw = [], [], []
    queued = getattr(driver, "_queue", None) is not None
    estimated0 = processor.estimated
    samples0 = driver.stats.samples
    last_key = None
    start = time.monotonic()
    end = None if duration_s is None else start + duration_s
    last_shown = None
    while True:
        now = time.monotonic()
        if end is not None and now >= end:
            break
        if is_open is not None and not is_open():
            break
        if driver.error is not None:
            raise DeviceError(driver.error)
        if queued:
            # every received frame is estimated; the view shows the newest
            readings = driver.get_batch(timeout=0.002)
            reading = readings[-1] if readings else None
        else:
            reading = driver.latest()
            readings = [reading]
        key = None if reading is None else (reading.host_ns, reading.sample.seq)
        if reading is None or key == last_key:
            if not queued:
                time.sleep(0.002)
            if view is not None:
                view.canvas.flush_events()
            continue
        last_key = key
        frame = processor.process_many(readings)
        t_draw = time.perf_counter()
        if view is not None:
            elapsed = time.monotonic() - start
            fps = len(latencies) / elapsed if elapsed > 0 else 0.0
            lat = np.median(latencies[-50:]) if latencies else math.nan
            view.update(
                frame, f"seq {reading.sample.seq}   {fps:.0f} fps   latency {lat:.0f} ms   lost {driver.stats.lost}"
            )
        done_ns = time.monotonic_ns()
        draw.append(time.perf_counter() - t_draw)
        process.append(frame.process_s)
        latencies.append((done_ns - reading.host_ns) * 1e-6)
        if on_frame is not None:
            on_frame(frame)
        if min_period and last_shown is not None:
            wait = last_shown + min_period - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        last_shown = time.monotonic()
    elapsed = time.monotonic() - start
    n = len(latencies)
    lat = (float(np.median(latencies)), float(np.percentile(latencies, 95))) if n else (math.nan, math.nan)
    return LiveStats(
        frames=n,
        received=driver.stats.samples - samples0,
        failures=processor.failures,
        elapsed_s=elapsed,
        fps=n / elapsed if elapsed > 0 else 0.0,
        latency_ms=lat,
        process_ms=float(np.median(process)) * 1e3 if n else math.nan,
        draw_ms=float(np.median(draw)) * 1e3 if n else math.nan,
        estimated=processor.estimated - estimated0,
        estimate_hz=(processor.estimated - estimated0) / elapsed if elapsed > 0 else 0.0,
    )
