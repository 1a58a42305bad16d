"""Uncertainty of the force estimate: linear propagation of the shift errors and the misfit χ².

With the weighted residual ``r(u) = W^½ (p(s; u) − p⁰(s))`` and ``J = ∂r/∂u``, the
optimum moves by ``δu = (JᵀJ)⁻¹ Jᵀ W^½ δp⁰`` when the reconstructed shape moves by
``δp⁰ = G δS``, ``G = ∂p⁰/∂S`` through the PCC kinematics (paper eq. 3–7). So
``Cov(F) = T Σ_S Tᵀ`` with ``T = ∂F/∂S`` (including the change of ``D`` with the tip
angle for ``tip_angle_source="shape"``). ``Σ_S`` holds the signal noise through the
calibration slope and the calibration's own error (:func:`bendsense.calibration._kernels.shift_covariance`).

The misfit: the residual is pulled back to the shift perturbation that explains it
best, ``δŜ = −(GᵀWG)⁻¹ GᵀW r``, and ``χ² = δŜᵀ C⁺ δŜ`` with ``C`` the covariance that
``Σ_S`` predicts for ``δŜ`` (rank N − k); ``Cov(F)`` is scaled by ``max(1, χ²/dof)``
(the Birge ratio). Without a noise model there is no σ: NaN (``uncertainty="none"``),
never one from the fit residual, which looks precise and is not. A direction the shape
does not determine (``JᵀJ`` singular) gets an infinite standard deviation.

:func:`covariance` is the compiled per-frame kernel (~15 µs for N = 16, M = 41).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit
from bendsense.errors import ArgumentError
from bendsense.mechanics import _beam_kernels as bk
from bendsense.shape._kernels import sinc


@njit(cache=True)
def _dsinc(v):
    """d/dv sin(v)/v, by its series near 0 where (cos v − sinc v)/v cancels."""
    if abs(v) < 1e-2:
        v2 = v * v
        return v * (-1.0 / 3.0 + v2 * (1.0 / 30.0 - v2 / 840.0))
    return (math.cos(v) - math.sin(v) / v) / v


@njit(cache=True)
def _arc_dkappa(kappa, sigma, phi0):
    """∂/∂κ of the chord σ sinc(κσ/2) (sin(φ0 + κσ/2), cos(φ0 + κσ/2)) (paper eq. 5–6)."""
    half = 0.5 * kappa * sigma
    c = sigma * sinc(half)
    dc = 0.5 * sigma * sigma * _dsinc(half)
    m = phi0 + half
    sm, cm = math.sin(m), math.cos(m)
    return dc * sm + 0.5 * sigma * c * cm, dc * cm - 0.5 * sigma * c * sm


@njit(cache=True)
def shape_jacobian(kappa, lengths, gap, seg, sigma, pos, out):
    """∂p⁰_j/∂S_i (2M, N) of the PCC shape at its points ``pos`` (M, 2) (paper eq. 3–7).

    Raising κ_i moves a point inside segment i along its chord derivative and turns every
    point beyond the segment about the segment's end ``P_i`` (R'v = (v_y, −v_x)); then
    ``κ_i = (S_i − S_{i−1}) / (d l_i)``.
    """
    N = lengths.size
    M = seg.size
    phi_start = np.empty(N)
    ends_x = np.empty(N)
    ends_y = np.empty(N)
    dch = np.empty((N, 2))
    acc = 0.0
    ex = 0.0
    ey = 0.0
    for i in range(N):
        theta = kappa[i] * lengths[i]
        phi_start[i] = acc
        half = 0.5 * theta
        chord = lengths[i] * sinc(half)
        ex += chord * math.sin(acc + half)
        ey += chord * math.cos(acc + half)
        ends_x[i] = ex
        ends_y[i] = ey
        dch[i, 0], dch[i, 1] = _arc_dkappa(kappa[i], lengths[i], acc)
        acc += theta
    for j in range(M):
        sj = seg[j]
        for i in range(N):
            if sj > i:
                gx = dch[i, 0] + lengths[i] * (pos[j, 1] - ends_y[i])
                gy = dch[i, 1] - lengths[i] * (pos[j, 0] - ends_x[i])
            elif sj == i:
                gx, gy = _arc_dkappa(kappa[i], sigma[j], phi_start[i])
            else:
                gx = gy = 0.0
            out[2 * j, i] = gx / (gap * lengths[i])
            out[2 * j + 1, i] = gy / (gap * lengths[i])
        for i in range(N - 1):  # κ_i depends on S_i and S_{i−1}
            out[2 * j, i] -= out[2 * j, i + 1]
            out[2 * j + 1, i] -= out[2 * j + 1, i + 1]


@njit(cache=True)
def mm(A, B):
    """A B of small matrices by loops: no BLAS call, no shape-check code to compile."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for c in range(A.shape[1]):
            a = A[i, c]
            for j in range(B.shape[1]):
                out[i, j] += a * B[c, j]
    return out


