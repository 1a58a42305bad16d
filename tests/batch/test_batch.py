"""Batch processing of many sessions (bendsense.batch) and the ``process`` command."""

import concurrent.futures as cf
import importlib.util
import os
import pickle
import re
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import linear_calibration, loaded_curvatures, signals_for

from bendsense import load_config
from bendsense.batch import (
    BatchReport,
    SessionOutcome,
    discover_sessions,
    process_session,
    process_sessions,
    session_names,
)
from bendsense.choices import Options
from bendsense.cli import main
from bendsense.errors import SessionError
from bendsense.output import read_manifest
from bendsense.results import read_results
from bendsense.session import Session, write_session_csv
from bendsense.session.native import SessionWriter, record_dtype
from bendsense.stop_signals import worker_pool

CONFIG = load_config()
SENSOR = CONFIG.sensor
N = SENSOR.n_segments
# the force estimator is written in parallel; until it lands the batch runs shapes only
ESTIMATE = importlib.util.find_spec("bendsense.estimation") is not None
FRAMES = 40


def loading(frames, seed):
    """Pressure [Pa] and tip force [N] of a time-varying session: a pressure ramp, a growing load."""
    t = np.linspace(0.0, 1.0, frames)
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    pressure = 40e3 + 40e3 * t
    force = np.column_stack([0.05 * np.sin(2 * np.pi * t + phase), -0.1 - 0.1 * t])
    return pressure, force


def true_curvatures(frames, seed):
    """Segment curvatures (frames, N) [1/m] of the simulated actuator (beam model) under ``loading``."""
    return loaded_curvatures(*loading(frames, seed))


def make_session(seed, frames=FRAMES):
    kappa = true_curvatures(frames, seed)
    t = 0.01 * np.arange(frames)
    pressure, _ = loading(frames, seed)
    session = Session(t, signals_for(kappa, linear_calibration()), pressure, extra={"truth_id": np.full(frames, seed)})
    return session, kappa


def write_csv_session(path, seed, frames=FRAMES):
    session, kappa = make_session(seed, frames)
    write_session_csv(session, path)
    return kappa


def write_native_session(path, seed, frames=FRAMES):
    session, kappa = make_session(seed, frames)
    with SessionWriter(path, record_dtype(N, "<f8")) as writer:
        rec = writer.empty(frames)
        rec["t_us"] = np.round(session.t_s * 1e6).astype(np.uint64)
        rec["seq"] = np.arange(frames)
        rec["pressure_pa"] = np.round(session.pressure_pa).astype(np.int32)
        rec["adc"] = session.signals
        writer.write(rec)
    return kappa


def write_bad_csv(path):
    header = "t_s,pressure_pa," + ",".join(f"ch{i + 1}" for i in range(N))
    good = ",".join(["0.0", "40000"] + ["2000"] * N)
    bad = ",".join(["0.01", "40000", "2000", "oops"] + ["2000"] * (N - 2))
    path.write_text("\n".join([header, good, bad]) + "\n")


@pytest.fixture
def sessions(tmp_path):
    """runs/: two CSV sessions, one native session directory, one malformed CSV."""
    runs = tmp_path / "runs"
    runs.mkdir()
    truth = {  # name: (curvatures, seed)
        "a": (write_csv_session(runs / "a.csv", 1), 1),
        "b": (write_csv_session(runs / "b.csv", 2), 2),
        "native": (write_native_session(runs / "native", 3), 3),
    }
    write_bad_csv(runs / "broken.csv")
    return runs, truth


def check_outputs(out, truth):
    """Curvatures against the generating ones; forces against a direct estimate of the same frames."""
    for name, (kappa, seed) in truth.items():
        res = read_results(out / name)
        np.testing.assert_allclose(res.curvature_per_m, kappa, rtol=1e-9, atol=1e-9)
        assert res.positions_m.shape == (len(kappa), 101, 2)
        assert list(res["status"]) == ["ok"] * len(kappa)
        if ESTIMATE:
            from bendsense.estimation import estimate_force
            from bendsense.shape.pcc import Shape

            shape = Shape.from_curvatures(kappa, SENSOR.lengths_m)
            direct = estimate_force(shape, res["pressure_pa"], CONFIG, constraint="none", method="fast")
            np.testing.assert_allclose(res["fx_n"], np.asarray(direct.force_n)[:, 0], atol=1e-6)
            np.testing.assert_allclose(res["fy_n"], np.asarray(direct.force_n)[:, 1], atol=1e-6)
            _, force = loading(len(kappa), seed)
            np.testing.assert_allclose(np.column_stack([res["fx_n"], res["fy_n"]]), force, atol=0.01)


