"""The output layer (bendsense.output): atomic directories and files that never destroy user files."""

import json
import multiprocessing
import os
import stat

import pytest
from helpers import hold_output

from bendsense import output
from bendsense.errors import BendsenseError, OutputError, OutputExistsError


def _write(tmp, **files):
    for name, text in files.items():
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp / name).write_text(text)


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def _visible(d):
    return sorted(p.name for p in d.iterdir())


@pytest.fixture
def cwd(tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def test_directory_written_whole_with_a_manifest(cwd):
    with output.write_dir("out", writer="test") as tmp:
        assert tmp.parent == cwd and tmp.name.startswith(".out.")
        assert not (cwd / "out").exists()  # nothing visible until the end
        _write(tmp, **{"a.csv": "1", "sub/b.txt": "2"})
    out = cwd / "out"
    assert _visible(out) == [".bendsense-output.json", "a.csv", "sub"]
    manifest = json.loads((out / output.MANIFEST_NAME).read_text())
    assert manifest["format"] == "bendsense-output" and manifest["version"] == 1
    assert manifest["writer"] == "test" and manifest["files"] == ["a.csv", "sub/b.txt"]
    assert _visible(cwd) == ["out"]  # no temporary or lock file left


def test_failure_leaves_nothing_and_keeps_the_old_output(cwd):
    with output.write_dir("out") as tmp:
        _write(tmp, **{"a.csv": "old"})
    with pytest.raises(RuntimeError), output.write_dir("out", overwrite=True) as tmp:
        _write(tmp, **{"a.csv": "new"})
        raise RuntimeError("boom")
    assert (cwd / "out/a.csv").read_text() == "old"
    assert _visible(cwd) == ["out"]


def test_existing_output_needs_overwrite_and_then_is_replaced(cwd):
    with output.write_dir("out") as tmp:
        _write(tmp, **{"a.csv": "old", "stale.csv": "old"})
    with pytest.raises(OutputExistsError, match=r"^out: exists and is not empty \(use --overwrite"):
        with output.write_dir("out"):
            pass
    with output.write_dir("out", overwrite=True) as tmp:
        _write(tmp, **{"a.csv": "new"})
    assert _visible(cwd / "out") == [".bendsense-output.json", "a.csv"]  # the stale output file is gone
    assert (cwd / "out/a.csv").read_text() == "new"
    # an existing empty directory is fine without overwrite
    (cwd / "empty").mkdir()
    with output.write_dir("empty") as tmp:
        _write(tmp, x="1")
    assert (cwd / "empty/x").read_text() == "1"


def test_overwrite_refuses_and_names_user_files(cwd):
    with output.write_dir("out") as tmp:
        _write(tmp, **{"a.csv": "ours"})
    _write(cwd, **{"out/notes.txt": "mine", "out/data/raw.bin": "mine"})
    with pytest.raises(OutputError, match=r"^out: holds files bendsense did not write: data/, notes.txt; nothing"):
        with output.write_dir("out", overwrite=True) as tmp:
            _write(tmp, **{"a.csv": "new"})
    assert (cwd / "out/notes.txt").read_text() == "mine" and (cwd / "out/a.csv").read_text() == "ours"
    assert _visible(cwd) == ["out"]


def test_overwrite_names_a_nested_output_as_bendsenses_own(cwd):
    with output.write_dir("rec") as tmp:  # e.g. a recording, then `save rec/results` inside it
        _write(tmp, **{"frames.bin": "ours"})
    with output.write_dir("rec/results") as tmp:
        _write(tmp, **{"results.csv": "ours too"})
    with pytest.raises(OutputError, match=r"^rec: holds another bendsense output that is not part of it: results/; "
                                          r"nothing was replaced"):
        with output.write_dir("rec", overwrite=True) as tmp:
            _write(tmp, **{"frames.bin": "new"})
    assert (cwd / "rec/results/results.csv").read_text() == "ours too"
    _write(cwd, **{"rec/notes.txt": "mine"})  # beside a user's file: the user's file is what it names
    with pytest.raises(OutputError, match=r"^rec: holds files bendsense did not write: notes.txt, results/"):
        with output.write_dir("rec", overwrite=True) as tmp:
            _write(tmp, **{"frames.bin": "new"})
    assert (cwd / "rec/frames.bin").read_text() == "ours"


def test_directory_without_manifest_is_not_ours(cwd):
    _write(cwd, **{"out/results.csv": "mine"})  # looks like an output, but bendsense did not write it
    not_ours = r"out: not a bendsense output \(no .bendsense-output.json\); it holds results.csv"
    with pytest.raises(OutputError, match=not_ours):
        output.check([output.directory("out", overwrite=True)])
    with pytest.raises(OutputError, match="out: not a bendsense output"):
        with output.write_dir("out", overwrite=True):
            pass
    assert (cwd / "out/results.csv").read_text() == "mine"


@pytest.mark.parametrize("target", [".", "..", "sub/..", "link", "/"])
def test_refuses_the_working_directory_and_its_ancestors(cwd, target):
    (cwd / "sub").mkdir()
    (cwd / "link").symlink_to(cwd)
    (cwd / "keep.txt").write_text("mine")
    with pytest.raises(OutputError, match="working directory"):
        with output.write_dir(target, overwrite=True):
            pass
    with pytest.raises(OutputError, match="working directory"):
        output.check([output.collection(target)])
    assert (cwd / "keep.txt").read_text() == "mine"


def test_refuses_inputs_and_directories_holding_them(cwd):
    _write(cwd, **{"data/run.csv": "input", "cal.yaml": "input"})
    (cwd / "alias").symlink_to(cwd / "data")
    with pytest.raises(OutputError, match=r"^data: holds the input data/run.csv of this command"):
        output.check([output.directory("data", overwrite=True)], inputs=["data/run.csv"])
    with pytest.raises(OutputError, match=r"^alias: holds the input"):
        output.check([output.directory("alias", overwrite=True)], inputs=["data/run.csv"])
    with pytest.raises(OutputError, match=r"^data/../cal.yaml: is an input of this command \(cal.yaml\)"):
        output.check([output.file("data/../cal.yaml", overwrite=True)], inputs=["cal.yaml"])
    with pytest.raises(OutputError, match="is an input"):
        output.write_text("alias/run.csv", "x", overwrite=True, inputs=["data/run.csv"])
    assert (cwd / "data/run.csv").read_text() == "input" and (cwd / "cal.yaml").read_text() == "input"
    # an output inside an input directory is fine: only the output is swapped
    output.check([output.directory("data/results")], inputs=["data"])


def test_file_writer(cwd):
    output.write_text("a/b/cal.yaml", "# bendsense one", suffixes=output.YAML)
    assert (cwd / "a/b/cal.yaml").read_text() == "# bendsense one"
    with pytest.raises(OutputExistsError, match=r"^a/b/cal.yaml: exists \(use --overwrite to replace it\)$"):
        output.write_text("a/b/cal.yaml", "two")
    output.write_text("a/b/cal.yaml", "# bendsense two", overwrite=True)  # it carries bendsense's mark
    assert (cwd / "a/b/cal.yaml").read_text() == "# bendsense two"
    (cwd / "mine.yaml").write_text("a user's file")  # no mark: never replaced
    with pytest.raises(OutputError, match=r"^mine.yaml: exists and bendsense did not write it"):
        output.write_text("mine.yaml", "x", overwrite=True)
    assert (cwd / "mine.yaml").read_text() == "a user's file"
    with pytest.raises(OutputError, match=r"^cal.txt: unknown suffix '.txt'; use one of .yaml, .yml$"):
        output.write_text("cal.txt", "x", suffixes=output.YAML)
    with pytest.raises(OutputError, match=r"^fig.xyz: unknown figure format '.xyz'; use one of .*\.png"):
        output.check([output.file("fig.xyz", suffixes=output.FIGURE)])
    with pytest.raises(OutputError, match=r"^a: is a directory"):
        output.write_text("a", "x", overwrite=True)
    with pytest.raises(RuntimeError), output.write_file("a/b/cal.yaml", overwrite=True) as tmp:
        tmp.write_text("half")
        raise RuntimeError
    assert (cwd / "a/b/cal.yaml").read_text() == "# bendsense two" and _visible(cwd / "a/b") == ["cal.yaml"]


def test_file_in_an_output_directory_joins_its_manifest(cwd):
    with output.write_dir("out") as tmp:
        _write(tmp, **{"results.csv": "1"})
    output.write_text("out/fig.svg", "<svg/>")
    assert output.read_manifest(cwd / "out")["files"] == ["results.csv", "fig.svg"]
    assert output.foreign_entries(cwd / "out") == []


def test_checks_before_work_name_every_problem_up_front(cwd):
    (cwd / "fig.png").write_bytes(b"png")
    (cwd / "file").write_text("x")
    with pytest.raises(OutputExistsError, match="^fig.png: exists"):
        output.check([output.directory("out"), output.file("fig.png", suffixes=output.FIGURE)])
    with pytest.raises(OutputError, match="^file/out: .*file is not a directory"):
        output.check([output.directory("file/out")])
    with pytest.raises(OutputError, match="^file: exists and is not a directory"):
        output.check([output.directory("file", overwrite=True)])
    with pytest.raises(OutputError, match="given as output twice"):
        output.check([output.directory("out"), output.directory("./out")])
    assert not (cwd / "out").exists()


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_permissions_follow_the_umask(cwd, umask):
    old = os.umask(umask)
    try:
        with output.write_dir("out") as tmp:
            _write(tmp, **{"a.csv": "1", "sub/b": "2"})
        output.write_text("cal.yaml", "x")
        with output.write_file("fig.png") as tmp:
            pass  # the temporary file itself, as a writer that only opens it would leave it
    finally:
        os.umask(old)
    for d in ("out", "out/sub"):
        assert _mode(cwd / d) == 0o777 & ~umask
    for f in ("out/a.csv", "out/.bendsense-output.json", "cal.yaml", "fig.png"):
        assert _mode(cwd / f) == 0o666 & ~umask


def test_error_messages_name_the_users_path_not_the_temporary_one(cwd):
    with pytest.raises(OutputError) as info, output.write_dir("out") as tmp:
        open(tmp / "missing" / "x.csv", "w")
    message = str(info.value)
    assert message.startswith("out/missing/x.csv: no such file or directory; nothing was written")
    assert ".bendsense-tmp" not in message
    assert isinstance(info.value, BendsenseError)


def test_a_second_writer_refuses_while_the_first_holds_the_output(cwd):
    ctx = multiprocessing.get_context("spawn")
    ready, release = ctx.Event(), ctx.Event()
    proc = ctx.Process(target=hold_output, args=(str(cwd / "out"), ready, release, 10))
    proc.start()
    try:
        assert ready.wait(30)
        with pytest.raises(OutputError, match="^out: another bendsense run is writing there"):
            with output.write_dir("out"):
                pass
        with pytest.raises(OutputError, match="another bendsense run"):
            output.begin_in_place("out", ["frames.bin"])
    finally:
        release.set()
        proc.join(30)
    with output.write_dir("out") as tmp:  # free again
        _write(tmp, a="1")
    assert _visible(cwd) == ["out"]


def test_reentrant_within_a_process(cwd):
    with output.reserve([output.directory("out"), output.file("out/fig.png", suffixes=output.FIGURE)]):
        with output.write_dir("out") as tmp:
            _write(tmp, a="1")
        with output.write_file("out/fig.png") as tmp:
            tmp.write_bytes(b"png")
    assert output.read_manifest(cwd / "out")["files"] == ["a", "fig.png"]


def test_in_place_recording(cwd):
    rec = output.begin_in_place("sess", ["meta.yaml", "frames.bin"], writer="bendsense record")
    assert output.read_manifest(cwd / "sess")["files"] == ["meta.yaml", "frames.bin"]  # written first
    (cwd / "sess/frames.bin").write_bytes(b"1234")
    rec.close()
    with pytest.raises(OutputExistsError):
        output.begin_in_place("sess", ["meta.yaml", "frames.bin"])
    (cwd / "sess/notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="notes.txt"):
        output.begin_in_place("sess", ["meta.yaml", "frames.bin"], overwrite=True)
    assert (cwd / "sess/frames.bin").read_bytes() == b"1234"
    (cwd / "sess/notes.txt").unlink()
    with output.begin_in_place("sess", ["meta.yaml", "frames.bin"], overwrite=True):
        assert _visible(cwd / "sess") == [".bendsense-output.json"]  # the old recording's files went


def test_nested_outputs_and_litter_of_a_killed_run(cwd):
    with output.write_dir("all") as tmp:
        with output.write_dir(tmp / "results") as inner:
            _write(inner, **{"results.csv": "1"})
        _write(tmp, **{"calibration/flat.csv": "2"})
    assert output.read_manifest(cwd / "all")["files"] == ["calibration/flat.csv", "results/"]
    (cwd / ".all.bendsense-tmp-dead").mkdir()  # a killed run's temporary directory
    (cwd / "all/results/mine.txt").write_text("mine")
    with pytest.raises(OutputError, match="results/mine.txt"):
        output.check([output.directory("all", overwrite=True)])
    (cwd / "all/results/mine.txt").unlink()
    with output.write_dir("all", overwrite=True) as tmp:
        _write(tmp, x="1")
    assert _visible(cwd) == ["all"] and _visible(cwd / "all") == [".bendsense-output.json", "x"]
