"""Frame decoder throughput and device-to-driver latency over a pseudo-terminal.

    python benchmarks/bench_frames.py

Prints one table: decoder throughput (16-channel SAMPLE frames, binary and line
dialects, several chunk sizes; a gripper's board: 48 channels and 3 pressure lines,
SAMPLE version 2), the cost of a SETPOINT sent by the driver, and the end-to-end latency
per frame from the moment a frame is written to the pseudo-terminal until the driver's
latest-value slot holds it.
Target (DESIGN.md section 5): decoder >= 20,000 frames/s.
"""

import os
import statistics
import time
import tty

import numpy as np

from bendsense.device import Driver, SimulatedDevice, ramp_source
from bendsense.wire.frames import Decoder, LineDecoder, encode_sample

N_CH = 16
N_FRAMES = 50_000


def stream(n=N_FRAMES):
    rng = np.random.default_rng(0)
    counts = rng.integers(0, 4096, size=(n, N_CH))
    binary = b"".join(encode_sample(i, 2000 * i, counts[i].tolist(), 20_000) for i in range(n))
    lines = "".join(f"{i},{2000 * i},20000," + ",".join(map(str, counts[i])) + "\n" for i in range(n)).encode()
    return binary, lines


def stream_gripper(n=N_FRAMES, n_ch=48, n_lines=3):
    """A gripper's board: ``n_ch`` channels and ``n_lines`` pressure lines per SAMPLE (version 2)."""
    rng = np.random.default_rng(1)
    counts = rng.integers(0, 4096, size=(n, n_ch))
    lines = 20_000 + rng.integers(0, 100_000, size=(n, n_lines))
    return b"".join(encode_sample(i, 2000 * i, counts[i].tolist(), pressures_pa=lines[i].tolist()) for i in range(n))


def setpoint_cost(n=5000):
    """Time per Driver.send_setpoint (validate, encode, write to a pseudo-terminal) [us], median and p99."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    times = []
    try:
        with Driver(os.ttyname(slave), handshake=False, queue_size=None) as drv:
            for k in range(n):
                t0 = time.perf_counter_ns()
                drv.send_setpoint(k % 3, 50_000.0 + k)
                times.append((time.perf_counter_ns() - t0) / 1e3)
                if k % 100 == 99:
                    try:
                        os.read(master, 1 << 16)  # the board's side drains the line
                    except BlockingIOError:
                        pass
    finally:
        os.close(master)
        os.close(slave)
    return np.percentile(times, [50, 99])


def throughput(make, data, chunk, repeat=3):
    best = np.inf
    for _ in range(repeat):
        dec = make()
        t = time.perf_counter()
        for i in range(0, len(data), chunk):
            dec.feed(data[i : i + chunk])
        best = min(best, time.perf_counter() - t)
    assert dec.frames == N_FRAMES and dec.errors == 0 and dec.lost == 0
    return N_FRAMES / best


def latency(n=1000, spacing_s=0.002):
    """Write frames one by one to a pty master; time until Driver.latest() holds each."""
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    read_lat, visible_lat = [], []
    try:
        with Driver(port, handshake=False, queue_size=None) as drv:
            time.sleep(0.05)
            for seq in range(n):
                frame = encode_sample(seq, 0, [seq % 4096] * N_CH)
                t0 = time.monotonic_ns()
                os.write(master, frame)
                while True:
                    r = drv.latest()
                    if r is not None and r.sample.seq == seq:
                        break
                    time.sleep(20e-6)  # a spinning poller would starve the reader thread of the GIL
                visible_lat.append((time.monotonic_ns() - t0) / 1e3)
                read_lat.append((r.host_ns - t0) / 1e3)
                time.sleep(spacing_s)
    finally:
        os.close(master)
        os.close(slave)
    return read_lat, visible_lat


def sustained(rate_hz, seconds=2.0):
    """Frames/s the simulated board + driver sustain without loss at ``rate_hz``."""
    n = int(rate_hz * seconds)
    with SimulatedDevice(ramp_source(N_CH), rate_hz=rate_hz, max_frames=n) as sim, Driver(sim.port) as drv:
        t = time.monotonic()
        drv.start()
        got = 0
        while not (sim.finished.is_set() and got >= sim.stats.sent):
            got += len(drv.get_batch(timeout=0.1))
        dt = time.monotonic() - t
    return got / dt, drv.stats.lost, sim.stats.tx_overflow


def main():
    binary, lines = stream()
    rows = []
    for chunk in (64, 512, 4096, 65536):
        rows.append((f"binary decoder, {chunk} B chunks", throughput(Decoder, binary, chunk), "frames/s"))
    rows.append(("line decoder, 4096 B chunks", throughput(lambda: _line(), lines, 4096), "frames/s"))
    rows.append(("binary decoder, gripper board (48 ch, 3 lines, v2), 4096 B chunks",
                 throughput(Decoder, stream_gripper(), 4096), "frames/s"))
    q = setpoint_cost()
    rows.append(("Driver.send_setpoint (encode + pty write), median / p99", f"{q[0]:.1f} / {q[1]:.1f}", "us"))
    t = time.perf_counter()
    for i in range(10_000):
        encode_sample(i, i, range(N_CH), 20_000)
    rows.append(("encode_sample", 10_000 / (time.perf_counter() - t), "frames/s"))
    read_lat, visible_lat = latency()
    for name, lat in (
        ("pty write -> reader thread has bytes", read_lat),
        ("pty write -> Driver.latest()", visible_lat),
    ):
        q = np.percentile(lat, [50, 99])
        rows.append((f"{name}, median / p99", f"{q[0]:.0f} / {q[1]:.0f}", "us"))
    for rate in (500, 2000):
        fps, lost, overflow = sustained(rate)
        rows.append(
            (f"sim board -> driver queue at {rate} Hz", f"{fps:.0f} (lost {lost}, tx overflow {overflow})", "frames/s")
        )

    print(f"bendsense frames benchmark ({N_CH} channels unless said, {N_FRAMES} frames; target >= 20,000 frames/s)")
    width = max(len(r[0]) for r in rows)
    for name, value, unit in rows:
        value = f"{value:,.0f}" if isinstance(value, float) else value
        print(f"  {name.ljust(width)}  {value:>28}  {unit}")
    print(f"  (latency over {len(visible_lat)} frames; mean {statistics.mean(visible_lat):.0f} us)")


def _line():
    return LineDecoder(columns=("seq", "t_us", "pressure_pa", *(f"ch{i + 1}" for i in range(N_CH))))


if __name__ == "__main__":
    main()
