"""Nothing compiles or loads once the control loop runs: ``warm_up`` readies every kernel the loop meets.

``bendsense control`` runs against the simulated grasp board over a pseudo-terminal. The
board sends no pressure reading in some frames (a sensor glitch: a block with such
frames made the window check compile a second layout of its kernel in the loop), and
after the loop the warmed processor gets a block of 2,100 frames (a loop that fell two
seconds behind its board: the parallel batch kernels). A kernel that gets a new
compiled version after ``warm_up`` returned fails, whether numba compiled it (a cold
cache) or loaded it from the cache (a warm one, as here: the test does not depend on the
cache's state, and loading in the loop stalls it too); so does a frame the board sent
that the loop skipped, or a loop that fell behind.
"""

import csv
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from bendsense.control import CONTROL_LOG
from bendsense.device.simdevice import SimulatedDevice
from control.test_board import RATE, S_C, Truth, board, fresh_board  # noqa: F401 (the board fixtures)

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals"),
              pytest.mark.slow, pytest.mark.realtime]

SECONDS = 0.5

# the command, with a numba compile listener and a mark where warm_up returns; after the loop, a block of
# 2,100 frames through the same processor
CHILD = textwrap.dedent('''
    import json, sys
    import numpy as np
    from numba.core import event

    phase, compiled = ["setup"], {"setup": [], "warm_up": [], "after": []}


    def versions():  # every bendsense kernel's compiled versions in this process (compiled or loaded)
        from numba.core.dispatcher import Dispatcher
        return {f"{name}.{key}": len(obj.overloads) for name, module in list(sys.modules.items())
                if name.startswith("bendsense") for key, obj in list(vars(module).items())
                if isinstance(obj, Dispatcher)}

    class Compiles(event.Listener):
        def on_start(self, ev):
            compiled[phase[0]].append(ev.data["dispatcher"].py_func.__qualname__)

        def on_end(self, ev):
            pass

    event.register("numba:compile", Compiles())

    from bendsense import control
    from bendsense.cli import main
    from bendsense.pipeline import LiveProcessor

    warm_up, run, seen = LiveProcessor.warm_up, control.run, {}

    def watched_warm_up(self):
        phase[0] = "warm_up"
        warm_up(self)
        phase[0] = "after"
        seen["warm"] = versions()

    def watched_run(driver, processor, *args, **kwargs):
        seen["warm before the loop"] = phase[0] == "after"
        result = run(driver, processor, *args, **kwargs)
        seen["blocks"] = result.block_frames.tolist()
        seen["big block"] = len(processor.process_block(np.tile(processor.calibration.offset, (2100, 1)),
                                                        np.full(2100, 45e3), t_s=10.0 + np.arange(2100) * 1e-3))
        seen["new versions"] = sorted(k for k, n in versions().items() if n > seen["warm"].get(k, 0))
        return result

    LiveProcessor.warm_up, control.run = watched_warm_up, watched_run
    try:
        main(sys.argv[1:], standalone_mode=False)
    finally:
        print(json.dumps({**seen, "compiled": compiled}))
''')


class Glitching:
    """The board without a pressure reading in every 7th frame (the truth still records the frame)."""

    def __init__(self, source):
        self.board = source

    def __getattr__(self, name):  # the board's set-point input
        return getattr(self.board, name)

    def __call__(self, k):
        p, counts, truth = self.board(k)
        return (None if k % 7 == 3 else p), counts, truth


def test_a_control_run_readies_every_kernel_before_the_loop_and_processes_every_frame(board, calibration_path,  # noqa: F811
                                                                                        tmp_path):
    truth, out = Truth(), tmp_path / "s"
    with SimulatedDevice(Glitching(board), rate_hz=RATE, truth=truth) as dev:
        proc = subprocess.run([sys.executable, "-c", CHILD, "control", dev.port, "--calibration", str(calibration_path),
                               "--target-force-n", "0.15", "--load", "contact", "--contact-s-m", str(S_C),
                               "--seconds", str(SECONDS), "--silence-s", "1", "-o", str(out)],
                              capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout.splitlines()[-1])
    compiled = report["compiled"]
    assert report["warm"]["bendsense.pipeline._kernels.live_block"] >= 1  # warm_up readied the live step
    assert report["warm before the loop"]  # and the command called it before the loop
    # nothing compiled or loaded in the loop, nor for the big block after it
    assert compiled["after"] == [] and report["new versions"] == [], (compiled["after"], report["new versions"])
    assert report["big block"] == 2100
    # every frame the board sent, in order, up to the loop's last, is in the control log; the loop kept up
    with open(out / CONTROL_LOG, newline="") as fh:
        done = [int(row["seq"]) for row in csv.DictReader(fh)]
    sent = [row[0] for row in truth.rows]
    assert done == sent[:len(done)]
    in_time = int(np.count_nonzero(truth.t_s < truth.t_s[0] + SECONDS))
    assert len(done) >= 0.9 * in_time, (len(done), in_time)
    blocks = report["blocks"]
    assert sum(blocks) == len(done) and max(blocks[5:]) <= 0.1 * RATE, blocks  # behind by at most 0.1 s
