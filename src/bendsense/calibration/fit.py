"""Fitting a calibration from recordings of the flat sensor and of the strips (paper section V-B).

The steps of :meth:`Calibration.from_data <bendsense.calibration.Calibration.from_data>`,
each a function here: check the options and the recordings, turn them into one point
per recording and channel (the mean ΔA against the strip's shifts ``S_i = κ_cal d L_i``),
choose the degree (``"auto"``: cross-validation), fit ``f_odd`` and ``f_even``, and
measure the fit on every strip (:class:`StripResidual`). :func:`read_recordings` reads
the recordings a manifest names (:meth:`Calibration.fit
<bendsense.calibration.Calibration.fit>`).

The functions return the calibration's fields, which the class methods turn into a
:class:`~bendsense.calibration.Calibration`.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bendsense import validation as check
from bendsense.calibration.manifest import read_manifest
from bendsense.calibration.polynomials import (
    DEGREES,
    WEIGHTINGS,
    _cv_fold_errors,
    _fit_parities,
    parity_masks,
    polyval_shift,
    select_degree,
    strip_shifts,
)
from bendsense.errors import ArgumentError, ConfigError, SessionError

__all__ = ["StripResidual"]


@dataclass(frozen=True, kw_only=True)
class StripResidual:
    """Fit quality on one calibration strip.

    Attributes
    ----------
    radius_m : float
        Strip radius R as given [m].
    curvature_per_m : float
        κ_cal used as ground truth [1/m].
    rms_shift_m : float
        RMS of f(ΔA_i) − S_i over the channels [m].
    max_abs_shift_m : float
        Largest |f(ΔA_i) − S_i| over the channels [m].
    signal_std : float
        Mean over channels of the per-frame standard deviation of the recording
        [signal units] (a noise estimate).
    n_frames : int
        Frames averaged.
    recording : str
        File name of the recording.
    """

    radius_m: float
    curvature_per_m: float
    rms_shift_m: float
    max_abs_shift_m: float
    signal_std: float = 0.0
    n_frames: int = 0
    recording: str = ""

    def to_dict(self) -> dict:
        """Plain values, for YAML."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


def read_recordings(manifest_path: str | os.PathLike, sensor=None, channels=None) -> dict:
    """The recordings a manifest names, checked against the sensor, as :func:`fit_fields` takes them.

    Parameters
    ----------
    manifest_path : path
        Calibration manifest YAML; recording paths are relative to it.
    sensor : SensorConfig or Config, optional
        ``None``: the paper's sensor (``bendsense.load_config().sensor``).
    channels : sequence of int, optional
        The 1-based board channels of the sensor's segments (a gripper's finger): the
        recordings hold the whole board and these columns are taken; None: the
        recordings hold the sensor's channels alone.

    Returns
    -------
    dict
        ``flat_signals``, ``strip_signals_list``, ``radii_m``, ``sensor``, ``recordings``
        and ``meta``.

    Raises
    ------
    ConfigError
        For a bad manifest, a missing recording or a channel count that does not
        match the sensor; the message names the field and file.
    SessionError
        For a malformed recording (line and column in the message).
    """
    from bendsense.session import read_session_csv

    sensor = _resolve_sensor(sensor)
    manifest = read_manifest(manifest_path)
    n = sensor.n_segments

    def load(where, path):
        session = read_session_csv(path)
        if channels is not None:
            if session.n_channels < max(channels):
                raise ConfigError(f"{manifest.source}: {where} ({path.name}): the finger reads board channels "
                                  f"{min(channels)}..{max(channels)}, the recording has {session.n_channels}")
            if len(session) == 0:
                raise SessionError(f"{path}: no frames")
            return session.signals[:, [c - 1 for c in channels]]
        if session.n_channels != n:
            raise ConfigError(
                f"{manifest.source}: {where} ({path.name}): expected {n} channels "
                f"(sensor.n_segments), got {session.n_channels}"
            )
        if len(session) == 0:
            raise SessionError(f"{path}: no frames")
        return session.signals

    flat = load("flat", manifest.flat)
    strips = [load(f"strips[{i}].recording", p) for i, (_, p) in enumerate(manifest.strips)]
    return {
        "flat_signals": flat,
        "strip_signals_list": strips,
        "radii_m": [r for r, _ in manifest.strips],
        "sensor": sensor,
        "recordings": [p.name for _, p in manifest.strips],
        "meta": {"manifest": Path(manifest_path).name, "flat": manifest.flat.name},
    }


