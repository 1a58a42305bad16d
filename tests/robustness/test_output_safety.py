"""Data safety: no command ever deletes or replaces a file that bendsense did not write.

User files are planted next to and inside every output of every writing command, which
then runs with and without ``--overwrite``; the files must survive byte for byte. The
special cases of issue 10 (``save . --overwrite``, the session being read inside the
output, ``process sess/sub/.. -o .``, symlinks, ancestors of the working directory, an
existing plot, two concurrent writers, the umask, a failure half-way) each have a test.
"""

import json
import multiprocessing
import os
import re
import shutil
import stat

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import hold_output, linear_calibration, signals_for

from bendsense import load_config, output
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.errors import OutputError
from bendsense.session import Session, write_session_csv
from bendsense.session.native import SessionWriter, read_session_dir, record_dtype
from bendsense.sim.scenarios import simulate

SENSOR = load_config().sensor
N = SENSOR.n_segments
FRAMES = 6


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A small lab: a calibration, a session CSV, a native session, calibration recordings."""
    root = tmp_path_factory.mktemp("lab")
    cal = linear_calibration(offset=np.full(N, 2000.0), delta_a=5e3, noise_std=None, sensor=None)
    cal.save(root / "cal.yaml")
    kappa = np.linspace(2.0, 12.0, FRAMES)[:, None] * np.ones(N)
    signals = signals_for(kappa, cal)
    session = Session(np.arange(FRAMES) * 0.1, signals, np.full(FRAMES, 50e3))
    write_session_csv(session, root / "run.csv")
    with SessionWriter(root / "native", record_dtype(N)) as w:
        rec = w.empty(FRAMES)
        rec["adc"] = np.round(signals)
        rec["pressure_pa"] = 50_000
        w.write(rec)
    simulate("calibration", root / "calib", frames_per_strip=2, radii_m=[0.05, 0.1, 0.2])
    (root / "bending.csv").write_text("pressure_kpa,bending_angle_deg\n20,25\n40,55\n60,80\n90,130\n120,176\n")
    return root


@pytest.fixture
def work(lab, tmp_path, monkeypatch):
    """A fresh copy of the lab as the working directory."""
    root = tmp_path / "work"
    shutil.copytree(lab, root, symlinks=True)
    monkeypatch.chdir(root)
    return root


def run(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result


def plant(*places):
    """Put a user file into each directory (created if needed); return {path: content}."""
    planted = {}
    for d in places:
        d.mkdir(parents=True, exist_ok=True)
        f = d / "USER_NOTES.txt"
        f.write_text(f"a user's notes in {d.name}")
        planted[f] = f.read_bytes()
    return planted


def intact(planted):
    return all(f.is_file() and f.read_bytes() == content for f, content in planted.items())


def one_line_error(result):
    return result.exit_code == 1 and result.output.startswith("Error: ") and result.output.strip().count("\n") == 0


def litter(root):
    """bendsense's temporary files and locks left anywhere under ``root``."""
    return [p for p in root.rglob("*") if ".bendsense-tmp-" in p.name or p.name.endswith(".bendsense-lock")]


# --- every directory-writing command ------------------------------------------------------

DIRECTORY_COMMANDS = {
    "save": lambda out: ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "save", out],
    "save-native": lambda out: ["load", "native", "--calibration", "cal.yaml", "reconstruct", "save", out],
    "simulate": lambda out: ["simulate", "validation", "-o", out, "--frames", "1"],
    "reproduce": lambda out: ["reproduce", "-o", out, "--quick"],
    "demo": lambda out: ["demo", "-o", out, "--seconds", "0.2"],
    "record": lambda out: ["record", "/dev/bendsense-no-such-port", "-o", out, "--seconds", "0.1"],
}
CHEAP = ("save", "save-native", "simulate")  # run to completion; the others are refused before any work


@pytest.mark.parametrize("name", list(DIRECTORY_COMMANDS))
def test_user_files_inside_an_output_directory_survive(work, name):
    args = DIRECTORY_COMMANDS[name]
    planted = plant(work / "out", work / "out" / "sub")
    for flag in ([], ["--overwrite"]):
        result = run(*args("out"), *flag)
        assert one_line_error(result), result.output
        assert intact(planted)
        if flag:
            assert "USER_NOTES.txt" in result.output and "sub/" in result.output
        else:
            assert "exists and is not empty (use --overwrite" in result.output
    assert sorted(p.name for p in (work / "out").iterdir()) == ["USER_NOTES.txt", "sub"]
    assert not litter(work)


