"""A gripper's board through the chain: each finger as a single actuator (issue 24).

The board session is made here: each finger simulated on its own
(:class:`bendsense.sim.actuator.SimulatedActuator`, the virtual sensor of seed 0 whose
calibration is the ``calibration_path`` fixture) and the channels concatenated, with
per-finger truth columns ``<finger>_fx_n`` and ``<finger>_fy_n``.
"""

import copy

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from bendsense import ConfigError, load_config
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.config import Finger, GripperConfig, save_config
from bendsense.results import read_results
from bendsense.results.gripper import read_gripper_results
from bendsense.session import Session, read_session, write_session_csv
from bendsense.session.fingers import calibrations, split_session
from bendsense.sim.actuator import SimulatedActuator

# under xdist, one worker: `board` (a module fixture of seconds) made once, not on both workers
pytestmark = pytest.mark.xdist_group("gripper-chain")
PAPER = load_config()
N = PAPER.sensor.n_segments
NAMES = ("thumb", "index", "middle")
FRAMES = 40
NOISE = False  # noise-free counts: the force error is the calibration's and the model's alone
# each finger's tip force [N] (the index pushes up, the others are pressed down and sideways)
FORCES = {"thumb": (0.05, -0.10), "index": (-0.04, 0.08), "middle": (0.0, -0.15)}


def gripper_config() -> GripperConfig:
    """Three fingers on channels 1-16, 17-32, 33-48 and pressure lines 0, 1, 2; the index a stiffer finger."""
    stiffer = PAPER.replace(stiffness=PAPER.stiffness.__class__(ei0_nm2=0.0030, ei1_nm2_per_pa=1.25e-8))
    configs = {"thumb": PAPER, "index": stiffer, "middle": PAPER}
    return GripperConfig(name="three fingers", fingers=tuple(
        Finger(name=n, channels=tuple(range(N * i + 1, N * i + N + 1)), pressure_line=i,
               config=configs[n].replace(name=n)) for i, n in enumerate(NAMES)))


@pytest.fixture(scope="module")
def board(tmp_path_factory, calibration_path):
    """The gripper's config file, the board session CSV and the shared calibration."""
    root = tmp_path_factory.mktemp("gripper")
    gripper = gripper_config()
    save_config(gripper, root / "gripper.yaml")
    t = np.arange(FRAMES) * 1e-3
    # each finger on its own line, each line its own ramp
    lines = np.column_stack([np.linspace(30e3, 90e3, FRAMES), np.linspace(40e3, 100e3, FRAMES),
                             np.linspace(90e3, 30e3, FRAMES)])
    counts, extra = [], {"label": np.arange(FRAMES) % 3}
    for finger in gripper.fingers:
        sim = SimulatedActuator.from_config(finger.config, seed=0, noise_counts=1.5)
        frames = sim.frames(lines[:, finger.pressure_line], FORCES[finger.name], noise=NOISE)
        assert frames.valid.all()
        counts.append(frames.counts)
        extra[f"{finger.name}_fx_n"] = frames.force_n[:, 0]
        extra[f"{finger.name}_fy_n"] = frames.force_n[:, 1]
    session = Session(t, np.hstack(counts).astype(float), lines, np.arange(FRAMES), {}, extra)
    write_session_csv(session, root / "board.csv")
    return root, gripper, calibration_path


def same_output(a, b, rtol=0.0):
    """results.csv byte for byte, and shape.npz array for array (a zip records its write time).

    ``rtol``: the chain's ``reconstruct --points`` and ``process`` space the arc lengths of
    shape.npz apart by an ulp (as for a single actuator).
    """
    assert (a / "results.csv").read_bytes() == (b / "results.csv").read_bytes()
    with np.load(a / "shape.npz") as x, np.load(b / "shape.npz") as y:
        assert sorted(x.files) == sorted(y.files) == ["positions_m", "s_m"]
        for key in x.files:
            np.testing.assert_allclose(x[key], y[key], rtol=rtol, atol=0)


def run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res


@pytest.fixture(scope="module")
def chain(board):
    """The whole chain over the board: save, mcap and plot."""
    root, gripper, cal = board
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", cal,
              "reconstruct", "estimate", "track", "save", root / "out", "plot", root / "fig.png")
    assert res.exit_code == 0, res.output
    return root / "out"


def test_each_finger_is_a_single_actuator_run_of_its_part(board, chain):
    root, gripper, cal = board
    parts = split_session(read_session(root / "board.csv"), gripper)
    for finger in gripper.fingers:
        save_config(finger.config, root / f"{finger.name}.yaml")
        write_session_csv(parts[finger.name], root / f"{finger.name}.csv")
        res = run("load", root / f"{finger.name}.csv", "--config", root / f"{finger.name}.yaml", "--calibration", cal,
                  "reconstruct", "estimate", "track", "save", root / f"single-{finger.name}")
        assert res.exit_code == 0, res.output
        same_output(chain / finger.name, root / f"single-{finger.name}")
    from bendsense.output.manifest import read_manifest

    assert sorted(p.name for p in chain.iterdir() if not p.name.startswith(".")) == sorted(NAMES)
    listed = read_manifest(chain)["files"]
    assert sorted(listed) == sorted(f"{n}/{f}" for n in NAMES for f in ("results.csv", "shape.npz"))


