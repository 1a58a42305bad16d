"""The file system says no: a full disk, a file-size limit, a too-long name, a read-only disk.

Every writing command runs as the ``bendsense`` command line against a real condition: a
small tmpfs filled to the last byte (:mod:`smalldisk`), a file-size limit set with
``setrlimit(RLIMIT_FSIZE)`` (Python ignores SIGXFSZ, so the write fails with EFBIG), a
300-character name, a read-only tmpfs. Each must end with one line ``Error: PATH:
reason``, a non-zero exit, nothing half-written and an earlier output intact; ``record``
keeps every frame written before the disk filled. On a tmpfs the command line's entry
point runs in this process where the tmpfs is mounted here (:meth:`SmallDisk.cli`: as
root, as on CI), in a process of its own inside the namespace that holds it otherwise; a
file-size limit is a process's, so those commands, ``record`` and ``live`` (a simulated
board against a process) run as processes of their own.
"""

import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import linear_calibration, signals_for
from smalldisk import SmallDisk

import bendsense
from bendsense import load_config
from bendsense.cli import main
from bendsense.session import Session, write_session_csv
from bendsense.sim.scenarios import simulate

N = load_config().sensor.n_segments
FRAMES = 40
CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """Inputs on the ordinary disk: a calibration, a session, calibration recordings, a results directory."""
    root = tmp_path_factory.mktemp("lab")
    cal = linear_calibration(offset=np.full(N, 2000.0), delta_a=5e3, noise_std=None, sensor=None)
    cal.save(root / "cal.yaml")
    kappa = np.linspace(2.0, 12.0, FRAMES)[:, None] * np.ones(N)
    write_session_csv(Session(np.arange(FRAMES) * 0.01, signals_for(kappa, cal), np.full(FRAMES, 50e3)),
                      root / "run.csv")
    simulate("calibration", root / "calib", frames_per_strip=2, radii_m=[0.05, 0.1, 0.2])
    (root / "bending.csv").write_text("pressure_kpa,bending_angle_deg\n20,25\n40,55\n60,80\n90,130\n120,176\n")
    result = CliRunner().invoke(main, ["load", str(root / "run.csv"), "--calibration", str(root / "cal.yaml"),
                                       "reconstruct", "save", str(root / "results")])
    assert result.exit_code == 0, result.output
    return root


@pytest.fixture
def disk(tmp_path):
    """A fresh 2 MiB tmpfs (:class:`smalldisk.SmallDisk`)."""
    fs = SmallDisk(tmp_path / "disk", 2 << 20)
    yield fs
    fs.close()


def commands(lab: Path, out: Path) -> dict:
    """Every writing command, writing to ``out`` (a name on the small disk)."""
    load = ["load", lab / "run.csv", "--calibration", lab / "cal.yaml", "reconstruct"]
    return {
        "save": [*load, "save", out / "out"],
        "export": ["load", lab / "run.csv", "export", out / "x.csv"],
        "mcap": [*load, "mcap", out / "x.mcap"],
        "plot-chain": [*load, "plot", out / "fig.png"],
        "plot": ["plot", lab / "results", "-o", out / "fig.png"],
        "calibrate": ["calibrate", lab / "calib" / "manifest.yaml", "-o", out / "cal.yaml"],
        "calibrate-plot": ["calibrate", lab / "calib" / "manifest.yaml", "-o", out / "cal.yaml", "--plot",
                           out / "fit.png"],
        "identify": ["identify", "free-bending", lab / "bending.csv", "-o", out / "cfg.yaml"],
        "simulate": ["simulate", "validation", "-o", out / "sim", "--frames", "2"],
        "process": ["process", lab / "run.csv", "--calibration", lab / "cal.yaml", "-o", out / "proc", "--workers",
                    "0", "--no-progress"],
        "demo": ["demo", "-o", out / "demo", "--seconds", "0.3"],
    }


CHEAP = ["save", "export", "mcap", "plot-chain", "plot", "calibrate", "calibrate-plot", "identify", "simulate",
         "process"]


