"""Sensor calibration: signals → total relative shifts (paper eq. 1–2, section V-B).

A calibration holds the offset A0 (the flat sensor's mean signal, paper eq. 1) and two
polynomials in ascending powers, ``f_odd`` for the odd channels i = 1, 3, … (1-based)
and ``f_even`` for the even ones (paper eq. 2): ``S_i = Σ_k c_k ΔA_i^k``.

It is fitted from a manifest of recordings (DESIGN.md section 3): the flat sensor and
one recording per calibration strip of radius R. For a strip the ground truth is
``S_i = κ_cal · d · L_i`` with L_i the cumulative segment length and κ_cal = 1/R, or
1/(R + c) when ``sensor.calibration_adds_sleeve`` (or ``sleeve=True``) says the strip
radius does not include the sleeve thickness c.

Choices made here where the paper is silent:

- Each recording enters the fit as the mean of its frames, one point per channel; the
  per-frame spread is kept as a noise estimate (``noise_std`` from the flat,
  ``StripResidual.signal_std`` per strip).
- The flat recording is a data point too: S = 0 at ΔA = 0 on every channel (a strip of
  zero curvature), which pins the polynomials through the origin's neighbourhood.
- ``weighting="none"`` (default) is the paper's ordinary least squares over all points.
  ``weighting="shift"`` weights the points of each parity by their spacing along the
  sorted shifts (a trapezoid rule in S), so the fit approximates ``∫ r(S)² dS`` over the
  calibrated shift range and the many small shifts (every strip starts at S = 0) stop
  dominating the few large ones — the imbalance the paper names as a likely cause of its
  larger errors at high curvature.
- ``degree="auto"`` picks the degree 1..5 by leave-one-strip-out cross-validation of
  the shift error: the smallest degree within one standard error of the best (the
  one-standard-error rule). The folds leave out every strip but the tightest one,
  whose prediction would be an extrapolation (flagged by ``in_range``) and whose
  noisy error would otherwise decide the degree; so ``auto`` needs >= 2 strips.
- ΔA is scaled to [−1, 1] for the least squares; the stored coefficients are plain
  ascending powers of ΔA.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from bendsense import validation as check
from bendsense._io import load_yaml
from bendsense.errors import ArgumentError, ConfigError, SessionError

log = logging.getLogger("bendsense")

__all__ = [
    "Calibration",
    "AngleCovariance",
    "StripResidual",
    "Manifest",
    "read_manifest",
    "strip_shifts",
    "polyfit_shift",
    "polyval_shift",
    "parity_masks",
    "cross_validate_degree",
    "select_degree",
    "WEIGHTINGS",
    "DEGREES",
]

FORMAT = "bendsense-calibration"
VERSION = 1
WEIGHTINGS = ("none", "shift")
DEGREES = (1, 2, 3, 4, 5)
RANGE_MARGIN_STD = 3.0


# --- pure functions ---------------------------------------------------------------------


def strip_shifts(curvature_per_m, lengths_m, strip_gap_m):
    """Total shifts of a sensor bent on an arc: ``S_i = κ · d · L_i`` (paper section V-B).

    Parameters
    ----------
    curvature_per_m : float or array_like, shape (...)
        Arc curvature κ_cal [1/m].
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    strip_gap_m : float
        Strip distance d [m].

    Returns
    -------
    ndarray, shape (..., N)
        S_i [m], with L_i = l_1 + … + l_i.
    """
    cumulative = np.cumsum(np.asarray(lengths_m, dtype=float))
    return np.asarray(curvature_per_m, dtype=float)[..., None] * strip_gap_m * cumulative


def parity_masks(n_channels: int):
    """Boolean masks of the odd (1-based i = 1, 3, …) and even channels.

    Parameters
    ----------
    n_channels : int
        Number of channels N.
    """
    odd = (np.arange(n_channels) % 2) == 0
    return odd, ~odd


def polyval_shift(coefficients, delta_a):
    """Evaluate ``Σ_k c_k ΔA^k`` (ascending powers, Horner's rule; paper eq. 2).

    Parameters
    ----------
    coefficients : array_like, shape (n + 1,) or (..., n + 1)
        Coefficients c_k in ascending powers [m / unit^k].
    delta_a : array_like
        Signal change ΔA = A − A0 [signal units].
    """
    c = np.asarray(coefficients, dtype=float)
    x = np.asarray(delta_a, dtype=float)
    out = np.full(x.shape, c[-1])
    for ck in c[-2::-1]:
        out = out * x + ck
    return out


def polyfit_shift(delta_a, shifts_m, degree: int, weights=None):
    """Weighted least-squares polynomial ``S = Σ_k c_k ΔA^k``, k = 0..degree (paper eq. 2).

    ΔA is scaled by its largest magnitude for conditioning; the result is in plain
    ascending powers of ΔA.

    Parameters
    ----------
    delta_a : array_like, shape (P,)
        Offset-free signals ΔA [signal units].
    shifts_m : array_like, shape (P,)
        Ground-truth shifts S [m].
    degree : int
        Polynomial degree n >= 0.
    weights : array_like, shape (P,), optional
        Non-negative weights of the squared residuals.

    Returns
    -------
    ndarray, shape (degree + 1,)
        Coefficients c_0..c_n.

    Raises
    ------
    ConfigError
        If the data cannot determine a polynomial of this degree.
    """
    x = np.asarray(delta_a, dtype=float).ravel()
    y = np.asarray(shifts_m, dtype=float).ravel()
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=float).ravel()
    keep = w > 0
    x, y, w = x[keep], y[keep], w[keep]
    distinct = np.unique(x).size
    if distinct < degree + 1:
        raise ConfigError(
            f"degree: {degree} needs at least {degree + 1} distinct signal levels per parity, got {distinct}"
        )
    scale = float(np.max(np.abs(x))) or 1.0
    vander = np.vander(x / scale, degree + 1, increasing=True)
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(vander * sw[:, None], y * sw, rcond=None)
    return coef / scale ** np.arange(degree + 1)


_MISFIT_POINTS = 240  # calibration points in the misfit likelihood (16 channels × 15 strips)


def _misfit_correlation(x, z, odd, top) -> dict:
    """Maximum-likelihood correlation of the calibration misfit (:meth:`Calibration.shift_error_m`).

    ``z`` (K,): the fit residuals at the shifts ``x`` scaled by their envelope σ, ``odd``
    their parity. The model: a Gaussian process with ``Cov(z_a, z_b) = (1 − w) c_ab
    exp(−(x_a − x_b)² / 2ℓ²) + w δ_ab`` (``c_ab`` 1 within a parity, ``c`` between),
    its parameters ℓ, ``c`` and the white fraction ``w`` chosen on a grid by the
    likelihood of ``z``. The white part (the noise of the strip means, the offsets)
    keeps ℓ from collapsing onto the closest pair of points. At most ``_MISFIT_POINTS``
    points, evenly spaced in ``x``, enter the likelihood (its cost grows with their cube).
    """
    if x.size > _MISFIT_POINTS:
        keep = np.argsort(x, kind="stable")[np.linspace(0, x.size - 1, _MISFIT_POINTS).round().astype(int)]
        x, z, odd = x[keep], z[keep], odd[keep]
    same = odd[:, None] == odd[None, :]
    lag2 = np.square(x[:, None] - x[None, :])
    eye = np.eye(x.size)
    best = (-np.inf, 0.0, 0.0, 1.0)
    for ell in np.geomspace(top / 300.0, top, 30):
        g = np.exp(-0.5 * lag2 / ell**2)
        for c in (0.0, 0.5, 0.9, 0.97):
            gc = g * np.where(same, 1.0, c)
            for w in (1e-3, 1e-2, 3e-2, 0.1, 0.3):
                try:
                    lc = np.linalg.cholesky((1.0 - w) * gc + w * eye)
                except np.linalg.LinAlgError:
                    continue
                y = np.linalg.solve(lc, z)
                ll = -0.5 * float(y @ y) - float(np.log(np.diag(lc)).sum())
                if ll > best[0]:
                    best = (ll, float(ell), float(c), float(w))
    return {"length_m": best[1], "parity_correlation": best[2], "white_fraction": best[3]}


def _shift_weights(shifts):
    """Trapezoid weights along the sorted shifts (the ``"shift"`` weighting), mean 1."""
    s = np.asarray(shifts, dtype=float).ravel()
    order = np.argsort(s, kind="stable")
    ss = s[order]
    w_sorted = np.zeros_like(ss)
    if ss.size > 1:
        gaps = np.diff(ss)
        w_sorted[:-1] += 0.5 * gaps
        w_sorted[1:] += 0.5 * gaps
    total = w_sorted.sum()
    if total <= 0:
        return np.ones_like(s)
    w = np.empty_like(s)
    w[order] = w_sorted
    return w * (s.size / total)


def _fit_parities(delta_a, shifts, degree, weighting, odd, even):
    """Fit f_odd and f_even on rows of (R, N) data."""
    out = []
    for mask in (odd, even):
        if not np.any(mask):  # a one-channel sensor has no even channels
            out.append(out[0].copy())
            continue
        x, y = delta_a[:, mask], shifts[:, mask]
        w = _shift_weights(y) if weighting == "shift" else None
        out.append(polyfit_shift(x, y, degree, w))
    return out[0], out[1]


def _cv_fold_errors(delta_a, shifts, groups, degrees, weighting):
    """Mean squared held-out shift error of every fold, per degree ({degree: (K,)})."""
    odd, even = parity_masks(delta_a.shape[1])
    folds = sorted(set(groups[groups >= 0].tolist()))
    result = {}
    for degree in degrees:
        errors = []
        try:
            for g in folds:
                train = groups != g
                c_odd, c_even = _fit_parities(delta_a[train], shifts[train], degree, weighting, odd, even)
                test = ~train
                pred = np.where(odd, polyval_shift(c_odd, delta_a[test]), polyval_shift(c_even, delta_a[test]))
                errors.append(float(np.mean((pred - shifts[test]) ** 2)))
        except ConfigError:
            errors = [math.inf] * len(folds)
        result[int(degree)] = np.array(errors)
    return result


def cross_validate_degree(delta_a, shifts_m, groups, degrees=DEGREES, weighting="none"):
    """Leave-one-strip-out cross-validation of the polynomial degree.

    Parameters
    ----------
    delta_a, shifts_m : array_like, shape (R, N)
        Per-recording mean ΔA and ground-truth shifts S [m].
    groups : array_like of int, shape (R,)
        Strip index of every row; rows with a negative group (the flat) are always
        kept in the training set.
    degrees : iterable of int
        Candidate degrees.
    weighting : str
        ``"none"`` or ``"shift"``.

    Returns
    -------
    dict of int to float
        RMS held-out shift error per degree [m] (``inf`` if a fold cannot be fitted).
    """
    errors = _cv_fold_errors(
        np.asarray(delta_a, dtype=float), np.asarray(shifts_m, dtype=float), np.asarray(groups), degrees, weighting
    )
    return {d: math.sqrt(float(np.mean(e))) if e.size else math.inf for d, e in errors.items()}


def select_degree(fold_errors: dict) -> int:
    """Smallest degree within one standard error of the best CV error (the one-SE rule).

    Extra degrees fit the noise of the training strips as readily as the sensor's
    curve; the rule keeps the simplest polynomial that CV cannot tell apart from the
    best one.

    Parameters
    ----------
    fold_errors : dict of int to ndarray
        Per degree, the leave-one-strip-out RMS shift error of each fold [m].
    """
    mean = {d: float(np.mean(e)) for d, e in fold_errors.items()}
    best = min(mean, key=mean.get)
    e = fold_errors[best]
    se = float(np.std(e, ddof=1) / math.sqrt(e.size)) if e.size > 1 else 0.0
    return min(d for d, m in mean.items() if m <= mean[best] + se)


# --- manifest ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Manifest:
    """A parsed calibration manifest: absolute recording paths and strip radii [m]."""

    flat: Path
    strips: tuple  # of (radius_m, Path)
    source: str = ""


_STRIP_KEYS = ("radius_m", "radius_mm", "recording")


def _radius_m(where: str, item: dict) -> float:
    """The strip radius of a manifest entry [m]: ``radius_m``, or ``radius_mm`` converted."""
    if "radius_m" in item:
        # a strip radius over 1 m is millimetres written as metres
        return check.length_m(f"{where}.radius_m", item["radius_m"], error=ConfigError)
    radius_mm = check.number(f"{where}.radius_mm", item["radius_mm"], error=ConfigError, positive=True)
    if radius_mm < 1:
        raise ConfigError(f"{where}.radius_mm: expected a radius in millimetres >= 1, got {radius_mm:g}; "
                          f"looks like metres (did you mean radius_m: {radius_mm:g}?)")
    return check.length_m(f"{where}.radius_mm", radius_mm * 1e-3, error=ConfigError)


def read_manifest(path: str | os.PathLike) -> Manifest:
    """Read and check a calibration manifest (DESIGN.md section 3).

    Parameters
    ----------
    path : str or path-like
        The manifest YAML file; recording paths in it are relative to it.

    Raises
    ------
    ConfigError
        Naming the file and the field, e.g. ``strips[2].radius_cm: unknown key``.
    """
    path = Path(path)
    return load_yaml(path, "manifest", lambda data: _parse_manifest(data, path.parent, str(path)))


def _recording(where: str, value: Any, base: Path) -> Path:
    if not isinstance(value, str) or not value:
        raise check.fail(where, "a file name", value, ConfigError)
    full = base / value
    if not full.is_file():
        raise ConfigError(f"{where}: no such recording {check.short(value)} ({check.short(str(full), 200)})")
    return full


def _parse_manifest(data: Any, base: Path, source: str) -> Manifest:
    if not isinstance(data, dict):
        raise check.fail("manifest", "a mapping with keys flat, strips", data, ConfigError)
    for key in data:
        if key not in ("flat", "strips"):
            raise ConfigError(f"{check.key(key)}: unknown key; allowed: flat, strips")
    for key in ("flat", "strips"):
        if key not in data:
            raise ConfigError(f"{key}: missing key")
    flat = _recording("flat", data["flat"], base)
    strips = data["strips"]
    if not isinstance(strips, list) or not strips:
        raise check.fail("strips", "a non-empty list of {radius_m: ..., recording: ...}", strips, ConfigError)
    out = []
    for i, item in enumerate(strips):
        where = f"strips[{i}]"
        if not isinstance(item, dict):
            raise check.fail(where, "a mapping with radius_m or radius_mm and recording", item, ConfigError)
        for key in item:
            if key not in _STRIP_KEYS:
                raise ConfigError(f"{where}.{check.key(key)}: unknown key; allowed: {', '.join(_STRIP_KEYS)}")
        if "radius_m" in item and "radius_mm" in item:
            raise ConfigError(f"{where}: give exactly one of radius_m, radius_mm, got both")
        if "radius_m" not in item and "radius_mm" not in item:
            raise ConfigError(f"{where}: missing key radius_m or radius_mm")
        radius = _radius_m(where, item)
        if "recording" not in item:
            raise ConfigError(f"{where}: missing key recording")
        recording = _recording(f"{where}.recording", item["recording"], base)
        # one recording counted twice would weigh its strip double; the flat as a strip is a mix-up
        if recording.resolve() == flat.resolve():
            raise ConfigError(f"{where}.recording: {recording.name} is the flat recording too")
        for j, (seen_radius, seen) in enumerate(out):
            if recording.resolve() == seen.resolve():
                raise ConfigError(f"{where}.recording: {recording.name} is listed twice (strips[{j}] too)")
            if seen_radius == radius:  # a repeated strip is fine; a mistyped radius is the common cause
                log.warning("%s: strips[%d] and strips[%d] have the same radius %g m (%s, %s): a repeated "
                            "measurement, or a mistyped radius?", source, j, len(out), radius, seen.name,
                            recording.name)
        out.append((radius, recording))
    return Manifest(flat=flat, strips=tuple(out), source=source)


# --- result object -----------------------------------------------------------------------


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


@dataclass(frozen=True, eq=False)
class AngleCovariance:
    """Covariance of the measured tangent angles ``φ(L_i) = S_i / d``, by source.

    Attributes
    ----------
    noise : ndarray, shape (..., N, N)
        The frame's signal noise through the calibration's slopes [rad²]; diagonal.
    calibration : ndarray, shape (..., N, N)
        The calibration's error: its coefficients and offsets (from the noise of
        the recordings it was fitted to) and the polynomials' misfit [rad²].
    """

    noise: np.ndarray
    calibration: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """``noise + calibration`` [rad²], shape (..., N, N)."""
        return self.noise + self.calibration

    @property
    def std_rad(self) -> np.ndarray:
        """Standard deviation of each angle from ``total`` [rad], shape (..., N)."""
        return np.sqrt(np.diagonal(self.total, axis1=-2, axis2=-1))


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


def _range(where: str, value: Any) -> tuple:
    arr = _array(where, value, 2)
    if arr[0] > arr[1]:
        raise ConfigError(f"{where}: expected [min, max] with min <= max, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]))


@dataclass(frozen=True, kw_only=True, eq=False)
class Calibration:
    """Signal → shift calibration of the sensor (paper eq. 1–2).

    Attributes
    ----------
    offset : ndarray, shape (N,)
        A0, the mean signal of the flat sensor [signal units] (paper eq. 1).
    coefficients_odd, coefficients_even : ndarray, shape (n + 1,)
        Coefficients a_k, b_k of f_odd and f_even in ascending powers [m / unit^k].
    degree : int
        Polynomial degree n.
    delta_a_range_odd, delta_a_range_even : tuple of float
        (min, max) of the fitted ΔA per parity [signal units].
    noise_std : ndarray, shape (N,)
        Per-channel signal noise, the flat recording's frame standard deviation.
    strip_residuals : tuple of StripResidual
        Fit quality on every calibration strip.
    cv_errors_m : dict of int to float or None
        Leave-one-strip-out RMS shift error per degree [m], when computed.
    weighting : str
        ``"none"`` or ``"shift"`` (see the module docstring).
    sleeve : bool
        Whether κ_cal = 1/(R + c) was used.
    sensor : SensorConfig or None
        Snapshot of the sensor the calibration was fitted for.
    fit_delta_a, fit_shifts_m : ndarray, shape (R, N), optional
        The fitted data (flat first, then one row per strip), for plots.
    meta : dict
        Free-form metadata (creation time, manifest).
    """

    offset: np.ndarray
    coefficients_odd: np.ndarray
    coefficients_even: np.ndarray
    degree: int
    delta_a_range_odd: tuple
    delta_a_range_even: tuple
    noise_std: np.ndarray | None = None
    strip_residuals: tuple = ()
    cv_errors_m: dict | None = None
    weighting: str = "none"
    sleeve: bool = False
    sensor: Any = None
    fit_delta_a: np.ndarray | None = None
    fit_shifts_m: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        set_ = object.__setattr__
        offset = _array("offset", self.offset)
        n = offset.size
        if n == 0:
            raise ConfigError("offset: expected at least one channel, got 0")
        set_(self, "offset", offset)
        c_odd = _array("coefficients_odd", self.coefficients_odd)
        c_even = _array("coefficients_even", self.coefficients_even)
        if isinstance(self.degree, bool) or not isinstance(self.degree, (int, np.integer)) or self.degree < 0:
            raise ConfigError(f"degree: expected an integer >= 0, got {check.short(self.degree)}")
        for name, c in (("coefficients_odd", c_odd), ("coefficients_even", c_even)):
            if c.size != self.degree + 1:
                raise ConfigError(
                    f"{name}: expected {self.degree + 1} coefficients (degree {self.degree}), got {c.size}"
                )
        set_(self, "degree", int(self.degree))
        set_(self, "coefficients_odd", c_odd)
        set_(self, "coefficients_even", c_even)
        set_(self, "delta_a_range_odd", _range("delta_a_range_odd", self.delta_a_range_odd))
        set_(self, "delta_a_range_even", _range("delta_a_range_even", self.delta_a_range_even))
        # noise_std stays an array (zeros when not measured) for the range margin;
        # noise_known tells a measured zero from a missing value
        set_(self, "_noise_known", self.noise_std is not None)
        noise = np.zeros(n) if self.noise_std is None else _array("noise_std", self.noise_std, n)
        if np.any(noise < 0):
            raise ConfigError(f"noise_std: values must be >= 0, got {noise.tolist()}")
        set_(self, "noise_std", noise)
        if self.weighting not in WEIGHTINGS:
            raise ConfigError(f"weighting: must be one of {', '.join(WEIGHTINGS)}, got {check.short(self.weighting)}")
        if not isinstance(self.sleeve, bool):
            raise ConfigError(f"sleeve: expected true or false, got {check.short(self.sleeve)}")
        if self.sensor is not None and getattr(self.sensor, "n_segments", n) != n:
            raise ConfigError(
                f"sensor.n_segments: expected {n} (the calibration's channels), got {self.sensor.n_segments}"
            )
        set_(self, "strip_residuals", tuple(self.strip_residuals))
        for name in ("fit_delta_a", "fit_shifts_m"):
            value = getattr(self, name)
            if value is not None:
                arr = np.asarray(value, dtype=float)
                if arr.ndim != 2 or arr.shape[1] != n:
                    raise ConfigError(f"{name}: expected shape (recordings, {n}), got {arr.shape}")
                set_(self, name, arr)
        if self.fit_delta_a is not None and self.fit_shifts_m is not None:
            rows = (self.fit_delta_a.shape[0], self.fit_shifts_m.shape[0])
            if rows[0] != rows[1]:
                raise ConfigError(f"fit_delta_a, fit_shifts_m: expected the same recordings, got {rows[0]} and "
                                  f"{rows[1]} rows")

    # -- the hot path: per-channel arrays precomputed once ---------------------------

    @property
    def n_channels(self) -> int:
        """Number of channels N."""
        return self.offset.size

    @cached_property
    def _channel_coefficients(self) -> np.ndarray:
        odd, _ = parity_masks(self.n_channels)
        return np.where(odd[:, None], self.coefficients_odd, self.coefficients_even)  # (N, n+1)

    @cached_property
    def _channel_range(self):
        odd, _ = parity_masks(self.n_channels)
        lo = np.where(odd, self.delta_a_range_odd[0], self.delta_a_range_even[0])
        hi = np.where(odd, self.delta_a_range_odd[1], self.delta_a_range_even[1])
        margin = RANGE_MARGIN_STD * self.noise_std
        return lo - margin, hi + margin

    @cached_property
    def _coefficient_columns(self) -> tuple:
        # per-channel coefficients of each power, highest first, contiguous (Horner's rule)
        c = self._channel_coefficients
        return tuple(np.ascontiguousarray(c[:, k]) for k in range(self.degree, -1, -1))

    @cached_property
    def _slope_columns(self) -> tuple:
        # the same for the slopes f'(ΔA) (highest power first); () for degree 0
        c = self._channel_coefficients
        return tuple(np.ascontiguousarray(k * c[:, k]) for k in range(self.degree, 0, -1))

    @cached_property
    def _noise_positive(self) -> bool:
        return bool(np.any(self.noise_std > 0))

    @cached_property
    def _linear_slope(self):
        # the linear coefficient per channel: where it is nonzero, and it with 1 elsewhere
        slope = self._channel_coefficients[:, 1] if self.degree > 0 else np.zeros(self.n_channels)
        nonzero = slope != 0
        return nonzero, np.where(nonzero, slope, 1.0)

    def shifts_from_delta(self, delta_a):
        """Shifts S (..., N) [m] from offset-free signals ΔA (..., N) (paper eq. 2).

        Parameters
        ----------
        delta_a : array_like, shape (..., N)
            Signal changes ΔA = A − A0 [signal units].
        """
        cols = self._coefficient_columns
        out = cols[0] + 0.0 * delta_a
        for ck in cols[1:]:
            out = out * delta_a + ck
        return out

    def shifts_m(self, signals):
        """Total relative shifts S (..., N) [m] from raw signals A (..., N) (paper eq. 1–2).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [signal units].
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return self.shifts_from_delta(a - self.offset)

    def shift_error_m(self, shifts_m, *, covariance: bool = False):
        """Model error of the calibration polynomials at shifts ``shifts_m`` [m].

        The polynomials of eq. 2 do not fit the coil response exactly; the misfit
        ``r(S) = f(ΔA) − S`` is a smooth function of the shift that grows with ``|S|``,
        one per parity. It is treated as a random smooth function: zero mean, standard
        deviation ``σ_p(|S|)`` the kernel-smoothed RMS of the fit residuals of the
        channels of parity p (Gaussian kernel, bandwidth a tenth of the largest fitted
        shift; constant beyond the largest fitted shift), and correlation
        ``ρ_ij = (1 − w) c_ij exp(−(S_i − S_j)² / 2ℓ²)`` between channels i ≠ j, with
        ``c_ij = 1`` within a parity and ``c`` between the odd and even polynomials.
        ``ℓ``, ``c`` and the white fraction ``w`` are maximum-likelihood fits of that
        Gaussian process to the residuals scaled by ``σ`` (:func:`_misfit_correlation`).
        So channels whose shifts are close err together, which independent errors miss.
        Without the fitted data (an old calibration file) ``σ`` is the RMS of the
        per-strip residuals for both parities and the channels are independent.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S of the N channels [m].
        covariance : bool
            Return the covariance between the channels instead of ``σ``.

        Returns
        -------
        ndarray, shape (..., N) or (..., N, N)
            ``σ(|S|)`` [m], or the covariance ``σ_i σ_j ρ_ij`` [m²].
        """
        s = np.asarray(shifts_m, dtype=float)
        n = self.n_channels
        if s.ndim == 0 or s.shape[-1] != n:
            raise ArgumentError(f"shifts_m: expected shape (..., {n}), got {s.shape}")
        if covariance:  # the misfit part of the one shift-covariance kernel (no noise, exact coefficients)
            from bendsense.shift_errors import shift_covariances

            model = self.error_model(0.0)._replace(coef_cov=np.zeros((1, 1)))
            flat = np.ascontiguousarray(np.broadcast_to(s, s.shape).reshape(-1, n))
            out, noise_var = np.empty((flat.shape[0], n, n)), np.empty((flat.shape[0], n))
            shift_covariances(model, flat, out, noise_var)
            return out.reshape(*s.shape, n)
        model = self._shift_error_table
        odd, _ = self._parity_correlation
        grid = model["grid_m"]
        a = np.abs(s)
        return np.where(odd, np.interp(a, grid, model["sigma_odd_m"]), np.interp(a, grid, model["sigma_even_m"]))

    @cached_property
    def _parity_correlation(self):
        # the odd channels, and c_ij of shift_error_m: 1 on the diagonal, 1 − w within a
        # parity, (1 − w) c between them (w: the misfit's white fraction)
        odd, _ = parity_masks(self.n_channels)
        same = odd[:, None] == odd[None, :]
        table = self._shift_error_table
        smooth = 1.0 - table.get("white_fraction", 0.0)
        c = np.where(same, smooth, smooth * table["parity_correlation"])
        np.fill_diagonal(c, 1.0)
        return odd, c

    @cached_property
    def _shift_error_table(self) -> dict:
        # grid_m, sigma_odd_m, sigma_even_m: the envelopes σ_p(|S|) [m]; length_m: ℓ [m]
        # (0: independent channels); parity_correlation: c; white_fraction: w (see shift_error_m)
        if self.fit_delta_a is None or self.fit_shifts_m is None:
            rms = [r.rms_shift_m for r in self.strip_residuals]
            level = float(np.sqrt(np.mean(np.square(rms)))) if rms else 0.0
            flat = np.array([level, level])
            return {"grid_m": np.array([0.0, 1.0]), "sigma_odd_m": flat, "sigma_even_m": flat, "length_m": 0.0,
                    "parity_correlation": 0.0}
        shifts = self.fit_shifts_m
        resid = self.shifts_from_delta(self.fit_delta_a) - shifts
        odd, even = parity_masks(self.n_channels)
        top = float(np.abs(shifts).max())
        grid = np.linspace(0.0, top, 65)
        h = 0.1 * top if top > 0 else 1.0

        def envelope(mask):
            x = np.abs(shifts[:, mask]).ravel()
            k = np.exp(-0.5 * ((grid[:, None] - x[None, :]) / h) ** 2)
            return np.sqrt(k @ resid[:, mask].ravel() ** 2 / k.sum(axis=1))

        sig_odd = envelope(odd)
        sig_even = envelope(even) if np.any(even) else sig_odd
        out = {"grid_m": grid, "sigma_odd_m": sig_odd, "sigma_even_m": sig_even, "length_m": 0.0,
               "parity_correlation": 0.0}
        level = np.where(odd, np.interp(np.abs(shifts), grid, sig_odd), np.interp(np.abs(shifts), grid, sig_even))
        if top > 0 and np.all(level > 0):
            out.update(_misfit_correlation(shifts.ravel(), (resid / level).ravel(),
                                           np.broadcast_to(odd, shifts.shape).ravel(), top))
        return out

    def extrapolated_delta(self, delta_a):
        """Per frame: True if any channel's ΔA lies outside the calibrated range.

        Parameters
        ----------
        delta_a : array_like, shape (..., N)
            Signal changes ΔA = A − A0 [signal units].
        """
        lo, hi = self._channel_range
        return np.any((delta_a < lo) | (delta_a > hi), axis=-1)

    def in_range(self, signals):
        """Per frame (...,): True if every channel's ΔA lies in the fitted range.

        The range is the (min, max) of the fitted ΔA of the channel's parity, widened
        by 3 × the channel's flat-recording noise so that a flat, noisy sensor is not
        flagged. Outside it the polynomials extrapolate and the shape is not to be
        trusted; :func:`bendsense.pcc.reconstruct` reports this as ``Shape.extrapolated``.

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [signal units].
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return ~self.extrapolated_delta(a - self.offset)

    def _check_channels(self, a):
        if a.shape[-1:] != (self.n_channels,):
            raise ArgumentError(f"signals: expected {self.n_channels} channels on the last axis, got shape {a.shape}")

    # -- the measurement model: public methods for the estimator ------------------------

    @property
    def noise_known(self) -> bool:
        """Whether the per-channel noise was measured (False for an old file without ``noise_std``)."""
        return self._noise_known

    def noise_std_counts(self) -> np.ndarray:
        """Per-channel signal noise σ_A [counts], the flat recording's frame standard deviation.

        Returns
        -------
        ndarray, shape (N,)
            ``noise_std`` as measured at fit time (a measured zero stays zero).

        Raises
        ------
        ConfigError
            If the calibration does not hold a measured noise (a file without
            ``noise_std``, or a flat recording of a single frame).
        """
        if not self._noise_known:
            raise ConfigError(
                "calibration: noise_std is missing (not measured: an older file or a one-frame flat "
                "recording); refit with `bendsense calibrate` from a flat recording of many frames"
            )
        return self.noise_std

    def shift_slopes(self, signals) -> np.ndarray:
        """Slopes dS/dA of the calibration at raw signals A, per channel (paper eq. 2).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].

        Returns
        -------
        ndarray, shape (..., N)
            ``f_i'(A_i − A0_i)`` [m/count], with f_odd for odd and f_even for even channels.
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return self._slopes_from_delta(a - self.offset)

    def _slopes_from_delta(self, delta_a):
        cols = self._slope_columns
        if not cols:
            return np.zeros(np.shape(delta_a))
        out = cols[0] + 0.0 * delta_a
        for ck in cols[1:]:
            out = out * delta_a + ck
        return out

    def delta_from_shifts(self, shifts_m) -> np.ndarray:
        """Offset-free signals ΔA with ``f_i(ΔA_i) = S_i``: the inverse of :meth:`shifts_from_delta`.

        Per channel, a safeguarded Newton iteration inside the fitted ΔA range of its
        parity widened by its width on both sides, where the root is bracketed (the
        polynomials are monotone there for a sensible calibration); elsewhere plain
        Newton from the linear inverse. Converges to ~1e-13 relative.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S [m].

        Returns
        -------
        ndarray, shape (..., N)
            ΔA [counts]; NaN where no inverse was found (a shift the polynomial
            never reaches, or a non-finite shift).
        """
        s = np.asarray(shifts_m, dtype=float)
        if s.ndim == 0 or s.shape[-1] != self.n_channels:
            raise ArgumentError(f"shifts_m: expected shape (..., {self.n_channels}), got {s.shape}")
        s = np.broadcast_to(s, s.shape).copy()
        lo_r, hi_r = self._channel_range
        width = np.maximum(hi_r - lo_r, 1e-12)
        lo = np.broadcast_to(lo_r - width, s.shape).copy()
        hi = np.broadcast_to(hi_r + width, s.shape).copy()
        g_lo = self.shifts_from_delta(lo) - s
        g_hi = self.shifts_from_delta(hi) - s
        sign = np.where(g_hi >= g_lo, 1.0, -1.0)
        bracketed = (g_lo * sign <= 0) & (g_hi * sign >= 0)
        nonzero, safe = self._linear_slope
        c0 = self._channel_coefficients[:, 0]
        x = np.where(nonzero, (s - c0) / safe, 0.0)  # the linear inverse, kept inside the bracket
        x = np.where(bracketed, np.clip(x, lo, hi), x)
        done = ~np.isfinite(s)
        tol_s = 1e-14 * np.maximum(np.abs(s), 1e-6)  # round-off of the shift [m]
        for _ in range(200):
            g = self.shifts_from_delta(x) - s
            done |= np.abs(g) <= tol_s
            if done.all():
                break
            fp = self._slopes_from_delta(x)
            h = g * sign
            lo = np.where(bracketed & (h < 0), x, lo)
            hi = np.where(bracketed & (h > 0), x, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                new = x - g / fp
            bad = ~np.isfinite(new) | (bracketed & ~((new >= lo) & (new <= hi)))
            new = np.where(bad, np.where(bracketed, 0.5 * (lo + hi), x), new)
            step = np.abs(new - x)
            x = np.where(done, x, new)
            done |= step <= 1e-13 * np.maximum(np.abs(x), width)
        ok = np.abs(self.shifts_from_delta(x) - s) <= 1e-9 * np.maximum(np.abs(s), 1e-9)
        return np.where(ok & np.isfinite(s), x, np.nan)

    def signals_from_shifts(self, shifts_m) -> np.ndarray:
        """Raw signals A = A0 + ΔA that the calibration maps to the shifts S (inverse of :meth:`shifts_m`).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S [m].

        Returns
        -------
        ndarray, shape (..., N)
            Signals A [counts]; NaN where the polynomial has no inverse
            (:meth:`delta_from_shifts`).
        """
        return self.delta_from_shifts(shifts_m) + self.offset

    def strip_gap_m(self, sensor=None) -> float:
        """The strip gap d the calibration's shifts were labelled with (``S = κ_cal d L_i``) [m].

        The calibration's own sensor snapshot wins: its shifts are ``d_cal`` times an
        angle, whatever gap another config states (docs/theory.md, "What the sensor
        measures"). Without a snapshot (an old file) the ``sensor`` given is used.

        Parameters
        ----------
        sensor : SensorConfig or Config, optional
            The sensor to use when the calibration has no snapshot of its own.

        Raises
        ------
        ConfigError
            Without a snapshot and without ``sensor``; or if ``sensor`` has another
            channel count or other segment lengths than the snapshot.
        """
        sensor = getattr(sensor, "sensor", sensor)
        if sensor is not None:
            if sensor.n_segments != self.n_channels:
                raise ConfigError(
                    f"sensor.n_segments: expected {self.n_channels} (the calibration's channels), "
                    f"got {sensor.n_segments}"
                )
            if self.sensor is not None and not np.allclose(sensor.lengths_m, self.sensor.lengths_m, rtol=1e-9):
                raise ConfigError(
                    f"sensor.segment_lengths_m: {list(sensor.segment_lengths_m)} differ from the calibration's "
                    f"{list(self.sensor.segment_lengths_m)}; the coil positions L_i would be ambiguous"
                )
        if self.sensor is not None:
            return float(self.sensor.strip_gap_m)
        if sensor is None:
            raise ConfigError(
                "calibration: sensor is missing (no snapshot of the sensor it was fitted for); "
                "pass the sensor (config) the calibration was fitted with"
            )
        return float(sensor.strip_gap_m)

    def angles_rad(self, signals, sensor=None) -> np.ndarray:
        """Tangent angle at each receiver coil, ``φ(L_i) = S_i / d`` (DESIGN "What the sensor measures").

        The shift of segment i is ``S_i = d φ(L_i)`` (paper eq. 3–4 read backwards);
        the calibration labelled its strips ``S_i = κ_cal d L_i`` with its own ``d``
        (:meth:`strip_gap_m`), so ``S_i / d`` is ``κ_cal L_i`` on a strip whatever
        the physical gap, and ``κ_cal`` (1/R, or 1/(R + c) with ``sleeve``) is the
        curvature of the receiver strip by the calibration's convention. Tangent
        angles of parallel curves agree at corresponding points, so no sleeve term
        enters here; docs/theory.md derives this and what a wrong convention costs.

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].
        sensor : SensorConfig or Config, optional
            Checked against the calibration's sensor snapshot; gives ``d`` for an
            old calibration without a snapshot.

        Returns
        -------
        ndarray, shape (..., N)
            φ(L_i) relative to the base [rad], L_i the cumulative segment lengths.
        """
        return self.shifts_m(signals) / self.strip_gap_m(sensor)

    def error_model(self, noise_std_counts=None):
        """The errors of this calibration's shifts as the compiled kernels take them.

        Parameters
        ----------
        noise_std_counts : array_like (N,), optional
            Signal noise per channel [counts]; default the flat recording's
            (``noise_std``, zero where unknown).

        Returns
        -------
        bendsense.shift_errors.ShiftErrorModel
            The channels' polynomials, the noise, the misfit envelopes with their
            correlation (:meth:`shift_error_m`) and the coefficients' and offsets'
            covariance (:attr:`coefficient_covariance`; zeros when the file lacks what
            it needs). :func:`bendsense.shift_errors.shift_covariance` evaluates it.
        """
        from bendsense.shift_errors import ShiftErrorModel

        noise = self.noise_std if noise_std_counts is None else noise_std_counts
        try:
            noise = np.array(np.broadcast_to(np.asarray(noise, dtype=float), (self.n_channels,)))
        except (TypeError, ValueError):
            raise ArgumentError(f"noise_std_counts: expected a number or {self.n_channels} numbers [counts], got "
                                f"{check.short(noise_std_counts)}") from None
        if not (np.all(np.isfinite(noise)) and np.all(noise >= 0)):
            raise ArgumentError(f"noise_std_counts: must be finite and >= 0, got {noise.tolist()}")
        coef = np.array(self._channel_coefficients, dtype=float)
        table = self._shift_error_table
        odd, parity = self._parity_correlation
        try:
            q = np.array(self.coefficient_covariance, dtype=float)
        except ConfigError:  # an old file without the fitted data or frame counts
            q = np.zeros((1, 1))
        return ShiftErrorModel(
            calibrated=True, noise_std=noise, coef=coef, dcoef=coef[:, 1:] * np.arange(1, coef.shape[1]),
            grid_m=np.array(table["grid_m"], dtype=float), sigma_odd_m=np.array(table["sigma_odd_m"], dtype=float),
            sigma_even_m=np.array(table["sigma_even_m"], dtype=float), odd=np.array(odd), parity=np.array(parity),
            length_m=float(table["length_m"]), coef_cov=q)

    def angle_covariance(self, signals, sensor=None) -> AngleCovariance:
        """Covariance of the measured angles :meth:`angles_rad`, by source (docs/theory.md).

        - ``noise``: the frame's signal noise through the slopes,
          ``diag(f_i'(ΔA_i)² σ_i²) / d²``, σ from :meth:`noise_std_counts`;
        - ``calibration``: the calibration's own error, the same for every frame
          that sees the same signals: the uncertainty of the coefficients and offsets
          (:attr:`coefficient_covariance`; the odd channels share f_odd's
          coefficients and so err together) through ``∂S_i/∂(a, b, A0)``, plus the
          polynomials' misfit from the fit residuals (:meth:`shift_error_m`).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].
        sensor : SensorConfig or Config, optional
            As in :meth:`angles_rad`.

        Returns
        -------
        AngleCovariance
            ``noise`` and ``calibration``, each (..., N, N) [rad²]; ``total`` their sum.

        Raises
        ------
        ConfigError
            Naming what the calibration lacks (``noise_std``, the fitted data
            ``fit_delta_a``/``fit_shifts_m``, frame counts) — never a silent zero.
        """
        from bendsense.shift_errors import shift_covariances

        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        d = self.strip_gap_m(sensor)
        sigma = self.noise_std_counts()  # these two raise, naming what an old file lacks
        self.coefficient_covariance  # noqa: B018
        model = self.error_model(sigma)
        n = self.n_channels
        shifts = np.ascontiguousarray(self.shifts_from_delta(a - self.offset).reshape(-1, n))
        total, noise_var = np.empty((shifts.shape[0], n, n)), np.empty((shifts.shape[0], n))
        shift_covariances(model, shifts, total, noise_var)
        noise = np.zeros_like(total)
        noise[:, np.arange(n), np.arange(n)] = noise_var
        shape = (*a.shape[:-1], n, n)
        return AngleCovariance(noise=noise.reshape(shape) / d**2, calibration=(total - noise).reshape(shape) / d**2)

    def _fit_operator(self, mask):
        """The fit's least-squares operator of one parity: ``c = op @ y[keep]`` (as :func:`polyfit_shift`)."""
        k = self.degree + 1
        x = self.fit_delta_a[:, mask].ravel()
        y = self.fit_shifts_m[:, mask]
        w = (_shift_weights(y) if self.weighting == "shift" else np.ones(y.size)).ravel()
        keep = w > 0
        xs = x[keep]
        scale = float(np.max(np.abs(xs))) or 1.0
        sw = np.sqrt(w[keep])
        op = np.linalg.pinv(np.vander(xs / scale, k, increasing=True) * sw[:, None]) * sw
        return keep, op / scale ** np.arange(k)[:, None]

    @cached_property
    def coefficient_covariance(self) -> np.ndarray:
        """Joint covariance of ``(a_0..a_n, b_0..b_n, A0_1..A0_N)`` from the fit's data noise.

        The strip means and the offsets are averages of noisy frames: strip k's
        ΔA has the error ``ε_k − δA0`` (``Var ε = σ²/frames_k``, ``Var δA0 =
        σ²/flat_frames``, σ = :meth:`noise_std_counts`), while its shift label is
        exact. Moving a point's ΔA by δx moves its residual like a shift error
        ``−f'(x) δx``, so the coefficients, linear in the labels, move by
        ``δc = −A diag(f') δx`` with ``A`` the fit's (weighted) least-squares
        operator. The offsets enter every later frame as well, which makes them part
        of the vector. The odd and even blocks are independent (no channel is in
        both); within a block all channels of that parity share the error.

        Returns
        -------
        ndarray, shape (2 (n + 1) + N, 2 (n + 1) + N)
            [m²/count^(j+k)] for the coefficient entries, [counts²] for the offsets.

        Raises
        ------
        ConfigError
            If the fitted data, the noise or the frame counts are not stored.
        """
        n, k = self.n_channels, self.degree + 1
        if self.fit_delta_a is None or self.fit_shifts_m is None:
            raise ConfigError(
                "calibration: fit_delta_a, fit_shifts_m are missing (an older file without the fitted data); "
                "refit with `bendsense calibrate` to get the coefficients' covariance"
            )
        sigma = self.noise_std_counts()
        rows = self.fit_delta_a.shape[0]
        flat_frames = self.meta.get("flat_frames")
        frames = [r.n_frames for r in self.strip_residuals]
        if not isinstance(flat_frames, int) or flat_frames < 1:
            raise ConfigError("calibration: meta.flat_frames is missing (frames of the flat recording)")
        if len(frames) != rows - 1 or min(frames, default=1) < 1:
            raise ConfigError(
                f"calibration: strip_residuals[].n_frames: expected the frame count of each of the {rows - 1} "
                f"strips, got {frames}"
            )
        var_strip = np.concatenate([[0.0], 1.0 / np.asarray(frames, dtype=float)])[:, None] * sigma**2  # (R, N)
        var_offset = sigma**2 / flat_frames
        odd, even = parity_masks(n)
        q = np.zeros((2 * k + n, 2 * k + n))
        q[2 * k :, 2 * k :] = np.diag(var_offset)
        for block, (mask, coef) in enumerate(((odd, self.coefficients_odd), (even, self.coefficients_even))):
            if not np.any(mask):
                continue
            x = self.fit_delta_a[:, mask]
            keep, op = self._fit_operator(mask)
            xs = x.ravel()[keep]
            slope = np.zeros(x.size)
            slope[keep] = polyval_shift(coef[1:] * np.arange(1, k), xs) if k > 1 else 0.0
            gain = np.zeros((k, x.size))
            gain[:, keep] = op * slope[keep]  # δc = −gain · δx, per point
            cov_eps = (gain * var_strip[:, mask].ravel()) @ gain.T
            # δx = ε − δA0(channel): δc gets +gain summed over the channel's points
            channel = np.broadcast_to(np.flatnonzero(mask), x.shape).ravel()
            strip_row = np.broadcast_to(np.arange(rows)[:, None] > 0, x.shape).ravel()
            to_offset = np.zeros((k, n))
            np.add.at(to_offset.T, channel[strip_row], gain[:, strip_row].T)
            sl = slice(block * k, (block + 1) * k)
            q[sl, sl] += cov_eps + (to_offset * var_offset) @ to_offset.T
            q[sl, 2 * k :] = to_offset * var_offset
            q[2 * k :, sl] = q[sl, 2 * k :].T
        return q


    # -- fitting ------------------------------------------------------------------------

    @classmethod
    def fit(
        cls,
        manifest_path: str | os.PathLike,
        sensor=None,
        degree: int | str = 3,
        weighting: str = "none",
        sleeve: bool | None = None,
    ) -> Calibration:
        """Fit a calibration from a manifest of session CSV recordings (DESIGN.md section 3).

        Parameters
        ----------
        manifest_path : path
            Calibration manifest YAML; recording paths are relative to it.
        sensor : SensorConfig or Config, optional
            ``None``: the paper's sensor (``bendsense.load_config().sensor``).
        degree : int or "auto"
            Polynomial degree 1..5, or ``"auto"`` for leave-one-strip-out CV.
        weighting : str
            ``"none"`` (the paper's) or ``"shift"``.
        sleeve : bool, optional
            Override ``sensor.calibration_adds_sleeve`` (κ_cal = 1/(R + c)).

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
        return cls.from_data(
            flat,
            strips,
            [r for r, _ in manifest.strips],
            sensor,
            degree=degree,
            weighting=weighting,
            sleeve=sleeve,
            recordings=[p.name for _, p in manifest.strips],
            meta={"manifest": Path(manifest_path).name, "flat": manifest.flat.name},
        )

    @classmethod
    def from_data(
        cls,
        flat_signals,
        strip_signals_list,
        radii_m,
        sensor=None,
        *,
        degree: int | str = 3,
        weighting: str = "none",
        sleeve: bool | None = None,
        recordings=None,
        meta: dict | None = None,
    ) -> Calibration:
        """Fit a calibration from in-memory recordings.

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
            As in :meth:`fit`.
        recordings : sequence of str, optional
            Names of the strip recordings, for the report.
        meta : dict, optional
            Extra metadata to store.
        """
        sensor = _resolve_sensor(sensor)
        n = sensor.n_segments
        if weighting not in WEIGHTINGS:
            raise ConfigError(f"weighting: must be one of {', '.join(WEIGHTINGS)}, got {check.short(weighting)}")
        auto = isinstance(degree, str) and degree == "auto"
        integer = isinstance(degree, (int, np.integer)) and not isinstance(degree, bool)
        if not auto and not (integer and degree in DEGREES):
            raise ConfigError(f"degree: must be 1..5 or 'auto', got {check.short(degree)}")
        sleeve = sensor.calibration_adds_sleeve if sleeve is None else bool(sleeve)
        flat = _signals("flat", flat_signals, n)
        radii = [check.length_m(f"radii_m[{i}]", r, error=ConfigError) for i, r in enumerate(radii_m)]
        if len(radii) != len(strip_signals_list):
            raise ConfigError(f"radii_m: expected {len(strip_signals_list)} radii (one per strip), got {len(radii)}")
        if not radii:
            raise ConfigError("strips: at least one calibration strip is needed")
        strips = [_signals(f"strips[{i}]", s, n) for i, s in enumerate(strip_signals_list)]
        recordings = list(recordings) if recordings is not None else [f"strip {i}" for i in range(len(strips))]

        offset = flat.mean(axis=0)
        noise = flat.std(axis=0, ddof=1) if flat.shape[0] > 1 else None  # one frame: not measured
        extra = sensor.sleeve_thickness_m if sleeve else 0.0
        kappa = np.array([1.0 / (r + extra) for r in radii])
        delta = np.vstack([np.zeros(n)] + [s.mean(axis=0) - offset for s in strips])  # flat first
        shifts = strip_shifts(np.concatenate(([0.0], kappa)), sensor.lengths_m, sensor.strip_gap_m)
        groups = np.arange(-1, len(strips))
        # the tightest strip stays in training: predicting it would test extrapolation,
        # which `in_range` flags anyway, and its noisy fold would drive the degree choice
        groups[1 + int(np.argmax(kappa))] = -1
        odd, even = parity_masks(n)

        cv = None
        if auto:
            if len(strips) < 2:
                raise ConfigError("degree: 'auto' needs at least 2 calibration strips for cross-validation")
            fold_errors = _cv_fold_errors(delta, shifts, groups, DEGREES, weighting)
            cv = {d: math.sqrt(float(np.mean(e))) for d, e in fold_errors.items()}
            if not math.isfinite(min(cv.values())):
                raise ConfigError("degree: no degree 1..5 can be fitted to these recordings")
            degree = select_degree(fold_errors)
        degree = int(degree)
        c_odd, c_even = _fit_parities(delta, shifts, degree, weighting, odd, even)

        pred = np.where(odd, polyval_shift(c_odd, delta), polyval_shift(c_even, delta))
        resid = pred - shifts
        residuals = tuple(
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
        even_delta = delta[:, even] if np.any(even) else delta[:, odd]
        info = {"created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        info["flat_frames"] = int(flat.shape[0])
        info.update(meta or {})
        return cls(
            offset=offset,
            coefficients_odd=c_odd,
            coefficients_even=c_even,
            degree=degree,
            delta_a_range_odd=(float(delta[:, odd].min()), float(delta[:, odd].max())),
            delta_a_range_even=(float(even_delta.min()), float(even_delta.max())),
            noise_std=noise,
            strip_residuals=residuals,
            cv_errors_m=cv,
            weighting=weighting,
            sleeve=sleeve,
            sensor=sensor,
            fit_delta_a=delta,
            fit_shifts_m=shifts,
            meta=info,
        )

    # -- files --------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """Return the calibration YAML layout (plain lists, floats and strings)."""
        cv = self.cv_errors_m
        out = {
            "format": FORMAT,
            "version": VERSION,
            "n_channels": self.n_channels,
            "degree": self.degree,
            "offset": self.offset.tolist(),
            "coefficients_odd": self.coefficients_odd.tolist(),
            "coefficients_even": self.coefficients_even.tolist(),
            "delta_a_range_odd": list(self.delta_a_range_odd),
            "delta_a_range_even": list(self.delta_a_range_even),
            "noise_std": self.noise_std.tolist() if self.noise_known else None,
            "weighting": self.weighting,
            "sleeve": self.sleeve,
            "strip_residuals": [r.to_dict() for r in self.strip_residuals],
            "cv_errors_m": None if cv is None else {int(k): float(v) for k, v in cv.items()},
            "sensor": None if self.sensor is None else self.sensor.to_dict(),
            "fit_delta_a": None if self.fit_delta_a is None else self.fit_delta_a.tolist(),
            "fit_shifts_m": None if self.fit_shifts_m is None else self.fit_shifts_m.tolist(),
            "meta": dict(self.meta),
        }
        return out

    def save(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        """Write the calibration YAML atomically (``format: bendsense-calibration``, ``version: 1``).

        ``overwrite=False`` refuses an existing file (:class:`~bendsense.errors.OutputExistsError`).

        Parameters
        ----------
        path : str or path-like
            Output YAML file.
        overwrite : bool, default True
            Replace an existing file; False refuses one.
        """
        from bendsense import output

        header = "# bendsense sensor calibration: S_i = sum_k c_k (A_i - offset_i)^k (ascending powers, paper eq. 2)\n"
        text = header + yaml.safe_dump(self.to_dict(), sort_keys=False)
        output.write_text(path, text, overwrite=overwrite, writer="bendsense calibrate")

    @classmethod
    def from_dict(cls, data: Any) -> Calibration:
        """Build a calibration from its YAML layout; raises `ConfigError` naming the field.

        Parameters
        ----------
        data : dict
            The calibration YAML's layout, as read by ``yaml.safe_load``.
        """
        if not isinstance(data, dict):
            raise ConfigError(f"calibration: expected a mapping, got {type(data).__name__}")
        if data.get("format") != FORMAT:
            raise ConfigError(f"format: expected {FORMAT!r}, got {check.short(data.get('format'))}")
        version = data.get("version")
        if version != VERSION:
            raise ConfigError(f"version: this bendsense reads version {VERSION}, got {check.short(version)}")
        allowed = [
            "format", "version", "n_channels", "degree", "offset", "coefficients_odd", "coefficients_even",
            "delta_a_range_odd", "delta_a_range_even", "noise_std", "weighting", "sleeve", "strip_residuals",
            "cv_errors_m", "sensor", "fit_delta_a", "fit_shifts_m", "meta",
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
        residuals = []
        for i, item in enumerate(data.get("strip_residuals") or []):
            try:
                residuals.append(StripResidual(**item))
            except TypeError as err:
                raise ConfigError(f"strip_residuals[{i}]: {err}") from None
        cv = data.get("cv_errors_m")
        if cv is not None:
            if not isinstance(cv, dict):
                raise ConfigError(f"cv_errors_m: expected a mapping of degree to error, got {check.short(cv)}")
            cv = {int(k): float(v) for k, v in cv.items()}
        meta = data.get("meta") or {}
        if not isinstance(meta, dict):
            raise ConfigError(f"meta: expected a mapping, got {check.short(meta)}")
        return cls(
            offset=offset,
            coefficients_odd=coef,
            coefficients_even=data["coefficients_even"],
            degree=degree,
            delta_a_range_odd=data["delta_a_range_odd"],
            delta_a_range_even=data["delta_a_range_even"],
            noise_std=data.get("noise_std"),
            strip_residuals=residuals,
            cv_errors_m=cv,
            weighting=data.get("weighting", "none"),
            sleeve=data.get("sleeve", False),
            sensor=sensor,
            fit_delta_a=data.get("fit_delta_a"),
            fit_shifts_m=data.get("fit_shifts_m"),
            meta=meta,
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        """Read a calibration YAML written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
            Calibration YAML file.

        Raises
        ------
        ConfigError
            If the file cannot be read, is not a bendsense calibration, or a field is
            invalid; the message names the file and the field.
        """
        return load_yaml(path, "calibration", cls.from_dict)

    # -- reporting ----------------------------------------------------------------------

    def report(self) -> str:
        """Summarise as text: degree, coefficients, ranges, per-strip residuals, CV table."""
        lines = [
            f"calibration: {self.n_channels} channels, degree {self.degree}, weighting {self.weighting}, "
            f"kappa_cal = 1/{'(R + c)' if self.sleeve else 'R'}",
            "  f_odd  coefficients (ascending): " + ", ".join(f"{c:.6g}" for c in self.coefficients_odd),
            "  f_even coefficients (ascending): " + ", ".join(f"{c:.6g}" for c in self.coefficients_even),
            f"  fitted dA range: odd [{self.delta_a_range_odd[0]:.6g}, {self.delta_a_range_odd[1]:.6g}], "
            f"even [{self.delta_a_range_even[0]:.6g}, {self.delta_a_range_even[1]:.6g}]",
            "  flat noise std (mean over channels): "
            + (f"{float(np.mean(self.noise_std)):.4g}" if self.noise_known else "not measured"),
        ]
        if self.strip_residuals:
            lines.append("  strip   R [mm]  kappa [1/m]  rms dS [um]  max dS [um]  frames  recording")
            for i, r in enumerate(self.strip_residuals):
                lines.append(
                    f"  {i:5d} {r.radius_m * 1e3:8.2f} {r.curvature_per_m:12.3f} {r.rms_shift_m * 1e6:12.3f} "
                    f"{r.max_abs_shift_m * 1e6:12.3f} {r.n_frames:7d}  {r.recording}"
                )
        if self.cv_errors_m:
            lines.append("  degree  CV rms dS [um] (leave one strip out)")
            for d, e in sorted(self.cv_errors_m.items()):
                mark = "  <- chosen" if d == self.degree else ""
                lines.append(f"  {d:6d} {e * 1e6:15.3f}{mark}")
        return "\n".join(lines)

    def plot(self, ax=None):
        """Plot the fitted polynomials over the data (S [mm] vs ΔA) and the residuals.

        With ``ax=None`` a figure with two panels (fit, residuals) is created and both
        axes are returned; with an ``ax`` only the fit is drawn on it.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes for the fit; None makes a figure with fit and residual panels.
        """
        import matplotlib.pyplot as plt

        axes = None
        if ax is None:
            _, axes = plt.subplots(2, 1, sharex=True, figsize=(6, 6))
            ax = axes[0]
        odd, even = parity_masks(self.n_channels)
        for mask, coef, rng, name, color in (
            (odd, self.coefficients_odd, self.delta_a_range_odd, "odd", "C0"),
            (even, self.coefficients_even, self.delta_a_range_even, "even", "C1"),
        ):
            if not np.any(mask):
                continue
            x = np.linspace(rng[0], rng[1], 200)
            ax.plot(x, polyval_shift(coef, x) * 1e3, color=color, label=f"f_{name} ({name} channels)")
            if self.fit_delta_a is not None:
                dx, sy = self.fit_delta_a[:, mask], self.fit_shifts_m[:, mask]
                ax.plot(dx.ravel(), sy.ravel() * 1e3, ".", color=color, alpha=0.6, label=f"strips, {name} channels")
                if axes is not None:
                    r = (polyval_shift(coef, dx) - sy) * 1e6
                    axes[1].plot(dx.ravel(), r.ravel(), ".", color=color)
        ax.set_ylabel("shift S [mm]")
        ax.set_title(f"calibration fit, degree {self.degree} (paper eq. 2)", fontsize="medium")
        ax.legend(fontsize="small")
        if axes is not None:
            axes[1].axhline(0.0, color="k", linewidth=0.5)
            axes[1].set_ylabel("residual f(ΔA) − S [µm]")
            axes[1].set_xlabel("ΔA = A − A0 [signal units]")
            return axes
        ax.set_xlabel("ΔA = A − A0 [signal units]")
        return ax


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
    return getattr(sensor, "sensor", sensor)
