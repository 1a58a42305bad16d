# ruff: noqa: D103  (the small builders of the cases below say what they do in their names)
"""Hostile cases for control, the gripper and tracking (issue 30), in tools/campaign.py's harness.

tools/campaign.py loads this module; its cases are named ``control-``, ``gripper-`` and
``track-`` (``python tools/campaign.py --only control- --only gripper- --only track-``).

Every ``control`` case runs against ``sim-device`` with ``--truth``; once the client has
ended (whatever the exit) the board is asked for a few more frames, and the simulator's
truth of the last one must show set-point 0 on every pressure line (a case whose command
must be refused before any work also requires that no line rose above 1 kPa). The probe
comes well within the board's host-silence watchdog (1 s): the verdict is on the host, not
on the board's safety net. The gripper
chain and tracking cases compare ``ok`` forces and tracks with the simulator's truth
columns (``results_ok_sane``; the API snippets do it themselves).
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import signal
import subprocess
import textwrap
import time

from campaign import (
    LAB_STEPS,
    _kill,
    api_case,
    case,
    edit_csv,
    edit_yaml,
    readonly_dir,
    results_ok_sane,
    steps,
    text,
    with_board,
    wrote,
)


def gripper_lab(lab, run):
    """The simulated gripper of sim-device --fingers 3 (config, calibration, a session) and a time-varying session."""
    run("simulate", "gripper", "-o", "grip", "--fingers", "3", "--seconds", "1")
    run("simulate", "gripper", "-o", "grip1", "--fingers", "1", "--seconds", "0.2")
    run("simulate", "time-varying", "-o", "tv")


LAB_STEPS.append(gripper_lab)

# --- control against a simulated board, checked against the board's truth ------------------------

GRIP = ["--config", "lab/grip/gripper.yaml", "--calibration", "lab/grip/calibration.yaml"]
CONTACT = ["--load", "contact", "--contact-s-m", "thumb=0.10", "--contact-s-m", "index=0.11",
           "--contact-s-m", "middle=0.095"]
BOARD = ("--fingers", "3", "--rate", "1000")
# a one-finger gripper: its board starts in a third of the time (the simulated object is solved per finger)
GRIP1 = ["--config", "lab/grip1/gripper.yaml", "--calibration", "lab/grip1/calibration.yaml"]
CONTACT1 = ["--load", "contact", "--contact-s-m", "thumb=0.10"]
BOARD1 = ("--fingers", "1", "--rate", "1000")


def grasp1(*extra, target="0.15", seconds="1", contact=CONTACT1):
    return grasp(*extra, target=target, seconds=seconds, contact=contact, config=GRIP1)


def grasp(*extra, target="0.15", seconds="1", contact=CONTACT, config=GRIP):
    """The documented grasp (docs/grasping.md) with EXTRA options; None drops an option."""
    def args(port):
        base = ["control", port, *config, "--target-force-n", target, *contact]
        if seconds is not None:
            base += ["--seconds", seconds]
        return [a for a in [*base, *extra] if a is not None]
    return args


def single(*extra, target="0.15", seconds="1"):
    """The paper's single actuator pressing the object of sim-device --object rigid (at 0.10 m)."""
    return lambda port: ["control", port, "--calibration", "lab/cal.yaml", "--target-force-n", target,
                         "--load", "contact", "--contact-s-m", "0.10", "--seconds", seconds, *extra]


def probe(port, board):
    """Ask the board for frames after the client ended: the truth then shows the set-points it holds."""
    from bendsense.wire.frames import FrameType, encode_command

    if board.poll() is not None:
        return
    try:
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return
    try:
        os.write(fd, encode_command(FrameType.START))
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.3:
            try:
                os.read(fd, 65536)
            except (BlockingIOError, OSError):
                pass
            time.sleep(0.02)
        os.write(fd, encode_command(FrameType.STOP))
        time.sleep(0.05)
    except OSError:
        pass
    finally:
        os.close(fd)


def truth_rows(work):
    """The board's truth so far: (header, rows)."""
    path = work / "truth.csv"
    if not path.exists():
        return [], []
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
    return (rows[0], rows[1:]) if rows else ([], [])


def truth_verdict(work, before_probe, never_driven, rc=0, out=""):
    """WRONG-OK lines when the board's truth shows a line left pressurised (or driven at all).

    BEFORE_PROBE rows are the client's; the probe's rows after them show what the board
    holds once the client ended (a board the client never started is not judged by them:
    the probe itself runs its closing profile). A board that ignores set-points cannot be
    made to let go: a line the command said "did not fall" of, with a non-zero exit, is the truth.
    """
    honest = {int(k) for k in re.findall(r"line (\d+) did not fall", out)} if rc else set()
    head, rows = truth_rows(work)
    rows = [r for r in rows if len(r) == len(head)]
    client = rows[:before_probe] if before_probe is not None else rows
    if not client:
        return ""
    out = []
    for i, name in enumerate(head):
        if not name.endswith("setpoint_pa"):
            continue
        last = float(rows[-1][i])
        line = int(name[4:name.index("_")]) if name.startswith("line") else 0
        if last > 0 and line not in honest:
            out.append(f"WRONG-OK: {name} = {last / 1e3:.1f} kPa on the board after the command ended")
        peak = max(float(r[i]) for r in client)
        if never_driven and peak > 1e3:  # a refusal that needs the board's frames may start it, not drive it
            out.append(f"WRONG-OK: a command refused before work let {name} reach {peak / 1e3:.1f} kPa")
    return "\n" + "\n".join(out) if out else ""