def test_forces_match_the_truth(board, chain):
    results = read_gripper_results(chain)
    assert list(results) == sorted(NAMES)
    lines = read_session(board[0] / "board.csv").pressure_pa
    assert lines.shape == (FRAMES, 3)
    for name, r in results.items():
        np.testing.assert_array_equal(r["pressure_pa"], lines[:, NAMES.index(name)])  # the finger's own line
        assert set(r["status"]) == {"ok"}, (name, r["status"])
        for k, axis in enumerate(("fx", "fy")):
            err = r[f"{axis}_n"] - FORCES[name][k]
            # noise-free counts: the error is the calibration's (fitted from noisy strips), within its σ
            assert np.all(np.abs(err) <= 2 * r[f"{axis}_std_n"]), (name, axis)
        # each finger's forces are its own truth's, not another finger's: its median distance to its own
        # truth is at most a third of that to any other finger's (the truths lie 0.07 to 0.25 N apart)
        force = np.column_stack([r["fx_n"], r["fy_n"]])
        distance = {m: np.median(np.hypot(*(force - np.array(FORCES[m])).T)) for m in NAMES}
        assert all(3 * distance[name] < distance[m] for m in NAMES if m != name), (name, distance)
        # the board's shared column came through; the finger's own truth without its prefix
        np.testing.assert_array_equal(r["label"], np.arange(FRAMES) % 3)
        np.testing.assert_array_equal(r["input_fx_n"], np.full(FRAMES, FORCES[name][0]))
        np.testing.assert_array_equal(r["input_fy_n"], np.full(FRAMES, FORCES[name][1]))
        assert not any(c.startswith(("thumb_", "index_", "middle_")) for c in r.columns)


def test_each_finger_used_its_own_config(board, chain):
    """The index (a stiffer finger) run with the thumb's config gives other forces than the chain's."""
    root, gripper, cal = board
    part = split_session(read_session(root / "board.csv"), gripper)["index"]
    write_session_csv(part, root / "index-part.csv")
    save_config(gripper.finger("thumb").config, root / "thumb-config.yaml")
    res = run("load", root / "index-part.csv", "--config", root / "thumb-config.yaml", "--calibration", cal,
              "reconstruct", "estimate", "save", root / "index-as-thumb")
    assert res.exit_code == 0, res.output
    wrong = read_results(root / "index-as-thumb")["fy_n"]
    right = read_gripper_results(chain)["index"]["fy_n"]
    assert np.abs(wrong - right).max() > 0.015


def test_plot_has_a_panel_per_finger(board, chain):
    root = board[0]
    assert (root / "fig.png").stat().st_size > 10_000
    res = run("plot", chain, "-o", root / "fig2.png")
    assert res.exit_code == 0, res.output
    assert (root / "fig2.png").stat().st_size > 10_000
    import matplotlib

    matplotlib.use("Agg")
    from bendsense.plots.gripper import grasp_force, plot_gripper

    results = read_gripper_results(chain, names=NAMES)
    fig = plot_gripper(results)
    titles = [ax.get_title() for ax in fig.axes]
    assert [t for t in titles if t in NAMES] == list(NAMES) and len(fig.axes) == 2 * len(NAMES) + 2
    grasp = fig.axes[-2]
    total = next(line for line in grasp.get_lines() if line.get_label() == "total").get_ydata()
    # the total is the sum of the fingers' tracked force magnitudes, from results.csv
    expected = sum(np.hypot(r["fx_track_n"], r["fy_track_n"]) for r in results.values())
    np.testing.assert_allclose(total, expected, rtol=1e-12)
    magnitude, std = grasp_force(results["thumb"])
    assert np.all(std > 0) and np.all(std <= np.hypot(results["thumb"]["fx_track_std_n"],
                                                      results["thumb"]["fy_track_std_n"]) * (1 + 1e-12))
    # the total's band: a sum of magnitudes, never below 0 (a barely determined finger's band reached -0.3 N)
    for r in results.values():
        for column in ("fx_track_std_n", "fy_track_std_n"):
            r.columns[column] = np.asarray(r.columns[column]) * 100.0
    band = next(c for c in plot_gripper(results).axes[-2].collections if c.get_label() == "total ± 2σ")
    assert band.get_paths()[0].vertices[:, 1].min() == 0.0


