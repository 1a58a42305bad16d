"""The covariance of the identified parameters: least squares, and a session's joint calibration error.

:mod:`bendsense.identify` fits the free-bending and stiffness models; the helpers here
give the fits' covariances and write them into a config's ``parameter_covariance``:
the least squares' sandwich, a prior's rows and its posterior (:class:`_Prior`, for
:func:`bendsense.adapt`), the stiffness regression over pressure levels.
:func:`session_covariance` is the covariance of quantities computed from many frames
of one session through the calibration's error model (the calibration error is common
to all frames: it does not average down over them).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from bendsense.config import FREE_BENDING_PARAMETERS, STIFFNESS_PARAMETERS
from bendsense.errors import ArgumentError

__all__ = ["session_covariance"]

_FRAMES_PER_BLOCK = 64  # frames per block of the joint covariance (memory (2 · 64 · N)² floats)


def _covariance(jac: np.ndarray, resid: np.ndarray, data_cov: np.ndarray | None = None,
                systematic_cov: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """s² (JᵀJ)⁻¹ with s² = RSS / (n − k); inf where the parameters are not identifiable.

    With the data's covariance Σ (n, n): the sandwich ``A (f Σ + Σ_sys) Aᵀ``,
    ``A = (JᵀJ)⁻¹Jᵀ``, ``f = max(1, RSS / E[RSS])`` with ``E[RSS] = tr((I − H) Σ)``
    (H the hat matrix): residuals that scatter more than Σ says scale Σ up, not the
    systematic part ``Σ_sys`` (an error common to the data that the residuals cannot show).
    """
    n, k = jac.shape
    dof = n - k
    if k == 0:
        return np.zeros((0, 0)), dof
    # SVD keeps the inverse honest when μ̄ and μ_s are nearly collinear
    u, sv, vt = np.linalg.svd(jac, full_matrices=False)
    s2 = float(resid @ resid) / dof if dof > 0 else math.nan
    if sv[0] == 0 or sv[-1] <= sv[0] * np.finfo(float).eps * max(n, k):
        return np.full((k, k), np.inf), dof
    if data_cov is None:
        return (vt.T / sv**2) @ vt * s2, dof
    a = (vt.T / sv) @ u.T  # (JᵀJ)⁻¹Jᵀ
    expected = float(np.trace(data_cov) - np.trace(u.T @ data_cov @ u))
    factor = max(1.0, float(resid @ resid) / expected) if expected > 0 else 1.0
    total = data_cov * factor + (0.0 if systematic_cov is None else systematic_cov)
    return a @ total @ a.T, dof


@dataclass(frozen=True)
class _Prior:
    """The prior rows of :func:`~bendsense.identify.fit_free_bending`: ``Σ₀^(-1/2) (x − x₀)``.

    ``held``: free-bending parameters the prior states no variance for (known exactly);
    ``stiffness``: the stiffness parameters it states, which the data see through
    ``response`` (n, len(stiffness)) = ∂θ_i/∂(ei0, ei1) only: their values stay the
    prior's (in one mount the gravity sag of free frames is a weak lever on EI, and a
    small misfit of K0(P) would move it), their uncertainty is carried in the data's
    weights and the posterior's cross-covariances. ``learned`` instead (free frames in
    two mounts, whose gravity sags differ: :func:`bendsense.identify.gravity.identify_gravity`):
    the stiffness parameters are fitted with the rest, the data moving by
    ``linear @ (b − b₀)``. ``mean`` and ``root`` over the parameters fitted (free
    bending, then ``learned``); ``cov`` the prior over those, then ``stiffness``.
    """

    held: tuple = ()
    stiffness: tuple = ()
    response: np.ndarray | None = None
    mean: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    root: np.ndarray | None = None
    cov: np.ndarray | None = None
    section: object = None
    learned: tuple = ()
    linear: np.ndarray | None = None

    @classmethod
    def of(cls, config, prior, fix, start, data_cov, stiffness_response, n, learn_stiffness=False):
        if not prior:
            if learn_stiffness:
                raise ArgumentError("learn_stiffness: needs prior=True (the stiffness is learned as an update)")
            return cls()
        section = config.parameter_covariance
        if section is None:
            raise ArgumentError(f"prior: config {config.name!r} states no parameter_covariance to update")
        if data_cov is None:
            raise ArgumentError("prior: needs data_covariance (what the data weigh against the prior)")
        if fix:
            raise ArgumentError("fix: not with a prior (a parameter known exactly has no prior variance)")
        var = {name: float(section.matrix[i, i]) for i, name in enumerate(section.parameters)}
        held = tuple(name for name in FREE_BENDING_PARAMETERS if not var.get(name, 0.0) > 0)
        stiffness = tuple(name for name in STIFFNESS_PARAMETERS if var.get(name, 0.0) > 0)
        response = np.zeros((n, 0))
        if stiffness:
            if stiffness_response is None:
                raise ArgumentError(f"stiffness_response: needed with a prior on {', '.join(stiffness)}")
            response = np.asarray(stiffness_response, dtype=float).reshape(n, len(STIFFNESS_PARAMETERS))
            response = response[:, [STIFFNESS_PARAMETERS.index(name) for name in stiffness]]
        fitted = [name for name in FREE_BENDING_PARAMETERS if name not in held]
        learned, linear = (), None
        if learn_stiffness:
            if not stiffness:
                raise ArgumentError("learn_stiffness: the prior states no variance of ei0_nm2 or ei1_nm2_per_pa")
            learned, stiffness, linear, response = stiffness, (), response, np.zeros((n, 0))
            fitted += learned
        idx = [section.parameters.index(name) for name in [*fitted, *stiffness]]
        cov = section.matrix[np.ix_(idx, idx)]
        k = len(fitted)
        root = np.linalg.inv(np.linalg.cholesky(cov[:k, :k]))
        return cls(held, stiffness, response, np.array([start[name] for name in fitted]), root, cov, section,
                   learned, linear)

    def moved(self, values: dict):
        """How far the learned stiffness moves the data from the prior's: ``linear @ (b − b₀)`` [rad] (0: none)."""
        if not self.learned:
            return 0.0
        b = np.array([values[name] for name in self.learned])
        return self.linear @ (b - self.mean[len(self.mean) - len(self.learned):])

    def stiffness_covariance(self) -> np.ndarray:
        """The data's covariance from the stiffness' prior: ``R Σ_b Rᵀ`` [rad²]."""
        k = len(self.mean)
        return self.response @ self.cov[k:, k:] @ self.response.T

    def sandwich(self, jac, resid, whiten, data_cov, sys_cov, scale) -> np.ndarray:
        """The posterior covariance over the fitted free-bending parameters, then ``stiffness``.

        The fit is linear in its errors: ``x̂ − x = A_p L (x₀ − x) + A_d W (R (b − b₀) + e)``
        (``A = J̃⁺`` split into the data's and the prior's columns, ``L = root``,
        ``W`` the whitening), the stiffness' estimate ``b₀`` errs by ``b₀ − b``; so with
        the prior's joint covariance Σ₀ the posterior is ``M Σ₀ Mᵀ + f A_d W Σ_e Wᵀ A_dᵀ``
        (``f = max(1, RSS / E[RSS])`` over the data rows, as :func:`_covariance`).
        """
        n, k = len(whiten), len(self.mean)
        pinv = np.linalg.pinv(jac)
        a = scale[:, None] * pinv  # in SI units (jac is in the scaled parameters)
        a_d, a_p = a[:, :n], a[:, n:]
        sigma = whiten @ data_cov @ whiten.T
        hat = (jac @ pinv)[:n, :n]
        expected = float(np.trace(sigma) - np.trace(hat @ sigma))
        factor = max(1.0, float(resid[:n] @ resid[:n]) / expected) if expected > 0 else 1.0
        m = np.eye(len(self.cov))
        m[:k, :k] = a_p @ self.root
        m[:k, k:] = -a_d @ whiten @ self.response
        out = m @ self.cov @ m.T
        noise = factor * sigma + (0.0 if sys_cov is None else whiten @ sys_cov @ whiten.T)
        out[:k, :k] += a_d @ noise @ a_d.T
        return 0.5 * (out + out.T)

    def posterior(self, names, values, joint, n) -> dict:
        """The posterior: the fitted ``values`` and the config's covariance section updated by ``joint``."""
        from bendsense.config import ParameterCovarianceConfig

        old = self.section
        idx = [old.parameters.index(name) for name in [*names, *self.stiffness]]
        matrix = np.zeros_like(old.matrix)  # the parameters the prior holds exactly stay exact
        matrix[np.ix_(idx, idx)] = joint
        source = f"{old.source or 'a prior'}; updated by {n} free frames (Bayesian: prior and data)"
        section = ParameterCovarianceConfig(parameters=old.parameters, source=source,
                                            covariance=tuple(tuple(float(v) for v in row) for row in matrix))
        return {"values": {name: values[name] for name in names}, "section": section}