@njit(cache=True)
def eigh2(H):
    """Eigenvalues (ascending) and eigenvectors (columns) of a symmetric 2×2 matrix (one Jacobi rotation)."""
    a, b, d = H[0, 0], 0.5 * (H[0, 1] + H[1, 0]), H[1, 1]
    lam = np.empty(2)
    V = np.empty((2, 2))
    if b == 0.0:
        c, s = 1.0, 0.0
        lo, hi = a, d
    else:
        t = (d - a) / (2.0 * b)
        tan = (1.0 if t >= 0 else -1.0) / (abs(t) + math.sqrt(1.0 + t * t))
        c = 1.0 / math.sqrt(1.0 + tan * tan)
        s = c * tan
        lo, hi = a - tan * b, d + tan * b
    if lo <= hi:  # (c, -s) belongs to lo, (s, c) to hi
        lam[0], lam[1] = lo, hi
        V[0, 0], V[1, 0], V[0, 1], V[1, 1] = c, -s, s, c
    else:
        lam[0], lam[1] = hi, lo
        V[0, 0], V[1, 0], V[0, 1], V[1, 1] = s, c, c, -s
    return lam, V


@njit(cache=True)
def inverse_cov(H):
    """Pseudo-inverse of JᵀJ (k, k), the eigen-directions it cannot resolve and its eigenvectors."""
    k = H.shape[0]
    if k == 1:
        h = H[0, 0]
        singular = np.array([h <= 1e-12 * max(h, 0.0) + 1e-300])
        return np.array([[0.0 if singular[0] else 1.0 / h]]), singular, np.ones((1, 1))
    lam, V = eigh2(H)
    top = max(lam[k - 1], 0.0)
    singular = lam <= 1e-12 * top + 1e-300
    inv = np.zeros((k, k))
    for q in range(k):
        if not singular[q]:
            for a in range(k):
                for b in range(k):
                    inv[a, b] += V[a, q] * V[b, q] / lam[q]
    return inv, singular, V


@njit(cache=True)
def lm_step(H, g, out):
    """−(H + ε I)⁻¹ g for a 1×1 or 2×2 system (closed form)."""
    k = g.size
    if k == 1:
        h = H[0, 0]
        out[0] = -g[0] / (h + (1e-14 * h + 1e-300))
        return
    eps = 1e-14 * (H[0, 0] + H[1, 1]) + 1e-300
    a = H[0, 0] + eps
    d = H[1, 1] + eps
    b = H[0, 1]
    det = a * d - b * b
    if not det > 0.0:  # H = 0 (ε² underflows): nothing to step on (a force with no moment arm at any node)
        out[0] = 0.0
        out[1] = 0.0
        return
    out[0] = -((d * g[0] - b * g[1]) / det)
    out[1] = -((a * g[1] - b * g[0]) / det)


@njit(cache=True)
def flat_direction(H, floor, out):
    """Whether ``H`` (k, k) has an eigenvalue below ``floor``; its eigenvector into ``out``."""
    if H.shape[0] == 1:
        out[0] = 1.0
        return H[0, 0] < floor
    lam, V = eigh2(H)
    out[0], out[1] = V[0, 0], V[1, 0]
    return lam[0] < floor


