"""The compiled Kalman filter and Rauch–Tung–Striebel smoother over per-frame force estimates.

State: the force and its rate, ``x = (Fx, Fy, Ḟx, Ḟy)`` [N, N/s], a local linear trend
(an integrated random walk): over an interval Δt the force moves by Δt × its rate and
the rate by a random walk of intensity ``q R̄`` (white noise on the force's second
derivative), ``Q(Δt) = q R̄ ⊗ [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` with ``R̄`` the latest
fully observed frame's noise variances (Fx, Fy) (the process noise follows each
component's noise variance, not their correlation: a force moves in any direction).
A random walk of the force alone has no rate: its filter lags on every ramp by
(rate)/(bandwidth), outside its σ; this one follows a ramp without lag.

Measurement: the frame's estimate ``z_k = (Fx, Fy)_k + v_k`` with ``v_k ~ N(0, R_k)``,
``R_k`` only the sensor-noise part of the frame's covariance (its calibration and
parameter parts are a bias common to neighbouring frames, added back whole by the
caller, never averaged down).

Bandwidth: ``q`` comes from the −3 dB bandwidth B of the steady-state filter at the
reference frame interval Δt (:func:`process_intensity`): in units of the noise and of
Δt the model has one parameter ``λ² = q Δt³``; the steady-state prior covariance solves
the discrete algebraic Riccati equation (:func:`steady_gain`, a structured doubling
iteration), its gain ``K = (α, β/Δt)`` gives the filter
``x̂_k = (I − K H) F x̂_(k−1) + K z_k`` and ``|H(e^(iω))|`` of its force output, and λ² is
the root of ``|H(e^(i 2π B Δt))|² = ½`` (a bisection in log λ²). The filter peaks a
little above 1 below B (a trend filter overshoots a step; the smoother does not lag).

Explicit cases: a frame flagged ``restart`` (a gap, a pressure step, the first frame)
starts from a diffuse prior (variance :data:`DIFFUSE` for the force, :data:`DIFFUSE_RATE`
for its rate); a component the frame's estimate does not give (NaN force, infinite σ:
failed or ``not_identifiable``) is not observed, the other one is; a frame without any
is predicted only. The innovations' log-likelihood (the first two observations of each
component after a restart left out: they fix the diffuse force and rate) chooses B
offline (:mod:`bendsense.tracking.track`).

Speed, measured on the shared 2-core machine (benchmarks/bench_track.py, 20,000 frames):
one filter pass 0.13 µs per frame (no array views per frame: the steps take indices and
scalars); ``track`` ~0.9 µs per frame with a given bandwidth (the window check ~0.5 of
it), ~1.9 µs with the maximum-likelihood choice (4–6 passes).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit

DIFFUSE = 1e6  # prior variance of a restarted force [N²]: σ = 1 kN, beyond any actuator
DIFFUSE_RATE = 1e4  # prior variance of a restarted rate [N²/s²]: σ = 100 N/s, beyond any actuator
_SEEN = 0.5 * DIFFUSE  # a variance above this: the component has not been observed since the restart
#: The least noise variance of a frame's estimate in any direction, relative to its trace: a constrained force
#: (``constraint="normal"``: one free direction) has a rank-1 noise covariance, and a prior that has learnt the
#: same direction would leave the innovation's covariance singular.
RANK_FLOOR = 1e-6
_LOG_LAMBDA2 = (-120.0, 25.0)  # the bisection's bracket of ln λ² (B from ~1e-10 of the frame rate to Nyquist)


@njit(cache=True)
def steady_gain(lambda2, out):
    """The steady-state gain (α, β) of the filter of ``λ² = q Δt³`` in units of the noise and of Δt into ``out`` (2,).

    The prior covariance P solves ``P = F P Fᵀ − F P Hᵀ (H P Hᵀ + 1)⁻¹ H P Fᵀ + Q`` with
    ``F = [[1, 1], [0, 1]]``, ``H = [1, 0]``, ``Q = λ² [[1/3, 1/2], [1/2, 1]]``: the
    structured doubling algorithm (Chu, Fan, Lin 2005) on the dual control form
    (A = Fᵀ, G = Hᵀ H, H₀ = Q), converging quadratically. Gain ``K = P Hᵀ / (H P Hᵀ + 1)``.
    """
    a00, a01, a10, a11 = 1.0, 0.0, 1.0, 1.0  # A = Fᵀ
    g00, g01, g11 = 1.0, 0.0, 0.0  # G = Hᵀ H
    h00, h01, h11 = lambda2 / 3.0, lambda2 / 2.0, lambda2
    for _ in range(200):
        # W = I + G H (not symmetric); Wi = W⁻¹
        w00, w01 = 1.0 + g00 * h00 + g01 * h01, g00 * h01 + g01 * h11
        w10, w11 = g01 * h00 + g11 * h01, 1.0 + g01 * h01 + g11 * h11
        det = w00 * w11 - w01 * w10
        i00, i01, i10, i11 = w11 / det, -w01 / det, -w10 / det, w00 / det
        # V = W⁻¹ A, U = W⁻¹ G
        v00, v01 = i00 * a00 + i01 * a10, i00 * a01 + i01 * a11
        v10, v11 = i10 * a00 + i11 * a10, i10 * a01 + i11 * a11
        u00, u01 = i00 * g00 + i01 * g01, i00 * g01 + i01 * g11
        u10, u11 = i10 * g00 + i11 * g01, i10 * g01 + i11 * g11
        # H' = H + Aᵀ H V; G' = G + A U Aᵀ; A' = A V
        t00, t01 = h00 * v00 + h01 * v10, h00 * v01 + h01 * v11
        t10, t11 = h01 * v00 + h11 * v10, h01 * v01 + h11 * v11
        n00 = h00 + a00 * t00 + a10 * t10
        n01 = h01 + a00 * t01 + a10 * t11
        n11 = h11 + a01 * t01 + a11 * t11
        s00, s01 = a00 * u00 + a01 * u10, a00 * u01 + a01 * u11
        s10, s11 = a10 * u00 + a11 * u10, a10 * u01 + a11 * u11
        g00, g01, g11 = g00 + s00 * a00 + s01 * a01, g01 + s00 * a10 + s01 * a11, g11 + s10 * a10 + s11 * a11
        a00, a01, a10, a11 = a00 * v00 + a01 * v10, a00 * v01 + a01 * v11, a10 * v00 + a11 * v10, a10 * v01 + a11 * v11
        done = abs(n00 - h00) <= 1e-15 * abs(n00) and abs(n11 - h11) <= 1e-15 * abs(n11)
        h00, h01, h11 = n00, n01, n11
        if done:
            break
    out[0] = h00 / (h00 + 1.0)
    out[1] = h01 / (h00 + 1.0)


@njit(cache=True)
def response2(lambda2, w):
    """``|H(e^(iw))|²`` of the steady-state filter's force output (:func:`steady_gain`), w in rad per frame."""
    K = np.empty(2)
    steady_gain(lambda2, K)
    al, be = K[0], K[1]
    # M = (I − K H) F = [[1 − α, 1 − α], [−β, 1 − β]]; H(z) = e₁ᵀ (I − M z⁻¹)⁻¹ K
    zi = complex(math.cos(w), -math.sin(w))
    m00, m01, m10, m11 = 1.0 - al, 1.0 - al, -be, 1.0 - be
    b00, b01, b10, b11 = 1.0 - m00 * zi, -m01 * zi, -m10 * zi, 1.0 - m11 * zi
    det = b00 * b11 - b01 * b10
    h = (b11 * al - b01 * be) / det
    return h.real * h.real + h.imag * h.imag