@pytest.mark.parametrize("name", CHEAP)
def test_user_files_next_to_an_output_directory_survive_and_overwrite_replaces_only_ours(work, name):
    args = DIRECTORY_COMMANDS[name]
    planted = plant(work, work / "elsewhere")
    assert run(*args("out")).exit_code == 0
    manifest = output.read_manifest(work / "out")
    assert manifest["writer"].startswith("bendsense") and manifest["files"]
    assert all((work / "out" / f).exists() for f in manifest["files"])
    assert run(*args("out")).exit_code == 1  # no --overwrite
    assert run(*args("out"), "--overwrite").exit_code == 0
    assert intact(planted) and not litter(work)
    # a user file put into the output since makes --overwrite refuse
    planted.update(plant(work / "out"))
    result = run(*args("out"), "--overwrite")
    assert one_line_error(result) and "holds files bendsense did not write: USER_NOTES.txt" in result.output
    assert intact(planted)


@pytest.mark.parametrize("name", CHEAP)
def test_an_edited_manifest_never_reaches_outside_its_directory(work, name):
    """Entries with '..', absolute paths or paths through a symbolic link are never removed."""
    args = DIRECTORY_COMMANDS[name]
    assert run(*args("out")).exit_code == 0
    planted = plant(work, work.parent / "beside", work / "linked")
    path = work / "out" / output.MANIFEST_NAME
    manifest = json.loads(path.read_text())
    for edit in (["../USER_NOTES.txt", "../../beside/USER_NOTES.txt"], [str(work / "USER_NOTES.txt")]):
        path.write_text(json.dumps({**manifest, "files": manifest["files"] + edit}))
        result = run(*args("out"), "--overwrite")  # not a manifest of bendsense's: refused
        assert one_line_error(result), result.output
        assert intact(planted)
    # a manifest that lists a link and a file behind it: the link may go, never what it points to
    (work / "out" / "link").symlink_to(work / "linked", target_is_directory=True)
    path.write_text(json.dumps({**manifest, "files": manifest["files"] + ["link", "link/USER_NOTES.txt"]}))
    run(*args("out"), "--overwrite")
    assert intact(planted)


def test_process_never_replaces_user_files(work):
    args = ["process", "run.csv", "native", "--calibration", "cal.yaml", "-o", "out", "--workers", "0",
            "--no-estimate", "--no-progress"]
    planted = plant(work / "out")  # the root collects outputs: user files there are fine
    result = run(*args)
    assert result.exit_code == 0, result.output
    assert output.read_manifest(work / "out")["files"] == ["run/", "native/"]
    assert (work / "out/run/results.csv").is_file() and (work / "out/native/results.csv").is_file()
    planted.update(plant(work / "out" / "run"))
    result = run(*args, "--overwrite")
    assert result.exit_code == 1 and "holds files bendsense did not write: USER_NOTES.txt" in result.output
    assert intact(planted)
    assert not litter(work)


@pytest.mark.parametrize("command", ["calibrate", "calibrate --plot", "identify", "export", "plot"])
def test_file_outputs_never_replace_a_file_without_overwrite(work, command):
    (work / "target.yaml").write_text("user's yaml")
    (work / "target.png").write_bytes(b"user's png")
    (work / "target.csv").write_text("user's csv")
    planted = plant(work)
    args = {
        "calibrate": ["calibrate", "calib/manifest.yaml", "-o", "target.yaml"],
        "calibrate --plot": ["calibrate", "calib/manifest.yaml", "-o", "new.yaml", "--plot", "target.png"],
        "identify": ["identify", "free-bending", "bending.csv", "-o", "target.yaml"],
        "export": ["load", "run.csv", "export", "target.csv"],
        "plot": ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "plot", "target.png"],
    }[command]
    result = run(*args)
    assert one_line_error(result) and "exists (use --overwrite to replace it)" in result.output
    # with --overwrite too: bendsense replaces only files it wrote (they carry its mark)
    result = run(*args, "--overwrite")
    assert one_line_error(result) and "bendsense did not write it" in result.output, result.output
    assert (work / "target.yaml").read_text() == "user's yaml"
    assert (work / "target.png").read_bytes() == b"user's png"
    assert (work / "target.csv").read_text() == "user's csv"
    assert not (work / "new.yaml").exists()  # checked before any work: the calibration was not written
    assert intact(planted) and not litter(work)
    # what bendsense wrote there, it replaces
    for f in ("target.yaml", "target.png", "target.csv"):
        (work / f).unlink()
    assert run(*args).exit_code == 0
    assert run(*args, "--overwrite").exit_code == 0
    assert intact(planted) and not litter(work)


