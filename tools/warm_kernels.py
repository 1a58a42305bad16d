"""Fill numba's cache with the kernels that ``bendsense demo`` leaves uncompiled, two processes at a time.

CI runs it after its first-run demo and before the suite: a developer's machine has every
kernel cached, and the suite's time (DESIGN.md section 5) is that of the tests, not of the
one-off compiles a fresh install pays on first use of tracking, batches and contacts
(~1.5 min on a 2-core machine). Each job is a process of its own, as a user's command is.

    python tools/warm_kernels.py
"""

import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

# three jobs, each a family of kernels: a batch above bendsense._jit.PARALLEL_MIN frames (the prange kernels, the
# kinematics' too) with the tracker and its window check; contact loads, known and not; the paper's baseline, the
# positions objective, adapt and the live tracker (a gripper's per-finger kernels are the single finger's)
SETUP = """
import numpy as np
from bendsense.calibration import Calibration
from bendsense.pipeline import process
from bendsense.session import Session, read_session
from bendsense.sim.scenarios import simulate

simulate("calibration", "cal", seed=0, frames_per_strip=20)
calibration = Calibration.fit("cal/manifest.yaml")
simulate("time-varying", "tv", seed=0)
tv = read_session("tv/session.csv")
rows = np.resize(np.arange(len(tv)), 3000)
session = Session(0.01 * np.arange(rows.size), tv.signals[rows], tv.pressure_pa[rows])
"""
JOBS = {
    "tracking, batch": "process(session, None, calibration, constraint='normal', track='smooth')\n"
                       "process(session, None, calibration, constraint='none', track='filter')\n"
                       "from bendsense import load_config\n"
                       "from bendsense.shape.pcc import forward_kinematics\n"
                       "lengths = np.asarray(load_config().sensor.segment_lengths_m)\n"
                       "forward_kinematics(np.zeros((rows.size, lengths.size)), lengths, [0.0, 0.1])",
    "contact": "process(session, None, calibration, constraint='normal', load='contact', contact_s_m=0.1)\n"
               "process(session, None, calibration, constraint='normal', load='contact')",
    "baseline, positions, adapt, live": """
from bendsense import adapt, load_config
from bendsense.shape.pcc import forward_kinematics
from bendsense.pipeline import LiveProcessor
short = Session(session.t_s[:40], session.signals[:40], session.pressure_pa[:40])
process(short, None, calibration, constraint='normal', method='paper')
done = process(short, None, calibration, constraint='normal', objective='positions')
forward_kinematics(done.shape.curvature_per_m, load_config().sensor.segment_lengths_m, [0.0, 0.1])
adapt(done.shape, short.pressure_pa, load_config(), calibration=calibration, t_s=short.t_s)
live = LiveProcessor(calibration, load_config(), track=True)
live.warm_up()
for k in range(0, 40, 10):
    live.process_block(session.signals[k:k + 10], session.pressure_pa[k:k + 10], t_s=session.t_s[k:k + 10])
""",
}


def run(name: str, code: str) -> str:
    """Run one job in a fresh process in a temporary directory; its line for the log."""
    with tempfile.TemporaryDirectory() as where:
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", SETUP + code], cwd=where, capture_output=True, text=True)
        if done.returncode:
            raise SystemExit(f"warm_kernels: {name} failed:\n{done.stderr}")
        return f"{name}: {time.perf_counter() - t0:.1f} s"


def main() -> None:
    """Every job, two at a time."""
    t0 = time.perf_counter()
    with ThreadPoolExecutor(2) as pool:
        for line in pool.map(run, JOBS, JOBS.values()):
            print(f"warm_kernels: {line}", flush=True)
    print(f"warm_kernels: {time.perf_counter() - t0:.1f} s in all", flush=True)


if __name__ == "__main__":
    main()