def by_name(report):
    return {s.name: s for s in report.sessions}


# --- discovery ------------------------------------------------------------------------------


def test_discovery_one_level_recursive_and_excluding_the_output(tmp_path):
    root = tmp_path / "data"
    (root / "day1" / "deep").mkdir(parents=True)
    write_csv_session(root / "top.csv", 0, frames=3)
    write_native_session(root / "rec", 0, frames=3)
    write_csv_session(root / "day1" / "x.csv", 0, frames=3)
    write_csv_session(root / "day1" / "deep" / "y.csv", 0, frames=3)
    (root / "notes.txt").write_text("not a session")
    (root / ".hidden.csv").write_text("t_s,ch1\n0,1\n")
    (root / "out" / "top").mkdir(parents=True)
    (root / "out" / "top" / "results.csv").write_text("t_s\n0\n")

    assert discover_sessions(root) == [root / "rec", root / "top.csv"]
    found = discover_sessions([root], recursive=True, exclude=root / "out")
    assert found == [root / "day1" / "deep" / "y.csv", root / "day1" / "x.csv", root / "rec", root / "top.csv"]
    # without the exclusion the earlier output would be taken for a session
    assert root / "out" / "top" / "results.csv" in discover_sessions(root, recursive=True)
    # explicit files and session directories are taken as given; duplicates dropped
    assert discover_sessions([root / "rec", root / "top.csv", root / "top.csv"]) == [root / "rec", root / "top.csv"]
    with pytest.raises(SessionError, match="nothing.csv: no such session file or directory"):
        discover_sessions([root / "nothing.csv"])


def test_session_names_are_unique(tmp_path):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "run.csv").write_text("")
    (tmp_path / "a" / "sess").mkdir()
    names = session_names([tmp_path / "a" / "run.csv", tmp_path / "b" / "run.csv", tmp_path / "a" / "sess"])
    assert names == ["a_run", "b_run", "sess"]
    # a recording's directory beside its CSV export: told apart by the suffix, not by the absolute path
    (tmp_path / "a" / "sess.csv").write_text("")
    assert session_names([tmp_path / "a" / "sess", tmp_path / "a" / "sess.csv"]) == ["sess", "sess_csv"]
    # parents prepended only as deep as they differ
    for d in ("x/day", "y/day"):
        (tmp_path / d).mkdir(parents=True)
        (tmp_path / d / "run.csv").write_text("")
    assert session_names([tmp_path / "x/day/run.csv", tmp_path / "y/day/run.csv"]) == ["x_day_run", "y_day_run"]


# --- processing ----------------------------------------------------------------------------


def test_relative_paths_reach_workers_that_run_elsewhere(sessions, tmp_path, monkeypatch):
    """Sessions and the output given relative to this directory are found by workers started in another one (a
    Dask cluster's workers have their own working directory)."""
    runs, truth = sessions
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(tmp_path)
    with cf.ProcessPoolExecutor(1, initializer=os.chdir, initargs=(str(elsewhere),)) as pool:
        report = process_sessions(runs.name, "out", calibration=linear_calibration(), executor=pool,
                                  estimate=False, progress=False)
    assert {s.name: s.status for s in report.sessions} == {"a": "ok", "b": "ok", "broken": "failed", "native": "ok"}
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith(".")) == ["a", "b", "native"]
    assert not any(elsewhere.iterdir())
    assert [s.source for s in report.sessions] == [str(runs / n) for n in ("a.csv", "b.csv", "broken.csv", "native")]
    assert f"{runs / 'broken.csv'}: line 3, column ch2" in by_name(report)["broken"].reason