def test_overwrite_replaces_a_bendsense_file_only_of_its_own_kind(work):
    """A session CSV is a lab's data: no truth file or export of another kind goes over it, nor over a config."""
    from bendsense.sim.truth import KIND, TruthWriter, truth_columns

    TruthWriter(work / "truth.csv", truth_columns()).close()
    kept = {f: (work / f).read_bytes() for f in ("run.csv", "cal.yaml", "truth.csv")}
    result = run("sim-device", "--seconds", "0.1", "--truth", "run.csv", "--overwrite")
    assert result.exit_code != 0 and "run.csv: exists and is not a sim-device truth file" in result.output
    assert result.output.strip().count("\n") == 0, result.output
    result = run("load", "run.csv", "export", "truth.csv", "--overwrite")
    assert one_line_error(result) and "truth.csv: exists and is not a session CSV" in result.output, result.output
    session = Session(np.arange(2) * 0.1, np.full((2, N), 2000.0), np.full(2, 50e3))
    with pytest.raises(OutputError, match="cal.yaml: exists and is not a session CSV"):
        write_session_csv(session, work / "cal.yaml")  # the API's default overwrite too
    assert {f: (work / f).read_bytes() for f in kept} == kept
    # a file of its own kind is replaced, as before
    assert output.check([output.file(work / "truth.csv", overwrite=True, replaces=KIND)]) is None
    assert run("load", "run.csv", "export", "copy.csv").exit_code == 0
    assert run("load", "native", "export", "copy.csv", "--overwrite").exit_code == 0
    assert "ch1" in (work / "copy.csv").read_text() and not litter(work)


def test_calibrate_with_plot_writes_both_and_overwrite_replaces_them(work):
    planted = plant(work)
    result = run("calibrate", "calib/manifest.yaml", "-o", "c/cal.yaml", "--plot", "c/fit.svg", "--degree", "1")
    assert result.exit_code == 0, result.output
    assert Calibration.load(work / "c/cal.yaml").degree == 1 and (work / "c/fit.svg").read_bytes().startswith(b"<?xml")
    result = run("calibrate", "calib/manifest.yaml", "-o", "c/cal.yaml", "--plot", "c/fit.svg", "--overwrite")
    assert result.exit_code == 0, result.output
    assert Calibration.load(work / "c/cal.yaml").degree == 3
    assert intact(planted) and not litter(work)


def test_unknown_plot_suffix_is_refused_before_the_calibration_is_written(work):
    result = run("calibrate", "calib/manifest.yaml", "-o", "cal2.yaml", "--plot", "fit.xyz")
    assert one_line_error(result) and "fit.xyz: unknown figure format '.xyz'" in result.output
    assert not (work / "cal2.yaml").exists()
    result = run("calibrate", "calib/manifest.yaml", "-o", "cal2.txt")
    assert one_line_error(result) and "cal2.txt: unknown suffix '.txt'; use one of .yaml, .yml" in result.output


# --- the targets issue 10 found destroying data ----------------------------------------------


@pytest.mark.parametrize("target", [".", "./", "..", "sub/..", "sub/../.", "/"])
def test_the_working_directory_and_its_ancestors_are_never_targets(work, target):
    (work / "sub").mkdir()
    before = sorted(p.name for p in work.iterdir())
    for args in (
        DIRECTORY_COMMANDS["save"](target),
        DIRECTORY_COMMANDS["simulate"](target),
        ["process", "run.csv", "--calibration", "cal.yaml", "-o", target, "--workers", "0", "--no-progress"],
    ):
        result = run(*args, "--overwrite")
        assert one_line_error(result) and "working directory" in result.output, result.output
        assert sorted(p.name for p in work.iterdir()) == before
    assert (work / "run.csv").is_file() and (work / "cal.yaml").is_file()


def test_process_of_a_subdirectory_dot_dot_into_the_working_directory(work):
    (work / "sess" / "sub").mkdir(parents=True)
    shutil.copy(work / "run.csv", work / "sess" / "a.csv")
    before = sorted(str(p.relative_to(work)) for p in work.rglob("*"))
    result = run("process", "sess/sub/..", "--calibration", "cal.yaml", "-o", ".", "--overwrite", "--workers", "0")
    assert one_line_error(result) and "working directory" in result.output
    assert sorted(str(p.relative_to(work)) for p in work.rglob("*")) == before