def _correlation(cov: np.ndarray) -> np.ndarray:
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cov / np.outer(sd, sd)


def _stderr(cov: np.ndarray, free, names: tuple[str, ...]) -> dict:
    """Standard errors by name: sqrt(diag(cov)) for the ``free`` parameters, 0 for the fixed ones."""
    stderr = dict.fromkeys(names, 0.0)
    stderr.update({n: float(s) for n, s in zip(free, np.sqrt(np.diag(cov)), strict=True)})
    return stderr


def _full_covariance(cov: np.ndarray, free, names: tuple[str, ...]) -> np.ndarray:
    """The fit's covariance over all its ``names``: ``cov`` for the free ones, 0 for the fixed ones."""
    out = np.zeros((len(names), len(names)))
    idx = [names.index(n) for n in free]
    out[np.ix_(idx, idx)] = cov
    return out


def _with_covariance(config, names: tuple[str, ...], block: np.ndarray, what: str):
    """``config`` with this fit's block in ``parameter_covariance``, other fits' blocks kept.

    The fits are separate least-squares problems, so the matrix is block diagonal:
    the covariance between the parameters of different fits is taken as zero (the
    stiffness fit uses K0(P) from the free-bending parameters; from a session,
    :func:`bendsense.identify.weights.fit_stiffness_session` adds their uncertainty to
    its own block's variance, a table fit does not). A block that is not finite (parameters not identifiable)
    is not written: the config's own variances of those parameters stay (never variance 0 for what the
    fit could not determine).
    """
    from bendsense.config import MODEL_PARAMETERS, ParameterCovarianceConfig

    blocks, kept, prior = [], [], ""
    old = config.parameter_covariance
    finite = bool(np.all(np.isfinite(block)))
    if old is not None:
        keep = [i for i, n in enumerate(old.parameters) if n not in names or not finite]
        if keep:
            kept = [old.parameters[i] for i in keep]
            blocks.append((kept, old.matrix[np.ix_(keep, keep)]))
            if not old.source.startswith("identify "):  # e.g. the shipped config's prior: not a fit
                prior = f"; {', '.join(kept)} kept from the config's prior ({old.source or 'no source given'})"
    if finite:
        blocks.append((list(names), 0.5 * (block + block.T)))
    if not blocks:
        return config.replace(parameter_covariance=None)
    fits = []
    listed = [n for b, _ in blocks for n in b]
    fitted = [n for n in listed if not (prior and n in kept)]
    if any(n in fitted for n in FREE_BENDING_PARAMETERS):
        fits.append("identify free-bending")
    if any(n in fitted for n in STIFFNESS_PARAMETERS):
        fits.append("identify stiffness")
    source = " and ".join(fits) or "none identified"
    if len(fits) > 1:
        source += ", fitted separately: block diagonal (cross-covariances between the fits taken as zero)"
    elif prior and fits:
        source += ", block diagonal (no covariance with the prior's parameters)"
    source += f"; last: {what}; fixed parameters have variance 0{prior}"
    # list the parameters in the canonical order
    order = sorted(range(len(listed)), key=lambda i: MODEL_PARAMETERS.index(listed[i]))
    full = ParameterCovarianceConfig.from_blocks(blocks, source=source)
    matrix = full.matrix[np.ix_(order, order)]
    section = ParameterCovarianceConfig(
        parameters=tuple(listed[i] for i in order),
        covariance=tuple(tuple(float(v) for v in row) for row in matrix),
        source=source,
    )
    return config.replace(parameter_covariance=section)