def test_local_process_pool_bad_session_and_skip_unless_overwrite(sessions, tmp_path, caplog):
    runs, truth = sessions
    out = tmp_path / "out"
    with cf.ProcessPoolExecutor(2) as pool:
        report = process_sessions(
            runs, out, calibration=linear_calibration(), executor=pool, estimate=ESTIMATE, progress=False
        )
    rows = by_name(report)
    assert [s.name for s in report.sessions] == ["a", "b", "broken", "native"]  # discovery order
    assert {n: s.status for n, s in rows.items()} == {"a": "ok", "b": "ok", "broken": "failed", "native": "ok"}
    assert "line 3, column ch2: expected a number, got 'oops'" in rows["broken"].reason
    assert not (out / "broken").exists()
    batch_records = [r for r in caplog.records if r.name == "bendsense.batch"]
    said = [r.getMessage().split(":")[:2] for r in batch_records]
    assert [x for x in said if x[1] == " failed"] == [["broken", " failed"]]  # live, as it happens
    # and what the data could not carry, whole: these sessions' windows are too short for the window test
    assert {name for name, text in said if text != " failed"} <= {"a", "b", "native"}
    assert all(text == " window check" for _, text in said if text != " failed")
    assert report.frames == 3 * FRAMES and report.n_ok == 3 and report.n_failed == 1 and not report.ok
    assert report.frames_per_s == pytest.approx(report.frames / report.wall_s)
    assert all(rows[n].seconds > 0 and rows[n].frames == FRAMES for n in truth)
    check_outputs(out, truth)
    # extra columns pass through, the native session's pressure round-trips in whole pascals
    assert list(read_results(out / "a")["truth_id"]) == [1] * FRAMES

    # a second run skips what exists and retries the failure
    stamp = (out / "a" / "results.csv").stat().st_mtime_ns
    again = process_sessions(runs, out, calibration=linear_calibration(), workers=0, estimate=ESTIMATE, progress=True)
    assert {s.name: s.status for s in again.sessions} == {
        "a": "skipped", "b": "skipped", "broken": "failed", "native": "skipped"
    }  # fmt: skip
    assert "output exists" in by_name(again)["a"].reason
    assert (out / "a" / "results.csv").stat().st_mtime_ns == stamp
    # overwrite reprocesses, but never over a file bendsense did not write
    (out / "a" / "marker").write_text("a user's note")
    redo = process_sessions(
        runs / "a.csv", out, calibration=linear_calibration(), workers=0, overwrite=True, estimate=ESTIMATE,
        progress=False,
    )  # fmt: skip
    assert [s.status for s in redo.sessions] == ["failed"]
    assert "holds files bendsense did not write: marker" in redo.sessions[0].reason
    assert (out / "a" / "marker").read_text() == "a user's note"
    (out / "a" / "marker").unlink()
    redo = process_sessions(
        runs / "a.csv", out, calibration=linear_calibration(), workers=0, overwrite=True, estimate=ESTIMATE,
        progress=False,
    )  # fmt: skip
    assert [s.status for s in redo.sessions] == ["ok"]
    check_outputs(out, {"a": truth["a"]})


def test_an_output_named_like_another_batchs_session_is_never_taken_for_this_one(tmp_path):
    """Names depend on the batch: ``tv/`` and ``tv.csv`` together are ``tv`` and ``tv_csv``, ``tv.csv`` alone ``tv``."""
    runs = tmp_path / "runs"
    runs.mkdir()
    kappa = write_native_session(runs / "tv", 3)
    write_csv_session(runs / "tv.csv", 1)
    out = tmp_path / "out"
    first = process_sessions(runs, out, calibration=linear_calibration(), workers=0, estimate=False, progress=False)
    assert {s.name: s.status for s in first.sessions} == {"tv": "ok", "tv_csv": "ok"}
    assert read_manifest(out / "tv")["source"] == str((runs / "tv").resolve())  # each output names its session
    assert read_manifest(out / "tv_csv")["source"] == str((runs / "tv.csv").resolve())
    before = {f: (out / "tv" / f).read_bytes() for f in ("results.csv", "shape.npz")}
    for overwrite in (False, True):  # neither skipped as done nor replaced: another session's results
        alone = process_sessions(runs / "tv.csv", out, calibration=linear_calibration(), workers=0, estimate=False,
                                 overwrite=overwrite, progress=False)
        (row,) = alone.sessions
        assert (row.name, row.status) == ("tv", "failed")
        assert f"holds the results of another session, {(runs / 'tv').resolve()}" in row.reason
        assert {f: (out / "tv" / f).read_bytes() for f in before} == before
    np.testing.assert_allclose(read_results(out / "tv").curvature_per_m, kappa, rtol=1e-9, atol=1e-9)
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    result = CliRunner().invoke(main, process_args(runs / "tv.csv", cal_path, out) + ["--workers", "0"])
    assert result.exit_code == 1 and "another session" in result.output and "Traceback" not in result.output
    # the same session is still skipped, and replaced with --overwrite
    again = process_sessions(runs / "tv", out, calibration=linear_calibration(), workers=0, estimate=False,
                             progress=False)
    assert [s.status for s in again.sessions] == ["skipped"]
    redo = process_sessions(runs / "tv", out, calibration=linear_calibration(), workers=0, estimate=False,
                            overwrite=True, progress=False)
    assert [s.status for s in redo.sessions] == ["ok"]