def fit_fields(flat_signals, strip_signals_list, radii_m, sensor=None, *, degree: int | str = 3,
               weighting: str = "none", sleeve: bool | None = None, recordings=None, meta: dict | None = None) -> dict:
    """The fields of a calibration fitted to in-memory recordings (:meth:`Calibration.from_data`).

    Parameters
    ----------
    flat_signals : array_like, shape (frames, N)
        Recording of the flat sensor.
    strip_signals_list : sequence of array_like, each (frames_k, N)
        One recording per calibration strip.
    radii_m : sequence of float
        Strip radii R [m].
    sensor : SensorConfig or Config, optional
        ``None``: the paper's sensor.
    degree, weighting, sleeve
        As in :meth:`Calibration.fit`.
    recordings : sequence of str, optional
        Names of the strip recordings, for the report.
    meta : dict, optional
        Extra metadata to store.

    Returns
    -------
    dict
        The keyword arguments of :class:`~bendsense.calibration.Calibration`.
    """
    sensor = _resolve_sensor(sensor)
    n = sensor.n_segments
    auto = _check_options(degree, weighting)
    sleeve = sensor.calibration_adds_sleeve if sleeve is None else bool(sleeve)
    flat, strips, radii = _check_recordings(flat_signals, strip_signals_list, radii_m, n)
    recordings = list(recordings) if recordings is not None else [f"strip {i}" for i in range(len(strips))]

    offset = flat.mean(axis=0)
    noise = flat.std(axis=0, ddof=1) if flat.shape[0] > 1 else None  # one frame: not measured
    extra = sensor.sleeve_thickness_m if sleeve else 0.0
    kappa = np.array([1.0 / (r + extra) for r in radii])
    delta = np.vstack([np.zeros(n)] + [s.mean(axis=0) - offset for s in strips])  # flat first
    shifts = strip_shifts(np.concatenate(([0.0], kappa)), sensor.lengths_m, sensor.strip_gap_m)
    odd, even = parity_masks(n)

    degree, cv = _choose_degree(delta, shifts, kappa, degree, weighting, auto)
    c_odd, c_even = _fit_parities(delta, shifts, degree, weighting, odd, even)

    resid = np.where(odd, polyval_shift(c_odd, delta), polyval_shift(c_even, delta)) - shifts
    even_delta = delta[:, even] if np.any(even) else delta[:, odd]
    info = {"created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    info["flat_frames"] = int(flat.shape[0])
    info.update(meta or {})
    return {
        "offset": offset,
        "coefficients_odd": c_odd,
        "coefficients_even": c_even,
        "degree": degree,
        "delta_a_range_odd": (float(delta[:, odd].min()), float(delta[:, odd].max())),
        "delta_a_range_even": (float(even_delta.min()), float(even_delta.max())),
        "noise_std": noise,
        "strip_residuals": _strip_residuals(resid, radii, kappa, strips, recordings),
        "cv_errors_m": cv,
        "weighting": weighting,
        "sleeve": sleeve,
        "sensor": sensor,
        "fit_delta_a": delta,
        "fit_shifts_m": shifts,
        "meta": info,
    }


def _check_options(degree, weighting) -> bool:
    """Check ``weighting`` and ``degree``; whether the degree is ``"auto"``."""
    if weighting not in WEIGHTINGS:
        raise ConfigError(f"weighting: must be one of {', '.join(WEIGHTINGS)}, got {check.short(weighting)}")
    auto = isinstance(degree, str) and degree == "auto"
    integer = isinstance(degree, (int, np.integer)) and not isinstance(degree, bool)
    if not auto and not (integer and degree in DEGREES):
        raise ConfigError(f"degree: must be 1..5 or 'auto', got {check.short(degree)}")
    return auto


def _check_recordings(flat_signals, strip_signals_list, radii_m, n: int):
    """The flat and strip recordings as (frames, n) arrays, and the strip radii [m]."""
    flat = _signals("flat", flat_signals, n)
    radii = [check.length_m(f"radii_m[{i}]", r, error=ConfigError) for i, r in enumerate(radii_m)]
    if len(radii) != len(strip_signals_list):
        raise ConfigError(f"radii_m: expected {len(strip_signals_list)} radii (one per strip), got {len(radii)}")
    if not radii:
        raise ConfigError("strips: at least one calibration strip is needed")
    strips = [_signals(f"strips[{i}]", s, n) for i, s in enumerate(strip_signals_list)]
    return flat, strips, radii


def _choose_degree(delta, shifts, kappa, degree, weighting, auto: bool):
    """The degree to fit, and the cross-validation errors per degree [m] when ``auto`` (else None)."""
    if not auto:
        return int(degree), None
    if len(kappa) < 2:
        raise ConfigError("degree: 'auto' needs at least 2 calibration strips for cross-validation")
    groups = np.arange(-1, len(kappa))
    # the tightest strip stays in training: predicting it would test extrapolation,
    # which `in_range` flags anyway, and its noisy fold would drive the degree choice
    groups[1 + int(np.argmax(kappa))] = -1
    fold_errors = _cv_fold_errors(delta, shifts, groups, DEGREES, weighting)
    cv = {d: math.sqrt(float(np.mean(e))) for d, e in fold_errors.items()}
    if not math.isfinite(min(cv.values())):
        raise ConfigError("degree: no degree 1..5 can be fitted to these recordings")
    return int(select_degree(fold_errors)), cv


def _strip_residuals(resid, radii, kappa, strips, recordings) -> tuple:
    """The fit's quality on every strip; ``resid`` (R, N) has the flat in its first row."""
    return tuple(
        StripResidual(
            radius_m=radii[k],
            curvature_per_m=float(kappa[k]),
            rms_shift_m=float(np.sqrt(np.mean(resid[k + 1] ** 2))),
            max_abs_shift_m=float(np.max(np.abs(resid[k + 1]))),
            signal_std=float(np.mean(strips[k].std(axis=0))),
            n_frames=int(strips[k].shape[0]),
            recording=str(recordings[k]),
        )
        for k in range(len(strips))
    )


def _signals(where: str, value, n: int) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != n:
        raise ConfigError(f"{where}: expected {n} channels (sensor.n_segments), got shape {a.shape}")
    if a.shape[0] == 0:
        raise ConfigError(f"{where}: no frames")
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{where}: signals must be finite")
    return a


def _resolve_sensor(sensor):
    if sensor is None:
        from bendsense.config import load_config

        return load_config().sensor
    from bendsense.config import SensorConfig

    sensor = getattr(sensor, "sensor", sensor)  # a whole Config is accepted too
    if not isinstance(sensor, SensorConfig):
        raise ArgumentError(f"sensor: expected a SensorConfig or a Config (bendsense.load_config(path)), got "
                            f"{type(sensor).__name__}")
    return sensor