def controlled(client, board=BOARD, during=None, never_driven=False, probe_after=True):
    """A driver: CLIENT(port) against sim-device BOARD --truth truth.csv, then the truth's verdict.

    A board that plays a recording back or sends ramps has no truth (and no regulators).
    """
    truth = () if "--replay" in board or "ramp" in board else ("--truth", "truth.csv")
    seen = {}

    def after(port, board, work):
        seen["rows"] = len(truth_rows(work)[1])
        # a board that a case ended while the client ran (a client that stopped before, on a fault of a loaded
        # machine, sent its zeros to a live board: not judged by its death)
        seen["dead"] = board.poll() is not None or (getattr(during, "ends_board", False)
                                                    and during.client_ran_at_end)
        if probe_after:
            probe(port, board)

    inner = with_board(client, board_args=("--seconds", "90", *board, *truth), during=during,
                       after=after)

    def run(work, env, timeout):
        seen.clear()
        rc, out, hung = inner(work, env, timeout)
        if seen.get("dead"):  # a board gone cannot be at rest: the loop must not say it is
            sent = re.search(r"set-point 0 sent on (every|line)[^\n]*", out)
            lost = re.search(r"could not be sent|not be confirmed", out)
            return rc, out + (f"\nWRONG-OK: the board died, yet '{sent.group(0)}'" if sent and not lost else ""), hung
        return rc, out + truth_verdict(work, seen.get("rows"), never_driven, rc, out), hung
    return run


def control_case(name, client, *, board=BOARD, during=None, expect="any", setup=None, check=None, timeout=60,
                 may_change=(), probe_after=True):
    case(name, "control", expect=expect, setup=setup, check=check or control_sane, timeout=timeout,
         may_change=may_change,
         run=controlled(client, board, during, never_driven=expect == "error", probe_after=probe_after))


def refused(name, client, **kw):
    """Nonsense: one line, non-zero, and the board never driven."""
    control_case(name, client, expect="error", **kw)


def control_sane(work, output):
    """An exit 0 of control whose summary holds NaN forces, or that recorded nothing it said it did."""
    summary = [ln for ln in output.splitlines() if " frames in " in ln]
    if summary and "nan" in summary[-1].lower():
        return "exit 0 with NaN in the summary: " + summary[-1][:200]
    if not summary:
        return "exit 0 without the summary line"
    return results_ok_sane(work, output)


def session_at(path):
    def check(work, output):
        return control_sane(work, output) or wrote(f"{path}/control.csv", f"{path}/meta.yaml")(work, output)
    return check


