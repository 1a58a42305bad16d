"""Third-party readers of what bendsense writes: ROS 2 messages in MCAP (``mcap_ros2``), LSL inlets (``pylsl``)."""

import csv
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from bendsense.cli import main
from bendsense.results import read_results
from bendsense.session import Session, write_session_csv
from bendsense.sim.scenarios import time_varying_frames

SEED = 0


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, calibration_path):
    """The virtual sensor's calibration and 1.2 s of its time-varying session at 50 Hz, as a session CSV."""
    root = tmp_path_factory.mktemp("interop")
    shutil.copyfile(calibration_path, root / "cal.yaml")
    frames = list(time_varying_frames(None, 50.0, SEED, duration_s=1.2))
    n = len(frames)
    pressure = np.array([p for p, _ in frames], dtype=float)
    pressure[3] = np.nan  # one frame without a reading: no FluidPressure for it
    session = Session(1.5 + np.arange(n) / 50.0, np.array([c for _, c in frames]), pressure)
    write_session_csv(session, root / "tv.csv")
    return root


def test_mcap_wrench_per_frame_equals_results_csv(workdir):
    from mcap_ros2.reader import read_ros2_messages

    res = CliRunner().invoke(main, [
        "load", str(workdir / "tv.csv"), "--calibration", str(workdir / "cal.yaml"), "--pressure-kpa", "40",
        "reconstruct", "--points", "21", "estimate", "--constraint", "normal",
        "save", str(workdir / "out"), "mcap", str(workdir / "out.mcap"),
    ])
    assert res.exit_code == 0, res.output
    results = read_results(workdir / "out")
    by_topic = {}
    for m in read_ros2_messages(str(workdir / "out.mcap")):
        by_topic.setdefault(m.channel.topic, []).append(m)
    wrench = by_topic["/bendsense/wrench"]
    n = len(results["t_s"])
    assert len(wrench) == n
    assert {m.schema.name for m in wrench} == {"geometry_msgs/msg/WrenchStamped"}
    force = np.array([[m.ros_msg.wrench.force.x, m.ros_msg.wrench.force.y, m.ros_msg.wrench.force.z]
                      for m in wrench])
    np.testing.assert_array_equal(force[:, 0], results["fx_n"])
    np.testing.assert_array_equal(force[:, 1], results["fy_n"])
    assert np.all(force[:, 2] == 0) and np.any(np.abs(force[:, :2]) > 1e-3)
    # stamps from the session's time (a CSV: t_s itself), in header and log time alike
    stamp = np.array([m.ros_msg.header.stamp.sec + 1e-9 * m.ros_msg.header.stamp.nanosec for m in wrench])
    np.testing.assert_allclose(stamp, results["t_s"], atol=1e-9)
    np.testing.assert_allclose([m.log_time_ns * 1e-9 for m in wrench], results["t_s"], atol=1e-9)
    assert {m.ros_msg.header.frame_id for m in wrench} == {"bendsense_base"}

    std = by_topic["/bendsense/force_std"]
    np.testing.assert_array_equal([m.ros_msg.vector.x for m in std], results["fx_std_n"])
    np.testing.assert_array_equal([m.ros_msg.vector.y for m in std], results["fy_std_n"])
    status = by_topic["/bendsense/status"]
    assert [m.ros_msg.status[0].message for m in status] == list(results["status"])
    levels = {"ok": 0, "extrapolated": 1, "model_misfit": 1, "not_identifiable": 1, "not_converged": 2}
    assert [m.ros_msg.status[0].level for m in status] == [levels[s] for s in results["status"]]

    # the shape: one pose per arc-length sample, at the positions of shape.npz
    shape = by_topic["/bendsense/shape"]
    assert len(shape) == n and shape[0].schema.name == "nav_msgs/msg/Path"
    for k in (0, n - 1):
        pos = np.array([[p.pose.position.x, p.pose.position.y] for p in shape[k].ros_msg.poses])
        np.testing.assert_array_equal(pos, results.positions_m[k])
        # orientation: the tangent; its yaw from +x is pi/2 - tip angle at the tip
        q = shape[k].ros_msg.poses[-1].pose.orientation
        yaw = 2 * np.arctan2(q.z, q.w)
        assert abs(np.angle(np.exp(1j * (yaw - (np.pi / 2 - results["tip_angle_rad"][k]))))) < 0.05
    pressure = by_topic["/bendsense/pressure"]
    assert len(pressure) == n  # --pressure-kpa filled the frame without a reading
    np.testing.assert_array_equal([m.ros_msg.fluid_pressure for m in pressure], results["pressure_pa"])
    assert pressure[3].ros_msg.fluid_pressure == 40e3


