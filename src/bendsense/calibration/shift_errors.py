"""The covariance of the measured shifts: the error model that one compiled kernel evaluates for all.

A calibration states its errors as a :class:`ShiftErrorModel`
(:meth:`bendsense.calibration.Calibration.error_model`); the kernel
:func:`~bendsense.calibration._kernels.shift_covariance`, one for the calibration, the
estimator and the window check, turns it into ``Σ_S`` (N, N) [m²] at one frame's shifts
``S`` (docs/theory.md, "The measured angles"):

- **noise**: the frame's signal noise through the calibration's slope,
  ``diag(f_i'(ΔA_i)² σ_i²)`` with ``ΔA_i = f_i⁻¹(S_i)``;
- **coefficients and offsets**: ``l_i Q l_jᵀ`` with ``Q`` the covariance of
  ``(a_0..a_n, b_0..b_n, A0_1..A0_N)`` from the noise of the recordings the calibration
  was fitted to and ``l_i = ∂S_i/∂(a, b, A0)`` = the powers of ``ΔA_i`` in the block of
  channel i's parity and ``−f_i'(ΔA_i)`` at ``A0_i``;
- **misfit**: the polynomials' residual envelope ``σ_p(|S|)`` with the correlation
  ``c_ij exp(−(S_i − S_j)² / 2ℓ²)``.

Without a calibration (:func:`noise_only`) the noise is in metres of shift and nothing else.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["ShiftErrorModel", "noise_only"]


class ShiftErrorModel(NamedTuple):
    """The error model of a calibration's shifts (N channels, polynomials of degree n).

    Built by :meth:`bendsense.calibration.Calibration.error_model`; read by
    :func:`~bendsense.calibration._kernels.shift_covariance`.
    """

    calibrated: bool  # a calibration maps the noise (else it is in metres of shift)
    noise_std: np.ndarray  # (N,) signal noise per channel [counts; m without a calibration]
    coef: np.ndarray  # (N, n+1) each channel's polynomial f_i, ascending powers [m/count^j]
    dcoef: np.ndarray  # (N, n) its derivative f_i'
    grid_m: np.ndarray  # (G,) |S| grid of the misfit envelopes [m]
    sigma_odd_m: np.ndarray  # (G,) misfit σ of the odd channels [m]
    sigma_even_m: np.ndarray  # (G,) of the even ones [m]
    odd: np.ndarray  # (N,) bool: channel of f_odd (1-based odd)
    parity: np.ndarray  # (N, N) c_ij: 1 within a parity, c between them
    length_m: float  # correlation length ℓ of the misfit [m] (0: independent channels)
    coef_cov: np.ndarray  # (2(n+1) + N, 2(n+1) + N) covariance of (a, b, A0); zeros if unknown

    @property
    def positive(self) -> bool:
        """Whether the model states any error at all (else Σ_S is zero)."""
        return bool(np.any(self.noise_std > 0) or np.any(self.sigma_odd_m > 0) or np.any(self.sigma_even_m > 0)
                    or np.any(self.coef_cov != 0))


def noise_only(noise_m, n_channels: int) -> ShiftErrorModel:
    """Independent shift noise ``noise_m`` [m] per channel, no calibration."""
    z = np.zeros(2)
    return ShiftErrorModel(
        calibrated=False, noise_std=np.array(np.broadcast_to(noise_m, (n_channels,)), dtype=float),
        coef=np.zeros((n_channels, 2)), dcoef=np.zeros((n_channels, 1)), grid_m=z, sigma_odd_m=z, sigma_even_m=z,
        odd=np.arange(n_channels) % 2 == 0, parity=np.eye(n_channels), length_m=0.0, coef_cov=np.zeros((1, 1)))
