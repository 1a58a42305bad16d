"""The compiled Kalman filter and Rauch–Tung–Striebel smoother over per-frame force estimates.

State: the force ``x`` (2,) [N], a random walk ``x_k = x_(k−1) + w_k``. Measurement: the
frame's estimate ``z_k = x_k + v_k`` with ``v_k ~ N(0, R_k)``, ``R_k`` only the sensor-noise
part of the frame's covariance (its calibration and parameter parts are a bias common to
neighbouring frames and are added back whole by the caller, never averaged down).

Process noise from the bandwidth B [Hz]: ``Q_k = ρ(B, Δt_k) diag(R̄)`` with ``R̄`` the
latest frame's noise variances (Fx, Fy) and ``ρ = K² / (1 − K)``, ``K`` the steady-state
gain of the filter whose −3 dB frequency is B at the frame interval Δt_k
(:func:`gain_for_bandwidth`): for a random walk observed in noise of variance R, the
steady-state filter is ``x̂_k = x̂_(k−1) + K (z_k − x̂_(k−1))``,
``|H(e^(iω))|² = K² / (1 − 2(1−K) cos ω + (1−K)²)``, and its Riccati equation gives
``Q/R = K²/(1 − K)``. So B is the bandwidth of each component's filter at the frame's own
noise (exactly so where the components' noise is uncorrelated; the filter uses the
correlation, which the process noise does not follow: a force moves in any direction,
whatever the shape of the noise).

Explicit cases: a frame flagged ``restart`` (a gap, a pressure step, the first frame)
starts from a diffuse prior (variance :data:`DIFFUSE`); a component the frame's estimate
does not give (NaN force, infinite σ: failed or ``not_identifiable``) is not observed, the
other one is; a frame without any is predicted only. The innovations' log-likelihood
(the diffuse first observations left out) chooses B offline (:mod:`bendsense.tracking.track`).

Speed, measured on the shared 2-core machine: 0.1–0.2 µs per frame and filter pass, 0.02 µs
for the smoother's backward pass; ``track`` as a whole ~0.9 µs per frame with a given
bandwidth, ~3 µs with the maximum-likelihood choice (16 passes) (benchmarks/bench_track.py).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit

DIFFUSE = 1e6  # prior variance of a restarted state [N²]: σ = 1 kN, beyond any actuator
_SEEN = 0.5 * DIFFUSE  # a variance above this: the component has not been observed since the restart


@njit(cache=True)
def gain_for_bandwidth(bandwidth_hz, dt_s):
    """The steady-state gain K whose filter ``K / (1 − (1−K) z⁻¹)`` is −3 dB at ``bandwidth_hz``.

    With ``h = 1 − cos(2π B Δt)``: ``K = √(h (2 + h)) − h`` (the root of
    ``|H|² = ½`` below 1). B at or beyond the Nyquist frequency gives its value there,
    K = 2√2 − 2; B → 0 gives K ≈ 2π B Δt.
    """
    w = min(2.0 * math.pi * bandwidth_hz * dt_s, math.pi)
    s = math.sin(0.5 * w)
    h = 2.0 * s * s
    return math.sqrt(h * (2.0 + h)) - h


@njit(cache=True)
def process_ratio(bandwidth_hz, dt_s):
    """ρ = Q/R = K²/(1 − K) of the steady-state filter of bandwidth ``bandwidth_hz`` (:func:`gain_for_bandwidth`)."""
    K = gain_for_bandwidth(bandwidth_hz, dt_s)
    return K * K / (1.0 - K)


@njit(cache=True)
def _mul(A, B, out):
    """Out = A B of 2×2 matrices."""
    for a in range(2):
        for b in range(2):
            out[a, b] = A[a, 0] * B[0, b] + A[a, 1] * B[1, b]


@njit(cache=True)
def _mul_t(A, B, out):
    """Out = A B Aᵀ of 2×2 matrices."""
    for a in range(2):
        for b in range(2):
            acc = 0.0
            for c in range(2):
                for d in range(2):
                    acc += A[a, c] * B[c, d] * A[b, d]
            out[a, b] = acc


@njit(cache=True)
def update(x, P, z, Rn, use0, use1, w):
    """Kalman update of ``x`` (2,), ``P`` (2, 2) in place by ``z`` along the observed components; returns log L.

    Joseph form ``P = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` with ``I − K H`` computed as
    ``R S⁻¹`` on the observed block (exact after a diffuse prior, where ``1 − K`` would
    cancel). ``w`` (6, 2, 2) is scratch. The log-likelihood of the innovation is 0 when
    an observed component was diffuse.
    """
    diffuse = (use0 and P[0, 0] > _SEEN) or (use1 and P[1, 1] > _SEEN)
    Sinv, K, IKH, Rm, t0, t1 = w[0], w[1], w[2], w[3], w[4], w[5]
    Sinv[:, :] = 0.0
    Rm[:, :] = 0.0
    if use0 and use1:
        s00, s01, s11 = P[0, 0] + Rn[0, 0], P[0, 1] + Rn[0, 1], P[1, 1] + Rn[1, 1]
        det = s00 * s11 - s01 * s01
        Sinv[0, 0], Sinv[1, 1], Sinv[0, 1], Sinv[1, 0] = s11 / det, s00 / det, -s01 / det, -s01 / det
        Rm[:, :] = Rn
        _mul(P, Sinv, K)
        _mul(Rm, Sinv, IKH)
        dims = 2
    else:
        j = 0 if use0 else 1
        det = P[j, j] + Rn[j, j]
        Sinv[j, j] = 1.0 / det
        Rm[j, j] = Rn[j, j]
        K[:, :] = 0.0
        K[0, j] = P[0, j] / det
        K[1, j] = P[1, j] / det
        IKH[:, :] = 0.0
        IKH[0, 0] = 1.0
        IKH[1, 1] = 1.0
        IKH[1 - j, j] = -K[1 - j, j]
        IKH[j, j] = Rn[j, j] / det
        dims = 1
    nu0 = z[0] - x[0] if use0 else 0.0
    nu1 = z[1] - x[1] if use1 else 0.0
    _mul_t(IKH, P, t0)
    _mul_t(K, Rm, t1)
    for a in range(2):
        x[a] += K[a, 0] * nu0 + K[a, 1] * nu1
    for a in range(2):
        for b in range(2):
            P[a, b] = 0.5 * (t0[a, b] + t0[b, a] + t1[a, b] + t1[b, a])
    if diffuse or not det > 0.0:
        return 0.0
    q = nu0 * Sinv[0, 0] * nu0 + 2.0 * nu0 * Sinv[0, 1] * nu1 + nu1 * Sinv[1, 1] * nu1
    return -0.5 * (q + math.log(det) + dims * math.log(2.0 * math.pi))


@njit(cache=True)
def observed(z, Rn, c):
    """Whether component ``c`` of the frame's estimate can be used: a finite force and noise variance."""
    return math.isfinite(z[c]) and math.isfinite(Rn[c, c]) and Rn[c, c] > 0.0


@njit(cache=True)
def kalman_filter(z, Rn, dt, restart, bandwidth_hz, state, x_pred, P_pred, x_filt, P_filt):
    """The Kalman filter over frames (B,); returns the innovations' log-likelihood.

    ``z`` (B, 2) the estimates [N], ``Rn`` (B, 2, 2) their noise covariances [N²], ``dt``
    (B,) the interval to the previous frame [s], ``restart`` (B,) bool (diffuse prior).
    ``state`` = (x (2,), P (2, 2), R̄ (2, 2), [has R̄]) carried from the previous call
    (streaming) and updated in place. Writes the predictions and the filtered states.
    """
    x, P, Rbar, has = state
    w = np.empty((6, 2, 2))
    loglik = 0.0
    last_dt = -1.0
    rho = 0.0
    for k in range(z.shape[0]):
        if restart[k]:
            x[:] = 0.0
            P[:, :] = 0.0
            P[0, 0] = DIFFUSE
            P[1, 1] = DIFFUSE
        elif has[0] > 0.0:
            if dt[k] != last_dt:  # the same interval as the last frame's (a steady rate): the same ratio
                rho = process_ratio(bandwidth_hz, dt[k])
                last_dt = dt[k]
            for a in range(2):
                for b in range(2):
                    P[a, b] += rho * Rbar[a, b]
        x_pred[k] = x
        P_pred[k] = P
        use0 = observed(z[k], Rn[k], 0)
        use1 = observed(z[k], Rn[k], 1)
        if use0 and use1:  # the process noise follows each component's noise variance, not their correlation
            Rbar[0, 0] = Rn[k, 0, 0]
            Rbar[1, 1] = Rn[k, 1, 1]
            has[0] = 1.0
        if use0 or use1:
            loglik += update(x, P, z[k], Rn[k], use0, use1, w)
        x_filt[k] = x
        P_filt[k] = P
    return loglik


@njit(cache=True)
def rts_smoother(restart, x_pred, P_pred, x_filt, P_filt, x_out, P_out):
    """The Rauch–Tung–Striebel smoother: ``x_out``, ``P_out`` from the filter's outputs (:func:`kalman_filter`).

    ``G_k = P_k P⁻_(k+1)⁻¹``, ``x̃_k = x_k + G_k (x̃_(k+1) − x⁻_(k+1))``,
    ``P̃_k = P_k + G_k (P̃_(k+1) − P⁻_(k+1)) G_kᵀ``; a restart at k+1 ends the recursion
    (the segments are independent).
    """
    B = x_pred.shape[0]
    G = np.empty((2, 2))
    Pinv = np.empty((2, 2))
    D = np.empty((2, 2))
    GD = np.empty((2, 2))
    for k in range(B - 1, -1, -1):
        Pn = P_pred[k + 1] if k < B - 1 else P_pred[k]
        det = Pn[0, 0] * Pn[1, 1] - Pn[0, 1] * Pn[1, 0]
        # the last frame, a restart at k+1, or no process noise and nothing learnt: the filtered state
        if k == B - 1 or restart[k + 1] or not det > 0.0:
            x_out[k] = x_filt[k]
            P_out[k] = P_filt[k]
            continue
        Pinv[0, 0], Pinv[1, 1] = Pn[1, 1] / det, Pn[0, 0] / det
        Pinv[0, 1], Pinv[1, 0] = -Pn[0, 1] / det, -Pn[1, 0] / det
        _mul(P_filt[k], Pinv, G)
        d0 = x_out[k + 1, 0] - x_pred[k + 1, 0]
        d1 = x_out[k + 1, 1] - x_pred[k + 1, 1]
        for a in range(2):
            x_out[k, a] = x_filt[k, a] + G[a, 0] * d0 + G[a, 1] * d1
            for b in range(2):
                D[a, b] = P_out[k + 1, a, b] - P_pred[k + 1, a, b]
        _mul_t(G, D, GD)
        for a in range(2):
            for b in range(2):
                P_out[k, a, b] = P_filt[k, a, b] + 0.5 * (GD[a, b] + GD[b, a])


@njit(cache=True)
def log_likelihoods(z, Rn, dt, restart, bandwidths_hz, out):
    """The innovations' log-likelihood of the filter at each of ``bandwidths_hz`` into ``out`` (a fresh state each)."""
    B = z.shape[0]
    xp, Pp, xf, Pf = np.empty((B, 2)), np.empty((B, 2, 2)), np.empty((B, 2)), np.empty((B, 2, 2))
    for i in range(bandwidths_hz.size):
        state = (np.zeros(2), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(1))
        out[i] = kalman_filter(z, Rn, dt, restart, bandwidths_hz[i], state, xp, Pp, xf, Pf)


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