def _covariance_note(cov) -> str:
    if cov is not None and np.all(np.isfinite(cov)):
        return "  covariance written to the config's parameter_covariance section"
    return "  covariance NOT written (parameters not identifiable, or no degrees of freedom)"


def session_covariance(calibration, shifts_m, weights, groups, n_groups: int, noise_std=None) -> np.ndarray:
    """Covariance of linear functions of many frames' shifts under one calibration's errors.

    Output ``g`` is ``y_g = Σ_{a: groups[a] = g} weights[a] · S_a`` (to first order),
    with ``S_a`` (N,) the shifts of frame ``a``. The frames' shifts are stacked into one
    vector and :func:`bendsense.calibration._kernels.shift_covariance` evaluates the
    calibration's error model over it (its channel tables tiled, the offsets' covariance
    indexed per channel): the noise is independent per frame, the coefficients',
    offsets' and misfit errors are correlated across frames as across channels. Pairs of
    blocks of frames keep the memory bounded.

    Parameters
    ----------
    calibration : Calibration
        The calibration (its :meth:`~bendsense.calibration.Calibration.error_model`).
    shifts_m : array_like, shape (K, N)
        The frames' shifts [m] (``calibration.shifts_m(signals)``).
    weights : array_like, shape (K, N)
        ∂y/∂S of each frame [output unit per m].
    groups : array_like of int, shape (K,)
        The output each frame contributes to, 0 … n_groups − 1.
    n_groups : int
        Outputs.
    noise_std : array_like (N,), optional
        Signal noise per channel [counts]; default the calibration's.

    Returns
    -------
    ndarray, shape (n_groups, n_groups)
        Covariance of the outputs.
    """
    from bendsense.calibration._kernels import shift_covariance

    m = calibration.error_model(noise_std)
    shifts = np.asarray(shifts_m, dtype=float)
    K, N = shifts.shape
    w = np.asarray(weights, dtype=float)
    g = np.asarray(groups, dtype=int)
    blocks = [np.arange(i, min(i + _FRAMES_PER_BLOCK, K)) for i in range(0, K, _FRAMES_PER_BLOCK)]
    out = np.zeros((n_groups, n_groups))
    for a, rows_a in enumerate(blocks):
        for b in range(a, len(blocks)):
            rows = rows_a if a == b else np.concatenate([rows_a, blocks[b]])
            S = shifts[rows].ravel()
            cov = np.empty((S.size, S.size))
            shift_covariance(_tiled_model(m, len(rows), N), S, cov, np.empty(S.size))
            W = np.zeros((n_groups, S.size))
            for r, frame in enumerate(rows):
                W[g[frame], r * N:(r + 1) * N] += w[frame]
            if a == b:
                out += W @ cov @ W.T
            else:
                n_a = len(rows_a) * N
                cross = W[:, :n_a] @ cov[:n_a, n_a:] @ W[:, n_a:].T
                out += cross + cross.T
    return 0.5 * (out + out.T)


