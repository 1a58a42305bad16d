"""A contact load where a user looks: results.csv, MCAP, LSL, the figures and the chain's options.

The estimates here are the tip estimates of a simulated session with a contact location
put in (``dataclasses.replace(estimate, load="contact", ...)``): what is tested is what
the outputs do with a location and its σ, not how they were estimated (tests of the
estimate itself: test_contact*.py of the estimator).
"""

import dataclasses
import shutil
import time

import matplotlib
import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.pipeline import process
from bendsense.results import Results, read_results
from bendsense.results.contact import arc_on_shape, point_on_shape
from bendsense.session import Session, write_session_csv
from bendsense.sim.scenarios import time_varying_frames

matplotlib.use("Agg")

SEED = 0
RATE_HZ = 100.0
L = bendsense.load_config().actuator.length_m
TIP_HEADER = ["t_s", "pressure_pa", *(f"kappa{i}" for i in range(1, 17)), "tip_x_m", "tip_y_m", "tip_angle_rad",
              "fx_n", "fy_n", "fx_std_n", "fy_std_n", "residual_m", "status", "window_p_value"]


@pytest.fixture(scope="module")
def work(tmp_path_factory, calibration_path):
    """1.5 s of the virtual sensor's time-varying session (a contact force pressed and released) at 100 Hz,
    processed with the tip load, and the same estimate as a contact: s_c moving from 0.6 L to L, σ 2-6 mm, the
    location unresolved (σ inf) in frames 10-14 and unknown (NaN) in frame 20."""
    root = tmp_path_factory.mktemp("contact-outputs")
    shutil.copyfile(calibration_path, root / "cal.yaml")
    frames = [f for f in time_varying_frames(None, RATE_HZ, SEED, duration_s=3.0)][150:]
    n = len(frames)
    session = Session(1.5 + np.arange(n) / RATE_HZ, np.array([c for _, c in frames], dtype=float),
                      np.array([p for p, _ in frames], dtype=float), source=str(root / "tv.csv"))
    write_session_csv(session, root / "tv.csv")
    processed = process(session, None, Calibration.load(root / "cal.yaml"))
    s_c = np.linspace(0.6 * L, L, n)
    std = np.linspace(0.002, 0.006, n)
    std[10:15] = np.inf
    s_c[20], std[20] = np.nan, np.nan
    contact = dataclasses.replace(processed.estimate, load="contact", contact_s_m=s_c, contact_std_m=std)
    return {"root": root, "processed": processed, "contact": contact}


def _pcc_point(kappa, lengths, s):
    """The point at arc length s of a piecewise-constant-curvature shape from the base (0, 0), angle 0 along +y
    (x toward the centre of curvature), continued straight beyond its end: the closed form of each arc."""
    p, phi = np.zeros(2), 0.0
    for k, length in zip(kappa, lengths):
        d = min(s, length)
        if abs(k) > 1e-12:
            p = p + [(np.cos(phi) - np.cos(phi + k * d)) / k, (np.sin(phi + k * d) - np.sin(phi)) / k]
        else:
            p = p + d * np.array([np.sin(phi), np.cos(phi)])
        phi, s = phi + k * d, s - d
        if s <= 0:
            return p
    return p + s * np.array([np.sin(phi), np.cos(phi)])


def test_a_tip_load_writes_results_as_before(work):
    results = work["processed"]
    assert list(results.columns) == TIP_HEADER and not results.has_contact
    assert "contact_unresolved" not in set(results.columns["status"])


def test_contact_columns_follow_fy_std_n_and_read_back(work, tmp_path):
    processed, contact = work["processed"], work["contact"]
    results = Results.from_state(processed.session, processed.shape, contact)
    header = list(results.columns)
    i = header.index("fy_std_n")
    assert header[i + 1:i + 4] == ["contact_s_m", "contact_std_m", "residual_m"]
    assert header == [*TIP_HEADER[:i + 1], "contact_s_m", "contact_std_m", *TIP_HEADER[i + 1:]]
    results.write(tmp_path / "out")
    back = read_results(tmp_path / "out")
    assert back.has_contact and back.extra_names == ()
    np.testing.assert_array_equal(back["contact_s_m"], contact.contact_s_m)
    np.testing.assert_array_equal(back["contact_std_m"], contact.contact_std_m)
    assert np.isinf(back["contact_std_m"][10:15]).all() and np.isnan(back["contact_s_m"][20])
    # an unresolved location: the force reported, the frame never ok; the others keep the tip estimate's status
    tip_status = np.asarray(processed.columns["status"])
    status = np.asarray(back["status"])
    assert (status[10:15] == np.where(tip_status[10:15] == "ok", "contact_unresolved", tip_status[10:15])).all()
    assert "contact_unresolved" in set(status[10:15])
    others = np.setdiff1d(np.arange(len(status)), np.arange(10, 15))
    assert (status[others] == tip_status[others]).all()
    np.testing.assert_array_equal(back["fx_n"], processed.columns["fx_n"])


