"""Every frame live: ``record --estimate`` writes results.csv as frames arrive (crash-safe), ``--lsl`` streams."""

import csv
import dataclasses
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import bendsense
from bendsense._batched import take_frames
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.device.simdevice import Faults, SimulatedDevice, default_source
from bendsense.pipeline import LiveProcessor
from bendsense.sim.scenarios import time_varying_frames
from bendsense.status import Status
from bendsense.tracking import DEFAULT_BANDWIDTH_HZ

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals"),
              pytest.mark.realtime]
SEED = 0
CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


def read_rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_record_estimate_every_frame_of_a_2khz_board(calibration_path, tmp_path):
    out = tmp_path / "s"
    # the frames computed ahead, so that the simulated board keeps its 2 kHz on a busy machine
    frames = list(time_varying_frames(None, 2000.0, SEED, duration_s=3.0))
    with SimulatedDevice(frames, rate_hz=2000) as dev:
        res = CliRunner().invoke(main, ["record", dev.port, "-o", str(out), "--seconds", "2",
                                        "--calibration", str(calibration_path), "--estimate",
                                        "--constraint", "normal"])
    assert res.exit_code == 0, res.output
    session = bendsense.read_session(out)
    assert len(session) > 3000 and session.meta["stats"]["queue_drops"] == 0
    header, rows = read_rows(out / "results.csv")
    # DESIGN section 3: the result columns end with status, the tracked force, the window p-value, then the
    # session's extra columns
    assert header[:2] == ["t_s", "pressure_pa"] and header[-16:] == [
        "tip_angle_rad", "fx_n", "fy_n", "fx_std_n", "fy_std_n", "residual_m", "status",
        "fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n", "track_status", "window_p_value",
        "host_s", "input_status", "tx_drops"]
    assert len(rows) == len(session)  # every recorded frame has a result
    cols = {h: np.array([r[i] for r in rows]) for i, h in enumerate(header)}
    np.testing.assert_array_equal(cols["t_s"].astype(float), session.t_s)
    np.testing.assert_array_equal(cols["pressure_pa"].astype(float), session.pressure_pa)
    assert np.mean(cols["status"] == "ok") > 0.99
    # the same frames through an independent path: the chain's batch estimate of the recorded session
    config = bendsense.load_config()
    cal = Calibration.load(calibration_path)
    shape = bendsense.reconstruct(session.signals, cal, config.sensor, s_m=np.linspace(0, config.sensor.length_m, 41))
    batch = bendsense.estimate_force(shape, session.pressure_pa, config, constraint="normal", calibration=cal)
    ok = (cols["status"] == "ok") & np.asarray(batch.success)
    force = np.column_stack([cols["fx_n"], cols["fy_n"]]).astype(float)
    np.testing.assert_allclose(force[ok], batch.force_n[ok], atol=1e-4)
    np.testing.assert_allclose(cols["tip_x_m"].astype(float), shape.tip_position_m[:, 0], atol=1e-12)
    assert "estimated" in res.output and "backlog" in res.output
    # the causal track of the recording, block by block as frames arrived, is the filter over the whole session
    # (a frame the live warm start could not estimate is not a measurement of the live filter either)
    live_failed = ~np.isfinite(force).all(axis=1)
    batch = dataclasses.replace(batch, force_n=np.where(live_failed[:, None], np.nan, batch.force_n))
    offline = bendsense.track(batch, session.t_s, mode="filter", bandwidth_hz=DEFAULT_BANDWIDTH_HZ,
                              pressure_pa=session.pressure_pa)
    tracked = np.column_stack([cols["fx_track_n"], cols["fy_track_n"]]).astype(float)
    tracked_std = np.column_stack([cols["fx_track_std_n"], cols["fy_track_std_n"]]).astype(float)
    assert np.isfinite(tracked).all(axis=1).mean() > 0.99
    np.testing.assert_allclose(tracked, offline.force_n, atol=1e-4, equal_nan=True)
    np.testing.assert_allclose(tracked_std, offline.std_n, rtol=1e-3, equal_nan=True)
    # the frames' own verdicts are kept: never ok where the frame is not
    assert not np.any((cols["track_status"] == "ok") & (cols["status"] != "ok"))


