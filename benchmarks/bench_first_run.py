"""The first run after an install, and a notebook's first call beside other work.

Prints one table:

- ``bendsense demo`` on an empty numba cache (``NUMBA_CACHE_DIR`` a new temporary
  directory, so the kernels compile as on the first run after ``pip install``): wall
  time, and the CPU time of the demo and the process that compiles beside it;
- the same demo again on the now-filled cache;
- a notebook's first ``estimate_force`` with a calibration (a fresh interpreter, kernels
  cached: importing, loading the kernels, the calibration's error tables), alone and
  beside a CPU-bound process on every core, with the BLAS threads as numpy starts them
  (the library limits its own linear algebra to one thread, the CLI's
  ``OPENBLAS_NUM_THREADS=1`` is not set here).

    python benchmarks/bench_first_run.py [--quick]

``--quick`` skips the cold demo (a minute or more) and measures the rest once.
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np, bendsense
from bendsense.calibration import Calibration
cal = Calibration.load({cal!r})
bendsense.estimate_force(np.full(16, 5.0), 40e3, bendsense.load_config(), calibration=cal)
print(time.perf_counter() - t0)
"""


def _env(cache):
    """The environment of a user's fresh shell: BLAS threads as numpy starts them, the numba cache ``cache``."""
    blas = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in blas}
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return env


def demo(cache: Path, out: Path) -> tuple[float, float]:
    """Wall and CPU seconds (this process's children) of one ``bendsense demo``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    command = [str(Path(sys.executable).with_name("bendsense")), "demo", "-o", str(out), "--overwrite"]
    subprocess.run(command, check=True, env=_env(cache), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def first_call(cal: Path, cache: Path, busy: bool) -> float:
    """Seconds from a fresh interpreter to the end of its first estimate (with ``busy`` CPU-bound processes)."""
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 1)] if busy \
        else []
    try:
        time.sleep(0.5 if busy else 0.0)
        out = subprocess.run([sys.executable, "-c", FIRST_CALL.format(cal=str(cal))], check=True, capture_output=True,
                             text=True, env=_env(cache))
        return float(out.stdout.split()[-1])
    finally:
        for h in hogs:
            h.kill()
            h.wait()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="skip the cold demo; every call once")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cache = None if args.quick else tmp / "numba-cache"  # --quick: the installed package's own cache
        if cache is not None:
            wall, cpu = demo(cache, tmp / "demo")
            rows.append(("bendsense demo, empty numba cache (first run)", f"{wall:.1f} s wall, {cpu:.1f} s CPU",
                         "<= 60 s"))
        wall, cpu = demo(cache, tmp / "demo")
        rows.append(("bendsense demo, cache filled", f"{wall:.1f} s wall, {cpu:.1f} s CPU", ""))
        cal = tmp / "demo" / "calibration" / "calibration.yaml"
        for busy in (False, True):
            times = [first_call(cal, cache, busy) for _ in range(1 if args.quick else 3)]
            label = "first estimate_force in a fresh interpreter" + (", every core busy" if busy else ", idle")
            rows.append((label, f"{min(times):.2f} s (best of {len(times)}), worst {max(times):.2f} s", ""))
    width = max(len(r[0]) for r in rows)
    print(f"{'what':{width}}  {'measured':40}  target")
    for what, value, target in rows:
        print(f"{what:{width}}  {value:40}  {target}")


if __name__ == "__main__":
    main()
