#!/usr/bin/env python
# ruff: noqa: D103  (the small builders of the cases below say what they do in their names)
"""A re-runnable campaign of hostile inputs against every command and the public API.

Each case runs the real ``bendsense`` (the one next to ``sys.executable``) or a snippet
of the public Python API in a subprocess, in a working directory of its own that holds a
copy of a small simulated lab (a calibration, a session CSV, a native session, a config),
and classifies what happened:

  handled    exit 0 with sensible output, or a non-zero exit with exactly one ``Error:``
             line and no traceback
  traceback  a Python traceback (for the API: an exception that is not a BendsenseError)
  crash      killed by a signal it did not ask for
  hang       still running at the timeout
  wrong-ok   a success for nonsense input, or results.csv rows with status ``ok`` whose
             values are NaN or absurd
  data-loss  a file that existed before the run changed or disappeared
  poor       a non-zero exit without one clear ``Error:`` line, an internal class name
             or a Python repr in the message, or a valid input refused
  skipped    the machine cannot provoke the condition (a permission case, as root)

Usage:

    python tools/campaign.py                 # every case
    python tools/campaign.py --only record   # the cases whose name or command matches
    python tools/campaign.py --jobs 2 --list
    python tools/campaign.py --self-check    # three quick cases

The exit code is 1 if any case is traceback, crash, hang, wrong-ok or data-loss.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import fnmatch
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from pathlib import Path

BIN = Path(sys.executable).with_name("bendsense")
PY = sys.executable
FAILING = ("traceback", "crash", "hang", "wrong-ok", "data-loss")
KINDS = ("handled", *FAILING, "poor", "skipped")
TIMEOUT = 60.0
ABSURD_FORCE_N = 50.0  # a silicone finger of the paper's size carries a few newtons
TRUTH_SIGMAS = 8.0  # the lab's own results are within 3 sigma of the simulated truth

# A Python repr or an internal name in a message meant for a user.
REPR = re.compile(
    r"<[\w.]+ object at 0x|\barray\(|np\.float\d*\(|\bdtype\(|\bPosixPath\(|"
    r"\b[A-Z][a-z]+(?:[A-Z][a-z]+)+(?:Error|Exception|Decoder|Writer|Reader|Processor)\b|"
    r"\bKeyError\b|\bIndexError\b|\bTypeError\b|\bValueError\b|\bAttributeError\b|"
    r"\bOSError\b|\bErrno\b|\(\d+, '"
)


# --- cases ------------------------------------------------------------------------------


class Skip(Exception):
    """The machine cannot provoke this case's condition."""


@dataclasses.dataclass
class Case:
    """One hostile input.

    ``args`` is the command line after ``bendsense`` (a list, or a callable of the working
    directory); ``api`` a Python snippet instead (``LAB`` is the lab path, ``bs`` the
    package, ``np`` numpy; print ``WRONG-OK: why`` for a result that must not be
    trusted). ``expect`` is ``"error"`` (nonsense: success is wrong-ok), ``"ok"`` (valid:
    a refusal is poor) or ``"any"``. ``check(work, output)`` returns a reason when an exit
    0 is a wrong ok (or a ``(kind, reason)`` pair). ``run`` replaces the whole subprocess (interactive cases).
    A setup or driver raises :class:`Skip` when the machine cannot provoke the condition
    (permissions, as root).
    """

    name: str
    command: str
    args: list | Callable | None = None
    api: str | None = None
    expect: str = "any"
    setup: Callable | None = None
    check: Callable | None = None
    env: dict | None = None
    unset: tuple = ()
    timeout: float = TIMEOUT
    may_change: tuple = ()
    run: Callable | None = None
    stdin: bytes | None = None


@dataclasses.dataclass
class Outcome:
    """What one case did."""

    case: Case
    kind: str
    detail: str
    seconds: float
    returncode: int | None
    output: str = ""  # the command's last output, for a case that was not handled


CASES: list[Case] = []


def case(*args, **kwargs) -> None:
    CASES.append(Case(*args, **kwargs))


# --- helpers used by the cases --------------------------------------------------------------


def readonly_dir(d: Path) -> None:
    """A directory nobody can write: mode 555, or as root (who ignores modes) a read-only tmpfs."""
    d.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        d.chmod(0o555)
        return
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k,mode=0755", "tmpfs", str(d)],
                       capture_output=True, text=True)
    if r.returncode:
        raise Skip("root ignores permissions and cannot mount a read-only tmpfs: " + r.stderr.strip())


def unreadable(f: Path) -> None:
    if os.geteuid() == 0:
        raise Skip("root reads any file")
    f.chmod(0)

CHAIN = ["--calibration", "lab/cal.yaml", "reconstruct", "estimate", "save", "out"]


def chain(session, *extra, tail=None):
    return ["load", session, *extra, *(CHAIN if tail is None else tail)]


def text(path, content, encoding="utf-8", newline=None):
    def setup(work):
        p = work / path
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p, "w", encoding=encoding, newline=newline) as fh:
            fh.write(content(work) if callable(content) else content)
    return setup


def raw(path, data):
    def setup(work):
        p = work / path
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data(work) if callable(data) else data)
    return setup


def steps(*setups):
    def setup(work):
        for s in setups:
            s(work)
    return setup


def csv_lines(work, name="lab/run.csv"):
    return (work / name).read_text(encoding="utf-8").splitlines()


def header_and_rows(work, name="lab/run.csv"):
    lines = [ln for ln in csv_lines(work, name) if not ln.startswith("#")]
    return lines[0], lines[1:]


def edit_csv(path, fn, src="lab/run.csv", comments=False):
    """Write PATH from the lab session SRC: fn(header, rows) -> list of lines (after SRC's comments)."""
    def setup(work):
        h, rows = header_and_rows(work, src)
        head = [ln for ln in csv_lines(work, src) if ln.startswith("#")] if comments else []
        (work / path).parent.mkdir(parents=True, exist_ok=True)
        (work / path).write_text("\n".join([*head, *fn(h, rows)]) + "\n", encoding="utf-8")
    return setup


def edit_column(path, column, value, row=None):
    def fn(h, rows):
        cols = h.split(",")
        i = cols.index(column)
        out = [h]
        for k, r in enumerate(rows):
            cells = r.split(",")
            if row is None or k == row:
                cells[i] = value
            out.append(",".join(cells))
        return out
    return edit_csv(path, fn)


def without_pressure(path):
    return edit_csv(path, lambda h, r: [",".join(c for c in h.split(",") if c != "pressure_pa"),
                                        *(",".join(c for c, n in zip(x.split(","), h.split(","))
                                                   if n != "pressure_pa") for x in r)])


def edit_yaml(path, src, fn):
    """Write PATH from the lab's YAML SRC edited by fn(dict)."""
    def setup(work):
        import yaml

        data = yaml.safe_load((work / src).read_text(encoding="utf-8"))
        fn(data)
        (work / path).parent.mkdir(parents=True, exist_ok=True)
        (work / path).write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return setup


def set_key(keys, value):
    def fn(d):
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value
    return fn


def results_ok_sane(work, output, root="out"):
    """A reason if some results.csv under ROOT has an ok row with a NaN or absurd value."""
    import csv

    for path in sorted((work / root).rglob("results.csv")) if (work / root).exists() else []:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
        if not rows:
            continue
        head = rows[0]
        if "status" not in head:
            continue
        si = head.index("status")
        for n, r in enumerate(rows[1:], start=2):
            if r[si] != "ok":
                continue
            for col in ("fx_n", "fy_n", "fx_std_n", "fy_std_n", "tip_x_m", "tip_y_m"):
                if col not in head:
                    continue
                try:
                    v = float(r[head.index(col)])
                except ValueError:
                    return f"{path.relative_to(work)} line {n}: {col}={r[head.index(col)]!r} with status ok"
                if v != v or abs(v) == float("inf"):
                    return f"{path.relative_to(work)} line {n}: {col}={v} with status ok"
                if col in ("fx_n", "fy_n") and abs(v) > ABSURD_FORCE_N:
                    return f"{path.relative_to(work)} line {n}: {col}={v:g} N with status ok"
                if col.startswith("tip_") and abs(v) > 1.0:
                    return f"{path.relative_to(work)} line {n}: {col}={v:g} m with status ok"
            far = _far_from_truth(head, r)
            if far:
                return f"{path.relative_to(work)} line {n}: status ok but {far}"
        if "track_status" in head:
            ti = head.index("track_status")
            for n, r in enumerate(rows[1:], start=2):
                far = r[ti] == "ok" and _far_from_truth(head, r, "_track")
                if far:
                    return f"{path.relative_to(work)} line {n}: track_status ok but {far}"
    return None


def _far_from_truth(head, row, kind=""):
    """Why an ok force (KIND "_track": the tracked one) is far from the simulated truth, or None.

    The truth travels with the lab's session (input_fx_n, input_fy_n); an ok force more
    than TRUTH_SIGMAS standard deviations (plus a small floor) from it is not ok.
    """
    try:
        for axis in ("x", "y"):
            f = float(row[head.index(f"f{axis}{kind}_n")])
            sd = float(row[head.index(f"f{axis}{kind}_std_n")])
            truth = float(row[head.index(f"input_f{axis}_n")])
            if not abs(f - truth) <= TRUTH_SIGMAS * sd + 0.05:
                return f"f{axis}{kind}_n={f:.3g} N, the truth {truth:.3g} N, sigma {sd:.2g} N"
    except (ValueError, IndexError):
        return None
    return None


def no_ok_rows(work, output, root="out"):
    """For nonsense that may be processed but must never be trusted: no row is ok."""
    import csv

    for path in sorted((work / root).rglob("results.csv")) if (work / root).exists() else []:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
        if rows and "status" in rows[0]:
            si = rows[0].index("status")
            ok = sum(1 for r in rows[1:] if r[si] == "ok")
            if ok:
                return f"{path.relative_to(work)}: {ok} rows 'ok' from nonsense input"
    return results_ok_sane(work, output, root)


def wrote(*paths):
    """Exit 0 must have written each path."""
    def check(work, output):
        for p in paths:
            if not (work / p).exists():
                return f"exit 0 but {p} was not written"
        return results_ok_sane(work, output)
    return check


# --- interactive drivers (board, record, live) ----------------------------------------------