def test_killed_recording_keeps_its_results(calibration_path, tmp_path):
    """SIGKILL: results.csv holds whole rows for a prefix of the recorded frames, synced within a second."""
    out = tmp_path / "s"
    with SimulatedDevice(default_source(rate_hz=500, seed=SEED), rate_hz=500) as dev:
        with open(tmp_path / "stderr.txt", "wb") as err:
            proc = subprocess.Popen([*CLI, "-q", "record", dev.port, "-o", str(out), "--calibration",
                                     str(calibration_path), "--estimate", "--quiet-status"],
                                    stdout=subprocess.DEVNULL, stderr=err)
        try:
            end = time.monotonic() + 60
            while not ((out / "results.csv").exists() and (out / "results.csv").stat().st_size > 20_000):
                assert time.monotonic() < end and proc.poll() is None, (tmp_path / "stderr.txt").read_text()
                time.sleep(0.05)
            time.sleep(1.2)
            synced = (out / "results.csv").stat().st_size
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    session = bendsense.read_session(out)
    raw = (out / "results.csv").read_bytes()
    assert raw.endswith(b"\n") and len(raw) >= synced  # whole rows only; nothing lost of what was written
    header, rows = read_rows(out / "results.csv")
    assert all(len(r) == len(header) for r in rows)
    assert 0 < len(rows) <= len(session)
    np.testing.assert_array_equal([float(r[0]) for r in rows], session.t_s[: len(rows)])


def test_record_estimate_needs_a_calibration(tmp_path):
    res = CliRunner().invoke(main, ["record", "/dev/null", "-o", str(tmp_path / "s"), "--estimate"])
    assert res.exit_code == 2 and "--estimate needs --calibration" in res.output
    assert not (tmp_path / "s").exists()


def test_processor_block_equals_frames_one_by_one(calibration_path):
    """A block and the same frames one at a time (blocks of one) give the same shapes, forces and tracked forces."""
    frames = [next(src) for src in [default_source(rate_hz=100, seed=SEED)] for _ in range(40)]
    signals = np.array([c for _, c in frames], dtype=float)
    pressure = np.array([p for p, _ in frames])
    cal = Calibration.load(calibration_path)
    block = LiveProcessor(cal, constraint="normal").process_block(signals, pressure, t_s=np.arange(40) / 100)
    proc = LiveProcessor(cal, constraint="normal")
    one = [proc.process_signals(a, p, t_s=k / 100) for k, (a, p) in enumerate(zip(signals, pressure))]
    np.testing.assert_allclose(block.force_n, [f.force_n for f in one], atol=1e-6)
    np.testing.assert_allclose(block.shape.positions_m, [f.shape.positions_m for f in one], atol=1e-12)
    # the causal track, its state kept from block to block
    assert np.isfinite(block.track_force_n).all(axis=1).mean() > 0.9
    np.testing.assert_allclose(block.track_force_n, [f.track_force_n for f in one], atol=1e-6)
    np.testing.assert_allclose(block.track_std_n, [f.track_std_n for f in one], rtol=1e-6, atol=1e-7)  # as the forces
    cols = block.columns()
    assert list(cols)[-7:] == ["status", "fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n",
                               "track_status", "window_p_value"] and len(cols["fx_n"]) == 40
    # a frame without pressure gets a shape and the status "no_pressure"
    pressure[5] = np.nan
    b2 = LiveProcessor(cal, constraint="normal").process_block(signals, pressure, t_s=np.arange(40) / 100)
    assert b2.status[5] == Status.NO_PRESSURE and np.isnan(b2.force_n[5]).all() and np.isfinite(b2.force_n[6]).all()
    assert b2.frame(5).estimate is None and b2.frame(6).estimate is not None


def test_record_estimate_writes_the_columns_of_save(calibration_path, tmp_path):
    """The live results.csv has the header of 'load SESSION reconstruct estimate track --filter save' of the same
    session, and its pass-through columns equal those the saved results read from frames.bin."""
    out = tmp_path / "s"
    with SimulatedDevice(default_source(rate_hz=500, seed=SEED), rate_hz=500,
                         faults=Faults(drop=0.05, seed=SEED)) as dev:
        res = CliRunner().invoke(main, ["record", dev.port, "-o", str(out), "--seconds", "1",
                                        "--calibration", str(calibration_path), "--estimate", "--quiet-status"])
    assert res.exit_code == 0, res.output
    saved = tmp_path / "saved"
    res = CliRunner().invoke(main, ["load", str(out), "--calibration", str(calibration_path), "reconstruct",
                                    "estimate", "track", "--filter", "save", str(saved)])
    assert res.exit_code == 0, res.output
    live_header, live_rows = read_rows(out / "results.csv")
    save_header, save_rows = read_rows(saved / "results.csv")
    assert live_header == save_header
    assert live_header[-10:] == ["status", "fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n",
                                 "track_status", "window_p_value", "host_s", "input_status", "tx_drops"]
    assert len(live_rows) == len(save_rows) == len(bendsense.read_session(out)) > 300
    for name in ("t_s", "host_s", "input_status", "tx_drops"):
        i = live_header.index(name)
        assert [r[i] for r in live_rows] == [r[i] for r in save_rows], name
    # and against the records of frames.bin, read here with yaml and numpy alone
    meta = yaml.safe_load((out / "meta.yaml").read_text())
    dtype = np.dtype([(name, "<u2", (meta["n_channels"],)) if name == "adc" else (name, t)
                      for name, t in meta["record_dtype"]])
    raw = np.fromfile(out / "frames.bin", dtype=dtype)
    cols = {h: [r[i] for r in live_rows] for i, h in enumerate(live_header)}
    assert raw["tx_drops"].max() > 0  # the board dropped frames: the counter is not all zeros
    np.testing.assert_array_equal(np.array(cols["host_s"], float), (raw["host_ns"] - raw["host_ns"][0]) * 1e-9)
    np.testing.assert_array_equal(np.array(cols["input_status"], int), raw["status"])
    np.testing.assert_array_equal(np.array(cols["tx_drops"], int), raw["tx_drops"])


