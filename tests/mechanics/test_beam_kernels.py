"""The small dense linear algebra of the compiled uncertainty kernel against numpy."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bendsense.estimation import uncertainty as unc


@settings(max_examples=200, deadline=None)
@given(st.floats(-8, 8), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.booleans())
def test_eigh2_matches_numpy(scale, a, b, d, diagonal):
    H = np.array([[a, 0.0 if diagonal else b], [0.0 if diagonal else b, d]]) * 10.0**scale
    lam, V = unc.eigh2(H)
    want = np.linalg.eigvalsh(H)
    top = max(np.abs(want).max(), 1e-300)
    np.testing.assert_allclose(lam, want, rtol=0, atol=1e-13 * top)
    np.testing.assert_allclose(H @ V, V * lam, rtol=0, atol=1e-12 * top)
    np.testing.assert_allclose(V.T @ V, np.eye(2), atol=1e-14)


def test_semidefinite_cholesky_is_a_pseudo_inverse_of_the_measured_channels():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((16, 16))
    full = A @ A.T + np.eye(16)
    Lc = full.copy()
    assert unc.cholesky(Lc) == 16
    np.testing.assert_allclose(Lc @ Lc.T, full, rtol=1e-12, atol=1e-12)
    # channels 3 and 9 without noise: the rank drops and the whitened residual ignores them
    S = full.copy()
    S[[3, 9], :] = 0.0
    S[:, [3, 9]] = 0.0
    Lc = S.copy()
    assert unc.cholesky(Lc) == 14
    y = rng.standard_normal((16, 1))
    z = y.copy()
    unc.forward(Lc, z)
    keep = np.setdiff1d(np.arange(16), [3, 9])
    want = y[keep, 0] @ np.linalg.solve(S[np.ix_(keep, keep)], y[keep, 0])
    assert float(z[:, 0] @ z[:, 0]) == pytest.approx(want, rel=1e-10)


@pytest.mark.parametrize("drop", [(), (3, 9)])
def test_forward_transposed_moves_the_whitening_onto_the_other_factor(drop):
    # Vᵀ (L⁺ B) = (L⁺ᵀ V)ᵀ B, also where channels without noise leave L singular
    rng = np.random.default_rng(len(drop))
    A = rng.standard_normal((16, 16))
    S = A @ A.T + np.eye(16)
    S[list(drop), :] = 0.0
    S[:, list(drop)] = 0.0
    Lc = S.copy()
    assert unc.cholesky(Lc) == 16 - len(drop)
    V, B = rng.standard_normal((16, 2)), rng.standard_normal((16, 16))
    whitened, moved = B.copy(), V.copy()
    unc.forward(Lc, whitened)
    unc.forward_transposed(Lc, moved)
    np.testing.assert_allclose(moved.T @ B, V.T @ whitened, rtol=1e-11, atol=1e-11)
    keep = np.setdiff1d(np.arange(16), drop)
    if drop:  # the dropped channels take no part: the pseudo-inverse of the kept block
        np.testing.assert_array_equal(moved[list(drop)], 0.0)
    np.testing.assert_allclose(Lc[np.ix_(keep, keep)].T @ moved[keep], V[keep], rtol=1e-10, atol=1e-12)  # Lᵀ X = V


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("case", ["full", "singular", "units"])
def test_chi2_with_model_is_the_generalised_least_squares_minimum(k, case):
    # χ² = min_δu (e + J δu)ᵀ C⁻¹ (e + J δu), C = I + B Σ Bᵀ: dense, by numpy; "units": Σ over
    # (K0, EI) in units 1e8 apart (B the inverse), where a factor of Σ with a relative pivot floor drops EI
    rng = np.random.default_rng(10 * k + len(case))
    R = 14
    e, J, B = rng.standard_normal(R), rng.standard_normal((R, k)), rng.standard_normal((R, 2))
    a = rng.standard_normal((2, 2))
    cov = np.outer(a[0], a[0]) if case == "singular" else a @ a.T
    if case == "units":
        scale = np.array([1e4, 1e-4])
        cov, B = cov * np.outer(scale, scale), B / scale
    C = np.eye(R) + B @ cov @ B.T
    Ci = np.linalg.inv(C)
    du = -np.linalg.solve(J.T @ Ci @ J, J.T @ Ci @ e)
    r = e + J @ du
    assert unc.chi2_with_model(e, J, B, cov) == pytest.approx(r @ Ci @ r, rel=1e-10)


def test_scalar_interp_matches_numpy():
    from bendsense.calibration._kernels import interp

    xp = np.linspace(0.0, 2.0, 9) ** 1.5
    fp = np.cos(xp)
    for x in np.concatenate([[-1.0, 0.0, 2.0**1.5, 5.0], np.random.default_rng(0).uniform(-0.5, 3.5, 200)]):
        assert interp(x, xp, fp) == pytest.approx(np.interp(x, xp, fp), abs=1e-15)


def test_small_products_match_numpy():
    rng = np.random.default_rng(1)
    A, B = rng.standard_normal((5, 3)), rng.standard_normal((3, 4))
    np.testing.assert_allclose(unc.mm(A, B), A @ B, rtol=1e-14)


@pytest.mark.parametrize("k", [1, 2])
def test_misfit_gls_equals_the_pseudo_inverse_form_when_the_fit_absorbs_k_directions(k):
    # δŜ = (GᵀWG)⁻¹GᵀW r, C = (I − ZT) Σ (I − ZT)ᵀ of rank N − k, χ² = δŜᵀ C⁺ δŜ
    rng = np.random.default_rng(k)
    M2, N = 40, 16
    G = rng.standard_normal((M2, N))
    w2 = rng.uniform(0.5, 2.0, M2)
    J = G @ rng.standard_normal((N, k))  # model directions the shifts can explain
    A = rng.standard_normal((N, N))
    cov = A @ A.T / N + 0.1 * np.eye(N)
    W = np.diag(w2)
    r = G @ rng.multivariate_normal(np.zeros(N), cov) + 1e-3 * rng.standard_normal(M2)
    r -= J @ np.linalg.solve(J.T @ W @ J, J.T @ W @ r)  # the residual at the optimum: J'W r = 0
    chi2, dof = unc.misfit(G, w2, r, J, cov)
    pull = np.linalg.solve(G.T @ W @ G, G.T @ W)
    dS, Z = pull @ r, pull @ J
    T = np.linalg.solve(J.T @ W @ J, J.T @ W @ G)
    P = np.eye(N) - Z @ T
    lam, V = np.linalg.eigh(P @ cov @ P.T)
    z = V.T @ dS
    want = np.sum(z[k:] ** 2 / lam[k:])
    assert dof == N - k
    assert chi2 == pytest.approx(want, rel=1e-8)


def test_lu_factor_and_apply_solve_column_by_column_as_together():
    from bendsense.mechanics import _beam_kernels as bk

    rng = np.random.default_rng(7)
    for _ in range(20):
        A = rng.standard_normal((19, 19))
        A[:, 0] *= 1e-3  # pivoting needed
        B = rng.standard_normal((19, 4))
        together, split = B.copy(), B.copy()
        assert bk.lu_solve(A.copy(), together)
        LU, piv = A.copy(), np.empty(19, dtype=np.int64)
        assert bk.lu_factor(LU, piv)
        bk.lu_apply(LU, piv, split, 0, 1)
        bk.lu_apply(LU, piv, split, 1, 4)
        np.testing.assert_array_equal(split, together)
        np.testing.assert_allclose(together, np.linalg.solve(A, B), rtol=1e-9, atol=1e-9)
    assert not bk.lu_solve(np.zeros((3, 3)), np.ones((3, 1)))


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 7, 14, 15, 16, 41])
def test_chi2_sf_is_the_chi2_survival_function(dof):
    from scipy import stats

    from bendsense.estimation.uncertainty import chi2_sf

    for x in (0.0, 1e-6, 0.3, 1.0, dof - 1.0, float(dof), 2.0 * dof, 5.0 * dof + 20.0, 300.0):
        x = max(x, 0.0)
        np.testing.assert_allclose(chi2_sf(x, dof), stats.chi2.sf(x, dof), rtol=1e-10, atol=1e-300)
