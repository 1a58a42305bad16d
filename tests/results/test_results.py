"""``bendsense.results``: ``results.csv`` and ``shape.npz`` written and read back (DESIGN.md section 3).

The shapes and estimates are plain objects with values chosen here, so every number read
back is compared with a number the test wrote, not with one the code computed.
"""

import csv
import math
from types import SimpleNamespace

import numpy as np
import pytest

from bendsense.errors import OutputError, OutputExistsError, SessionError
from bendsense.results import read_results, write_results
from bendsense.session import Session
from bendsense.status import Status

N = 3  # channels: kappa1..kappa3
M = 4  # shape points
FRAMES = 5
RNG = np.random.default_rng(11)


def inputs(*, estimate=True, extra=None):
    """A session, a shape and (optionally) an estimate of FRAMES frames with known values."""
    session = Session(0.25 * np.arange(FRAMES), RNG.normal(size=(FRAMES, N)), np.array([2e4, 3e4, np.nan, 5e4, 6e4]),
                      extra=extra or {})
    shape = SimpleNamespace(
        curvature_per_m=RNG.normal(size=(FRAMES, N)),
        tip_position_m=RNG.normal(size=(FRAMES, 2)),
        tip_angle_rad=np.array([0.1, -0.2, 0.3, 1.0, 2.0]),
        s_m=np.linspace(0.0, 0.13, M),
        positions_m=RNG.normal(size=(FRAMES, M, 2)),
        extrapolated=np.zeros(FRAMES, dtype=bool),
    )
    if not estimate:
        return session, shape, None
    est = SimpleNamespace(
        force_n=RNG.normal(size=(FRAMES, 2)),
        std_n=np.abs(RNG.normal(size=(FRAMES, 2))),
        residual_m=np.abs(RNG.normal(size=FRAMES)),
        success=np.ones(FRAMES, dtype=bool),
        status=np.full(FRAMES, Status.OK, dtype=np.int8),
        message=np.full(FRAMES, "", dtype="<U64"),
    )
    return session, shape, est


def header(out):
    with open(out / "results.csv", newline="", encoding="utf-8") as fh:
        return next(csv.reader(fh))


def test_round_trip_is_exact(tmp_path):
    session, shape, est = inputs(extra={"trial": np.arange(FRAMES), "note": np.array(["a", "b,c", "d", "e", "f"])})
    write_results(tmp_path / "out", session, shape, est)
    got = read_results(tmp_path / "out")
    np.testing.assert_array_equal(got["t_s"], session.t_s)
    np.testing.assert_array_equal(got["pressure_pa"], session.pressure_pa)  # NaN where there is no reading
    np.testing.assert_array_equal(got.curvature_per_m, shape.curvature_per_m)
    np.testing.assert_array_equal(np.column_stack([got["tip_x_m"], got["tip_y_m"]]), shape.tip_position_m)
    np.testing.assert_array_equal(got["tip_angle_rad"], shape.tip_angle_rad)
    np.testing.assert_array_equal(np.column_stack([got["fx_n"], got["fy_n"]]), est.force_n)
    np.testing.assert_array_equal(np.column_stack([got["fx_std_n"], got["fy_std_n"]]), est.std_n)
    np.testing.assert_array_equal(got["residual_m"], est.residual_m)
    np.testing.assert_array_equal(got.s_m, shape.s_m)
    np.testing.assert_array_equal(got.positions_m, shape.positions_m)
    np.testing.assert_array_equal(got["trial"], np.arange(FRAMES))
    assert list(got["note"]) == ["a", "b,c", "d", "e", "f"]  # a comma inside a cell survives
    assert got.has_forces and got.extra_names == ("trial", "note")


