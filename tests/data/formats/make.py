"""Write the frozen format fixtures that tests/integration/test_formats_frozen.py loads.

    python tests/data/formats/make.py          # stream_v1.bin, session_v2/
    python tests/data/formats/make.py lines    # stream_v2_lines.bin, session_v2_lines/

One run of the simulated board (wire protocol version 1), read by the driver and
recorded by the recorder as ``bendsense record`` does:

- ``stream_v1.bin``: every byte the driver read from the board, in order;
- ``session_v2/``: the native session (format version 2) the recorder wrote from them.

And one run of a gripper's board (SAMPLE version 2, three pressure lines: a replayed
session), written by ``main_lines``:

- ``stream_v2_lines.bin``: every byte the driver read;
- ``session_v2_lines/``: the native session (format version 2 with ``n_lines: 3``).

The board starts shortly before the wraps of its sequence number and its u32 clock,
drops and corrupts a few frames, sends a TEXT and, every 37th frame, no pressure, so
that the two files hold what a reader must get right. They are committed and the test
checks the committed files: run this only to add the fixtures of a new format version
(then rename the outputs below, beside the old ones, which must keep loading).
"""

import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2] / "src"))

from bendsense.device.driver import Driver  # noqa: E402
from bendsense.device.recorder import Recorder  # noqa: E402
from bendsense.device.simdevice import Faults, Firmware, SimulatedDevice, default_source  # noqa: E402

STREAM = HERE / "stream_v1.bin"
SESSION = HERE / "session_v2"
FRAMES = 300
RATE_HZ = 1000.0


class CapturingDriver(Driver):
    """The driver, keeping a copy of every chunk of bytes it reads from the port."""

    def __init__(self, *args, **kwargs):
        self.captured = []
        super().__init__(*args, **kwargs)

    def _handle(self, data, host_ns):
        self.captured.append(bytes(data))
        super()._handle(data, host_ns)


def wait_for(condition, timeout_s=10.0):
    end = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > end:
            raise SystemExit("the simulated board or the recorder stalled")
        time.sleep(0.01)


def main():
    scenario = default_source(n_channels=16, adc_bits=12, rate_hz=RATE_HZ, seed=13)

    def source():
        for k, (pressure, counts) in enumerate(scenario):
            if k == FRAMES // 2:
                sim.send_text("fixture: a log line from the firmware")  # sent after the burst at hand
            yield (None if k % 37 == 5 else pressure), counts

    shutil.rmtree(SESSION, ignore_errors=True)
    sim = SimulatedDevice(source(), rate_hz=RATE_HZ, n_channels=16, adc_bits=12,
                          faults=Faults(drop=0.02, corrupt=0.01, seed=13), max_frames=FRAMES,
                          firmware=Firmware(start_seq=65536 - 120, start_t_us=2**32 - 100_000))
    with sim, CapturingDriver(sim.port) as drv:
        rec = Recorder(drv, SESSION, meta={"fixture": "tests/data/formats/make.py"})
        drv.start()
        rec.start()
        wait_for(sim.finished.is_set)
        wait_for(lambda: drv.queued == 0 and rec.stats.records == drv.stats.samples)
        rec.stop()
    STREAM.write_bytes(b"".join(drv.captured))
    print(f"{STREAM.name}: {STREAM.stat().st_size} bytes; {SESSION.name}: {rec.stats.records} records; {sim.stats}")


STREAM_LINES = HERE / "stream_v2_lines.bin"
SESSION_LINES = HERE / "session_v2_lines"
FRAMES_LINES = 150


def main_lines():
    import numpy as np

    from bendsense.device.replay import ReplayDevice
    from bendsense.session import Session

    k = np.arange(FRAMES_LINES)
    pressure = np.column_stack([20_000.0 + 100.0 * k, 30_000.0 + 50.0 * k, 40_000.0 - 20.0 * k])
    pressure[k % 23 == 4, 2] = np.nan  # line 2 without a reading now and then
    pressure[k % 41 == 7, 0] = np.nan  # and line 0 (offset 12 says "no reading" too)
    counts = (k[:, None] * 13 + 211 * np.arange(8)[None, :]) % 4096
    seq = (65536 - 60 + k) % 65536  # the sequence wraps
    session = Session(k * 1e-3, counts.astype(float), pressure, seq=seq, extra={"status": (k % 5 == 0) * 2})
    shutil.rmtree(SESSION_LINES, ignore_errors=True)
    dev = ReplayDevice(session, adc_bits=12, faults=Faults(drop=0.02, corrupt=0.02, seed=5))
    with dev, CapturingDriver(dev.port) as drv:
        rec = Recorder(drv, SESSION_LINES, meta={"fixture": "tests/data/formats/make.py"})
        drv.start()
        rec.start()
        wait_for(dev.finished.is_set)
        wait_for(lambda: drv.queued == 0 and rec.stats.records == drv.stats.samples)
        rec.stop()
    STREAM_LINES.write_bytes(b"".join(drv.captured))
    print(f"{STREAM_LINES.name}: {STREAM_LINES.stat().st_size} bytes; {SESSION_LINES.name}: {rec.stats.records} "
          f"records; {dev.stats}")


if __name__ == "__main__":
    if sys.argv[1:] == ["lines"]:
        main_lines()
    else:
        main()