def test_mcap_stamps_of_a_recorded_session_are_exact_to_the_nanosecond(workdir):
    """A recorded session: stamps = its start time (meta.yaml) + t_s, in integer ns (no float rounding)."""
    import calendar
    import dataclasses

    from mcap_ros2.reader import read_ros2_messages

    import bendsense
    from bendsense.interop.ros2 import write_mcap

    csv_session = bendsense.read_session(workdir / "tv.csv")
    t_s = 5.000123 + np.arange(len(csv_session)) * 0.001  # a 1 kHz device clock; stamps count from its first frame
    session = dataclasses.replace(csv_session, t_s=t_s, meta={"start_time_utc": "2026-03-04T05:06:07.891011Z"})
    shape = bendsense.reconstruct(session.signals, bendsense.Calibration.load(workdir / "cal.yaml"),
                                  bendsense.load_config().sensor)
    write_mcap(workdir / "stamps.mcap", session, shape)
    start_ns = calendar.timegm((2026, 3, 4, 5, 6, 7)) * 10**9 + 891_011_000
    expected = [start_ns + k * 1_000_000 for k in range(len(session))]
    msgs = list(read_ros2_messages(str(workdir / "stamps.mcap"), topics=["/bendsense/shape"]))
    assert [m.ros_msg.header.stamp.sec * 10**9 + m.ros_msg.header.stamp.nanosec for m in msgs] == expected
    assert [m.log_time_ns for m in msgs] == expected