@njit(cache=True)
def process_intensity(bandwidth_hz, dt_s):
    """The process intensity q [1/s³] per unit noise variance whose steady filter is −3 dB at ``bandwidth_hz``.

    At the frame interval ``dt_s``: the root in ln λ² of ``|H(e^(i 2π B Δt))|² = ½``
    (:func:`response2`), by bisection to 1e-12; B at or beyond the Nyquist frequency gives
    its value there.
    """
    w = min(2.0 * math.pi * bandwidth_hz * dt_s, math.pi)
    lo, hi = _LOG_LAMBDA2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if response2(math.exp(mid), w) < 0.5:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12:
            break
    return math.exp(0.5 * (lo + hi)) / dt_s ** 3


@njit(cache=True)
def update(x, P, z0, z1, r00, r01, r11, use0, use1, S, K, T):
    """Kalman update of ``x`` (4,), ``P`` (4, 4) in place by ``z`` along the observed force components; returns log L.

    With O the observed components and ``S = P_OO + R_OO``: ``x += P_(:,O) S⁻¹ ν``; the
    observed rows ``P⁺_(O,:) = R_OO S⁻¹ P_(O,:)`` (exact after a diffuse prior, where
    ``P − P S⁻¹ P`` would cancel), the others ``P_(i,:) − P_(i,O) S⁻¹ P_(O,:)``,
    symmetrised. ``z0, z1`` the force, ``r00, r01, r11`` its noise covariance (scalars: no
    array views per frame); ``S`` (2, 2), ``K`` (4, 2), ``T`` (4, 4) are scratch.
    """
    o0 = 0 if use0 else 1
    m = 2 if (use0 and use1) else 1
    if m == 2:
        s00, s01, s11 = P[0, 0] + r00, P[0, 1] + r01, P[1, 1] + r11
        det = s00 * s11 - s01 * s01
        if not det > 0.0:
            return 0.0  # no information this frame can add (roundoff below the rank floor): prior kept
        S[0, 0], S[1, 1], S[0, 1], S[1, 0] = s11 / det, s00 / det, -s01 / det, -s01 / det
        nu0, nu1 = z0 - x[0], z1 - x[1]
    else:
        roo = r00 if use0 else r11
        det = P[o0, o0] + roo
        if not det > 0.0:
            return 0.0
        S[0, 0] = 1.0 / det
        nu0, nu1 = (z0 if use0 else z1) - x[o0], 0.0
    if m == 2:
        for i in range(4):
            K[i, 0] = P[i, 0] * S[0, 0] + P[i, 1] * S[1, 0]
            K[i, 1] = P[i, 0] * S[0, 1] + P[i, 1] * S[1, 1]
            x[i] += K[i, 0] * nu0 + K[i, 1] * nu1
    else:
        for i in range(4):
            K[i, 0] = P[i, o0] * S[0, 0]
            x[i] += K[i, 0] * nu0
    if m == 2:  # both observed (the usual frame): rows 0, 1 = R S⁻¹ P_(O,:), rows 2, 3 = P − K P_(O,:)
        rs00 = r00 * S[0, 0] + r01 * S[1, 0]
        rs01 = r00 * S[0, 1] + r01 * S[1, 1]
        rs10 = r01 * S[0, 0] + r11 * S[1, 0]
        rs11 = r01 * S[0, 1] + r11 * S[1, 1]
        for j in range(4):
            T[0, j] = rs00 * P[0, j] + rs01 * P[1, j]
            T[1, j] = rs10 * P[0, j] + rs11 * P[1, j]
        for i in range(2, 4):
            for j in range(4):
                T[i, j] = P[i, j] - K[i, 0] * P[0, j] - K[i, 1] * P[1, j]
    else:
        rs = roo * S[0, 0]
        for i in range(4):
            for j in range(4):
                T[i, j] = rs * P[o0, j] if i == o0 else P[i, j] - K[i, 0] * P[o0, j]
    for i in range(4):
        for j in range(i, 4):
            v = 0.5 * (T[i, j] + T[j, i])
            P[i, j] = v
            P[j, i] = v
    if m == 2:
        q = nu0 * S[0, 0] * nu0 + 2.0 * nu0 * S[0, 1] * nu1 + nu1 * S[1, 1] * nu1
    else:
        q = nu0 * nu0 * S[0, 0]
    return -0.5 * (q + math.log(det) + m * math.log(2.0 * math.pi))


