"""The CLI chain load → reconstruct → estimate → save on a session with known tip loads."""

import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.mechanics.beam import solve_beam
from bendsense.results import read_results
from bendsense.session import Session, write_session_csv
from bendsense.sim.sensor import shifts_from_shape

CFG = bendsense.load_config()
SLOPE_M = 2.0e-6  # shift per signal unit of the linear test calibration [m]
OFFSET = 1500.0


def _calibration(noise=0.5):
    """A linear calibration S = SLOPE · ΔA on every channel, with a flat-noise estimate."""
    return Calibration(offset=np.full(16, OFFSET), coefficients_odd=[0.0, SLOPE_M], coefficients_even=[0.0, SLOPE_M],
                       degree=1, delta_a_range_odd=(-1e4, 1e4), delta_a_range_even=(-1e4, 1e4),
                       noise_std=np.full(16, noise))


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A session CSV of vertical tip loads on the model actuator, and its calibration."""
    root = tmp_path_factory.mktemp("estimate")
    model = FreeBendingModel.from_config(CFG)
    pressure = np.array([30e3, 60e3, 90e3, 120e3, 60e3])
    fy = np.array([-0.1, 0.05, -0.2, 0.15, 0.0])
    force = np.stack([np.zeros_like(fy), fy], axis=-1)
    s = np.linspace(0.0, CFG.actuator.length_m, 135)
    sol = solve_beam(CFG.actuator.length_m, CFG.stiffness.ei_nm2(pressure), model.tip_curvature_per_m(pressure),
                     force, CFG.weight_per_length_n_per_m, 0.0, s)
    assert sol.success.all()
    # what the sensor sees: S_i = d φ(L_i), through the linear calibration
    shifts = shifts_from_shape(s, sol.angle_rad, CFG.sensor.lengths_m, CFG.sensor.strip_gap_m)
    signals = OFFSET + shifts / SLOPE_M
    session = Session(np.arange(5) * 0.1, signals, pressure, extra={"fy_true_n": fy})
    write_session_csv(session, root / "session.csv")
    _calibration().save(root / "cal.yaml")
    return root


def test_chain_writes_vertical_forces(workdir):
    out = workdir / "out"
    res = CliRunner().invoke(main, ["load", str(workdir / "session.csv"), "--calibration", str(workdir / "cal.yaml"),
                                    "reconstruct", "estimate", "--constraint", "vertical", "save", str(out)])
    assert res.exit_code == 0, res.output
    results = read_results(out)
    assert results.has_forces
    fy_true = results["fy_true_n"].astype(float)
    np.testing.assert_array_equal(results["fx_n"], 0.0)  # the vertical constraint: Fx = 0
    # the estimate of the PCC shape differs from the beam's load by the PCC model error only
    np.testing.assert_allclose(results["fy_n"], fy_true, atol=0.01)
    assert np.all(results["fy_std_n"] > 0) and np.all(np.isfinite(results["fy_std_n"]))
    np.testing.assert_array_equal(results["fx_std_n"], 0.0)
    assert np.all(results["residual_m"] < 1e-3)
    assert list(results["status"]) == ["ok"] * 5


def test_chain_matches_the_library(workdir):
    """The CLI writes what estimate_force returns, with the calibration's noise."""
    out = workdir / "out_none"
    res = CliRunner().invoke(main, ["load", str(workdir / "session.csv"), "--calibration", str(workdir / "cal.yaml"),
                                    "reconstruct", "estimate", "save", str(out)])
    assert res.exit_code == 0, res.output
    results = read_results(out)
    session = bendsense.read_session(workdir / "session.csv")
    shape = bendsense.reconstruct(session.signals, _calibration(), CFG.sensor)
    est = bendsense.estimate_force(shape, session.pressure_pa, CFG, calibration=_calibration())
    np.testing.assert_allclose(results["fx_n"], est.force_n[:, 0], atol=1e-9)
    np.testing.assert_allclose(results["fy_n"], est.force_n[:, 1], atol=1e-9)
    np.testing.assert_allclose(results["fy_std_n"], est.std_n[:, 1], rtol=1e-6)


def test_push_only_without_a_direction_is_a_usage_error(workdir):
    res = CliRunner().invoke(main, ["load", str(workdir / "session.csv"), "--calibration", str(workdir / "cal.yaml"),
                                    "reconstruct", "estimate", "--constraint", "none", "--push-only",
                                    "save", str(workdir / "never")])
    assert res.exit_code != 0
    assert "push_only" in res.output and "Traceback" not in res.output
    assert not (workdir / "never").exists()


@pytest.mark.parametrize("factor", [10.0, 1000.0])
def test_a_calibration_off_by_a_factor_gives_no_ok_frame(workdir, tmp_path, factor):
    # a calibration in mm where metres belong (or any unit slip): the shapes and forces are nonsense
    cal = Calibration(offset=np.full(16, OFFSET), coefficients_odd=[0.0, SLOPE_M * factor],
                      coefficients_even=[0.0, SLOPE_M * factor], degree=1, delta_a_range_odd=(-1e4, 1e4),
                      delta_a_range_even=(-1e4, 1e4), noise_std=np.full(16, 0.5))
    cal.save(tmp_path / "cal_off.yaml")
    args = ["load", str(workdir / "session.csv"), "--calibration", str(tmp_path / "cal_off.yaml")]
    res = CliRunner().invoke(main, [*args,
                                    "reconstruct", "estimate", "--constraint", "vertical", "save", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    status = set(read_results(tmp_path / "o")["status"])
    assert "ok" not in status and status <= {"model_misfit", "implausible_shape", "not_converged"}, status
