"""Figures (bendsense.plots) and the ``plot`` command, standalone and chained."""

import matplotlib

matplotlib.use("Agg")  # before pyplot: render to files only

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from click.testing import CliRunner  # noqa: E402
from helpers import linear_calibration, signals_for  # noqa: E402

from bendsense import load_config  # noqa: E402
from bendsense.calibration import Calibration  # noqa: E402
from bendsense.cli import main  # noqa: E402
from bendsense.plots import (  # noqa: E402
    plot_calibration,
    plot_force_error_map,
    plot_results,
    plot_shape_comparison,
    plot_shapes,
    plot_time_series,
    results_from_state,
)
from bendsense.results import read_results, write_results  # noqa: E402
from bendsense.session import Session, write_session_csv  # noqa: E402
from bendsense.shape.pcc import Shape  # noqa: E402
from bendsense.status import Status  # noqa: E402

SENSOR = load_config().sensor
N = SENSOR.n_segments
L = SENSOR.length_m
FRAMES = 30
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


class FakeEstimate:
    """Stands in for a ForceEstimate: known forces and uncertainties per frame."""

    def __init__(self, t):
        self.force_n = np.column_stack([0.1 * np.sin(t), -0.2 * t / t.max()])
        self.std_n = np.column_stack([np.full_like(t, 0.01), np.full_like(t, 0.02)])
        self.residual_m = np.full_like(t, 1e-4)
        self.success = np.arange(t.size) != 3  # one frame not converged
        self.status = np.where(self.success, Status.OK, Status.NOT_CONVERGED)


def uniform_kappa(frames=FRAMES):
    return np.repeat(np.linspace(2.0, 20.0, frames)[:, None], N, axis=1)


def session_shape_estimate():
    t = np.linspace(0.0, 3.0, FRAMES)
    session = Session(t, np.zeros((FRAMES, N)), np.linspace(20e3, 120e3, FRAMES))
    return session, Shape.from_curvatures(uniform_kappa(), SENSOR.lengths_m), FakeEstimate(t)


@pytest.fixture
def results_dir(tmp_path):
    session, shape, est = session_shape_estimate()
    return write_results(tmp_path / "res", session, shape, est)


def arc_tip_mm(kappa):
    # closed-form tip of a circular arc of length L (paper eq. 5), in mm
    return 1e3 * np.array([(1 - np.cos(kappa * L)) / kappa, np.sin(kappa * L) / kappa])


def saved(fig, path):
    fig.savefig(path)
    data = path.read_bytes()
    assert data.startswith(PNG) and len(data) > 5000
    return path


def bar_heights(ax):
    from matplotlib.container import BarContainer

    return np.array([[bar.get_height() for bar in c] for c in ax.containers if isinstance(c, BarContainer)]).T


def labels(ax):
    return ax.get_xlabel(), ax.get_ylabel()


def test_plot_shapes_draws_mm_positions_with_legend(tmp_path):
    shape = Shape.from_curvatures(uniform_kappa(), SENSOR.lengths_m)
    ax = plot_shapes(shape, max_frames=5)
    assert labels(ax) == ("x [mm]", "y [mm]")
    assert ax.get_aspect() == 1.0
    curves = [line for line in ax.lines if line.get_label().startswith("frame")]
    assert [c.get_label() for c in curves] == ["frame 0", "frame 7", "frame 14", "frame 22", "frame 29"]
    kappa = uniform_kappa()[:, 0]
    for curve, i in zip(curves, (0, 7, 14, 22, 29), strict=True):
        np.testing.assert_allclose(curve.get_xydata()[-1], arc_tip_mm(kappa[i]), rtol=1e-9)
    assert len(ax.get_legend().get_texts()) == 5
    saved(ax.figure, tmp_path / "shapes.png")
    # a positions array and explicit frames and labels
    ax = plot_shapes(shape.positions_m[:2], labels=["a", "b"])
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["a", "b"]
    # one line: no legend
    assert plot_shapes(shape.positions_m[0]).get_legend() is None
    with pytest.raises(ValueError, match="labels: expected 2 labels"):
        plot_shapes(shape.positions_m[:2], labels=["a"])
    with pytest.raises(ValueError, match=r"positions_m: expected shape \(\.\.\., M, 2\)"):
        plot_shapes(np.zeros((3, 4)))