def test_table_lists_every_session_and_the_totals():
    report = BatchReport(
        sessions=(
            SessionOutcome(name="run_1", source="r1.csv", status="ok", frames=100, seconds=0.5),
            SessionOutcome(name="r2", source="r2.csv", status="failed", seconds=0.1, reason="r2.csv: line 3: bad"),
            SessionOutcome(name="r3", source="r3", status="skipped", reason="output exists"),
        ),
        wall_s=2.0,
        workers="ProcessPoolExecutor(2 workers)",
    )
    lines = report.table().splitlines()
    assert lines[0].split() == ["session", "status", "frames", "time", "[s]", "note"]
    assert lines[1].split() == ["run_1", "ok", "100", "0.50"]
    assert lines[2].split()[:4] == ["r2", "failed", "-", "0.10"] and lines[2].endswith("r2.csv: line 3: bad")
    assert lines[3].split()[:4] == ["r3", "skipped", "-", "-"]
    assert lines[4] == (
        "3 sessions: 1 ok, 1 skipped, 1 failed; 100 frames in 2.00 s (50 frames/s, ProcessPoolExecutor(2 workers))"
    )
    assert report.to_dict()["sessions"][1]["reason"] == "r2.csv: line 3: bad"
    assert pickle.loads(pickle.dumps(report)) == report


def test_process_session_reports_failures_instead_of_raising(tmp_path):
    session, _ = make_session(0, frames=5)
    no_pressure = Session(session.t_s, session.signals, np.full(5, np.nan))
    write_session_csv(no_pressure, tmp_path / "nop.csv")
    cal = linear_calibration()
    row = process_session(tmp_path / "nop.csv", tmp_path / "o1", config=CONFIG, calibration=cal,
                          options=Options(estimate=True))
    assert row.status == "failed" and "5 of 5 frames have no pressure reading" in row.reason
    row = process_session(
        tmp_path / "nop.csv", tmp_path / "o2", config=CONFIG, calibration=cal,
        options=Options(pressure_pa=50e3, estimate=ESTIMATE)
    )
    assert row.status == "ok" and row.frames == 5
    assert np.all(read_results(tmp_path / "o2")["pressure_pa"] == 50e3)
    # a session with the wrong channel count
    write_session_csv(Session(session.t_s, session.signals[:, :8], session.pressure_pa), tmp_path / "ch8.csv")
    row = process_session(tmp_path / "ch8.csv", tmp_path / "o3", config=CONFIG, calibration=cal,
                          options=Options(estimate=ESTIMATE))
    assert row.status == "failed" and "ch8.csv: 8 signal channels (ch1..ch8), but the calibration has 16" in row.reason
    row = process_session(tmp_path / "missing.csv", tmp_path / "o4", config=CONFIG, calibration=cal)
    assert row.status == "failed" and "missing.csv: no such file" in row.reason


def test_a_batch_whose_every_session_fails_leaves_no_output_root(tmp_path):
    """Nothing to keep: the collection the run made goes (it stayed, holding only its manifest); one made before it,
    or one that a session wrote into, stays."""
    session, _ = make_session(0, frames=5)
    write_session_csv(Session(session.t_s, session.signals, np.full(5, np.nan)), tmp_path / "nop.csv")
    report = process_sessions([tmp_path / "nop.csv"], tmp_path / "out", config=CONFIG,
                              calibration=linear_calibration(), workers=0)
    assert report.n_failed == 1 and not (tmp_path / "out").exists()
    (tmp_path / "mine").mkdir()
    process_sessions([tmp_path / "nop.csv"], tmp_path / "mine", config=CONFIG, calibration=linear_calibration(),
                     workers=0)
    assert (tmp_path / "mine").is_dir()
    write_csv_session(tmp_path / "good.csv", 1, frames=5)
    report = process_sessions([tmp_path / "nop.csv", tmp_path / "good.csv"], tmp_path / "both", config=CONFIG,
                              calibration=linear_calibration(), workers=0)
    assert report.n_ok == 1 and (tmp_path / "both" / "good" / "results.csv").exists()


def test_extrapolated_frames_are_counted(tmp_path):
    session, _ = make_session(0, frames=5)
    signals = session.signals.copy()
    signals[2, 0] += 4000.0  # beyond the calibrated ΔA range of ±3000
    write_session_csv(Session(session.t_s, signals, session.pressure_pa), tmp_path / "x.csv")
    cal = linear_calibration()
    row = process_session(tmp_path / "x.csv", tmp_path / "o", config=CONFIG, calibration=cal,
                          options=Options(estimate=ESTIMATE))
    assert row.status == "ok" and row.extrapolated == 1 and "1 of 5 frames extrapolated" in row.reason
    assert list(read_results(tmp_path / "o")["status"])[2] in ("extrapolated", "not_converged", "model_misfit")


