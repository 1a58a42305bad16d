"""A stop signal stops a command with its one line and exit status, whatever a call under it made of the signal.

Seen by a campaign of signals sent to ``live`` at random moments: numba unboxing a typed
list reports an interrupted unboxing as ``TypeError: can't unbox ...``, matplotlib in the
middle of a draw as ``ValueError: Invalid affine transformation matrix`` (a traceback and
exit 1 instead of 128 + the signal), an exception in a finaliser is only printed (the
signal lost, the command running on), and a second signal while the interpreter exits
killed the finished command by that signal.
"""

import os
import signal
import subprocess
import sys
import time

import pytest
from click.testing import CliRunner

from bendsense.cli import _signals, main
from bendsense.device.simdevice import SimulatedDevice, default_source

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="POSIX signals")


def signalled():
    """Send this process SIGHUP and wait for the handler's KeyboardInterrupt."""
    os.kill(os.getpid(), signal.SIGHUP)
    time.sleep(2.0)
    raise AssertionError("no KeyboardInterrupt within 2 s of the signal")


def test_an_error_a_call_made_of_the_signal_is_the_interrupt():
    with _signals.installed(), pytest.raises(KeyboardInterrupt) as info, _signals.interrupting():
        try:
            signalled()
        except KeyboardInterrupt:
            raise TypeError("can't unbox a <class 'numba.typed.typedlist.List'> as a <NULL>") from None
    assert isinstance(info.value.__cause__, TypeError)


def test_a_swallowed_signal_still_ends_the_block_with_the_interrupt():
    with _signals.installed(), pytest.raises(KeyboardInterrupt) as info, _signals.interrupting():
        try:
            signalled()
        except KeyboardInterrupt:
            pass  # "Exception ignored in ...": a finaliser's
    assert info.value.__cause__ is None


# llvmlite's callback from compiled code (its object cache, called while numba compiles or loads a kernel), as a
# ctypes callback of the same file name: here called back by libc's qsort
CALLBACK = """
import ctypes, ctypes.util, os, signal

calls = []

@ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int))
def compare(a, b):
    if not calls:
        os.kill(os.getpid(), signal.SIGHUP)  # the handler runs here, inside the callback
        for _ in range(1000):
            pass
    calls.append(1)
    return a[0] - b[0]

def sort(values):
    array = (ctypes.c_int * len(values))(*values)
    ctypes.CDLL(ctypes.util.find_library("c")).qsort(array, len(values), ctypes.sizeof(ctypes.c_int), compare)
    return list(array)
"""


def test_a_signal_inside_a_compiled_callback_comes_again_after_it(capfd):
    """A KeyboardInterrupt raised inside a ctypes callback is printed ("Exception ignored on calling ctypes
    callback function") and dropped: numba compiling a kernel when Ctrl-C came went on, and the command finished
    with status 0. The signal is sent again after the callback, and stops the command there."""
    space: dict = {}
    exec(compile(CALLBACK, "/site-packages/llvmlite/binding/executionengine.py", "exec"), space)
    with _signals.installed(), pytest.raises(KeyboardInterrupt):
        assert space["sort"]([3, 1, 2]) == [1, 2, 3]  # the callback came back whole
        assert not _signals.stopping()  # (not yet: the signal comes again)
        time.sleep(2.0)
    assert _signals.exit_code() == 129
    assert "Exception ignored" not in capfd.readouterr().err

def test_without_a_signal_an_error_is_itself():
    with _signals.installed(), pytest.raises(ValueError, match="a bad value"), _signals.interrupting():
        raise ValueError("a bad value")


def live(tmp_path, calibration_path, monkeypatch, run_live):
    """``bendsense live`` (headless) on the simulated board, with ``run_live`` in place of the live loop."""
    import bendsense.apps.live_view as view

    monkeypatch.setattr(view, "run_live", run_live)
    with SimulatedDevice(default_source(rate_hz=200, seed=0), rate_hz=200) as dev:
        return CliRunner().invoke(main, ["live", dev.port, "--calibration", str(calibration_path), "--save",
                                         str(tmp_path / "fig.png"), "--seconds", "30"])


def assert_interrupted(res):
    assert res.exit_code == 129, res.output
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert lines[-1].startswith("Interrupted (SIGHUP): ") and "Traceback" not in res.output, res.output


def test_live_stopped_while_it_draws_is_interrupted(tmp_path, calibration_path, monkeypatch):
    def drawing(*args, **kw):
        try:
            signalled()
        except KeyboardInterrupt:
            raise ValueError("Invalid affine transformation matrix") from None

    res = live(tmp_path, calibration_path, monkeypatch, drawing)
    assert_interrupted(res)
    assert "no figure saved" in res.output and not (tmp_path / "fig.png").exists()


def test_live_whose_signal_was_swallowed_stops_at_its_next_turn(tmp_path, calibration_path, monkeypatch):
    def swallowing(driver, processor, view, *, is_open, **kw):
        try:
            signalled()
        except KeyboardInterrupt:
            pass
        end = time.monotonic() + 10.0
        while is_open() and time.monotonic() < end:  # the loop's turns: the window open, --seconds not over
            time.sleep(0.01)
        assert not is_open()  # the signal closes it

    assert_interrupted(live(tmp_path, calibration_path, monkeypatch, swallowing))


def test_a_second_signal_while_the_finished_command_exits_keeps_its_status(tmp_path):
    # the interpreter's exit takes a moment (threads, pools, finalisers): here an exit handler of 3 s
    script = ("import atexit, sys, time\n"
              "atexit.register(lambda: (print('exiting', flush=True), time.sleep(3)))\n"
              "sys.argv = ['bendsense', '--version']\n"
              "from bendsense.cli import run\n"
              "run()\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        while not lines or lines[-1] != "exiting\n":
            lines.append(proc.stdout.readline())
            assert lines[-1], (lines, proc.stderr.read())
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0, proc.stderr.read()  # not -15: killed by the signal after it had finished
        assert "version" in "".join(lines)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
