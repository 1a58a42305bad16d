"""The recipes of docs/architecture.md ("Where do I add ..."), each done once.

Nothing here changes the library: a new constraint is registered in a separate Python
process (the registry is read when the modules are imported), a new output format is a
writer and a chain step defined in the test, a calibration model is built from its
coefficients.
"""

import json
import math
import subprocess
import sys
import textwrap
import time

import click
import numpy as np
import pytest
from click.testing import CliRunner
from helpers import SENSOR, linear_calibration, signals_for

from bendsense import output
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.cli._common import InterspersedCommand, overwrite_option, step_io
from bendsense.session import Session, write_session_csv
from bendsense.shape.pcc import reconstruct

# --------------------------------------------------------------------------- a constraint

NEW_CONSTRAINT = textwrap.dedent(
    """
    import dataclasses, json, math
    import numpy as np
    import bendsense.choices as choices

    # step 1: one entry in the registry, before anything reads it
    choices.CONSTRAINTS = (*choices.CONSTRAINTS, "diagonal")

    # step 2: its kind of D, a fixed direction at 45 degrees
    from bendsense import estimation
    from bendsense.estimation import problem

    original = problem.constraint_kind

    def constraint_kind(constraint, direction=(0.0, -1.0)):
        if constraint == "diagonal":
            return original("direction", (math.sqrt(0.5), math.sqrt(0.5)))
        return original(constraint, direction)

    problem.constraint_kind = estimation.constraint_kind = constraint_kind

    import bendsense
    from bendsense.cli import main

    offered = {}
    for name, command in main.commands.items():
        for param in command.params:
            if param.name == "constraint":
                offered[name] = list(param.type.choices)
    config = bendsense.load_config()
    config = config.replace(estimation=dataclasses.replace(config.estimation, constraint="diagonal"))
    from bendsense.sim.actuator import SimulatedActuator

    # the curvatures of the actuator at 60 kPa under 0.1 N along (1, 1)/sqrt(2)
    truth = np.full((1, 2), 0.1 * math.sqrt(0.5))
    kappa = SimulatedActuator.from_config(config, noise_counts=0.0).frames(
        np.array([60e3]), truth, noise=False).curvature_per_m[0]
    new = bendsense.estimate_force(kappa, 60e3, config, constraint=None)  # None: the config's
    same = bendsense.estimate_force(kappa, 60e3, config, constraint="direction",
                                    direction=(math.sqrt(0.5), math.sqrt(0.5)))
    print(json.dumps({"offered": offered, "new": new.force_n.tolist(), "same": same.force_n.tolist(),
                      "success": bool(new.success), "constraint": new.constraint}))
    """
)


def test_a_new_constraint():
    out = subprocess.run([sys.executable, "-c", NEW_CONSTRAINT], capture_output=True, text=True, check=True)
    got = json.loads(out.stdout.splitlines()[-1])
    # every command with --constraint offers it: the CLI's choices follow the registry
    assert set(got["offered"]) >= {"estimate", "process", "record", "live"}
    assert all(choices[-1] == "diagonal" for choices in got["offered"].values()), got["offered"]
    # the config accepted it, and the estimate is the one along the same direction
    assert got["success"] and got["constraint"] == "diagonal"
    np.testing.assert_allclose(got["new"], got["same"], rtol=0, atol=1e-12)
    fx, fy = got["new"]
    assert fx == pytest.approx(fy, abs=1e-12)  # along (1, 1)/√2
    assert math.hypot(fx, fy) == pytest.approx(0.1, abs=2e-3)  # the simulated load (PCC curvatures: ~mN bias)


def test_the_registry_is_where_the_cli_reads_its_choices():
    # in this process, unpatched: the choices each option offers are the registry's, in its order
    from bendsense import choices

    for command in main.commands.values():
        if not any(p.name == "constraint" for p in command.params):
            continue  # (identify's --method is the beam solver's, another choice)
        for param in command.params:
            registry = {"constraint": choices.CONSTRAINTS, "method": choices.METHODS,
                        "objective": choices.OBJECTIVES, "tip_angle_source": choices.ANGLE_SOURCES}.get(param.name)
            if registry is not None and isinstance(param.type, click.Choice):
                assert tuple(param.type.choices) == registry, (command.name, param.name)