def _popen(argv, work, env):
    return subprocess.Popen(argv, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def _board(work, env, *extra, timeout=30):
    """Start sim-device; return (Popen, port) once it printed its port."""
    p = _popen([str(BIN), "sim-device", *extra], work, env)
    t0 = time.monotonic()
    line = b""
    os.set_blocking(p.stdout.fileno(), False)
    while time.monotonic() - t0 < timeout and p.poll() is None:
        chunk = p.stdout.read() or b""
        line += chunk
        if b"\n" in line:
            break
        time.sleep(0.05)
    port = line.decode(errors="replace").strip().splitlines()[0] if line.strip() else ""
    return p, port


def _finish(p, timeout):
    try:
        out, err = p.communicate(timeout=timeout)
        return p.returncode, (out + err).decode(errors="replace"), False
    except subprocess.TimeoutExpired:
        out, err = _dump_and_kill(p)
        return None, (out + err).decode(errors="replace"), True


def _dump_and_kill(p):
    """Stop a hung process, and return its (stdout, stderr).

    SIGABRT first, whose faulthandler (PYTHONFAULTHANDLER, :func:`base_env`) prints every
    thread's stack into its output; then SIGKILL to its group.
    """
    try:
        p.send_signal(signal.SIGABRT)
        return p.communicate(timeout=5)
    except subprocess.TimeoutExpired:
        pass
    finally:
        _kill(p)
    return p.communicate()


def _kill(p):
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def with_board(client_args, board_args=("--rate", "100", "--seconds", "40"), during=None, expect_board=False,
               after=None):
    """A driver: start a simulated board, run CLIENT_ARGS(port) against it, stop the board.

    ``during(client, board, work)`` runs while the client runs (e.g. kill the board);
    ``after(port, board, work)`` once the client ended, before the board is stopped (e.g. probe it).
    """
    def run(work, env, timeout):
        board, port = _board(work, env, *board_args)
        if not port.startswith("/"):
            rc, out, hung = _finish(board, 5)
            return rc, "board did not start: " + out, hung
        try:
            client = _popen([str(BIN), *client_args(port)], work, env)
            if during is not None:
                during(client, board, work)
            rc, out, hung = _finish(client, timeout)
            if after is not None:
                after(port, board, work)
        finally:
            if board.poll() is None:
                board.send_signal(signal.SIGINT)
            brc, bout, bhung = _finish(board, 10)
        if expect_board:
            if bhung:
                return None, "sim-device did not stop within 10 s of SIGINT\n" + bout, True
            return brc, bout, False
        return rc, out, hung
    return run


def sigint_after(seconds, target="client"):
    def during(client, board, work):
        time.sleep(seconds)
        p = client if target == "client" else board
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    return during


def kill_board_after(seconds):
    def during(client, board, work):
        time.sleep(seconds)
        _kill(board)
    return during


def text_board(client_args, hello=True, texts=("calibrating coil 3", "überhitzt? ✓", "x" * 300)):
    """A driver: a board on a pseudo-terminal that answers HELLO and then sends only TEXT frames."""
    def run(work, env, timeout):
        import pty
        import threading
        import tty

        from bendsense.wire.frames import encode_hello, encode_text

        master, slave = pty.openpty()
        tty.setraw(slave)
        port = os.ttyname(slave)
        stop = threading.Event()

        def board():
            seq = 0
            t0 = time.monotonic()
            os.set_blocking(master, False)
            while not stop.is_set():
                try:
                    got = os.read(master, 4096)
                except (BlockingIOError, OSError):
                    got = b""
                if hello and got:  # any command: say hello (the client asks for it)
                    os.write(master, encode_hello(seq, 0, 16, 12, 100, 3300, "campaign-text-only"))
                    seq += 1
                try:
                    os.write(master, encode_text(seq, int((time.monotonic() - t0) * 1e6), texts[seq % len(texts)]))
                except OSError:
                    pass
                seq += 1
                time.sleep(0.01)

        th = threading.Thread(target=board, daemon=True)
        th.start()
        try:
            client = _popen([str(BIN), *client_args(port)], work, env)
            return _finish(client, timeout)
        finally:
            stop.set()
            th.join(2)
            os.close(master)
            os.close(slave)
    return run


# --- the lab -----------------------------------------------------------------------------------


LAB_STEPS: list[Callable] = []  # step(lab, run): more of the lab, from a module of cases (run: bendsense ARGS in lab)


def make_lab(root: Path, log=print) -> Path:
    """Simulate a calibration and a session once; every case gets a copy."""
    lab = root / "lab"
    lab.mkdir(parents=True)
    env = base_env()

    def run(*args, cwd=lab):
        r = subprocess.run([str(BIN), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
        if r.returncode:
            raise SystemExit(f"lab: bendsense {' '.join(args)} failed:\n{r.stdout}{r.stderr}")

    t0 = time.monotonic()
    run("simulate", "calibration", "-o", "calsim", "--frames", "3")
    run("calibrate", "calsim/manifest.yaml", "-o", "cal.yaml")
    run("simulate", "tip-loads", "-o", "tl", "--frames", "1")
    sessions = sorted((lab / "tl").glob("*.csv"))
    shutil.copy(sessions[len(sessions) // 2], lab / "run.csv")
    code = textwrap.dedent("""
        import sys
        import numpy as np
        import bendsense as bs
        import bendsense.config
        from bendsense.session.native import SessionWriter, record_dtype
        lab = sys.argv[1]
        s = bs.read_session_csv(lab + "/run.csv")
        with SessionWriter(lab + "/native", record_dtype(s.n_channels)) as w:
            rec = w.empty(len(s.t_s))
            rec["adc"] = np.round(s.signals)
            rec["pressure_pa"] = np.round(s.pressure_pa)
            w.write(rec)
        bs.config.save_config(bs.load_config(), lab + "/cfg.yaml")
    """)
    r = subprocess.run([PY, "-c", code, str(lab)], env=env, capture_output=True, text=True, timeout=300)
    if r.returncode:
        raise SystemExit(f"lab: native session failed:\n{r.stderr}")
    (lab / "bend.csv").write_text("pressure_kpa,bending_angle_deg\n20,25\n40,55\n60,80\n90,130\n120,176\n",
                                  encoding="utf-8")
    run("load", "run.csv", "--calibration", "cal.yaml", "reconstruct", "estimate", "save", "res")
    for step in LAB_STEPS:
        step(lab, run)
    log(f"lab ready in {time.monotonic() - t0:.0f} s ({len(sessions)} tip-load sessions)")
    return lab


def base_env() -> dict:
    env = dict(os.environ)
    env.setdefault("MPLBACKEND", "Agg")
    env["PYTHONFAULTHANDLER"] = "1"  # a hang's output shows where every thread was (_dump_and_kill)
    env.pop("PYTHONWARNINGS", None)
    return env


# --- running and classifying ------------------------------------------------------------------


def snapshot(root: Path) -> dict:
    out = {}
    for p in sorted(root.rglob("*")):
        try:
            if p.is_symlink():
                out[str(p.relative_to(root))] = "link:" + os.readlink(p)
            elif p.is_file():
                out[str(p.relative_to(root))] = hashlib.sha1(p.read_bytes()).hexdigest()
        except OSError:
            pass
    return out


API_PRELUDE = textwrap.dedent("""
    import sys, json, warnings
    import numpy as np
    import bendsense as bs
    import bendsense.config
    import bendsense.estimation.cramer_rao
    import bendsense.mechanics.actuator
    import bendsense.session
    from bendsense.errors import BendsenseError
    LAB = sys.argv[1]
    def wrong(why):
        print("WRONG-OK: " + why)
    def trusted(est):
        # frames an API user would trust: success and no model misfit
        ok = np.atleast_1d(np.asarray(est.success, dtype=bool))
        p = getattr(est, "p_value", None)
        if p is not None:
            ok = ok & ~(np.atleast_1d(np.asarray(p, dtype=float)) < 1e-3)
        return ok.reshape(-1)
    def finite_ok(est):
        fr = np.asarray(est.force_n, dtype=float).reshape(-1, 2)
        ok = trusted(est)
        if ok.size == fr.shape[0] and ok.any():
            bad = ~np.isfinite(fr[ok]).all(axis=1) | (np.abs(fr[ok]) > 50).any(axis=1)
            if bad.any():
                wrong(f"success with force {fr[ok][bad][0]}")
    try:
""")
API_EPILOGUE = textwrap.dedent("""
    except BendsenseError as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        print("Error: " + msg, file=sys.stderr)
        sys.exit(1)
""")


def unmount_under(work: Path) -> None:
    """Unmount what a case mounted (read-only tmpfs) inside its working directory."""
    try:
        mounts = Path("/proc/mounts").read_text().splitlines()
    except OSError:
        return
    for line in reversed(mounts):
        point = line.split()[1].replace("\\040", " ")
        if point.startswith(str(work) + os.sep):
            subprocess.run(["umount", "-l", point], capture_output=True)


def run_case(c: Case, lab: Path, tmp: Path) -> Outcome:
    work = tmp / re.sub(r"[^\w.-]", "_", c.name)
    work.mkdir(parents=True)
    shutil.copytree(lab, work / "lab", symlinks=True)
    env = base_env()
    env.update(c.env or {})
    for k in c.unset:
        env.pop(k, None)
    try:
        if c.setup:
            c.setup(work)
    except Skip as e:
        unmount_under(work)
        return Outcome(c, "skipped", str(e), 0.0, None)
    except Exception as e:  # a broken case is the campaign's fault: say so
        return Outcome(c, "poor", f"CAMPAIGN SETUP FAILED: {type(e).__name__}: {e}", 0.0, None)
    before = snapshot(work)
    t0 = time.monotonic()
    if c.run is not None:
        try:
            rc, out, hung = c.run(work, env, c.timeout)
        except Skip as e:
            unmount_under(work)
            return Outcome(c, "skipped", str(e), 0.0, None)
    else:
        if c.api is not None:
            body = textwrap.indent(textwrap.dedent(c.api).strip("\n"), "    ")
            argv = [PY, "-c", API_PRELUDE + body + "\n" + API_EPILOGUE, str(work / "lab")]
        else:
            args = c.args(work) if callable(c.args) else c.args
            argv = [str(BIN), *map(str, args)]
        p = subprocess.Popen(argv, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             stdin=subprocess.PIPE if c.stdin is not None else subprocess.DEVNULL,
                             start_new_session=True)
        try:
            o, e = p.communicate(c.stdin, timeout=c.timeout)
            rc, hung = p.returncode, False
        except subprocess.TimeoutExpired:
            o, e = _dump_and_kill(p)
            rc, hung = None, True
        out = (o + e).decode("utf-8", errors="replace")
        _kill(p)  # nothing of the case outlives it
    seconds = time.monotonic() - t0
    unmount_under(work)
    # restore permissions the case removed, so that the snapshot and cleanup can read
    for d in [work, *work.rglob("*")]:
        try:
            if d.is_dir() and not d.is_symlink():
                d.chmod(0o755)
        except OSError:
            pass
    kind, detail = classify(c, work, before, rc, out, hung)
    return Outcome(c, kind, detail, seconds, rc, "" if kind == "handled" else out[-4000:])


def first_line(out: str, pattern=None) -> str:
    lines = [ln for ln in out.splitlines() if ln.strip()]
    if pattern:
        for ln in lines:
            if re.search(pattern, ln):
                return ln.strip()[:300]
    return (lines[-1].strip() if lines else "(no output)")[:300]


def classify(c: Case, work: Path, before: dict, rc, out: str, hung: bool) -> tuple[str, str]:
    after = snapshot(work)
    lost = [p for p, h in before.items() if p not in c.may_change and after.get(p) != h]
    if hung:
        return "hang", f"still running after {c.timeout:.0f} s: " + first_line(out)
    if "Traceback (most recent call last)" in out:
        return "traceback", first_line(out, r"^\w*(Error|Exception|Interrupt)\b|^\w+\.\w+.*Error")
    if lost:
        changed = [p for p in lost if p in after]
        gone = [p for p in lost if p not in after]
        return "data-loss", f"changed {changed[:3]} deleted {gone[:3]}"
    if rc is not None and rc < 0 and rc != -signal.SIGINT:
        return "crash", f"killed by signal {-rc}: " + first_line(out)
    if "WRONG-OK:" in out:
        return "wrong-ok", first_line(out, "WRONG-OK:")
    if rc == 0:
        if c.expect == "error":
            return "wrong-ok", "exit 0 for nonsense input: " + first_line(out)
        why = (c.check or results_ok_sane)(work, out)
        if isinstance(why, tuple):  # (kind, why): e.g. a quiet exit 0 that should have said something
            return why
        if why:
            return "wrong-ok", why
        return "handled", "exit 0: " + first_line(out)
    glued = re.search(r"[^\n\r]((WARNING|Error): .*)", out)
    if glued:  # e.g. a progress bar drawn with \r into a log file, the message at its end
        return "poor", "a message glued to other output on one line: " + glued.group(0)[-160:]
    out = out.replace("\r", "\n")
    errors = [ln for ln in out.splitlines() if ln.startswith("Error:")]
    if c.command == "process" and not errors and rc == 1 and re.search(r"(?m)^error: \d+ of \d+ sessions failed$", out):
        return "handled", "documented: " + first_line(out, r"failed: ")  # each failure in the table, exit 1
    if rc in (129, 130, 131, 143) and not errors:  # SIGHUP, SIGINT, SIGQUIT, SIGTERM: 128 + the signal
        return "handled", f"stopped, exit {rc}"
    if len(errors) != 1:
        return "poor", f"exit {rc} with {len(errors)} 'Error:' lines: " + first_line(out)
    msg = errors[0]
    if REPR.search(msg):
        return "poor", "internal name or repr in: " + msg[:300]
    if len(msg) > 400:
        return "poor", f"a {len(msg)}-character message: " + msg[:200]
    if c.expect == "ok":
        return "poor", "a valid input refused: " + msg[:300]
    return "handled", msg[:300]


# --- output ----------------------------------------------------------------------------------


def table(rows, header):
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = "  ".join(f"{{:<{w}}}" for w in widths)
    print(line.format(*header))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print(line.format(*r))


def report(outcomes: list[Outcome], elapsed: float) -> int:
    by_kind = Counter(o.kind for o in outcomes)
    print()
    table([(k, by_kind.get(k, 0)) for k in KINDS], ("kind", "cases"))
    print()
    per_cmd = defaultdict(Counter)
    for o in outcomes:
        per_cmd[o.case.command][o.kind] += 1
    table([(cmd, sum(cnt.values()), *(cnt.get(k, 0) for k in KINDS)) for cmd, cnt in sorted(per_cmd.items())],
          ("command", "cases", *KINDS))
    for kind in KINDS[1:]:
        bad = [o for o in outcomes if o.kind == kind]
        if not bad:
            continue
        print(f"\n{kind} ({len(bad)}):")
        for o in bad:
            print(f"  {o.case.name} [{o.case.command}]: {o.detail}")
    failing = sum(by_kind.get(k, 0) for k in FAILING)
    print(f"\n{len(outcomes)} cases in {elapsed:.0f} s: " + ", ".join(f"{by_kind.get(k, 0)} {k}" for k in KINDS)
          + (" — FAILED" if failing else " — no traceback, crash, hang, wrong ok or data loss"))
    return 1 if failing else 0


def _signals_as_a_terminal_gives_them() -> None:
    """The stop signals at their defaults for every command the campaign starts.

    A shell starts a background job with SIGINT and SIGQUIT ignored (and nohup SIGHUP), an
    ignored signal is inherited ignored, and every Ctrl-C case would then test a command
    that cannot receive one.
    """
    for signum in (signal.SIGINT, signal.SIGQUIT, signal.SIGHUP):
        if signal.getsignal(signum) == signal.SIG_IGN:
            signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL)


def main(argv=None) -> int:
    _signals_as_a_terminal_gives_them()
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", metavar="PATTERN", action="append",
                    help="run the cases whose name or command matches (substring or glob; repeatable)")
    ap.add_argument("--jobs", type=int, default=1, help="cases run in parallel (default 1)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--keep", action="store_true", help="keep the working directories")
    ap.add_argument("--self-check", action="store_true", help="run three quick cases")
    ap.add_argument("--json", metavar="FILE", help="also write the outcomes as JSON")
    opts = ap.parse_args(argv)
    if not BIN.exists():
        print(f"Error: no bendsense next to {sys.executable}", file=sys.stderr)
        return 2
    names = [c.name for c in CASES]
    dup = [n for n, k in Counter(names).items() if k > 1]
    if dup:
        print(f"Error: duplicate case names {dup}", file=sys.stderr)
        return 2
    cases = CASES
    if opts.self_check:
        cases = [c for c in CASES if c.name in SELF_CHECK]
    elif opts.only:
        def hit(c):
            return any(p in c.name or p == c.command or fnmatch.fnmatch(c.name, p) for p in opts.only)
        cases = [c for c in CASES if hit(c)]
    if opts.list:
        for c in cases:
            print(f"{c.command:12} {c.name}")
        print(f"{len(cases)} cases, {len({c.command for c in cases})} commands")
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="bendsense-campaign-"))
    t0 = time.monotonic()
    try:
        lab = make_lab(tmp / "shared")
        lab_before = snapshot(lab)
        outcomes = []
        with concurrent.futures.ThreadPoolExecutor(max(1, opts.jobs)) as pool:
            futures = {pool.submit(run_case, c, lab, tmp / "cases"): c for c in cases}
            for f in concurrent.futures.as_completed(futures):
                o = f.result()
                outcomes.append(o)
                print(f"[{len(outcomes):3}/{len(cases)}] {o.kind:9} {o.seconds:5.1f} s  {o.case.name}"
                      + ("" if o.kind == "handled" else f"  -- {o.detail[:160]}"), flush=True)
        if snapshot(lab) != lab_before:
            print("data-loss: the shared lab changed during the campaign", flush=True)
            outcomes.append(Outcome(Case("shared-lab", "all"), "data-loss", "the shared lab changed", 0, None))
        order = {c.name: i for i, c in enumerate(CASES)}
        outcomes.sort(key=lambda o: order.get(o.case.name, -1))
        if opts.json:
            Path(opts.json).write_text(json.dumps([
                {"name": o.case.name, "command": o.case.command, "kind": o.kind, "detail": o.detail,
                 "seconds": round(o.seconds, 2), "returncode": o.returncode, "output": o.output} for o in outcomes],
                indent=1))
        return report(outcomes, time.monotonic() - t0)
    finally:
        if opts.keep:
            print(f"kept {tmp}")
        else:
            for d in [tmp, *tmp.rglob("*")]:
                try:
                    if d.is_dir() and not d.is_symlink():
                        d.chmod(0o755)
                except OSError:
                    pass
            shutil.rmtree(tmp, ignore_errors=True)


# =========================================================================================
# The cases. None repeats the kinds of issue 21 or the corpus under tests/data/invalid.
# =========================================================================================

SELF_CHECK = ("load-one-frame", "api-load-config-dir", "chain-no-steps-but-load")

# --- load / chain: odd but valid-looking session CSVs ----------------------------------------

case("load-one-frame", "load", chain("one.csv"), setup=edit_csv("one.csv", lambda h, r: [h, r[0]]))
case("load-crlf", "load", chain("crlf.csv"), expect="ok",
     setup=edit_csv("crlf.csv", lambda h, r: [ln + "\r" for ln in [h, *r]]))
case("load-bom-csv", "load", chain("bom.csv"), expect="ok",
     setup=lambda w: (w / "bom.csv").write_bytes(b"\xef\xbb\xbf" + (w / "lab/run.csv").read_bytes()))
case("load-trailing-blank-lines", "load", chain("blank.csv"), expect="ok",
     setup=edit_csv("blank.csv", lambda h, r: [h, *r, "", "", ""]))
case("load-blank-line-in-middle", "load", chain("mid.csv"),
     setup=edit_csv("mid.csv", lambda h, r: [h, r[0], "", *r[1:]]))
case("load-spaces-around-cells", "load", chain("sp.csv"),
     setup=edit_csv("sp.csv", lambda h, r: [", ".join(h.split(",")), *(", ".join(x.split(",")) for x in r)]))
case("load-quoted-header", "load", chain("q.csv"),
     setup=edit_csv("q.csv", lambda h, r: [",".join(f'"{c}"' for c in h.split(",")), *r]))
case("load-header-uppercase", "load", chain("up.csv"),
     setup=edit_csv("up.csv", lambda h, r: [h.upper(), *r]))
case("load-columns-reordered", "load", chain("ro.csv"), expect="ok",
     setup=edit_csv("ro.csv", lambda h, r: [",".join(reversed(h.split(","))),
                                            *(",".join(reversed(x.split(","))) for x in r)]))
case("load-many-extra-columns", "load", chain("wide.csv"), timeout=90,
     setup=edit_csv("wide.csv", lambda h, r: [h + "".join(f",x{i}" for i in range(20000)),
                                              *(x + ",0" * 20000 for x in r)]))
case("load-100k-frames", "load", chain("big.csv", tail=["--calibration", "lab/cal.yaml", "reconstruct", "save", "out"]),
     timeout=120, setup=edit_csv("big.csv", lambda h, r: [h, *(
         ",".join([f"{k * 1e-3:.3f}", *x.split(",")[1:]]) for k, x in enumerate((r * 100000)[:100000]))]))
case("load-time-1e308", "load", chain("t308.csv"), setup=edit_column("t308.csv", "t_s", "1e308", row=0))
case("load-time-negative-zero", "load", chain("tneg0.csv"),
     setup=edit_column("tneg0.csv", "t_s", "-0", row=0))
case("load-time-negative", "load", chain("tneg.csv"),
     setup=edit_csv("tneg.csv", lambda h, r: [h, *(",".join([str(-100 + k), *x.split(",")[1:]])
                                                   for k, x in enumerate(r))]))
case("load-signal-1e308", "load", chain("s308.csv"), check=no_ok_rows,
     setup=edit_column("s308.csv", "ch3", "1e308"))
case("load-signal-negative-zero", "load", chain("sneg0.csv"), setup=edit_column("sneg0.csv", "ch3", "-0.0"))
case("load-signal-negative", "load", chain("sneg.csv"), check=no_ok_rows,
     setup=edit_column("sneg.csv", "ch5", "-40000"))
case("load-signal-hex", "load", chain("hex.csv"), expect="error", setup=edit_column("hex.csv", "ch2", "0x7ff"))
case("load-signal-underscore", "load", chain("us.csv"), setup=edit_column("us.csv", "ch2", "2_000"))
case("load-signal-fullwidth-digits", "load", chain("fw.csv"),
     setup=edit_column("fw.csv", "ch2", "２０００"))
case("load-signal-comma-decimal", "load", chain("cd.csv"), expect="error",
     setup=edit_csv("cd.csv", lambda h, r: [h, *(x.replace(".", ",", 1) for x in r)]))
case("load-pressure-1e308", "load", chain("p308.csv"), check=no_ok_rows,
     setup=edit_column("p308.csv", "pressure_pa", "1e308"))
case("load-pressure-negative-zero", "load", chain("pneg0.csv"),
     setup=edit_column("pneg0.csv", "pressure_pa", "-0"))
case("load-pressure-below-vacuum", "load", chain("vac.csv"), check=no_ok_rows,
     setup=edit_column("vac.csv", "pressure_pa", "-200000"))
case("load-pressure-subnormal", "load", chain("psub.csv"), setup=edit_column("psub.csv", "pressure_pa", "5e-324"))
case("load-pressure-empty-cells", "load", chain("pe.csv"), setup=edit_column("pe.csv", "pressure_pa", ""))
case("load-pressure-empty-one-cell", "load", chain("pe1.csv"), setup=edit_column("pe1.csv", "pressure_pa", "", row=0))
case("load-only-ch1", "load", chain("ch1.csv"),
     setup=edit_csv("ch1.csv", lambda h, r: [",".join(h.split(",")[:3]), *(",".join(x.split(",")[:3]) for x in r)]))
case("load-64-channels", "load", chain("ch64.csv"), expect="error",
     setup=edit_csv("ch64.csv", lambda h, r: [h + "".join(f",ch{i}" for i in range(17, 65)),
                                              *(x + ",2000" * 48 for x in r)]))
case("load-filename-unicode-space", "load", chain("ses sión ✓.csv"), expect="ok",
     setup=lambda w: shutil.copy(w / "lab/run.csv", w / "ses sión ✓.csv"))
case("load-filename-newline", "load", chain("a\nb.csv"), expect="ok",
     setup=lambda w: shutil.copy(w / "lab/run.csv", w / "a\nb.csv"))
case("load-filename-dash", "load", ["load", "--", "-run.csv", *CHAIN],
     setup=lambda w: shutil.copy(w / "lab/run.csv", w / "-run.csv"))
case("load-filename-dash-dotslash", "load", chain("./-run.csv"), expect="ok",
     setup=lambda w: shutil.copy(w / "lab/run.csv", w / "-run.csv"))
case("load-relative-dotdot", "load", lambda w: ["load", "../" + w.name + "/lab/run.csv", *CHAIN], expect="ok")
case("load-directory-not-session", "load", chain("lab/calsim"), expect="error")
case("load-empty-directory", "load", chain("emptydir"), expect="error", setup=lambda w: (w / "emptydir").mkdir())
case("load-symlink-loop", "load", chain("loop.csv"), expect="error",
     setup=lambda w: (os.symlink("loop2.csv", w / "loop.csv"), os.symlink("loop.csv", w / "loop2.csv")))
case("load-unreadable-file", "load", chain("secret.csv"), expect="error",
     setup=lambda w: (shutil.copy(w / "lab/run.csv", w / "secret.csv"), unreadable(w / "secret.csv")))
case("load-session-empty-name", "load", chain(""), expect="error")
case("load-csv-extension-on-yaml", "load", chain("lab/cal.yaml"), expect="error")
case("load-calibration-is-session", "load", ["load", "lab/run.csv", "--calibration", "lab/run.csv",
                                             "reconstruct", "save", "out"], expect="error")
case("load-config-is-calibration", "load", ["load", "lab/run.csv", "--config", "lab/cal.yaml", *CHAIN],
     expect="error")
case("load-option-repeated", "load", ["load", "lab/run.csv", "--pressure-kpa", "20", "--pressure-kpa", "60", *CHAIN])
case("load-pressure-kpa-1e308", "load", chain("nop.csv", "--pressure-kpa", "1e308"), check=no_ok_rows,
     setup=without_pressure("nop.csv"))
case("load-pressure-kpa-neg-zero", "load", chain("nop.csv", "--pressure-kpa", "-0"),
     setup=without_pressure("nop.csv"))
case("load-pressure-kpa-tiny", "load", chain("nop.csv", "--pressure-kpa", "1e-300"),
     setup=without_pressure("nop.csv"))
case("load-pressure-kpa-empty", "load", chain("lab/run.csv", "--pressure-kpa", ""), expect="error")
case("chain-no-steps-but-load", "load", ["load", "lab/run.csv"])
case("chain-save-twice-same-dir", "save", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml",
                                           "reconstruct", "save", "out", "save", "out"], expect="error")
