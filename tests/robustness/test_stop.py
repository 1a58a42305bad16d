"""Stopping a run: real signals to real process trees of the ``bendsense`` command.

Ctrl-C (SIGINT to the process group) or SIGTERM (to the command alone) stops every long
command within seconds with one ``Interrupted (...)`` line and exit status 130 / 143,
takes its workers with it and leaves every output complete or absent; a worker whose
parent was killed exits by itself and writes nothing; a rerun finishes the job.
Processes are found through /proc (``/proc/<pid>/stat``: state, ppid, process group).
"""

import csv
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import linear_calibration, loaded_curvatures, signals_for

from bendsense.session import Session, write_session_csv

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process trees from /proc")

SCRIPT = Path(sys.executable).with_name("bendsense")
CLI = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-c", "from bendsense.cli import main; main()"]
STOP_S = 5.0  # the promise is 2 s; slack for a loaded CI machine
SESSIONS, FRAMES = 16, 2000


# --- process trees ------------------------------------------------------------------------


def _stat(pid):
    """(state, ppid, pgrp) of ``pid``, or None if it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return fields[0], int(fields[1]), int(fields[2])


def _pids():
    return [int(d) for d in os.listdir("/proc") if d.isdigit()]


def alive(pid) -> bool:
    """Running (a zombie is dead: it only waits for its parent to read its status)."""
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def children(pid) -> list:
    return [p for p in _pids() if (st := _stat(p)) is not None and st[1] == pid and alive(p)]


def group(pgid) -> list:
    return [p for p in _pids() if (st := _stat(p)) is not None and st[2] == pgid and alive(p)]


def cmdline(pid) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def wait_until(predicate, timeout, what):
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, what
        time.sleep(0.05)


def start(args, tmp_path, **kw):
    """The bendsense command in a session of its own (its own process group), stderr to a file."""
    err = open(tmp_path / "stderr.txt", "w+", encoding="utf-8")  # noqa: SIM115 - closed by stop()
    proc = subprocess.Popen([*CLI, *args], start_new_session=True, stdout=subprocess.DEVNULL, stderr=err,
                            cwd=tmp_path, **kw)
    proc.err_file = err
    return proc


def stderr_of(proc) -> str:
    proc.err_file.flush()
    return Path(proc.err_file.name).read_text(encoding="utf-8")


def stop(proc, sig, *, whole_group):
    """Send ``sig`` (to the group or the command alone); the exit status and the seconds until it came."""
    t0 = time.monotonic()
    if whole_group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    try:
        code = proc.wait(60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return code, time.monotonic() - t0


def cleanup(proc):
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    for p in group(proc.pid):
        os.kill(p, signal.SIGKILL)
    proc.err_file.close()


def assert_one_interrupted_line(text, sig):
    lines = [line for line in text.replace("\r", "\n").splitlines() if line.strip()]
    assert "Traceback" not in text, text
    assert lines[-1].startswith(f"Interrupted ({signal.Signals(sig).name}): "), text
    assert sum("Interrupted" in line for line in lines) == 1, text
    return lines[-1]


# --- process --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    """Many copies of one session CSV: a ``process`` run of several seconds on two workers."""
    root = tmp_path_factory.mktemp("batch")
    cal = linear_calibration()
    cal.save(root / "cal.yaml")
    t = np.linspace(0.0, 1.0, FRAMES)
    pressure = 40e3 + 40e3 * t
    force = np.column_stack([0.05 * np.sin(2 * np.pi * t), -0.1 - 0.1 * t])
    session = Session(0.01 * np.arange(FRAMES), signals_for(loaded_curvatures(pressure, force), cal), pressure)
    (root / "runs").mkdir()
    write_session_csv(session, root / "runs" / "s00.csv")
    for i in range(1, SESSIONS):
        shutil.copy(root / "runs" / "s00.csv", root / "runs" / f"s{i:02d}.csv")
    return root


def process_args(batch, out):
    return ["process", str(batch / "runs"), "--calibration", str(batch / "cal.yaml"), "-o", str(out),
            "--workers", "2", "--no-progress"]


def finished_sessions(out: Path) -> list:
    return sorted(p.name for p in out.iterdir() if p.is_dir() and not p.name.startswith(".")) if out.exists() else []


def assert_complete(out: Path, names):
    """Each session directory holds its manifest and a results.csv with a row for every frame."""
    for name in names:
        assert (out / name / ".bendsense-output.json").is_file(), name
        with open(out / name / "results.csv", newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
        assert len(rows) == FRAMES + 1 and all(len(r) == len(rows[0]) for r in rows), name


def running_process(batch, out, tmp_path):
    """``process`` started and caught with its two workers running and at least one session finished."""
    proc = start(process_args(batch, out), tmp_path)
    wait_until(lambda: finished_sessions(out) or proc.poll() is not None, 120,
               "no session finished")
    assert proc.poll() is None, stderr_of(proc)
    workers = [p for p in children(proc.pid) if "spawn_main" in cmdline(p)]
    assert len(workers) == 2, [cmdline(p) for p in children(proc.pid)]
    assert len(finished_sessions(out)) < SESSIONS  # still working
    return proc, workers



def test_process_overwrite_stopped_counts_only_the_sessions_it_redid(batch, tmp_path):
    """Ctrl-C during ``process --overwrite``: the earlier outputs are not counted as finished, the line says which
    were redone (each complete) and that the others keep their earlier output."""
    out = tmp_path / "out"
    first = subprocess.run([*CLI, *process_args(batch, out)], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    earlier = {p.name: p.stat().st_ino for p in out.iterdir() if p.is_dir() and not p.name.startswith(".")}
    assert len(earlier) == SESSIONS

    def redone():
        return sorted(name for name, ino in earlier.items()
                      if (out / name).exists() and (out / name).stat().st_ino != ino)

    proc = start([*process_args(batch, out), "--overwrite"], tmp_path)
    try:
        wait_until(lambda: redone() or proc.poll() is not None, 120, "no session redone")
        assert proc.poll() is None, stderr_of(proc)
        code, _ = stop(proc, signal.SIGINT, whole_group=True)
        text = stderr_of(proc)
    finally:
        cleanup(proc)
    assert code == 128 + signal.SIGINT, text
    line = assert_one_interrupted_line(text, signal.SIGINT)
    done = redone()
    assert 0 < len(done) < SESSIONS, line
    assert f": {len(done)} of {SESSIONS} sessions redone in " in line
    assert "the others keep their earlier output" in line
    assert finished_sessions(out) == sorted(earlier)  # nothing lost
    assert_complete(out, sorted(earlier))

@pytest.mark.parametrize(("sig", "whole_group"), [(signal.SIGINT, True), (signal.SIGTERM, False),
                                                  (signal.SIGHUP, True), (signal.SIGQUIT, True)],
                         ids=["ctrl-c-to-the-group", "sigterm-to-the-command", "closed-terminal-to-the-group",
                              "ctrl-backslash-to-the-group"])
def test_process_stops_with_its_workers_and_a_rerun_finishes(batch, tmp_path, sig, whole_group):
    out = tmp_path / "out"
    proc, workers = running_process(batch, out, tmp_path)
    try:
        code, seconds = stop(proc, sig, whole_group=whole_group)
        text = stderr_of(proc)
    finally:
        cleanup(proc)
    assert code == 128 + sig, text
    assert seconds < STOP_S, f"{seconds:.1f} s to stop"
    wait_until(lambda: not any(alive(w) for w in workers), STOP_S, "a worker outlived the command")
    wait_until(lambda: group(proc.pid) == [], STOP_S, "a process of the run is left")  # resource tracker neither
    line = assert_one_interrupted_line(text, sig)
    done = finished_sessions(out)
    assert f": {len(done)} of {SESSIONS} sessions finished in " in line
    assert_complete(out, done)  # every session directory there is whole ...
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".bendsense-output.json"]  # ... no litter
    # the rerun processes the rest and skips what is done, without --overwrite
    rerun = subprocess.run([*CLI, *process_args(batch, out)], capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{SESSIONS} sessions: {SESSIONS - len(done)} ok, {len(done)} skipped, 0 failed" in rerun.stdout
    assert_complete(out, [f"s{i:02d}" for i in range(SESSIONS)])


def test_workers_of_a_killed_process_exit_and_write_nothing(batch, tmp_path):
    """SIGKILL of the command alone (no cleanup of its own): its workers notice and exit; nothing is written
    after; a rerun finishes the job and removes the killed run's leftovers."""
    out = tmp_path / "out"
    proc, workers = running_process(batch, out, tmp_path)
    try:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        wait_until(lambda: not any(alive(w) for w in workers), STOP_S, "a worker outlived its killed parent")
    finally:
        cleanup(proc)

    def listing():
        return sorted((str(p.relative_to(out)), p.stat().st_size if p.is_file() else -1)
                      for p in out.rglob("*"))

    before = listing()
    time.sleep(2.0)
    assert listing() == before  # nobody writes for a run that is over
    done = finished_sessions(out)
    assert_complete(out, done)
    rerun = subprocess.run([*CLI, *process_args(batch, out)], capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{SESSIONS} sessions: {SESSIONS - len(done)} ok, {len(done)} skipped, 0 failed" in rerun.stdout
    assert_complete(out, [f"s{i:02d}" for i in range(SESSIONS)])
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".bendsense-output.json"]


