"""Gripper configs (``fingers:``) and the board split per finger (issue 24, DESIGN section 2b)."""

import copy
import pickle

import numpy as np
import pytest
import yaml

import bendsense
from bendsense import ConfigError, SessionError
from bendsense.config import Config, Finger, GripperConfig, load_config, save_config
from bendsense.errors import ArgumentError
from bendsense.session import Session
from bendsense.session.fingers import split_session, split_signals

PAPER = load_config().to_dict()
N = PAPER["sensor"]["n_segments"]


def gripper_dict(k=3, **overrides):
    """A k-finger gripper dict: the paper's sections as defaults, finger i on channels 16 i + 1.. and line i."""
    data = {key: copy.deepcopy(v) for key, v in PAPER.items() if key != "name"}
    data["name"] = "test gripper"
    data["fingers"] = [{"name": n, "channels": list(range(N * i + 1, N * i + N + 1)), "pressure_line": i}
                       for i, n in enumerate(["thumb", "index", "middle", "ring"][:k])]
    data.update(overrides)
    return data


def write(tmp_path, data, name="g.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_load_config_dispatches_on_fingers(tmp_path):
    data = gripper_dict(2)
    data["fingers"][1]["stiffness"] = {"ei0_nm2": 0.003, "ei1_nm2_per_pa": 1e-8}
    g = load_config(write(tmp_path, data))
    assert isinstance(g, GripperConfig) and g.names == ("thumb", "index")
    assert g.n_channels == 2 * N and g.n_lines == 2 and g.name == "test gripper"
    thumb, index = g.fingers
    assert thumb.channels == tuple(range(1, N + 1)) and index.pressure_line == 1
    # the thumb inherits every section whole; the index overrides its stiffness only
    assert thumb.config == Config.from_dict({**PAPER, "name": "thumb"})
    assert index.config.stiffness.ei0_nm2 == 0.003 and index.config.material == thumb.config.material
    assert g.finger("index") is index
    # a single-actuator YAML still loads as the Config it loaded as before
    assert isinstance(load_config(write(tmp_path, PAPER, "one.yaml")), Config)
    assert bendsense.config.GripperConfig is GripperConfig and bendsense.config.Finger is Finger


def test_save_and_load_round_trip(tmp_path):
    data = gripper_dict(3)
    data["fingers"][2]["actuator"] = {**PAPER["actuator"], "length_m": 0.12}
    data["fingers"][2]["sensor"] = {**PAPER["sensor"], "segment_lengths_m": [0.0075] * N}
    g = load_config(write(tmp_path, data))
    save_config(g, tmp_path / "out.yaml")
    again = load_config(tmp_path / "out.yaml")
    assert again == g
    written = yaml.safe_load((tmp_path / "out.yaml").read_text())
    # shared sections at the top level, the differing ones in the finger that has them
    assert "material" in written and "actuator" not in written and "sensor" not in written
    assert written["fingers"][2]["actuator"]["length_m"] == 0.12
    assert GripperConfig.from_dict(g.to_dict()) == g


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["fingers"][1].update(channels=list(range(17, 32))),
     "fingers[1].channels: 15 channels for a 16-segment sensor"),
    (lambda d: d["fingers"][2].update(channels=list(range(5, 21))),
     "fingers[2].channels: channel 5 is already finger thumb's"),
    (lambda d: d["fingers"][0].update(channels=[1] * 16), "fingers[0].channels: channel 1 is given twice"),
    (lambda d: d["fingers"][0].update(channels=list(range(50, 66))), "fingers[0].channels[15]: expected an integer"
                                                                    " in 1..64, got 65"),
    (lambda d: d["fingers"][1].update(name="thumb"), "fingers[1].name: finger 'thumb' is named twice"),
    (lambda d: d["fingers"][1].update(name="2nd"), "fingers[1].name: expected a name matching"),
    (lambda d: d["fingers"][1].update(name="a/b"), "fingers[1].name: expected a name matching"),
    (lambda d: d["fingers"][0].update(pressure_line=255), "fingers[0].pressure_line: expected an integer in 0..254"),
    (lambda d: d["fingers"][0].pop("pressure_line"), "fingers[0]: missing keys pressure_line"),
    (lambda d: d["fingers"][0].update(colour="red"), "fingers[0]: unknown keys colour"),
    (lambda d: d.pop("material"), "fingers[0]: missing sections material"),
    (lambda d: d["fingers"][1].update(stiffness={"ei0_nm2": -1, "ei1_nm2_per_pa": 0.0}),
     "fingers[1].stiffness.ei0_nm2:"),
    (lambda d: d.update(stiffness={"ei0_nm2": -1, "ei1_nm2_per_pa": 0.0}), "stiffness.ei0_nm2:"),
    (lambda d: d.update(fingers=[]), "fingers: expected a non-empty list of fingers"),
    (lambda d: d.update(hand="left"), "config: unknown keys hand"),
])
def test_clear_errors_name_the_field(tmp_path, edit, message):
    data = gripper_dict(3)
    edit(data)
    path = write(tmp_path, data)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and message in text, text
    assert "\n" not in text


