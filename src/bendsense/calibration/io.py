"""The calibration file (DESIGN.md section 3): ``format: bendsense-calibration``, ``version: 1``.

The YAML layout of a :class:`~bendsense.calibration.Calibration` (:func:`to_dict`,
:func:`fields_from_dict`) and the checks of its array fields, which the class's
constructor shares.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import yaml

from bendsense import validation as check
from bendsense.calibration.fit import StripResidual
from bendsense.errors import ConfigError

__all__ = []

FORMAT = "bendsense-calibration"
VERSION = 1


def _array(where: str, value: Any, length: int | None = None) -> np.ndarray:
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise ConfigError(f"{where}: expected a list of numbers, got {check.short(value)}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected a list of numbers, got {check.short(value)}") from None
    if arr.ndim != 1 or (length is not None and arr.size != length):
        want = f"{length} numbers" if length is not None else "a flat list of numbers"
        raise ConfigError(f"{where}: expected {want}, got {arr.size if arr.ndim == 1 else arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}: values must be finite, got {check.short(value)}")
    return arr


def _matrix(where: str, value: Any, n: int) -> np.ndarray:
    """A (rows, n) matrix of finite numbers, from a list of rows."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(row, (list, tuple)) for row in value):
        raise ConfigError(f"{where}: expected a list of rows of {n} numbers, got {check.short(value)}")
    rows = [_array(f"{where}[{i}]", row, n) for i, row in enumerate(value)]
    if not rows:
        raise ConfigError(f"{where}: expected at least one row, got none")
    return np.array(rows)


_STRIP_FIELDS = ("radius_m", "curvature_per_m", "rms_shift_m", "max_abs_shift_m", "signal_std", "n_frames",
                 "recording")


def _strip_residual(i: int, item: Any) -> StripResidual:
    """One entry of ``strip_residuals``, every field checked (the frame count enters σ)."""
    where = f"strip_residuals[{i}]"
    if not isinstance(item, dict):
        raise ConfigError(f"{where}: expected a mapping with keys {', '.join(_STRIP_FIELDS)}, got {check.short(item)}")
    unknown = [check.key(k) for k in item if k not in _STRIP_FIELDS]
    if unknown:
        raise ConfigError(f"{where}: unknown keys {', '.join(unknown)}; allowed: {', '.join(_STRIP_FIELDS)}")
    missing = [k for k in ("radius_m", "curvature_per_m", "rms_shift_m", "max_abs_shift_m") if k not in item]
    if missing:
        raise ConfigError(f"{where}: missing keys {', '.join(missing)}")
    kwargs = {
        "radius_m": check.number(f"{where}.radius_m", item["radius_m"], error=ConfigError, positive=True),
        "curvature_per_m": check.number(f"{where}.curvature_per_m", item["curvature_per_m"], error=ConfigError),
        "rms_shift_m": check.number(f"{where}.rms_shift_m", item["rms_shift_m"], error=ConfigError, nonnegative=True),
        "max_abs_shift_m": check.number(f"{where}.max_abs_shift_m", item["max_abs_shift_m"], error=ConfigError,
                                        nonnegative=True),
    }
    if kwargs["max_abs_shift_m"] < kwargs["rms_shift_m"] * (1 - 1e-9):
        raise ConfigError(f"{where}.max_abs_shift_m: {kwargs['max_abs_shift_m']:g} is below its rms_shift_m "
                          f"{kwargs['rms_shift_m']:g} (the largest error is never below the RMS)")
    if "signal_std" in item:
        kwargs["signal_std"] = check.number(f"{where}.signal_std", item["signal_std"], error=ConfigError,
                                            nonnegative=True)
    if "n_frames" in item:  # the strip means' variance is σ²/n_frames (coefficient_covariance)
        kwargs["n_frames"] = check.integer(f"{where}.n_frames", item["n_frames"], error=ConfigError, minimum=1)
    if "recording" in item:
        if not isinstance(item["recording"], str):
            raise ConfigError(f"{where}.recording: expected a file name, got {check.short(item['recording'])}")
        kwargs["recording"] = item["recording"]
    return StripResidual(**kwargs)