@pytest.mark.parametrize("session", ["data/run.csv", "data/native"])
def test_save_over_the_directory_that_holds_the_session_being_read(work, session):
    (work / "data").mkdir()
    shutil.move(work / session.split("/", 1)[1], work / session)  # the lab's run.csv or native
    before = {p: p.read_bytes() for p in (work / "data").rglob("*") if p.is_file()}
    for target in ("data", "data/.", "data/../data"):
        args = ["load", session, "--calibration", "cal.yaml", "reconstruct", "save", target, "--overwrite"]
        result = run(*args)
        assert one_line_error(result) and f"holds the input {session} of this command" in result.output
    if session == "data/native":  # the session directory itself
        result = run("load", session, "--calibration", "cal.yaml", "reconstruct", "save", session, "--overwrite")
        assert one_line_error(result) and "is an input of this command" in result.output
    assert {p: p.read_bytes() for p in (work / "data").rglob("*") if p.is_file()} == before
    # inside the session's directory is fine: the output is swapped, the input stays
    result = run("load", session, "--calibration", "cal.yaml", "reconstruct", "save", "data/results")
    assert result.exit_code == 0, result.output
    assert all(p.read_bytes() == content for p, content in before.items())


def test_inputs_are_never_targets(work):
    result = run("load", "run.csv", "export", "run.csv", "--overwrite")
    assert one_line_error(result) and "run.csv: is an input of this command" in result.output
    result = run("calibrate", "calib/manifest.yaml", "-o", "calib/manifest.yaml", "--overwrite")
    assert one_line_error(result) and "is an input of this command" in result.output
    result = run("identify", "free-bending", "bending.csv", "--config", "cal.yaml", "-o", "cal.yaml", "--overwrite")
    assert one_line_error(result) and "is an input of this command" in result.output
    result = run("process", "native", "--calibration", "cal.yaml", "-o", "native/..", "--workers", "0")
    assert one_line_error(result)
    assert Calibration.load(work / "cal.yaml").degree == 1 and len(read_session_dir(work / "native")) == FRAMES


def test_symlinked_targets_resolve_before_the_checks(work):
    user = work / "userdir"
    planted = plant(user)
    (work / "link").symlink_to(user)
    (work / "here").symlink_to(work)
    (work / "cal-link.yaml").symlink_to(work / "cal.yaml")
    result = run(*DIRECTORY_COMMANDS["save"]("link"), "--overwrite")
    assert one_line_error(result) and "not a bendsense output" in result.output and "USER_NOTES.txt" in result.output
    result = run(*DIRECTORY_COMMANDS["save"]("here"), "--overwrite")
    assert one_line_error(result) and "working directory" in result.output
    result = run("load", "run.csv", "--calibration", "cal.yaml",
                 "calibrate", "calib/manifest.yaml", "-o", "cal-link.yaml", "--overwrite")
    assert one_line_error(result) and "is an input of this command" in result.output
    assert intact(planted) and Calibration.load(work / "cal.yaml").degree == 1
    # a link to a directory bendsense wrote is followed: the output is replaced behind it
    assert run(*DIRECTORY_COMMANDS["save"]("real")).exit_code == 0
    (work / "out-link").symlink_to(work / "real")
    assert run(*DIRECTORY_COMMANDS["save"]("out-link"), "--overwrite").exit_code == 0
    assert (work / "out-link").is_symlink() and (work / "real" / "results.csv").is_file()


def test_a_chain_checks_every_output_before_the_first_step(work):
    (work / "fig.png").write_bytes(b"user's png")
    args = ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "save", "out", "plot", "fig.png"]
    result = run(*args)
    assert one_line_error(result) and "fig.png: exists" in result.output
    assert not (work / "out").exists()  # save did not run
    result = run(*args[:-1], "fig.webp2")
    assert one_line_error(result) and "unknown figure format" in result.output and not (work / "out").exists()
    # into the results directory: the figure joins its manifest, so --overwrite may replace both
    args = ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "save", "out", "plot", "out/fig.png"]
    assert run(*args).exit_code == 0
    assert output.read_manifest(work / "out")["files"] == ["results.csv", "shape.npz", "fig.png"]
    assert run(*args[:7], "--overwrite", "plot", "out/fig.png", "--overwrite").exit_code == 0
    assert (work / "fig.png").read_bytes() == b"user's png"


