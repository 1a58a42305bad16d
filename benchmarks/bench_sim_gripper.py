"""Does the simulated gripper board keep its frame rate? (python benchmarks/bench_sim_gripper.py [--quick])

The board of ``sim-device --fingers K`` (:class:`bendsense.sim.gripper.GraspBoard`: a
first-order regulator per line, each finger pressing a rigid object, its equilibrium
tabulated over pressure at the start) measured three ways:

- the table's build per finger (once, before the port is printed);
- the board's cost per frame (regulators, table lookups, noise) and the SAMPLE v2
  encoding, for 1, 3 and 4 fingers;
- the board on a pseudo-terminal at 1 kHz with 3 fingers and its truth file, read by the
  real driver for a few seconds while the host sends SETPOINTs: SAMPLEs received against
  the frames due, sequence gaps, and the CPU time of the process (the board's thread and
  the driver's reader thread together).
"""

import argparse
import os
import tempfile
import time

RATE_HZ = 1000.0


def _per_frame(k: int, n: int) -> tuple:
    from bendsense.sim.gripper import GraspBoard, default_objects, gripper_config
    from bendsense.wire.frames import encode_sample

    t0 = time.perf_counter()
    board = GraspBoard(gripper_config(k), default_objects(k), rate_hz=RATE_HZ, seed=0)
    build = (time.perf_counter() - t0) / k
    for i in range(200):  # warm
        board(i)
    t0 = time.perf_counter()
    frames = [board(i) for i in range(200, 200 + n)]
    board_s = (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    for i, (p, counts, _) in enumerate(frames):
        encode_sample(i, i, counts.tolist(), pressures_pa=p)
    encode_s = (time.perf_counter() - t0) / n
    return build, board_s, encode_s


def _on_a_port(seconds: float) -> dict:
    from bendsense.device import Driver, SimulatedDevice
    from bendsense.sim.gripper import GraspBoard, default_objects, gripper_config
    from bendsense.sim.truth import TruthWriter, truth_columns

    board = GraspBoard(gripper_config(3), default_objects(3), rate_hz=RATE_HZ, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        truth = TruthWriter(os.path.join(tmp, "truth.csv"), truth_columns(board.truth_fingers, board.n_lines))
        with SimulatedDevice(board, rate_hz=RATE_HZ, n_channels=board.n_channels, truth=truth) as dev, \
                Driver(dev.port) as driver:
            driver.start()
            time.sleep(0.3)
            driver.get_batch(timeout=0.1)
            before, cpu0, t0 = driver.stats, time.process_time(), time.monotonic()
            sent = 0
            while time.monotonic() - t0 < seconds:
                driver.get_batch(timeout=0.05)
                if sent < 3 and time.monotonic() - t0 > (sent + 1) * seconds / 4:
                    driver.send_setpoint(sent, 50e3 + 5e3 * sent)
                    sent += 1
            elapsed, cpu = time.monotonic() - t0, time.process_time() - cpu0
            after = driver.stats
            driver.stop()
        truth.close()
        rows = truth.rows
    return {"elapsed_s": elapsed, "samples": after.samples - before.samples, "lost": after.lost - before.lost,
            "cpu_s": cpu, "setpoints": dev.stats.setpoints, "truth_rows": rows}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a short run: fewer frames, 1.5 s on the port")
    args = ap.parse_args(argv)
    n = 1000 if args.quick else 10_000
    seconds = 1.5 if args.quick else 6.0
    print(f"simulated gripper board, {RATE_HZ:g} Hz (load average {os.getloadavg()[0]:.2f})")
    for k in (1, 3, 4):
        build, board_s, encode_s = _per_frame(k, n)
        print(f"  {k} finger(s): table {build:.2f} s per finger; per frame: board {board_s * 1e6:.0f} us, "
              f"SAMPLE v2 encoding {encode_s * 1e6:.0f} us")
    r = _on_a_port(seconds)
    due = r["elapsed_s"] * RATE_HZ
    print(f"  on a pseudo-terminal, 3 fingers: {r['samples']} SAMPLEs in {r['elapsed_s']:.3f} s "
          f"({r['samples'] / r['elapsed_s']:.1f}/s, {due:.0f} due), {r['lost']} lost, {r['setpoints']} SETPOINTs "
          f"taken, {r['truth_rows']} truth rows; board + driver CPU {100 * r['cpu_s'] / r['elapsed_s']:.0f} % "
          f"of a core")


if __name__ == "__main__":
    main()