# --- the other long commands ------------------------------------------------------------------


def run_and_stop(args, tmp_path, sig, *, whole_group, after_s=None, ready=None):
    """Start ``bendsense ARGS``, wait ``after_s`` seconds or until ``ready()``, send ``sig``; (exit status,
    seconds to stop, stderr), after checking that no process of the command is left."""
    proc = start(args, tmp_path)
    try:
        if ready is not None:
            wait_until(lambda: ready() or proc.poll() is not None, 120, "the command never got going")
        else:
            time.sleep(after_s)
        assert proc.poll() is None, stderr_of(proc)  # still working when stopped
        code, seconds = stop(proc, sig, whole_group=whole_group)
        text = stderr_of(proc)
        wait_until(lambda: group(proc.pid) == [], STOP_S, "a process of the command is left")
    finally:
        cleanup(proc)
    assert code == 128 + sig, text
    assert seconds < STOP_S, f"{seconds:.1f} s to stop"
    return assert_one_interrupted_line(text, sig)


def no_output(tmp_path, name):
    """Neither the output nor any hidden working copy of it."""
    left = [str(p.relative_to(tmp_path)) for p in tmp_path.iterdir()
            if p.name == name or p.name.startswith(f".{name}.")]
    left += [str(q.relative_to(tmp_path)) for p in tmp_path.iterdir() if p.name.startswith(f".{name}.") and p.is_dir()
             for q in p.rglob("*")]
    assert left == []
    return True