def test_mcap_after_reconstruct_only_and_overwrite(workdir):
    out = workdir / "shape.mcap"
    args = ["load", str(workdir / "tv.csv"), "--calibration", str(workdir / "cal.yaml"), "reconstruct",
            "--points", "5", "mcap", str(out)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    from mcap_ros2.reader import read_ros2_messages

    topics = [m.channel.topic for m in read_ros2_messages(str(out))]
    assert "/bendsense/wrench" not in topics and topics.count("/bendsense/shape") == 60
    assert topics.count("/bendsense/pressure") == 59  # the frame without a reading has none
    before = out.read_bytes()
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and "use --overwrite" in res.output and out.read_bytes() == before
    res = CliRunner().invoke(main, ["load", str(workdir / "tv.csv"), "mcap", str(workdir / "fresh.mcap")])
    assert res.exit_code == 2 and "'mcap' needs 'reconstruct'" in res.output


def test_mcap_without_the_extra_names_it(workdir, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "mcap_ros2.writer", None)  # as if not installed
    out = workdir / "none.mcap"
    res = CliRunner().invoke(main, ["load", str(workdir / "tv.csv"), "--calibration", str(workdir / "cal.yaml"),
                                    "reconstruct", "mcap", str(out)])
    assert res.exit_code == 1 and not out.exists()
    assert res.output.strip().splitlines() == [
        "Error: the mcap step needs the optional extra 'ros' (mcap_ros2.writer is not installed): "
        "pip install '.[ros]' in bendsense's source directory "
        "(from a package index: 'bendsense[ros]')"
    ]


def test_mcap_without_the_extra_stops_the_chain_before_any_step(workdir, monkeypatch):
    """The missing extra is named before the chain's steps ran: the 'save' before 'mcap' wrote nothing."""
    monkeypatch.setitem(sys.modules, "mcap", None)  # as if not installed
    out = workdir / "not-saved"
    res = CliRunner().invoke(main, ["load", str(workdir / "tv.csv"), "--calibration", str(workdir / "cal.yaml"),
                                    "reconstruct", "save", str(out), "mcap", str(workdir / "none.mcap")])
    assert res.exit_code == 1
    assert res.output.strip().splitlines() == [
        "Error: the mcap step needs the optional extra 'ros' (mcap is not installed): pip install '.[ros]' in "
        "bendsense's source directory (from a package index: 'bendsense[ros]')"
    ]
    assert not out.exists() and not (workdir / "none.mcap").exists()


CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


def pull_all(inlets, proc, idle_s=2.0):
    """Samples and time stamps of each inlet until ``proc`` ended and nothing came for ``idle_s``."""
    data = [[] for _ in inlets]
    stamps = [[] for _ in inlets]
    last = time.monotonic()
    while True:
        got = False
        for inlet, d, st in zip(inlets, data, stamps):
            chunk, ts = inlet.pull_chunk(timeout=0.1, max_samples=4096)
            if chunk:
                d += chunk
                st += ts
                got = True
        if got:
            last = time.monotonic()
        elif proc.poll() is not None and time.monotonic() - last > idle_s:
            return [(np.array(d), np.array(st)) for d, st in zip(data, stamps)]
        assert time.monotonic() - last < 60, "no samples for a minute"


@pytest.mark.realtime
def test_lsl_inlet_receives_every_force_sample_of_a_1khz_recording(workdir, tmp_path):
    import pylsl

    from bendsense.device.simdevice import SimulatedDevice, default_source

    out = tmp_path / "s"
    with SimulatedDevice(default_source(rate_hz=1000, seed=SEED), rate_hz=1000) as dev:
        with open(tmp_path / "stderr.txt", "wb") as err, subprocess.Popen(
            [*CLI, "-q", "record", dev.port, "-o", str(out), "--seconds", "3", "--calibration",
             str(workdir / "cal.yaml"), "--estimate", "--lsl", "--lsl-wait", "30", "--quiet-status"],
            stdout=subprocess.DEVNULL, stderr=err
        ) as proc:
            try:
                # this recording's streams (the port is in their source id), not another test's running beside it
                found = pylsl.resolve_bypred(f"name='bendsense-force' and source_id='bendsense {dev.port}-force'", 1,
                                             30.0)
                assert found, "no bendsense-force stream"
                shapes = pylsl.resolve_bypred(f"name='bendsense-shape' and source_id='bendsense {dev.port}-shape'", 1,
                                              10.0)
                force_in = pylsl.StreamInlet(found[0], max_buflen=60)
                shape_in = pylsl.StreamInlet(shapes[0], max_buflen=60)
                # the shape stream first: --lsl-wait starts the board when the force stream has a consumer, and a
                # shape inlet subscribed after that would miss the first frames' shapes (a loaded machine, ~5)
                shape_in.open_stream(timeout=10)
                force_in.open_stream(timeout=10)
                info, sinfo = force_in.info(timeout=10), shape_in.info(timeout=10)
                (force, stamps), (shape, _) = pull_all([force_in, shape_in], proc)
                proc.wait(30)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            assert proc.returncode == 0, (tmp_path / "stderr.txt").read_text()
    assert (info.type(), info.channel_count(), info.nominal_srate()) == ("Force", 8, 1000.0)
    ch = info.desc().child("channels").child("channel")
    labels, units = [], []
    while not ch.empty():
        labels.append(ch.child_value("label"))
        units.append(ch.child_value("unit"))
        ch = ch.next_sibling()
    # the per-frame force, then the causally tracked one
    assert labels == ["fx_n", "fy_n", "fx_std_n", "fy_std_n", "fx_track_n", "fy_track_n", "fx_track_std_n",
                      "fy_track_std_n"] and units == ["N"] * 8
    from bendsense.tracking import DEFAULT_BANDWIDTH_HZ

    assert info.desc().child_value("track") == f"filter, bandwidth {DEFAULT_BANDWIDTH_HZ:g} Hz"
    assert sinfo.type() == "Shape" and sinfo.channel_count() == 16 + 3
    header, rows = None, None
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    header, rows = rows[0], rows[1:]
    results = {h: np.array([r[i] for r in rows]) for i, h in enumerate(header)}
    n = len(rows)
    assert n > 1000  # ~3 s of a 1 kHz board (the simulated one lags on a busy machine)
    assert len(force) >= 0.99 * n
    # the samples are the results, in order (the first ones sent are the first recorded)
    m = min(len(force), n)
    want = np.column_stack([results[c][:m].astype(float) for c in ("fx_n", "fy_n", "fx_std_n", "fy_std_n",
                                                                     "fx_track_n", "fy_track_n", "fx_track_std_n",
                                                                     "fy_track_std_n")])
    np.testing.assert_allclose(force[:m], want, rtol=0, atol=1e-12, equal_nan=True)
    # the track starts within its first 0.4 s of frames and then holds (a fraction of the whole would depend on
    # how many frames a loaded machine let the board make)
    tracked = np.isfinite(force[:m, 4:]).all(axis=1)
    assert tracked.any() and np.argmax(tracked) < 400 and tracked[np.argmax(tracked):].mean() > 0.9
    np.testing.assert_allclose(shape[:m, -3], results["tip_x_m"][:m].astype(float), atol=1e-15)
    # time stamps: arrival times on the LSL clock, in order, about 1 ms apart
    assert np.all(np.diff(stamps) >= 0)
    assert 0.5e-3 < np.median(np.diff(stamps)) < 2e-3 or np.percentile(np.diff(stamps), 90) < 0.05
    assert abs(stamps[-1] - pylsl.local_clock()) < 60


def test_lsl_without_the_extra_names_it(workdir, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "pylsl", None)  # as if not installed
    res = CliRunner().invoke(main, ["record", "/dev/null", "-o", str(tmp_path / "s"), "--calibration",
                                    str(workdir / "cal.yaml"), "--lsl"])
    assert res.exit_code == 1 and not (tmp_path / "s").exists()
    assert res.output.strip().splitlines() == [
        "Error: --lsl needs the optional extra 'lsl' (pylsl is not installed): pip install '.[lsl]' in "
        "bendsense's source directory (from a package index: 'bendsense[lsl]')"]


@pytest.mark.parametrize("command", ["live", "record"])
@pytest.mark.parametrize("wait", ["nan", "-1", "inf"])
def test_lsl_wait_must_be_a_finite_time(command, wait, tmp_path):
    # NaN and a negative wait were taken as no wait, inf waited for a consumer until killed
    extra = ["-o", str(tmp_path / "s")] if command == "record" else []
    res = CliRunner().invoke(main, [command, "/dev/null", *extra, "--lsl", "--lsl-wait", wait])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert "Invalid value for '--lsl-wait'" in res.output and not (tmp_path / "s").exists()