case("chain-reconstruct-twice", "reconstruct", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml",
                                                "reconstruct", "reconstruct", "--points", "3", "save", "out"])
case("reconstruct-points-huge", "reconstruct", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml",
                                               "reconstruct", "--points", "10000", "save", "out"], timeout=90)
case("reconstruct-points-2", "reconstruct", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml",
                                            "reconstruct", "--points", "2", "estimate", "save", "out"])
case("estimate-twice", "estimate", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml", "reconstruct",
                                    "estimate", "estimate", "--constraint", "vertical", "save", "out"])
case("estimate-direction-without-direction", "estimate",
     chain("lab/run.csv", tail=["--calibration", "lab/cal.yaml", "reconstruct", "estimate",
                                "--constraint", "direction", "save", "out"]))
case("estimate-follower-positions-paper", "estimate",
     chain("lab/run.csv", tail=["--calibration", "lab/cal.yaml", "reconstruct", "estimate", "--constraint",
                                "follower", "--method", "paper", "--objective", "positions", "save", "out"]),
     timeout=120)
case("estimate-wrong-constraint-horizontal", "estimate",
     chain("lab/run.csv", tail=["--calibration", "lab/cal.yaml", "reconstruct", "estimate", "--constraint",
                                "horizontal", "save", "out"]))
