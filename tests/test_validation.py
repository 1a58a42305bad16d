"""The error layer: ArgumentError, the checks of bendsense.validation, the bounded readers."""

import pickle
import time
import tracemalloc

import numpy as np
import pytest

import bendsense
from bendsense import validation as check
from bendsense._io import MAX_YAML_BYTES, MAX_YAML_NODES
from bendsense.errors import ArgumentError, BendsenseError, ConfigError, SessionError
from bendsense.session import read_session_csv


def test_argument_error_is_a_value_error_and_pickles():
    err = ArgumentError("x: expected > 0, got -1")
    assert isinstance(err, BendsenseError) and isinstance(err, ValueError)
    again = pickle.loads(pickle.dumps(err))
    assert type(again) is ArgumentError and str(again) == str(err)


@pytest.mark.parametrize(
    ("value", "kwargs", "message"),
    [
        ("7", {}, r"^f: expected a number, got '7'$"),
        (True, {}, r"^f: expected a number, got True$"),
        (float("nan"), {}, r"^f: expected a finite number, got nan$"),
        (-np.inf, {"positive": True}, r"^f: expected a finite number, got -inf$"),
        (0, {"positive": True}, r"^f: expected > 0, got 0.0$"),
        (-1e-9, {"nonnegative": True}, r"^f: expected >= 0, got -1e-09$"),
        (11, {"maximum": 10}, r"^f: expected <= 10, got 11.0$"),
    ],
)
def test_number_messages(value, kwargs, message):
    with pytest.raises(ArgumentError, match=message):
        check.number("f", value, **kwargs)


def test_checks_raise_the_given_error_class():
    with pytest.raises(ConfigError, match=r"^g: expected one of a, b, got 'c'$"):
        check.choice("g", "c", ("a", "b"), error=ConfigError)
    with pytest.raises(SessionError, match=r"^n: expected an integer in 1\.\.64, got 65$"):
        check.integer("n", 65, minimum=1, maximum=64, error=SessionError)
    assert check.integer("n", np.int64(3), minimum=1) == 3
    with pytest.raises(ArgumentError, match="expected an integer"):
        check.integer("n", 3.0)


@pytest.mark.parametrize("value", [0.132, 1.0])
def test_length_in_metres_passes(value):
    assert check.length_m("l", value) == value


def test_length_a_thousand_times_off_looks_like_millimetres():
    with pytest.raises(ArgumentError, match=r"^l: expected a length in metres <= 1, got 134; looks like millimetres "
                                            r"\(did you mean 0\.134\?\)$"):
        check.length_m("l", 134)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -1.0, 0.0])
def test_duration_refuses_nan_inf_and_negatives(value):
    with pytest.raises(ArgumentError, match="^--seconds: expected"):
        check.duration_s("--seconds", value)


def test_messages_never_embed_unbounded_values():
    huge = "x" * 1_000_000
    for value in (huge, list(range(100_000)), np.arange(1e6), {i: i for i in range(10_000)}, b"\xff" * 10**6):
        text = check.short(value)
        assert len(text) <= check.SHORT_LIMIT
        err = check.fail("field", "something", value)
        assert len(str(err)) < 120 and "\n" not in str(err)


def _yaml_bomb(levels=9, width=9) -> str:
    lines = ["a0: &a0 [" + ", ".join(['"lol"'] * width) + "]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def test_yaml_alias_bomb_is_refused_quickly_in_bounded_memory(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(_yaml_bomb())  # 9^9 = 387 million strings once expanded
    tracemalloc.start()
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=rf"bomb.yaml: YAML expands to more than {MAX_YAML_NODES:,} nodes"):
        bendsense.load_config(path)
    elapsed = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert elapsed < 1.0 and peak < 50e6


def test_recursive_yaml_alias_is_refused(tmp_path):
    path = tmp_path / "loop.yaml"
    path.write_text("sensor: &s {n_segments: 16, again: *s}\n")
    with pytest.raises(ConfigError, match=r"loop.yaml: YAML alias refers to itself"):
        bendsense.load_config(path)


