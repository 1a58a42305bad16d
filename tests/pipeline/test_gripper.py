"""A gripper live (issue 24): a processor per finger over the board's readings, its outputs per finger.

The reference of every test is the single-actuator code run on each finger's own part of
the board, cut here by hand (the finger's channels, its line's pressure), never numbers the
gripper code printed.
"""

import itertools
import time

import numpy as np
import pytest

from bendsense.calibration import Calibration
from bendsense.config import Finger, GripperConfig
from bendsense.device.driver import Reading
from bendsense.pipeline import LiveProcessor
from bendsense.pipeline.gripper import GripperProcessor
from bendsense.sim.scenarios import time_varying_frames
from bendsense.status import Status
from bendsense.wire.frames import decode_frame, encode_sample

pytestmark = pytest.mark.realtime  # a simulated board against the live path at its frame rate

# the board: index on channels 1..16 (line 0), thumb on 33..48 in reverse board order (line 1), middle on
# 17..32 sharing the thumb's line; 48 channels, two lines
MAP = {"index": (list(range(1, 17)), 0), "thumb": (list(range(48, 32, -1)), 1), "middle": (list(range(17, 33)), 1)}
RATE_HZ = 1000.0
CONTACT_S_M = 0.1  # where the simulated object touches every finger
N_FRAMES = 120


@pytest.fixture(scope="module")
def gripper(config):
    return GripperConfig(name="test-gripper", fingers=tuple(
        Finger(name=name, channels=tuple(ch), pressure_line=line, config=config) for name, (ch, line) in MAP.items()))


@pytest.fixture(scope="module")
def board():
    """Each finger's frames of the virtual sensor (another seed each), and the board's readings of them (SAMPLE v2)."""
    stream = list(itertools.islice(time_varying_frames(None, RATE_HZ, 0), 3 * N_FRAMES))
    # the virtual sensor of the calibration (seed 0), another stretch of its frames per finger; the middle finger
    # two frames behind the thumb, whose line it reads
    own = {"index": stream[:N_FRAMES], "thumb": stream[N_FRAMES:2 * N_FRAMES],
           "middle": stream[N_FRAMES - 2:2 * N_FRAMES - 2]}
    readings = []
    for k in range(N_FRAMES):
        adc = np.zeros(48, dtype=int)
        lines = [np.nan, np.nan]
        for name, (channels, line) in MAP.items():
            p, counts = own[name][k]
            adc[np.array(channels) - 1] = counts
            if name != "middle":  # the middle finger reads the thumb's line
                lines[line] = p
        if k == 5:
            lines[1] = None  # a frame without a reading of line 1
        wire = encode_sample(k, 1_000_000 + 1000 * k, adc.tolist(), pressures_pa=lines)
        sample = decode_frame(wire)
        readings.append(Reading(host_ns=10**12 + 10**6 * k, device_us=1_000_000 + 1000 * k, sample=sample))
    return readings


def finger_readings(readings, name):
    """The readings a board holding only this finger would send: its channels, its line as the pressure."""
    channels, line = MAP[name]
    out = []
    for r in readings:
        s = r.sample
        adc = [s.adc[c - 1] for c in channels]
        p = s.pressures_pa[line]
        sample = decode_frame(encode_sample(s.seq, s.t_us, adc, p, status=s.status, tx_drops=s.tx_drops))
        out.append(Reading(host_ns=r.host_ns, device_us=r.device_us, sample=sample))
    return out


def assert_same_block(got, want):
    a, b = got.columns(), want.columns()
    assert list(a) == list(b)
    for name in a:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)