@njit(cache=True)
def observed(zc, rcc):
    """Whether a component of the frame's estimate can be used: a finite force ``zc`` and noise variance ``rcc``."""
    return math.isfinite(zc) and math.isfinite(rcc) and rcc > 0.0


@njit(cache=True)
def predict(x, P, h, q, Rbar):
    """``x ← F x``, ``P ← F P Fᵀ + Q(h)`` in place, ``F = [[I, h I], [0, I]]``, Q of intensity ``q R̄``."""
    x[0] += h * x[2]
    x[1] += h * x[3]
    for a in range(2):
        for b in range(4):
            P[a, b] += h * P[a + 2, b]
    for b in range(2):
        for a in range(4):
            P[a, b] += h * P[a, b + 2]
    for c in range(2):
        r = q * Rbar[c, c]
        P[c, c] += r * h * h * h / 3.0
        P[c, c + 2] += r * h * h / 2.0
        P[c + 2, c] += r * h * h / 2.0
        P[c + 2, c + 2] += r * h


@njit(cache=True)
def advance(x, P, Rbar, has, dt, restart, q):
    """A frame's prior: the diffuse one at a restart, else the prediction over ``dt`` (:func:`predict`)."""
    if restart:
        x[:] = 0.0
        P[:, :] = 0.0
        P[0, 0] = DIFFUSE
        P[1, 1] = DIFFUSE
        P[2, 2] = DIFFUSE_RATE
        P[3, 3] = DIFFUSE_RATE
        has[1] = 0.0
        has[2] = 0.0
    else:  # before any fully observed frame R̄ is 0: the state moves by its rate only
        predict(x, P, dt, q, Rbar)