# --------------------------------------------------------------------------- a wire field


def test_the_sample_fields_reach_every_layer(tmp_path):
    import dataclasses

    from bendsense import read_session, read_session_csv
    from bendsense.device import Driver, Recorder, SimulatedDevice, ramp_source
    from bendsense.session.native import export_session_csv, record_dtype
    from bendsense.wire.frames import SAMPLE_FIELDS, Sample

    # the table's fields are the SAMPLE's scalar values (adc and its count apart), and the record's
    table = [f.name for f in SAMPLE_FIELDS]
    assert set(table) == {f.name for f in dataclasses.fields(Sample)} - {"n_channels", "adc"}
    assert record_dtype(4).names == ("host_ns", *table, "adc")
    # and goes from the wire through the recorder to the Session, and through the session CSV
    frames = 40
    with SimulatedDevice(ramp_source(4), n_channels=4, rate_hz=1000, max_frames=frames) as sim, \
            Driver(sim.port) as drv:
        rec = Recorder(drv, tmp_path / "s")
        drv.start()
        rec.start()
        deadline = time.monotonic() + 20
        while rec.stats.records < frames and time.monotonic() < deadline:
            time.sleep(0.01)
        rec.stop()
    session = read_session(tmp_path / "s")
    assert len(session) == frames
    np.testing.assert_array_equal(session.seq, session.seq[0] + np.arange(frames))  # seq, none lost
    np.testing.assert_array_equal(session.pressure_pa, 20_000.0)  # pressure_pa
    np.testing.assert_allclose(np.diff(session.t_s), 1e-3, atol=1e-6)  # t_us, at 1 kHz
    assert {"status", "tx_drops"} <= set(session.extra)  # the fields without a column of their own
    export_session_csv(tmp_path / "s", tmp_path / "s.csv")
    again = read_session_csv(tmp_path / "s.csv")
    for name in ("status", "tx_drops"):
        np.testing.assert_array_equal(again.extra[name], session.extra[name])


# --------------------------------------------------------------------------- a calibration model