def test_a_truth_column_named_contact_s_m_never_poses_as_the_estimate(work):
    processed = work["processed"]
    truth = np.full(len(processed.session), 0.1)
    session = dataclasses.replace(processed.session, extra={"contact_s_m": truth})
    for est in (processed.estimate, work["contact"]):
        results = Results.from_state(session, processed.shape, est)
        np.testing.assert_array_equal(results["input_contact_s_m"], truth)
        assert results.extra_names == ("input_contact_s_m",)


def test_the_point_on_the_shape_is_the_pcc_point_at_s_c(work):
    shape = work["processed"].shape
    lengths = bendsense.load_config().sensor.segment_lengths_m
    k = 30
    # the base, inside segments, at the sensor's end (0.132 m, its last sample) and beyond it (the tip, 0.134 m)
    for s in (0.0, 0.013, 0.6 * L, 0.1005, 0.132, L):
        want = _pcc_point(shape.curvature_per_m[k], lengths, s)
        got = point_on_shape(shape.s_m, shape.positions_m[k], s)
        # 101 samples over 0.13 m: the chord of a sample interval departs from its arc by ~κ h²/8 ~ 6 µm
        np.testing.assert_allclose(got, want, atol=1e-5)
    frames = shape.positions_m.shape[0]
    pts = point_on_shape(shape.s_m, shape.positions_m, np.full(frames, 0.6 * L))
    assert pts.shape == (frames, 2)
    np.testing.assert_array_equal(pts[k], point_on_shape(shape.s_m, shape.positions_m[k], 0.6 * L))
    assert np.isnan(point_on_shape(shape.s_m, shape.positions_m[k], np.nan)).all()
    arc = arc_on_shape(shape.s_m, shape.positions_m[k], 0.08, 0.09)
    np.testing.assert_allclose(arc[0], _pcc_point(shape.curvature_per_m[k], lengths, 0.08), atol=1e-5)
    np.testing.assert_allclose(arc[-1], _pcc_point(shape.curvature_per_m[k], lengths, 0.09), atol=1e-5)
    assert arc_on_shape(shape.s_m, shape.positions_m[k], 0.08, np.inf).shape == (0, 2)