def test_plot_shapes_dashes_extrapolated_frames():
    shape = Shape.from_curvatures(uniform_kappa(3), SENSOR.lengths_m, extrapolated=np.array([False, True, False]))
    ax = plot_shapes(shape)
    styles = [line.get_linestyle() for line in ax.lines if line.get_label().startswith("frame")]
    assert styles == ["-", "--", "-"]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[-1].startswith("dashed: extrapolated") and "outside the calibrated range" in legend[-1]
    # no extrapolated frame drawn: no such entry
    ax = plot_shapes(shape, frames=[0, 2])
    assert not any(t.get_text().startswith("dashed") for t in ax.get_legend().get_texts())


def test_plot_shape_comparison_styles(tmp_path):
    est = Shape.from_curvatures(uniform_kappa(3), SENSOR.lengths_m)
    truth = Shape.from_curvatures(uniform_kappa(3) * 1.05, SENSOR.lengths_m).positions_m[:, ::10]
    model = Shape.from_curvatures(uniform_kappa(3) * 0.95, SENSOR.lengths_m)
    ax = plot_shape_comparison(est, truth, model=model, labels=["0 N", "0.1 N", "0.2 N"])
    assert labels(ax) == ("x [mm]", "y [mm]")
    drawn = [line for line in ax.lines if len(line.get_xdata()) > 1]
    assert [line.get_linestyle() for line in drawn] == ["-", "--", ":"] * 3
    np.testing.assert_allclose(drawn[2].get_xydata(), truth[0] * 1e3)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["0 N", "0.1 N", "0.2 N", "sensor", "model", "ground truth"]
    saved(ax.figure, tmp_path / "comparison.png")
    with pytest.raises(ValueError, match="truth: expected 3 shapes"):
        plot_shape_comparison(est, truth[:2])


def paper_grid():
    pressures = np.arange(20e3, 121e3, 10e3)
    loads = np.array([0.0, 0.1, 0.2, 0.3])
    return pressures, loads, 0.01 + 0.05 * loads[None, :] + 1e-7 * pressures[:, None]


def test_force_error_bars_from_a_grid_and_from_samples(tmp_path):
    pressures, loads, error = paper_grid()
    ax = plot_force_error_map(pressures, loads, error)
    assert labels(ax) == ("pressure [kPa]", "force error [N]")
    assert [t.get_text() for t in ax.get_xticklabels()] == [f"{p:g}" for p in np.arange(20, 121, 10)]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["0 N", "0.1 N", "0.2 N", "0.3 N"]
    heights = bar_heights(ax)  # (P, L)
    np.testing.assert_allclose(heights, error)
    saved(ax.figure, tmp_path / "bars.png")

    # samples: three repeats per cell, averaged, with their spread as error bars
    rng = np.random.default_rng(0)
    p, f = np.meshgrid(pressures, loads, indexing="ij")
    p, f = np.repeat(p.ravel(), 3), np.repeat(f.ravel(), 3)
    e = rng.normal(0.05, 0.01, p.size)
    ax = plot_force_error_map(p, f, e, error_label="error [% of 0.3 N]")
    assert ax.get_ylabel() == "error [% of 0.3 N]"
    heights = bar_heights(ax)
    np.testing.assert_allclose(heights, e.reshape(pressures.size, loads.size, 3).mean(axis=-1))


def test_force_error_heatmap_has_a_colour_bar(tmp_path):
    pressures, loads, error = paper_grid()
    error = error.copy()
    error[0, 0] = np.nan  # an empty cell
    ax = plot_force_error_map(pressures, loads, error, kind="heatmap")
    assert labels(ax) == ("pressure [kPa]", "tip load [N]")
    colorbar_ax = [a for a in ax.figure.axes if a is not ax]
    assert len(colorbar_ax) == 1 and colorbar_ax[0].get_ylabel() == "force error [N]"
    image = ax.images[0]
    np.testing.assert_allclose(image.get_array()[1:, 1:], error.T[1:, 1:])
    assert image.get_array().mask[0, 0]
    assert len(ax.texts) == error.size - 1
    saved(ax.figure, tmp_path / "heatmap.png")
    # signed errors: a diverging colour map centred on zero
    ax = plot_force_error_map(pressures, loads, error - 0.02, kind="heatmap")
    lo, hi = ax.images[0].get_clim()
    assert lo == -hi
    with pytest.raises(ValueError, match="kind: must be 'bars' or 'heatmap'"):
        plot_force_error_map(pressures, loads, error, kind="pie")
    with pytest.raises(ValueError, match="error: expected shape"):
        plot_force_error_map(pressures, loads, error[:3])


