"""The covariance of the identified parameters: least squares, and a session's joint calibration error.

:mod:`bendsense.identify` fits the free-bending and stiffness models; the helpers here
give the fits' covariances and write them into a config's ``parameter_covariance``.
:func:`session_covariance` is the covariance of quantities computed from many frames
of one session through the calibration's error model (the calibration error is common
to all frames: it does not average down over them).
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.config import FREE_BENDING_PARAMETERS, STIFFNESS_PARAMETERS

__all__ = ["session_covariance"]

_FRAMES_PER_BLOCK = 64  # frames per block of the joint covariance (memory (2 · 64 · N)² floats)


def _covariance(jac: np.ndarray, resid: np.ndarray, data_cov: np.ndarray | None = None,
                systematic_cov: np.ndarray | None = None, n_data: int | None = None) -> tuple[np.ndarray, int]:
    """s² (JᵀJ)⁻¹ with s² = RSS / (n − k); inf where the parameters are not identifiable.

    With the data's covariance Σ (n, n): the sandwich ``A (f Σ + Σ_sys) Aᵀ``,
    ``A = (JᵀJ)⁻¹Jᵀ``, ``f = max(1, RSS / E[RSS])`` with ``E[RSS] = tr((I − H) Σ)``
    (H the hat matrix): residuals that scatter more than Σ says scale Σ up, not the
    systematic part ``Σ_sys`` (an error common to the data that the residuals cannot show).
    ``n_data``: only the first rows are data (RSS and its expectation over them); the
    others are a prior's rows (their covariance in ``Σ_sys``).
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
    d = n if n_data is None else n_data
    ud = u[:d]
    expected = float(np.trace(data_cov[:d, :d]) - np.trace(ud.T @ data_cov[:d, :d] @ ud))
    factor = max(1.0, float(resid[:d] @ resid[:d]) / expected) if expected > 0 else 1.0
    total = data_cov * factor + (0.0 if systematic_cov is None else systematic_cov)
    return a @ total @ a.T, dof


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
    :func:`bendsense.identify_session.fit_stiffness_session` adds their uncertainty to
    its own block's variance, a table fit does not). A block that is not finite (parameters not identifiable)
    is not written, and an older block of the same parameters is removed.
    """
    from bendsense.config import MODEL_PARAMETERS, ParameterCovarianceConfig

    blocks, kept, prior = [], [], ""
    old = config.parameter_covariance
    if old is not None:
        keep = [i for i, n in enumerate(old.parameters) if n not in names]
        if keep:
            kept = [old.parameters[i] for i in keep]
            blocks.append((kept, old.matrix[np.ix_(keep, keep)]))
            if not old.source.startswith("identify "):  # e.g. the shipped config's prior: not a fit
                prior = f"; {', '.join(kept)} kept from the config's prior ({old.source or 'no source given'})"
    if np.all(np.isfinite(block)):
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
    vector and :func:`bendsense.shift_errors.shift_covariance` evaluates the
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
    from bendsense.shift_errors import shift_covariance

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
