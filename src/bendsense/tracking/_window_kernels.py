"""Compiled kernels of the window test (:mod:`bendsense.tracking.windows`, docs/theory.md, "Time").

:func:`window_sums` adds a window's frames up, :func:`window_statistic` turns the sums into
the test's p-value (:func:`window_metric`: the statistic ``T = r̄ᵀ C⁺ r̄`` and the metric it
defines), :func:`window_tests` runs it over every window of a series and
:func:`window_metrics` over rows of means (a contact's location,
:mod:`bendsense.estimation.contact`). ``check_windows`` costs ~0.5 µs per frame in all
(benchmarks/bench_track.py).
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit
from bendsense.calibration._kernels import shift_covariance
from bendsense.calibration.shift_errors import ShiftErrorModel
from bendsense.estimation import uncertainty as unc

MIN_FRAMES = 5  # fewer usable frames in a window: no test (p NaN)


@njit(cache=True)
def complement(A):
    """An orthonormal basis (R, R − rank) of the complement of the column space of ``A`` (R, k).

    Modified Gram–Schmidt over the columns of A, then of the identity; a column left
    with less than 1e-8 of its norm is dependent and dropped.
    """
    R, k = A.shape
    basis = np.zeros((R, R))
    m = 0
    rank = 0
    for src in range(k + R):
        v = np.empty(R)
        for i in range(R):
            v[i] = A[i, src] if src < k else (1.0 if i == src - k else 0.0)
        n0 = 0.0
        for i in range(R):
            n0 += v[i] * v[i]
        n0 = math.sqrt(n0)
        if n0 == 0.0:
            continue
        for _ in range(2):  # twice: Gram–Schmidt keeps orthogonality to round-off
            for j in range(m):
                d = 0.0
                for i in range(R):
                    d += basis[i, j] * v[i]
                for i in range(R):
                    v[i] -= d * basis[i, j]
        nv = 0.0
        for i in range(R):
            nv += v[i] * v[i]
        nv = math.sqrt(nv)
        if nv <= 1e-8 * n0 or m == R:
            continue
        for i in range(R):
            basis[i, m] = v[i] / nv
        m += 1
        if src < k:
            rank += 1
    return basis[:, rank:m].copy()


@njit(cache=True)
def window_sums(lo, hi, resid, jac, mfac, shifts, rsum, Asum, Msum, Ssum):
    """Add the usable frames ``lo:hi`` (a finite payload) to the sums of r, A, M and the shifts; returns how many."""
    R = resid.shape[1]
    N = shifts.shape[1]
    n = 0
    for f in range(lo, hi):
        ok = True
        for i in range(R):
            ok = ok and math.isfinite(resid[f, i]) and math.isfinite(jac[f, i, 0] + jac[f, i, 1])
            ok = ok and math.isfinite(mfac[f, i, 0] + mfac[f, i, 1])
        for j in range(N):
            ok = ok and math.isfinite(shifts[f, j])
        if not ok:
            continue
        n += 1
        for i in range(R):
            rsum[i] += resid[f, i]
            for c in range(2):
                Asum[i, c] += jac[f, i, c]
                Msum[i, c] += mfac[f, i, c]
        for j in range(N):
            Ssum[j] += shifts[f, j]
    return n


@njit(cache=True)
def window_test(lo, hi, resid, jac, mfac, shifts, err, coils, gap):
    """The p-value and the usable frames of the window test over frames ``lo:hi`` (:func:`window_metric`)."""
    R = resid.shape[1]
    N = shifts.shape[1]
    rbar, A, M, S = np.zeros(R), np.zeros((R, 2)), np.zeros((R, 2)), np.zeros(N)
    n = window_sums(lo, hi, resid, jac, mfac, shifts, rbar, A, M, S)
    return window_statistic(rbar, A, M, S, n, err, coils, gap), n


@njit(cache=True)
def window_statistic(rsum, Asum, Msum, Ssum, n, err, coils, gap):
    """The p-value of a window from the sums of its ``n`` usable frames (:func:`window_sums`); NaN below MIN_FRAMES."""
    if n < MIN_FRAMES:
        return np.nan
    t, dof, _, _, _, _ = window_metric(rsum, Asum, Msum, Ssum, n, err, coils, gap, np.zeros((rsum.shape[0], 0)))
    return np.nan if dof == 0 else unc.chi2_sf(t, dof)


@njit(cache=True)
def window_metric(rsum, Asum, Msum, Ssum, n, err, coils, gap, extra):
    """The statistic of the window test and the metric it defines, from the sums of ``n`` frames (n ≥ 1).

    ``T = r̄ᵀ Ω r̄`` with ``Ω`` the pseudo-inverse of the mean residual's covariance ``C`` on
    the complement of the fitted directions Ā (:mod:`bendsense.tracking.windows`: ``Ω Ā = 0``, ``Ω C Ω =
    Ω``). Returns ``T``, its degrees of freedom (0: no test, T NaN), ``eᵀ Ω r̄`` (m,) and
    ``eᵀ Ω e`` (m, m) for the columns of ``extra`` (R, m) (directions of further
    parameters, e.g. the contact location's), and ``e₀ᵀ Ω C_p Ω e₀`` (3,) for the first
    column and the three parts ``C_p`` of ``C``: sensor noise / n, calibration, model
    parameters; and ``X`` (2, 5): ``Āᵀ W C_p Ω e₀`` (2,) per part and ``Āᵀ W Ā`` (2, 2),
    ``W = Σ_θ⁻¹`` the per-frame estimator's weights (they make the covariance of a
    frame's fitted parameters with the first extra parameter's estimate on the mean).
    """
    R = rsum.shape[0]
    N = Ssum.shape[0]
    m = extra.shape[1]
    rbar, A, M, S = rsum / n, Asum / n, Msum / n, Ssum / n
    cov_s = np.zeros((N, N))
    nv_s = np.zeros(N)
    shift_covariance(err, S, cov_s, nv_s)
    inv_d2 = 1.0 / (gap * gap)
    Lc = np.empty((R, R))
    C = np.empty((R, R))
    parts = np.zeros((3, R, R))
    for a in range(R):
        for b in range(R):
            Lc[a, b] = cov_s[coils[a], coils[b]] * inv_d2  # Σ_θ = diag(nv) + Σ_cal
            parts[1, a, b] = Lc[a, b]
            parts[2, a, b] = M[a, 0] * M[b, 0] + M[a, 1] * M[b, 1]
            C[a, b] = Lc[a, b] + parts[2, a, b]
        C[a, a] -= (1.0 - 1.0 / n) * nv_s[coils[a]] * inv_d2  # the noise averages down
        parts[0, a, a] = nv_s[coils[a]] * inv_d2 / n
        parts[1, a, a] -= nv_s[coils[a]] * inv_d2
    er, ee, var_parts, X = np.full(m, np.nan), np.full((m, m), np.nan), np.full(3, np.nan), np.full((2, 5), np.nan)
    if unc.cholesky(Lc) == 0:
        return np.nan, 0, er, ee, var_parts, X
    unc.forward(Lc, A)  # whitened: Ã, r̃, ẽ, G = Lc⁻¹ C Lc⁻ᵀ
    r = rbar.reshape(R, 1).copy()
    unc.forward(Lc, r)
    e = extra.copy()
    unc.forward(Lc, e)
    unc.forward(Lc, C)
    G = C.T.copy()
    unc.forward(Lc, G)
    Q = complement(A)
    y = unc.mm(Q.T.copy(), r)
    ye = unc.mm(Q.T.copy(), e)
    Cy = unc.mm(unc.mm(Q.T.copy(), G), Q)
    dof = unc.cholesky(Cy)
    if dof == 0:
        return np.nan, 0, er, ee, var_parts, X
    unc.forward(Cy, y)
    unc.forward(Cy, ye)
    t = 0.0
    for i in range(y.shape[0]):
        t += y[i, 0] * y[i, 0]
    for a in range(m):
        er[a] = 0.0
        for i in range(y.shape[0]):
            er[a] += ye[i, a] * y[i, 0]
        for b in range(m):
            ee[a, b] = 0.0
            for i in range(y.shape[0]):
                ee[a, b] += ye[i, a] * ye[i, b]
    x = np.zeros((0, 1))
    if m > 0:
        x = ye[:, :1].copy()
        unc.forward_transposed(Cy, x)  # Cy⁻¹ Qᵀ ẽ₀ = Ly⁻ᵀ ỹ
        for c in range(2):
            for c2 in range(2):
                X[c, 3 + c2] = 0.0
                for i in range(R):
                    X[c, 3 + c2] += A[i, c] * A[i, c2]  # Āᵀ W Ā = ÃᵀÃ
    for p in range(3 if m > 0 else 0):  # e₀ᵀ Ω C_p Ω e₀ = ỹᵀ (Ly⁻¹ Qᵀ G_p Q Ly⁻ᵀ) ỹ, ỹ = Ly⁻¹ Qᵀ ẽ₀ (Cy = Ly Lyᵀ)
        Gp = parts[p].copy()  # G_p = Lc⁻¹ C_p Lc⁻ᵀ
        unc.forward(Lc, Gp)
        Gp = Gp.T.copy()
        unc.forward(Lc, Gp)
        v = unc.mm(Gp, unc.mm(Q, x))
        for c in range(2):  # Āᵀ W C_p Ω e₀ = Ãᵀ G_p Q Cy⁻¹ Qᵀ ẽ₀
            X[c, p] = 0.0
            for i in range(R):
                X[c, p] += A[i, c] * v[i, 0]
        Z = unc.mm(unc.mm(Q.T.copy(), Gp), Q)
        unc.forward(Cy, Z)
        Z = Z.T.copy()
        unc.forward(Cy, Z)
        acc = 0.0
        for i in range(Z.shape[0]):
            for j in range(Z.shape[0]):
                acc += ye[i, 0] * Z[i, j] * ye[j, 0]
        var_parts[p] = acc
    return t, dof, er, ee, var_parts, X


@njit(cache=True)
def window_tests(bounds, resid, jac, mfac, shifts, err, coils, gap, p_out, n_out):
    """The window test of every window ``bounds[w]:bounds[w + 1]`` into ``p_out``, its usable frames into ``n_out``.

    ``resid`` (B, R), ``jac`` (B, R, 2), ``mfac`` (B, R, 2), ``shifts`` (B, N): the
    frames' payload (:class:`~bendsense.estimation.ForceEstimate`); ``err`` the shift error
    model as a plain tuple; ``coils`` (R,) the channels of the rows; ``gap`` d [m].
    """
    model = ShiftErrorModel(*err)
    for w in range(bounds.size - 1):
        p_out[w], n_out[w] = window_test(bounds[w], bounds[w + 1], resid, jac, mfac, shifts, model, coils, gap)


@njit(cache=True)
def window_metrics(resid, jac, mfac, shifts, extra, n, err, coils, gap, t_out, er_out, ee_out, parts_out, x_out):
    """:func:`window_metric` of K rows of means.

    ``resid`` (K, R), ``jac``/``mfac`` (K, R, 2), ``shifts`` (K, N),
    ``extra`` (K, R) one further direction per row, ``n`` (K,) the frames each mean is over; into the outputs
    (K,), (K, 3) and (K, 2, 5). ``err`` the shift error model as a plain tuple.
    """
    model = ShiftErrorModel(*err)
    for k in range(resid.shape[0]):
        if n[k] < 1:
            t_out[k] = er_out[k] = ee_out[k] = np.nan
            parts_out[k, :] = np.nan
            x_out[k] = np.nan
            continue
        t, dof, er, ee, parts, X = window_metric(resid[k] * n[k], jac[k] * n[k], mfac[k] * n[k], shifts[k] * n[k], n[k],
                                              model, coils, gap, extra[k].reshape(-1, 1).copy())
        t_out[k] = t if dof > 0 else np.nan
        er_out[k], ee_out[k] = er[0], ee[0, 0]
        parts_out[k, :] = parts
        x_out[k] = X


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