def test_time_series_force_band_and_curvatures(results_dir, tmp_path):
    fig = plot_time_series(results_dir)
    ax_f, ax_k = fig.axes[:2]
    assert ax_f.get_ylabel() == "tip force [N]"
    assert labels(ax_k) == ("time [s]", "curvature κ_i [1/m]")
    assert fig.axes[2].get_ylabel() == "segment i"  # the segments' colour bar
    assert fig.axes[2].get_ylim() == (0.5, N + 0.5)
    # both panels keep the same width: the colour bar has its own column
    fig.canvas.draw()
    np.testing.assert_allclose(ax_f.get_position().x1, ax_k.get_position().x1)
    assert len(ax_k.lines) == N
    res = read_results(results_dir)
    fy = [line for line in ax_f.lines if line.get_label() == "F_y"][0]
    np.testing.assert_allclose(fy.get_ydata(), res["fy_n"])
    band = [c for c in ax_f.collections if c.get_label() == "F_y ± 2σ"][0]
    ys = band.get_paths()[0].vertices[:, 1]
    np.testing.assert_allclose([ys.min(), ys.max()], [res["fy_n"].min() - 0.04, res["fy_n"].max() + 0.04])
    legend = [t.get_text() for t in ax_f.get_legend().get_texts()]
    assert legend == ["F_x ± 2σ", "F_y ± 2σ", "status not ok", "pressure (right axis)"]
    # the pressure on a second axis of the force panel, in kPa
    px = [a for a in fig.axes if a is not ax_f and a.bbox.bounds == ax_f.bbox.bounds][0]
    assert px.get_ylabel() == "pressure [kPa]"
    np.testing.assert_allclose(px.lines[0].get_ydata(), res["pressure_pa"] * 1e-3)
    # the legend covers no data: it sits above the panel
    renderer = fig.canvas.get_renderer()
    assert ax_f.get_legend().get_window_extent(renderer).y0 >= ax_f.get_window_extent(renderer).y1 - 1
    saved(fig, tmp_path / "series.png")