def test_a_failure_half_way_leaves_nothing(work, monkeypatch):
    import bendsense.results

    def disk_full(path, **arrays):
        with open(path, "wb") as fh:
            fh.write(b"PK\x03\x04 half")
        raise OSError(28, "No space left on device", str(path))

    with monkeypatch.context() as m:
        m.setattr(bendsense.results.np, "savez", disk_full)
        result = run(*DIRECTORY_COMMANDS["save"]("out"))
    assert one_line_error(result)
    assert "out/shape.npz: no space left on device; nothing was written" in result.output
    assert ".bendsense-tmp" not in result.output  # the user's path, not the hidden one
    assert not (work / "out").exists() and not litter(work)
    assert run(*DIRECTORY_COMMANDS["save"]("out")).exit_code == 0
    before = (work / "out" / "results.csv").read_bytes()
    with monkeypatch.context() as m:
        m.setattr(bendsense.results.np, "savez", disk_full)
        assert run(*DIRECTORY_COMMANDS["save"]("out"), "--overwrite").exit_code == 1
    assert (work / "out" / "results.csv").read_bytes() == before and (work / "out" / "shape.npz").is_file()
    assert not litter(work)


# --- concurrency, permissions, recordings ---------------------------------------------------


def test_two_runs_on_one_output_the_second_refuses(work):
    ctx = multiprocessing.get_context("spawn")
    ready, release = ctx.Event(), ctx.Event()
    proc = ctx.Process(target=hold_output, args=(str(work / "out"), ready, release, 30))
    proc.start()
    try:
        assert ready.wait(60)
        for args in (DIRECTORY_COMMANDS["save"]("out"), DIRECTORY_COMMANDS["simulate"]("out"),
                     DIRECTORY_COMMANDS["record"]("out")):
            result = run(*args)
            assert one_line_error(result) and "another bendsense run is writing there" in result.output
        assert not (work / "out").exists()
    finally:
        release.set()
        proc.join(60)
    assert run(*DIRECTORY_COMMANDS["save"]("out")).exit_code == 0


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_permissions_follow_the_umask(work, umask):
    old = os.umask(umask)
    try:
        assert run(*DIRECTORY_COMMANDS["save"]("out")).exit_code == 0
        assert run("calibrate", "calib/manifest.yaml", "-o", "new.yaml", "--degree", "1").exit_code == 0
        with SessionWriter(work / "rec", record_dtype(N)) as w:
            w.write(w.empty(1))
    finally:
        os.umask(old)
    for p in [work / "out", *(work / "out").iterdir(), work / "new.yaml", work / "rec", *(work / "rec").iterdir()]:
        full = 0o777 if p.is_dir() else 0o666
        assert stat.S_IMODE(p.stat().st_mode) == full & ~umask, p


def test_a_killed_recording_is_still_bendsenses_and_user_files_stop_record(work):
    w = SessionWriter(work / "rec", record_dtype(N))  # never closed: killed
    w.write(w.empty(2))
    manifest = json.loads((work / "rec" / output.MANIFEST_NAME).read_text())
    assert manifest["files"] == ["meta.yaml", "frames.bin", "events.log"] and manifest["writer"] == "bendsense record"
    w.close()
    assert output.foreign_entries(work / "rec") == []
    planted = plant(work / "rec")
    result = run(*DIRECTORY_COMMANDS["record"]("rec"), "--overwrite")  # refused before the port is opened
    assert one_line_error(result) and "holds files bendsense did not write: USER_NOTES.txt" in result.output
    assert intact(planted) and len(read_session_dir(work / "rec")) == 2
    (work / "rec" / "USER_NOTES.txt").unlink()
    with SessionWriter(work / "rec", record_dtype(N), overwrite=True) as w2:
        w2.write(w2.empty(1))
    assert len(read_session_dir(work / "rec")) == 1


def test_what_a_chain_wrote_earlier_is_not_an_input_of_its_later_steps(work):
    args = ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "save", "out", "plot", "out", "-o",
            "fig.png"]
    result = run(*args)
    assert result.exit_code == 0, result.output
    assert (work / "fig.png").is_file() and (work / "out" / "results.csv").is_file()
    # the other way round, the results directory is read before it would be written over
    result = run("plot", "out", "-o", "fig2.png", "load", "run.csv", "--calibration", "cal.yaml", "reconstruct",
                 "save", "out", "--overwrite")
    assert one_line_error(result) and "out: is an input of this command" in result.output
    assert not (work / "fig2.png").exists()


