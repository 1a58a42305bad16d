import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import bendsense
from bendsense.errors import OutputExistsError, SessionError
from bendsense.session import Session, read_session, read_session_csv, write_session_csv

# the bad-input corpus (tests/data/invalid/sessions) is run by test_invalid_corpus.py


def test_reads_kpa_metadata_and_extra_columns(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text(
        "# rig: upright\n# operator: ada\nt_s,pressure_kpa,ch1,ch2,fx_n,note\n0,20,1,2,0.1,a\n0.5,40,3,4,0.2,b\n"
    )
    s = read_session(p)
    assert s.meta == {"rig": "upright", "operator": "ada"}
    np.testing.assert_array_equal(s.pressure_pa, [20e3, 40e3])
    np.testing.assert_array_equal(s.signals, [[1, 2], [3, 4]])
    assert list(s.extra) == ["fx_n", "note"]
    np.testing.assert_array_equal(s.extra["fx_n"], [0.1, 0.2])
    assert list(s.extra["note"]) == ["a", "b"]


def test_an_integer_wider_than_int64_is_kept_as_written(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("t_s,pressure_kpa,ch1,frame_id\n0,20,1,1000000000000000000001\n0.5,40,3,1000000000000000000002\n")
    s = read_session(p)
    assert list(s.extra["frame_id"]) == ["1000000000000000000001", "1000000000000000000002"]
    write_session_csv(s, tmp_path / "back.csv")
    assert list(read_session(tmp_path / "back.csv").extra["frame_id"]) == list(s.extra["frame_id"])


def test_channels_in_any_column_order(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("ch2,t_s,ch1\n5,0,7\n")
    s = read_session_csv(p)
    np.testing.assert_array_equal(s.signals, [[7, 5]])
    assert np.isnan(s.pressure_pa).all() and not s.has_pressure
    assert s.with_pressure(3e4).has_pressure


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=40, deadline=None)
@given(
    signals=hnp.arrays(np.float64, st.tuples(st.integers(1, 8), st.integers(1, 5)), elements=finite),
    # 1 Pa..1 kPa in pressure_pa is refused as kPa in a pascal column (test below)
    pressure=finite.filter(lambda p: not 1.0 <= abs(p) < 1e3),
)
def test_write_read_round_trip_is_bit_exact(tmp_path_factory, signals, pressure):
    n = signals.shape[0]
    s = Session(np.arange(n) / 7.0, signals, np.full(n, pressure), seq=np.arange(n) + 65530,
                extra={"fx_n": np.linspace(-1, 1, n)}, meta={"scenario": "test"})
    path = tmp_path_factory.mktemp("rt") / "s.csv"
    write_session_csv(s, path)
    r = read_session_csv(path)
    np.testing.assert_array_equal(r.signals, s.signals)
    np.testing.assert_array_equal(r.t_s, s.t_s)
    np.testing.assert_array_equal(r.pressure_pa, s.pressure_pa)
    np.testing.assert_array_equal(r.seq, s.seq)
    np.testing.assert_array_equal(r.extra["fx_n"], s.extra["fx_n"])
    assert r.meta == {"scenario": "test"}


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    from bendsense.session import cells

    calls = []
    column_cells = cells.column_cells

    def failing_cells(values):  # the disk fills up after the header, while the columns are written
        calls.append(values)
        if len(calls) > 2:
            raise OSError("disk full")
        return column_cells(values)

    monkeypatch.setattr(cells, "column_cells", failing_cells)
    target = tmp_path / "out.csv"
    earlier = "# written by bendsense (a session CSV, docs/formats.md)\nprevious content"  # one of bendsense's
    target.write_text(earlier)
    s = Session([0.0, 1.0, 2.0], [[1.0], [2.0], [3.0]], 0.0)
    with pytest.raises(OSError, match="disk full"):
        write_session_csv(s, target)
    assert target.read_text() == earlier
    assert list(tmp_path.iterdir()) == [target]


def test_refuses_to_overwrite_when_asked(tmp_path):
    s = Session([0.0], [[1.0]], [0.0])
    target = tmp_path / "out.csv"
    write_session_csv(s, target)
    with pytest.raises(OutputExistsError, match="exists"):
        write_session_csv(s, target, overwrite=False)


def test_shape_errors_name_the_field():
    with pytest.raises(SessionError, match=r"signals: expected shape \(2, N\)"):
        Session([0.0, 1.0], [[1.0, 2.0, 3.0]], 0.0)


def test_missing_path(tmp_path):
    with pytest.raises(SessionError, match="no such file"):
        read_session(tmp_path / "none.csv")


@pytest.mark.parametrize(
    ("column", "values", "message"),
    [
        ("pressure_kpa", "0,60000,120000", r"line 1, column pressure_kpa: readings up to 120000 kPa \(over 1 MPa\); "
                                           r"looks like pascals: name the column pressure_pa"),
    ],
)
def test_pressure_a_thousand_times_off_is_refused(tmp_path, column, values, message):
    path = tmp_path / "s.csv"
    rows = "\n".join(f"{i},{p},1,2" for i, p in enumerate(values.split(",")))
    path.write_text(f"t_s,{column},ch1,ch2\n{rows}\n")
    with pytest.raises(SessionError, match=message):
        read_session_csv(path)


# a session at rest (every reading below 1 kPa) is a session: estimate_force judges it against the config
@pytest.mark.parametrize(("column", "values"), [("pressure_pa", "0,0,0"), ("pressure_pa", "0,20000,120000"),
                                                ("pressure_pa", "120,480,950"),
                                                ("pressure_kpa", "0,20,120"), ("pressure_pa", "-500,0,0.5")])
def test_plausible_pressure_columns_pass(tmp_path, column, values):
    path = tmp_path / "s.csv"
    rows = "\n".join(f"{i},{p},1,2" for i, p in enumerate(values.split(",")))
    path.write_text(f"t_s,{column},ch1,ch2\n{rows}\n")
    scale = 1e3 if column == "pressure_kpa" else 1.0
    np.testing.assert_array_equal(read_session_csv(path).pressure_pa, np.array(values.split(","), float) * scale)


def test_all_equal_time_stamps_are_refused(tmp_path):
    # (they were a warning: plots over time meaningless; tracking and windows are wrong too)
    path = tmp_path / "s.csv"
    path.write_text("t_s,ch1\n0,1\n0,2\n0,3\n")
    with pytest.raises(SessionError, match=r"line 3, column t_s: time repeats \(0 s after 0 s on line 2\); 2 rows out "
                                           r"of order in all \(also line 4\)"):
        read_session_csv(path)


def test_the_first_cell_that_is_not_finite_is_named_in_reading_order_at_every_run(tmp_path):
    """Row by row, then left to right, whatever order Python's hashing gives the column names (subprocesses: each
    its own string hashing)."""
    import subprocess
    import sys

    rows = [",".join(["0.01"] * 1 + ["1"] * 16)] * 6
    rows[3] = ",".join(["0.04"] + ["1"] * 7 + ["nan"] + ["1"] * 4 + ["nan"] + ["1"] * 3)  # ch8 and ch13
    rows[4] = ",".join(["0.05"] + ["nan"] * 16)  # a later row with every channel NaN
    body = "\n".join(",".join([f"{0.01 * i:.2f}", *r.split(",")[1:]]) for i, r in enumerate(rows))
    path = tmp_path / "nan.csv"
    path.write_text("t_s," + ",".join(f"ch{i}" for i in range(1, 17)) + "\n" + body + "\n")
    code = f"from bendsense.session.csvfile import read_session_csv\nread_session_csv({str(path)!r})"
    said = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stderr.strip().splitlines()[-1]
            for _ in range(4)}
    assert len(said) == 1 and said.pop().endswith("line 5, column ch8: must be finite, got 'nan'")


def test_an_infinite_pressure_is_no_missing_reading(tmp_path):
    path = tmp_path / "inf.csv"
    path.write_text("t_s,pressure_pa,ch1\n0,50000,1\n0.1,inf,2\n0.2,nan,3\n")
    with pytest.raises(SessionError, match=r"line 3, column pressure_pa: must be finite, got 'inf'"):
        read_session_csv(path)


def test_an_empty_pressure_cell_is_no_reading(tmp_path):
    path = tmp_path / "gap.csv"
    path.write_text("t_s,pressure_kpa,ch1\n0,50,1\n0.1,,2\n0.2,nan,3\n")
    p = read_session_csv(path).pressure_pa
    assert p[0] == 50e3 and np.isnan(p[1:]).all()


def test_a_long_session_and_its_results_print_in_a_few_lines():
    """A notebook's print of a session of 1,000 frames was 136 kB (every time, pressure and extra column)."""
    n = 1000
    t = np.arange(n) * 0.01
    session = bendsense.Session(t, np.full((n, 16), 2000.0), np.linspace(0.0, 1e5, n),
                                extra={f"col{i}": np.zeros(n) for i in range(9)})
    text = repr(session)
    assert len(text) < 600 and text.startswith("Session(t_s=<float64 array (1000,), 0..9.99>")
    assert "pressure_pa=<float64 array (1000,), 0..1e+05>" in text and "(9 keys)" in text
    est = bendsense.estimate_force(np.full((n, 16), 5.0), 5e4, bendsense.load_config(), noise_std=1.0)
    text = repr(est)
    assert len(text) < 1200 and "force_n=<float64 array (1000, 2), " in text and "method='fast'" in text
    assert "message=<str array (1000,)>" in text