@pytest.fixture(scope="module")
def long_session(tmp_path_factory):
    """One session CSV long enough that reading, reconstructing and estimating it takes seconds."""
    root = tmp_path_factory.mktemp("long")
    cal = linear_calibration()
    cal.save(root / "cal.yaml")
    t = np.linspace(0.0, 1.0, 500)
    pressure = 40e3 + 40e3 * t
    force = np.column_stack([0.05 * np.sin(2 * np.pi * t), -0.1 - 0.1 * t])
    signals = signals_for(loaded_curvatures(pressure, force), cal)
    reps = 120  # 60,000 frames
    session = Session(1e-3 * np.arange(500 * reps), np.tile(signals, (reps, 1)), np.tile(pressure, reps))
    write_session_csv(session, root / "long.csv")
    return root


@pytest.mark.parametrize("after_s", [1.0, 3.0])
def test_chain_stops_and_writes_nothing(long_session, tmp_path, after_s):
    """``load ... reconstruct estimate save`` stopped while reading or estimating: no results directory."""
    line = run_and_stop(["load", str(long_session / "long.csv"), "--calibration", str(long_session / "cal.yaml"),
                         "reconstruct", "estimate", "save", "res"], tmp_path, signal.SIGTERM, whole_group=False,
                        after_s=after_s)
    assert line == "Interrupted (SIGTERM): no output left half-written"
    assert no_output(tmp_path, "res")


