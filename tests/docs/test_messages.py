"""Every ``Error:`` and ``WARNING:`` line the docs show comes from the code.

The docs' example messages (``text`` blocks of README.md and docs/*.md) are read from
the pages, never pasted here. A line is covered when

- it is in an ``<!-- output -->`` block: tests/docs/test_docs.py runs the command above
  it and compares;
- the pinned message regex of a case of the bad-input corpus
  (tests/robustness/test_invalid_corpus.py) finds it; or
- a provoker below recreates the documented situation for real (the file names the
  page uses, in a temporary directory), runs ``bendsense`` and the documented line
  appears exactly in its output (masked as in test_docs.py: rates, durations,
  ``/dev/pts/N``, temporary paths; a trailing `` ...`` abridges).

``test_every_documented_message_is_checked`` fails on a line covered by none of
these, so that a message pasted into the docs fails CI.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import run_cli
from robustness.test_invalid_corpus import (
    CALIBRATIONS,
    CLI,
    CONFIGS,
    GOOD_CAL,
    MANIFESTS,
    NATIVE,
    RESULTS,
    SESSIONS,
    expected,
)

from docs.test_docs import FENCE, OUTPUT_MARK, PAGES, ROOT, missing_output

MESSAGE = re.compile(r"^\s*(?:Error|WARNING):")
N = 16


def documented_messages() -> list[tuple[str, str, bool]]:
    """``(page, line, in_output_block)`` of every Error/WARNING line of a text block."""
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            if m["lang"].lower() != "text":
                continue
            line_start = text.rfind("\n", 0, max(m.start() - 1, 0)) + 1 if m.start() else 0
            marked = bool(OUTPUT_MARK.match(text[line_start:m.start()]))
            out += [(page.name, line.strip(), marked) for line in m["body"].splitlines() if MESSAGE.match(line)]
    return out


def corpus_patterns() -> list[str]:
    pats = [expected(p) for p in (*CONFIGS, *SESSIONS, *CALIBRATIONS, *MANIFESTS, *NATIVE, *RESULTS)]
    return pats + [yaml.safe_load(p.read_text(encoding="utf-8"))["expect"] for p in CLI]


# ------------------------------------------------------------------ provokers

PROVOKERS: dict[str, object] = {}


def provokes(key: str):
    """Register a provoker of the documented lines that ``key`` (a regex) finds."""

    def register(fn):
        PROVOKERS[key] = fn
        return fn

    return register


def bendsense(cwd: Path, *args: str, ok: bool = False) -> str:
    """``bendsense ARGS`` in ``cwd`` (the command line called in this process, :func:`helpers.run_cli`): its
    stdout + stderr; exit 0 if ``ok``, else non-zero."""
    proc = run_cli(args, cwd=cwd)
    text = proc.stdout + "\n" + proc.stderr
    assert (proc.returncode == 0) == ok, f"exit {proc.returncode}:\n{text}"
    assert "Traceback" not in text
    return text


def offsets(n=N) -> np.ndarray:
    return np.array(yaml.safe_load(GOOD_CAL.read_text(encoding="utf-8"))["offset"][:n])


def write_csv(path: Path, pressure, signals, pressure_column="pressure_kpa", sep=","):
    n = signals.shape[1]
    head = sep.join(["t_s", pressure_column, *(f"ch{i + 1}" for i in range(n))])
    rows = [sep.join([f"{0.01 * k:g}", f"{p:g}", *(f"{s:g}" for s in sig)])
            for k, (p, sig) in enumerate(zip(pressure, signals))]
    path.write_text("\n".join([head, *rows]) + "\n", encoding="utf-8")


def flat_run(tmp: Path, frames=10, n=N, **kw):
    write_csv(tmp / "run.csv", kw.pop("pressure", np.full(frames, 40.0)), np.tile(offsets(n), (frames, 1)), **kw)


def cal(tmp: Path) -> Path:
    (tmp / "cal.yaml").write_bytes(GOOD_CAL.read_bytes())
    return tmp / "cal.yaml"


@provokes(r"frames outside the calibrated signal range")
def extrapolated(tmp):
    signals = np.tile(offsets(), (220, 1))
    signals[100:120] += 5000.0  # 20 frames far beyond the fitted signal range
    write_csv(tmp / "run.csv", np.full(220, 40.0), signals)
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct", ok=True)


@provokes(r"window check: 50 ms windows hold at most 3 frames at 35 Hz")
def windows_at_35_hz(tmp):
    signals = np.tile(offsets(), (40, 1)) + np.random.default_rng(0).normal(0.0, 1.5, (40, N))
    rows = [",".join([repr(k / 35), "40", *(f"{v:.3f}" for v in sig)]) for k, sig in enumerate(signals)]
    (tmp / "run.csv").write_text("\n".join(["t_s,pressure_kpa," + ",".join(f"ch{i + 1}" for i in range(N)), *rows])
                                 + "\n", encoding="utf-8")
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "estimate", ok=True)


@provokes(r"frames have a pressure outside actuator\.pressure_range_pa")
def pressure_out_of_range(tmp):
    pressure = np.full(88, 40.0)
    pressure[::4] = 250.0  # 22 of 88 frames above the paper config's 200 kPa
    write_csv(tmp / "run.csv", pressure, np.tile(offsets(), (88, 1)))
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "estimate", ok=True)


@provokes(r"run\.csv: line 1: columns are separated by ';'")
def semicolons(tmp):
    flat_run(tmp, sep=";")
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct")


@provokes(r"cal\.yaml: too large for a calibration")
def calibration_too_large(tmp):
    flat_run(tmp)
    (tmp / "cal.yaml").write_text(GOOD_CAL.read_text(encoding="utf-8") + ("#" + "x" * 1023 + "\n") * 2049)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct")


@provokes(r"cal\.yaml: YAML has more than [\d,]+ nodes")
def calibration_too_many_nodes(tmp):
    flat_run(tmp)
    (tmp / "cal.yaml").write_text("format: bendsense-calibration\nnotes: [" + "1," * 50_001 + "1]\n")
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct")


@provokes(r"WARNING: pressure_pa: every pressure is below 1 kPa \(largest 120 Pa\)")
def pressure_pa_holds_kpa(tmp):
    flat_run(tmp, pressure=np.linspace(20, 120, 10), pressure_column="pressure_pa")
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "estimate", ok=True)


@provokes(r"run\.csv: line \d+, column pressure_kpa: readings up to")
def pressure_kpa_holds_pa(tmp):
    flat_run(tmp, pressure=np.linspace(20_000, 120_000, 10))
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct")


@provokes(r"run\.csv: \d+ signal channels \(ch1\.\.ch\d+\), but the calibration")
def session_channels(tmp):
    flat_run(tmp, n=8)
    cal(tmp)
    return bendsense(tmp, "load", "run.csv", "--calibration", "cal.yaml", "reconstruct")


@provokes(r"channels, but the config's sensor has \d+ segments")
def config_segments(tmp):
    flat_run(tmp)
    cal(tmp)
    config = yaml.safe_load((ROOT / "configs" / "paper.yaml").read_text(encoding="utf-8"))
    config["sensor"]["n_segments"] = 8
    if isinstance(config["sensor"].get("segment_lengths_m"), list):
        config["sensor"]["segment_lengths_m"] = config["sensor"]["segment_lengths_m"][:8]
    (tmp / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    return bendsense(tmp, "load", "run.csv", "--config", "config.yaml", "--calibration", "cal.yaml", "reconstruct")


def native_run(tmp: Path, records: int) -> tuple[Path, int]:
    """A finished native session ``run1/`` of ``records`` 16-channel records; its record size."""
    from bendsense.session.native import SessionWriter, record_dtype

    d = tmp / "run1"
    with SessionWriter(d, record_dtype(N), adc_bits=12, device={"firmware": "docs"}) as w:
        rec = w.empty(records)
        rec["t_us"] = np.arange(records) * 2000
        rec["host_ns"] = np.arange(records) * 2_000_000
        rec["seq"] = np.arange(records)
        rec["pressure_pa"] = 40_000
        rec["adc"] = offsets().astype(np.uint16)
        w.write(rec)
    return d, rec.dtype.itemsize


def load_native(tmp, ok=False):
    cal(tmp)
    return bendsense(tmp, "load", "run1", "--calibration", "cal.yaml", "reconstruct", ok=ok)


@provokes(r"run1/frames\.bin: [\d,]+ of [\d,]+ records present; [\d,]+ lost \(frames\.bin was cut short")
def frames_cut_short(tmp):
    d, size = native_run(tmp, 1500)
    frames = d / "frames.bin"
    frames.write_bytes(frames.read_bytes()[: 745 * size])
    return load_native(tmp)


@provokes(r"run1/frames\.bin: [\d,]+ records present, but meta\.yaml recorded")
def frames_too_long(tmp):
    d, size = native_run(tmp, 1500)
    frames = d / "frames.bin"
    data = frames.read_bytes()
    frames.write_bytes(data + data[: 10 * size])
    return load_native(tmp)


@provokes(r"run1/meta\.yaml: record_size is \d+ bytes, but record_dtype gives")
def record_size_edited(tmp):
    d, _ = native_run(tmp, 20)
    meta = yaml.safe_load((d / "meta.yaml").read_text(encoding="utf-8"))
    meta["record_size"] = 60
    (d / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return load_native(tmp)


@provokes(r"run1: unfinished recording")
def unfinished(tmp):
    d, size = native_run(tmp, 1234)
    meta = yaml.safe_load((d / "meta.yaml").read_text(encoding="utf-8"))
    meta["finished"] = False  # as meta.yaml reads while recording (killed, crashed)
    meta.pop("n_records", None)
    (d / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    with open(d / "frames.bin", "ab") as f:
        f.write(b"\x01" * 7)  # a torn last record
    return load_native(tmp, ok=True)


@provokes(r"Invalid value for --scheduler: expected tcp://HOST:PORT, got 'localhost'")
def scheduler_without_scheme(tmp):
    flat_run(tmp)
    cal(tmp)
    return bendsense(tmp, "process", "run.csv", "--calibration", "cal.yaml", "-o", "out", "--scheduler", "localhost")


UNWRITABLE_FOR_ROOT = ("/sys/kernel/uevent_seqnum", "/proc/sys/kernel/osrelease", "/proc/sys/kernel/ostype")


def _refuses_write(path: str) -> bool:
    try:
        os.close(os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK))
    except PermissionError:
        return True
    except OSError:
        return False
    return False


@provokes(r"/dev/ttyACM0: cannot open serial port \(\[Errno 13\]")
def permission_denied(tmp):
    # root opens any file; a read-only sysfs or sysctl file refuses even root
    if os.geteuid() == 0:
        port = next((f for f in UNWRITABLE_FOR_ROOT if _refuses_write(f)), None)
        assert port, f"none of {UNWRITABLE_FOR_ROOT} refuses root's O_RDWR open with EACCES here"
    else:
        port = str(tmp / "ttyACM0")
        Path(port).touch()
        Path(port).chmod(0)
    return bendsense(tmp, "record", port, "-o", "s", "--seconds", "1"), {"/dev/ttyACM0": port}


@provokes(r"/dev/ttyACM0: no HELLO within")
def no_hello(tmp):
    master, slave = os.openpty()  # a terminal whose other end never answers
    try:
        port = os.ttyname(slave)
        return bendsense(tmp, "record", port, "-o", "s", "--seconds", "1"), {"/dev/ttyACM0": port}
    finally:
        os.close(slave)
        os.close(master)


# ------------------------------------------------------------------ the tests


@pytest.mark.parametrize("key", list(PROVOKERS), ids=[f.__name__ for f in PROVOKERS.values()])
def test_documented_message_is_what_the_code_prints(key, tmp_path):
    lines = [line for _, line, _ in documented_messages() if re.search(key, line)]
    assert lines, f"no page shows a message that {key!r} finds (remove the provoker?)"
    result = PROVOKERS[key](tmp_path)
    output, subst = result if isinstance(result, tuple) else (result, {})
    for line in lines:
        for doc_path, real in subst.items():
            line = line.replace(doc_path, real)
        assert not missing_output(line, output), f"documented:\n{line}\nprinted:\n{output}"


def unchecked(messages: list[tuple[str, str, bool]]) -> list[str]:
    """The messages that no output block, corpus case or provoker checks."""
    patterns = [*corpus_patterns(), *PROVOKERS]
    return [f"{page}: {line}" for page, line, in_output in messages
            if not in_output and not any(re.search(p, line) for p in patterns)]


def test_every_documented_message_is_checked():
    missing = unchecked(documented_messages())
    assert not missing, "documented messages neither provoked nor in the corpus:\n" + "\n".join(missing)


def test_a_pasted_message_is_caught():
    pasted = ("x.md", "Error: run.csv: the sensor is on fire", False)
    corpus = ("x.md", "Error: run.csv: UTF-16 text, not UTF-8; save the file as UTF-8", False)
    provoked = ("x.md", "Error: run1/frames.bin: 3 of 9 records present; 6 lost (frames.bin was cut short ...", False)
    in_output = ("x.md", "Error: run.csv: the sensor is on fire", True)
    assert unchecked([pasted, corpus, provoked, in_output]) == ["x.md: Error: run.csv: the sensor is on fire"]


def test_the_walk_finds_the_messages():
    # the walk itself works: messages of both kinds, from text blocks only
    found = documented_messages()
    assert any(line.startswith("Error: ") for _, line, _ in found)
    assert any(line.startswith("WARNING: ") for _, line, _ in found)
    assert all(MESSAGE.match(line) for _, line, _ in found)