@njit(cache=True)
def observe(x, P, Rbar, has, Rn, k, z0, z1, S, K, T):
    """A frame's update by its estimate ``z0, z1`` and noise covariance ``Rn[k]``; returns its log-likelihood.

    The first two observations of a component after a restart fix its force and rate:
    they count 0. The process noise follows each component's noise variance (R̄, of the
    latest fully observed frame), not their correlation. The noise covariance's least
    eigenvalue is raised to :data:`RANK_FLOOR` of its trace (a constrained force's
    covariance has rank 1).
    """
    r00, r01, r11 = Rn[k, 0, 0], Rn[k, 0, 1], Rn[k, 1, 1]
    if math.isfinite(r00 + r01 + r11) and r00 + r11 > 0.0:  # its least eigenvalue raised to the rank floor
        least = 0.5 * (r00 + r11 - math.sqrt((r00 - r11) ** 2 + 4.0 * r01 * r01))
        lift = RANK_FLOOR * (r00 + r11) - least
        if lift > 0.0:
            r00, r11 = r00 + lift, r11 + lift
    use0 = observed(z0, r00)
    use1 = observed(z1, r11)
    if use0 and use1:
        Rbar[0, 0] = r00
        Rbar[1, 1] = r11
        has[0] = 1.0
    if not (use0 or use1):
        return 0.0
    known = (not use0 or has[1] >= 2.0) and (not use1 or has[2] >= 2.0)
    ll = update(x, P, z0, z1, r00, r01, r11, use0, use1, S, K, T)
    if use0:
        has[1] += 1.0
    if use1:
        has[2] += 1.0
    return ll if known else 0.0


@njit(cache=True)
def kalman_filter(z, Rn, dt, restart, q, state, x_pred, P_pred, x_filt, P_filt, store):
    """The Kalman filter over frames (B,); returns the innovations' log-likelihood.

    ``z`` (B, 2) the estimates [N], ``Rn`` (B, 2, 2) their noise covariances [N²], ``dt``
    (B,) the interval to the previous frame [s], ``restart`` (B,) bool (diffuse prior),
    ``q`` the process intensity per unit noise variance [1/s³] (:func:`process_intensity`).
    ``state`` = (x (4,), P (4, 4), R̄ (2, 2), [has R̄, observations of Fx, of Fy since the
    restart]) carried from the previous call (streaming) and updated in place. With
    ``store`` writes the predictions (B, 4), (B, 4, 4) and the filtered states.
    """
    x, P, Rbar, has = state
    S, K, T = np.empty((2, 2)), np.empty((4, 2)), np.empty((4, 4))
    loglik = 0.0
    for k in range(z.shape[0]):
        advance(x, P, Rbar, has, dt[k], restart[k], q)
        if store:  # element by element: no array views per frame
            for a in range(4):
                x_pred[k, a] = x[a]
                for b in range(4):
                    P_pred[k, a, b] = P[a, b]
        loglik += observe(x, P, Rbar, has, Rn, k, z[k, 0], z[k, 1], S, K, T)
        if store:
            for a in range(4):
                x_filt[k, a] = x[a]
                for b in range(4):
                    P_filt[k, a, b] = P[a, b]
    return loglik


@njit(cache=True)
def finish_frame(x, P, floor, force, std, cov):
    """A frame's tracked force (2,), σ (2,), covariance (2, 2): the state's force block plus the floor, whole.

    A component not observed since the restart (variance over half :data:`DIFFUSE`) is NaN
    with σ and its covariance row infinite; a floor that is not finite adds nothing.
    """
    for a in range(2):
        seen_a = P[a, a] < _SEEN
        force[a] = x[a] if seen_a else np.nan
        for b in range(2):
            if seen_a and P[b, b] < _SEEN:
                cov[a, b] = P[a, b] + (floor[a, b] if math.isfinite(floor[a, b]) else 0.0)
            else:
                cov[a, b] = np.inf
        std[a] = math.sqrt(cov[a, a])