def test_simulate_stops_and_writes_nothing(tmp_path):
    line = run_and_stop(["simulate", "all", "-o", "sim", "--frames", "3000"], tmp_path, signal.SIGINT,
                        whole_group=True, after_s=2.0)
    assert line == "Interrupted (SIGINT): no output left half-written"
    assert no_output(tmp_path, "sim")


def test_calibrate_stops_and_writes_nothing(tmp_path):
    from bendsense.sim.scenarios import simulate

    simulate("calibration", tmp_path / "c", seed=0, frames_per_strip=20000)  # (bendsense simulate ... --frames 20000)
    line = run_and_stop(["calibrate", str(tmp_path / "c" / "manifest.yaml"), "-o", "cal.yaml", "--plot", "fit.png"],
                        tmp_path, signal.SIGTERM, whole_group=False, after_s=1.0)
    assert line == "Interrupted (SIGTERM): no output left half-written"
    assert no_output(tmp_path, "cal.yaml") and no_output(tmp_path, "fit.png")


def test_reproduce_stops_and_writes_nothing(tmp_path):
    line = run_and_stop(["reproduce", "--quick", "-o", "rep"], tmp_path, signal.SIGINT, whole_group=True,
                        ready=lambda: "simulating" in stderr_of_file(tmp_path))
    assert line == "Interrupted (SIGINT): no output left half-written"
    assert no_output(tmp_path, "rep")


def test_demo_stops_and_writes_nothing(tmp_path):
    """Stopped while it records its simulated board (a thread and a pseudo-terminal of its own)."""
    line = run_and_stop(["demo", "-o", "d", "--seconds", "5"], tmp_path, signal.SIGINT, whole_group=True,
                        ready=lambda: "recording" in stderr_of_file(tmp_path))
    assert line == "Interrupted (SIGINT): no output left half-written"
    assert no_output(tmp_path, "d")