def test_each_finger_block_equals_a_single_processor_on_its_split_readings(calibration_path, gripper, board):
    cal = Calibration.load(calibration_path)
    proc = GripperProcessor(cal, gripper, constraint="normal")
    assert proc.fingers == ("index", "thumb", "middle") and set(proc.processors) == set(MAP)
    single = {name: LiveProcessor(cal, gripper.finger(name).config, constraint="normal") for name in MAP}
    parts = {name: finger_readings(board, name) for name in MAP}
    cuts = [0, 1, 8, 38, 39, 90, N_FRAMES]  # blocks of 1, 7, 30, 1, 51 and 30 frames: warm starts, track across
    for lo, hi in itertools.pairwise(cuts):
        blocks = proc.process_readings(board[lo:hi])
        assert list(blocks) == ["index", "thumb", "middle"]
        for name in MAP:
            want = single[name].process_readings(parts[name][lo:hi])
            assert_same_block(blocks[name], want)
            # the finger's channels of the board, in the sensor's order (an independent cut)
            np.testing.assert_array_equal(blocks[name].signals,
                                          [[r.sample.adc[c - 1] for c in MAP[name][0]] for r in board[lo:hi]])
    assert proc.frames == N_FRAMES
    assert proc.estimated == sum(p.estimated for p in single.values())
    assert proc.status_counts == {s: sum(p.status_counts.get(s, 0) for p in single.values())
                                  for s in set().union(*(p.status_counts for p in single.values()))}
    for name in ("index", "thumb"):  # not a comparison of two failures
        assert proc.processors[name].status_counts.get("ok", 0) > 0.9 * N_FRAMES, name
    # the shared line: the middle finger is estimated at the thumb's pressure, frame 5 has none for both
    np.testing.assert_array_equal(blocks["middle"].pressure_pa, blocks["thumb"].pressure_pa)
    first = proc.processors["thumb"]
    assert first.frames == N_FRAMES


def test_reset_and_warm_up_start_every_finger_over(calibration_path, gripper, board):
    cal = Calibration.load(calibration_path)
    proc = GripperProcessor(cal, gripper)
    proc.warm_up()
    assert proc.frames == 0 and proc.estimated == 0 and proc.status_counts == {}
    first = proc.process_readings(board[:20])
    proc.process_readings(board[20:40])
    proc.reset()
    again = proc.process_readings(board[:20])  # the same frames, from the same time origin, cold again
    for name in MAP:
        assert_same_block(again[name], first[name])


def test_a_line_the_board_does_not_send(calibration_path, gripper, board):
    cal = Calibration.load(calibration_path)
    one_line = [Reading(r.host_ns, r.device_us, decode_frame(encode_sample(r.sample.seq, r.sample.t_us,
                                                                           list(r.sample.adc), 80e3)))
                for r in board[:4]]  # version-1 frames: line 0 only
    with pytest.raises(Exception, match="line 1") as err:
        GripperProcessor(cal, gripper).process_readings(one_line)
    assert "thumb" in str(err.value) or "middle" in str(err.value)
    # with a fallback pressure, the missing line's frames take it; line 0 keeps its reading
    blocks = GripperProcessor(cal, gripper, pressure_pa=50e3).process_readings(one_line)
    np.testing.assert_array_equal(blocks["index"].pressure_pa, 80e3)
    np.testing.assert_array_equal(blocks["thumb"].pressure_pa, 50e3)


def test_finger_options_and_calibrations_per_finger(calibration_path, gripper, board):
    cal = Calibration.load(calibration_path)
    proc = GripperProcessor({name: calibration_path for name in MAP}, gripper, constraint="normal",
                            finger_options={"thumb": {"constraint": "none"}})
    assert [proc.processors[n].constraint for n in MAP] == ["normal", "none", "normal"]
    np.testing.assert_array_equal(proc.processors["middle"].calibration.offset, cal.offset)
    with pytest.raises(Exception, match="finger_options: unknown finger pinky"):
        GripperProcessor(cal, gripper, finger_options={"pinky": {}})
    with pytest.raises(ValueError, match="gripper: expected a GripperConfig .* got Config"):
        GripperProcessor(cal, gripper.finger("thumb").config)