def one_error_line(result, pattern: str) -> str:
    """The promises of a refused write: exit 1, no traceback, exactly one ``Error:`` line matching ``pattern``."""
    text = result.stdout + result.stderr
    assert result.returncode == 1, text
    assert "Traceback" not in text, text
    errors = [line for line in result.stderr.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and re.search(pattern, errors[0]), text
    return errors[0]


@pytest.mark.parametrize("name", CHEAP)
def test_a_full_disk_leaves_the_earlier_output_intact(lab, disk, name):
    args = commands(lab, disk.path)[name]
    first = disk.cli(args)
    assert first.returncode == 0, first.stderr
    before = disk.files()
    assert before  # the first run wrote its output
    assert disk.fill(0) == 0
    result = disk.cli([*args, "--overwrite"])
    one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/\S+: no space left on device")
    assert disk.files() == before  # unchanged, nothing half-written, no temporary file left


@pytest.mark.parametrize("name", [*CHEAP, "demo", "reproduce"])
def test_a_full_disk_writes_nothing(lab, disk, name):
    args = commands(lab, disk.path).get(name) or ["reproduce", "-o", disk.path / "rep", "--quick"]
    disk.fill(0)
    result = disk.cli(args)
    one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/\S+: no space left on device")
    assert disk.files() == {}


@pytest.mark.parametrize(("name", "leave"), [("save", 32 << 10), ("demo", 256 << 10), ("simulate", 16 << 10)])
def test_a_disk_that_fills_half_way_through_an_output(lab, disk, name, leave):
    """Space for some of the files, not for all: the earlier output stays whole and nothing else is left."""
    args = commands(lab, disk.path)[name]
    first = disk.cli(args)
    assert first.returncode == 0, first.stderr
    before = disk.files()
    assert disk.fill(leave) <= leave
    result = disk.cli([*args, "--overwrite"])
    one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/\S+: no space left on device; nothing was written; "
                           "the earlier output is unchanged")
    assert disk.files() == before


@pytest.mark.parametrize("workers", ["0", "2"])
def test_process_stops_when_the_disk_fills(lab, disk, tmp_path, workers):
    runs = tmp_path / "runs"
    runs.mkdir()
    for name in ("a", "b", "c"):
        shutil.copy(lab / "run.csv", runs / f"{name}.csv")
    disk.fill(8192)  # room for the root's manifest, not for a session's results
    result = disk.cli(["process", runs, "--calibration", lab / "cal.yaml", "-o", disk.path / "proc",
                       "--workers", workers, "--no-progress"])
    one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/proc/[abc]: no space left on device; nothing was "
                           r"written; processing stopped \(0 of 3 sessions written before\)")
    assert set(disk.files()) <= {"proc", "proc/.bendsense-output.json"}  # no half-written session


def _file_size_limit(limit):
    def apply():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


@pytest.mark.parametrize("name", ["save", "export", "mcap", "plot", "calibrate-plot", "simulate", "process"])
def test_a_file_size_limit_is_one_line_and_keeps_the_earlier_output(lab, tmp_path, name):
    out = tmp_path / "out-root"
    out.mkdir()
    args = commands(lab, out)[name]
    first = CliRunner().invoke(main, [str(a) for a in args])  # the earlier output: no limit, no process needed
    assert first.exit_code == 0, first.output
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    result = subprocess.run([*CLI, *args, "--overwrite"], capture_output=True, text=True,
                            preexec_fn=_file_size_limit(1500))
    reason = r"file too large \(beyond the file-size limit, see 'ulimit -f'"
    if name == "process":  # a limit per file fails the sessions too large for it, each with its reason
        assert result.returncode == 1 and "Traceback" not in result.stderr
        assert re.search(rf"WARNING: run: failed: {re.escape(str(out))}/proc/run: {reason}", result.stderr)
        assert "Error: 1 of 1 sessions failed" in result.stderr
    else:
        one_error_line(result, rf"^Error: {re.escape(str(out))}/\S+: {reason}")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


LONG = "n" * 300


