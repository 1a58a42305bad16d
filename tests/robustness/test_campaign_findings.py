"""What the hostile-input campaign (tools/campaign.py) found after the fixes of issue 21, each provoked here.

A strip radius no sensor can wrap, a bending angle beyond a full turn, sequence numbers
that stand still, a directory or a regular file given as the serial port, and a
message that printed numpy's repr of its numbers.
"""

import logging

import numpy as np
import pytest

import bendsense
from bendsense.device.driver import Driver
from bendsense.errors import ArgumentError, DeviceError, SessionError
from bendsense.estimation import cramer_rao
from bendsense.identify import read_free_bending_csv
from bendsense.session.native import record_dtype, records_to_session


def test_a_bending_angle_beyond_a_full_turn_is_refused_naming_its_line(tmp_path):
    path = tmp_path / "b.csv"
    path.write_text("pressure_kpa,bending_angle_deg\n20,25\n40,1e308\n60,80\n")
    with pytest.raises(SessionError, match=r"b\.csv: line 3, column bending_angle_deg: .* more than a full turn"):
        read_free_bending_csv(path)
    path.write_text("pressure_kpa,bending_angle_deg\n20,25\n40,300\n60,350\n")  # within a turn: read
    assert read_free_bending_csv(path)[1][-1] == pytest.approx(np.deg2rad(350))


@pytest.mark.parametrize("seq, lost", [([5, 5, 5, 5], 0), ([0, 1, 4, 5], 2), ([0, 2, 2, 5], 3),
                                       ([65534, 65535, 0, 2], 1)])
def test_frames_lost_counts_the_gaps_never_a_repeat(seq, lost, caplog):
    records = np.zeros(len(seq), dtype=record_dtype(2))
    records["seq"] = seq
    records["t_us"] = np.arange(len(seq)) * 1000
    records["host_ns"] = np.arange(len(seq)) * 1_000_000
    with caplog.at_level(logging.WARNING):
        session = records_to_session(records, {})
    assert session.meta["frames_lost"] == lost


@pytest.mark.parametrize("kind", ["a directory", "a regular file"])
def test_a_path_that_is_no_serial_port_is_named_as_what_it_is(tmp_path, kind):
    port = tmp_path / "lab"
    port.mkdir() if kind == "a directory" else port.write_text("t_s,ch1\n")
    with pytest.raises(DeviceError, match=rf"^{port}: {kind}, not a serial port"):
        Driver(str(port)).open()


@pytest.mark.parametrize("port, said", [("", "port: empty"), ("  ", "port: empty"),
                                        ("/dev/null", "/dev/null: a device that is no terminal, not a serial port")])
def test_an_empty_port_or_a_device_that_is_no_terminal_is_named(port, said):
    with pytest.raises(DeviceError) as err:
        Driver(port).open()
    assert str(err.value).startswith(said) and "Errno" not in str(err.value) and "ioctl" not in str(err.value)


def test_record_on_a_regular_file_is_one_line_without_a_blank_one_before(tmp_path):
    """The status line is ended before an error only when one was drawn: none before the port opened."""
    import subprocess
    import sys

    (tmp_path / "session.csv").write_text("t_s,ch1\n0,1\n")
    out = subprocess.run([sys.executable, "-c", "from bendsense.cli import main; main()", "record",
                          str(tmp_path / "session.csv"), "-o",
                          str(tmp_path / "rec")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 1 and out.stderr.startswith(f"Error: {tmp_path / 'session.csv'}: a regular file")
    assert out.stderr.count("\n") == 1 and not (tmp_path / "rec").exists()


def test_a_message_shows_numbers_not_numpys_repr():
    with pytest.raises(ArgumentError) as err:
        bendsense.solve_beam(0.13, 2.5e-3, 5.0, s_m=[0, 0.5, 1.0])
    assert "np.float64" not in str(err.value) and "got [0, 1]" in str(err.value)


def test_times_and_bounds_show_numbers_not_numpys_repr():
    with pytest.raises(ArgumentError) as err:
        cramer_rao.contact_bound(contact_s_m=0.1, force_n=float("nan"), pressure_pa=5e4)
    assert str(err.value).endswith("got nan")
    est = bendsense.estimate_force(np.full((3, 16), 5.0), 5e4)
    with pytest.raises(ArgumentError) as err:
        bendsense.check_windows(est, np.array([0.0, 0.002, 0.001]))
    assert "np.float64" not in str(err.value) and "got 0.001 s after 0.002 s" in str(err.value)