def test_columns_in_the_documented_order(tmp_path):
    kappa = [f"kappa{i}" for i in range(1, N + 1)]
    shape_cols = ["t_s", "pressure_pa", *kappa, "tip_x_m", "tip_y_m", "tip_angle_rad"]
    force_cols = ["fx_n", "fy_n", "fx_std_n", "fy_std_n", "residual_m", "status"]
    truth = {"fx_n": np.zeros(FRAMES), "label": np.array(list("abcde"))}
    write_results(tmp_path / "est", *inputs(extra=truth))
    assert header(tmp_path / "est") == [*shape_cols, *force_cols, "input_fx_n", "label"]
    # shapes only: no force columns, the status stays; a ground-truth fx_n never poses as an estimate
    write_results(tmp_path / "shape", *inputs(estimate=False, extra=truth))
    assert header(tmp_path / "shape") == [*shape_cols, "status", "input_fx_n", "label"]
    got = read_results(tmp_path / "shape")
    assert not got.has_forces and "fx_n" not in got.columns
    np.testing.assert_array_equal(got["input_fx_n"], np.zeros(FRAMES))


def test_status_column_names_the_reason_of_each_frame(tmp_path):
    session, shape, est = inputs()
    shape.extrapolated[0] = True
    shape.curvature_per_m[1, 2] = np.nan
    est.success[2] = False
    est.status[2], est.message[2] = Status.PRESSURE_OUT_OF_RANGE, "pressure_out_of_range: 250 kPa"
    est.force_n[3] = np.nan  # a NaN force is never ok, whatever the solver said
    shape.tip_angle_rad[4] = 2 * math.pi + 0.1  # beyond a full turn
    write_results(tmp_path / "out", session, shape, est)
    with open(tmp_path / "out" / "results.csv", newline="", encoding="utf-8") as fh:
        status = [row["status"] for row in csv.DictReader(fh)]
    assert status == ["extrapolated", "no_shape", "pressure_out_of_range", "no_force", "implausible_shape"]
    assert list(read_results(tmp_path / "out")["status"]) == status


def test_not_converged_model_misfit_and_not_identifiable(tmp_path):
    session, shape, est = inputs()
    est.success[:2] = False
    est.status[:2] = [Status.NOT_CONVERGED, Status.MODEL_MISFIT]
    est.message[:2] = ["gave up after 100 iterations", "model_misfit: p = 1e-9"]
    est.std_n[2, 1] = np.inf  # a converged fit whose shape does not determine Fy
    est.status[2] = Status.NOT_IDENTIFIABLE
    est.message[2] = "not identifiable: the shape does not determine the load along (0, 1)"
    write_results(tmp_path / "out", session, shape, est)
    want = ["not_converged", "model_misfit", "not_identifiable", "ok", "ok"]
    assert list(read_results(tmp_path / "out")["status"]) == want


def test_nan_and_inf_are_written_and_read_back(tmp_path):
    session, shape, est = inputs()
    est.force_n[1] = np.nan
    est.std_n[0] = [np.nan, np.nan]  # no noise model: no σ
    est.std_n[2, 1] = np.inf  # a direction the shape cannot determine
    est.residual_m[4] = np.nan
    write_results(tmp_path / "out", session, shape, est)
    text = (tmp_path / "out" / "results.csv").read_text(encoding="utf-8")
    assert ",nan," in text and ",inf," in text
    got = read_results(tmp_path / "out")
    np.testing.assert_array_equal(np.column_stack([got["fx_std_n"], got["fy_std_n"]]), est.std_n)
    np.testing.assert_array_equal(np.column_stack([got["fx_n"], got["fy_n"]]), est.force_n)
    np.testing.assert_array_equal(got["residual_m"], est.residual_m)
    assert np.isnan(got["pressure_pa"][2])


def test_refuses_to_overwrite_files_it_did_not_write(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match=r"out: exists and is not empty \(use --overwrite"):
        write_results(out, *inputs())
    not_ours = r"out: not a bendsense output \(no .bendsense-output.json\); it holds notes.txt"
    with pytest.raises(OutputError, match=not_ours):
        write_results(out, *inputs(), overwrite=True)
    assert (out / "notes.txt").read_text() == "mine" and sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    # its own earlier output is replaced with overwrite, and only with it
    mine = tmp_path / "mine"
    write_results(mine, *inputs())
    with pytest.raises(OutputExistsError):
        write_results(mine, *inputs())
    session, shape, est = inputs()
    write_results(mine, session, shape, est, overwrite=True)
    np.testing.assert_array_equal(read_results(mine)["fx_n"], est.force_n[:, 0])
    # a user's file put inside it since: overwrite refuses and names it
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match=r"mine: holds files bendsense did not write: notes.txt; nothing"):
        write_results(mine, *inputs(), overwrite=True)
    assert (mine / "notes.txt").read_text() == "mine"
    np.testing.assert_array_equal(read_results(mine)["fx_n"], est.force_n[:, 0])