def streaming(work, timeout=60.0):
    """Wait until the board has sent 0.2 s of frames to the client (its truth grows)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if len(truth_rows(work)[1]) > 200:
            return
        time.sleep(0.1)


def signal_after(seconds, sig, target="client", running=True):
    """SIG to the client (or board) SECONDS after the loop started driving (RUNNING) or after its start."""
    def during(client, board, work):
        if running:
            streaming(work)
        time.sleep(seconds)
        p = client if target == "client" else board
        during.client_ran_at_end = client.poll() is None
        if p.poll() is None:
            p.send_signal(sig)
    during.ends_board = target == "board"  # a board told to stop is gone: its lines hold what they held
    return during


def signals_after(seconds, *sigs):
    def during(client, board, work):
        streaming(work)
        time.sleep(seconds)
        for s in sigs:
            if client.poll() is None:
                client.send_signal(s)
            time.sleep(0.05)
    return during


def kill_board(seconds):
    def during(client, board, work):
        streaming(work)
        time.sleep(seconds)
        during.client_ran_at_end = client.poll() is None
        _kill(board)
    during.ends_board = True
    return during


def board_ends():
    """Wait for the board to end its own run (its --seconds) while the client runs: then it is gone."""
    def during(client, board, work):
        try:
            board.wait(timeout=60)
        except subprocess.TimeoutExpired:  # still running: judged by its truth
            return
        during.client_ran_at_end = client.poll() is None
    during.ends_board = True
    during.client_ran_at_end = False
    return during


def freeze_board(seconds, pause):
    """SIGSTOP the board SECONDS after the loop started driving, SIGCONT it PAUSE seconds later."""
    def during(client, board, work):
        streaming(work)
        time.sleep(seconds)
        board.send_signal(signal.SIGSTOP)
        time.sleep(pause)
        board.send_signal(signal.SIGCONT)
    return during


def stopped(work, output):
    """A stop by signal is fine; an exit 0 still has to be sane."""
    return control_sane(work, output)


def gripper_yaml(path, fn):
    return edit_yaml(path, "lab/grip/gripper.yaml", fn)


def finger(i, **kw):
    def fn(d):
        d["fingers"][i].update(kw)
    return fn


def with_config(path):
    return ["--config", path, "--calibration", "lab/grip/calibration.yaml"]


# the documented grasp and odd but valid boards
control_case("control-grip-baseline", grasp("-o", "grasp"), expect="ok", check=session_at("grasp"))
control_case("control-grip-rate-35", grasp(seconds="2"), board=("--fingers", "3", "--rate", "35"))
control_case("control-one-rate-7", grasp1(seconds="2"), board=("--fingers", "1", "--rate", "7"))
control_case("control-one-rate-2000", grasp1(), board=("--fingers", "1", "--rate", "2000"))
control_case("control-one-rate-fractional", grasp1(seconds="2"), board=("--fingers", "1", "--rate", "12.5"))
control_case("control-one-drop-5pc", grasp1(), board=(*BOARD1, "--drop", "0.05", "--seed", "1"))
control_case("control-grip-drop-40pc", grasp(), board=(*BOARD, "--drop", "0.4", "--seed", "1"))
control_case("control-one-corrupt-5pc", grasp1(), board=(*BOARD1, "--corrupt", "0.05", "--seed", "2"))
control_case("control-one-truncate-5pc", grasp1(), board=(*BOARD1, "--truncate", "0.05", "--seed", "3"))
control_case("control-grip-all-faults", grasp(), board=(*BOARD, "--drop", "0.02", "--corrupt", "0.02",
                                                        "--truncate", "0.02", "--seed", "4"))
control_case("control-one-compliant-object", grasp1(), board=(*BOARD1, "--object", "compliant"))
control_case("control-one-object-stiffness-tiny", grasp1(),
             board=(*BOARD1, "--object", "compliant", "--object-stiffness", "1e-6"))
control_case("control-one-object-elsewhere", grasp1(), board=(*BOARD1, "--object-s-m", "0.06"))
control_case("control-one-board-limit-30kpa", grasp1(),
             board=(*BOARD1, "--max-pressure-kpa", "30", "--object-touch-kpa", "20"))
control_case("control-one-board-slow-regulator", grasp1(), board=(*BOARD1, "--tau-ms", "2000"))
control_case("control-one-board-close-0", grasp1(), board=(*BOARD1, "--close-kpa", "0"))
control_case("control-grip-four-finger-board", grasp(), board=("--fingers", "4", "--rate", "1000"))
control_case("control-one-load-tip", grasp1(contact=["--load", "tip"]), board=BOARD1)
control_case("control-one-constraint-none", grasp1("--constraint", "none"), board=BOARD1)
control_case("control-one-constraint-follower", grasp1("--constraint", "follower"), board=BOARD1)
control_case("control-one-constraint-vertical", grasp1("--constraint", "vertical"), board=BOARD1)
control_case("control-grip-finger-index", grasp("--finger", "index"))
control_case("control-grip-finger-twice", grasp("--finger", "index", "--finger", "index"))
control_case("control-grip-plain-contact-for-all", grasp(contact=["--load", "contact", "--contact-s-m", "0.1"]))
control_case("control-single-object", single(), board=("--object", "rigid", "--rate", "500"))
control_case("control-single-on-gripper-board", single(), board=BOARD)
control_case("control-grip-on-plain-board", grasp(), board=("--rate", "500"))
control_case("control-grip-on-ramp-board", grasp(),
             board=("--source", "ramp", "--channels", "48", "--rate", "1000"))
control_case("control-single-plain-board-ignores-setpoints", single(), board=("--rate", "500"))
control_case("control-grip-on-replayed-session", grasp(), board=("--replay", "lab/grip/session.csv"))
control_case("control-one-target-tiny", grasp1(target="1e-9"), board=BOARD1)
control_case("control-one-target-zero", grasp1(target="0"), board=BOARD1)
control_case("control-one-gains-zero", grasp1("--kp-kpa-per-n", "0", "--ki-kpa-per-n-s", "0"), board=BOARD1)
control_case("control-one-ki-huge", grasp1("--ki-kpa-per-n-s", "1e12"), board=BOARD1)
control_case("control-one-kp-huge", grasp1("--kp-kpa-per-n", "1e12"), board=BOARD1)
control_case("control-one-rate-limit-tiny", grasp1("--max-rate-kpa-per-s", "1e-9"), board=BOARD1)
control_case("control-one-bandwidth-tiny", grasp1("--bandwidth-hz", "1e-6"), board=BOARD1)
control_case("control-one-bandwidth-above-nyquist", grasp1("--bandwidth-hz", "5000"), board=BOARD1)
control_case("control-grip-silence-huge-board-killed", grasp("--silence-s", "1e6", seconds=None),
             during=kill_board(3), timeout=40)
control_case("control-one-silence-tiny", grasp1("--silence-s", "1e-6"), board=BOARD1)
control_case("control-one-max-pressure-above-board", grasp1("--max-pressure-kpa", "150"), board=BOARD1)
control_case("control-one-max-pressure-tiny", grasp1("--max-pressure-kpa", "1e-6"), board=BOARD1)
control_case("control-one-seconds-tiny", grasp1(seconds="1e-6"), board=BOARD1)
control_case("control-one-hello-timeout-tiny", grasp1("--hello-timeout", "1e-6"), board=BOARD1)

# whatever ends the loop
control_case("control-grip-sigint-at-1s", grasp("-o", "s", seconds=None), during=signal_after(1, signal.SIGINT),
             check=stopped)
control_case("control-grip-sigterm-at-1s", grasp("-o", "s", seconds=None), during=signal_after(1, signal.SIGTERM),
             check=stopped)
control_case("control-grip-sigint-at-start", grasp(seconds=None),
             during=signal_after(0.8, signal.SIGINT, running=False))
control_case("control-grip-sigterm-at-start", grasp(seconds=None),
             during=signal_after(1.5, signal.SIGTERM, running=False))
control_case("control-grip-sighup", grasp(seconds=None), during=signal_after(3, signal.SIGHUP))
control_case("control-grip-double-sigint", grasp(seconds=None), during=signals_after(3, signal.SIGINT, signal.SIGINT))
control_case("control-grip-sigint-then-sigterm", grasp(seconds=None),
             during=signals_after(3, signal.SIGINT, signal.SIGTERM))
control_case("control-grip-board-killed", grasp(seconds="10"), during=kill_board(3), probe_after=False)
control_case("control-grip-board-sigint", grasp(seconds="10"), during=signal_after(3, signal.SIGINT, "board"),
             probe_after=False)
control_case("control-grip-board-ends-its-run", grasp(seconds="40"), board=(*BOARD, "--seconds", "20"),
             during=board_ends(), probe_after=False)
control_case("control-grip-board-freezes-2s", grasp(seconds="10"), during=freeze_board(1, 2), timeout=40)

# nonsense options: refused before the port is opened (a port nobody can open would say so instead)
def option_refused(name, args):
    case(name, "control", args("/dev/null"), expect="error")


for value in ("nan", "inf", "-0.1", "0.15N", ""):
    option_refused(f"control-opt-target-{value or 'empty'}", grasp1(target=value))
for option, values in {"--kp-kpa-per-n": ("-50", "nan"), "--ki-kpa-per-n-s": ("-1",),
                       "--max-rate-kpa-per-s": ("0", "nan"), "--max-pressure-kpa": ("0", "-10", "nan"),
                       "--bandwidth-hz": ("0", "nan", "inf"), "--silence-s": ("0", "nan"),
                       "--hello-timeout": ("-1",)}.items():
    for value in values:
        option_refused(f"control-opt{option[1:]}-{value}", grasp1(option, value))
for value in ("0", "nan"):
    option_refused(f"control-opt-seconds-{value}", grasp1(seconds=value))
option_refused("control-opt-baud-tiny", grasp1("--baud", "10"))
option_refused("control-opt-contact-s-m-zero", grasp1(contact=["--load", "contact", "--contact-s-m", "0"]))
option_refused("control-opt-contact-s-m-beyond-length", grasp1(contact=["--load", "contact", "--contact-s-m", "0.5"]))
option_refused("control-opt-contact-s-m-nan", grasp1(contact=["--load", "contact", "--contact-s-m", "thumb=nan"]))
option_refused("control-opt-contact-s-m-missing", grasp1(contact=["--load", "contact"]))
control_case("control-one-seconds-1e300-then-sigint", grasp1(seconds="1e300"), board=BOARD1,
             during=signal_after(1, signal.SIGINT), check=stopped)
refused("control-grip-finger-unknown", grasp("--finger", "pinky"))
refused("control-one-finger-empty", grasp1("--finger", ""), board=BOARD1)
refused("control-grip-finger-without-config", single("--finger", "thumb"), board=("--object", "rigid"))
refused("control-grip-contact-s-m-unknown-finger", grasp(contact=[*CONTACT, "--contact-s-m", "pinky=0.1"]))
refused("control-grip-contact-s-m-one-finger-missing",
        grasp(contact=["--load", "contact", "--contact-s-m", "thumb=0.1", "--contact-s-m", "index=0.1"]))
refused("control-one-constraint-direction", grasp1("--constraint", "direction"), board=BOARD1)
refused("control-grip-calibration-unknown-finger",
        grasp(config=["--config", "lab/grip/gripper.yaml", "--calibration", "pinky=lab/grip/calibration.yaml",
                      "--calibration", "lab/grip/calibration.yaml"]))
refused("control-grip-calibration-is-session",
        grasp(config=["--config", "lab/grip/gripper.yaml", "--calibration", "lab/grip/session.csv"]))
refused("control-grip-calibration-8-channels",
        grasp(config=["--config", "lab/grip/gripper.yaml", "--calibration", "c8.yaml"]),
        setup=edit_yaml("c8.yaml", "lab/cal.yaml", lambda d: [d.update({k: v[:8]}) for k, v in list(d.items())
                                                              if isinstance(v, list) and len(v) == 16]))
refused("control-grip-config-channels-beyond-board", grasp(config=with_config("g.yaml")),
        setup=gripper_yaml("g.yaml", finger(2, channels=list(range(49, 65)))))
refused("control-grip-config-line-beyond-board", grasp(config=with_config("g.yaml")),
        setup=gripper_yaml("g.yaml", finger(2, pressure_line=7)))
refused("control-grip-config-shared-line", grasp(config=with_config("g.yaml")),
        setup=gripper_yaml("g.yaml", finger(1, pressure_line=0)))
refused("control-grip-config-overlapping-channels", grasp(config=with_config("g.yaml")),
        setup=gripper_yaml("g.yaml", finger(1, channels=list(range(9, 25)))))
refused("control-grip-config-3-fingers-on-2-finger-board", grasp(), board=("--fingers", "2", "--rate", "1000"))
refused("control-one-port-is-file", lambda port: grasp1()("lab/grip/gripper.yaml"), board=BOARD1)
refused("control-one-port-is-directory", lambda port: grasp1()("lab"), board=BOARD1)
refused("control-one-port-empty", lambda port: grasp1()(""), board=BOARD1)
refused("control-one-port-dev-null", lambda port: grasp1()("/dev/null"), board=BOARD1)
refused("control-one-output-existing-session", grasp1("-o", "lab/grip1"), board=BOARD1)
refused("control-one-output-is-file", grasp1("-o", "lab/grip1/gripper.yaml"), board=BOARD1)
refused("control-one-output-overwrite-user-dir", grasp1("-o", "mine", "--overwrite"), board=BOARD1,
        setup=text("mine/notes.txt", "x\n"))
refused("control-one-output-readonly", grasp1("-o", "ro/s"), board=BOARD1,
        setup=lambda w: (readonly_dir(w / "ro"), None))


# --- the gripper chain on hostile configs and odd sessions ----------------------------------------

GCHAIN_TAIL = ["reconstruct", "estimate", "save", "out"]


def gload(session="lab/grip/session.csv", config="lab/grip/gripper.yaml", cal=("lab/grip/calibration.yaml",),
          tail=GCHAIN_TAIL):
    return ["load", session, "--config", config, *(a for c in cal for a in ("--calibration", c)), *tail]


def gcase(name, args, **kw):
    case(name, "gripper", args, **kw)


def gsession(path, fn):
    return edit_csv(path, fn, src="lab/grip/session.csv", comments=True)


def gcol(path, column, value, rows=None):
    def fn(h, r):
        i = h.split(",").index(column)
        out = [h]
        for k, row in enumerate(r):
            cells = row.split(",")
            if rows is None or k in rows:
                cells[i] = value
            out.append(",".join(cells))
        return out
    return gsession(path, fn)


def retime(path, fn):
    """Replace t_s of each row k by fn(k, t)."""
    def edit(h, r):
        out = [h]
        for k, row in enumerate(r):
            cells = row.split(",")
            cells[0] = repr(fn(k, float(cells[0])))
            out.append(",".join(cells))
        return out
    return gsession(path, edit)


FULL = ["reconstruct", "estimate", "track", "save", "out"]
CONTACT_FULL = ["reconstruct", "estimate", "--load", "contact", "track", "save", "out"]

gcase("gripper-chain-full", gload(tail=[*CONTACT_FULL, "plot", "f.png", "mcap", "a.mcap", "export", "e.csv"]),
      expect="ok", check=wrote("out/thumb/results.csv", "f.png", "a.mcap", "e.csv"))
gcase("gripper-chain-filter", gload(tail=[*FULL[:2], "track", "--filter", "save", "out"]), expect="ok")
gcase("gripper-export-finger", gload(tail=["export", "t.csv", "--finger", "thumb"]), expect="ok", check=wrote("t.csv"))
gcase("gripper-export-finger-unknown", gload(tail=["export", "t.csv", "--finger", "pinky"]), expect="error")
gcase("gripper-one-frame", gload("one.csv", tail=FULL), setup=gsession("one.csv", lambda h, r: [h, r[0]]))
gcase("gripper-two-frames", gload("two.csv", tail=FULL), setup=gsession("two.csv", lambda h, r: [h, *r[100:102]]))
gcase("gripper-header-only", gload("h.csv", tail=FULL), expect="error", setup=gsession("h.csv", lambda h, r: [h]))
gcase("gripper-nan-rows", gload("n.csv", tail=FULL), setup=gcol("n.csv", "ch20", "nan", rows=range(50, 60)))
gcase("gripper-nan-pressure-one-line", gload("np.csv", tail=FULL),
      setup=gcol("np.csv", "line1_pressure_pa", "nan", rows=range(80, 120)))
gcase("gripper-inf-counts", gload("i.csv", tail=FULL), setup=gcol("i.csv", "ch40", "inf", rows=range(10, 12)))
gcase("gripper-constant-pressure", gload("c.csv", tail=FULL), setup=gcol("c.csv", "line0_pressure_pa", "50000"))
gcase("gripper-pressure-negative", gload("neg.csv", tail=FULL),
      setup=gcol("neg.csv", "line2_pressure_pa", "-150000"), check=None)
gcase("gripper-time-backwards", gload("b.csv", tail=FULL), setup=retime("b.csv", lambda k, t: 10.0 - t))
gcase("gripper-time-one-step-back", gload("b1.csv", tail=FULL),
      setup=retime("b1.csv", lambda k, t: t - 0.5 if k == 100 else t))
gcase("gripper-time-duplicated", gload("d.csv", tail=FULL), setup=retime("d.csv", lambda k, t: (k // 2) * 0.01))
gcase("gripper-time-all-equal", gload("eq.csv", tail=FULL), setup=retime("eq.csv", lambda k, t: 1.0))
gcase("gripper-time-huge-gap", gload("g.csv", tail=FULL),
      setup=retime("g.csv", lambda k, t: t + (1e6 if k >= 100 else 0)))
gcase("gripper-time-35hz", gload("s.csv", tail=FULL), setup=retime("s.csv", lambda k, t: k / 35.0))
gcase("gripper-time-2khz", gload("f.csv", tail=FULL), setup=retime("f.csv", lambda k, t: k / 2000.0))
gcase("gripper-time-nan", gload("tn.csv", tail=FULL),
      setup=retime("tn.csv", lambda k, t: float("nan") if k == 7 else t))
gcase("gripper-time-1e300", gload("tb.csv", tail=FULL), setup=retime("tb.csv", lambda k, t: 1e300 + k * 1e290))
gcase("gripper-missing-line-column", gload("ml.csv", tail=FULL), expect="error",
      setup=gsession("ml.csv", lambda h, r: [",".join(c for c in h.split(",") if c != "line2_pressure_pa"),
                                            *(",".join(c for c, n in zip(x.split(","), h.split(","))
                                                       if n != "line2_pressure_pa") for x in r)]))
gcase("gripper-missing-channel-column", gload("mc.csv", tail=FULL), expect="error",
      setup=gsession("mc.csv", lambda h, r: [",".join(c for c in h.split(",") if c != "ch48"),
                                            *(",".join(c for c, n in zip(x.split(","), h.split(",")) if n != "ch48")
                                              for x in r)]))
gcase("gripper-single-session-with-gripper-config", gload("lab/run.csv", tail=FULL), expect="error")
gcase("gripper-gripper-session-single-config", ["load", "lab/grip/session.csv", "--calibration",
                                                "lab/grip/calibration.yaml", *FULL])
gcase("gripper-native-single-with-gripper-config", gload("lab/native", tail=FULL), expect="error")
gcase("gripper-contact-then-plot-mcap", gload(tail=["reconstruct", "estimate", "--load", "contact", "plot",
                                                    "f.png", "mcap", "a.mcap"]), expect="ok")
gcase("gripper-track-bandwidth-tiny", gload(tail=[*FULL[:2], "track", "--bandwidth-hz", "1e-9", "save", "out"]))
gcase("gripper-track-bandwidth-nyquist", gload(tail=[*FULL[:2], "track", "--bandwidth-hz", "50", "save", "out"]))
gcase("gripper-track-window-huge", gload(tail=[*FULL[:2], "track", "--window-s", "1e6", "save", "out"]))
gcase("gripper-track-window-tiny", gload(tail=[*FULL[:2], "track", "--window-s", "1e-9", "save", "out"]))
gcase("gripper-track-without-estimate", gload(tail=["reconstruct", "track", "save", "out"]), expect="error")
gcase("gripper-estimate-twice-track", gload(tail=["reconstruct", "estimate", "estimate", "--load", "contact",
                                                  "track", "save", "out"]))
gcase("gripper-track-twice", gload(tail=[*FULL[:2], "track", "track", "--filter", "save", "out"]))


def configs(name, fn, expect="error", session="lab/grip/session.csv"):
    gcase(f"gripper-config-{name}", gload(session, config="g.yaml"), expect=expect,
          setup=gripper_yaml("g.yaml", fn))


configs("shared-line", finger(1, pressure_line=0), expect="any")  # one regulator for two fingers
configs("overlapping-channels", finger(1, channels=list(range(9, 25))))
configs("channels-beyond-session", finger(2, channels=list(range(49, 65))))
configs("line-beyond-session", finger(2, pressure_line=9))
configs("line-negative", finger(2, pressure_line=-1))
configs("line-float", finger(2, pressure_line=1.5))
configs("line-bool", finger(2, pressure_line=True))
configs("channel-zero", finger(0, channels=list(range(0, 16))))
configs("channels-15", finger(0, channels=list(range(1, 16))))
configs("channels-strings", finger(0, channels=[str(c) for c in range(1, 17)]))
configs("channels-duplicated-in-finger", finger(0, channels=[1] * 16))
configs("name-duplicate", finger(1, name="thumb"))
configs("name-empty", finger(1, name=""))
configs("name-slash", finger(1, name="in/dex"))
configs("name-dotdot", finger(1, name=".."))
configs("name-unicode", finger(1, name="índice✓"), expect="any")
configs("name-number", finger(1, name=7))
configs("name-newline", finger(1, name="in\ndex"))
configs("fingers-empty", lambda d: d.update(fingers=[]))
configs("fingers-mapping", lambda d: d.update(fingers={"thumb": d["fingers"][0]}))
configs("fingers-null-entry", lambda d: d["fingers"].append(None))
configs("finger-missing-line", lambda d: d["fingers"][0].pop("pressure_line"))
configs("finger-unknown-key", finger(0, stiffnes={"ei0_nm2": 1}))
configs("finger-partial-actuator", finger(0, actuator={"length_m": -0.1}))
gcase("gripper-config-yaml-anchors", gload(config="a.yaml"), expect="ok",  # one list twice: an anchor and an alias
      setup=gripper_yaml("a.yaml", lambda d: d["estimation"].update(direction=d["gravity"]["direction"])))
gcase("gripper-config-duplicate-key", gload(config="dk.yaml"), expect="error",
      setup=text("dk.yaml", lambda w: (w / "lab/grip/gripper.yaml").read_text(encoding="utf-8") + "fingers: []\n"))
gcase("gripper-calibration-missing-finger", gload(cal=("thumb=lab/grip/calibration.yaml",
                                                       "index=lab/grip/calibration.yaml")), expect="error")
gcase("gripper-calibration-single-actuator-for-all", gload(cal=("lab/cal.yaml",)), check=results_ok_sane)
gcase("gripper-calibration-8-channel-for-one",
      gload(cal=("middle=c8.yaml", "lab/grip/calibration.yaml")), expect="error",
      setup=edit_yaml("c8.yaml", "lab/cal.yaml", lambda d: [d.update({k: v[:8]}) for k, v in list(d.items())
                                                            if isinstance(v, list) and len(v) == 16]))
gcase("gripper-save-over-config-dir", gload(tail=[*GCHAIN_TAIL[:-1], "lab/grip", "--overwrite"]), expect="error")
gcase("gripper-save-finger-dir-is-file", gload(tail=GCHAIN_TAIL), setup=text("out/thumb", "mine\n"), expect="error")
gcase("gripper-process-track-mixed", ["process", "lab/grip/session.csv", "lab/run.csv", "--calibration",
                                      "lab/cal.yaml", "-o", "pout", "--track", "--workers", "0", "--no-progress"],
      timeout=180, check=lambda w, o: results_ok_sane(w, o, "pout"))

# --- tracking: the API and the CLI on odd arrays and sessions ------------------------------------

TV = """
    c = bs.Calibration.load(LAB + '/cal.yaml')
    s = bs.read_session_csv(LAB + '/tv/session.csv')
    import csv as _csv
    with open(LAB + '/tv/session.csv', newline='') as fh:
        _rows = [r for r in _csv.reader(fh) if r and not r[0].startswith('#')]
    _h = _rows[0]
    truth = np.array([[float(r[_h.index('fx_n')]), float(r[_h.index('fy_n')])] for r in _rows[1:]])
    n = 120  # 1.2 s of a time-varying load
    s = s.select(np.arange(400, 400 + n))
    truth = truth[400:400 + n]
    sh = bs.reconstruct(s.signals, c)
    e = bs.estimate_force(sh, s.pressure_pa, calibration=c)
    t, p = s.t_s, s.pressure_pa
    def track_sane(tr, truth=truth):
        f = np.asarray(tr.force_n, dtype=float).reshape(-1, 2)
        sd = np.asarray(tr.std_n, dtype=float).reshape(-1, 2)
        ok = np.asarray(tr.status).reshape(-1) == 'ok'
        if f.shape[0] != ok.size:
            wrong(f'{f.shape[0]} tracked forces for {ok.size} statuses')
            return
        bad = ok & ~(np.abs(f - truth[:f.shape[0]]) <= 8 * sd + 0.05).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            wrong(f'track ok at frame {k}: {f[k]} N, truth {truth[k]} N, sigma {sd[k]} N')
