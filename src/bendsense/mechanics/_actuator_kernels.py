"""Compiled free-bending model: θ0(P) from its interpolant, and the beam's inputs at a pressure (:func:`model_inputs`).

The interpolant is :class:`bendsense.mechanics.actuator.FreeBendingModel`'s: a monotone
cubic Hermite interpolant on nodes ``p_pa`` (n+1,): on interval k, with
``u = (P − p_k) / (p_(k+1) − p_k)``, ``θ0 = c0 + u (c1 + u (c2 + u c3))`` and
``dθ0/dP = (c1 + u (2 c2 + 3 u c3)) / (p_(k+1) − p_k)``. A uniform bucket index no wider
than the narrowest interval finds k in O(1): the interval that holds the bucket's left end,
or the next one.
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit


@njit(cache=True)
def hermite(p, p_pa, inv_width, coef, bucket_pa, bucket_start, theta, slope):
    """θ0 (B,) [rad] and dθ0/dP (B,) [rad/Pa] of the table at the pressures ``p`` (B,) [Pa].

    A pressure is clipped to [0, p_max]; below 0 its slope is 0. ``coef`` (n, 4) holds
    the cubic of each interval in u, ``inv_width`` (n,) the intervals' reciprocal widths,
    ``bucket_start`` (n_buckets,) the interval that holds each bucket's left end. Returns
    how many pressures lie above p_max (the caller solves those directly), or ``−1 − i``
    if ``p[i]`` is the first that is not finite. ~10 ns a pressure; one pressure costs the
    call (~0.5 µs).
    """
    n, last_bucket, p_max = coef.shape[0], bucket_start.size - 1, p_pa[p_pa.size - 1]
    above = 0
    for i in range(p.size):
        if not math.isfinite(p[i]):
            return -1 - i
        q = p[i]
        if q < 0.0:
            q = 0.0
        elif q > p_max:
            q = p_max
            above += 1
        k = bucket_start[min(int(q / bucket_pa), last_bucket)]
        if q >= p_pa[k + 1]:
            k = min(k + 1, n - 1)
        w = inv_width[k]
        u = (q - p_pa[k]) * w
        c0, c1, c2, c3 = coef[k, 0], coef[k, 1], coef[k, 2], coef[k, 3]
        theta[i] = c0 + u * (c1 + u * (c2 + u * c3))
        slope[i] = 0.0 if p[i] < 0.0 else (c1 + u * (2.0 * c2 + 3.0 * u * c3)) * w
    return above


@njit(cache=True)
def curvature_jacobian(p, theta0, slope, c_a, mu, mu_s, length, out):
    """∂K0/∂(μ̄, μ_s, θ_pre) (B, 3) into ``out`` at the pressures ``p`` (B,) from θ0 and dθ0/dP there (paper eq. 8–12).

    With ``D = c_a / (dθ0/dP)`` and the balance's ``m(θ0) = (c_a P − μ_s θ0) / μ̄``:
    ``∂θ0/∂μ̄ = −m(θ0) / D``, ``∂θ0/∂μ_s = −θ0 / D``, ``∂θ/∂θ_pre = 1``; ``K0 = θ / L``
    (:meth:`bendsense.mechanics.actuator.FreeBendingModel.tip_curvature_jacobian`).
    """
    for i in range(p.size):
        per = slope[i] / c_a  # 1 / D
        unit = (c_a * (p[i] if p[i] > 0.0 else 0.0) - mu_s * theta0[i]) / mu
        out[i, 0] = -unit * per / length
        out[i, 1] = -theta0[i] * per / length
        out[i, 2] = 1.0 / length


@njit(cache=True)
def model_inputs(p, table, prebend, length, ei0, ei1, cov, has_cov, mu, mu_s, c_a, theta, ei, k0, model_cov):
    """The beam's inputs of the frames at the pressures ``p`` (B,) [Pa], within the free-bending table's range.

    θ = θ0(P) + θ_pre (the table, :func:`hermite`), K0 = θ / L, EI = γ0 + γ1 P (paper eq. 8,
    15), and the covariance of (K0, EI) from the parameters' ``cov`` (5, 5) over
    :data:`bendsense.config.MODEL_PARAMETERS`: ``J Σ Jᵀ`` with ∂K0/∂(μ̄, μ_s, θ_pre) from
    :func:`curvature_jacobian` and ∂EI/∂(γ0, γ1) = (1, P). Without a parameter covariance
    (``has_cov`` False, ``cov`` zeros) the Jacobian is not computed and the covariance is
    zero. Returns how many pressures lie above the table (:func:`hermite`: their θ is the
    table's end, the caller's to replace), or ``−1 − i`` for the first that is not finite.
    """
    B = p.size
    p_pa, inv_width, coef, bucket_pa, bucket_start = table
    slope = np.empty(B)
    above = hermite(p, p_pa, inv_width, coef, bucket_pa, bucket_start, theta, slope)
    k = np.zeros((B, 3))
    if has_cov:
        curvature_jacobian(p, theta, slope, c_a, mu, mu_s, length, k)
    for i in range(B):
        theta[i] += prebend
        k0[i] = theta[i] / length
        ei[i] = ei0 + ei1 * p[i]
        kk = 0.0
        ke = 0.0
        for a in range(3):
            for b in range(3):
                kk += k[i, a] * k[i, b] * cov[a, b]
            ke += k[i, a] * (cov[a, 3] + p[i] * cov[a, 4])
        ee = cov[3, 3] + 2.0 * p[i] * cov[3, 4] + p[i] * p[i] * cov[4, 4]
        model_cov[i, 0, 0] = kk
        model_cov[i, 0, 1] = ke
        model_cov[i, 1, 0] = ke
        model_cov[i, 1, 1] = ee
    return above


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