def test_time_series_lines_stop_at_a_gap_in_the_frames(tmp_path):
    """A recording with a 2 s gap: the force, its band, the pressure and the curvatures stop at the gap instead of
    drawing a straight line across it; the frames on either side are drawn as they are."""
    session, shape, est = session_shape_estimate()
    t = session.t_s.copy()
    t[FRAMES // 2:] += 2.0  # the board stopped for 2 s
    session = Session(t, session.signals, session.pressure_pa)
    fig = plot_time_series(write_results(tmp_path / "res", session, shape, est))
    ax_f, ax_k = fig.axes[:2]
    gap = FRAMES // 2
    fy = [line for line in ax_f.lines if line.get_label() == "F_y"][0]
    x, y = fy.get_xdata(), fy.get_ydata()
    assert x.size == FRAMES + 1 and np.flatnonzero(np.isnan(y)).tolist() == [gap]
    assert t[gap - 1] < x[gap] < t[gap]
    np.testing.assert_array_equal(np.delete(y, gap), est.force_n[:, 1])
    np.testing.assert_array_equal(np.delete(x, gap), t)
    band = [c for c in ax_f.collections if c.get_label() == "F_y ± 2σ"][0]
    assert len(band.get_paths()) == 2  # one band on each side
    for ax in (ax_k, [a for a in fig.axes if a is not ax_f and a.bbox.bounds == ax_f.bbox.bounds][0]):
        assert all(np.flatnonzero(np.isnan(line.get_ydata())).tolist() == [gap] for line in ax.lines)
    ticks = [line for line in ax_f.lines if line.get_label() == "status not ok"][0]
    np.testing.assert_array_equal(ticks.get_xdata(), t[3:4])  # the one frame not converged, where it is
    saved(fig, tmp_path / "series.png")


def test_a_tracked_series_leaves_out_the_frames_whose_track_is_not_ok(tmp_path):
    """A smoother carried through frames that do not determine the force swings there (0.5 N, σ tens of N, on a
    straight finger at rest): the tracked line and band leave those frames out; the ticks say why."""
    from bendsense.tracking import Track

    session, shape, est = session_shape_estimate()
    status = np.full(FRAMES, Status.OK, dtype=np.int8)
    status[:5] = Status.NOT_IDENTIFIABLE  # the first frames' tracks, at rest
    swing = est.force_n.copy()
    swing[:5, 1] = -0.5
    track = Track(force_n=swing, std_n=np.where(np.arange(FRAMES)[:, None] < 5, 26.0, est.std_n),
                  covariance_n2=np.zeros((FRAMES, 2, 2)), window_p_value=None, status=status, bandwidth_hz=5.0,
                  mode="smooth", t_s=session.t_s, frame_force_n=est.force_n)
    fig = plot_time_series(write_results(tmp_path / "res", session, shape, est, track=track))
    ax_f = fig.axes[0]
    fy = [line for line in ax_f.lines if line.get_label() == "F_y tracked"][0]
    y = np.asarray(fy.get_ydata(), dtype=float)
    assert np.isnan(y[:5]).all() and np.isfinite(y[5:]).all()
    assert ax_f.get_ylim()[0] > -0.5  # the swing is not drawn, and does not set the scale
    saved(fig, tmp_path / "tracked.png")


def test_a_track_plot_stops_at_a_gap_and_keeps_its_labels_in_the_figure(tmp_path):
    from bendsense.tracking import Track

    t = np.concatenate([np.arange(50) * 0.01, 3.0 + np.arange(50) * 0.01])
    est = FakeEstimate(t)
    track = Track(force_n=est.force_n, std_n=est.std_n, covariance_n2=np.zeros((100, 2, 2)), window_p_value=None,
                  status=np.full(100, Status.OK, dtype=np.int8), bandwidth_hz=5.0, mode="filter", t_s=t,
                  frame_force_n=est.force_n)
    ax = track.plot()
    series = [line for line in ax.lines if len(line.get_ydata()) > 2]  # (not the zero line)
    assert len(series) == 4  # Fx and Fy: the per-frame points and the tracked line
    for line in series:
        assert np.flatnonzero(np.isnan(line.get_ydata())).tolist() == [50]
    fig = ax.figure
    fig.canvas.draw()
    inside = fig.bbox
    for label in (ax.xaxis.label, ax.yaxis.label):
        box = label.get_window_extent(fig.canvas.get_renderer())
        assert inside.x0 <= box.x0 and box.x1 <= inside.x1 and inside.y0 <= box.y0 and box.y1 <= inside.y1
    saved(fig, tmp_path / "track.png")

def test_time_series_without_forces(tmp_path):
    session, shape, _ = session_shape_estimate()
    fig = plot_time_series(results_from_state(session, shape))
    assert fig.axes[0].texts[0].get_text() == "no force estimate"
    saved(fig, tmp_path / "series.png")


def fitted_calibration():
    # S = 2e-6 ΔA − 1e-10 ΔA² on odd channels, the negative on even ones
    odd = np.arange(N) % 2 == 0
    radii = [0.04, 0.06, 0.1, 0.2]
    shifts = [np.zeros(N)] + [SENSOR.strip_gap_m * np.cumsum(SENSOR.lengths_m) / r for r in radii]
    delta = [np.where(odd, 1, -1) * s / 2e-6 for s in shifts]
    flat = 1000.0 + np.zeros((5, N)) + delta[0]
    strips = [np.tile(1000.0 + d, (5, 1)) for d in delta[1:]]
    return Calibration.from_data(flat, strips, radii, SENSOR, degree=2), odd


def test_plot_calibration_delegates_and_adds_check_data(tmp_path):
    cal, odd = fitted_calibration()
    check_shift = SENSOR.strip_gap_m * np.cumsum(SENSOR.lengths_m) / 0.08
    check_delta = np.where(odd, 1, -1) * check_shift / 2e-6
    fig = plot_calibration(cal, data=(check_delta[None], check_shift[None]))
    fit_ax, res_ax = fig.axes
    assert labels(fit_ax) == ("", "shift S [mm]")
    assert labels(res_ax) == ("ΔA = A − A0 [signal units]", "residual f(ΔA) − S [µm]")
    crosses = [line for line in fit_ax.lines if line.get_label() == "check data"][0]
    np.testing.assert_allclose(crosses.get_ydata(), check_shift * 1e3)
    np.testing.assert_allclose(res_ax.lines[-1].get_ydata(), 0.0, atol=1e-6)  # an exact fit: zero residual
    saved(fig, tmp_path / "calibration.png")
    _, ax = plt.subplots()
    assert plot_calibration(cal, ax=ax) is ax


def test_plot_results_summary_to_file(results_dir, tmp_path):
    out = tmp_path / "figs" / "summary.png"
    fig = plot_results(results_dir, out, max_shapes=4)
    assert out.read_bytes().startswith(PNG) and out.stat().st_size > 20000
    assert fig not in [plt.figure(n) for n in plt.get_fignums()]  # not registered with pyplot
    ax_s, ax_f, ax_k = fig.axes[:3]
    assert labels(ax_s) == ("x [mm]", "y [mm]")
    assert ax_f.get_ylabel() == "tip force [N]" and labels(ax_k) == ("time [s]", "curvature κ_i [1/m]")
    assert fig.get_suptitle() == f"res: shapes and tip forces of {FRAMES} frames"
    assert [t.get_text() for t in ax_s.get_legend().get_texts()][0] == "tip path"
    renderer = fig._get_renderer()  # the shapes' legend below the panel, over no shape
    assert ax_s.get_legend().get_window_extent(renderer).y1 <= ax_s.get_window_extent(renderer).y0 + 1
    fig2 = plot_results(results_dir, tmp_path / "s2.png", estimated="constraint normal, method fast")
    assert fig2.get_suptitle() == f"res: shapes and tip forces (constraint normal, method fast) of {FRAMES} frames"
    tip = [line for line in ax_s.lines if line.get_label() == "tip path"][0]
    np.testing.assert_allclose(tip.get_xydata()[-1], arc_tip_mm(20.0), rtol=1e-9)
    # vector formats by suffix; unknown suffixes are refused
    plot_results(results_dir, tmp_path / "summary.pdf")
    assert (tmp_path / "summary.pdf").read_bytes().startswith(b"%PDF")
    with pytest.raises(ValueError, match="unknown figure format 'xyz'"):
        plot_results(results_dir, tmp_path / "summary.xyz")
    assert not (tmp_path / "summary.xyz").exists()


# --- the plot command ------------------------------------------------------------------------


def test_cli_plot_standalone(results_dir, tmp_path):
    fig = tmp_path / "fig.png"
    result = CliRunner().invoke(main, ["plot", str(results_dir), "-o", str(fig)])
    assert result.exit_code == 0, result.output
    assert f"wrote {fig}" in result.output and fig.read_bytes().startswith(PNG)
    result = CliRunner().invoke(main, ["plot", str(results_dir), "-o", str(fig)])
    assert result.exit_code == 1 and "exists (use --overwrite" in result.output
    result = CliRunner().invoke(main, ["plot", "-o", str(fig), str(results_dir), "--overwrite", "--dpi", "50"])
    assert result.exit_code == 0, result.output
    # a figure file without a chain, a directory without -o, a non-directory with -o
    result = CliRunner().invoke(main, ["plot", str(tmp_path / "other.png")])
    assert result.exit_code == 2 and "needs 'reconstruct' earlier in the chain" in result.output
    result = CliRunner().invoke(main, ["plot", str(results_dir)])
    assert result.exit_code == 2 and "-o FIG.png" in result.output
    result = CliRunner().invoke(main, ["plot", str(tmp_path / "none"), "-o", str(tmp_path / "x.png")])
    assert result.exit_code == 2 and "none: no such results directory" in result.output
    result = CliRunner().invoke(main, ["plot", str(fig), "-o", str(tmp_path / "x.png")])  # a file
    assert result.exit_code == 2 and "fig.png: not a results directory" in result.output
    result = CliRunner().invoke(main, ["plot", str(results_dir), "-o", str(tmp_path / "fig.doc")])
    assert result.exit_code == 1 and "unknown figure format '.doc' (-o/--output); use one of" in result.output


def test_cli_plot_in_a_chain_after_save(tmp_path):
    # signals of a linear calibration S = ±2e-6 ΔA for curvatures 2..20 1/m
    kappa = uniform_kappa()
    cal = linear_calibration(2e-6, offset=np.full(N, 2000.0), delta_a=5e3, noise_std=None, sensor=None)
    cal.save(tmp_path / "cal.yaml")
    signals = signals_for(kappa, cal, 2e-6)
    write_session_csv(Session(np.arange(FRAMES) * 0.1, signals, np.full(FRAMES, 50e3)), tmp_path / "run.csv")
    fig = tmp_path / "fig.png"
    args = ["load", str(tmp_path / "run.csv"), "--calibration", str(tmp_path / "cal.yaml"), "reconstruct",
            "save", str(tmp_path / "out"), "plot", str(fig)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert fig.read_bytes().startswith(PNG) and (tmp_path / "out" / "results.csv").exists()
    # the chained figure and the standalone figure of the saved results show the same data
    chained = plot_results(results_from_state(*_state(tmp_path, cal)))
    standalone = plot_results(tmp_path / "out")
    for a, b in zip(chained.axes[0].lines, standalone.axes[0].lines, strict=True):
        np.testing.assert_allclose(a.get_xydata(), b.get_xydata(), rtol=1e-12)


def _state(tmp_path, cal):
    from bendsense.session import read_session
    from bendsense.shape.pcc import reconstruct

    session = read_session(tmp_path / "run.csv")
    return session, reconstruct(session.signals, cal, SENSOR)