"""


def track_api(name, code, expect="any"):
    api_case(f"track-api-{name}", textwrap.dedent(TV) + textwrap.dedent(code), expect=expect, command="track")


track_api("baseline-smooth", "track_sane(bs.track(e, t, pressure_pa=p))", expect="ok")
track_api("baseline-filter", "track_sane(bs.track(e, t, mode='filter', pressure_pa=p))", expect="ok")
track_api("mode-bad", "bs.track(e, t, mode='kalman')", expect="error")
track_api("t-list", "track_sane(bs.track(e, list(t)))", expect="ok")
track_api("t-int", "track_sane(bs.track(e, (t * 100).astype(int)))")
track_api("t-float32", "track_sane(bs.track(e, t.astype(np.float32)))", expect="ok")
track_api("t-noncontiguous", "t2 = np.repeat(t, 2)[::2]\ntrack_sane(bs.track(e, t2))", expect="ok")
track_api("t-wrong-length", "bs.track(e, t[:-1])", expect="error")
track_api("t-2d", "bs.track(e, t[:, None])", expect="error")
track_api("t-scalar", "bs.track(e, 0.0)", expect="error")
track_api("t-nan", "t2 = t.copy(); t2[5] = np.nan\ntrack_sane(bs.track(e, t2))")
track_api("t-inf", "t2 = t.copy(); t2[-1] = np.inf\ntrack_sane(bs.track(e, t2))")
track_api("t-decreasing", "bs.track(e, t[::-1].copy())", expect="error")
track_api("t-all-equal", "track_sane(bs.track(e, np.zeros_like(t)))")
track_api("t-duplicated", "track_sane(bs.track(e, np.repeat(t[::2], 2)[:len(t)]))")
track_api("t-huge-gap", "t2 = t.copy(); t2[60:] += 1e6\ntrack_sane(bs.track(e, t2))")
track_api("t-1e300", "track_sane(bs.track(e, 1e300 + t * 1e290))")
track_api("t-35hz", "track_sane(bs.track(e, np.arange(n) / 35.0))")
track_api("t-2khz", "track_sane(bs.track(e, np.arange(n) / 2000.0))")
track_api("t-masked", "tm = np.ma.masked_array(t, mask=np.arange(n) % 7 == 0)\ntrack_sane(bs.track(e, tm))")
track_api("one-frame", """
    e1 = bs.estimate_force(bs.reconstruct(s.signals[:1], c), s.pressure_pa[:1], calibration=c)
    track_sane(bs.track(e1, t[:1]))
