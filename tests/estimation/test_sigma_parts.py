"""No part of σ is dropped without a word (issue 21: silently dropped uncertainty).

A calibration whose coefficient covariance or misfit cannot be computed still gives a σ
(from what it has), but says which part is missing and why, once per calibration; a
calibration whose counts are impossible is refused when it is read (the corpus under
tests/data/invalid/calibrations holds a case per field).
"""

import logging
from pathlib import Path

import numpy as np
import pytest
import yaml

import bendsense
from bendsense.calibration import Calibration
from bendsense.errors import ConfigError

DATA = Path(__file__).parents[1] / "data"
OLD_CAL = DATA / "calibration" / "calibration_v1.yaml"  # a version-1 file without the fitted data
FULL_CAL = DATA / "regression" / "calibration.yaml"  # written by `bendsense calibrate`: everything σ needs
CONFIG = bendsense.load_config()
SESSION = bendsense.read_session_csv(DATA / "invalid" / "good" / "session.csv")


def _estimate(cal):
    shape = bendsense.reconstruct(SESSION.signals, cal, CONFIG.sensor)
    return bendsense.estimate_force(shape, SESSION.pressure_pa, CONFIG, calibration=cal)


def _sigma_warnings(caplog):
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "σ leaves out" in r.getMessage()]


def test_a_calibration_without_its_fitted_data_says_that_sigma_lacks_the_coefficient_part(caplog):
    cal = Calibration.load(OLD_CAL)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        first = _estimate(cal)
        _estimate(cal)  # once per calibration, not per call (a live run estimates block after block)
    messages = _sigma_warnings(caplog)
    assert len(messages) == 1, messages
    assert "calibration-coefficient part" in messages[0]
    assert "fit_delta_a, fit_shifts_m are missing" in messages[0]
    assert first.covariance_parts_n2 is not None


def test_a_complete_calibration_warns_nothing_and_carries_the_coefficient_part(caplog):
    cal = Calibration.load(FULL_CAL)
    assert np.any(cal.coefficient_covariance != 0)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        cal.error_model()
    assert _sigma_warnings(caplog) == []


def test_strip_frame_counts_missing_from_an_older_file_are_named(caplog, tmp_path):
    data = yaml.safe_load(FULL_CAL.read_text(encoding="utf-8"))
    for strip in data["strip_residuals"]:
        del strip["n_frames"]  # an older writer did not store them
    (tmp_path / "cal.yaml").write_text(yaml.safe_dump(data), encoding="utf-8")
    cal = Calibration.load(tmp_path / "cal.yaml")
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        model = cal.error_model()
    assert not np.any(model.coef_cov)  # the part is left out ...
    messages = _sigma_warnings(caplog)  # ... and said so, naming the field
    assert len(messages) == 1 and "strip_residuals[].n_frames" in messages[0], messages


def test_a_calibration_with_no_misfit_information_says_so(caplog):
    cal = Calibration(offset=np.full(16, 2000.0), coefficients_odd=[0.0, 1e-6], coefficients_even=[0.0, -1e-6],
                      degree=1, delta_a_range_odd=(0.0, 600.0), delta_a_range_even=(-600.0, 0.0),
                      noise_std=np.full(16, 0.5))
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        cal.error_model()
    messages = _sigma_warnings(caplog)
    assert any("calibration misfit" in m and "strip_residuals" in m for m in messages), messages


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d["strip_residuals"][0].update(n_frames=-5),
     r"strip_residuals\[0\]\.n_frames: expected an integer >= 1"),
    (lambda d: d["meta"].update(flat_frames=0), r"meta\.flat_frames: expected an integer >= 1, got 0"),
])
def test_impossible_counts_are_refused_naming_the_file_and_field(edit, message, tmp_path):
    data = yaml.safe_load(FULL_CAL.read_text(encoding="utf-8"))
    edit(data)
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ConfigError, match=message) as info:
        Calibration.load(path)
    assert str(info.value).startswith(str(path))


def test_the_constructor_refuses_impossible_counts_and_data_too():
    from bendsense.calibration.fit import StripResidual

    full = Calibration.load(FULL_CAL)
    fields = {name: getattr(full, name) for name in ("offset", "coefficients_odd", "coefficients_even", "degree",
                                                     "delta_a_range_odd", "delta_a_range_even", "noise_std")}
    bad = StripResidual(radius_m=0.04, curvature_per_m=25.0, rms_shift_m=1e-6, max_abs_shift_m=2e-6, n_frames=-5)
    with pytest.raises(ConfigError, match=r"^strip_residuals\[0\]\.n_frames: expected an integer >= 1"):
        Calibration(**fields, strip_residuals=(bad,))
    data = np.array(full.fit_delta_a)
    data[2, 3] = np.nan
    with pytest.raises(ConfigError, match=r"^fit_delta_a: values must be finite"):
        Calibration(**fields, strip_residuals=full.strip_residuals, fit_delta_a=data, fit_shifts_m=full.fit_shifts_m)