def _tiled_model(m, frames: int, N: int):
    """The error model of ``frames`` frames' shifts stacked into one vector (:func:`session_covariance`)."""
    k = m.coef.shape[1]
    coef = m.coef_cov.shape[0] == 2 * k + N
    idx = np.concatenate([np.arange(2 * k), 2 * k + np.tile(np.arange(N), frames)])
    return m._replace(
        noise_std=np.tile(m.noise_std, frames), coef=np.tile(m.coef, (frames, 1)),
        dcoef=np.tile(m.dcoef, (frames, 1)), odd=np.tile(m.odd, frames),
        parity=np.tile(m.parity, (frames, frames)),
        coef_cov=np.ascontiguousarray(m.coef_cov[np.ix_(idx, idx)]) if coef else m.coef_cov)


def _pooled_errors(lse, lrms, counts):
    """The levels' standard errors of EI, their residual variance at least the one pooled over the levels.

    A level's own ``s_j² = RSS_j / (n_j − 1)`` rests on 3–5 degrees of freedom (two or
    three loads); weighted by such noisy ``1/se²`` the regression claimed a σ of γ1 0.77 of
    its scatter over 200 refits (tests/estimation/test_parameter_prior.py). One camera sees every
    level with the same noise: ``max(s_j², s²)``, ``s² = Σ RSS_j / Σ (n_j − 1)``,
    ``RSS_j = n_j rms_j²``; a level that misfits more than the others keeps its weight down.
    """
    dof = counts - 1
    rss = counts * lrms**2
    own = rss / np.maximum(dof, 1)
    use = np.isfinite(lse) & np.isfinite(rss) & (dof > 0)
    if not use.any() or not rss[use].sum() > 0:
        return lse
    pooled = rss[use].sum() / dof[use].sum()
    scale = use & (own > 0)
    out = lse.copy()
    out[scale] = lse[scale] * np.sqrt(np.maximum(pooled, own[scale]) / own[scale])
    return out


