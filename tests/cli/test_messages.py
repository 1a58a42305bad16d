"""The poor messages of issue 21: a fallback pressure that changes nothing, a second ``load``,
``-q`` that still printed reports, internal class names, nonsense baud rates.

(The one-line errors are also corpus cases: tests/data/invalid/cli/load_twice.yaml, *_baud_*.yaml.)
"""

import logging

import numpy as np
import pytest
from calibration.test_calibration import RADII, SyntheticSensor, write_manifest
from click.testing import CliRunner
from robustness.test_invalid_corpus import GOOD_CAL, GOOD_CSV

from bendsense.cli import main
from bendsense.errors import DeviceError, FrameError


def _run(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return CliRunner().invoke(main, [str(a) for a in args])


def test_pressure_kpa_ignored_when_every_frame_has_a_reading(tmp_path, monkeypatch, caplog):
    # good/session.csv has a pressure_kpa column: --pressure-kpa 50 changes nothing, and says so
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        result = _run(["load", GOOD_CSV, "--pressure-kpa", "50", "--calibration", GOOD_CAL, "reconstruct", "save",
                       "out"], tmp_path, monkeypatch)
    assert result.exit_code == 0, result.output
    assert [r.getMessage() for r in caplog.records] == [
        f"--pressure-kpa ignored: every frame of {GOOD_CSV} has a pressure reading (the fallback fills only frames "
        "without one)"]
    pressure = np.genfromtxt(tmp_path / "out" / "results.csv", delimiter=",", names=True)["pressure_pa"]
    np.testing.assert_array_equal(pressure, [20e3, 40e3, 60e3, 80e3])  # the recorded readings, not 50 kPa


def test_pressure_kpa_that_fills_some_frames_says_how_many(tmp_path, monkeypatch, caplog):
    lines = GOOD_CSV.read_text().splitlines()
    lines[2] = lines[2].replace(",40,", ",,", 1)  # frame 2 without a reading
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        result = _run(["load", tmp_path / "s.csv", "--pressure-kpa", "50", "--calibration", GOOD_CAL, "reconstruct",
                       "save", "out"], tmp_path, monkeypatch)
    assert result.exit_code == 0, result.output
    assert "--pressure-kpa fills the 1 of 4 frames of" in caplog.text
    assert "without a pressure reading; the other 3 keep their reading" in caplog.text


def test_a_live_fallback_pressure_the_board_overrides_is_told_once(caplog):
    from bendsense.calibration import Calibration
    from bendsense.pipeline import LiveProcessor

    proc = LiveProcessor(Calibration.load(GOOD_CAL), pressure_pa=50e3, estimate=False)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        proc.process_block(np.full((2, 16), 2000.0), np.array([np.nan, np.nan]))
        assert "fallback pressure" not in caplog.text  # it filled both frames: nothing to say
        for _ in range(3):
            proc.process_block(np.full((2, 16), 2000.0), np.array([20e3, np.nan]))
    assert caplog.text.count("the fallback pressure 50 kPa is ignored for frames with a pressure reading") == 1


def test_load_twice_is_an_error_before_any_work(tmp_path, monkeypatch):
    result = _run(["load", GOOD_CSV, "--calibration", GOOD_CAL, "reconstruct", "save", "a", "load", GOOD_CSV,
                   "--calibration", GOOD_CAL, "reconstruct", "save", "b"], tmp_path, monkeypatch)
    assert result.exit_code == 2
    assert result.output.startswith("Error: 'load' given 2 times")
    assert "use 'bendsense process SESSION... -o OUT' for several" in result.output
    assert list(tmp_path.iterdir()) == []  # neither a nor b


def test_calibrate_quiet_prints_only_errors(tmp_path, monkeypatch):
    manifest = write_manifest(tmp_path, SyntheticSensor(), radii=RADII[:4])
    loud = _run(["calibrate", manifest, "-o", "cal.yaml"], tmp_path, monkeypatch)
    assert loud.exit_code == 0 and "wrote cal.yaml" in loud.output and len(loud.output.splitlines()) > 3
    quiet = _run(["-q", "calibrate", manifest, "-o", "cal2.yaml", "--plot", "fit.png"], tmp_path, monkeypatch)
    assert quiet.exit_code == 0, quiet.output
    assert quiet.output == ""
    assert (tmp_path / "cal2.yaml").is_file() and (tmp_path / "fit.png").is_file()
    # and an error still is one line
    failed = _run(["-q", "calibrate", manifest, "-o", "cal2.yaml"], tmp_path, monkeypatch)
    assert failed.exit_code == 1 and failed.output.startswith("Error: ") and len(failed.output.splitlines()) == 1


@pytest.mark.parametrize("args", [
    ["-q", "load", GOOD_CSV, "--calibration", GOOD_CAL, "reconstruct", "save", "out", "export", "s.csv"],
    ["-q", "simulate", "validation", "-o", "sim", "--frames", "2"],
])
def test_quiet_chains_print_nothing(tmp_path, monkeypatch, args):
    result = _run(args, tmp_path, monkeypatch)
    assert result.exit_code == 0, result.output
    assert result.output == ""
    assert any(tmp_path.iterdir())


def test_the_line_dialect_message_says_what_the_user_knows():
    from bendsense.wire.frames import LineDecoder

    with pytest.raises(FrameError, match=r"^the line dialect needs its column layout: give columns") as info:
        LineDecoder()
    assert "LineDecoder" not in str(info.value)


@pytest.mark.parametrize("baud", [0, -9600, 10**9, 9600.5, True])
def test_driver_refuses_nonsense_baud_rates(baud):
    from bendsense.device.driver import Driver

    with pytest.raises(DeviceError, match=r"baudrate: expected an integer in 50\.\.12,000,000"):
        Driver("loop://", baudrate=baud)


@pytest.mark.parametrize("args", [
    ["record", "/dev/null", "-o", "new.csv"],
    ["control", "/dev/null", "--calibration", GOOD_CAL, "--target-force-n", "0.1", "-o", "run.CSV"],
    ["process", GOOD_CSV, "--calibration", GOOD_CAL, "-o", "out.csv"],
    ["load", GOOD_CSV, "--calibration", GOOD_CAL, "reconstruct", "save", "results.csv"],
    ["simulate", "validation", "-o", "sessions.csv"],
    ["demo", "-o", "demo.png"],
    ["reproduce", "--quick", "-o", "report.md"],
    ["record", "/dev/null", "-o", "rec.yaml"],
], ids=["record", "control", "process", "save", "simulate", "demo", "reproduce", "record-yaml"])
def test_a_directory_output_named_like_a_file_is_refused_before_any_work(args, tmp_path, monkeypatch):
    """``record -o new.csv`` made a directory named ``new.csv``, ``demo -o demo.png`` one holding ``demo.png/demo.png``:
    every command that writes a directory refuses a file's name in one line, and writes nothing."""
    result = _run(args, tmp_path, monkeypatch)
    assert result.exit_code == 2, result.output
    name = args[-1]
    suffix = "." + name.rsplit(".", 1)[1]
    assert result.output.strip().splitlines()[-1].endswith(
        f"{name!r} is a file's name ({suffix}), but this writes a directory of files: give a directory's name"), \
        result.output
    assert "Traceback" not in result.output
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, hint, said", [
    (["record", "/dev/bendsense-no-such-port", "-o", "rec", "--lsl-wait", "3"], "'--lsl-wait'", "it needs --lsl"),
    (["control", "/dev/bendsense-no-such-port", "--calibration", GOOD_CAL, "--target-force-n", "0.15",
      "--overwrite"], "'--overwrite'", "give -o"),
])
def test_an_option_of_another_option_is_refused_alone(args, hint, said, tmp_path, monkeypatch):
    result = _run(args, tmp_path, monkeypatch)
    assert result.exit_code == 2 and hint in result.output and said in result.output, result.output
    assert list(tmp_path.iterdir()) == []  # before any work: nothing made
