"""A gripper's fingers touch at their own places: ``--contact-s-m NAME=S_C`` (issue 24).

The board session is made here: each finger of the simulated gripper
(:func:`bendsense.sim.gripper_config`, the virtual sensor of seed 0 whose calibration is
the ``calibration_path`` fixture) pressed by a normal contact force at its own arc
length, the channels concatenated. The chain with per-finger locations must give, for
each finger, what the single-actuator chain gives for the finger's part at its location.
"""

import numpy as np
import pytest
from click.testing import CliRunner

from bendsense.cli import main
from bendsense.config import save_config
from bendsense.session import Session, write_session_csv
from bendsense.session.fingers import split_session
from bendsense.sim import gripper_config
from bendsense.sim.actuator import SimulatedActuator

FRAMES = 30
# where each finger is touched [m] (the simulated board's default objects: 0.10, 0.11, 0.095)
WHERE = {"thumb": 0.10, "index": 0.11, "middle": 0.095}


def read_results(path):
    """A results.csv as columns: floats where every cell is a number, else strings."""
    import csv

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = {}
    for key in rows[0]:
        cells = [r[key] for r in rows]
        try:
            out[key] = np.array([float(c) if c else np.nan for c in cells])
        except ValueError:
            out[key] = np.array(cells)
    return out


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    """The gripper's config file and a board session CSV: each finger touched at WHERE."""
    root = tmp_path_factory.mktemp("contact-board")
    gripper = gripper_config(3)
    save_config(gripper, root / "gripper.yaml")
    lines = np.column_stack([np.linspace(40e3, 80e3, FRAMES)] * 3)
    counts = []
    for finger in gripper.fingers:
        sim = SimulatedActuator.from_config(finger.config, seed=0)
        frames = sim.frames(lines[:, finger.pressure_line], contact_n=np.full(FRAMES, 0.1),
                            contact_s_m=WHERE[finger.name], noise=False)
        counts.append(frames.counts)
    session = Session(np.arange(FRAMES) * 1e-3, np.hstack(counts).astype(float), lines, np.arange(FRAMES), {}, {})
    write_session_csv(session, root / "board.csv")
    return root, gripper, session


def test_chain_estimates_each_finger_at_its_own_location(board, calibration_path, tmp_path):
    root, gripper, session = board
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", calibration_path,
              "reconstruct", "estimate", "--constraint", "normal", "--load", "contact", "--contact-s-m", "0.10",
              "--contact-s-m", "index=0.11", "--contact-s-m", "middle=0.095", "save", tmp_path / "g")
    assert res.exit_code == 0, res.output
    parts = split_session(session, gripper)
    for finger in gripper.fingers:
        got = read_results(tmp_path / "g" / finger.name / "results.csv")
        np.testing.assert_array_equal(got["contact_s_m"], WHERE[finger.name])
        # the finger's part alone, a single actuator at its location: the same forces
        write_session_csv(parts[finger.name], tmp_path / f"{finger.name}.csv")
        save_config(finger.config, tmp_path / f"{finger.name}.yaml")
        one = run("load", tmp_path / f"{finger.name}.csv", "--config", tmp_path / f"{finger.name}.yaml",
                  "--calibration", calibration_path, "reconstruct", "estimate", "--constraint", "normal", "--load",
                  "contact", "--contact-s-m", WHERE[finger.name], "save", tmp_path / finger.name)
        assert one.exit_code == 0, one.output
        alone = read_results(tmp_path / finger.name / "results.csv")
        for column in ("fx_n", "fy_n", "status"):
            np.testing.assert_array_equal(got[column], alone[column])
        # and not what the plain 0.10 gives a finger touched elsewhere (the location mattered)
        if WHERE[finger.name] != 0.10:
            assert np.max(np.abs(got["fy_n"] - read_results(
                tmp_path / "g" / "thumb" / "results.csv")["fy_n"])) > 0


@pytest.mark.parametrize(("values", "message"), [
    (("ring=0.1",), "Invalid value for '--contact-s-m': ring=0.1: ring is not a finger of this gripper; its fingers: "
                    "thumb, index, middle"),
    (("index=0.5",), "Invalid value for '--contact-s-m': finger index: expected 0 < s_c <= L = "),
    (("0.1", "0.09"), "Invalid value for '--contact-s-m': two locations for every finger (a plain S_C): 0.1 and 0.09"),
    (("index=",), "Invalid value for '--contact-s-m': index=: no location after the finger's name (give "
                   "index=S_C"),
])
def test_chain_refuses_a_bad_location(board, calibration_path, values, message):
    root, _, _ = board
    flags = [a for v in values for a in ("--contact-s-m", v)]
    res = run("load", root / "board.csv", "--config", root / "gripper.yaml", "--calibration", calibration_path,
              "reconstruct", "estimate", "--load", "contact", *flags)
    assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output
    assert len([line for line in res.output.splitlines() if line.startswith("Error")]) == 1


def test_a_finger_name_with_one_actuator_is_refused(tmp_path, calibration_path):
    from bendsense.config import load_config

    save_config(load_config(), tmp_path / "one.yaml")
    res = run("control", "no-such-port", "--config", tmp_path / "one.yaml", "--calibration", calibration_path,
              "--target-force-n", "0.1", "--load", "contact", "--contact-s-m", "index=0.1")
    assert res.exit_code == 2 and ("index=0.1 names a finger, but the config is a single actuator (no fingers:); "
                                   "give --contact-s-m S_C") in res.output, res.output