def test_the_note_counts_each_frame_by_the_status_results_csv_gives_it(tmp_path):
    """Signals far beyond the calibration (a unit mistake) turn the tip by more than a full turn: those frames are
    implausible_shape in results.csv and in the note, not also counted as estimates that did not converge."""
    import collections

    session, _ = make_session(0, frames=6)
    signals = session.signals.copy()
    signals[:3] += 10_000.0
    write_session_csv(Session(session.t_s, signals, session.pressure_pa), tmp_path / "x.csv")
    row = process_session(tmp_path / "x.csv", tmp_path / "o", config=CONFIG, calibration=linear_calibration(),
                          options=Options(estimate=ESTIMATE))
    words = collections.Counter(read_results(tmp_path / "o")["status"])
    assert words == {"implausible_shape": 3, "ok": 3}
    assert row.reason == "3 of 6 frames extrapolated, 3 of 6 frames implausible_shape" and row.not_converged == 0


def test_a_session_without_a_frame_to_use_says_so_first(tmp_path, caplog):
    """Processed, so listed ok in the table; but every frame's pressure is beyond the actuator's range (no force):
    the note begins with that, before the counts, and a chain on the command line warns so too."""
    session, _ = make_session(0, frames=6)
    beyond = np.full(6, CONFIG.actuator.pressure_range_pa[1] + 50e3)
    write_session_csv(Session(session.t_s, session.signals, beyond), tmp_path / "x.csv")
    cal = linear_calibration()
    row = process_session(tmp_path / "x.csv", tmp_path / "o", config=CONFIG, calibration=cal,
                          options=Options(estimate=ESTIMATE))
    assert set(read_results(tmp_path / "o")["status"]) == {"pressure_out_of_range"}
    assert row.status == "ok" and row.reason.startswith("no frame ok (0 of 6), 6 of 6 frames pressure out of range")
    cal.save(tmp_path / "cal.yaml")
    res = CliRunner().invoke(main, ["load", str(tmp_path / "x.csv"), "--calibration", str(tmp_path / "cal.yaml"),
                                    "reconstruct", "estimate"])
    assert res.exit_code == 0, res.output
    assert "no frame of 6 has status 'ok'" in caplog.text

    good = tmp_path / "good.csv"
    write_csv_session(good, 1, frames=6)
    row = process_session(good, tmp_path / "g", config=CONFIG, calibration=cal, options=Options(estimate=ESTIMATE))
    assert "no frame ok" not in row.reason


def test_an_unfinished_recording_is_processed_and_its_note_says_so(tmp_path):
    """A recorder killed before its clean stop (meta.yaml still ``finished: false``): its whole records are read
    and processed, and the batch's row says what ``load`` logs (a worker's log line would be lost)."""
    session, _ = make_session(0, frames=8)
    writer = SessionWriter(tmp_path / "killed", record_dtype(N, "<f8"))
    rec = writer.empty(8)
    rec["t_us"] = np.round(session.t_s * 1e6).astype(np.uint64)
    rec["seq"] = np.arange(8)
    rec["pressure_pa"] = np.round(session.pressure_pa).astype(np.int32)
    rec["adc"] = session.signals
    writer.write(rec)
    os.close(writer._fd)  # killed: the OS closes the files, meta.yaml is never rewritten (finished: false)
    writer._events.close()
    row = process_session(tmp_path / "killed", tmp_path / "o", config=CONFIG, calibration=linear_calibration(),
                          options=Options(estimate=ESTIMATE))
    assert row.status == "ok" and row.frames == 8
    assert row.reason.endswith("unfinished recording (no clean stop: killed, crashed or still recording)")


def test_no_sessions_is_an_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SessionError, match="no sessions"):
        process_sessions(tmp_path / "empty", tmp_path / "out", calibration=linear_calibration(), progress=False)


# --- Dask ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0", silence_logs=50
    ) as cluster:
        yield cluster


def test_dask_local_cluster(sessions, tmp_path, dask_cluster):
    from dask.distributed import Client

    runs, truth = sessions
    out = tmp_path / "out"
    with Client(dask_cluster) as client:
        report = process_sessions(
            runs, out, calibration=linear_calibration(), executor=client.get_executor(), estimate=ESTIMATE,
            progress=False,
        )  # fmt: skip
    rows = by_name(report)
    assert {n: s.status for n, s in rows.items()} == {"a": "ok", "b": "ok", "broken": "failed", "native": "ok"}
    assert "expected a number" in rows["broken"].reason
    assert report.workers == "ClientExecutor"
    check_outputs(out, truth)


# --- command line --------------------------------------------------------------------------


def process_args(runs, cal_path, out):
    return ["process", str(runs), "--calibration", str(cal_path), "-o", str(out), "--no-progress"] + (
        [] if ESTIMATE else ["--no-estimate"]
    )


