"""Plausibility at the edges: no ok force outside the actuator's pressure range; channel counts agree."""

import dataclasses

import numpy as np
import pytest

import bendsense
from bendsense.beam import solve_beam
from bendsense.errors import ArgumentError, SessionError
from bendsense.estimation import estimate_force
from bendsense.plausibility import OUT_OF_RANGE, check_channels, pressure_outside
from bendsense.results import frame_status
from bendsense.session import Session

CONFIG = bendsense.load_config()


def _shapes(pressures):
    """Segment curvatures of the beam model under a small tip load at each pressure."""
    from bendsense.actuator import FreeBendingModel

    model = FreeBendingModel.from_config(CONFIG)
    sensor = CONFIG.sensor
    ends = np.cumsum(sensor.lengths_m)
    s = np.concatenate([[0.0], ends])
    kappa = []
    for p in pressures:
        p = min(max(p, 0.0), 200e3)
        sol = solve_beam(CONFIG.actuator.length_m, CONFIG.stiffness.ei_nm2(p), model.tip_curvature_per_m(p),
                         force_n=(0.05, -0.05), distributed_load_n_per_m=CONFIG.weight_per_length_n_per_m, s_m=s)
        kappa.append(np.diff(sol.angle_rad) / sensor.lengths_m)
    return np.array(kappa)


def test_default_range_is_the_paper_prototype():
    assert CONFIG.actuator.pressure_range_pa == (0.0, 200e3)
    np.testing.assert_array_equal(pressure_outside([-1.0, 0.0, 200e3, 200001.0, np.nan], CONFIG),
                                  [True, False, False, True, False])


def test_frames_outside_the_range_get_no_force_and_the_others_are_unchanged():
    pressures = np.array([60e3, -50e3, 120e3, 250e3])
    kappa = _shapes(pressures)
    est = estimate_force(kappa, pressures, CONFIG, warm_start=False)
    inside = estimate_force(kappa[[0, 2]], pressures[[0, 2]], CONFIG, warm_start=False)
    np.testing.assert_allclose(est.force_n[[0, 2]], inside.force_n, rtol=1e-9, atol=1e-12)
    assert np.isnan(est.force_n[[1, 3]]).all() and np.isnan(est.std_n[[1, 3]]).all()
    np.testing.assert_array_equal(est.success, [True, False, True, False])
    assert est.message[1] == f"{OUT_OF_RANGE}: -50 kPa outside 0..200 kPa (actuator.pressure_range_pa)"
    shape = bendsense.pcc.Shape.from_curvatures(kappa, CONFIG.sensor.lengths_m)
    assert list(frame_status(shape, est)) == ["ok", OUT_OF_RANGE, "ok", OUT_OF_RANGE]


def test_one_frame_outside_and_strict():
    kappa = _shapes([60e3])[0]
    est = estimate_force(kappa, -5e3, CONFIG)
    assert est.batch_shape == () and not est.success and np.isnan(est.force_n).all()
    assert est.message.startswith(OUT_OF_RANGE)
    with pytest.raises(ArgumentError, match=r"pressure_pa: 1 of 1 pressure\(s\) outside actuator.pressure_range_pa "
                                            r"0..200 kPa \(first: -5 kPa\)"):
        estimate_force(kappa, -5e3, CONFIG, strict=True)


def test_a_wider_configured_range_lets_the_frame_through():
    wide = CONFIG.replace(actuator=dataclasses.replace(CONFIG.actuator, pressure_range_pa=(-10e3, 200e3)))
    kappa = _shapes([0.0])[0]
    assert estimate_force(kappa, -5e3, wide).success


def test_a_nan_force_is_never_ok():
    kappa = _shapes([60e3])
    est = estimate_force(kappa, [60e3], CONFIG)
    broken = dataclasses.replace(est, force_n=np.full((1, 2), np.nan))
    shape = bendsense.pcc.Shape.from_curvatures(kappa, CONFIG.sensor.lengths_m)
    assert frame_status(shape, broken)[0] != "ok"


def test_channel_counts_must_agree():
    cal = bendsense.Calibration.load("tests/data/calibration/calibration_v1.yaml")
    session = Session([0.0], np.zeros((1, 8)), [0.0], source="run.csv")
    with pytest.raises(SessionError, match=r"^run.csv: 8 signal channels \(ch1..ch8\), but the calibration cal.yaml "
                                           rf"has {cal.n_channels}$"):
        check_channels(session, cal, CONFIG.sensor, calibration_source="cal.yaml")
