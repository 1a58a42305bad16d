"""The contact load end to end: ``estimate --load contact``, ``process``, ``record --estimate`` on sessions of an
independent beam (tests/forward_model.py: scipy's solve_bvp with the load at s_c, a hidden sensor, a fitted
calibration)."""

import csv
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.results import read_results
from bendsense.session import Session, write_session_csv

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parents[1]))
from forward_model import HiddenSensor, forward  # noqa: E402

CFG = bendsense.load_config()
L = CFG.actuator.length_m
RATE_HZ = 2000.0
HOLD = 100  # frames of a quasi-static hold: one 50 ms window at 2 kHz
#: (pressure [Pa], force (Fx, Fy) [N], s_c [m]) of each hold; None: a tip load
HOLDS = [(80e3, (-0.20, -0.05), 0.09), (100e3, (-0.15, -0.08), 0.11), (60e3, (-0.12, 0.0), 0.10),
         (90e3, (-0.10, -0.05), None)]


def _session(hidden, holds, seed):
    rng = np.random.default_rng(seed)
    signals, pressure, truth = [], [], {"fx_n": [], "fy_n": [], "contact_s_m": []}
    for p, force, s_c in holds:
        shifts = forward(CFG, p, force, contact_s_m=s_c).shifts_m
        signals.append(hidden.signals(np.tile(shifts, (HOLD, 1)), rng))
        pressure.append(np.full(HOLD, p))
        truth["fx_n"].append(np.full(HOLD, force[0]))
        truth["fy_n"].append(np.full(HOLD, force[1]))
        truth["contact_s_m"].append(np.full(HOLD, L if s_c is None else s_c))
    n = HOLD * len(holds)
    return Session(np.arange(n) / RATE_HZ, np.concatenate(signals), np.concatenate(pressure),
                   extra={k: np.concatenate(v) for k, v in truth.items()})


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A hidden sensor at 1.5 counts, its fitted calibration, and a session of the holds above."""
    root = tmp_path_factory.mktemp("contact-chain")
    hidden = HiddenSensor(noise_counts=1.5, seed=7)
    Calibration.fit(hidden.write_calibration(root / "cal", CFG)).save(root / "cal.yaml")
    write_session_csv(_session(hidden, HOLDS, 11), root / "holds.csv")
    write_session_csv(_session(hidden, [(80e3, (-0.2, -0.05), 0.09)] * 2, 12), root / "known.csv")
    return root


def _chain(root, session, out, *estimate):
    res = CliRunner().invoke(main, ["load", str(root / session), "--calibration", str(root / "cal.yaml"),
                                    "reconstruct", "estimate", *estimate, "save", str(root / out)])
    assert res.exit_code == 0, res.output
    return read_results(root / out)


@pytest.fixture(scope="module")
def known(work):
    """The chain on the session of contacts at 0.09 m: with that location known, and with the tip load."""
    return {"contact": _chain(work, "known.csv", "known", "--load", "contact", "--contact-s-m", "0.09"),
            "tip": _chain(work, "known.csv", "known-tip")}


def test_a_known_location_writes_it_and_is_closer_than_the_tip_model(known):
    contact, tip = known["contact"], known["tip"]
    header = list(contact.columns)
    assert header[header.index("fy_std_n") + 1:header.index("fy_std_n") + 3] == ["contact_s_m", "contact_std_m"]
    assert (contact["contact_s_m"] == 0.09).all() and (contact["contact_std_m"] == 0).all()
    np.testing.assert_array_equal(contact["input_contact_s_m"], 0.09)  # the truth column, never posing
    truth = np.column_stack([contact["input_fx_n"], contact["input_fy_n"]])
    err = {name: np.column_stack([r["fx_n"], r["fy_n"]]) - truth for name, r in (("contact", contact), ("tip", tip))}
    std = np.column_stack([contact["fx_std_n"], contact["fy_std_n"]])
    # the hold's mean error: noise averages down, the calibration error does not; within 3 σ of a frame
    assert (np.abs(err["contact"].mean(axis=0)) < 3 * std.mean(axis=0)).all()
    # the tip model puts the same shape's load at L: it is further off than the contact model at the right s_c
    assert np.linalg.norm(err["tip"].mean(axis=0)) > 2 * np.linalg.norm(err["contact"].mean(axis=0))


def test_a_contact_at_the_tip_is_the_tip_load(work, known):
    """s_c = L is the tip load through the same kernels: the same forces."""
    at_l = _chain(work, "known.csv", "at-l", "--load", "contact", "--contact-s-m", repr(L))
    tip = known["tip"]
    np.testing.assert_allclose(at_l["fx_n"], tip["fx_n"], atol=1e-6)
    np.testing.assert_allclose(at_l["fy_n"], tip["fy_n"], atol=1e-6)
    assert "contact_s_m" not in tip.columns


def test_an_unknown_location_per_window(work):
    res = _chain(work, "holds.csv", "unknown", "--load", "contact", "--window-s", "0.05")
    s_c, std = res["contact_s_m"], res["contact_std_m"]
    truth = res["input_contact_s_m"]
    for k, (_, _, true_s) in enumerate(HOLDS):
        hold = slice(k * HOLD, (k + 1) * HOLD)
        # one location per window: a hold is one window
        assert len(set(s_c[hold].tolist())) == 1 or np.isnan(s_c[hold]).all()
        if true_s is not None and np.isfinite(std[hold][0]):
            assert abs(s_c[hold][0] - truth[hold][0]) < 4 * std[hold][0] + 1e-3, (k, s_c[hold][0], std[hold][0])
    contact_holds = [k for k, h in enumerate(HOLDS) if h[2] is not None]
    resolved = [k for k in contact_holds if np.isfinite(std[k * HOLD])]
    assert resolved, "no contact hold resolved"
    status = np.asarray(res["status"])
    assert (status[np.isinf(std)] != "ok").all()


def test_process_runs_the_contact_chain(work, known):
    out = work / "batch"
    res = CliRunner().invoke(main, ["process", str(work / "known.csv"), "--calibration", str(work / "cal.yaml"),
                                    "-o", str(out), "--load", "contact", "--contact-s-m", "0.09", "--workers", "0",
                                    "--no-progress"])
    assert res.exit_code == 0, res.output
    batch = read_results(out / "known")
    chain = known["contact"]
    for name in ("fx_n", "fy_n", "fx_std_n", "contact_s_m", "contact_std_m", "status"):
        np.testing.assert_array_equal(batch[name], chain[name])


def test_record_estimate_at_a_known_location(tmp_path, calibration_path):
    from bendsense.device.simdevice import SimulatedDevice, default_source

    shutil.copyfile(calibration_path, tmp_path / "cal.yaml")
    out = tmp_path / "rec"
    with SimulatedDevice(default_source(rate_hz=500, seed=0), rate_hz=500) as dev:
        cli = [sys.executable, "-c", "from bendsense.cli import main; main()", "-q"]
        proc = subprocess.run([*cli, "record", dev.port, "-o", str(out), "--seconds", "1.5", "--calibration",
                               str(tmp_path / "cal.yaml"), "--estimate", "--load", "contact", "--contact-s-m", "0.1",
                               "--quiet-status"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    header, rows = rows[0], rows[1:]
    i = header.index("fy_std_n")
    assert header[i + 1:i + 3] == ["contact_s_m", "contact_std_m"] and len(rows) > 100
    has_force = [r for r in rows if r[header.index("fx_n")] not in ("", "nan")]
    assert has_force and {r[i + 1] for r in has_force} == {"0.1"} and {r[i + 2] for r in has_force} == {"0.0"}