def test_lsl_streams_per_finger_reach_an_inlet(calibration_path, gripper, board):
    pylsl = pytest.importorskip("pylsl")
    import uuid
    from types import SimpleNamespace

    from bendsense.cli.device import make_outlets

    cal = Calibration.load(calibration_path)
    proc = GripperProcessor(cal, gripper)
    port = f"test-{uuid.uuid4().hex[:8]}"  # the streams' source id: bendsense <port>-force-<finger>, ...
    source = f"bendsense {port}"
    outlets = make_outlets(proc, SimpleNamespace(hello=SimpleNamespace(rate_hz=RATE_HZ)), port)
    inlets = {}
    for name in MAP:
        for kind in ("force", "shape"):
            found = pylsl.resolve_bypred(f"name='bendsense-{kind}-{name}' and source_id='{source}-{kind}-{name}'",
                                         1, 10.0)
            assert found, f"no bendsense-{kind}-{name} stream"
            inlets[kind, name] = pylsl.StreamInlet(found[0], max_buflen=60)
            inlets[kind, name].open_stream(timeout=10)
    info = inlets["force", "thumb"].info(timeout=10)
    assert (info.type(), info.channel_count(), info.desc().child_value("finger")) == ("Force", 8, "thumb")
    assert (info.nominal_srate(), info.desc().child_value("constraint")) == (RATE_HZ, proc.constraint)
    assert inlets["shape", "index"].info(timeout=10).channel_count() == 16 + 3
    blocks = [proc.process_readings(board[lo:hi]) for lo, hi in ((0, 30), (30, 60))]
    for b in blocks:
        outlets.push(b)
    for name in MAP:
        want = {k: np.concatenate([np.asarray(b[name].columns()[k], dtype=float) for b in blocks])
                for k in ("fx_n", "fy_n", "fx_std_n", "fy_std_n", "fx_track_n", "fy_track_n", "fx_track_std_n",
                          "fy_track_std_n", "kappa1", "tip_angle_rad")}
        got = {}
        for kind in ("force", "shape"):
            rows = []
            end = time.monotonic() + 10
            while len(rows) < 60 and time.monotonic() < end:
                chunk, _ = inlets[kind, name].pull_chunk(timeout=0.2)
                rows += chunk
            got[kind] = np.array(rows)
        np.testing.assert_array_equal(got["force"], np.column_stack([want[k] for k in list(want)[:8]]))
        np.testing.assert_array_equal(got["shape"][:, 0], want["kappa1"])
        np.testing.assert_array_equal(got["shape"][:, -1], want["tip_angle_rad"])
    outlets.close()


def test_live_view_draws_a_panel_per_finger(calibration_path, gripper, board, tmp_path):
    from bendsense.apps.live_view import GripperView

    cal = Calibration.load(calibration_path)
    proc = GripperProcessor(cal, gripper, constraint="normal")
    view = GripperView(proc, headless=True)
    for lo, hi in ((0, 60), (60, N_FRAMES)):
        blocks = proc.process_readings(board[lo:hi])
        view.add_block(blocks)
        view.update({k: b.frame(-1) for k, b in blocks.items()}, {k: f"{k} status" for k in blocks})
    for name, panel in view.views.items():
        want = np.asarray(blocks[name].shape.positions_m)[-1] * 1e3
        np.testing.assert_allclose(np.column_stack(panel.shape_line.get_data()), want)
        np.testing.assert_allclose(panel.bar_heights, blocks[name].signals[-1] - cal.offset)
        assert panel.status_text.get_text() == f"{name} status" and panel.ax_shape.get_title().startswith(name)
        assert panel.figure.figure is view.figure  # one figure, a panel each
    view.save(tmp_path / "gripper.png", dpi=50)
    import matplotlib.image

    image = matplotlib.image.imread(tmp_path / "gripper.png")
    assert image.shape[0] > image.shape[1]  # three panels stacked (12 x 16.2 in)


@pytest.fixture(scope="module")
def grasp(tmp_path_factory):
    """The simulated gripper (3 fingers closing on a rigid object) and its config file."""
    from bendsense.config import save_config
    from bendsense.sim.gripper import GraspBoard, Regulation, default_objects, gripper_config

    root = tmp_path_factory.mktemp("grasp")
    gripper = gripper_config(3)
    save_config(gripper, root / "gripper.yaml")
    # coarse tables (2 kPa) keep the build short; a fast close reaches the object within the recording
    board = GraspBoard(gripper, default_objects(3, contact_s_m=CONTACT_S_M), rate_hz=RATE_HZ, seed=0, step_pa=2000.0,
                       regulation=Regulation(period_s=0.8))
    return root, gripper, board