def test_cli_process_exit_code_and_table(sessions, tmp_path):
    runs, truth = sessions
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, process_args(runs, cal_path, out) + ["--workers", "2"])
    assert result.exit_code == 1, result.output
    assert "1 of 4 sessions failed" in result.output
    table = result.output.splitlines()
    assert any(line.split()[:2] == ["broken", "failed"] for line in table)
    assert "4 sessions: 3 ok, 0 skipped, 1 failed" in result.output
    check_outputs(out, truth)
    # all good now: skipped ones count as success
    (runs / "broken.csv").unlink()
    result = CliRunner().invoke(main, process_args(runs, cal_path, out) + ["--workers", "0"])
    assert result.exit_code == 0, result.output
    assert "3 sessions: 0 ok, 3 skipped, 0 failed" in result.output


def test_cli_process_on_a_dask_scheduler(sessions, tmp_path, dask_cluster):
    runs, truth = sessions
    (runs / "broken.csv").unlink()
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    out = tmp_path / "out"
    args = process_args(runs, cal_path, out) + ["--scheduler", dask_cluster.scheduler_address]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "3 sessions: 3 ok" in result.output
    check_outputs(out, truth)


def test_cli_process_refuses_a_scheduler_without_workers_in_one_line(sessions, tmp_path, monkeypatch):
    """Its tasks would wait for ever (a scheduler whose workers were never started, or have left)."""
    from dask.distributed import LocalCluster

    import bendsense.cli.batch as cli_batch

    monkeypatch.setattr(cli_batch, "WORKER_WAIT_S", 1.0)
    runs, _ = sessions
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    with LocalCluster(n_workers=0, processes=False, protocol="tcp", dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        result = CliRunner().invoke(main, process_args(runs, cal_path, tmp_path / "out") + ["--scheduler", address])
    assert result.exit_code == 1
    assert result.output.strip() == f"Error: --scheduler {address!r}: no worker joined it in 1 s (start one: dask " \
                                    f"worker {address!r})"




@pytest.mark.parametrize(("address", "said"), [
    ("http://192.0.2.2:8787", "Error: Invalid value for --scheduler: expected the scheduler's tcp://HOST:PORT, got "
                              "'http://192.0.2.2:8787' (a web address: the dashboard's, not the scheduler's)"),
    ("foo://192.0.2.2:8786", "Error: Invalid value for --scheduler: expected tcp://HOST:PORT, got "
                             "'foo://192.0.2.2:8786' (Dask knows no foo://; it knows inproc://, tcp://, tls://"),
    ("tls://192.0.2.2:8786", "Error: Invalid value for --scheduler: 'tls://192.0.2.2:8786': tls:// needs Dask's TLS "
                             "configuration (a client certificate: distributed.comm.tls.client.cert)"),
], ids=["dashboard", "scheme", "tls-without-context"])
def test_cli_process_a_scheduler_address_it_cannot_use_is_one_line(sessions, tmp_path, address, said):
    pytest.importorskip("dask.distributed")
    runs, _ = sessions
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    result = CliRunner().invoke(main, process_args(runs, cal_path, tmp_path / "out") + ["--scheduler", address])
    assert result.exit_code == 2, result.output
    assert result.output.strip().startswith(said) and len(result.output.strip().splitlines()) == 1, result.output
    assert not (tmp_path / "out").exists()

@pytest.mark.realtime  # a worker closed while the cluster works
def test_cli_process_stops_in_one_line_when_the_schedulers_workers_leave(tmp_path, monkeypatch):
    """Every worker gone mid-run: the tasks would wait for ever; the command stops in one line, the sessions
    finished before complete, and a rerun on a cluster with a worker does the rest."""
    import shutil
    import threading
    import time

    from dask.distributed import LocalCluster

    import bendsense.cli.batch as cli_batch

    monkeypatch.setattr(cli_batch, "WORKER_WAIT_S", 1.0)
    runs = tmp_path / "runs"
    runs.mkdir()
    write_csv_session(runs / "s00.csv", 1, frames=400)
    for i in range(1, 40):
        shutil.copy(runs / "s00.csv", runs / f"s{i:02d}.csv")
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    out = tmp_path / "out"

    def finished():
        return sorted(p.name for p in out.glob("s*") if p.is_dir())

    with LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=":0",
                      silence_logs=50) as cluster:
        def leave():  # the worker goes once a session is done
            end = time.monotonic() + 120
            while not finished() and time.monotonic() < end:
                time.sleep(0.05)
            cluster.scale(0)

        leaving = threading.Thread(target=leave)
        leaving.start()
        address = cluster.scheduler_address
        t0 = time.monotonic()
        result = CliRunner().invoke(main, process_args(runs, cal_path, out) + ["--scheduler", address])
        seconds = time.monotonic() - t0
        leaving.join()
        assert result.exit_code == 1, result.output
        said = re.fullmatch(
            rf"Error: --scheduler {re.escape(address)}: no worker left on the scheduler for 1 s and its tasks "
            rf"cancelled; (\d+) of 40 sessions finished in {re.escape(str(out))} \(each complete\); the rest have "
            r"no output: run the same command again to process them \(finished sessions are skipped\)",
            result.output.strip().splitlines()[-1])
        assert said, result.output
        assert "Traceback" not in result.output and seconds < 60
        done = finished()
        assert 0 < len(done) < 40
        # (a session the worker was running as it left may have been swapped in, whole, after the count)
        assert int(said[1]) <= len(done) <= int(said[1]) + 1
        cluster.scale(1)
        cluster.wait_for_workers(1)
        rerun = CliRunner().invoke(main, process_args(runs, cal_path, out) + ["--scheduler", address])
    assert rerun.exit_code == 0, rerun.output
    assert f"40 sessions: {40 - len(done)} ok, {len(done)} skipped, 0 failed" in rerun.output