case("estimate-wrong-constraint-normal-push-only", "estimate",
     chain("lab/run.csv", tail=["--calibration", "lab/cal.yaml", "reconstruct", "estimate", "--constraint",
                                "normal", "--push-only", "save", "out"]))
case("estimate-calibration-from-other-sensor", "estimate", chain("lab/run.csv"), check=no_ok_rows,
     setup=edit_yaml("lab/cal.yaml", "lab/cal.yaml",
                     lambda d: d.update(offset=[x + 3000 for x in d["offset"]])), may_change=("lab/cal.yaml",))
case("load-config-1-segment", "load", chain("lab/run.csv", "--config", "one.yaml"), expect="error",
     setup=edit_yaml("one.yaml", "lab/cfg.yaml", lambda d: d["sensor"].update(n_segments=1, segment_lengths_m=[0.13])))
case("estimate-flat-session", "estimate", chain("lab/calsim/flat.csv", "--pressure-kpa", "0"))

# --- native sessions ---------------------------------------------------------------------------


def native_copy(name, edit=None):
    def setup(work):
        shutil.copytree(work / "lab/native", work / name)
        if edit:
            edit(work / name)
    return setup


def truncate_frames(keep_fraction=None, extra=0):
    def edit(d):
        import yaml

        meta = yaml.safe_load((d / "meta.yaml").read_text())
        size = (d / "frames.bin").stat().st_size
        n = meta.get("n_records") or 0
        rec = size // n if n else size
        data = (d / "frames.bin").read_bytes()
        (d / "frames.bin").write_bytes(data[: rec * int(keep_fraction) + extra])
    return edit


def meta_set(key, value):
    def edit(d):
        import yaml

        meta = yaml.safe_load((d / "meta.yaml").read_text())
        meta[key] = value
        (d / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return edit


case("native-truncated-at-record-1", "load", chain("n1"), setup=native_copy("n1", truncate_frames(1)))
case("native-truncated-zero-records", "load", chain("n0"), expect="error", setup=native_copy("n0", truncate_frames(0)))
case("native-truncated-mid-first-record", "load", chain("nh"), expect="error",
     setup=native_copy("nh", truncate_frames(0, extra=7)))
case("native-truncated-last-record-1-byte", "load", chain("nt1"),
     setup=native_copy("nt1", lambda d: (d / "frames.bin").write_bytes((d / "frames.bin").read_bytes()[:-1])))
case("native-frames-bin-directory", "load", chain("nd"), expect="error",
     setup=native_copy("nd", lambda d: ((d / "frames.bin").unlink(), (d / "frames.bin").mkdir())))
case("native-meta-directory", "load", chain("nm"), expect="error",
     setup=native_copy("nm", lambda d: ((d / "meta.yaml").unlink(), (d / "meta.yaml").mkdir())))
case("native-meta-bom", "load", chain("nb"), expect="ok",
     setup=native_copy("nb", lambda d: (d / "meta.yaml").write_bytes(
         b"\xef\xbb\xbf" + (d / "meta.yaml").read_bytes())))
case("native-meta-crlf", "load", chain("nc"), expect="ok",
     setup=native_copy("nc", lambda d: (d / "meta.yaml").write_bytes(
         (d / "meta.yaml").read_bytes().replace(b"\n", b"\r\n"))))
case("native-meta-start-time-garbage", "load", chain("ns"), setup=native_copy("ns", meta_set("start_time", [1, 2])))
case("native-meta-config-snapshot-garbage", "load", chain("ncf"),
     setup=native_copy("ncf", meta_set("config", "not a config")))
case("native-frames-symlink-to-dev-null", "load", chain("nn"), expect="error",
     setup=native_copy("nn", lambda d: ((d / "frames.bin").unlink(), os.symlink("/dev/null", d / "frames.bin"))))
case("native-events-log-binary", "load", chain("ne"),
     setup=native_copy("ne", lambda d: (d / "events.log").write_bytes(bytes(range(256)) * 4)))
case("native-export-roundtrip", "export", ["load", "lab/native", "export", "back.csv"], expect="ok",
     check=wrote("back.csv"))
case("native-results-inside-session", "save", ["load", "lab/native", "--calibration", "lab/cal.yaml",
                                               "reconstruct", "save", "lab/native/res"])

# --- save / export / plot / mcap outputs ---------------------------------------------------------

case("save-into-readonly-dir", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "ro/out"]), expect="error",
     setup=lambda w: (readonly_dir(w / "ro"), None), timeout=240)
case("save-target-is-file", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "afile"]), expect="error",
     setup=text("afile", "user data\n"))