def test_record_estimate_writes_every_finger_for_every_frame(calibration_path, grasp, tmp_path):
    from click.testing import CliRunner

    import bendsense
    from bendsense.cli import main
    from bendsense.device import SimulatedDevice
    from bendsense.tracking import DEFAULT_BANDWIDTH_HZ

    root, gripper, board = grasp
    board.reset()
    out = tmp_path / "s"
    with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels) as dev:
        res = CliRunner().invoke(main, [str(a) for a in (
            "record", dev.port, "-o", out, "--seconds", 1, "--config", root / "gripper.yaml", "--calibration",
            calibration_path, "--estimate", "--constraint", "normal", "--bandwidth-hz", DEFAULT_BANDWIDTH_HZ,
            "--load", "contact", "--contact-s-m", CONTACT_S_M)])
    assert res.exit_code == 0, res.output
    assert f"estimated to {out / '<finger>' / 'results.csv'} (fingers thumb, index, middle)" in res.output
    session = bendsense.read_session(out)
    n = len(session)
    assert n > 500 and session.pressure_pa.shape == (n, 3) and session.meta["stats"]["queue_drops"] == 0
    # the recorded session through the offline chain, per finger (split, estimate, the causal filter, save)
    chain = CliRunner().invoke(main, [str(a) for a in (
        "load", out, "--config", root / "gripper.yaml", "--calibration", calibration_path, "reconstruct", "estimate",
        "--constraint", "normal", "--load", "contact", "--contact-s-m", CONTACT_S_M, "track", "--filter",
        "--bandwidth-hz", DEFAULT_BANDWIDTH_HZ, "save", tmp_path / "off")])
    assert chain.exit_code == 0, chain.output
    touched = 0
    for finger in gripper.fingers:
        live = read_csv(out / finger.name / "results.csv")
        offline = read_csv(tmp_path / "off" / finger.name / "results.csv")
        assert list(live) == list(offline)  # the columns of 'save'
        assert len(live["t_s"]) == n  # every recorded frame has a row
        np.testing.assert_array_equal(live["t_s"], session.t_s)
        np.testing.assert_array_equal(live["pressure_pa"], session.pressure_pa[:, finger.pressure_line])
        np.testing.assert_array_equal(live["tip_x_m"], offline["tip_x_m"])
        ok = (live["status"] == "ok") & (offline["status"] == "ok")
        assert ok.mean() > 0.9, (finger.name, np.unique(live["status"], return_counts=True))
        assert np.mean(live["status"] == offline["status"]) > 0.98
        np.testing.assert_array_equal(live["contact_s_m"][ok], CONTACT_S_M)
        for c in ("fx_n", "fy_n"):
            np.testing.assert_allclose(live[c][ok], offline[c][ok], atol=1e-4)
            np.testing.assert_allclose(live[c.replace("_n", "_track_n")][ok], offline[c.replace("_n", "_track_n")][ok],
                                       atol=1e-4)
        touched += np.abs(live["fx_n"][ok]).max() > 0.05  # the fingers closed on the object: forces, not zeros
    assert touched == 3
    from bendsense.output.manifest import read_manifest

    assert {f"{f}/results.csv" for f in gripper.names} <= set(read_manifest(out)["files"])
    # a new recording over it (--overwrite) replaces every finger's results, and only them
    (out / "notes.txt").write_text("mine")
    with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels) as dev:
        res = CliRunner().invoke(main, [str(a) for a in (
            "record", dev.port, "-o", out, "--seconds", 0.3, "--config", root / "gripper.yaml", "--calibration",
            calibration_path, "--estimate", "--overwrite")])
    assert res.exit_code == 1 and "notes.txt" in res.output
    (out / "notes.txt").unlink()
    with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels) as dev:
        res = CliRunner().invoke(main, [str(a) for a in (
            "record", dev.port, "-o", out, "--seconds", 0.3, "--config", root / "gripper.yaml", "--calibration",
            calibration_path, "--estimate", "--overwrite")])
    assert res.exit_code == 0, res.output
    n = len(bendsense.read_session(out))
    assert all(len(read_csv(out / f / "results.csv")["t_s"]) == n for f in gripper.names)