def test_a_calibration_model_given_by_its_coefficients(tmp_path):
    # S = a ΔA + b ΔA² with its own pair per parity, as a datasheet or another fitter might give it
    a_odd, b_odd, a_even, b_even = 2.0e-6, 1.0e-10, -1.8e-6, 2.0e-10
    offset = 1500.0 + 5.0 * np.arange(16)
    model = Calibration(offset=offset, coefficients_odd=[0.0, a_odd, b_odd], coefficients_even=[0.0, a_even, b_even],
                        degree=2, delta_a_range_odd=(-4000.0, 4000.0), delta_a_range_even=(-4000.0, 4000.0),
                        noise_std=np.full(16, 1.5), sensor=SENSOR)
    model.save(tmp_path / "model.yaml")
    cal = Calibration.load(tmp_path / "model.yaml")
    np.testing.assert_array_equal(cal.coefficients_odd, [0.0, a_odd, b_odd])
    np.testing.assert_array_equal(cal.coefficients_even, [0.0, a_even, b_even])
    # signals for known curvatures, by the quadratic formula per channel
    kappa = np.array([np.linspace(2.0, 12.0, 16), np.full(16, -5.0)])
    shifts = SENSOR.strip_gap_m * np.cumsum(kappa * SENSOR.lengths_m, axis=-1)
    odd = np.arange(16) % 2 == 0
    a, b = np.where(odd, a_odd, a_even), np.where(odd, b_odd, b_even)
    delta = (-a + np.sign(a) * np.sqrt(a**2 + 4.0 * b * shifts)) / (2.0 * b)
    signals = offset + delta
    np.testing.assert_allclose(cal.shifts_m(signals), shifts, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(cal.shift_slopes(signals), a + 2.0 * b * delta, rtol=1e-12)
    shape = reconstruct(signals, cal, SENSOR)
    np.testing.assert_allclose(shape.curvature_per_m, kappa, rtol=1e-8, atol=1e-8)
    assert not np.any(shape.extrapolated)


# --------------------------------------------------------------------------- an output format


def write_results_json(path, session, shape, estimate=None, *, overwrite=False):
    """The recipe's writer: the per-frame tip and force as JSON, through the output layer."""
    # the mark (output.MARK) lets a later --overwrite recognise the file as bendsense's
    doc = {"generator": "bendsense", "t_s": session.t_s.tolist(),
           "tip_position_m": np.asarray(shape.tip_position_m).tolist()}
    if estimate is not None:
        doc["force_n"] = np.asarray(estimate.force_n).tolist()
    with output.write_file(path, overwrite=overwrite, suffixes=(".json",), writer="bendsense json") as tmp:
        tmp.write_text(json.dumps(doc), encoding="utf-8")


@click.command("json", cls=InterspersedCommand)
@click.argument("json_path", type=click.Path(dir_okay=False))
@overwrite_option
def json_step(json_path, overwrite):
    """Write the tips and forces as JSON (the recipe's chain step)."""

    def step(state):
        write_results_json(json_path, state["session"], state["shape"], state.get("estimate"), overwrite=overwrite)
        return state

    return step_io(step, outputs=[output.file(json_path, overwrite=overwrite, suffixes=(".json",))])


@pytest.fixture
def chain_with_json(monkeypatch, tmp_path):
    monkeypatch.setitem(main.commands, "json", json_step)
    kappa = np.linspace(2.0, 10.0, 6)[:, None] * np.ones(16)
    cal = linear_calibration()
    cal.save(tmp_path / "cal.yaml")
    write_session_csv(Session(0.1 * np.arange(6), signals_for(kappa, cal), np.full(6, 50e3)), tmp_path / "run.csv")
    return ["load", str(tmp_path / "run.csv"), "--calibration", str(tmp_path / "cal.yaml"), "reconstruct"], kappa


def test_a_new_output_format(chain_with_json, tmp_path):
    chain, kappa = chain_with_json
    res = CliRunner().invoke(main, [*chain, "estimate", "--constraint", "vertical", "json", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    assert doc["t_s"] == pytest.approx(0.1 * np.arange(6), abs=1e-15)
    # the tip of an arc of uniform curvature κ over the sensor length L_N (closed form)
    length = float(np.sum(SENSOR.lengths_m))
    theta = kappa[:, 0] * length
    tips = np.column_stack([(1 - np.cos(theta)) / kappa[:, 0], np.sin(theta) / kappa[:, 0]])
    np.testing.assert_allclose(doc["tip_position_m"], tips, atol=1e-12)
    assert np.shape(doc["force_n"]) == (6, 2) and np.all(np.asarray(doc["force_n"])[:, 0] == 0.0)
    # its own file is replaced only with --overwrite; another's is never replaced
    res = CliRunner().invoke(main, [*chain, "json", str(tmp_path / "r.json")])
    assert res.exit_code == 1 and "r.json: exists (use --overwrite" in res.output, res.output
    res = CliRunner().invoke(main, [*chain, "json", str(tmp_path / "r.json"), "--overwrite"])
    assert res.exit_code == 0, res.output
    assert "force_n" not in json.loads((tmp_path / "r.json").read_text())  # shapes only this time
    (tmp_path / "mine.json").write_text("{}")
    res = CliRunner().invoke(main, [*chain, "json", str(tmp_path / "mine.json"), "--overwrite"])
    assert res.exit_code == 1 and "mine.json: exists and bendsense did not write it" in res.output, res.output
    assert (tmp_path / "mine.json").read_text() == "{}"
    # a wrong suffix is refused
    res = CliRunner().invoke(main, [*chain, "json", str(tmp_path / "r.txt")])
    assert res.exit_code == 1 and "r.txt" in res.output and not (tmp_path / "r.txt").exists(), res.output