case("save-into-calibration-path", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "lab/cal.yaml"]), expect="error")
case("save-name-dash", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "-out"]))
case("save-empty-name", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], ""]), expect="error")
case("save-trailing-slash-file", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "afile/"]), expect="error",
     setup=text("afile", "user data\n"))
case("save-overwrite-user-dir", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "userdir", "--overwrite"]),
     expect="error", setup=text("userdir/notes.txt", "mine\n"))
case("save-existing-results-no-overwrite", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "lab/res"]),
     expect="error")
case("save-existing-results-overwrite", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "lab/res", "--overwrite"]),
     may_change=("lab/res/results.csv", "lab/res/shape.npz", "lab/res/.bendsense-output",
                 "lab/res/.bendsense-output.json"))
case("save-path-too-deep-but-legal", "save", chain("lab/run.csv", tail=[*CHAIN[:-1], "/".join(["d"] * 60)]))
case("export-same-as-input", "export", ["load", "lab/run.csv", "export", "lab/run.csv", "--overwrite"],
     expect="error")
case("export-into-dir", "export", ["load", "lab/run.csv", "export", "lab"], expect="error")
case("export-no-suffix", "export", ["load", "lab/run.csv", "export", "out"])
case("export-dev-null", "export", ["load", "lab/run.csv", "export", "/dev/null"])
case("export-twice-same-file", "export", ["load", "lab/run.csv", "export", "a.csv", "export", "a.csv"],
     expect="error")


def readonly_cwd(args):
    def run(work, env, timeout):
        d = work / "rocwd"
        readonly_dir(d)
        try:
            p = subprocess.run([str(BIN), *args], cwd=d, env=env, capture_output=True, timeout=timeout)
            return p.returncode, (p.stdout + p.stderr).decode(errors="replace"), False
        except subprocess.TimeoutExpired as e:
            return None, str(e), True
        finally:
            if os.geteuid() != 0:
                d.chmod(0o755)
    return run


case("export-readonly-cwd", "export", expect="error",
     run=readonly_cwd(["load", "../lab/run.csv", "export", "a.csv"]))
case("plot-readonly-cwd-mplconfig", "plot", run=readonly_cwd(["plot", "../lab/res", "-o", "../f.png"]),
     unset=("MPLCONFIGDIR",), env={"HOME": "/nonexistent-home"})
case("plot-results-dir-empty", "plot", ["plot", "empty", "-o", "f.png"], expect="error",
     setup=lambda w: (w / "empty").mkdir())
case("plot-results-one-row", "plot", ["plot", "one", "-o", "f.png"],
     setup=steps(lambda w: shutil.copytree(w / "lab/res", w / "one"),
                 lambda w: (w / "one/results.csv").write_text(
                     "\n".join((w / "one/results.csv").read_text().splitlines()[:2]) + "\n")))
case("plot-output-is-results-csv", "plot", ["plot", "lab/res", "-o", "lab/res/results.csv", "--overwrite"],
     expect="error")
case("plot-output-is-input-dir", "plot", ["plot", "lab/res", "-o", "lab/res"], expect="error")
case("plot-dpi-max-pdf", "plot", ["plot", "lab/res", "-o", "f.pdf", "--dpi", "1200"], check=wrote("f.pdf"))
case("plot-option-after-target-repeated", "plot", ["plot", "lab/res", "-o", "a.png", "-o", "b.png"])
case("plot-results-nan-forces", "plot", ["plot", "nanres", "-o", "f.png"],
     setup=steps(lambda w: shutil.copytree(w / "lab/res", w / "nanres"),
                 lambda w: (w / "nanres/results.csv").write_text(
                     re.sub(r"(?m)^([^#\n][^,\n]*),", r"\1,", (w / "nanres/results.csv").read_text())
                     .replace(",ok", ",not_converged"))))
case("mcap-without-estimate", "mcap", ["load", "lab/run.csv", "--calibration", "lab/cal.yaml", "reconstruct",
                                       "mcap", "a.mcap"])
case("mcap-without-reconstruct", "mcap", ["load", "lab/run.csv", "mcap", "a.mcap"])
case("mcap-into-missing-dir", "mcap", [*chain("lab/run.csv")[:-2], "mcap", "no/such/dir/a.mcap"])
case("mcap-over-session", "mcap", [*chain("lab/run.csv")[:-2], "mcap", "lab/run.csv", "--overwrite"],
     expect="error")
case("mcap-wrong-suffix", "mcap", [*chain("lab/run.csv")[:-2], "mcap", "a.csv"])

# --- calibrate -----------------------------------------------------------------------------------


def manifest(name, fn):
    return edit_yaml(f"lab/calsim/{name}", "lab/calsim/manifest.yaml", fn)


case("calibrate-duplicate-radii", "calibrate", ["calibrate", "lab/calsim/dup.yaml", "-o", "c.yaml"],
     setup=manifest("dup.yaml", lambda d: d["strips"].__setitem__(1, dict(d["strips"][0]))))
case("calibrate-two-strips", "calibrate", ["calibrate", "lab/calsim/two.yaml", "-o", "c.yaml", "--degree", "3"],
     setup=manifest("two.yaml", lambda d: d.update(strips=d["strips"][:2])))
case("calibrate-one-strip-auto", "calibrate", ["calibrate", "lab/calsim/one.yaml", "-o", "c.yaml", "--degree", "auto"],
     setup=manifest("one.yaml", lambda d: d.update(strips=d["strips"][:1])))