def test_block_without_pressure_keeps_the_column_order(calibration_path):
    """No frame with a pressure (NaN forces): the same columns in the same order as a block with one."""
    frames = [next(src) for src in [default_source(rate_hz=100, seed=SEED)] for _ in range(5)]
    signals = np.array([c for _, c in frames], dtype=float)
    extra = {"host_s": np.arange(5.0), "status": np.zeros(5, int)}
    cal = Calibration.load(calibration_path)
    with_p = LiveProcessor(cal).process_block(signals, [p for p, _ in frames], extra=extra).columns()
    without = LiveProcessor(cal).process_block(signals, None, extra=extra).columns()
    assert list(without) == list(with_p)
    assert list(with_p)[-9:] == ["status", "fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n",
                                 "track_status", "window_p_value", "host_s", "input_status"]
    assert list(without["status"]) == list(without["track_status"]) == ["no_pressure"] * 5
    assert np.isnan(without["fx_track_n"]).all()


def test_record_estimate_of_no_frames_writes_no_results(calibration_path, tmp_path):
    """A board that never starts: an empty session, no results.csv, and a message that says so (as 'save',
    which refuses a session without frames)."""
    out = tmp_path / "s"
    with SimulatedDevice(default_source(rate_hz=500, seed=SEED), rate_hz=500) as dev:
        res = CliRunner().invoke(main, ["record", dev.port, "-o", str(out), "--seconds", "0.3", "--no-start",
                                        "--calibration", str(calibration_path), "--estimate", "--quiet-status"])
    assert res.exit_code == 0, res.output
    assert len(bendsense.read_session(out)) == 0 and (out / "frames.bin").stat().st_size == 0
    assert not (out / "results.csv").exists()
    assert "no frames to estimate: no results.csv written" in res.output
    assert "estimated to" not in res.output
    saved = CliRunner().invoke(main, ["load", str(out), "--calibration", str(calibration_path), "reconstruct",
                                      "estimate", "save", str(tmp_path / "saved")])
    assert saved.exit_code != 0 and "no frames" in saved.output and not (tmp_path / "saved").exists()


def test_a_clock_that_jumps_back_restarts_the_live_track(calibration_path):
    """A device reset mid-block (its clock jumps back): the causal track restarts there, each stretch the filter
    of its own frames; nothing fails."""
    frames = [next(src) for src in [default_source(rate_hz=100, seed=SEED)] for _ in range(160)][100:]
    signals = np.array([c for _, c in frames], dtype=float)
    pressure = np.array([p for p, _ in frames])
    t = np.concatenate([np.arange(30), np.arange(30)]) / 100  # the clock back to 0 at frame 30
    cal = Calibration.load(calibration_path)
    proc = LiveProcessor(cal, constraint="normal")
    first = proc.process_block(signals[:40], pressure[:40], t_s=t[:40])  # the jump inside a block
    second = proc.process_block(signals[40:], pressure[40:], t_s=t[40:])
    tracked = np.concatenate([first.track_force_n, second.track_force_n])
    config = bendsense.load_config()
    shape = bendsense.reconstruct(signals, cal, config.sensor, s_m=proc.s_m)
    cold = bendsense.estimate_force(shape, pressure, config, constraint="normal", calibration=cal)
    for part in (slice(0, 30), slice(30, 60)):
        offline = bendsense.track(take_frames(cold, part, 60), t[part], mode="filter",
                                  bandwidth_hz=DEFAULT_BANDWIDTH_HZ, pressure_pa=pressure[part])
        np.testing.assert_allclose(tracked[part], offline.force_n, atol=1e-5)
    assert np.isfinite(tracked).all()
    # the block ran in two calls of the step, one per stretch: each frame's own outputs where they belong
    np.testing.assert_allclose(first.force_n, np.asarray(cold.force_n)[:40], atol=1e-5)
    np.testing.assert_allclose(first.std_n, np.asarray(cold.std_n)[:40], rtol=1e-4)
    np.testing.assert_allclose(first.shape.positions_m, np.asarray(shape.positions_m)[:40], atol=1e-12)
    assert (first.status == bendsense.results.frame_codes(take_frames(shape, slice(0, 40), 60),
                                                          take_frames(cold, slice(0, 40), 60))).all()
    assert first.estimate.status.shape == (40,) and proc.estimated == 60