def test_sensor_of_a_finger_sets_its_channel_count(tmp_path):
    data = gripper_dict(2)
    data["fingers"][1]["sensor"] = {**PAPER["sensor"], "n_segments": 8, "segment_lengths_m": [0.016] * 8}
    data["fingers"][1]["channels"] = list(range(17, 25))
    g = load_config(write(tmp_path, data))
    assert g.finger("index").config.sensor.n_segments == 8 and g.n_channels == 24


def test_unknown_finger_and_single_actuator_functions_refuse_a_gripper(tmp_path):
    g = load_config(write(tmp_path, gripper_dict(2)))
    with pytest.raises(ConfigError, match=r"finger 'pinky': not a finger of this gripper; its fingers: thumb, index"):
        g.finger("pinky")
    with pytest.raises(ConfigError, match=r"is a gripper config \(fingers thumb, index\)"):
        bendsense.estimate_force(np.zeros(N), 0.0, g)
    with pytest.raises(ConfigError, match=r"config: the config 'test gripper' is a gripper config"):
        bendsense.mechanics.actuator.FreeBendingModel.from_config(g)
    with pytest.raises(AttributeError):
        g.no_such_attribute  # noqa: B018 (other attributes stay plain AttributeErrors)
    assert copy.deepcopy(g) == g
    assert pickle.loads(pickle.dumps(g)) == g  # (batch workers get it pickled)