""")
track_api("two-frames", """
    e2 = bs.estimate_force(bs.reconstruct(s.signals[:2], c), s.pressure_pa[:2], calibration=c)
    track_sane(bs.track(e2, t[:2]))
""")
track_api("empty", """
    e0 = bs.estimate_force(bs.reconstruct(s.signals[:0], c), s.pressure_pa[:0], calibration=c)
    tr = bs.track(e0, t[:0])
    if np.asarray(tr.force_n).size:
        wrong('forces from no frames')
""")
track_api("single-frame-estimate", """
    e1 = bs.estimate_force(bs.reconstruct(s.signals[5], c), s.pressure_pa[5], calibration=c)
    track_sane(bs.track(e1, t[5]))
""")
track_api("all-frames-failed", """
    e2 = bs.estimate_force(bs.reconstruct(np.full((50, 16), np.nan), c), p[:50], calibration=c)
    tr = bs.track(e2, t[:50])
    if (np.asarray(tr.status) == 'ok').any():
        wrong('ok tracks from frames that all failed')
""")
track_api("no-noise-model", """
    e2 = bs.estimate_force(sh.curvature_per_m, p)  # no calibration: no noise model
    tr = bs.track(e2, t)
    if (np.asarray(tr.status) == 'ok').any() and not np.isfinite(np.asarray(tr.force_n)).all():
        wrong('ok with NaN tracked forces without a noise model')
