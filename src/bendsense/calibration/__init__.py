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

The package reads as the method, one module per step:

- :mod:`~bendsense.calibration.polynomials`: the strips' shifts, the polynomials and
  their fit, the choice of the degree by cross-validation;
- :mod:`~bendsense.calibration.manifest`: the manifest of recordings;
- :mod:`~bendsense.calibration.fit`: a calibration from the recordings
  (:meth:`Calibration.fit`, :meth:`Calibration.from_data`);
- :mod:`~bendsense.calibration.model`: the :class:`Calibration` object, the
  measurement model the estimator uses;
- :mod:`~bendsense.calibration.error_model`: the errors of its shifts (the
  polynomials' misfit, the coefficients' covariance);
- :mod:`~bendsense.calibration.io`: the calibration YAML;
- :mod:`~bendsense.calibration.report`: its text summary and plot.
"""

from __future__ import annotations

from bendsense.calibration.error_model import AngleCovariance
from bendsense.calibration.fit import StripResidual
from bendsense.calibration.manifest import Manifest, read_manifest
from bendsense.calibration.model import Calibration
from bendsense.calibration.polynomials import (
    DEGREES,
    WEIGHTINGS,
    cross_validate_degree,
    parity_masks,
    polyfit_shift,
    polyval_shift,
    select_degree,
    strip_shifts,
)

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