def stderr_of_file(tmp_path):
    return (tmp_path / "stderr.txt").read_text(encoding="utf-8") if (tmp_path / "stderr.txt").exists() else ""


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")
@pytest.mark.parametrize(("sig", "whole_group"), [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["ctrl-c-to-the-group", "sigterm-to-the-command"])
def test_record_stops_and_keeps_its_frames(tmp_path, sig, whole_group):
    """The simulated board on a pseudo-terminal: the session keeps every frame written, marked finished, and the
    one line says how many."""
    import bendsense
    from bendsense.device.simdevice import SimulatedDevice, default_source

    with SimulatedDevice(default_source(rate_hz=500, seed=0), rate_hz=500) as dev:
        line = run_and_stop(["record", dev.port, "-o", "run", "--quiet-status"], tmp_path, sig,
                            whole_group=whole_group,
                            ready=lambda: (tmp_path / "run" / "frames.bin").exists()
                            and (tmp_path / "run" / "frames.bin").stat().st_size > 10_000)
    session = bendsense.read_session(tmp_path / "run")
    assert line == (f"Interrupted ({signal.Signals(sig).name}): kept {len(session)} frames in run "
                    "(synced to disk, session marked finished)")
    assert session.meta["finished"] and session.meta["outcome"] == "interrupted"
    assert np.all(np.diff(session.seq) >= 1)


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")
def test_record_estimate_stops_with_whole_results(tmp_path):
    """``record --estimate``: the results of a prefix of the kept frames, in whole rows, and the line says how
    many."""
    import bendsense
    from bendsense.device.simdevice import SimulatedDevice, default_source

    linear_calibration().save(tmp_path / "cal.yaml")
    with SimulatedDevice(default_source(rate_hz=500, seed=0), rate_hz=500) as dev:
        line = run_and_stop(["record", dev.port, "-o", "run", "--quiet-status", "--calibration", "cal.yaml",
                             "--estimate"], tmp_path, signal.SIGTERM, whole_group=False,
                            ready=lambda: (tmp_path / "run" / "results.csv").exists()
                            and (tmp_path / "run" / "results.csv").stat().st_size > 20_000
                            and (tmp_path / "run" / "frames.bin").stat().st_size > 40_000)
    session = bendsense.read_session(tmp_path / "run")
    raw = (tmp_path / "run" / "results.csv").read_bytes()
    with open(tmp_path / "run" / "results.csv", newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
    assert raw.endswith(b"\n") and all(len(r) == len(rows[0]) for r in rows)
    assert 0 < len(rows) - 1 <= len(session)
    assert line == (f"Interrupted (SIGTERM): kept {len(session)} frames in run (synced to disk, session marked "
                    f"finished); {len(rows) - 1} of them estimated to {Path('run') / 'results.csv'}")


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")
def test_live_stops_without_an_image(tmp_path):
    from bendsense.device.simdevice import SimulatedDevice, default_source

    linear_calibration().save(tmp_path / "cal.yaml")
    with SimulatedDevice(default_source(rate_hz=200, seed=0), rate_hz=200) as dev:
        # --seconds far beyond the wait for the board: a live start slowed by a busy machine must still be stopped
        line = run_and_stop(["live", dev.port, "--calibration", "cal.yaml", "--save", "fig.png", "--seconds", "600"],
                            tmp_path, signal.SIGTERM, whole_group=False, ready=lambda: dev.stats.sent > 400)
    assert line == "Interrupted (SIGTERM): no figure saved (fig.png is written when --seconds ends)"
    assert no_output(tmp_path, "fig.png")


# --- the first run: compiled once, before the workers start ---------------------------------------

DASK_RUN = """
import sys
from dask.distributed import Client, LocalCluster
from bendsense.batch import process_sessions
if __name__ == "__main__":
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \\
            Client(cluster) as client:
        report = process_sessions([sys.argv[1]], sys.argv[2], calibration=sys.argv[3],
                                  executor=client.get_executor(), progress=False, estimate=False)
    print(report.table())
"""


@pytest.mark.slow
def test_a_cold_cache_compiles_once_before_the_workers_start(batch, tmp_path):
    """numba's cache in a fresh directory (NUMBA_CACHE_DIR): the first ``process`` compiles the kernels in one
    process (one compile report per kernel group, not one per worker) and the two workers load its cache; with a
    local process pool and with a Dask cluster, each on its own cold cache. ``--no-estimate``: the shape
    kernels only, seconds to compile where the estimation kernels take a minute (the warm-up is the same
    step for both; a cold ``control`` and the demo compile those)."""
    runs = tmp_path / "runs"
    runs.mkdir()
    for i in range(4):
        shutil.copy(batch / "runs" / "s00.csv", runs / f"r{i}.csv")
    commands = {"pool": [*CLI, "process", str(runs), "--calibration", str(batch / "cal.yaml"), "-o",
                         str(tmp_path / "out-pool"), "--workers", "2", "--no-progress", "--no-estimate"]}
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        pass
    else:
        (tmp_path / "run.py").write_text(DASK_RUN, encoding="utf-8")
        commands["dask"] = [sys.executable, str(tmp_path / "run.py"), str(runs), str(tmp_path / "out-dask"),
                            str(batch / "cal.yaml")]
    started = {}
    for name, args in commands.items():
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"numba-cache-{name}")}
        started[name] = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                                         cwd=tmp_path)
    for name, proc in started.items():
        stdout, stderr = proc.communicate(timeout=1200)
        assert proc.returncode == 0, (name, stderr)
        assert "4 sessions: 4 ok" in stdout, (name, stdout)
        # each compile ends with one final line ("... 59/59 functions, 35 s"): one per group of kernels means one
        # process compiled them, and the workers found its cache
        finals = re.findall(r"^bendsense: compiling the (.+?) \(first run.*functions, \d+ s$", stderr, re.MULTILINE)
        assert "shape reconstruction" in finals and len(finals) == len(set(finals)), (name, stderr)
        assert list((tmp_path / f"numba-cache-{name}").rglob("*.nbi"))  # (the cache really was the fresh directory)