def test_mcap_has_topics_per_finger(board, chain):
    pytest.importorskip("mcap_ros2")
    from mcap_ros2.reader import read_ros2_messages

    root, gripper, cal = board
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", cal,
              "reconstruct", "estimate", "mcap", root / "g.mcap")
    assert res.exit_code == 0, res.output
    topics = {}
    with open(root / "g.mcap", "rb") as fh:
        for msg in read_ros2_messages(fh):
            topics.setdefault(msg.channel.topic, []).append(msg.ros_msg)
    for name in NAMES:
        for topic in ("wrench", "shape", "pressure", "status"):
            assert len(topics[f"/bendsense/{name}/{topic}"]) == FRAMES
    assert "/bendsense/wrench" not in topics
    fx = [m.wrench.force.x for m in topics["/bendsense/middle/wrench"]]
    np.testing.assert_allclose(fx, read_gripper_results(chain)["middle"]["fx_n"], rtol=0, atol=1e-3)
    assert topics["/bendsense/index/status"][0].status[0].name == "bendsense/index/force"


def test_calibrations_library(board):
    root, gripper, cal_path = board
    cal = Calibration.load(cal_path)
    got = calibrations(gripper, cal_path)
    assert list(got) == list(NAMES) and all(np.array_equal(c.offset, cal.offset) for c in got.values())
    other = copy.copy(cal)
    object.__setattr__(other, "finger", "thumb")
    got = calibrations(gripper, {"thumb": other, None: cal})
    assert got["thumb"] is other and got["index"] is cal
    with pytest.raises(ConfigError, match=r"fitted for finger thumb, given for finger index"):
        calibrations(gripper, {"index": other, None: cal})
    with pytest.raises(ConfigError, match=r"no calibration for fingers index, middle \(give --calibration index="):
        calibrations(gripper, {"thumb": cal})
    with pytest.raises(ConfigError, match=r"calibration for finger pinky: not a finger of this gripper; its fingers: "
                                        r"thumb, index, middle"):
        calibrations(gripper, {"pinky": cal, None: cal})
    eight = Calibration(offset=np.zeros(8), coefficients_odd=[0.0, 1e-6], coefficients_even=[0.0, -1e-6], degree=1,
                        delta_a_range_odd=(-1e3, 1e3), delta_a_range_even=(-1e3, 1e3))
    with pytest.raises(ConfigError, match=r"calibration: 8 channels, finger middle's sensor has 16 segments"):
        calibrations(gripper, {"middle": eight, None: cal})


def test_calibration_options_on_the_command_line(board):
    root, gripper, cal = board
    base = ["load", root / "board.csv", "--config", root / "gripper.yaml"]
    res = run(*base, "--calibration", f"thumb={cal}", "reconstruct")
    assert res.exit_code == 1 and "Error: no calibration for fingers index, middle" in res.output
    res = run(*base, "--calibration", f"pinky={cal}", "--calibration", cal, "reconstruct")
    assert res.exit_code == 1 and "calibration for finger pinky: not a finger of this gripper" in res.output
    res = run(*base, "--calibration", f"thumb={cal}", "--calibration", f"thumb={cal}", "reconstruct")
    assert res.exit_code == 2 and "two calibrations for finger thumb" in res.output
    # a single actuator: a NAME= form is an error, one plain path as ever
    res = run("load", root / "board.csv", "--calibration", f"thumb={cal}", "reconstruct")
    assert res.exit_code == 2 and f"thumb={cal} names a finger, but the config is a single actuator" in res.output
    assert len(res.output.strip().splitlines()) == 1
    res = run("load", root / "board.csv", "--calibration", "thumb=missing.yaml", "reconstruct")
    assert res.exit_code == 2 and "'missing.yaml' does not exist" in res.output


def test_calibrate_a_finger_from_board_recordings(tmp_path, board):
    """--finger takes the finger's channels of whole-board recordings; the result records the finger."""
    from bendsense.sim.scenarios import simulate

    root, gripper, _ = board
    simulate("calibration", tmp_path / "cal", seed=0, frames_per_strip=5)
    manifest = yaml.safe_load((tmp_path / "cal" / "manifest.yaml").read_text())
    board_dir = tmp_path / "board"
    board_dir.mkdir()
    names = [manifest["flat"], *(s["recording"] for s in manifest["strips"])]
    for name in names:  # the sensor's channels on the index's board channels (17-32), noise elsewhere
        s = read_session(tmp_path / "cal" / name)
        rng = np.random.default_rng(1)
        signals = rng.normal(2000, 50, size=(len(s), 3 * N))
        signals[:, N:2 * N] = s.signals
        write_session_csv(Session(s.t_s, signals, s.pressure_pa, None, {}, {}), board_dir / name)
    (board_dir / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    res = run("calibrate", board_dir / "manifest.yaml", "--config", root / "gripper.yaml", "--finger", "index",
              "-o", tmp_path / "index.yaml")
    assert res.exit_code == 0, res.output
    fitted = Calibration.load(tmp_path / "index.yaml")
    direct = Calibration.fit(tmp_path / "cal" / "manifest.yaml")
    assert fitted.finger == "index" and direct.finger is None
    np.testing.assert_array_equal(fitted.coefficients_odd, direct.coefficients_odd)
    np.testing.assert_array_equal(fitted.offset, direct.offset)
    assert "finger: index" in (tmp_path / "index.yaml").read_text()
    assert "finger:" not in yaml.safe_dump(direct.to_dict())
    # the index's calibration for every finger: refused, naming both
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", tmp_path / "index.yaml",
              "reconstruct")
    assert res.exit_code == 1 and "fitted for finger index, given for finger thumb" in res.output
    res = run("calibrate", board_dir / "manifest.yaml", "--config", root / "gripper.yaml", "-o", tmp_path / "x.yaml")
    assert res.exit_code == 2 and "give --finger NAME" in res.output and not (tmp_path / "x.yaml").exists()