@njit(cache=True)
def restricted_step(H, g, v, out):
    """The Gauss–Newton step −(wᵀHw)⁻¹(wᵀg) w in the direction w ⊥ ``v`` (none for k = 1)."""
    if H.shape[0] == 1:
        out[0] = 0.0
        return
    w0, w1 = -v[1], v[0]
    h = w0 * (H[0, 0] * w0 + H[0, 1] * w1) + w1 * (H[1, 0] * w0 + H[1, 1] * w1)
    t = -(w0 * g[0] + w1 * g[1]) / h if h > 0 else 0.0
    out[0], out[1] = t * w0, t * w1


@njit(cache=True)
def cholesky(A):
    """Lower Cholesky factor of a symmetric positive semidefinite A (n, n) in place; returns its rank.

    A pivot at round-off (≤ 1e-12 of the largest diagonal element: a channel without
    noise) gets a zero column: :func:`forward` leaves that direction out (a pseudo-inverse).
    """
    n = A.shape[0]
    top = 0.0
    for j in range(n):
        top = max(top, A[j, j])
    rank = 0
    for j in range(n):
        d = A[j, j]
        for c in range(j):
            d -= A[j, c] * A[j, c]
        if d > 1e-12 * top:
            d = math.sqrt(d)
            rank += 1
        else:
            d = 0.0
        A[j, j] = d
        for i in range(j + 1, n):
            acc = A[i, j]
            for c in range(j):
                acc -= A[i, c] * A[j, c]
            A[i, j] = acc / d if d > 0.0 else 0.0
        for c in range(j + 1, n):
            A[j, c] = 0.0
    return rank


@njit(cache=True)
def forward(Lc, B):
    """Solve Lc X = B in place (Lc lower triangular, B (n, m)); rows of a zero pivot get 0."""
    for i in range(Lc.shape[0]):
        for c in range(B.shape[1]):
            acc = B[i, c]
            for j in range(i):
                acc -= Lc[i, j] * B[j, c]
            B[i, c] = acc / Lc[i, i] if Lc[i, i] > 0.0 else 0.0


@njit(cache=True)
def forward_transposed(Lc, V):
    """``V`` (n, m) ← Mᵀ V in place, with M the linear map of :func:`forward` (X = M B).

    ``(M V)ᵀ B = Vᵀ (M B)``: a product with a whitened matrix of many columns (the
    whitened ∂r/∂S, N of them) needs the whitening only of the few columns of ``V``.
    Backward substitution with Lcᵀ; rows of a zero pivot get 0, as in :func:`forward`.
    """
    for i in range(Lc.shape[0] - 1, -1, -1):
        for c in range(V.shape[1]):
            acc = V[i, c]
            for j in range(i + 1, Lc.shape[0]):
                acc -= Lc[j, i] * V[j, c]
            V[i, c] = acc / Lc[i, i] if Lc[i, i] > 0.0 else 0.0


@njit(cache=True)
def misfit(Gf, w2, r, JD, cov_s):
    """χ² of the residual ``r`` (2M,) against the propagated shift covariance, and its dof.

    The residual is pulled back to the shifts, ``δŜ = (GᵀWG)⁻¹ GᵀW r``; shift errors ``e``
    leave ``δŜ = (I − ZT) e`` with ``Z = (GᵀWG)⁻¹ GᵀW J``: the fit absorbs the part
    along ``Z``. So ``χ² = min_c (δŜ + Z c)ᵀ Σ_S⁻¹ (δŜ + Z c)`` (the Mahalanobis length of
    δŜ modulo what the fit absorbs), with rank(Σ_S) − k degrees of freedom: one Cholesky
    factorisation of Σ_S and a k-parameter least-squares problem.
    """
    N = Gf.shape[1]
    k = JD.shape[1]
    A = np.zeros((N, N))
    rhs = np.zeros((N, 1 + k))
    for row in range(Gf.shape[0]):
        wr = w2[row]
        for i in range(N):
            gi = wr * Gf[row, i]
            if gi == 0.0:
                continue
            for j in range(i + 1):
                A[i, j] += gi * Gf[row, j]
            rhs[i, 0] += gi * r[row]
            for c in range(k):
                rhs[i, 1 + c] += gi * JD[row, c]
    for i in range(N):
        for j in range(i):
            A[j, i] = A[i, j]
    if not bk.lu_solve(A, rhs):
        return np.nan, 0
    Lc = cov_s.copy()
    rank = cholesky(Lc)
    forward(Lc, rhs)  # whitened: columns ỹ and Z̃
    H = np.zeros((k, k))
    g = np.zeros(k)
    chi2 = 0.0
    for i in range(N):
        chi2 += rhs[i, 0] * rhs[i, 0]
        for a in range(k):
            g[a] += rhs[i, 1 + a] * rhs[i, 0]
            for b in range(k):
                H[a, b] += rhs[i, 1 + a] * rhs[i, 1 + b]
    c = np.empty(k)  # the part the fit absorbs: min_c ‖ỹ − Z̃ c‖²
    lm_step(H, g, c)
    for a in range(k):
        chi2 += c[a] * g[a]
    return max(chi2, 0.0), max(rank - k, 0)