def _regress_levels(lp, lei, lse, free, fixed: dict, weighted: bool, level_cov=None):
    """Linear regression EI_j = ei0 + ei1 P_j over the levels (paper eq. 15).

    Weighted by 1/σ_EI² when ``weighted`` and every level has a finite standard error;
    the covariance scaled up by χ²/(levels − k) when the levels scatter more than their
    errors say. With the levels' covariances (Σ, Σ_sys) (correlated errors): the
    sandwich ``A (f Σ + Σ_sys) Aᵀ`` (A the regression's linear map), ``f = max(1,
    χ² / E[χ²])`` with E[χ²] from Σ. Returns
    the parameters' values, the levels' residuals [N m²], the free parameters'
    covariance and whether the weights were used.
    """
    n_levels = len(lp)
    design = {"ei0_nm2": np.ones(n_levels), "ei1_nm2_per_pa": lp}
    target = lei - sum(fixed[n] * design[n] for n in fixed)
    X = np.stack([design[n] for n in free], axis=-1) if free else np.zeros((n_levels, 0))
    finite_se = np.isfinite(lse) & (lse > 0)
    use_weights = weighted and bool(np.all(finite_se))
    weights = 1.0 / lse**2 if use_weights else np.ones(n_levels)
    sw = np.sqrt(weights)
    if free:
        beta, *_ = np.linalg.lstsq(X * sw[:, None], target * sw, rcond=None)
    else:
        beta = np.zeros(0)
    values = dict(fixed)
    values.update({n: float(b) for n, b in zip(free, beta, strict=True)})
    line = values["ei0_nm2"] + values["ei1_nm2_per_pa"] * lp
    residuals = lei - line
    dof = n_levels - len(free)
    if free and level_cov is not None:
        a = np.linalg.pinv((X * weights[:, None]).T @ X) @ (X * weights[:, None]).T
        resid_map = np.eye(n_levels) - X @ a
        data_cov, sys_cov = level_cov
        expected = float(np.trace(weights[:, None] * (resid_map @ data_cov @ resid_map.T)))
        chi2 = float(np.sum(weights * residuals**2))
        cov = a @ (data_cov * (max(1.0, chi2 / expected) if expected > 0 else 1.0) + sys_cov) @ a.T
    elif free:
        xtwx_inv = np.linalg.pinv((X * weights[:, None]).T @ X)
        chi2 = float(np.sum(weights * residuals**2))
        if use_weights:
            factor = max(1.0, chi2 / dof) if dof > 0 else 1.0
        else:
            factor = chi2 / dof if dof > 0 else math.inf
        cov = xtwx_inv * factor
    else:
        cov = np.zeros((0, 0))
    return values, residuals, cov, use_weights