def _range(where: str, value: Any) -> tuple:
    arr = _array(where, value, 2)
    if arr[0] > arr[1]:
        raise ConfigError(f"{where}: expected [min, max] with min <= max, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]))


def to_dict(cal) -> dict:
    """The calibration YAML layout of ``cal`` (plain lists, floats and strings).

    Parameters
    ----------
    cal : Calibration
        The calibration to write.

    Returns
    -------
    dict
    """
    cv = cal.cv_errors_m
    out = {
        "format": FORMAT,
        "version": VERSION,
        "n_channels": cal.n_channels,
        "degree": cal.degree,
        "offset": cal.offset.tolist(),
        "coefficients_odd": cal.coefficients_odd.tolist(),
        "coefficients_even": cal.coefficients_even.tolist(),
        "delta_a_range_odd": list(cal.delta_a_range_odd),
        "delta_a_range_even": list(cal.delta_a_range_even),
        "noise_std": cal.noise_std.tolist() if cal.noise_known else None,
        "weighting": cal.weighting,
        "sleeve": cal.sleeve,
        "strip_residuals": [r.to_dict() for r in cal.strip_residuals],
        "cv_errors_m": None if cv is None else {int(k): float(v) for k, v in cv.items()},
        "sensor": None if cal.sensor is None else cal.sensor.to_dict(),
        "fit_delta_a": None if cal.fit_delta_a is None else cal.fit_delta_a.tolist(),
        "fit_shifts_m": None if cal.fit_shifts_m is None else cal.fit_shifts_m.tolist(),
        "meta": dict(cal.meta),
    }
    if cal.finger is not None:  # a gripper finger's calibration (a single actuator's file is unchanged)
        out["finger"] = cal.finger
    return out


def save(cal, path: str | os.PathLike, *, overwrite: bool = True) -> None:
    """Write the calibration YAML atomically (:meth:`Calibration.save`).

    Parameters
    ----------
    cal : Calibration
        The calibration to write.
    path : path
        The YAML file.
    overwrite : bool
        ``False`` refuses an existing file.
    """
    from bendsense import output

    header = "# bendsense sensor calibration: S_i = sum_k c_k (A_i - offset_i)^k (ascending powers, paper eq. 2)\n"
    text = header + yaml.safe_dump(cal.to_dict(), sort_keys=False)
    output.write_text(path, text, overwrite=overwrite, writer="bendsense calibrate")


def fields_from_dict(data: Any) -> dict:
    """The keyword arguments of a calibration from its YAML layout; raises `ConfigError` naming the field.

    Parameters
    ----------
    data : Any
        The parsed YAML.

    Returns
    -------
    dict
        The keyword arguments of :class:`~bendsense.calibration.Calibration`.
    """
    if not isinstance(data, dict):
        what = " (a session CSV? a calibration is the YAML of 'bendsense calibrate')" if isinstance(data, str) and \
            "," in data else ""
        raise ConfigError(f"calibration: expected a mapping (format: {FORMAT}), got {check.short(data)}{what}")
    if data.get("format") != FORMAT:
        hint = (" (a calibration manifest: fit it with 'bendsense calibrate MANIFEST -o cal.yaml', or "
                "Calibration.fit(MANIFEST), and give the YAML it writes)" if "strips" in data else
                " (an actuator config: a calibration is the YAML of 'bendsense calibrate')"
                if {"actuator", "sensor", "stiffness"} & set(map(str, data)) and "offset" not in data else "")
        raise ConfigError(f"format: expected {FORMAT!r}, got {check.short(data.get('format'))}{hint}")
    version = data.get("version")
    if version != VERSION:
        raise ConfigError(f"version: this bendsense reads version {VERSION}, got {check.short(version)}")
    allowed = [
        "format", "version", "n_channels", "degree", "offset", "coefficients_odd", "coefficients_even",
        "delta_a_range_odd", "delta_a_range_even", "noise_std", "weighting", "sleeve", "strip_residuals",
        "cv_errors_m", "sensor", "fit_delta_a", "fit_shifts_m", "meta", "finger",
    ]  # fmt: skip
    unknown = [str(k) for k in data if k not in allowed]
    if unknown:
        raise ConfigError(f"calibration: unknown keys {', '.join(unknown)}; allowed: {', '.join(allowed)}")
    required = ["offset", "coefficients_odd", "coefficients_even", "delta_a_range_odd", "delta_a_range_even"]
    missing = [k for k in required if k not in data]
    if missing:
        raise ConfigError(f"calibration: missing keys {', '.join(missing)}")
    coef = _array("coefficients_odd", data["coefficients_odd"])
    degree = data.get("degree", coef.size - 1)
    offset = _array("offset", data["offset"])
    if "n_channels" in data and data["n_channels"] != offset.size:
        got = check.short(data["n_channels"])
        raise ConfigError(f"n_channels: {got} does not match the {offset.size} offset values")
    sensor = None
    if data.get("sensor") is not None:
        from bendsense.config import SensorConfig

        sensor = SensorConfig.from_dict(data["sensor"])
    strips = data.get("strip_residuals")
    if strips is not None and not isinstance(strips, list):
        raise ConfigError(f"strip_residuals: expected a list of mappings, got {check.short(strips)}")
    residuals = [_strip_residual(i, item) for i, item in enumerate(strips or [])]
    cv = data.get("cv_errors_m")
    if cv is not None:
        if not isinstance(cv, dict):
            raise ConfigError(f"cv_errors_m: expected a mapping of degree to error, got {check.short(cv)}")
        cv = {check.integer(f"cv_errors_m key {check.short(k)}", k, error=ConfigError, minimum=0):
              check.number(f"cv_errors_m[{check.short(k)}]", v, error=ConfigError, nonnegative=True)
              for k, v in cv.items()}
    meta = data.get("meta") or {}
    if not isinstance(meta, dict):
        raise ConfigError(f"meta: expected a mapping, got {check.short(meta)}")
    if "flat_frames" in meta:
        # the offsets' variance is σ²/flat_frames: a count that is no count drops or inflates it
        frames = check.integer("meta.flat_frames", meta["flat_frames"], error=ConfigError, minimum=1)
        if frames < 2 and data.get("noise_std") is not None:
            raise ConfigError("meta.flat_frames: 1 frame cannot have given noise_std (a standard deviation over "
                              "the flat recording's frames); expected >= 2")
    fit = {}
    for name in ("fit_delta_a", "fit_shifts_m"):
        if data.get(name) is not None:
            fit[name] = _matrix(name, data[name], offset.size)
    rows = {name: a.shape[0] for name, a in fit.items()}
    if residuals and rows:
        # one row for the flat recording, then one per strip (coefficient_covariance pairs them)
        name, got = next(iter(rows.items()))
        if got != len(residuals) + 1:
            raise ConfigError(f"{name}: expected {len(residuals) + 1} rows (the flat recording and "
                              f"{len(residuals)} strips of strip_residuals), got {got}")
    return {
        "offset": offset,
        "coefficients_odd": coef,
        "coefficients_even": data["coefficients_even"],
        "degree": degree,
        "delta_a_range_odd": data["delta_a_range_odd"],
        "delta_a_range_even": data["delta_a_range_even"],
        "noise_std": data.get("noise_std"),
        "strip_residuals": residuals,
        "cv_errors_m": cv,
        "weighting": data.get("weighting", "none"),
        "sleeve": data.get("sleeve", False),
        "sensor": sensor,
        "fit_delta_a": fit.get("fit_delta_a"),
        "fit_shifts_m": fit.get("fit_shifts_m"),
        "meta": meta,
        "finger": data.get("finger"),
    }