def test_process_over_gripper_sessions(board):
    """``process`` writes OUT/<session>/<finger>/, each finger as the chain writes it."""
    root, gripper, cal = board
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", cal,
              "reconstruct", "estimate", "save", root / "chain-estimate")
    assert res.exit_code == 0, res.output
    res = run("process", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", f"thumb={cal}",
              "--calibration", cal, "-o", root / "batch", "--workers", "0", "--no-progress")
    assert res.exit_code == 0, res.output
    for name in NAMES:
        same_output(root / "batch" / "board" / name, root / "chain-estimate" / name, rtol=1e-14)
    assert "board" in res.output and " 40 " in res.output.replace("|", " ")
    res = run("process", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", f"thumb={cal}",
              "-o", root / "batch2", "--workers", "0", "--no-progress")
    assert res.exit_code == 1 and "no calibration for fingers index, middle" in res.output


def test_export_one_finger(board):
    root, gripper, cal = board
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "export", "--finger", "middle",
              root / "export-middle.csv", "export", root / "board-copy.csv")
    assert res.exit_code == 0, res.output
    middle = read_session(root / "export-middle.csv")
    board_session = read_session(root / "board.csv")
    np.testing.assert_array_equal(middle.signals, board_session.signals[:, 2 * N:])
    np.testing.assert_array_equal(middle.extra["fy_n"], board_session.extra["middle_fy_n"])
    assert read_session(root / "board-copy.csv").n_channels == 3 * N
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "export", "--finger", "pinky",
              root / "pinky.csv")
    assert res.exit_code == 1 and "finger 'pinky': not a finger of this gripper" in res.output
    assert not (root / "pinky.csv").exists()
    res = run("load", root / "board.csv", "export", "--finger", "thumb", root / "export-thumb.csv")
    assert res.exit_code == 2 and "a finger needs a gripper's config" in res.output


def test_identify_one_finger_of_a_board(board):
    """identify --finger fits the finger's part of a board sweep, as identify on that part alone does."""
    root, gripper, cal = board
    pressure = np.linspace(10e3, 120e3, 30)
    counts = [SimulatedActuator.from_config(f.config, seed=0, noise_counts=1.5).frames(pressure).counts
              for f in gripper.fingers]
    write_session_csv(Session(np.arange(30) * 0.05, np.hstack(counts).astype(float), np.column_stack([pressure] * 3)),
                      root / "sweep.csv")
    res = run("identify", "free-bending", "--session", root / "sweep.csv", "--calibration", f"index={cal}",
              "--config", root / "gripper.yaml", "--finger", "index", "-o", root / "identified.yaml")
    assert res.exit_code == 0, res.output
    identified = load_config(root / "identified.yaml")
    assert isinstance(identified, GripperConfig) and identified.names == gripper.names
    assert identified.finger("thumb").config == gripper.finger("thumb").config
    # the same fit as identify on the index's part alone, with the index's config
    write_session_csv(split_session(read_session(root / "sweep.csv"), gripper)["index"], root / "sweep-index.csv")
    save_config(gripper.finger("index").config, root / "index-config.yaml")
    res = run("identify", "free-bending", "--session", root / "sweep-index.csv", "--calibration", cal,
              "--config", root / "index-config.yaml", "-o", root / "identified-index.yaml")
    assert res.exit_code == 0, res.output
    alone = load_config(root / "identified-index.yaml")
    assert identified.finger("index").config == alone
    assert alone.material != gripper.finger("index").config.material  # something was fitted
    res = run("identify", "free-bending", "--session", root / "sweep.csv", "--calibration", cal,
              "--config", root / "gripper.yaml", "-o", root / "none.yaml")
    assert res.exit_code == 2 and "give --finger NAME" in res.output and not (root / "none.yaml").exists()