@njit(cache=True)
def unresolved(c, D, V, singular, out):
    """``out`` = the covariance ``c`` (2, 2) with an infinite variance along each direction the fit cannot resolve."""
    for q in range(singular.size):
        if singular[q]:
            v = mm(D, V[:, q:q + 1].copy())[:, 0]
            for a in range(2):
                for b in range(2):
                    if abs(v[a] * v[b]) > 1e-12:
                        c[a, b] = np.inf
    bk.copy_into(c, out)


@njit(cache=True, inline="always")
def covariance(L, p0, w, D, dD, has_dD, u, pos, dpos, has_cov, cov_s, kappa, lengths, gap, seg, sigma, dphi_ds, out,
               noise_var, dym, model_cov, parts):
    """Cov(F) (2, 2) into ``out`` and its parts into ``parts`` (:func:`budget`); returns χ²/dof and its p-value.

    The module docstring derives it; ``dym`` (2M, 2) = ∂p/∂(K0, EI) at the comparison
    nodes carries the model inputs' covariance ``model_cov``. NaN without a noise model.
    """
    M = p0.shape[0]
    k = D.shape[1]
    A = np.empty((2 * M, 2))  # ∂p/∂F
    w2 = np.empty(2 * M)
    r = np.empty(2 * M)
    for j in range(M):
        for a in range(2):
            A[2 * j + a, 0] = dpos[j, a, 0]
            A[2 * j + a, 1] = dpos[j, a, 1]
            w2[2 * j + a] = w[j]
            r[2 * j + a] = pos[j, a] - p0[j, a]
    GF = np.zeros((2, 2))  # AᵀWA
    for row in range(2 * M):
        for a in range(2):
            for b in range(2):
                GF[a, b] += w2[row] * A[row, a] * A[row, b]
    Dc, Dt = D, D.T.copy()
    Hinv, singular, V = inverse_cov(mm(mm(Dt, GF), Dc))
    ratio = np.nan
    p = np.nan
    if has_cov:
        N = lengths.size
        Gf = np.empty((2 * M, N))
        shape_jacobian(kappa, lengths, gap, seg, sigma, p0, Gf)
        hF = np.zeros((2, N))  # AᵀW G
        for row in range(2 * M):
            for a in range(2):
                wa = w2[row] * A[row, a]
                for i in range(N):
                    hF[a, i] += wa * Gf[row, i]
        hs = mm(Dt, hF)  # (k, N)
        Fd = np.zeros(2)
        if has_dD:
            # D follows the reconstructed tip angle φ_L
            for a in range(2):
                for c in range(k):
                    Fd[a] += dD[a, c] * u[c]
            t = mm(Dt, mm(GF, Fd.reshape(2, 1)))[:, 0]
            for c in range(k):
                for i in range(N):
                    hs[c, i] -= t[c] * dphi_ds[i]
        T = mm(Dc, mm(Hinv, hs))  # ∂F/∂S
        if has_dD:
            for a in range(2):
                for i in range(N):
                    T[a, i] += Fd[a] * dphi_ds[i]
        hm = np.zeros((2, 2))  # AᵀW ∂p/∂(K0, EI)
        for row in range(2 * M):
            for a in range(2):
                for b in range(2):
                    hm[a, b] += w2[row] * A[row, a] * dym[row, b]
        c = budget(T, cov_s, noise_var, -mm(Dc, mm(Hinv, mm(Dt, hm))), model_cov, parts)
        chi2, dof = misfit(Gf, w2, r, mm(A, Dc), cov_s)
        if dof > 0:  # else nothing is left to test the fit with: χ²/dof is NaN
            ratio = chi2 / dof
            p = chi2_sf(chi2, dof)
            c *= max(ratio, 1.0)
            parts *= max(ratio, 1.0)
    else:  # no noise model: no σ (never one from the fit residual, which looks precise and is not)
        out[:, :] = np.nan
        parts[:, :, :] = np.nan
        return ratio, p
    unresolved(c, Dc, V, singular, out)
    return ratio, p