def read_csv(path):
    """A results.csv as columns: floats where every cell is a number, else strings."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    out = {}
    for i, name in enumerate(rows[0]):
        cells = [r[i] for r in rows[1:]]
        try:
            out[name] = np.array(cells, dtype=float)
        except ValueError:
            out[name] = np.array(cells)
    return out


def test_live_save_shows_a_panel_per_finger_of_the_simulated_gripper(calibration_path, grasp, tmp_path):
    from click.testing import CliRunner

    from bendsense.cli import main
    from bendsense.device import SimulatedDevice

    root, gripper, board = grasp
    board.reset()
    with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels) as dev:
        res = CliRunner().invoke(main, [str(a) for a in (
            "live", dev.port, "--config", root / "gripper.yaml", "--calibration", f"thumb={calibration_path}",
            "--calibration", calibration_path, "--save", tmp_path / "live.png", "--seconds", 0.8)])
    assert res.exit_code == 0, res.output
    assert f"wrote {tmp_path / 'live.png'}" in res.output
    import matplotlib.image

    image = matplotlib.image.imread(tmp_path / "live.png")
    assert image.shape[0] > image.shape[1]  # three panels stacked
    # a calibration for a finger the gripper does not have: one line, nothing written
    res = CliRunner().invoke(main, [str(a) for a in (
        "live", "/dev/null", "--config", root / "gripper.yaml", "--calibration", f"pinky={calibration_path}",
        "--calibration", calibration_path, "--save", tmp_path / "no.png")])
    assert res.exit_code == 1 and "pinky" in res.output and not (tmp_path / "no.png").exists()
    assert "Traceback" not in res.output


def test_blocks_as_long_as_the_segments_or_the_shape_points(calibration_path, config):
    """A block of 16 frames (the sensor's segments) or 41 (the shape's points) is cut frame by frame, never the
    shape's segment lengths or points along the body (a live board delivers blocks of any length)."""
    cal = Calibration.load(calibration_path)
    frames = list(itertools.islice(time_varying_frames(None, RATE_HZ, 0), 41))
    signals = np.array([c for _, c in frames], dtype=float)
    pressure = np.array([p for p, _ in frames], dtype=float)
    pressure[3] = np.nan  # a frame without a reading: the others are estimated as a sub-block
    t_s = np.arange(41) / RATE_HZ
    keep = np.isfinite(pressure[:16])
    block = LiveProcessor(cal, config, constraint="normal").process_block(signals[:16], pressure[:16], t_s=t_s[:16])
    without = LiveProcessor(cal, config, constraint="normal").process_block(signals[:16][keep], pressure[:16][keep],
                                                                            t_s=t_s[:16][keep])
    np.testing.assert_array_equal(block.force_n[keep], without.force_n)
    assert block.status[3] == Status.NO_PRESSURE and np.all(block.status[keep] == without.status)
    proc = LiveProcessor(cal, config, constraint="normal", load="contact", contact_s_m=CONTACT_S_M)
    block = proc.process_block(signals, np.nan_to_num(pressure, nan=pressure[2]), t_s=t_s)
    frame = block.frame(-1)
    np.testing.assert_array_equal(frame.shape.s_m, proc.s_m)
    np.testing.assert_array_equal(frame.shape.lengths_m, config.sensor.segment_lengths_m)
    np.testing.assert_array_equal(frame.shape.positions_m, block.shape.positions_m[-1])


def test_record_lsl_publishes_every_finger_of_the_board(calibration_path, grasp, tmp_path):
    """``record --estimate --lsl`` with a gripper: each finger's force stream carries its results.csv, in order."""
    pylsl = pytest.importorskip("pylsl")
    import subprocess
    import sys

    from bendsense.device import SimulatedDevice

    root, gripper, board = grasp
    board.reset()
    out = tmp_path / "s"
    with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels) as dev:
        cmd = [sys.executable, "-c", "from bendsense.cli import main; main()", "-q", "record", dev.port, "-o",
               str(out), "--seconds", "1", "--config", str(root / "gripper.yaml"), "--calibration",
               str(calibration_path), "--estimate", "--lsl", "--lsl-wait", "30", "--quiet-status"]
        with open(tmp_path / "stderr.txt", "wb") as err, subprocess.Popen(cmd, stdout=subprocess.DEVNULL,
                                                                           stderr=err) as proc:
            try:
                inlets = {}
                for name in gripper.names:  # this recording's streams: the port is in their source id
                    found = pylsl.resolve_bypred(f"name='bendsense-force-{name}' and "
                                                 f"source_id='bendsense {dev.port}-force-{name}'", 1, 30.0)
                    assert found, (tmp_path / "stderr.txt").read_text()
                    inlets[name] = pylsl.StreamInlet(found[0], max_buflen=60)
                    inlets[name].open_stream(timeout=10)
                got = {name: [] for name in gripper.names}
                end = time.monotonic() + 60
                while proc.poll() is None or any(inlet.samples_available() for inlet in inlets.values()):
                    for name, inlet in inlets.items():
                        got[name] += inlet.pull_chunk(timeout=0.05, max_samples=4096)[0]
                    assert time.monotonic() < end
                for name, inlet in inlets.items():  # what was still under way
                    got[name] += inlet.pull_chunk(timeout=1.0, max_samples=4096)[0]
            finally:
                if proc.poll() is None:
                    proc.kill()
            assert proc.wait(30) == 0, (tmp_path / "stderr.txt").read_text()
    for name in gripper.names:
        rows = read_csv(out / name / "results.csv")
        force = np.array(got[name])
        assert len(force) >= 0.99 * len(rows["t_s"]) > 500
        m = len(force)
        want = np.column_stack([rows[c][:m] for c in ("fx_n", "fy_n", "fx_std_n", "fy_std_n", "fx_track_n",
                                                        "fy_track_n", "fx_track_std_n", "fy_track_std_n")])
        np.testing.assert_allclose(force, want, rtol=0, atol=1e-12, equal_nan=True)
