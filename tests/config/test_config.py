import dataclasses
import math
from pathlib import Path

import pytest
import yaml

import bendsense
from bendsense.config import Config, GravityConfig, SensorConfig, load_config, save_config
from bendsense.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
INVALID = sorted((Path(__file__).parents[1] / "data" / "invalid" / "configs").glob("*.yaml"))


def _expected(path):
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("# expect: ")
    return first[len("# expect: ") :]


def test_builtin_config_is_the_shipped_paper_yaml():
    shipped = (ROOT / "configs" / "paper.yaml").read_text(encoding="utf-8")
    builtin = (ROOT / "src" / "bendsense" / "data" / "paper.yaml").read_text(encoding="utf-8")
    assert shipped == builtin
    assert bendsense.load_config() == load_config(ROOT / "configs" / "paper.yaml")


def test_paper_values_in_si_units():
    cfg = load_config()
    assert cfg.sensor.n_segments == 16
    assert cfg.sensor.segment_lengths_m[0] == 0.010 and cfg.sensor.segment_lengths_m[1] == 0.008
    assert math.isclose(cfg.sensor.length_m, 0.132)
    assert cfg.actuator.length_m == 0.134
    assert math.isclose(cfg.actuator.mass_kg, 0.02586 + 0.01341)
    # gamma_1 = 1.25e-5 N m^2 / kPa
    assert math.isclose(cfg.stiffness.ei_nm2(60e3), 2.53e-3 + 1.25e-5 * 60)
    w = cfg.weight_per_length_n_per_m
    assert math.isclose(w[1], -0.03927 * 9.81 / 0.134) and w[0] == 0


def test_yaml_round_trip_is_exact(tmp_path):
    cfg = load_config()
    save_config(cfg, tmp_path / "c.yaml")
    again = load_config(tmp_path / "c.yaml")
    assert again == cfg
    assert yaml.safe_load((tmp_path / "c.yaml").read_text()) == cfg.to_dict()


def test_dataclasses_are_frozen_and_keyword_only():
    cfg = load_config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.sensor.strip_gap_m = 2.0
    with pytest.raises(TypeError):
        SensorConfig(16, [0.008] * 16, 0.001, 0.0)


@pytest.mark.parametrize("path", INVALID, ids=[p.stem for p in INVALID])
def test_invalid_config_corpus(path):
    with pytest.raises(ConfigError, match=_expected(path)):
        load_config(path)


def test_corpus_is_large_enough():
    assert len(INVALID) >= 20


def test_error_is_a_value_error_and_pickles():
    import pickle

    with pytest.raises(ValueError) as info:
        GravityConfig(direction=(1.0, 1.0))
    again = pickle.loads(pickle.dumps(info.value))
    assert isinstance(again, ConfigError) and str(again) == str(info.value)


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(tmp_path / "nope.yaml")


def test_replace_section():
    cfg = load_config()
    stiffer = cfg.replace(stiffness=dataclasses.replace(cfg.stiffness, ei0_nm2=5e-3))
    assert stiffer.stiffness.ei0_nm2 == 5e-3 and cfg.stiffness.ei0_nm2 == 2.53e-3
    assert isinstance(stiffer, Config)
