"""The calibration polynomials and their fit (paper eq. 2, section V-B).

The ground truth of a strip (:func:`strip_shifts`), the polynomials ``f_odd`` and
``f_even`` in ascending powers (:func:`polyval_shift`, :func:`polyfit_shift`), the
``"shift"`` weighting, and the choice of their degree by leave-one-strip-out
cross-validation (:func:`cross_validate_degree`, :func:`select_degree`).
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.choices import CALIBRATION_DEGREES, CALIBRATION_WEIGHTINGS
from bendsense.errors import ConfigError

__all__ = [
    "strip_shifts",
    "parity_masks",
    "polyval_shift",
    "polyfit_shift",
    "cross_validate_degree",
    "select_degree",
    "WEIGHTINGS",
    "DEGREES",
]

WEIGHTINGS, DEGREES = CALIBRATION_WEIGHTINGS, CALIBRATION_DEGREES  # declared once, in bendsense.choices


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
