"""Compiled kernels of the shifts' error model: Σ_S at one frame's shifts, and over frames.

:func:`shift_covariance` evaluates a :class:`~bendsense.calibration.shift_errors.ShiftErrorModel`
(its terms: :mod:`bendsense.calibration.shift_errors`); :func:`shift_covariances` is its
``prange`` loop over frames. :func:`horner` evaluates a calibration polynomial (also for the
reconstruction's kernels, :mod:`bendsense.shape._kernels`).
"""

import math

import numpy as np
from numba import njit, prange

from bendsense import _jit


@njit(cache=True, inline="always")
def horner(c, x):
    """``Σ_j c[j] x^j`` (ascending coefficients ``c``) by Horner's rule."""
    acc = 0.0
    for j in range(c.size - 1, -1, -1):
        acc = acc * x + c[j]
    return acc


@njit(cache=True, inline="always")
def inverse(c, dc, shift):
    """ΔA with ``f(ΔA) = shift`` by Newton's method from the linear inverse; returns (ΔA, f'(ΔA))."""
    x = (shift - c[0]) / dc[0] if dc[0] != 0 else 0.0
    for _ in range(50):
        fp = horner(dc, x)
        dx = (horner(c, x) - shift) / (fp if fp != 0 else 1.0)
        x -= dx
        if abs(dx) <= 1e-12 * max(1.0, abs(x)):
            break
    return x, horner(dc, x)


@njit(cache=True, inline="always")
def interp(x, xp, fp):
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

    ``m``: a :class:`~bendsense.calibration.shift_errors.ShiftErrorModel`.
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
                x[i], slope[i] = inverse(m.coef[i], m.dcoef[i], S[i])
            sd[i] = slope[i] * m.noise_std[i]
            err[i] = interp(abs(S[i]), m.grid_m, m.sigma_odd_m if m.odd[i] else m.sigma_even_m)
    coef = m.calibrated and m.coef_cov.shape[0] == 2 * k + n
    # the calibration's part l_i Q l_jᵀ, l_i nonzero at the powers of ΔA_i in its parity's block and
    # at A0_i (−f_i'): the rows T = L Q once, then each pair's product with l_j
    Q = m.coef_cov
    width = Q.shape[0] if coef else 0
    T = np.zeros((n, width))
    powers = np.empty((n, k))
    for i in range(n if coef else 0):
        bi = 0 if m.odd[i] else k
        pw = 1.0
        for a in range(k):
            powers[i, a] = pw
            for c in range(width):
                T[i, c] += pw * Q[bi + a, c]
            pw *= x[i]
        for c in range(width):
            T[i, c] -= slope[i] * Q[2 * k + i, c]
    trace = 0.0
    for i in range(n):
        for j in range(i + 1):
            v = 0.0
            if m.length_m > 0:
                d = (S[i] - S[j]) / m.length_m
                v = err[i] * err[j] * math.exp(-0.5 * d * d) * (1.0 if i == j else m.parity[i, j])
            elif i == j:
                v = err[i] * err[i]
            if coef:
                bj = 0 if m.odd[j] else k
                for b in range(k):
                    v += T[i, bj + b] * powers[j, b]
                v -= T[i, 2 * k + j] * slope[j]
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