@njit(cache=True)
def finish(x, P, floor, force, std, cov):
    """:func:`finish_frame` over frames (B,)."""
    for k in range(x.shape[0]):
        finish_frame(x[k], P[k], floor[k], force[k], std[k], cov[k])


@njit(cache=True)
def _cholesky_solve(A, m, B, L, out):
    """``out = A[m]⁻¹ B`` for A[m] (4, 4) symmetric positive definite, B (4, 4); False when it is not (L scratch)."""
    n = 4
    for j in range(n):
        d = A[m, j, j]
        for c in range(j):
            d -= L[j, c] * L[j, c]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            s = A[m, i, j]
            for c in range(j):
                s -= L[i, c] * L[j, c]
            L[i, j] = s / L[j, j]
    for col in range(B.shape[1]):
        for i in range(n):
            s = B[i, col]
            for c in range(i):
                s -= L[i, c] * out[c, col]
            out[i, col] = s / L[i, i]
        for i in range(n - 1, -1, -1):
            s = out[i, col]
            for c in range(i + 1, n):
                s -= L[c, i] * out[c, col]
            out[i, col] = s / L[i, i]
    return True


@njit(cache=True)
def _fp(P_filt, k, h, FP):
    """``F P_k`` into FP (4, 4) (P_k symmetric: the smoother's gain is ``Gᵀ = P⁻⁻¹ F P_k``); returns FP."""
    for a in range(4):
        for b in range(4):
            FP[a, b] = P_filt[k, a, b] + (h * P_filt[k, a + 2, b] if a < 2 else 0.0)
    return FP


@njit(cache=True)
def rts_smoother(dt, restart, x_pred, P_pred, x_filt, P_filt, x_out, P_out):
    """The Rauch–Tung–Striebel smoother: ``x_out``, ``P_out`` from the filter's outputs (:func:`kalman_filter`).

    ``G_k = P_k Fᵀ P⁻_(k+1)⁻¹`` (F of the interval ``dt[k+1]``),
    ``x̃_k = x_k + G_k (x̃_(k+1) − x⁻_(k+1))``, ``P̃_k = P_k + G_k (P̃_(k+1) − P⁻_(k+1)) G_kᵀ``;
    a restart at k+1 ends the recursion (the segments are independent).
    """
    B = x_pred.shape[0]
    FP, Gt, L, D, GD = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
    d = np.empty(4)
    for k in range(B - 1, -1, -1):
        if k == B - 1 or restart[k + 1] or not _cholesky_solve(P_pred, k + 1, _fp(P_filt, k, dt[k + 1], FP), L, Gt):
            for a in range(4):  # the last frame, a restart next, or no process noise and nothing learnt: filtered
                x_out[k, a] = x_filt[k, a]
                for b in range(4):
                    P_out[k, a, b] = P_filt[k, a, b]
            continue
        for a in range(4):
            d[a] = x_out[k + 1, a] - x_pred[k + 1, a]
            for b in range(4):
                D[a, b] = P_out[k + 1, a, b] - P_pred[k + 1, a, b]
        for a in range(4):
            acc = x_filt[k, a]
            for c in range(4):
                acc += Gt[c, a] * d[c]
            x_out[k, a] = acc
        for a in range(4):  # G D
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += Gt[c, a] * D[c, b]
                GD[a, b] = acc
        for a in range(4):  # P_k + (G D) Gᵀ
            for b in range(a, 4):
                acc = 0.0
                for c in range(4):
                    acc += GD[a, c] * Gt[c, b]
                v = P_filt[k, a, b] + acc
                P_out[k, a, b] = v
                P_out[k, b, a] = v


@njit(cache=True)
def log_likelihoods(z, Rn, dt, restart, intensities, out):
    """The innovations' log-likelihood of the filter at each process intensity of ``intensities`` into ``out``."""
    none = np.empty((1, 4))
    none3 = np.empty((1, 4, 4))
    for i in range(intensities.size):
        state = (np.zeros(4), np.zeros((4, 4)), np.zeros((2, 2)), np.zeros(3))
        out[i] = kalman_filter(z, Rn, dt, restart, intensities[i], state, none, none3, none, none3, False)


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
