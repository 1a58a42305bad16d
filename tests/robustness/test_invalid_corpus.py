"""The bad-input corpus under tests/data/invalid: every case fails with its pinned message.

Each file case pins its message as a regular expression, on its first line
(``# expect: REGEX``) or, where the file cannot hold one (binary, not UTF-8, a
byte-order mark), in a ``NAME.expect`` sidecar; a native session directory holds an
``expect`` file (a second line ``cli-only``: the library reads it, the CLI refuses it).
``cli/*.yaml`` are command lines with their message.

Every case is checked twice: through the library (the error class and the message)
and through the ``bendsense`` command line, where a user mistake must give exactly
one ``Error:`` line naming the file, a non-zero exit code, no traceback, and must
leave nothing written.
"""

import os
import re
import shlex
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.errors import BendsenseError, ConfigError, SessionError
from bendsense.session import read_session, read_session_csv

DATA = Path(__file__).parents[1] / "data"
INVALID = DATA / "invalid"
GOOD_CSV = INVALID / "good" / "session.csv"
GOOD_CAL = DATA / "calibration" / "calibration_v1.yaml"


def _files(kind, pattern):
    return sorted(p for p in (INVALID / kind).glob(pattern) if p.is_file() and p.suffix != ".expect")


def expected(path: Path) -> str:
    sidecar = path.with_name(path.name + ".expect")
    if path.is_dir():
        return (path / "expect").read_text(encoding="utf-8").splitlines()[0]
    if sidecar.exists():
        return sidecar.read_text(encoding="utf-8").splitlines()[0]
    first = path.read_bytes().split(b"\n", 1)[0].decode("utf-8")
    assert first.startswith("# expect: "), f"{path}: no '# expect: ' line and no .expect sidecar"
    return first[len("# expect: "):]


CONFIGS = _files("configs", "*.yaml")
SESSIONS = _files("sessions", "*.csv")
CALIBRATIONS = _files("calibrations", "*.yaml")
MANIFESTS = _files("manifests", "*.yaml")
NATIVE = sorted(p for p in (INVALID / "native").iterdir() if p.is_dir())
RESULTS = sorted(p for p in (INVALID / "results").iterdir() if p.is_dir())
CLI = _files("cli", "*.yaml")


def test_the_corpus_is_large():
    cases = [*CONFIGS, *SESSIONS, *CALIBRATIONS, *MANIFESTS, *NATIVE, *RESULTS, *CLI]
    assert len(cases) >= 100
    for kind in (CONFIGS, SESSIONS, CALIBRATIONS, MANIFESTS, NATIVE, RESULTS, CLI):
        assert len(kind) >= 10


# --- through the library ------------------------------------------------------------------


@pytest.mark.parametrize("path", CALIBRATIONS, ids=[p.stem for p in CALIBRATIONS])
def test_calibration_api(path):
    with pytest.raises(ConfigError, match=expected(path)) as info:
        Calibration.load(path)
    assert str(info.value).startswith(str(path))


@pytest.mark.parametrize("path", MANIFESTS, ids=[p.stem for p in MANIFESTS])
def test_manifest_api(path):
    with pytest.raises(BendsenseError, match=expected(path)) as info:
        Calibration.fit(path)
    assert isinstance(info.value, (ConfigError, SessionError))


@pytest.mark.parametrize("path", NATIVE, ids=[p.name for p in NATIVE])
def test_native_session_api(path):
    if "cli-only" in (path / "expect").read_text():
        assert len(read_session(path)) == 0
        return
    with pytest.raises(SessionError, match=expected(path)) as info:
        read_session(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("path", RESULTS, ids=[p.name for p in RESULTS])
def test_results_api(path):
    from bendsense.results import read_results

    with pytest.raises(SessionError, match=expected(path)) as info:
        read_results(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("path", SESSIONS, ids=[p.stem for p in SESSIONS])
def test_session_api_message_starts_with_the_file(path):
    with pytest.raises(SessionError, match=expected(path)) as info:
        read_session_csv(path)
    assert str(info.value).startswith(str(path))


# --- through the command line -------------------------------------------------------------


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.lstat().st_size, p.lstat().st_mtime_ns)  # lstat: links/dangling
            for p in sorted(root.rglob("*"))}