@pytest.mark.parametrize("name", [*commands(Path("lab"), Path("out")), "record", "reproduce", "live"])
def test_a_too_long_name_is_refused_before_any_work(lab, tmp_path, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    special = {
        "record": ["record", "/dev/bendsense-no-such-port", "-o", LONG, "--seconds", "1"],
        "reproduce": ["reproduce", "-o", LONG, "--quick"],
        "live": ["live", "loop://", "--calibration", lab / "cal.yaml", "--save", LONG + ".png", "--seconds", "1"],
    }
    args = [str(a) for a in special.get(name) or commands(lab, Path("OUT"))[name]]
    # the output's own name (the last output given) becomes 300 characters long
    i = max(k for k, a in enumerate(args) if a.startswith(("OUT/", LONG)))
    if args[i].startswith("OUT/"):
        args[i] = LONG + Path(args[i]).suffix
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and re.match(r"Error: n{16}\.\.\.\S+: file name too long \(30\d bytes; at most 2\d\d here",
                                        lines[0]), result.output
    assert os.listdir(tmp_path) == []


def test_a_name_that_fits_but_leaves_no_room_for_the_temporary_file(lab, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = "n" * 240 + ".csv"
    result = CliRunner().invoke(main, ["load", str(lab / "run.csv"), "export", name])
    assert result.exit_code == 1
    assert "file name too long (244 bytes; at most" in result.output
    assert "hidden temporary file beside it" in result.output and os.listdir(tmp_path) == []


def test_a_path_longer_than_the_file_system_allows(lab, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    deep = "/".join(["d" * 200] * 25)  # every name fits, the whole path (5,024 bytes) does not
    for args in (["load", lab / "run.csv", "--calibration", lab / "cal.yaml", "reconstruct", "save", f"{deep}/out"],
                 ["calibrate", lab / "calib" / "manifest.yaml", "-o", f"{deep}/cal.yaml"]):
        result = CliRunner().invoke(main, [str(a) for a in args])
        assert result.exit_code == 1 and "Traceback" not in result.output
        assert re.fullmatch(r"Error: d{16}\.\.\.d{16}/.*: path too long \([\d,]+ bytes; this file system allows "
                            r"[\d,]+ for an output\)\n", result.output), result.output
    assert os.listdir(tmp_path) == []


def test_a_read_only_disk(lab, tmp_path):
    fs = SmallDisk(tmp_path / "ro", 1 << 20, read_only=True)
    try:
        for name in ("save", "export", "calibrate", "simulate"):
            result = fs.cli(commands(lab, fs.path)[name])
            one_error_line(result, rf"^Error: {re.escape(str(fs.path))}/\S+: cannot write in "
                                   rf"{re.escape(str(fs.path))} \(read-only file system\)")
    finally:
        fs.close()


# --- record: the frames written before the disk filled are kept ---------------------------


def _record(disk, port, *extra):
    return disk.run([*CLI, "record", port, "-o", disk.path / "rec", "--seconds", "20", "--quiet-status", *extra],
                    timeout=120)


@pytest.mark.parametrize("estimate", [False, True], ids=["record", "record-estimate"])
def test_record_keeps_every_frame_written_before_the_disk_filled(tmp_path, calibration_path, estimate):
    from bendsense.device.simdevice import SimulatedDevice, default_source

    # results.csv takes ~8x the space of frames.bin: a larger disk, so that the pressure ramp of the
    # simulated board rises above 1 kPa before it fills (a session entirely below that looks like kPa)
    disk = SmallDisk(tmp_path / "disk", (1536 if estimate else 192) << 10)
    extra = ["--estimate", "--calibration", calibration_path] if estimate else []
    try:
        with SimulatedDevice(default_source(rate_hz=2000, seed=1), rate_hz=2000) as dev:
            start = time.monotonic()
            result = _record(disk, dev.port, *extra)
            took = time.monotonic() - start
        where = "(frames.bin|results.csv)" if estimate else "frames.bin"
        line = one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/rec/{where}: no space left on device")
        assert took < 60  # stopped when the disk filled, not after --seconds 20 of refused writes
        session_dir = disk.copy_out("rec", tmp_path / "kept")
    finally:
        disk.close()
    session = bendsense.read_session(session_dir)  # readable, closed: no warning of an unfinished recording
    assert session.meta["finished"] is True and session.meta["torn_bytes"] == 0
    assert len(session) > 500
    assert np.all(np.diff(session.seq) == 1)  # consecutive frames, none lost at the end
    assert session.meta["outcome"].startswith("output error: ")
    if "frames.bin" in line:
        kept = int(re.search(r"([\d,]+) frames kept", line).group(1).replace(",", ""))
        assert kept == len(session)
    assert not [p for p in session_dir.iterdir() if "bendsense-tmp" in p.name]  # the reserve is given back
    if estimate:
        text = (session_dir / "results.csv").read_text()
        assert text.endswith("\n")
        rows = text.splitlines()
        width = rows[0].count(",")
        assert all(row.count(",") == width for row in rows)  # no torn row
        assert 0 < len(rows) - 1 <= len(session)


def test_record_under_a_file_size_limit_keeps_its_frames(tmp_path):
    from bendsense.device.simdevice import SimulatedDevice, default_source
    from bendsense.session.native import record_dtype

    out = tmp_path / "rec"
    size = record_dtype(16).itemsize
    limit = size * 1000 + size // 3  # frames.bin reaches it after 1,000 records, the next one torn
    with SimulatedDevice(default_source(rate_hz=2000, seed=2), rate_hz=2000) as dev:
        result = subprocess.run([*CLI, "record", dev.port, "-o", out, "--seconds", "20", "--quiet-status"],
                                capture_output=True, text=True, timeout=120, preexec_fn=_file_size_limit(limit))
    line = one_error_line(result, rf"^Error: {re.escape(str(out))}/frames.bin: file too large \(beyond the "
                                  r"file-size limit, see 'ulimit -f'.*; recording stopped; 1,000 frames kept")
    session = bendsense.read_session(out)
    assert len(session) == 1000 and (out / "frames.bin").stat().st_size == size * 1000
    assert session.meta["finished"] is True and np.all(np.diff(session.seq) == 1)
    assert "1,000 frames kept" in session.meta["outcome"] and line.endswith("(the session is readable)")


def test_live_save_on_a_full_disk(lab, disk):
    from bendsense.device.simdevice import SimulatedDevice, default_source

    with SimulatedDevice(default_source(rate_hz=500, seed=3), rate_hz=500) as dev:
        first = disk.run([*CLI, "live", dev.port, "--calibration", lab / "cal.yaml", "--seconds", "0.5", "--save",
                          disk.path / "live.png"], timeout=120)
        assert first.returncode == 0, first.stderr
        before = disk.files()
        disk.fill(0)
        result = disk.run([*CLI, "live", dev.port, "--calibration", lab / "cal.yaml", "--seconds", "0.5", "--save",
                           disk.path / "live.png", "--overwrite"], timeout=120)
    one_error_line(result, rf"^Error: {re.escape(str(disk.path))}/live.png: no space left on device; nothing was "
                           "written; the earlier output is unchanged")
    assert disk.files() == before


# --- the library: OutputError naming the path, with the errno ------------------------------

_LIBRARY = r"""
import errno, pickle, sys
import numpy as np
import bendsense
from bendsense.calibration import Calibration
from bendsense.errors import OutputError
from bendsense.session import read_session_csv, write_session_csv
from bendsense.session.native import SessionWriter, record_dtype

disk, lab = sys.argv[1], sys.argv[2]
session = read_session_csv(lab + "/run.csv")
calls = {
    "Calibration.save": lambda: Calibration.load(lab + "/cal.yaml").save(disk + "/cal.yaml"),
    "write_session_csv": lambda: write_session_csv(session, disk + "/s.csv"),
    "SessionWriter": lambda: SessionWriter(disk + "/rec", record_dtype(16)).write(np.zeros(100000, record_dtype(16))),
}
for name, call in calls.items():
    try:
        call()
    except OutputError as err:
        back = pickle.loads(pickle.dumps(err))
        print(name, "|", type(err).__name__, "|", errno.errorcode[err.errno], "|", back.errno == err.errno, "|", err)
    else:
        print(name, "| no error")
"""


def test_the_library_raises_output_errors_naming_the_path(lab, disk):
    disk.fill(0)
    result = disk.run([sys.executable, "-c", _LIBRARY, disk.path, lab])
    assert result.returncode == 0, result.stderr
    lines = dict(line.split(" | ", 1) for line in result.stdout.splitlines())
    d = re.escape(str(disk.path))
    assert re.fullmatch(rf"OutputError \| ENOSPC \| True \| {d}/cal\.yaml: no space left on device; nothing was "
                        "written", lines["Calibration.save"])
    assert re.fullmatch(rf"OutputError \| ENOSPC \| True \| {d}/s\.csv: no space left on device; nothing was "
                        "written", lines["write_session_csv"])
    # a recording that cannot start: nothing of it is left
    assert re.fullmatch(rf"OutputError \| ENOSPC \| True \| {d}/rec/\S+: no space left on device.*",
                        lines["SessionWriter"])
    assert disk.files() == {}
