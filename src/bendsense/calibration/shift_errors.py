"""The covariance of the measured shifts: one compiled kernel for the calibration and the estimator.

A calibration states its errors as a :class:`ShiftErrorModel`
(:meth:`bendsense.calibration.Calibration.error_model`); :func:`shift_covariance` turns
it into ``Σ_S`` (N, N) [m²] at one frame's shifts ``S`` (docs/theory.md, "The measured
angles"):

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

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from bendsense import _jit

__all__ = ["ShiftErrorModel", "noise_only", "shift_covariance", "shift_covariances", "horner"]


class ShiftErrorModel(NamedTuple):
    """The error model of a calibration's shifts (N channels, polynomials of degree n).

    Built by :meth:`bendsense.calibration.Calibration.error_model`; read by
    :func:`shift_covariance`.
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


@njit(cache=True)
def horner(c, x):
    """``Σ_j c[j] x^j`` (ascending coefficients ``c``) by Horner's rule."""
    acc = 0.0
    for j in range(c.size - 1, -1, -1):
        acc = acc * x + c[j]
    return acc


@njit(cache=True)
def _inverse(c, dc, shift):
    """ΔA with ``f(ΔA) = shift`` by Newton's method from the linear inverse; returns (ΔA, f'(ΔA))."""
    x = (shift - c[0]) / dc[0] if dc[0] != 0 else 0.0
    for _ in range(50):
        fp = horner(dc, x)
        dx = (horner(c, x) - shift) / (fp if fp != 0 else 1.0)
        x -= dx
        if abs(dx) <= 1e-12 * max(1.0, abs(x)):
            break
    return x, horner(dc, x)


@njit(cache=True)
def _interp(x, xp, fp):
    """np.interp for one value (ascending ``xp``; constant beyond its ends)."""
    n = xp.size
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    t = (x - xp[lo]) / (xp[hi] - xp[lo])
    return fp[lo] + t * (fp[hi] - fp[lo])


@njit(cache=True)
def shift_covariance(m, S, out, noise_var):
    """Σ_S (N, N) [m²] at the shifts ``S`` (N,) into ``out``, its noise part (N,) into ``noise_var``; returns its trace.

    ``m``: a :class:`ShiftErrorModel` (module docstring).
    """
    n = S.size
    k = m.coef.shape[1]
    x = np.zeros(n)  # ΔA
    sd = np.empty(n)
    err = np.zeros(n)
    slope = np.zeros(n)
    for i in range(n):
        if not m.calibrated:
            sd[i] = m.noise_std[i]
        else:
            if m.dcoef.shape[1] > 0:
                x[i], slope[i] = _inverse(m.coef[i], m.dcoef[i], S[i])
            sd[i] = slope[i] * m.noise_std[i]
            err[i] = _interp(abs(S[i]), m.grid_m, m.sigma_odd_m if m.odd[i] else m.sigma_even_m)
    coef = m.calibrated and m.coef_cov.shape[0] == 2 * k + n
    trace = 0.0
    for i in range(n):
        for j in range(i + 1):
            v = 0.0
            if m.length_m > 0 or i == j:
                d = (S[i] - S[j]) / m.length_m if m.length_m > 0 else 0.0
                v = err[i] * err[j] * math.exp(-0.5 * d * d) * (1.0 if i == j else m.parity[i, j])
            if coef:
                # l_i Q l_jᵀ with l_i nonzero at the powers of its parity's block and at A0_i
                bi, bj = (0 if m.odd[i] else k), (0 if m.odd[j] else k)
                pi = 1.0
                for a in range(k):
                    pj = 1.0
                    for b in range(k):
                        v += pi * m.coef_cov[bi + a, bj + b] * pj
                        pj *= x[j]
                    v -= pi * m.coef_cov[bi + a, 2 * k + j] * slope[j]
                    pi *= x[i]
                pj = 1.0
                for b in range(k):
                    v -= slope[i] * m.coef_cov[2 * k + i, bj + b] * pj
                    pj *= x[j]
                v += slope[i] * m.coef_cov[2 * k + i, 2 * k + j] * slope[j]
            out[i, j] = out[j, i] = v
        noise_var[i] = sd[i] * sd[i]
        out[i, i] += noise_var[i]
        trace += out[i, i]
    return trace


@njit(cache=True, parallel=True)
def shift_covariances(m, S, out, noise_var):
    """:func:`shift_covariance` of every frame: ``S`` (B, N), ``out`` (B, N, N), ``noise_var`` (B, N)."""
    for b in prange(S.shape[0]):
        shift_covariance(m, S[b], out[b], noise_var[b])


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