def run_cli(args, tmp_path, match):
    """Run ``bendsense ARGS`` in an empty working directory; check the promises of a user mistake."""
    work = tmp_path / "work"
    work.mkdir()
    before_inputs = _tree(INVALID)
    old = os.getcwd()
    os.chdir(work)
    try:
        result = CliRunner().invoke(main, [str(a) for a in args])
    finally:
        os.chdir(old)
    text = result.output
    assert result.exit_code != 0, text
    assert isinstance(result.exception, SystemExit), f"{type(result.exception).__name__}: {result.exception}"
    assert "Traceback" not in text
    errors = [line for line in text.splitlines() if line.strip() and not line.startswith("WARNING:")]
    assert len(errors) == 1, text
    assert errors[0].startswith("Error: ") and re.search(match, errors[0]), text
    assert len(errors[0]) < 400
    assert _tree(work) == {}, "something was written"
    assert _tree(INVALID) == before_inputs


OUT = "out"  # relative to the empty working directory: must not appear


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_config_cli(path, tmp_path):
    args = ["load", GOOD_CSV, "--config", path, "--calibration", GOOD_CAL, "reconstruct", "estimate", "save", OUT]
    run_cli(args, tmp_path, re.escape(str(path)) + ": " + expected(path))


@pytest.mark.parametrize("path", SESSIONS, ids=[p.stem for p in SESSIONS])
def test_session_cli(path, tmp_path):
    args = ["load", path, "--calibration", GOOD_CAL, "reconstruct", "save", OUT]
    run_cli(args, tmp_path, re.escape(str(path)) + ": " + expected(path))


@pytest.mark.parametrize("path", CALIBRATIONS, ids=[p.stem for p in CALIBRATIONS])
def test_calibration_cli(path, tmp_path):
    args = ["load", GOOD_CSV, "--calibration", path, "reconstruct", "save", OUT]
    run_cli(args, tmp_path, re.escape(str(path)) + ": " + expected(path))


@pytest.mark.parametrize("path", MANIFESTS, ids=[p.stem for p in MANIFESTS])
def test_manifest_cli(path, tmp_path):
    run_cli(["calibrate", path, "-o", "cal.yaml", "--plot", "fit.png"], tmp_path, expected(path))


@pytest.mark.parametrize("path", NATIVE, ids=[p.name for p in NATIVE])
def test_native_session_cli(path, tmp_path):
    args = ["load", path, "--calibration", GOOD_CAL, "reconstruct", "save", OUT]
    run_cli(args, tmp_path, re.escape(str(path)) + ".*" + expected(path))


@pytest.mark.parametrize("path", RESULTS, ids=[p.name for p in RESULTS])
def test_results_cli(path, tmp_path):
    run_cli(["plot", path, "-o", "fig.png"], tmp_path, re.escape(str(path)) + ".*" + expected(path))


@pytest.mark.parametrize("path", CLI, ids=[p.stem for p in CLI])
def test_command_line_cases(path, tmp_path):
    case = yaml.safe_load(path.read_text(encoding="utf-8"))
    subst = {"good_csv": GOOD_CSV, "good_cal": GOOD_CAL, "invalid": INVALID, "data": DATA}
    args = [a.format(**subst) for a in shlex.split(case["args"])]
    run_cli(args, tmp_path, case["expect"])


def test_package_paper_config_is_valid():
    # the corpus's cases are mistakes only because the shipped config is right
    assert bendsense.load_config().actuator.pressure_range_pa == (0.0, 200e3)