def test_a_batch_whose_executor_cancels_its_tasks_stops_instead_of_failing_each_session(sessions, tmp_path):
    """A Dask scheduler gone cancels every task: one error for the batch (the command says it in one line), not a
    'failed' row of an empty reason for every session."""

    class Cancelling(cf.ThreadPoolExecutor):
        calls = 0

        def submit(self, fn, *args, **kwargs):
            Cancelling.calls += 1
            if Cancelling.calls == 1:  # the warm-up runs; the sessions' tasks are cancelled
                return super().submit(fn, *args, **kwargs)
            future = cf.Future()
            future.cancel()
            future.set_running_or_notify_cancel()  # as an executor does: as_completed sees it done
            return future

    runs, _ = sessions
    with Cancelling(1) as executor, pytest.raises(cf.CancelledError):
        process_sessions(runs, tmp_path / "out", calibration=linear_calibration(), executor=executor,
                         estimate=ESTIMATE, progress=False)


def test_cli_process_says_what_the_data_could_not_carry_whole(tmp_path, caplog):
    """The table cuts its notes to its width; the DataWarning behind one (pressures in kPa written as Pa) is said
    whole, once, as the session's WARNING line."""
    import logging

    session, _ = make_session(0)
    runs = tmp_path / "runs"
    runs.mkdir()
    write_session_csv(Session(session.t_s, session.signals, session.pressure_pa / 1e3), runs / "kpa.csv")
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        res = CliRunner().invoke(main, process_args(runs, cal_path, tmp_path / "out"))
    assert res.exit_code == 0, res.output
    said = [r.getMessage() for r in caplog.records if "kPa given as Pa" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith("kpa: pressure_pa: every pressure is below 1 kPa (largest 80 Pa)")
    assert said[0].endswith("(multiply by 1000, or name the column pressure_kpa)")


def test_cli_process_option_errors(sessions, tmp_path, monkeypatch):
    runs, _ = sessions
    cal_path = tmp_path / "cal.yaml"
    linear_calibration().save(cal_path)
    args = process_args(runs, cal_path, tmp_path / "out")
    result = CliRunner().invoke(main, args + ["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"])
    assert result.exit_code == 2 and "give --workers or --scheduler, not both" in result.output
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if the extra were not installed
    result = CliRunner().invoke(main, args + ["--scheduler", "tcp://127.0.0.1:1"])
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        "Error: --scheduler needs Dask distributed, which is not installed: pip install bendsense[distributed]"
    )
    assert not (tmp_path / "out").exists()


def test_processes_or_numba_threads_never_both(sessions, tmp_path):
    """The default pool's workers run one numba thread each; in-process runs use numba's threads.

    The report says which.
    """
    import numba

    runs, truth = sessions
    pooled = process_sessions(runs / "a.csv", tmp_path / "pool", calibration=linear_calibration(), workers=2,
                              estimate=ESTIMATE, progress=False)
    assert [s.status for s in pooled.sessions] == ["ok"]
    assert pooled.workers == "ProcessPoolExecutor(1 worker, 1 numba thread each)"
    local = process_sessions(runs / "a.csv", tmp_path / "here", calibration=linear_calibration(), workers=0,
                             estimate=ESTIMATE, progress=False)
    assert local.workers == f"in-process, {numba.get_num_threads()} numba threads"
    pool = worker_pool(1)
    try:
        assert pool.submit(numba.get_num_threads).result() == 1
    finally:
        pool.shutdown()