""")
track_api("bandwidth-values", """
    for bw in (1e-9, 0.01, 1.0, 25.0, 49.9, 50.0, 1e6):
        try:
            track_sane(bs.track(e, t, bandwidth_hz=bw))
        except BendsenseError as err:
            print('refused', bw, err)
""")
for bw in ("0", "-1", "nan", "inf"):
    track_api(f"bandwidth-{bw}", f"bs.track(e, t, bandwidth_hz=float('{bw}'))", expect="error")
track_api("bandwidth-string", "bs.track(e, t, bandwidth_hz='fast')", expect="error")
track_api("bandwidth-array", "bs.track(e, t, bandwidth_hz=np.array([1.0, 2.0]))", expect="error")
track_api("window-zero", "bs.track(e, t, window_s=0)", expect="error")
track_api("window-nan", "bs.track(e, t, window_s=float('nan'))", expect="error")
track_api("window-huge", "track_sane(bs.track(e, t, window_s=1e9))")
track_api("pressure-wrong-length", "bs.track(e, t, pressure_pa=p[:-3])", expect="error")
track_api("pressure-nan", "p2 = p.copy(); p2[10:20] = np.nan\ntrack_sane(bs.track(e, t, pressure_pa=p2))")
track_api("pressure-kpa-steps", "track_sane(bs.track(e, t, pressure_pa=p / 1e3))")
track_api("estimate-not-estimate", "bs.track(np.zeros((n, 2)), t)", expect="error")
track_api("check-windows-baseline", """
    w = bs.check_windows(e, t, pressure_pa=p)
    if np.asarray(w.window_p_value).shape != (n,):
        wrong(f'window_p_value of shape {np.asarray(w.window_p_value).shape}')