def test_mcap_has_the_contact_point_of_resolved_frames(work, tmp_path):
    from mcap_ros2.reader import read_ros2_messages

    from bendsense.interop.ros2 import write_mcap

    processed, contact = work["processed"], work["contact"]
    write_mcap(tmp_path / "c.mcap", processed.session, processed.shape, contact)
    by_topic = {}
    for m in read_ros2_messages(str(tmp_path / "c.mcap")):
        by_topic.setdefault(m.channel.topic, []).append(m)
    points = by_topic["/bendsense/contact"]
    n = len(processed.session)
    resolved = [k for k in range(n) if k not in (*range(10, 15), 20)]
    assert len(points) == len(resolved)
    assert {m.schema.name for m in points} == {"geometry_msgs/msg/PointStamped"}
    assert {m.ros_msg.header.frame_id for m in points} == {"bendsense_base"}
    stamps = [m.ros_msg.header.stamp.sec + 1e-9 * m.ros_msg.header.stamp.nanosec for m in points]
    np.testing.assert_allclose(stamps, processed.session.t_s[resolved], atol=1e-9)
    lengths = bendsense.load_config().sensor.segment_lengths_m
    got = np.array([[m.ros_msg.point.x, m.ros_msg.point.y, m.ros_msg.point.z] for m in points])
    want = np.array([_pcc_point(processed.shape.curvature_per_m[k], lengths, contact.contact_s_m[k])
                     for k in resolved])
    np.testing.assert_allclose(got[:, :2], want, atol=1e-5)
    assert (got[:, 2] == 0).all()
    status = by_topic["/bendsense/status"]
    values = {kv.key: kv.value for kv in status[12].ros_msg.status[0].values}
    assert values["contact_std_m"] == "inf" and float(values["contact_s_m"]) == contact.contact_s_m[12]
    assert status[12].ros_msg.status[0].level in (1, 2)
    # a tip load: no contact topic, and no PointStamped schema in the file
    write_mcap(tmp_path / "tip.mcap", processed.session, processed.shape, processed.estimate)
    from mcap.reader import make_reader

    with open(tmp_path / "tip.mcap", "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert "/bendsense/contact" not in {c.topic for c in summary.channels.values()}
    assert "geometry_msgs/msg/PointStamped" not in {s.name for s in summary.schemas.values()}


def _block(processed, est, lo, hi, load):
    from bendsense._batched import take_frames
    from bendsense.pipeline import LiveBlock

    n = len(processed.session)
    est = None if est is None else dataclasses.replace(est, window_p_value=None)  # (the live path tracks instead)
    return LiveBlock(t_s=processed.session.t_s[lo:hi], seq=np.arange(lo, hi), host_ns=time.monotonic_ns()
                     + np.arange(hi - lo) * 1_000_000, pressure_pa=processed.session.pressure_pa[lo:hi],
                     signals=processed.session.signals[lo:hi], shape=take_frames(processed.shape, slice(lo, hi), n),
                     estimate=None if est is None else take_frames(est, slice(lo, hi), n), estimated=True,
                     process_s=0.0, offset=np.zeros(16), load=load)


def test_lsl_force_stream_carries_the_contact_after_its_channels(work):
    import pylsl

    from bendsense.interop.lsl import LslOutlets

    processed, contact = work["processed"], work["contact"]
    outlets = LslOutlets(16, 100.0, source_id=f"contact-test-{time.monotonic_ns()}", contact=True)
    try:
        found = pylsl.resolve_bypred(f"source_id='{outlets.force.get_info().source_id()}'", 1, 30)
        assert found
        inlet = pylsl.StreamInlet(found[0], max_buflen=60)
        inlet.open_stream(timeout=10)
        info = inlet.info(timeout=10)
        time.sleep(0.5)
        outlets.push(_block(processed, contact, 0, 25, "contact"))
        outlets.push(_block(processed, None, 25, 30, "contact"))  # a block without an estimate: NaN
        got, deadline = [], time.monotonic() + 30
        while len(got) < 30 and time.monotonic() < deadline:
            chunk, _ = inlet.pull_chunk(timeout=0.2)
            got += chunk
    finally:
        outlets.close()
    ch = info.desc().child("channels").child("channel")
    labels = []
    while not ch.empty():
        labels.append((ch.child_value("label"), ch.child_value("unit")))
        ch = ch.next_sibling()
    assert labels == [("fx_n", "N"), ("fy_n", "N"), ("fx_std_n", "N"), ("fy_std_n", "N"), ("contact_s_m", "m"),
                      ("contact_std_m", "m")]
    got = np.array(got)
    assert got.shape == (30, 6)
    np.testing.assert_array_equal(got[:25, 4], contact.contact_s_m[:25])
    np.testing.assert_array_equal(got[:25, 5], contact.contact_std_m[:25])
    np.testing.assert_array_equal(got[:25, 0], contact.force_n[:25, 0])
    assert np.isnan(got[25:, 4:]).all()


def test_live_block_without_an_estimate_keeps_the_contact_columns(work):
    processed, contact = work["processed"], work["contact"]
    with_est = _block(processed, contact, 0, 5, "contact").columns()
    without = _block(processed, None, 5, 10, "contact").columns()
    assert list(with_est) == list(without)
    assert np.isnan(without["contact_s_m"]).all() and np.isnan(without["contact_std_m"]).all()
    tip = _block(processed, None, 5, 10, "tip").columns()
    assert "contact_s_m" not in tip


@pytest.mark.parametrize("value, reason", [
    ("0", "expected > 0, got 0"), ("-0.01", "expected > 0"), ("abc", "'abc' is not a valid float"),
    ("nan", "expected a finite number"), ("0.2", "expected 0 < s_c <= L = 0.134 m"),
])
def test_a_bad_contact_location_is_one_line(work, value, reason):
    root = work["root"]
    res = CliRunner().invoke(main, ["load", str(root / "tv.csv"), "--calibration", str(root / "cal.yaml"),
                                    "reconstruct", "estimate", "--load", "contact", "--contact-s-m", value,
                                    "save", str(root / "never")])
    lines = res.output.strip().splitlines()
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert lines[0].startswith("Error: Invalid value for '--contact-s-m'") and reason in lines[0], lines[0]
    assert not (root / "never").exists()


def test_a_location_without_a_contact_load_is_refused(work):
    root = work["root"]
    res = CliRunner().invoke(main, ["load", str(root / "tv.csv"), "--calibration", str(root / "cal.yaml"),
                                    "reconstruct", "estimate", "--contact-s-m", "0.1"])
    assert res.exit_code == 2
    assert res.output.strip() == ("Error: Invalid value for '--contact-s-m': a contact location needs "
                                  "--load contact")
    res = CliRunner().invoke(main, ["record", "/dev/null", "-o", str(root / "rec"), "--calibration",
                                    str(root / "cal.yaml"), "--load", "contact", "--contact-s-m", "0.1"])
    assert res.exit_code == 2 and "a load model needs --estimate" in res.output
    res = CliRunner().invoke(main, ["record", "/dev/null", "-o", str(root / "rec"), "--calibration",
                                    str(root / "cal.yaml"), "--estimate", "--load", "contact"])
    assert res.exit_code == 2 and "needs the known location --contact-s-m" in res.output, res.output
    assert not (root / "rec").exists()


def test_summary_figure_draws_the_contact_on_the_shapes_and_over_time(work, tmp_path):
    from bendsense.plots import plot_results

    processed, contact = work["processed"], work["contact"]
    results = Results.from_state(processed.session, processed.shape, contact)
    fig = plot_results(results, tmp_path / "c.png", max_shapes=6, length_m=L)
    assert (tmp_path / "c.png").stat().st_size > 10_000
    by_label = {ax.get_ylabel(): ax for ax in fig.axes}
    ax_c, ax_s = by_label["contact s_c [mm]"], by_label["y [mm]"]
    assert "contact force [N]" in by_label
    # s_c over time: the line is the location in mm where it is resolved, a gap where it is not
    line = next(a for a in ax_c.get_lines() if a.get_label().startswith("contact s_c"))
    y = np.asarray(line.get_ydata(), dtype=float)
    np.testing.assert_allclose(y[:10], contact.contact_s_m[:10] * 1e3)
    assert np.isnan(y[10:15]).all() and np.isnan(y[20])
    # on the shapes: one diamond per drawn frame at the shape's point at s_c (frames 0, 30, 60, ... of 150)
    idx = np.unique(np.linspace(0, len(results["t_s"]) - 1, 6).round().astype(int))
    diamonds = [a for a in ax_s.get_lines() if a.get_marker() == "D"]
    assert len(diamonds) == len(idx)
    got = np.array([[a.get_xdata()[0], a.get_ydata()[0]] for a in diamonds])
    want = point_on_shape(processed.shape.s_m, processed.shape.positions_m[idx], contact.contact_s_m[idx]) * 1e3
    np.testing.assert_allclose(got, want)
    # a tip load: no contact panel
    tip = plot_results(Results.from_state(processed.session, processed.shape, processed.estimate),
                       tmp_path / "t.png")
    assert "contact s_c [mm]" not in {ax.get_ylabel() for ax in tip.axes}


def test_time_series_names_the_load(work):
    from bendsense.plots import plot_time_series

    processed, contact = work["processed"], work["contact"]
    ylabel = {load: plot_time_series(Results.from_state(processed.session, processed.shape, est)).axes[0].get_ylabel()
              for load, est in (("tip", processed.estimate), ("contact", contact))}
    assert ylabel == {"tip": "tip force [N]", "contact": "contact force [N]"}


def test_live_view_draws_the_contact_point_and_its_arc(work, tmp_path):
    from bendsense.apps.live_view import LiveView
    from bendsense.pipeline import LiveProcessor

    processed, contact = work["processed"], work["contact"]
    proc = LiveProcessor(Calibration.load(work["root"] / "cal.yaml"), load="contact", contact_s_m=0.1)
    view = LiveView(proc, headless=True)
    block = _block(processed, contact, 30, 40, "contact")
    view.update_block(block)
    frame = block.frame(-1)
    s_c, sd = contact.contact_s_m[39], contact.contact_std_m[39]
    want = point_on_shape(frame.shape.s_m, frame.shape.positions_m, s_c) * 1e3
    np.testing.assert_allclose([view.contact_marker.get_xdata()[0], view.contact_marker.get_ydata()[0]], want)
    np.testing.assert_allclose(view.arrow._posA_posB[0], want)  # the arrow starts at the contact (no public getter)
    arc = np.column_stack([view.contact_arc.get_xdata(), view.contact_arc.get_ydata()])
    np.testing.assert_allclose(arc[0], point_on_shape(frame.shape.s_m, frame.shape.positions_m, s_c - 2 * sd) * 1e3)
    assert f"s_c = {s_c * 1e3:.1f} mm (± {sd * 1e3:.1f} mm)" in view.force_text.get_text()
    view.update_block(_block(processed, contact, 10, 15, "contact"))  # unresolved: a hollow point, no arc
    assert view.contact_marker.get_markerfacecolor() == "none" and len(view.contact_arc.get_xdata()) == 0
    assert "unresolved" in view.force_text.get_text()
    view.save(tmp_path / "live.png")


def test_process_checks_the_load_options_before_any_work(work, tmp_path):
    root = work["root"]
    base = ["process", str(root / "tv.csv"), "--calibration", str(root / "cal.yaml"), "-o", str(tmp_path / "out"),
            "--workers", "0", "--no-progress"]
    res = CliRunner().invoke(main, [*base, "--load", "contact", "--contact-s-m", "0.5"])
    assert res.exit_code == 2 and res.output.strip() == (
        "Error: Invalid value for '--contact-s-m': expected 0 < s_c <= L = 0.134 m (actuator.length_m, arc length "
        "from the base), got 0.5")
    res = CliRunner().invoke(main, [*base, "--no-estimate", "--load", "contact"])
    assert res.exit_code == 2 and "--load and --contact-s-m are options of the force estimate" in res.output
    assert not (tmp_path / "out").exists()


def test_one_frame_of_a_contact_draws_its_arrow_at_the_contact(work):
    from bendsense._batched import take_frames

    processed, contact = work["processed"], work["contact"]
    n = len(processed.session)
    shape, est = take_frames(processed.shape, 40, n), take_frames(contact, 40, n)
    ax = est.plot(shape=shape)
    s_c, sd = contact.contact_s_m[40], contact.contact_std_m[40]
    assert ax.get_title().endswith(f"at s_c = {s_c * 1e3:.1f} ± {sd * 1e3:.1f} mm")
    start = np.asarray(ax.texts[0].xyann if hasattr(ax.texts[0], "xyann") else ax.texts[0].xytext, dtype=float)
    np.testing.assert_allclose(start, point_on_shape(shape.s_m, shape.positions_m, s_c) * 1e3)
    tip_ax = take_frames(processed.estimate, 40, n).plot(shape=shape)
    assert "s_c" not in tip_ax.get_title()


def test_record_and_live_publish_the_contact_channels_of_a_contact_processor(work):
    """``record --lsl``/``live --lsl`` make their outlets from the processor: a contact load adds its channels."""
    import types

    from bendsense.cli.device import make_outlets
    from bendsense.pipeline import LiveProcessor

    cal = Calibration.load(work["root"] / "cal.yaml")
    board = types.SimpleNamespace(hello=None)
    for options, contact in (({}, False), ({"load": "contact", "contact_s_m": 0.1}, True)):
        outlets = make_outlets(LiveProcessor(cal, **options), board, f"test-{time.monotonic_ns()}")
        try:
            info = outlets.force.get_info()
            assert outlets.contact is contact and info.channel_count() == 8 + 2 * contact
            assert (info.desc().child_value("contact_s_m") == "0.1 (known)") is contact
        finally:
            outlets.close()


def test_an_unknown_location_with_the_paper_method_is_one_line(work):
    root = work["root"]
    res = CliRunner().invoke(main, ["load", str(root / "tv.csv"), "--calibration", str(root / "cal.yaml"),
                                    "reconstruct", "estimate", "--load", "contact", "--method", "paper"])
    assert res.exit_code == 1 and res.output.strip() == (
        "Error: method: an unknown contact location is estimated with method 'fast' only, got 'paper' (with a "
        "known contact_s_m any method)")