def board(k=3, frames=5, lines=None):
    """A board session: finger i's channel j holds 1000 i + j; truth columns with finger prefixes."""
    t = np.arange(frames) * 1e-3
    signals = np.array([[1000.0 * (c // N) + c % N for c in range(k * N)]] * frames) + t[:, None]
    extra = {"thumb_fx_n": np.full(frames, 0.1), "index_fx_n": np.full(frames, 0.2), "label": np.arange(frames),
             "fx_n": np.full(frames, 9.0)}
    return Session(t, signals, 1000.0 * np.arange(frames), np.arange(frames) + 7, {"device": "board"}, extra,
                   "board.csv")


def test_split_session_gives_each_finger_its_channels_and_truth(tmp_path):
    g = load_config(write(tmp_path, gripper_dict(3)))
    # every finger on line 0 here: the board has one pressure line
    g = GripperConfig(name="g", fingers=tuple(Finger(name=f.name, channels=f.channels, pressure_line=0,
                                                     config=f.config) for f in g.fingers))
    session = board(3)
    parts = split_session(session, g)
    assert list(parts) == ["thumb", "index", "middle"]
    for i, name in enumerate(parts):
        s = parts[name]
        np.testing.assert_array_equal(s.signals, 1000.0 * i + np.arange(N) + session.t_s[:, None])
        np.testing.assert_array_equal(s.t_s, session.t_s)
        np.testing.assert_array_equal(s.seq, session.seq)
        np.testing.assert_array_equal(s.pressure_pa, session.pressure_pa)
        assert s.meta == session.meta and s.source == "board.csv"
    assert list(parts["thumb"].extra) == ["label", "fx_n"] and parts["thumb"].extra["fx_n"][0] == 0.1
    assert parts["index"].extra["fx_n"][0] == 0.2
    assert parts["middle"].extra["fx_n"][0] == 9.0  # no truth of its own: the shared column
    np.testing.assert_array_equal(parts["middle"].extra["label"], np.arange(5))


def test_split_refuses_a_board_too_small(tmp_path):
    g = load_config(write(tmp_path, gripper_dict(3)))
    small = board(2)
    with pytest.raises(SessionError, match=r"board.csv: 32 channels, but finger middle reads channel 48 "
                                           r"\(fingers\[2\].channels of the config\)"):
        split_session(small, g)
    two = GripperConfig(name="", fingers=g.fingers[:2])
    with pytest.raises(SessionError, match=r"board.csv: 1 pressure line, but finger index is on line 1"):
        split_session(small, two)
    with pytest.raises(ArgumentError, match=r"signals: 32 channels, but finger middle reads channel 48"):
        split_signals(small.signals, small.pressure_pa, g)


def test_split_signals_picks_lines(tmp_path):
    g = load_config(write(tmp_path, gripper_dict(3)))
    rng = np.random.default_rng(0)
    signals, pressure = rng.normal(size=(4, 3 * N)), rng.normal(size=(4, 3))
    parts = split_signals(signals, pressure, g)
    for i, f in enumerate(g.fingers):
        sig, p = parts[f.name]
        np.testing.assert_array_equal(sig, signals[:, i * N:(i + 1) * N])
        np.testing.assert_array_equal(p, pressure[:, i])
    with pytest.raises(ArgumentError, match=r"signals: 2 pressure lines, but finger middle is on line 2 "
                                            r"\(fingers\[2\].pressure_line of the config, 0-based\)"):
        split_signals(signals, pressure[:, :2], g)
    with pytest.raises(ArgumentError, match=r"pressure_pa: expected shape \(4,\) or \(4, n_lines\)"):
        split_signals(signals, pressure[:3], g)


def test_split_session_gives_each_finger_its_pressure_line(tmp_path):
    """A board with several pressure lines: each finger gets its own line's pressure, 1-D."""
    data = gripper_dict(3)
    data["fingers"][2]["pressure_line"] = 1  # the middle shares the index's line
    g = load_config(write(tmp_path, data))
    session = board(3)
    lines = np.column_stack([session.pressure_pa, session.pressure_pa + 5e3, session.pressure_pa + 9e3])
    multi = Session(session.t_s, session.signals, lines, session.seq, session.meta, session.extra, session.source)
    assert multi.pressure_pa.shape == (5, 3)
    parts = split_session(multi, g)
    np.testing.assert_array_equal(parts["thumb"].pressure_pa, lines[:, 0])
    np.testing.assert_array_equal(parts["index"].pressure_pa, lines[:, 1])
    np.testing.assert_array_equal(parts["middle"].pressure_pa, lines[:, 1])
    assert all(p.pressure_pa.ndim == 1 for p in parts.values())
    g4 = GripperConfig(name="", fingers=(*g.fingers[:2], Finger(name="ring", channels=g.fingers[2].channels,
                                                                pressure_line=3, config=g.fingers[2].config)))
    with pytest.raises(SessionError, match=r"board.csv: 3 pressure lines, but finger ring is on line 3 "
                                           r"\(fingers\[2\].pressure_line of the config, 0-based\)"):
        split_session(multi, g4)


@pytest.mark.parametrize(("section", "keep"), [
    ("stiffness", ["ei0_nm2"]), ("material", ["shear_modulus_pa", "sensor_stiffness_nm_per_rad"]),
    ("sensor", ["n_segments", "segment_lengths_m", "strip_gap_m", "sleeve_thickness_m"]),
    ("actuator", ["chamber_radius_m", "bottom_thickness_m", "wall_thickness_m", "length_m", "mass_kg"]),
])
def test_a_partial_section_names_its_missing_keys(tmp_path, section, keep):
    """A finger's section replaces the gripper's whole: one that lacks keys is an error naming them (the finger's
    stiffness without ei1_nm2_per_pa was EI(P) = ei0, silently); a single actuator's model parameters too."""
    from click.testing import CliRunner

    from bendsense.cli import main

    data = gripper_dict()
    partial = {k: v for k, v in PAPER[section].items() if k in keep}
    lacking = sorted(k for k in PAPER[section] if k not in keep)  # in the order of the YAML (safe_dump sorts)
    data["fingers"][1][section] = partial
    path = write(tmp_path, data)
    with pytest.raises(ConfigError, match=rf"fingers\[1\]\.{section}: missing keys {', '.join(lacking)} \(a finger's "
                                          r"section replaces the gripper's whole"):
        load_config(path)
    from bendsense.session import write_session_csv

    write_session_csv(Session(np.arange(3) * 0.01, np.full((3, 3 * N), 2000.0), np.full(3, 40e3)), tmp_path / "s.csv")
    res = CliRunner().invoke(main, ["load", str(tmp_path / "s.csv"), "--config", str(path), "save",
                                    str(tmp_path / "never")])
    assert res.exit_code != 0 and len(res.output.strip().splitlines()) == 1 and lacking[0] in res.output
    assert not (tmp_path / "never").exists()
    model = {"stiffness": ["ei1_nm2_per_pa"], "material": ["prebend_angle_rad"]}.get(section)
    if model:  # a single actuator: its model parameters must be given (the others keep documented defaults)
        single = {**PAPER, section: partial}
        with pytest.raises(ConfigError, match=rf"{section}: missing keys {model[0]}$"):
            load_config(write(tmp_path, single, "one.yaml"))