@pytest.mark.parametrize("command", ["live", "control"])
def test_live_commands_check_the_fingers_before_the_port(board, calibration_path, command):
    root, _, _ = board
    extra = ["--target-force-n", "0.1"] if command == "control" else []
    res = run(command, "no-such-port", "--config", root / "gripper.yaml", "--calibration", calibration_path, *extra,
              "--load", "contact", "--contact-s-m", "0.1", "--contact-s-m", "pinky=0.1")
    assert res.exit_code == 2 and "pinky is not a finger of this gripper" in res.output, res.output
    # a finger without a location (no plain S_C) is named
    res = run(command, "no-such-port", "--config", root / "gripper.yaml", "--calibration", calibration_path, *extra,
              "--load", "contact", "--contact-s-m", "thumb=0.1")
    assert res.exit_code == 2 and "finger index: --load contact as frames arrive needs" in res.output, res.output


def test_gripper_processor_takes_each_finger_its_location(board, calibration_path):
    from bendsense.cli.device import live_load
    from bendsense.pipeline.gripper import GripperProcessor

    _, gripper, _ = board
    options = live_load("contact", ((None, 0.1), ("index", 0.11)), gripper)
    assert options == {"finger_options": {"thumb": {"load": "contact", "contact_s_m": 0.1},
                                          "index": {"load": "contact", "contact_s_m": 0.11},
                                          "middle": {"load": "contact", "contact_s_m": 0.1}}}
    # a plain calibration path for every finger ({None: path}, as --calibration CAL.yaml gives it)
    proc = GripperProcessor({None: calibration_path}, gripper, estimate=False, **options)
    assert {n: p.options["contact_s_m"] for n, p in proc.processors.items()} == {"thumb": 0.1, "index": 0.11,
                                                                                "middle": 0.1}


def test_a_board_of_several_lines_with_one_actuator_config_is_one_line(board, calibration_path, tmp_path):
    """16 channels (one finger's) but 2 pressure lines, read with the paper's single-actuator config."""
    from bendsense.errors import SessionError
    from bendsense.pipeline import process

    _, _, session = board
    two = Session(session.t_s, session.signals[:, :16], session.pressure_pa[:, :2], session.seq, {}, {})
    write_session_csv(two, tmp_path / "two.csv")
    want = (f"{tmp_path / 'two.csv'}: 2 pressure lines per frame (a gripper's board), but the config is a single "
            f"actuator: give a gripper config (--config G.yaml with fingers:, each finger's channels and "
            f"pressure_line)")
    res = run("load", tmp_path / "two.csv", "--calibration", calibration_path, "reconstruct", "estimate",
              "save", tmp_path / "out")
    assert res.exit_code == 1 and res.output == f"Error: {want}\n", res.output
    assert not (tmp_path / "out").exists()
    with pytest.raises(SessionError) as err:
        process(tmp_path / "two.csv", None, calibration_path)
    assert str(err.value) == want
    res = run("process", tmp_path / "two.csv", "--calibration", calibration_path, "-o", tmp_path / "batch",
              "--no-progress")
    assert res.exit_code == 1 and "two.csv: 2 pressure lines per fram" in res.output, res.output


@pytest.mark.parametrize("scenario", ["tip-loads", "calibration", "time-varying", "all"])
def test_simulate_with_a_gripper_config_says_it_is_one(board, tmp_path, scenario):
    root, gripper, _ = board
    res = run("simulate", scenario, "--config", root / "gripper.yaml", "-o", tmp_path / "sim")
    want = (f"Error: {root / 'gripper.yaml'}: the config {gripper.name!r} is a gripper config (fingers thumb, index, "
            f"middle); this takes one actuator's config: one finger's (gripper.finger(NAME).config in Python; on the "
            f"command line a config without fingers:)\n")
    assert res.exit_code == 1 and res.output == want, res.output
    assert not (tmp_path / "sim").exists()


def test_simulate_given_a_gripper_object(board, tmp_path):
    from bendsense.errors import ConfigError
    from bendsense.sim.scenarios import simulate

    _, gripper, _ = board
    with pytest.raises(ConfigError, match=r"^config: the config .* is a gripper config \(fingers thumb, index, "
                                          r"middle\)"):
        simulate("tip-loads", tmp_path / "sim", config=gripper)
    assert not (tmp_path / "sim").exists()


def test_each_finger_stream_tells_its_own_location(monkeypatch, board, calibration_path):
    from types import SimpleNamespace

    import bendsense.interop.lsl as lsl
    from bendsense.cli.device import live_load, make_outlets
    from bendsense.pipeline.gripper import GripperProcessor

    _, gripper, _ = board
    made = {}

    class Outlets:  # what each finger's LslOutlets is made with (no LSL needed)
        def __init__(self, n_segments, rate_hz, *, source_id, meta, tracked, contact, finger):
            made[finger] = (meta, contact)

    monkeypatch.setattr(lsl, "LslOutlets", Outlets)
    proc = GripperProcessor({None: calibration_path}, gripper, estimate=False,
                            **live_load("contact", ((None, 0.1), ("middle", 0.095)), gripper))
    make_outlets(proc, SimpleNamespace(hello=None), "port")
    assert {n: (m["contact_s_m"], m["load"], c) for n, (m, c) in made.items()} == {
        "thumb": ("0.1 (known)", "contact", True), "index": ("0.1 (known)", "contact", True),
        "middle": ("0.095 (known)", "contact", True)}
