"""``bendsense demo``: the whole chain on a simulated board, with the truth to check it against.

:func:`run_demo` needs no hardware:

1. calibrates the virtual sensor: the paper's calibration experiment (flat + strips,
   :func:`bendsense.sim.scenarios.simulate`) on the same sensor hardware (same seed),
   fitted with :meth:`bendsense.calibration.Calibration.fit` (reused when present);
2. starts the simulated board (:class:`~bendsense.device.simdevice.SimulatedDevice`) on
   a pseudo-terminal, streaming the ``time-varying`` scenario (pressure ramps, a
   contact force normal to the tip switching on and off), connects the real driver
   (HELLO handshake, START) and records a native session with the real recorder;
3. reconstructs the shape (paper eq. 1–7) and estimates the tip force (eq. 18) of every
   recorded frame (:func:`bendsense.pipeline.process`), with the contact constraint
   ``normal`` (eq. 21; the scenario's force is normal to the tip) and without constraint
   (``none``);
4. writes ``results/`` (DESIGN.md section 3) and ``demo.png``, and compares the
   forces with the simulated truth.

The truth is recomputed, not transmitted: the board's frame ``k`` is the scenario at
``t = k / rate_hz``, so the same seed and rate give the same frames. A recorded frame's
``k`` follows from its device clock (``t_us = round(k · 1e6 / rate_hz)``), checked
against its sequence number; a dropped frame is simply missing.

Layout of the output directory::

    calibration/   the simulated calibration recordings, manifest.yaml, calibration.yaml
    session/       the recorded native session (meta.yaml, frames.bin, events.log)
    results/       results.csv (constraint normal; truth and the ``none`` estimate as
                   extra columns) and shape.npz
    demo.png       shapes over time, force estimate against truth with ±2σ, curvatures
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bendsense.errors import ArgumentError, DeviceError, SessionError
from bendsense.validation import short

__all__ = ["DemoResult", "run_demo", "DEFAULT_DIR"]

DEFAULT_DIR = "bendsense-demo"
#: Iteration limit of the unconstrained estimate: near zero pressure the actuator is
#: straight and an axial tip force does not change its shape, so those frames cannot
#: converge; a lower limit lets them fail fast instead of spending 100 beam solves each.
NONE_MAX_ITER = 25


@dataclass(frozen=True)
class DemoResult:
    """What the demo did and how well it worked.

    Attributes
    ----------
    out_dir, session_dir, results_dir, figure_path, calibration_path : Path
        Where the outputs are.
    calibration_reused : bool
        An existing calibration of the same seed was used.
    calibration_degree : int
        Polynomial degree of the calibration (paper eq. 2).
    calibration_rms_shift_m : float
        RMS shift residual of the calibration fit over all strips [m].
    frames_generated : int
        SAMPLE frames the simulated board produced.
    frames_received, frames_lost, crc_errors, malformed : int
        The driver's counters.
    frames_recorded : int
        Frames in the recorded session.
    counts_match : bool
        Every recorded frame's ADC counts equal the recomputed frame's (the session
        and the truth are aligned frame by frame).
    frames_compared : int
        Frames with a valid simulated truth (the simulator's beam solve converged).
    force_rms_error_n : dict of str to float
        Per constraint: RMS of ``|F̂ − F_true|`` over the identifiable frames (converged,
        finite σ) [N].
    within_2sigma : dict of str to float
        Per constraint: fraction of force components (x and y of every converged frame)
        whose truth lies within ±2σ of the estimate.
    converged : dict of str to float
        Per constraint: fraction of frames whose estimate converged.
    identifiable : dict of str to float
        Per constraint: fraction of frames whose force is identifiable (finite σ in
        every direction); the others are near-straight frames with an axial load.
    estimation_rate_hz : dict of str to float
        Per constraint: frames estimated per second of wall time (batched) [1/s].
    reconstruction_rate_hz : float
        Frames reconstructed per second (batched) [1/s].
    contact_n : float
        Magnitude of the simulated contact force while on [N].
    elapsed_s : float
        Wall time of the whole demo [s].
    parameter_covariance : bool
        The config declares a ``parameter_covariance`` (the shipped config: its prior), so
        σ includes the model parameters' part; the simulated actuator has the config's
        own parameters, so there it over-covers.
    """

    out_dir: Path
    session_dir: Path
    results_dir: Path
    figure_path: Path
    calibration_path: Path
    calibration_reused: bool
    calibration_degree: int
    calibration_rms_shift_m: float
    frames_generated: int
    frames_received: int
    frames_lost: int
    crc_errors: int
    malformed: int
    frames_recorded: int
    counts_match: bool
    frames_compared: int
    force_rms_error_n: dict = field(default_factory=dict)
    within_2sigma: dict = field(default_factory=dict)
    converged: dict = field(default_factory=dict)
    identifiable: dict = field(default_factory=dict)
    estimation_rate_hz: dict = field(default_factory=dict)
    reconstruction_rate_hz: float = math.nan
    contact_n: float = math.nan
    elapsed_s: float = math.nan
    parameter_covariance: bool = False

    def summary(self) -> str:
        """A short report for the terminal."""
        cal = "reused" if self.calibration_reused else "fitted"
        lines = [
            f"frames: {self.frames_generated} generated, {self.frames_received} received, {self.frames_lost} lost, "
            f"{self.crc_errors} CRC errors, {self.malformed} malformed; {self.frames_recorded} recorded"
            + ("" if self.counts_match else " (counts differ from the recomputed stream!)"),
            f"calibration ({cal}): degree {self.calibration_degree}, RMS shift residual "
            f"{self.calibration_rms_shift_m * 1e6:.1f} um over the strips",
            f"reconstruction: {self.reconstruction_rate_hz:,.0f} frames/s",
            f"force vs simulated truth ({self.frames_compared} frames, peak contact force {self.contact_n:.3g} N):",
        ]
        for name in self.force_rms_error_n:
            lines.append(
                f"  constraint {name:<6}  RMS error {self.force_rms_error_n[name]:.4f} N, "
                f"truth within ±2σ {100 * self.within_2sigma[name]:.0f} %, "
                f"converged {100 * self.converged[name]:.0f} %, "
                f"identifiable {100 * self.identifiable[name]:.0f} %, "
                f"{self.estimation_rate_hz[name]:,.0f} frames/s"
            )
        parts = ("sensor noise, calibration error and the config's parameter prior" if self.parameter_covariance
                 else "sensor noise and calibration error")
        lines.append(f"  (σ: {parts}, scaled up where the shape misfits the model; RMS over identifiable frames)")
        lines.append(f"wrote {self.session_dir}, {self.results_dir}, {self.figure_path} in {self.elapsed_s:.1f} s")
        return "\n".join(lines)


def _nothing(_message: str) -> None:
    pass


def _calibrate(cal_dir: Path, previous: Path, config, seed: int, echo):
    """Fit the calibration of the virtual sensor of ``seed`` into ``cal_dir``, or reuse the one in ``previous``."""
    import shutil

    import yaml

    from bendsense.calibration import Calibration
    from bendsense.sim.scenarios import simulate

    cal_path = previous / "calibration.yaml"
    description = previous / "scenario.yaml"
    if cal_path.is_file() and description.is_file():
        try:
            same_seed = yaml.safe_load(description.read_text(encoding="utf-8")).get("seed") == seed
        except (OSError, yaml.YAMLError, AttributeError):
            same_seed = False
        if same_seed:
            echo(f"calibration: reusing {cal_path}")
            shutil.copytree(previous, cal_dir, symlinks=True)
            return Calibration.load(cal_dir / "calibration.yaml"), True
    echo(f"calibration: simulating the calibration strips (seed {seed}) and fitting ...")
    simulate("calibration", cal_dir, config, seed, overwrite=True)
    cal = Calibration.fit(cal_dir / "manifest.yaml", config.sensor)
    cal.save(cal_dir / "calibration.yaml")
    return cal, False


def _record(session_dir: Path, config, *, seconds, rate_hz, seed, echo, progress=None):
    """Stream the virtual sensor through a pseudo-terminal, the driver and the recorder."""
    from bendsense.device.driver import Driver
    from bendsense.device.recorder import Recorder
    from bendsense.device.simdevice import Firmware, SimulatedDevice, default_source

    n_frames = max(1, round(seconds * rate_hz))
    n_channels = config.sensor.n_segments
    source = default_source(n_channels=n_channels, rate_hz=rate_hz, seed=seed, config=config)
    meta = {
        "command": "bendsense demo",
        "demo": {"seed": seed, "rate_hz": rate_hz, "frames": n_frames, "scenario": "time-varying"},
    }
    device = SimulatedDevice(
        source, rate_hz=rate_hz, n_channels=n_channels, max_frames=n_frames,
        firmware=Firmware(name="bendsense-sim demo"),
    )
    with device, Driver(device.port) as driver:
        hello = driver.hello
        echo(
            f"device: simulated board on {device.port}: HELLO {hello.firmware!r}, {hello.n_channels} channels, "
            f"{hello.rate_hz} Hz; recording {n_frames} frames ({seconds:g} s) ..."
        )
        recorder = Recorder(driver, session_dir, overwrite=True, config=config, meta=meta)
        with recorder:  # stopped and joined on the way out, also when interrupted: nothing writes after
            driver.start()
            recorder.start()
            deadline = time.monotonic() + 3.0 * seconds + 30.0
            while not device.finished.wait(timeout=0.1):
                if progress is not None:
                    progress(recorder.stats.records, n_frames)
                if time.monotonic() > deadline:
                    recorder.stop()
                    raise DeviceError(f"{device.port}: the simulated board did not finish {n_frames} frames in time")
            # the last frames may still be on their way through the pty, the driver and the queue
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                ds = driver.stats
                if ds.samples + ds.lost >= device.stats.generated and recorder.stats.records >= ds.samples:
                    break
                time.sleep(0.02)
            recorder.stop()
        stats = driver.stats
        if progress is not None:
            progress(recorder.stats.records, n_frames)
    return device.stats, stats


def _frame_index(session_dir: Path, rate_hz: float) -> np.ndarray:
    """Scenario frame index k of every recorded frame, from the device clock, checked against seq."""
    from bendsense.session.native import read_records

    records, _ = read_records(session_dir)
    k = np.rint(records["t_us"].astype(np.int64) * rate_hz / 1e6).astype(np.int64)
    seq = records["seq"].astype(np.int64)
    if k.size and np.any((seq - seq[0]) % 65536 != (k - k[0]) % 65536):
        raise SessionError(f"{session_dir}: device clock and sequence numbers disagree; cannot align the truth")
    return k


def _truth(config, rate_hz, seed, n_frames):
    """Recompute the board's frames with their truth: counts (K, N), force (K, 2), fc (K,), valid (K,)."""
    from bendsense.sim.scenarios import time_varying_frames

    rows = list(time_varying_frames(config, rate_hz, seed, truth=True, duration_s=n_frames / rate_hz))
    counts = np.array([c for _, c, _ in rows], dtype=np.int64)
    force = np.array([[t["fx_n"], t["fy_n"]] for _, _, t in rows])
    fc = np.array([t["fc_n"] for _, _, t in rows])
    valid = np.array([t["valid"] for _, _, t in rows], dtype=bool)
    positions = np.array([t["positions_m"] for _, _, t in rows])
    return counts, force, fc, valid, positions


def _force_stats(estimate, truth_force, valid):
    """RMS error over the identifiable frames, ±2σ coverage, converged and identifiable fractions."""
    ok = np.asarray(estimate.success) & valid
    std = np.asarray(estimate.std_n)
    # σ = ∞: an axial load on a nearly straight actuator, which the shape cannot show
    identifiable = ok & np.all(np.isfinite(std), axis=-1)
    err = np.asarray(estimate.force_n) - truth_force
    rms = float(np.sqrt(np.mean(np.sum(err[identifiable] ** 2, axis=-1)))) if identifiable.any() else math.nan
    within = float(np.mean(np.abs(err[ok]) <= 2.0 * std[ok])) if ok.any() else math.nan
    n = max(int(valid.sum()), 1)
    return rms, within, float(np.mean(np.asarray(estimate.success))), float(identifiable.sum() / n)


def run_demo(
    out_dir=DEFAULT_DIR,
    *,
    seconds: float = 5.0,
    rate_hz: float = 100.0,
    seed: int = 0,
    overwrite: bool = False,
    config=None,
    echo=None,
    progress=None,
) -> DemoResult:
    """Run the demo (module docstring) and write its outputs into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output directory; must not exist unless ``overwrite``.
    seconds : float
        Recording time [s].
    rate_hz : float
        Frame rate of the simulated board [Hz].
    seed : int
        Seed of the virtual sensor's hardware and noise.
    overwrite : bool
        Replace an earlier demo's outputs in ``out_dir`` (a calibration of the same seed
        there is reused); a directory holding files bendsense did not write is refused.
    config : Config, optional
        The actuator and sensor (simulated and assumed alike); default the paper's.
    echo : callable, optional
        Called with a line of progress text per step.
    progress : callable, optional
        Called as ``progress(frames_recorded, frames_total)`` while recording.

    Returns
    -------
    DemoResult

    Raises
    ------
    OutputExistsError
        If ``out_dir`` exists and ``overwrite`` is false (a ``FileExistsError``).
    OutputError
        If ``out_dir`` holds files bendsense did not write, or may not be written over.
    ValueError
        For ``seconds`` or ``rate_hz`` not > 0.
    """
    from bendsense import output
    from bendsense.config import load_config

    t_start = time.monotonic()
    echo = _nothing if echo is None else echo
    for name, value in (("seconds", seconds), ("rate_hz", rate_hz)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ArgumentError(f"{name}: expected a number > 0, got {short(value)}")
    if rate_hz > 65535:
        raise ArgumentError(f"rate_hz: the HELLO carries at most 65535 Hz, got {short(rate_hz)}")
    out = Path(out_dir)
    output.check([output.directory(out, overwrite=overwrite)])
    config = load_config() if config is None else config
    with output.write_dir(out, overwrite=overwrite, writer="bendsense demo") as work:
        result = _run(work, out, config, seconds=seconds, rate_hz=rate_hz, seed=seed, echo=echo, progress=progress)
    return dataclasses.replace(result, elapsed_s=time.monotonic() - t_start)


def _run(work: Path, out: Path, config, *, seconds, rate_hz, seed, echo, progress) -> DemoResult:
    """The demo's steps, writing into ``work`` (swapped in as ``out`` at the end)."""
    from bendsense import _jit
    from bendsense.estimation import _kernels as kernels
    from bendsense.pipeline import process
    from bendsense.results import write_results
    from bendsense.results._kernels import compile_kernels as compile_status_kernels
    from bendsense.session.native import read_session_dir
    from bendsense.shape.pcc import reconstruct
    from bendsense.tracking.windows import MIN_FRAMES, WINDOW_S
    from bendsense.tracking.windows import compile_kernels as compile_window_kernels

    session_dir, results_dir, figure_path = work / "session", work / "results", work / "demo.png"
    # first run after an install: the estimation kernels compile on the second core while
    # this process simulates (the beam solver's kernels) and records
    with _jit.Background(kernels.estimate_block, "bendsense.estimation:compile_kernels") as compiling:
        cal, reused = _calibrate(work / "calibration", out / "calibration", config, seed, echo)
        sim_stats, drv_stats = _record(
            session_dir, config, seconds=seconds, rate_hz=rate_hz, seed=seed, echo=echo, progress=progress
        )
        session = read_session_dir(session_dir)
        truth = _aligned_truth(session, session_dir, config, seconds=seconds, rate_hz=rate_hz, seed=seed,
                               echo=echo)
        if compiling.process is not None:  # the kernels of the steps after the estimate, while it compiles
            compile_window_kernels(cal, config)
            compile_status_kernels()
            reconstruct(session.signals[:1], cal, config.sensor)
        compiling.wait()

    echo(f"processing {len(session)} frames: shape, force (constraint normal and none) ...")
    # the model check's windows hold a test's frames at the demo's rate (--rate below 100 Hz: longer ones)
    window_s = WINDOW_S if WINDOW_S >= MIN_FRAMES / rate_hz else math.ceil((MIN_FRAMES + 1) * 1e3 / rate_hz) / 1e3
    # the first estimate compiles (first run after install) or loads the kernels: the rates
    # reported are those of the estimator, from a second run of the same frames
    process(session, config, cal, constraint="none", max_iter=NONE_MAX_ITER, window_s=window_s)
    # the contact is normal to the loaded tip, so the normal takes the reconstructed tip
    # angle (the paper takes the free-motion model's, which a contact force turns away)
    normal = process(session, config, cal, constraint="normal", tip_angle_source="shape", points=101,
                     window_s=window_s)
    none = process(session, config, cal, constraint="none", shape=normal.shape, max_iter=NONE_MAX_ITER,
                   window_s=window_s)
    processed = {"normal": normal, "none": none}
    stats = {name: _force_stats(p.estimate, truth["force"], truth["valid"]) for name, p in processed.items()}

    write_results(results_dir, _annotated(session, truth, none.estimate), normal.shape, normal.estimate,
                  overwrite=True)
    echo(f"figure: {out / figure_path.name} ...")
    write_figure(results_dir, figure_path, title=f"bendsense demo: simulated board, seed {seed}, {len(session)} frames")

    residuals = [r.rms_shift_m for r in cal.strip_residuals]
    return DemoResult(
        out_dir=out,
        session_dir=out / session_dir.name,
        results_dir=out / results_dir.name,
        figure_path=out / figure_path.name,
        calibration_path=out / "calibration" / "calibration.yaml",
        calibration_reused=reused,
        calibration_degree=cal.degree,
        calibration_rms_shift_m=float(np.sqrt(np.mean(np.square(residuals)))) if residuals else math.nan,
        frames_generated=sim_stats.generated,
        frames_received=drv_stats.samples,
        frames_lost=drv_stats.lost,
        crc_errors=drv_stats.crc_errors,
        malformed=drv_stats.malformed,
        frames_recorded=len(session),
        counts_match=truth["counts_match"],
        frames_compared=int(truth["valid"].sum()),
        force_rms_error_n={name: s[0] for name, s in stats.items()},
        within_2sigma={name: s[1] for name, s in stats.items()},
        converged={name: s[2] for name, s in stats.items()},
        identifiable={name: s[3] for name, s in stats.items()},
        estimation_rate_hz={name: len(session) / max(p.estimate_s, 1e-9) for name, p in processed.items()},
        reconstruction_rate_hz=len(session) / max(normal.reconstruct_s, 1e-9),
        contact_n=float(np.max(truth["fc"])) if truth["fc"].size else math.nan,
        elapsed_s=math.nan,
        parameter_covariance=config.parameter_covariance is not None,
    )


def _aligned_truth(session, session_dir: Path, config, *, seconds, rate_hz, seed, echo) -> dict:
    """The simulated truth of every recorded frame, aligned by its frame index.

    ``k`` (frame index), ``force`` (frames, 2) [N], ``fc`` (frames,) [N], ``valid``
    (frames,) and ``counts_match`` (the recorded ADC counts are the recomputed ones).
    """
    k = _frame_index(session_dir, rate_hz)
    n_frames = max(1, round(seconds * rate_hz))
    echo(f"truth: recomputing the {n_frames} frames of seed {seed} ...")
    true_counts, true_force, true_fc, valid, _ = _truth(config, rate_hz, seed, n_frames)
    if k.size and (k.min() < 0 or k.max() >= n_frames):
        raise SessionError(f"{session_dir}: frame index {int(k.max())} outside the {n_frames} frames sent")
    counts_match = bool(np.array_equal(session.signals.astype(np.int64), true_counts[k]))
    return {"k": k, "force": true_force[k], "fc": true_fc[k], "valid": valid[k], "counts_match": counts_match}


def _annotated(session, truth: dict, none):
    """``session`` with the truth and the unconstrained estimate ``none`` as extra columns of ``results.csv``."""
    from bendsense.session import Session

    extra = {
        **session.extra,
        "frame": truth["k"],
        "fx_true_n": truth["force"][:, 0],
        "fy_true_n": truth["force"][:, 1],
        "fc_true_n": truth["fc"],
        "truth_valid": truth["valid"].astype(np.int64),
        "fx_none_n": np.asarray(none.force_n)[:, 0],
        "fy_none_n": np.asarray(none.force_n)[:, 1],
        "fx_none_std_n": np.asarray(none.std_n)[:, 0],
        "fy_none_std_n": np.asarray(none.std_n)[:, 1],
    }
    return Session(
        session.t_s, session.signals, session.pressure_pa, session.seq, dict(session.meta), extra, session.source
    )


def write_figure(results_dir, path, *, title=None, max_shapes: int = 8, dpi: int = 130):
    """Write the demo figure from a results directory with truth columns.

    Left: shapes of ``max_shapes`` frames and the tip path; right, over time: the
    estimated tip force (constraint ``normal``) with its ±2σ band against the simulated
    truth (dashed), the unconstrained estimate (thin), and the segment curvatures.
    Drawn with :func:`bendsense.plots.plot_shapes` and :func:`bendsense.plots.plot_time_series`.

    Parameters
    ----------
    results_dir : path
        Results directory of the demo (with truth columns).
    path : path
        Figure file to write.
    title : str, optional
        Figure title.
    max_shapes : int, default 8
        Number of frames whose shapes are drawn.
    dpi : int, default 130
        Resolution of a raster figure [dots per inch].
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from bendsense import output
    from bendsense.plots import plot_shapes, plot_time_series
    from bendsense.results import read_results

    results = read_results(results_dir)
    fig = Figure(figsize=(13, 7), layout="constrained")
    grid = fig.add_gridspec(2, 3, width_ratios=(1, 1.7, 0.04))
    ax_s = fig.add_subplot(grid[:, 0])
    ax_f = fig.add_subplot(grid[0, 1])
    ax_k = fig.add_subplot(grid[1, 1], sharex=ax_f)
    cax = fig.add_subplot(grid[1, 2])

    tip = np.column_stack([results["tip_x_m"], results["tip_y_m"]]).astype(float) * 1e3
    ax_s.plot(tip[:, 0], tip[:, 1], color="0.6", linewidth=0.8, zorder=0, label="tip path")
    plot_shapes(results, ax_s, max_frames=max_shapes, legend=False)
    # below the panel, where it covers no shape
    ax_s.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.09), ncols=2, frameon=False)
    ax_s.set_title("reconstructed shapes over time", fontsize="medium")

    plot_time_series(results, (ax_f, ax_k), cax=cax)
    ax_f.tick_params(labelbottom=False)
    ax_f.set_ylabel("tip force, base frame [N]")
    t = np.asarray(results["t_s"], dtype=float)
    handles, labels = _force_legend(ax_f)
    for comp, color in (("x", "C0"), ("y", "C3")):
        truth = np.asarray(results[f"f{comp}_true_n"], dtype=float)
        valid = np.asarray(results["truth_valid"], dtype=float) > 0
        (line,) = ax_f.plot(
            t, np.where(valid, truth, np.nan), "--", color="k" if comp == "x" else "0.45", linewidth=1.2
        )
        handles.append(line)
        labels.append(f"F_{comp} truth")
        none = np.asarray(results[f"f{comp}_none_n"], dtype=float)
        # unidentifiable frames (σ = ∞, near-straight actuator) carry no information
        none_std = np.asarray(results[f"f{comp}_none_std_n"], dtype=float)
        ax_f.plot(t, np.where(np.isfinite(none_std), none, np.nan), ":", color=color, linewidth=1.0)
    handles.append(Line2D([], [], linestyle=":", color="0.3"))
    labels.append("no constraint")
    # scale to the constrained estimate and the truth (a ±2σ band can be wide where the
    # actuator is nearly straight), with head room for the legend
    shown = np.concatenate([np.asarray(results[c], dtype=float) for c in ("fx_n", "fy_n", "fx_true_n", "fy_true_n")])
    shown = shown[np.isfinite(shown)]
    lo, hi = (min(shown.min(), 0.0), max(shown.max(), 0.0)) if shown.size else (-0.1, 0.1)
    pad = 0.15 * max(hi - lo, 0.05)
    y0, y1 = lo - pad, hi + 3 * pad
    ax_f.set_ylim(y0, y1)
    # the unconstrained estimate can leave that range: mark where it is clipped
    clipped = False
    for comp, color in (("x", "C0"), ("y", "C3")):
        none = np.asarray(results[f"f{comp}_none_n"], dtype=float)
        none = np.where(np.isfinite(np.asarray(results[f"f{comp}_none_std_n"], dtype=float)), none, np.nan)
        for beyond, edge, marker in ((none > y1, y1, "^"), (none < y0, y0, "v")):
            if np.any(beyond):
                ax_f.plot(t[beyond], np.full(beyond.sum(), edge), marker, color=color, markersize=4, clip_on=False,
                          linestyle="none")
                clipped = True
    if clipped:
        handles.append(Line2D([], [], marker="^", linestyle="none", color="0.3", markersize=4))
        labels.append("no constraint: off the axis (clipped)")
    ax_f.legend(handles, labels, fontsize="small", ncols=4, loc="lower center", bbox_to_anchor=(0.5, 1.0),
                frameon=False, borderaxespad=0.2, title="estimate normal to the tip vs simulated truth",
                title_fontsize="small")
    if title:
        fig.suptitle(title)
    path = Path(path)
    with output.write_file(path, overwrite=True, writer="bendsense demo") as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata=output.figure_metadata("png"))
    return fig


def _force_legend(ax):
    """Handles and labels of the force panel drawn by :func:`bendsense.plots.plot_time_series`.

    Each estimate's line and ±2σ band are paired into one legend entry, as there.
    """
    legend = ax.get_legend()
    if legend is not None:
        legend.remove()
    found = dict(zip(*reversed(ax.get_legend_handles_labels())))
    handles, labels = [], []
    for comp in ("x", "y"):
        line, band = found.get(f"F_{comp}"), found.get(f"F_{comp} ± 2σ")
        if line is not None:
            handles.append((line, band) if band is not None else line)
            labels.append(f"F_{comp} ± 2σ")
    if "status not ok" in found:
        handles.append(found["status not ok"])
        labels.append("status not ok")
    for twin in ax.figure.axes:  # the pressure, on the panel's second axis
        if twin is not ax and twin.bbox.bounds == ax.bbox.bounds:
            handles += [line for line in twin.lines if line.get_label() == "pressure"]
            labels += ["pressure (right axis)"] * (len(handles) - len(labels))
    return handles, labels