@njit(cache=True, inline="always")
def covariance_angles(e, tg, D, dD, has_dD, u, has_cov, cov_s, coils, gap, dphi_ds, dy, out, noise_var, dym, model_cov,
                      parts):
    """Cov(F) (2, 2) into ``out``, its parts into ``parts``, χ²/dof and p of one frame fitted to the coil angles.

    ``e`` (R, 3): the whitened residual and its Jacobian by F at the optimum
    (:func:`bendsense.estimation._kernels.whitened`); the measured angles are
    ``θ_i = S_(c_i) / d`` at the coils ``coils``. The optimum moves by
    ``δu = −H⁻¹ J̃ᵀ L_w⁻¹ ∂r/∂S δS`` with ``J̃ = L_w⁻¹ (∂y/∂F) D``, ``H = J̃ᵀ J̃`` and
    ``∂r/∂S = −E/d`` (plus the turn of D with the shape's tip angle for
    ``has_dD``); ``Cov(F) = T Σ_S Tᵀ`` with ``T = ∂F/∂S``, which is ``D H⁻¹ Dᵀ`` when the
    weights are the inverse covariance of the angles. The model inputs (K0, EI) with
    covariance ``model_cov`` move it by ``T_m = −D H⁻¹ J̃ᵀ L_w⁻¹ ∂y/∂(K0, EI)`` (``dym``,
    (R, 2)); :func:`budget` sums the parts. χ² = ‖e‖² with rank(Σ_θ) − k degrees of
    freedom; the covariance is scaled by ``max(1, χ²/dof)``. Without a noise model
    (``has_cov`` False) the covariance is NaN.
    """
    R = e.shape[0]
    k = D.shape[1]
    N = dphi_ds.size
    JD = mm(e[:, 1:].copy(), D)
    Hinv, singular, V = inverse_cov(mm(JD.T.copy(), JD))
    if not has_cov:
        out[:, :] = np.nan
        parts[:, :, :] = np.nan
        return np.nan, np.nan
    Fd = np.zeros(2)
    if has_dD:
        for a in range(2):
            for c in range(k):
                Fd[a] += dD[a, c] * u[c]
    y0, sw, Lw, whiten = tg
    # J̃ᵀ L_w⁻¹ ∂r/∂S (k, N) with ∂r/∂S = −E/d + (∂y/∂F · F_d) ∂φ_L/∂S (E picks the coils'
    # columns): the whitening moved onto J̃'s k columns (forward_transposed), ∂r/∂S never formed
    Y = JD.copy()
    if whiten:
        forward_transposed(Lw, Y)
    JB = np.zeros((k, N))
    for a in range(R):
        for c in range(k):
            JB[c, coils[a]] -= Y[a, c] / gap
    for c in range(k if has_dD else 0):  # the turn of D with the shape's tip angle
        turn = 0.0
        for a in range(R):
            turn += Y[a, c] * (dy[a, 0] * Fd[0] + dy[a, 1] * Fd[1])
        for j in range(N):
            JB[c, j] += turn * dphi_ds[j]
    Bm = dym.copy()  # ∂r/∂(K0, EI), then whitened
    if whiten:
        forward(Lw, Bm)
    T = mm(D, mm(Hinv, JB))
    for a in range(2):
        for j in range(N):
            T[a, j] = Fd[a] * dphi_ds[j] - T[a, j]
    c = budget(T, cov_s, noise_var, -mm(D, mm(Hinv, mm(JD.T.copy(), Bm))), model_cov, parts)
    chi2 = 0.0
    for a in range(R):
        chi2 += e[a, 0] * e[a, 0]
    if model_cov[0, 0] > 0.0 or model_cov[1, 1] > 0.0:
        chi2 = chi2_with_model(e[:, 0].copy(), JD, Bm, model_cov)
    rank = 0
    for a in range(Lw.shape[0] if whiten else 0):
        rank += Lw[a, a] > 0.0
    dof = rank - k
    ratio = np.nan
    p = np.nan
    if dof > 0:
        ratio = chi2 / dof
        p = chi2_sf(chi2, dof)
        c *= max(ratio, 1.0)
        parts *= max(ratio, 1.0)
    unresolved(c, D, V, singular, out)
    return ratio, p