def test_the_session_source_is_never_an_output(tmp_path):
    session, shape, est = inputs()
    source = tmp_path / "data" / "run.csv"
    source.parent.mkdir()
    source.write_text("t_s\n0\n")
    session = Session(session.t_s, session.signals, session.pressure_pa, source=str(source))
    with pytest.raises(OutputError, match="holds the input"):
        write_results(tmp_path / "data", session, shape, est, overwrite=True)
    assert source.read_text() == "t_s\n0\n"


def _written(tmp_path):
    write_results(tmp_path / "out", *inputs())
    path = tmp_path / "out" / "results.csv"
    return path, path.read_text(encoding="utf-8").splitlines()


def test_a_row_with_a_missing_cell_names_the_file_and_line(tmp_path):
    path, lines = _written(tmp_path)
    lines[3] = lines[3].rsplit(",", 1)[0]  # the third frame loses its status cell
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    n_columns = len(lines[0].split(","))
    with pytest.raises(SessionError) as info:
        read_results(tmp_path / "out")
    assert str(info.value) == f"{path}: line 4: {n_columns - 1} cells, expected {n_columns} (one per column)"


def test_text_in_a_number_column_names_the_file_column_and_line(tmp_path):
    path, lines = _written(tmp_path)
    cells = lines[5].split(",")
    cells[2] = "twelve"  # kappa1 of the fifth frame
    lines[5] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(SessionError) as info:
        read_results(tmp_path / "out")
    assert str(info.value) == f"{path}: column kappa1: expected numbers, got 'twelve' on line 6"


def test_an_infinite_time_names_the_line(tmp_path):
    path, lines = _written(tmp_path)
    lines[2] = "inf" + lines[2][lines[2].index(","):]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(SessionError, match=r"results\.csv: line 3, column t_s: must be finite or nan, got inf$"):
        read_results(tmp_path / "out")


def test_not_a_results_directory(tmp_path):
    with pytest.raises(SessionError, match=r"nowhere: no such results directory$"):
        read_results(tmp_path / "nowhere")
    (tmp_path / "elsewhere").mkdir()
    with pytest.raises(SessionError, match=r"elsewhere: no results.csv \(not a results directory\)"):
        read_results(tmp_path / "elsewhere")


@pytest.mark.parametrize("finger", ["", "index"], ids=["actuator", "gripper-finger"])
def test_a_recordings_results_without_shapes_say_how_to_get_a_results_directory(tmp_path, finger):
    """``record --estimate`` writes SESSION/results.csv (a gripper's SESSION/<finger>/) and no shape.npz: reading
    it says so and how to make a results directory, not that the directory is damaged."""
    from bendsense.session.native import SessionWriter, record_dtype

    session = tmp_path / "rec"
    with SessionWriter(session, record_dtype(N, "<f8")) as writer:
        writer.write(writer.empty(2))
    path, _ = _written(tmp_path)
    (session / finger).mkdir(exist_ok=True)
    (session / finger / "results.csv").write_bytes(path.read_bytes())
    with pytest.raises(SessionError) as info:
        read_results(session / finger)
    assert str(info.value) == (f"{session / finger / 'results.csv'}: a recording's results ('record --estimate' keeps "
                               f"no shapes); for a results directory: bendsense load {session} --calibration CAL.yaml "
                               "reconstruct estimate save OUT_DIR")
    (tmp_path / "out" / "shape.npz").unlink()  # a results directory that lost its shapes: damaged
    with pytest.raises(SessionError, match=r"out/shape\.npz: missing \(every results directory has one\)$"):
        read_results(tmp_path / "out")