def test_large_yaml_is_refused_by_size_and_by_node_count(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"# " + b"x" * MAX_YAML_BYTES + b"\n")
    with pytest.raises(ConfigError, match=r"big.yaml: too large for a config \(over 2 MiB\)"):
        bendsense.load_config(big)
    flat = tmp_path / "flat.yaml"
    flat.write_text("x: [" + ",".join(["1"] * (MAX_YAML_NODES + 10)) + "]\n")
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=rf"flat.yaml: YAML has more than {MAX_YAML_NODES:,} nodes"):
        bendsense.load_config(flat)
    assert time.perf_counter() - start < 1.0


def test_yaml_syntax_error_is_one_line_with_line_and_column(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("sensor:\n  n_segments: [1,\n  x: }\n")
    with pytest.raises(ConfigError) as info:
        bendsense.load_config(path)
    assert "\n" not in str(info.value)
    assert str(info.value).startswith(f"{path}: not valid YAML: ") and "(line 3, column 6)" in str(info.value)


def test_utf8_bom_is_accepted(tmp_path):
    config = tmp_path / "bom.yaml"
    config.write_bytes(b"\xef\xbb\xbf" + (bendsense.config.resources.files("bendsense.data") / "paper.yaml")
                       .read_bytes())
    assert bendsense.load_config(config) == bendsense.load_config()
    csv = tmp_path / "bom.csv"
    csv.write_bytes(b"\xef\xbb\xbft_s,ch1\n0,1\n")
    assert read_session_csv(csv).signals.tolist() == [[1.0]]


def test_binary_and_non_utf8_files_name_the_byte_offset(tmp_path):
    binary = tmp_path / "garbage.yaml"
    binary.write_bytes(b"sensor:\x00\x01\x02")
    with pytest.raises(ConfigError, match=r"garbage.yaml: binary data, not a config \(NUL byte at byte offset 7\)"):
        bendsense.load_config(binary)
    latin = tmp_path / "latin.yaml"
    latin.write_bytes("name: caf\u00e9\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin.yaml: not UTF-8 text \(byte offset 9, line 1\)"):
        bendsense.load_config(latin)


@pytest.mark.parametrize(("sep", "name"), [(";", "';'"), ("\t", "tabs")])
def test_other_csv_separators_are_named(tmp_path, sep, name):
    path = tmp_path / "excel.csv"
    path.write_text(f"t_s{sep}ch1{sep}ch2\n0{sep}1,5{sep}2\n")
    with pytest.raises(SessionError, match=rf"excel.csv: line 1: columns are separated by {name}, expected ','"):
        read_session_csv(path)


def test_no_bare_value_errors_for_user_input_and_no_cli_handler_catches_them():
    # ArgumentError (a ValueError) is the library's error for a bad argument; a CLI
    # handler that caught ValueError would hide real bugs behind a one-line message
    import re
    from pathlib import Path

    src = Path(bendsense.__file__).parent
    raises = [f"{p.name}:{i}" for p in src.rglob("*.py")
              for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
              if re.search(r"raise ValueError\(", line)]
    assert raises == []
    catches = [f"{p.name}:{i}" for p in (src / "cli").rglob("*.py")
               for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
               if re.search(r"except\s*\(?[^)]*\bValueError\b", line)]
    assert catches == []


def test_a_repeated_yaml_key_is_refused_with_both_lines(tmp_path):
    text = (bendsense.config.resources.files("bendsense.data") / "paper.yaml").read_text()
    path = tmp_path / "twice.yaml"
    path.write_text(text + "stiffness:\n  ei0_nm2: 0.001\n")
    first = 1 + text.splitlines().index("stiffness:")
    second = len(text.splitlines()) + 1
    message = rf"twice.yaml: duplicate key 'stiffness' \(line {second}; first on line {first}\)"
    with pytest.raises(ConfigError, match=message):
        bendsense.load_config(path)