def test_process_reports_lost_frames_and_firmware_drops(tmp_path):
    from bendsense.session.native import SessionWriter, record_dtype

    cal = linear_calibration()
    with SessionWriter(tmp_path / "runs" / "rec", record_dtype(16), adc_bits=16) as w:
        rec = w.empty(6)
        rec["seq"] = [10, 11, 14, 15, 16, 20]  # 2 + 3 frames missing
        rec["tx_drops"] = [7, 7, 9, 9, 9, 10]  # the firmware could not send 3 of them
        rec["t_us"] = np.arange(6) * 1000
        rec["adc"] = np.asarray(cal.offset).round().astype(np.uint16)
        w.write(rec)
    report = process_sessions(tmp_path / "runs", tmp_path / "out", config=CONFIG, calibration=cal, estimate=False,
                              workers=0, progress=False)
    (row,) = report.sessions
    assert row.status == "ok" and row.frames_lost == 5 and row.tx_drops == 3
    assert "5 frames lost (3 dropped by the firmware)" in row.reason
    assert report.table().splitlines()[-1] == "5 frames lost in the recordings (3 dropped by the firmware)"


def test_more_workers_than_the_memory_holds_are_refused_before_any_work(tmp_path):
    """Each worker holds numpy, scipy, numba and the kernels (~300 MB): '--workers' for more sessions than the free
    memory holds workers is one line naming the option and the cap; nothing is processed or written."""
    from bendsense.sim.memory import available_memory_bytes

    available = available_memory_bytes()
    if available is None:
        pytest.skip("no /proc/meminfo: the free memory is unknown")
    n = 2 * int(available // 300e6) + 10  # twice what fits: the free memory moves while the test runs
    for i in range(n):
        (tmp_path / f"s{i:04d}.csv").write_text("t_s,pressure_kpa,ch1\n0,40,2000\n")
    linear_calibration().save(tmp_path / "cal.yaml")
    res = CliRunner().invoke(main, ["process", str(tmp_path), "--calibration", str(tmp_path / "cal.yaml"),
                                    "-o", str(tmp_path / "out"), "--workers", str(n), "--no-estimate"])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert re.search(rf"workers \(--workers\): {n:,} worker processes would need about .*; this machine has .* "
                     r"available \(at most [\d,]+ workers\)", res.output), res.output
    assert not (tmp_path / "out").exists()


def test_a_rerun_removes_the_manifest_copy_a_killed_run_left(sessions, tmp_path):
    """A run killed between writing the collection's manifest aside and renaming it leaves the copy; the next run
    removes it (and only it)."""
    runs, _ = sessions
    out = tmp_path / "out"
    process_sessions(runs / "a.csv", out, calibration=linear_calibration(), workers=0, estimate=False, progress=False)
    stale = out / "..bendsense-output.json.bendsense-tmp-k1lled"
    stale.write_text('{"format": "bendsense-out')  # cut off mid-write
    (out / ".my-settings").write_text("a user's")  # hidden, but not bendsense's: kept
    (out / "notes.txt").write_text("a user's")
    report = process_sessions(runs / "b.csv", out, calibration=linear_calibration(), workers=0, estimate=False,
                              progress=False)
    assert [s.status for s in report.sessions] == ["ok"]
    assert sorted(p.name for p in out.iterdir()) == [".bendsense-output.json", ".my-settings", "a", "b", "notes.txt"]
    assert read_manifest(out)["files"] == ["a/", "b/"]


def test_a_calibration_that_fails_stops_the_pool_started_beside_it(sessions, tmp_path, monkeypatch):
    """The local pool's workers start while the parent prepares the calibration; a calibration that cannot be read
    is the batch's one error, its workers are stopped (none left running) and nothing is written."""
    import multiprocessing

    import bendsense.batch as batch
    from bendsense.errors import BendsenseError

    runs, _ = sessions
    bad = tmp_path / "cal.yaml"
    bad.write_text("coefficients_odd: [1, 2\n")  # cut off mid-list
    pools = []

    def recorded(workers, **kwargs):
        pools.append(worker_pool(workers, **kwargs))
        return pools[-1]

    workers = []  # the pool's processes when the parent prepares the calibration
    prepared = batch._prepared

    def preparing(*args):
        workers.extend(pools[0]._processes.values())
        return prepared(*args)

    monkeypatch.setattr(batch, "worker_pool", recorded)
    monkeypatch.setattr(batch, "_prepared", preparing)
    with pytest.raises(BendsenseError, match="cal.yaml"):
        process_sessions(runs, tmp_path / "out", calibration=bad, workers=2, progress=False)
    assert len(workers) == 2  # both started before the calibration was read
    assert all(w.exitcode is not None for w in workers)  # ended and joined: none left running
    assert not set(workers) & set(multiprocessing.active_children())
    assert not (tmp_path / "out").exists()