def test_a_plot_that_cannot_be_drawn_leaves_no_calibration(work, monkeypatch):
    def broken(self, *args, **kwargs):
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(Calibration, "plot", broken)
    result = CliRunner().invoke(main, ["calibrate", "calib/manifest.yaml", "-o", "new.yaml", "--plot", "fit.png"])
    assert result.exit_code != 0 and isinstance(result.exception, RuntimeError)
    assert not (work / "new.yaml").exists() and not (work / "fit.png").exists() and not litter(work)


def test_a_chain_whose_estimate_lacks_pressure_writes_nothing(work):
    session = Session(np.arange(FRAMES) * 0.1, np.full((FRAMES, N), 2000.0), np.full(FRAMES, np.nan))
    write_session_csv(session, work / "nopressure.csv")
    result = run("load", "nopressure.csv", "--calibration", "cal.yaml", "reconstruct", "save", "first", "estimate",
                 "save", "second")
    assert result.exit_code == 2 and f"{FRAMES} of {FRAMES} frames without pressure" in result.output, result.output
    assert not (work / "first").exists() and not (work / "second").exists() and not litter(work)


# --- two steps writing one file; outputs through symbolic links (issue 21) --------------------


def test_two_steps_writing_one_file_are_refused_before_any_work(work):
    load = ["load", "run.csv", "--calibration", "cal.yaml", "reconstruct"]
    for steps, named in (
        (["save", "out", "export", "out/results.csv", "--overwrite"], "out/results.csv: .*'save' and 'export'"),
        (["export", "out/shape.npz", "save", "out"], "out/shape.npz: .*'export' and 'save'"),
        (["plot", "fig.png", "plot", "fig.png"], r"fig.png: .*'plot' \(step 3\) and 'plot' \(step 4\)"),
        (["save", "res", "mcap", "res/results.csv"], "res/results.csv: .*'save' and 'mcap'"),
    ):
        result = run(*load, *steps)
        assert one_line_error(result) and "written by two steps of this command line" in result.output
        assert re.search(named, result.output), result.output
        assert not (work / "out").exists() and not (work / "res").exists() and not (work / "fig.png").exists()
    # a file added to an earlier step's results directory is not one of its files: fine
    assert run(*load, "save", "out", "export", "out/session.csv").exit_code == 0
    assert output.read_manifest(work / "out")["files"] == ["results.csv", "shape.npz", "session.csv"]


@pytest.mark.parametrize("name", ["save", "simulate", "record", "export", "calibrate", "process"])
def test_an_output_through_a_dangling_link_creates_nothing_at_its_target(work, tmp_path, name):
    (work / "link").symlink_to(tmp_path / "elsewhere" / "deep")
    args = {
        "save": DIRECTORY_COMMANDS["save"]("link/out"),
        "simulate": DIRECTORY_COMMANDS["simulate"]("link/out"),
        "record": DIRECTORY_COMMANDS["record"]("link/out"),
        "export": ["load", "run.csv", "export", "link/x.csv"],
        "calibrate": ["calibrate", "calib/manifest.yaml", "-o", "link/cal.yaml"],
        "process": ["process", "run.csv", "--calibration", "cal.yaml", "-o", "link", "--workers", "0"],
    }[name]
    result = run(*args)
    assert one_line_error(result), result.output
    assert result.output.startswith(f"Error: link: a symbolic link to {tmp_path / 'elsewhere' / 'deep'}, which does "
                                    "not exist; refusing to write through it")
    assert not (tmp_path / "elsewhere").exists() and not litter(work)


def test_an_output_that_is_a_link_out_of_its_directory_is_refused(work, tmp_path):
    (tmp_path / "shared").mkdir()
    (work / "out").symlink_to(tmp_path / "shared")
    result = run(*DIRECTORY_COMMANDS["save"]("out"))
    assert one_line_error(result) and "out: a symbolic link to" in result.output
    assert "outside its directory" in result.output
    assert os.listdir(tmp_path / "shared") == []
    # a link within its own directory is followed
    (work / "sub" / "results").mkdir(parents=True)  # empty: an output may go there
    (work / "inner").symlink_to(work / "sub" / "results")
    assert run(*DIRECTORY_COMMANDS["save"]("inner")).exit_code == 0
    assert (work / "sub" / "results" / "results.csv").is_file() and (work / "inner").is_symlink()