@njit(cache=True)
def chi2_with_model(e, JD, Bm, model_cov):
    """χ² of the whitened residual ``e`` (R,) when the model inputs are uncertain too.

    In whitened units the residual's covariance is ``C = I + B_m Σ_m B_mᵀ`` (``Bm`` (R, 2)
    = whitened ∂r/∂(K0, EI)); χ² = min_δu (e + J̃ δu)ᵀ C⁻¹ (e + J̃ δu), a k-parameter
    least-squares problem (docs/theory.md). C is the identity plus a rank-2 term:
    ``C⁻¹ = I − B_m Σ_m (I + B_mᵀ B_m Σ_m)⁻¹ B_mᵀ`` (Woodbury's identity in the form that
    needs no factor of Σ_m, which may be singular and mixes the units of K0 and EI), so
    the Gram matrix of ``[e, J̃]`` under C⁻¹ costs O(R), not C's O(R³) factorisation.
    """
    R = e.size
    k = JD.shape[1]
    A = np.empty((R, 1 + k))
    for a in range(R):
        A[a, 0] = e[a]
        for c in range(k):
            A[a, 1 + c] = JD[a, c]
    Bt = Bm.T.copy()
    P = mm(Bt, A)  # B_mᵀ [e, J̃] (2, 1 + k)
    S = mm(mm(Bt, Bm), model_cov)  # I + B_mᵀ B_m Σ_m: its eigenvalues are ≥ 1
    S[0, 0] += 1.0
    S[1, 1] += 1.0
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    Si = np.empty((2, 2))
    Si[0, 0], Si[1, 1], Si[0, 1], Si[1, 0] = S[1, 1] / det, S[0, 0] / det, -S[0, 1] / det, -S[1, 0] / det
    M = mm(A.T.copy(), A) - mm(P.T.copy(), mm(mm(model_cov, Si), P))  # [e, J̃]ᵀ C⁻¹ [e, J̃]
    G = M[1:, 1:].copy()
    g = M[1:, 0].copy()
    step = np.empty(k)
    lm_step(G, g, step)
    chi2 = M[0, 0]
    for c in range(k):
        chi2 += 2.0 * g[c] * step[c]
        for d in range(k):
            chi2 += step[c] * G[c, d] * step[d]
    return max(chi2, 0.0)


@njit(cache=True)
def budget(T, cov_s, noise_var, Tm, model_cov, parts):
    """The force covariance's parts into ``parts`` (3, 2, 2) and their sum (2, 2).

    Sensor noise ``T diag(noise_var) Tᵀ``, calibration error ``T (Σ_S − diag(noise_var))
    Tᵀ`` and model parameters ``T_m Σ_m T_mᵀ``: ``T`` (2, N) = ∂F/∂S, ``Σ_S`` = ``cov_s``
    whose diagonal holds the signal noise ``noise_var`` (N,) [m²] besides the
    calibration's error; ``Tm`` (2, 2) = ∂F/∂(K0, EI) and ``model_cov`` their covariance.
    """
    shifts = mm(mm(T, cov_s), T.T.copy())
    noise = np.zeros((2, 2))
    for i in range(noise_var.size):
        for a in range(2):
            for b in range(2):
                noise[a, b] += T[a, i] * noise_var[i] * T[b, i]
    bk.copy_into(noise, parts[0])
    bk.copy_into(shifts - noise, parts[1])
    bk.copy_into(mm(mm(Tm, model_cov), Tm.T.copy()), parts[2])
    return shifts + parts[2]