case("calibrate-strip-is-flat-recording", "calibrate", ["calibrate", "lab/calsim/ff.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("ff.yaml", lambda d: [s.update(recording="flat.csv") for s in d["strips"][:3]]))
case("calibrate-manifest-lists-itself", "calibrate", ["calibrate", "lab/calsim/self.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("self.yaml", lambda d: d.update(flat="self.yaml")))
case("calibrate-recording-absolute-path", "calibrate", ["calibrate", "lab/calsim/abs.yaml", "-o", "c.yaml"],
     setup=lambda w: edit_yaml("lab/calsim/abs.yaml", "lab/calsim/manifest.yaml",
                               lambda d: d.update(flat=str(w / "lab/calsim/flat.csv")))(w))
case("calibrate-recording-is-directory", "calibrate", ["calibrate", "lab/calsim/dir.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("dir.yaml", lambda d: d["strips"][0].update(recording=".")))
case("calibrate-radius-1e308", "calibrate", ["calibrate", "lab/calsim/huge.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("huge.yaml", lambda d: d["strips"][0].update(radius_m=1e308)))
case("calibrate-radius-tiny", "calibrate", ["calibrate", "lab/calsim/tiny.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("tiny.yaml", lambda d: d["strips"][0].update(radius_m=1e-300)))
case("calibrate-radius-neg-zero", "calibrate", ["calibrate", "lab/calsim/z.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("z.yaml", lambda d: d["strips"][0].update(radius_m=-0.0)))
case("calibrate-manifest-bom", "calibrate", ["calibrate", "lab/calsim/bom.yaml", "-o", "c.yaml"], expect="ok",
     setup=lambda w: (w / "lab/calsim/bom.yaml").write_bytes(
         b"\xef\xbb\xbf" + (w / "lab/calsim/manifest.yaml").read_bytes()))
case("calibrate-manifest-tabs", "calibrate", ["calibrate", "lab/calsim/tab.yaml", "-o", "c.yaml"], expect="error",
     setup=lambda w: (w / "lab/calsim/tab.yaml").write_text(
         (w / "lab/calsim/manifest.yaml").read_text().replace("  ", "\t")))
case("calibrate-manifest-empty-strips-entry", "calibrate", ["calibrate", "lab/calsim/ne.yaml", "-o", "c.yaml"],
     expect="error", setup=manifest("ne.yaml", lambda d: d["strips"].append(None)))
case("calibrate-output-is-manifest", "calibrate",
     ["calibrate", "lab/calsim/manifest.yaml", "-o", "lab/calsim/manifest.yaml", "--overwrite"], expect="error")
case("calibrate-output-is-recording", "calibrate",
     ["calibrate", "lab/calsim/manifest.yaml", "-o", "lab/calsim/flat.csv", "--overwrite"], expect="error")
case("calibrate-output-dir", "calibrate", ["calibrate", "lab/calsim/manifest.yaml", "-o", "lab"], expect="error")
case("calibrate-plot-same-as-output", "calibrate",
     ["calibrate", "lab/calsim/manifest.yaml", "-o", "c.svg", "--plot", "c.svg"], expect="error")
case("calibrate-config-1-segment", "calibrate", ["calibrate", "lab/calsim/manifest.yaml", "-o", "c.yaml",
                                                 "--config", "one.yaml"], expect="error",
     setup=edit_yaml("one.yaml", "lab/cfg.yaml", lambda d: d["sensor"].update(
         n_segments=1, segment_lengths_m=[0.13]) if "n_segments" in d["sensor"] else d["sensor"].update(
         segment_lengths_m=[0.13])))
case("calibrate-degree-repeated", "calibrate", ["calibrate", "lab/calsim/manifest.yaml", "-o", "c.yaml",
                                                "--degree", "1", "--degree", "5"])
case("calibrate-sleeve-both", "calibrate", ["calibrate", "lab/calsim/manifest.yaml", "-o", "c.yaml",
                                            "--sleeve", "--no-sleeve"])

# --- identify ---------------------------------------------------------------------------------------

case("identify-bend-crlf-bom", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"], expect="ok",
     setup=lambda w: (w / "b.csv").write_bytes(
         b"\xef\xbb\xbf" + (w / "lab/bend.csv").read_bytes().replace(b"\n", b"\r\n")))
case("identify-bend-one-row", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"], expect="error",
     setup=text("b.csv", "pressure_kpa,bending_angle_deg\n60,80\n"))
case("identify-bend-all-same-pressure", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"],
     check=lambda w, o: None if "not identifiable" in o else "a fit from one pressure level, without a warning",
     setup=text("b.csv", "pressure_kpa,bending_angle_deg\n60,80\n60,81\n60,79\n60,80\n"))
case("identify-bend-negative-angles", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"],
     expect="error", setup=text("b.csv", "pressure_kpa,bending_angle_deg\n20,-25\n40,-55\n60,-80\n90,-130\n"))
case("identify-bend-angle-1e308", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"],
     expect="error", setup=text("b.csv", "pressure_kpa,bending_angle_deg\n20,25\n40,1e308\n60,80\n90,130\n"))
case("identify-bend-radians-in-deg-column", "identify", ["identify", "free-bending", "b.csv", "-o", "c.yaml"],
     expect="error",
     setup=text("b.csv", "pressure_kpa,bending_angle_deg\n20,0.44\n40,0.96\n60,1.4\n90,2.27\n120,3.07\n"))
case("identify-fix-all", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml", "--fix", "mu",
                                      "--fix", "mu_s", "--fix", "prebend"])
case("identify-fix-same-twice", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml",
                                             "--fix", "mu=1e5", "--fix", "mu=2e5"])
case("identify-fix-unknown", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml",
                                          "--fix", "youngs_modulus=3"], expect="error")
case("identify-fix-stiffness-param-in-bending", "identify",
     ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml", "--fix", "ei0=0.0025"], expect="error")
case("identify-fix-1e308", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml",
                                        "--fix", "mu=1e308"], expect="error")
case("identify-fix-empty-value", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "c.yaml",
                                              "--fix", "mu="])
case("identify-output-is-input", "identify", ["identify", "free-bending", "lab/bend.csv", "-o", "lab/bend.csv",
                                              "--overwrite"], expect="error")
case("identify-output-is-config", "identify", ["identify", "free-bending", "lab/bend.csv", "--config", "lab/cfg.yaml",
                                               "-o", "lab/cfg.yaml", "--overwrite"], expect="error")
case("identify-stiffness-on-tip-loads", "identify", ["identify", "stiffness", "lab/run.csv", "-o", "c.yaml"])
case("identify-stiffness-tolerance-negative", "identify", ["identify", "stiffness", "lab/run.csv", "-o", "c.yaml",
                                                           "--pressure-tolerance-kpa", "-1"], expect="error")
case("identify-stiffness-tolerance-inf", "identify", ["identify", "stiffness", "lab/run.csv", "-o", "c.yaml",
                                                      "--pressure-tolerance-kpa", "inf"], expect="error")
case("identify-stiffness-zero-forces", "identify", ["identify", "stiffness", "z.csv", "-o", "c.yaml"], expect="error",
     setup=text("z.csv", "pressure_kpa,fx_n,fy_n,tip_x_m,tip_y_m\n20,0,0,0.01,0.12\n40,0,0,0.03,0.11\n"
                         "60,0,0,0.05,0.10\n"))
case("identify-bend-directory", "identify", ["identify", "free-bending", "lab", "-o", "c.yaml"], expect="error")
case("identify-kind-case", "identify", ["identify", "Free-Bending", "lab/bend.csv", "-o", "c.yaml"], expect="error")

# --- simulate ---------------------------------------------------------------------------------------

case("simulate-ei-error-minus-one", "simulate", ["simulate", "validation", "-o", "s", "--ei-error", "-1"],
     expect="error")
case("simulate-ei-error-1e308", "simulate", ["simulate", "validation", "-o", "s", "--ei-error", "1e308"],
     expect="error")
case("simulate-k0-error-inf", "simulate", ["simulate", "validation", "-o", "s", "--k0-error", "inf"], expect="error")
case("simulate-base-rotation-nan", "simulate", ["simulate", "validation", "-o", "s", "--base-rotation", "nan"],
     expect="error")
case("simulate-noise-negative-zero", "simulate", ["simulate", "validation", "-o", "s", "--noise-counts", "-0",
                                                  "--frames", "1"])
case("simulate-noise-1e308", "simulate", ["simulate", "validation", "-o", "s", "--noise-counts", "1e308"],
     expect="error")
case("simulate-hysteresis-huge", "simulate", ["simulate", "contact", "-o", "s", "--hysteresis-kpa", "1e300"],
     expect="error")
case("simulate-output-is-file", "simulate", ["simulate", "validation", "-o", "lab/run.csv", "--overwrite"],
     expect="error")
case("simulate-output-inside-lab-session", "simulate", ["simulate", "validation", "-o", "lab/native/sim",
                                                        "--frames", "1"])
case("simulate-config-64-segments", "simulate", ["simulate", "calibration", "-o", "s", "--config", "c64.yaml",
                                                 "--frames", "1"], timeout=90,
     setup=edit_yaml("c64.yaml", "lab/cfg.yaml",
                     lambda d: d["sensor"].update(n_segments=64, segment_lengths_m=[0.13 / 64] * 64)))
case("simulate-seed-max", "simulate", ["simulate", "validation", "-o", "s", "--seed", "4294967295", "--frames", "1"],
     expect="ok")
case("simulate-scenario-case", "simulate", ["simulate", "Validation", "-o", "s"], expect="error")
case("simulate-overwrite-user-dir", "simulate", ["simulate", "validation", "-o", "ud", "--overwrite",
                                                 "--frames", "1"], expect="error", setup=text("ud/mine.txt", "x"))

# --- sim-device ------------------------------------------------------------------------------------

case("sim-device-channels-zero", "sim-device", ["sim-device", "--channels", "0", "--seconds", "1"], expect="error")
case("sim-device-channels-65", "sim-device", ["sim-device", "--channels", "65", "--seconds", "1"], expect="error")
case("sim-device-channels-negative", "sim-device", ["sim-device", "--channels", "-3", "--seconds", "1"],
     expect="error")
case("sim-device-adc-bits-zero", "sim-device", ["sim-device", "--adc-bits", "0", "--seconds", "1"], expect="error")
case("sim-device-adc-bits-32", "sim-device", ["sim-device", "--adc-bits", "32", "--seconds", "1"], expect="error")
case("sim-device-corrupt-negative", "sim-device", ["sim-device", "--corrupt", "-0.1", "--seconds", "1"],
     expect="error")
case("sim-device-truncate-inf", "sim-device", ["sim-device", "--truncate", "inf", "--seconds", "1"], expect="error")
case("sim-device-speed-zero", "sim-device", ["sim-device", "--replay", "lab/native", "--speed", "0",
                                             "--seconds", "1"], expect="error")
case("sim-device-speed-nan", "sim-device", ["sim-device", "--replay", "lab/native", "--speed", "nan",
                                            "--seconds", "1"], expect="error")
case("sim-device-replay-missing", "sim-device", ["sim-device", "--replay", "nothere", "--seconds", "1"],
     expect="error")
case("sim-device-replay-calibration", "sim-device", ["sim-device", "--replay", "lab/cal.yaml", "--seconds", "1"],
     expect="error")
case("sim-device-replay-one-frame", "sim-device", ["sim-device", "--replay", "one.csv", "--seconds", "1"],
     setup=edit_csv("one.csv", lambda h, r: [h, r[0]]))
case("sim-device-seconds-tiny", "sim-device", ["sim-device", "--seconds", "1e-300"])
case("sim-device-rate-tiny", "sim-device", ["sim-device", "--rate", "1e-300", "--seconds", "1"])
case("sim-device-loop-without-replay", "sim-device", ["sim-device", "--loop", "--seconds", "1"])
case("sim-device-sigint-while-client-reads", "sim-device",
     run=with_board(lambda port: ["record", port, "-o", "rec", "--seconds", "5", "--quiet-status"],
                    during=sigint_after(2.5, "board"), expect_board=True))



def kill_client_after(seconds):
    def during(client, board, work):
        time.sleep(seconds)
        _kill(client)
        time.sleep(1.0)  # the board sees its client gone while it streams
    return during


case("sim-device-client-killed-midstream", "sim-device",
     run=with_board(lambda port: ["record", port, "-o", "rec", "--seconds", "20", "--quiet-status"],
                    during=kill_client_after(3), expect_board=True), timeout=30)

# --- record -----------------------------------------------------------------------------------------

case("record-board-killed-midway", "record",
     run=with_board(lambda port: ["record", port, "-o", "rec", "--seconds", "20", "--quiet-status"],
                    during=kill_board_after(3)), timeout=30,
     check=lambda w, o: None if (w / "rec/frames.bin").exists() else "exit 0 but no frames.bin")
def says_nothing_arrived(work, output):
    if re.search(r"\b0 frames written", output) and "WARNING" not in output:
        return "poor", "exit 0 and no warning after a recording without a single frame: " + first_line(output)
    return None


case("record-text-only-board", "record", check=says_nothing_arrived,
     run=text_board(lambda port: ["record", port, "-o", "rec", "--seconds", "3", "--quiet-status"]))
case("record-text-only-board-no-handshake", "record", check=says_nothing_arrived,
     run=text_board(lambda port: ["record", port, "-o", "rec", "--seconds", "3", "--no-handshake", "--quiet-status"],
                    hello=False))
case("record-output-inside-lab-native", "record",
     run=with_board(lambda port: ["record", port, "-o", "lab/native/rec", "--seconds", "2", "--quiet-status"]))
case("record-output-over-native-overwrite", "record",
     run=with_board(lambda port: ["record", port, "-o", "lab/native", "--seconds", "2", "--overwrite",
                                  "--quiet-status"]),
     may_change=("lab/native/meta.yaml", "lab/native/frames.bin", "lab/native/events.log",
                 "lab/native/.bendsense-output", "lab/native/.bendsense-output.json"))


def two_records(work, env, timeout):
    board, port = _board(work, env, "--rate", "100", "--seconds", "30")
    if not port.startswith("/"):
        return None, "board did not start", False
    try:
        a = _popen([str(BIN), "record", port, "-o", "rec", "--seconds", "3", "--quiet-status"], work, env)
        time.sleep(0.5)
        b = _popen([str(BIN), "record", port, "-o", "rec", "--seconds", "3", "--quiet-status"], work, env)
        ra, oa, ha = _finish(a, timeout)
        rb, ob, hb = _finish(b, timeout)
    finally:
        board.send_signal(signal.SIGINT)
        _finish(board, 10)
    if ha or hb:
        return None, oa + ob, True
    if ra == 0 and rb == 0:
        return 0, "WRONG-OK: both recordings to one directory exited 0\n" + oa + ob, False
    return (rb if ra == 0 else ra), (ob if ra == 0 else oa), False


case("record-two-at-once", "record", run=two_records, timeout=30)
case("record-baud-huge", "record", ["record", "loop://", "-o", "rec", "--baud", "99999999999999", "--seconds", "1"],
     expect="error")
case("record-baud-negative", "record", ["record", "loop://", "-o", "rec", "--baud", "-9600", "--seconds", "1"],
     expect="error")
case("record-channels-zero-line", "record", ["record", "loop://", "-o", "rec", "--dialect", "line",
                                             "--channels", "0", "--seconds", "1"], expect="error")
case("record-columns-duplicate", "record", ["record", "loop://", "-o", "rec", "--dialect", "line",
                                            "--columns", "ch1,ch1,ch2", "--seconds", "1"], expect="error")
case("record-columns-empty", "record", ["record", "loop://", "-o", "rec", "--dialect", "line", "--columns", "",
                                        "--seconds", "1"], expect="error")
case("record-columns-and-channels", "record", ["record", "loop://", "-o", "rec", "--dialect", "line", "--columns",
                                               "ch1,ch2", "--channels", "5", "--seconds", "1", "--no-handshake",
                                               "--quiet-status"])
case("record-estimate-without-calibration", "record", ["record", "loop://", "-o", "rec", "--estimate",
                                                       "--seconds", "1"], expect="error")
case("record-lsl-wait-negative", "record", ["record", "loop://", "-o", "rec", "--lsl", "--calibration",
                                            "lab/cal.yaml", "--lsl-wait", "-1", "--seconds", "1"], expect="error")
case("record-output-is-port-path", "record", ["record", "lab/run.csv", "-o", "lab/run.csv", "--seconds", "1",
                                              "--overwrite"], expect="error")
case("record-port-is-directory", "record", ["record", "lab", "-o", "rec", "--seconds", "1"], expect="error")
case("record-port-is-regular-file", "record", ["record", "lab/run.csv", "-o", "rec", "--seconds", "2"],
     expect="error")
case("record-seconds-tiny", "record", run=with_board(lambda port: ["record", port, "-o", "rec", "--seconds",
                                                                   "1e-300", "--quiet-status"]))
case("record-estimate-board-8-channels", "record",
     run=with_board(lambda port: ["record", port, "-o", "rec", "--seconds", "3", "--estimate", "--calibration",
                                  "lab/cal.yaml", "--quiet-status"],
                    board_args=("--rate", "100", "--seconds", "40", "--channels", "8")), check=no_ok_rows)
case("record-sigint-early", "record",
     run=with_board(lambda port: ["record", port, "-o", "rec", "--quiet-status"], during=sigint_after(2)))

# --- live -------------------------------------------------------------------------------------------

case("live-text-only-board", "live", run=text_board(lambda port: ["live", port, "--calibration", "lab/cal.yaml",
                                                                   "--save", "l.png", "--seconds", "3"]))
case("live-loop-url-no-board", "live", ["live", "loop://", "--calibration", "lab/cal.yaml", "--save", "l.png",
                                        "--seconds", "2", "--no-start"])
case("live-scale-zero", "live", ["live", "loop://", "--calibration", "lab/cal.yaml", "--save", "l.png",
                                 "--scale", "0", "--seconds", "1"], expect="error")
case("live-max-fps-negative", "live", ["live", "loop://", "--calibration", "lab/cal.yaml", "--save", "l.png",
                                       "--max-fps", "-5", "--seconds", "1"], expect="error")
case("live-max-fps-inf", "live", ["live", "loop://", "--calibration", "lab/cal.yaml", "--save", "l.png",
                                  "--max-fps", "inf", "--seconds", "1"], expect="error")
case("live-save-over-calibration", "live", ["live", "loop://", "--calibration", "lab/cal.yaml", "--save",
                                            "lab/cal.yaml", "--overwrite", "--seconds", "1"], expect="error")
case("live-board-8-channels", "live",
     run=with_board(lambda port: ["live", port, "--calibration", "lab/cal.yaml", "--save", "l.png",
                                  "--seconds", "3"], board_args=("--rate", "100", "--seconds", "40",
                                                                 "--channels", "8")))
case("live-board-killed-midway", "live",
     run=with_board(lambda port: ["live", port, "--calibration", "lab/cal.yaml", "--save", "l.png",
                                  "--seconds", "15"], during=kill_board_after(4)), timeout=40)
case("live-no-display", "live", run=with_board(lambda port: ["live", port, "--calibration", "lab/cal.yaml",
                                                             "--seconds", "2"]),
     env={"MPLBACKEND": "", "DISPLAY": "", "WAYLAND_DISPLAY": ""})

# --- process ----------------------------------------------------------------------------------------

case("process-empty-folder", "process", ["process", "empty", "--calibration", "lab/cal.yaml", "-o", "out",
                                         "--workers", "0"], expect="error", setup=lambda w: (w / "empty").mkdir())


def mixed_kept(work, output):
    if not (work / "out/good/results.csv").exists():
        return "the good session's results are missing"
    return results_ok_sane(work, output)


def process_mixed(work, env, timeout):
    p = subprocess.run([str(BIN), "process", "mix", "--calibration", "lab/cal.yaml", "-o", "out", "--workers", "2",
                        "--no-progress"], cwd=work, env=env, capture_output=True, timeout=timeout)
    out = (p.stdout + p.stderr).decode(errors="replace")
    why = mixed_kept(work, out)
    if why:
        return 0, "WRONG-OK: " + why + "\n" + out, False
    if p.returncode == 0:
        return 0, "WRONG-OK: exit 0 although two sessions failed\n" + out, False
    # exit 1 with a summary is the documented behaviour: report it as handled
    return 0, out, False


case("process-mixed-good-and-bad", "process", run=process_mixed, timeout=120,
     setup=steps(lambda w: (w / "mix").mkdir(), lambda w: shutil.copy(w / "lab/run.csv", w / "mix/good.csv"),
                 text("mix/bad.csv", "t_s,ch1\nx,y\n"), text("mix/empty.csv", ""),
                 lambda w: shutil.copytree(w / "lab/native", w / "mix/nat")))
case("process-same-session-twice", "process", ["process", "lab/run.csv", "lab/run.csv", "--calibration",
                                               "lab/cal.yaml", "-o", "out", "--workers", "0"])
case("process-two-sessions-same-name", "process", ["process", "a/run.csv", "b/run.csv", "--calibration",
                                                   "lab/cal.yaml", "-o", "out", "--workers", "0"],
     setup=steps(lambda w: (w / "a").mkdir(), lambda w: (w / "b").mkdir(),
                 lambda w: shutil.copy(w / "lab/run.csv", w / "a/run.csv"),
                 lambda w: shutil.copy(w / "lab/calsim/flat.csv", w / "b/run.csv")))
case("process-output-is-input-dir", "process", ["process", "lab/tl", "--calibration", "lab/cal.yaml", "-o", "lab/tl",
                                                "--workers", "0"], expect="error")
case("process-output-inside-input-dir", "process", ["process", "lab/tl", "--calibration", "lab/cal.yaml", "-o",
                                                    "lab/tl/out", "--workers", "0", "--no-progress"], timeout=120)
case("process-workers-huge", "process", ["process", "lab/run.csv", "--calibration", "lab/cal.yaml", "-o", "out",
                                         "--workers", "100000", "--no-progress"], timeout=90)
case("process-recursive-symlink-loop", "process", ["process", "tree", "-r", "--calibration", "lab/cal.yaml", "-o",
                                                   "out", "--workers", "0", "--no-progress"], timeout=60,
     setup=steps(lambda w: (w / "tree/sub").mkdir(parents=True),
                 lambda w: shutil.copy(w / "lab/run.csv", w / "tree/sub/r.csv"),
                 lambda w: os.symlink("..", w / "tree/sub/up")))
case("process-csv-and-non-csv", "process", ["process", "lab", "--calibration", "lab/cal.yaml", "-o", "out",
                                            "--workers", "0", "--no-progress"], timeout=90)
case("process-scheduler-unreachable", "process", ["process", "lab/run.csv", "--calibration", "lab/cal.yaml", "-o",
                                                  "out", "--scheduler", "tcp://127.0.0.1:1"], expect="error",
     timeout=60)
case("process-no-estimate-pressure-nan", "process", ["process", "pn.csv", "--calibration", "lab/cal.yaml", "-o",
                                                     "out", "--workers", "0", "--no-estimate", "--no-progress"],
     setup=edit_column("pn.csv", "pressure_pa", "nan"))
def no_negative_counts(work, output):
    m = re.search(r"(?<![\w.])-\d+ frames (lost|dropped)", output)
    return f"a negative count printed: {m.group(0)!r}" if m else results_ok_sane(work, output)


case("process-native-seq-all-zero", "process", ["process", "lab/native", "--calibration", "lab/cal.yaml", "-o", "out",
                                                "--workers", "0", "--no-progress"], check=no_negative_counts)
case("load-native-seq-all-zero", "load", chain("lab/native"), check=no_negative_counts)
case("process-one-frame-session", "process", ["process", "one.csv", "--calibration", "lab/cal.yaml", "-o", "out",
                                              "--workers", "0", "--no-progress"],
     setup=edit_csv("one.csv", lambda h, r: [h, r[0]]))
case("process-header-only-native-and-csv", "process", ["process", "hdr.csv", "n0", "--calibration", "lab/cal.yaml",
                                                       "-o", "out", "--workers", "0", "--no-progress"],
     setup=steps(edit_csv("hdr.csv", lambda h, r: [h]), native_copy("n0", truncate_frames(0))))

# --- reproduce / demo / devices ------------------------------------------------------------------

case("reproduce-output-is-file", "reproduce", ["reproduce", "-o", "lab/run.csv", "--quick", "--overwrite"],
     expect="error")
case("reproduce-output-readonly-parent", "reproduce", ["reproduce", "-o", "ro/rep", "--quick"], expect="error",
     setup=lambda w: (readonly_dir(w / "ro"), None), timeout=240)
case("demo-seconds-zero", "demo", ["demo", "-o", "d", "--seconds", "0"], expect="error")
case("demo-seconds-nan", "demo", ["demo", "-o", "d", "--seconds", "nan"], expect="error")
case("demo-rate-inf", "demo", ["demo", "-o", "d", "--rate", "inf"], expect="error")
case("demo-rate-negative", "demo", ["demo", "-o", "d", "--rate", "-100"], expect="error")
case("demo-output-is-file", "demo", ["demo", "-o", "lab/run.csv", "--overwrite"], expect="error")
case("demo-output-readonly", "demo", ["demo", "-o", "ro/d"], expect="error",
     setup=lambda w: (readonly_dir(w / "ro"), None), timeout=240)
case("demo-seconds-tiny", "demo", ["demo", "-o", "d", "--seconds", "0.01"], timeout=120)
case("devices-no-sys", "devices", ["devices"])
case("devices-extra-arg", "devices", ["devices", "extra"], expect="error")

# --- the whole command line and its environment -------------------------------------------------------

case("env-home-unset", "load", chain("lab/run.csv"), unset=("HOME",), expect="ok")
case("env-lang-c", "load", chain("ses sión.csv"), env={"LANG": "C", "LC_ALL": "C"}, expect="ok",
     setup=lambda w: shutil.copy(w / "lab/run.csv", w / "ses sión.csv"))
case("env-lang-latin1-locale", "load", chain("lab/run.csv"), env={"LC_ALL": "en_US.ISO-8859-1",
                                                                  "PYTHONIOENCODING": "latin-1"}, expect="ok")
case("env-tmpdir-not-writable", "process", ["process", "lab/run.csv", "--calibration", "lab/cal.yaml", "-o", "out",
                                            "--workers", "2", "--no-progress"], env={"TMPDIR": "/proc"}, timeout=90)
case("env-numba-cache-not-writable", "load", chain("lab/run.csv"), env={"NUMBA_CACHE_DIR": "/proc/nocache"},
     timeout=240)
case("env-mplconfigdir-not-writable", "plot", ["plot", "lab/res", "-o", "f.png"], env={"MPLCONFIGDIR": "/proc/x"})


def broken_stdout(args):
    """Standard output is a pipe nobody reads (``bendsense ... | head -0``): quiet, no traceback."""
    def run(work, env, timeout):
        r, w = os.pipe()
        os.close(r)
        try:
            q = subprocess.run([str(BIN), *args], cwd=work, env=env, stdout=w, stderr=subprocess.PIPE,
                               timeout=timeout)
        except subprocess.TimeoutExpired as e:
            return None, str(e), True
        finally:
            os.close(w)
        err = q.stderr.decode(errors="replace")
        return (0 if "Traceback" not in err else q.returncode), err, False
    return run


case("env-stdout-broken-pipe-export", "export", run=broken_stdout(["load", "lab/run.csv", "export", "/dev/stdout",
                                                                   "--overwrite"]))
case("env-stdout-broken-pipe-help", "load", run=broken_stdout(["load", "--help"]))
case("env-stdout-broken-pipe-devices", "devices", run=broken_stdout(["devices"]))
case("cli-verbose-and-quiet", "load", ["-v", "-q", *chain("lab/run.csv")])
case("cli-triple-verbose", "load", ["-vvv", *chain("lab/run.csv")])
case("cli-help-of-chain-step", "estimate", ["load", "lab/run.csv", "estimate", "--help"])
case("cli-stdin-dash-session", "load", chain("-"), expect="error", stdin=b"t_s,ch1\n0,1\n")

# --- the public Python API ----------------------------------------------------------------------------

def api_case(name, code, expect="any", command="api"):
    case(name, command, api=code, expect=expect)


api_case("api-load-config-dir", "bs.load_config(LAB)", expect="error")
api_case("api-load-config-calibration", "bs.load_config(LAB + '/cal.yaml')", expect="error")
api_case("api-load-config-bytes-path", "c = bs.load_config((LAB + '/cfg.yaml').encode())")
api_case("api-save-config-over-session", "bs.config.save_config(bs.load_config(), LAB + '/run.csv', overwrite=False)",
         expect="error")
api_case("api-read-session-int", "bs.read_session(3)", expect="error")
api_case("api-read-session-none", "bs.read_session(None)", expect="error")
api_case("api-read-session-csv-native-dir", "bs.read_session_csv(LAB + '/native')", expect="error")
api_case("api-session-lists", """
    s = bs.Session([0.0, 0.1], [[2000.0] * 16, [2001.0] * 16], [5e4, 5e4])
    assert s.n_channels == 16
""", expect="ok")
api_case("api-session-0d", "bs.Session(np.float64(0), np.zeros(16), np.float64(5e4))", expect="error")
api_case("api-session-3d-signals", "bs.Session(np.arange(2.0), np.zeros((2, 4, 4)), np.zeros(2))", expect="error")
api_case("api-session-negative-pressure", """
    s = bs.Session(np.arange(3.0), np.full((3, 16), 2000.0), np.full(3, -2e5))
    from bendsense import pipeline
    r = pipeline.process(s, calibration=bs.Calibration.load(LAB + '/cal.yaml'))
    st = np.asarray(getattr(r, "status", []))
    if (st == "ok").any():
        wrong("ok at -200 kPa (below vacuum)")
""")
api_case("api-session-string-signals", "bs.Session(np.arange(2.0), [['a'] * 16] * 2, np.zeros(2))", expect="error")
api_case("api-session-select-out-of-range", """
    s = bs.read_session_csv(LAB + '/run.csv')
    s.select(np.arange(len(s.t_s) + 5))
""", expect="error")
api_case("api-write-session-csv-over-itself", """
    s = bs.read_session_csv(LAB + '/run.csv')
    bs.session.write_session_csv(s, LAB + '/run.csv', overwrite=True)
    t = bs.read_session_csv(LAB + '/run.csv')
    if not np.allclose(t.signals, s.signals):
        wrong('the session changed when written over itself')
""")
api_case("api-write-session-csv-dir", "bs.session.write_session_csv(bs.read_session_csv(LAB + '/run.csv'), LAB)",
         expect="error")
api_case("api-calibration-load-session", "bs.Calibration.load(LAB + '/run.csv')", expect="error")
api_case("api-calibration-fit-degree-0", "bs.Calibration.fit(LAB + '/calsim/manifest.yaml', degree=0)",
         expect="error")
api_case("api-calibration-fit-degree-float", "bs.Calibration.fit(LAB + '/calsim/manifest.yaml', degree=2.5)",
         expect="error")
api_case("api-calibration-fit-weighting-bad", "bs.Calibration.fit(LAB + '/calsim/manifest.yaml', weighting='L1')",
         expect="error")
api_case("api-calibration-shifts-wrong-width", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    c.shifts_m(np.zeros((3, 8)))
""", expect="error")
api_case("api-reconstruct-list", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    sh = bs.reconstruct([list(c.offset)] if hasattr(c, 'offset') else [[2000.0] * 16], c)
""")
api_case("api-reconstruct-float32-noncontig", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    a = np.asfortranarray(np.repeat(s.signals.astype(np.float32), 2, axis=0))[::2]
    sh = bs.reconstruct(a, c)
    ref = bs.reconstruct(s.signals, c)
    if not np.allclose(np.asarray(sh.curvature_per_m if hasattr(sh, 'curvature_per_m') else sh.kappa_per_m),
                       np.asarray(ref.curvature_per_m if hasattr(ref, 'curvature_per_m') else ref.kappa_per_m),
                       rtol=1e-3, atol=1e-3):
        wrong('float32 non-contiguous signals gave other curvatures')
""")
api_case("api-reconstruct-0d", "bs.reconstruct(np.float64(2000), bs.Calibration.load(LAB + '/cal.yaml'))",
         expect="error")
api_case("api-reconstruct-empty", "bs.reconstruct(np.zeros((0, 16)), bs.Calibration.load(LAB + '/cal.yaml'))")
api_case("api-reconstruct-batch-axes", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    sh = bs.reconstruct(np.stack([s.signals, s.signals]), c)
""")
api_case("api-reconstruct-nan", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    sh = bs.reconstruct(np.full((2, 16), np.nan), c)
""")
api_case("api-reconstruct-calibration-path", "bs.reconstruct(np.full((2, 16), 2000.0), LAB + '/cal.yaml')")
api_case("api-estimate-negative-pressure", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), -np.abs(s.pressure_pa), calibration=c)
    finite_ok(e)
    if trusted(e).any():
        wrong('status ok at a negative (vacuum beyond the range) pressure')
""")
api_case("api-estimate-pressure-list", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), list(s.pressure_pa), calibration=c)
    finite_ok(e)
""", expect="ok")
api_case("api-estimate-pressure-wrong-length", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), np.full(len(s.t_s) + 3, 5e4), calibration=c)
""", expect="error")
api_case("api-estimate-pressure-float32", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    sh = bs.reconstruct(s.signals, c)
    e = bs.estimate_force(sh, s.pressure_pa.astype(np.float32), calibration=c)
    r = bs.estimate_force(sh, s.pressure_pa, calibration=c)
    finite_ok(e)
    if not np.allclose(np.asarray(e.force_n), np.asarray(r.force_n), atol=1e-3, equal_nan=True):
        wrong('float32 pressure gave other forces')
""", expect="ok")
api_case("api-estimate-pressure-1e308", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), np.full(len(s.t_s), 1e308), calibration=c)
    if trusted(e).any():
        wrong('status ok at 1e308 Pa')
""")
api_case("api-estimate-constraint-bad", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, constraint='sideways')
""", expect="error")
api_case("api-estimate-direction-zero", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, constraint='direction', direction=(0, 0))
    finite_ok(e)
""", expect="error")
api_case("api-estimate-direction-nan", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, constraint='direction',
                          direction=(np.nan, 1))
    finite_ok(e)
""", expect="error")
api_case("api-estimate-max-iter-zero", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, max_iter=0)
    finite_ok(e)
""")
api_case("api-estimate-curvatures-zero", "finite_ok(bs.estimate_force(np.zeros((3, 16)), 5e4))")
api_case("api-estimate-curvatures-wrong-width", "bs.estimate_force(np.zeros((3, 7)), 5e4)", expect="error")
api_case("api-estimate-config-path", """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/run.csv')
    e = bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, config=LAB + '/cfg.yaml')
    finite_ok(e)
""")
api_case("api-solve-beam-ei-zero", "bs.solve_beam(0.13, 0.0, 5.0)", expect="error")
api_case("api-solve-beam-ei-negative", "bs.solve_beam(0.13, -2.5e-3, 5.0)", expect="error")
api_case("api-solve-beam-length-nan", "bs.solve_beam(float('nan'), 2.5e-3, 5.0)", expect="error")
api_case("api-solve-beam-force-1e308", """
    b = bs.solve_beam(0.13, 2.5e-3, 5.0, force_n=(1e308, 0))
    if np.all(b.success) and not np.isfinite(np.asarray(b.positions_m)).all():
        wrong("success with non-finite positions")
    if np.all(b.success):
        wrong("success under a tip force of 1e308 N")
""")
api_case("api-solve-beam-force-3-components", "bs.solve_beam(0.13, 2.5e-3, 5.0, force_n=(1, 2, 3))",
         expect="error")
api_case("api-solve-beam-method-bad", "bs.solve_beam(0.13, 2.5e-3, 5.0, method='rk4')", expect="error")
api_case("api-solve-beam-s-m-outside", "bs.solve_beam(0.13, 2.5e-3, 5.0, s_m=[0, 0.5, 1.0])", expect="error")
api_case("api-solve-beam-n-nodes-1", "bs.solve_beam(0.13, 2.5e-3, 5.0, n_nodes=1)", expect="error")
api_case("api-free-bending-negative-mu", """
    m = bs.mechanics.actuator.FreeBendingModel(chamber_radius_m=0.01, bottom_thickness_m=0.002, wall_thickness_m=0.002,
                            length_m=0.13, shear_modulus_pa=-1.8e5, sensor_stiffness_nm_per_rad=1.5e-3)
""", expect="error")
api_case("api-free-bending-length-inf", """
    m = bs.mechanics.actuator.FreeBendingModel(chamber_radius_m=0.01, bottom_thickness_m=0.002, wall_thickness_m=0.002,
                            length_m=float('inf'), shear_modulus_pa=1.8e5, sensor_stiffness_nm_per_rad=1.5e-3)
""", expect="error")
api_case("api-config-mutate-then-estimate", """
    cfg = bs.load_config()
    import dataclasses
    try:
        cfg.actuator.length_m = -1.0
    except (dataclasses.FrozenInstanceError, AttributeError):
        pass
    else:
        c = bs.Calibration.load(LAB + '/cal.yaml')
        s = bs.read_session_csv(LAB + '/run.csv')
        e = bs.estimate_force(bs.reconstruct(s.signals, c), s.pressure_pa, config=cfg)
        if trusted(e).any():
            wrong('ok from a config mutated to a negative length')
""")
api_case("api-pipeline-process-native-path", """
    from bendsense import pipeline
    r = pipeline.process(LAB + '/native', calibration=LAB + '/cal.yaml')
""")


if __name__ == "__main__":
    sys.modules.setdefault("campaign", sys.modules[__name__])  # the modules of cases below extend this one
    import campaign_safety  # noqa: E402, F401  (control, the gripper and tracking: issue 30)

    sys.exit(main())