def _running_tasks(dask_worker):
    """The tasks occupying a thread of a Dask worker, those its scheduler cancelled included."""
    return len(dask_worker.state.all_running_tasks)


@pytest.mark.realtime  # a Ctrl-C while the cluster works
# Dask's LocalCluster may leave a socket of its own to the garbage collector when it closes on a busy machine.
# dashboard_address=":0" everywhere: None still binds the HTTP server to 8787, which another test worker may hold.
@pytest.mark.filterwarnings("ignore::ResourceWarning", "ignore::pytest.PytestUnraisableExceptionWarning")
def test_process_on_a_dask_scheduler_stops_and_a_rerun_finishes(batch, tmp_path):
    """``process --scheduler``: Ctrl-C cancels the queued sessions and closes the client within seconds; the
    sessions the cluster finished are complete (a running one may still finish: then whole), a rerun does the
    rest."""
    distributed = pytest.importorskip("dask.distributed")
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        args = [*process_args(batch, out)[:-3], "--scheduler", cluster.scheduler_address, "--no-progress"]
        line = run_and_stop(args, tmp_path, signal.SIGINT, whole_group=True, ready=lambda: finished_sessions(out))
        # the sessions the workers were running when the client left go on (a thread cannot be stopped): their end
        with distributed.Client(cluster) as observer:
            wait_until(lambda: not any(observer.run(_running_tasks).values()), 120,
                       "the cluster's workers never finished their tasks")
        done = finished_sessions(out)
        assert 0 < len(done) < SESSIONS
        assert_complete(out, done)
        assert f" of {SESSIONS} sessions finished in " in line
        rerun = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{SESSIONS} sessions: {SESSIONS - len(done)} ok, {len(done)} skipped, 0 failed" in rerun.stdout
    assert_complete(out, [f"s{i:02d}" for i in range(SESSIONS)])


WATCHED = """
import os, subprocess, sys, time
import bendsense.stop_signals as stop_signals
if sys.argv[1] == "parent":
    child = subprocess.Popen([sys.executable, __file__, "worker", str(os.getpid()), sys.argv[2]])
    print(child.pid, flush=True)
    time.sleep(600)
else:
    if sys.argv[3] == "thread":  # the portable fallback: a thread that watches the parent's pid
        stop_signals._pdeathsig = lambda: False
    stop_signals.exit_with_parent(int(sys.argv[2]), poll_s=0.1)
    print("watching", flush=True)
    end = time.monotonic() + 600
    while time.monotonic() < end:  # busy, as a worker in its session
        sum(range(1000))
"""


@pytest.mark.parametrize("how", ["prctl", "thread"])
def test_a_worker_exits_when_its_parent_is_killed(tmp_path, how):
    """bendsense.stop_signals.exit_with_parent, both ways (Linux's PR_SET_PDEATHSIG and the thread that polls the
    parent's pid): a busy child of a parent killed with SIGKILL ends within seconds."""
    (tmp_path / "watched.py").write_text(WATCHED, encoding="utf-8")
    parent = subprocess.Popen([sys.executable, str(tmp_path / "watched.py"), "parent", how], stdout=subprocess.PIPE,
                              text=True, start_new_session=True)
    try:
        worker = int(parent.stdout.readline())
        assert parent.stdout.readline() == "watching\n" and alive(worker)
        parent.kill()
        parent.wait(10)
        wait_until(lambda: not alive(worker), STOP_S, f"the worker outlived its parent ({how})")
    finally:
        for p in group(parent.pid):
            os.kill(p, signal.SIGKILL)
        parent.stdout.close()