@njit(cache=True)
def chi2_sf(x, dof):
    """P(χ² > x) for ``dof`` degrees of freedom: the closed forms of Q(dof/2, x/2).

    Even dof: ``e^(−h) Σ_(j<dof/2) h^j / j!``; odd: ``erfc(√h) + e^(−h) Σ_(j<(dof−1)/2)
    h^(j+½) / Γ(j + 3/2)``, with ``h = x/2`` (Abramowitz & Stegun 6.5.13, 26.4.4).
    """
    h = 0.5 * max(x, 0.0)
    if dof % 2 == 0:
        term = math.exp(-h)
        total = term
        for j in range(1, dof // 2):
            term *= h / j
            total += term
    else:
        total = math.erfc(math.sqrt(h))
        term = math.exp(-h) * math.sqrt(h) / math.gamma(1.5)
        for j in range(dof // 2):
            total += term
            term *= h / (j + 1.5)
    return min(total, 1.0)


def tip_angle_weights(lengths, length_m):
    """Weights c with φ(L) = c · κ: the tip angle of the actuator from the segment curvatures.

    The sensor (length L_N) may end short of the actuator tip L, where the contact acts;
    the last segment's curvature is carried on to the tip.
    """
    c = np.array(lengths, dtype=float)
    c[-1] += max(length_m - c.sum(), 0.0)
    return c


def tip_angle_shift_gradient(lengths, length_m, strip_gap_m):
    """∂φ(L)/∂S (N,) through κ_i = (S_i − S_(i−1)) / (d l_i) (paper eq. 3–4)."""
    c = tip_angle_weights(lengths, length_m) / (np.asarray(lengths, dtype=float) * strip_gap_m)
    return c - np.append(c[1:], 0.0)


def noise_std(noise_opt, calibration, est):
    """Signal noise per channel (option, else the calibration's if nonzero, else the config's)."""
    if noise_opt is not None:
        sigma_a = np.asarray(noise_opt, dtype=float)
    elif calibration is not None and np.any(np.asarray(calibration.noise_std) > 0):
        sigma_a = np.asarray(calibration.noise_std, dtype=float)
    else:
        sigma_a = np.asarray(est.signal_noise_std, dtype=float)
    if np.any(sigma_a < 0) or not np.all(np.isfinite(sigma_a)):
        raise ArgumentError(f"noise_std: must be finite and >= 0, got {sigma_a.tolist()}")
    return sigma_a



def no_parameter_covariance_message(config) -> str:
    """What an estimate with ``config`` leaves out of σ when it declares no ``parameter_covariance``.

    Parameters
    ----------
    config : Config
        The config of the estimate (its ``name`` is quoted when it has one).
    """
    which = f"config {config.name!r}" if config.name else "config"
    return (f"{which} declares no parameter_covariance: σ holds sensor noise and calibration only; identify your "
            "actuator (bendsense identify free-bending / stiffness) or keep the shipped paper config's prior "
            "(docs/theory.md, 'The parameter prior')")


_PRIOR_WARNED = [False]  # NoParameterCovarianceWarning is given once per process (a live loop calls per frame)


def warn_no_parameter_covariance(config, stacklevel: int = 2) -> None:
    """Warn once per process (:class:`~bendsense.errors.NoParameterCovarianceWarning`) for a config without a prior.

    Costs one attribute look-up per call after that (the per-frame path calls it).

    Parameters
    ----------
    config : Config
        The config of the estimate.
    stacklevel : int
        As for :func:`warnings.warn`, counted from the caller of this function.
    """
    if _PRIOR_WARNED[0] or config.parameter_covariance is not None:
        return
    import warnings

    from bendsense.errors import NoParameterCovarianceWarning

    _PRIOR_WARNED[0] = True
    warnings.warn(no_parameter_covariance_message(config), NoParameterCovarianceWarning, stacklevel=stacklevel + 1)

_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
