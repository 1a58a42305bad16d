"""Recording over pyserial URLs: a real local RFC 2217 server in front of the simulated board."""

import socket
import threading

import numpy as np
import pytest
import serial
import serial.rfc2217
from click.testing import CliRunner

from bendsense import read_session
from bendsense.cli import main
from bendsense.device.driver import Driver
from bendsense.device.simdevice import Faults, SimulatedDevice, ramp_source

# pyserial's RFC 2217 client starts its reader thread with the deprecated setDaemon(), setName()
pytestmark = [
    pytest.mark.filterwarnings("ignore:setDaemon\\(\\) is deprecated:DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:setName\\(\\) is deprecated:DeprecationWarning"),
]


class _Connection:
    """The socket as PortManager wants it (``write``)."""

    def __init__(self, sock):
        self.sock = sock

    def write(self, data):
        self.sock.sendall(data)


class _PtyPort:
    """The pseudo-terminal as PortManager drives it: it has no modem lines (RTS, DTR, break)."""

    def __init__(self, ser):
        object.__setattr__(self, "_ser", ser)

    def __getattr__(self, name):
        try:
            return getattr(self._ser, name)
        except OSError:  # a modem line (cts, dsr, ri, cd) of a pty
            return False

    def __setattr__(self, name, value):
        try:
            setattr(self._ser, name, value)
        except OSError:  # ioctl on a pty: inappropriate, as on a USB CDC board
            pass


class RFC2217Server:
    """pyserial's PortManager (the server side of RFC 2217) bridging TCP to ``port`` (one client)."""

    def __init__(self, port: str):
        self.port = port
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"rfc2217://127.0.0.1:{self.listener.getsockname()[1]}"
        self.stop = threading.Event()
        self.threads = []

    def __enter__(self):
        self.threads.append(threading.Thread(target=self._accept, daemon=True))
        self.threads[-1].start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.listener.close()
        for t in self.threads:
            t.join(2.0)

    def _accept(self):
        self.listener.settimeout(0.1)
        while not self.stop.is_set():
            try:
                conn, _ = self.listener.accept()
            except (TimeoutError, OSError):
                continue
            self._serve(conn)

    def _serve(self, conn):
        """Bridge one client connection and the pseudo-terminal until either side ends."""
        conn.settimeout(0.05)
        ser = serial.serial_for_url(self.port, timeout=0.02)
        manager = serial.rfc2217.PortManager(_PtyPort(ser), _Connection(conn))
        done = threading.Event()

        def to_client():
            while not (self.stop.is_set() or done.is_set()):
                data = ser.read(4096)
                if data:
                    try:
                        conn.sendall(b"".join(manager.escape(data)))
                    except OSError:
                        break
            done.set()

        def from_client():
            while not (self.stop.is_set() or done.is_set()):
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                ser.write(b"".join(manager.filter(data)))
            done.set()

        workers = [threading.Thread(target=to_client, daemon=True), threading.Thread(target=from_client, daemon=True)]
        for w in workers:
            w.start()
        done.wait()
        for w in workers:
            w.join(1.0)
        ser.close()
        conn.close()


@pytest.fixture
def board():
    with SimulatedDevice(ramp_source(4), n_channels=4, rate_hz=500, faults=Faults(drop=0.1, seed=3)) as sim:
        yield sim


def test_rfc2217_plain_pyserial_refuses_write_timeout(board):
    # the reason the driver retries without it
    with RFC2217Server(board.port) as server, pytest.raises(NotImplementedError):
        serial.serial_for_url(server.url, timeout=0.02, write_timeout=1.0)


def test_driver_handshakes_over_rfc2217(board):
    with RFC2217Server(board.port) as server, Driver(server.url, hello_timeout_s=5.0) as drv:
        assert drv.hello is not None and drv.n_channels == 4
        drv.start()
        readings = []
        while len(readings) < 50:
            readings += drv.get_batch(timeout=2.0)
        assert all(r.sample.n_channels == 4 for r in readings)


def test_record_cli_over_rfc2217_reports_firmware_drops(board, tmp_path):
    with RFC2217Server(board.port) as server:
        res = CliRunner().invoke(main, ["record", server.url, "-o", str(tmp_path / "s"), "--seconds", "1",
                                        "--hello-timeout", "5", "--quiet-status"])
    assert res.exit_code == 0, res.output
    session = read_session(tmp_path / "s")
    assert len(session) > 100 and session.meta["finished"]
    gaps = int(np.sum(np.diff(session.seq) - 1))
    # every frame the simulated firmware dropped is counted in its tx_drops: the gaps in
    # the sequence numbers and the firmware's counter agree (dropped with p = 0.1)
    assert gaps > 0 and session.meta["tx_drops"] == gaps == session.meta["frames_lost"]
    assert session.meta["stats"]["tx_drops"] == gaps
    assert f"({gaps} dropped by the firmware)" in res.output