""", expect="ok")
track_api("check-windows-35hz", "w = bs.check_windows(e, np.arange(n) / 35.0)")
track_api("check-windows-one-frame", "w = bs.check_windows(bs.estimate_force(sh[:1], p[:1], calibration=c), t[:1])")
track_api("check-windows-t-wrong-length", "bs.check_windows(e, t[:10])", expect="error")
track_api("check-windows-window-negative", "bs.check_windows(e, t, window_s=-0.05)", expect="error")
track_api("check-windows-t-nan", "t2 = t.copy(); t2[::3] = np.nan\nbs.check_windows(e, t2)")
track_api("check-windows-t-int", "bs.check_windows(e, (t * 1000).astype(np.int64))")
track_api("contact-baseline", """
    ec = bs.estimate_contact(sh, p, calibration=c, t_s=t)
    finite_ok(ec)
""", expect="ok")
track_api("contact-one-frame", "ec = bs.estimate_contact(bs.reconstruct(s.signals[100], c), p[100], calibration=c)\n"
                               "finite_ok(ec)")
track_api("contact-curvatures-int", "ec = bs.estimate_contact(np.zeros((5, 16), dtype=int), np.full(5, 5e4))\n"
                                    "finite_ok(ec)")
track_api("contact-curvatures-float32", "ec = bs.estimate_contact(sh.curvature_per_m[:50].astype(np.float32), "
                                        "p[:50], calibration=c)\nfinite_ok(ec)")
track_api("contact-empty", "ec = bs.estimate_contact(np.zeros((0, 16)), np.zeros(0))")
track_api("contact-nan", "ec = bs.estimate_contact(np.full((5, 16), np.nan), np.full(5, 5e4))\nfinite_ok(ec)")
track_api("contact-inf-pressure", "ec = bs.estimate_contact(sh, np.full(n, np.inf), calibration=c)\nfinite_ok(ec)\n"
                                  "if trusted(ec).any():\n    wrong('ok at infinite pressure')")
track_api("contact-wrong-width", "bs.estimate_contact(np.zeros((5, 9)), np.full(5, 5e4))", expect="error")
track_api("contact-3d", "bs.estimate_contact(np.zeros((2, 5, 16)), np.full((2, 5), 5e4))")
track_api("contact-t-wrong-length", "bs.estimate_contact(sh, p, calibration=c, t_s=t[:5])", expect="error")
track_api("contact-window-zero", "bs.estimate_contact(sh, p, calibration=c, t_s=t, window_s=0)", expect="error")
track_api("contact-threshold-nan", "bs.estimate_contact(sh, p, calibration=c, threshold=float('nan'))",
          expect="error")
track_api("contact-noise-negative", "bs.estimate_contact(sh, p, calibration=c, noise_std=-1.0)", expect="error")
track_api("contact-then-track", "ec = bs.estimate_contact(sh, p, calibration=c, t_s=t)\n"
                                "track_sane(bs.track(ec, t, pressure_pa=p))")
BOUND = "bs.estimation.cramer_rao.contact_bound"
track_api("contact-bound-broadcast-ok", f"{BOUND}(contact_s_m=[0.05, 0.1], force_n=0.1, pressure_pa=[[4e4], [6e4]])",
          expect="ok")
track_api("contact-bound-force-nan", f"{BOUND}(contact_s_m=0.1, force_n=float('nan'), pressure_pa=5e4)", expect="error")
track_api("contact-bound-frames-zero", f"{BOUND}(contact_s_m=0.1, force_n=0.1, pressure_pa=5e4, frames=0)",
          expect="error")

TVC = ["load", "lab/tv/session.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate"]


def tcli(name, args, expect="any", setup=None, check=None, timeout=120):
    case(f"track-cli-{name}", "track", args, expect=expect, setup=setup, check=check, timeout=timeout)


tcli("baseline", [*TVC, "track", "save", "out"], expect="ok", check=wrote("out/results.csv"))
tcli("filter", [*TVC, "track", "--filter", "save", "out"], expect="ok")
for bw in ("0", "-5", "nan", "inf", "1e400", "abc", ""):
    tcli(f"bandwidth-{bw or 'empty'}", [*TVC, "track", "--bandwidth-hz", bw, "save", "out"], expect="error")
for bw in ("1e-9", "49.99", "50", "1e6"):
    tcli(f"bandwidth-{bw}", [*TVC, "track", "--bandwidth-hz", bw, "save", "out"])
tcli("window-zero", [*TVC, "track", "--window-s", "0", "save", "out"], expect="error")
tcli("window-huge", [*TVC, "track", "--window-s", "1e9", "save", "out"])
tcli("filter-and-smooth", [*TVC, "track", "--filter", "--smooth", "save", "out"])
tcli("before-estimate", ["load", "lab/tv/session.csv", "--calibration", "lab/cal.yaml", "reconstruct", "track",
                         "save", "out"], expect="error")
tcli("without-calibration", ["load", "lab/tv/session.csv", "track", "save", "out"], expect="error")
tcli("contact-load", [*TVC[:-1], "estimate", "--load", "contact", "track", "save", "out"])
tcli("one-frame", ["load", "one.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track", "save",
                   "out"], setup=edit_csv("one.csv", lambda h, r: [h, r[0]], src="lab/tv/session.csv"))
tcli("two-frames", ["load", "two.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track", "save",
                    "out"], setup=edit_csv("two.csv", lambda h, r: [h, *r[500:502]], src="lab/tv/session.csv"))
tcli("35hz", ["load", "s.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track", "save", "out"],
     setup=edit_csv("s.csv", lambda h, r: [h, *(",".join([repr(k / 35.0), *x.split(",")[1:]])
                                               for k, x in enumerate(r))], src="lab/tv/session.csv"))
tcli("time-backwards", ["load", "b.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track", "save",
                        "out"], setup=edit_csv("b.csv", lambda h, r: [h, *r[::-1]], src="lab/tv/session.csv"))
tcli("duplicated-t", ["load", "d.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track", "save",
                      "out"], setup=edit_csv("d.csv", lambda h, r: [h, *(x for row in r[:300] for x in (row, row))],
                                             src="lab/tv/session.csv"))
tcli("constant-pressure", ["load", "cp.csv", "--calibration", "lab/cal.yaml", "reconstruct", "estimate", "track",
                           "save", "out"],
     setup=edit_csv("cp.csv", lambda h, r: [h, *(",".join([x.split(",")[0], "60000", *x.split(",")[2:]]) for x in r)],
                    src="lab/tv/session.csv"))
tcli("process-track-folder", ["process", "lab/tv", "lab/run.csv", "--calibration", "lab/cal.yaml", "-o", "pout",
                              "--track", "--workers", "0", "--no-progress"],
     check=lambda w, o: results_ok_sane(w, o, "pout"), timeout=180)
tcli("process-track-session-and-results", ["process", "lab/tv/session.csv", "lab/res", "--calibration",
                                           "lab/cal.yaml", "-o", "pout", "--track", "--workers", "0",
                                           "--no-progress"], timeout=180)
tcli("native-track", [*["load", "lab/native", "--calibration", "lab/cal.yaml", "reconstruct", "estimate"], "track",
                      "save", "out"])
tcli("track-plot-mcap", [*TVC, "track", "plot", "f.png", "mcap", "a.mcap"], expect="ok",
     check=wrote("f.png", "a.mcap"))
tcli("results-dir-as-input", ["load", "lab/res", "track", "save", "out"], expect="error")
tcli("copy-of-session-with-results", [*TVC, "track", "save", "lab/tv", "--overwrite"], expect="error",
     setup=steps(lambda w: shutil.copy(w / "lab/tv/session.csv", w / "lab/tv/copy.csv")))
