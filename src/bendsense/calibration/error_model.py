"""The errors of a calibration's shifts: the polynomials' misfit and the fit's data noise.

How wrong ``S = f(ΔA)`` is, apart from the frame's own signal noise
(:meth:`Calibration.shift_error_m <bendsense.calibration.Calibration.shift_error_m>`,
:attr:`~bendsense.calibration.Calibration.coefficient_covariance`):

- the misfit ``r(S) = f(ΔA) − S`` of the polynomials, a smooth random function of the
  shift: its envelope per parity from the fit residuals, and its correlation between
  channels, a Gaussian process fitted by maximum likelihood (:func:`_misfit_correlation`);
- the coefficients' and offsets' covariance from the noise of the recordings they were
  fitted to.

:func:`error_model` gathers both, with the signal noise, into the
:class:`~bendsense.calibration.shift_errors.ShiftErrorModel` the compiled kernels take.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bendsense import validation as check
from bendsense._blas import one_thread
from bendsense.calibration.polynomials import _shift_weights, parity_masks, polyval_shift
from bendsense.errors import ArgumentError, ConfigError

__all__ = ["AngleCovariance"]


_MISFIT_POINTS = 240  # calibration points in the misfit likelihood (16 channels × 15 strips)


def _misfit_correlation(x, z, odd, top) -> dict:
    """Maximum-likelihood correlation of the calibration misfit (:meth:`Calibration.shift_error_m`).

    ``z`` (K,): the fit residuals at the shifts ``x`` scaled by their envelope σ, ``odd``
    their parity. The model: a Gaussian process with ``Cov(z_a, z_b) = (1 − w) c_ab
    exp(−(x_a − x_b)² / 2ℓ²) + w δ_ab`` (``c_ab`` 1 within a parity, ``c`` between),
    its parameters ℓ, ``c`` and the white fraction ``w`` chosen on a grid by the
    likelihood of ``z``. The white part (the noise of the strip means, the offsets)
    keeps ℓ from collapsing onto the closest pair of points. At most ``_MISFIT_POINTS``
    points, evenly spaced in ``x``, enter the likelihood (its cost grows with their cube).
    """
    from scipy.linalg import solve_triangular  # here: scipy is imported where it is used (~0.1 s)

    if x.size > _MISFIT_POINTS:
        keep = np.argsort(x, kind="stable")[np.linspace(0, x.size - 1, _MISFIT_POINTS).round().astype(int)]
        x, z, odd = x[keep], z[keep], odd[keep]
    same = odd[:, None] == odd[None, :]
    lag2 = np.square(x[:, None] - x[None, :])
    eye = np.eye(x.size)
    best = (-np.inf, 0.0, 0.0, 1.0)
    for ell in np.geomspace(top / 300.0, top, 30):
        g = np.exp(-0.5 * lag2 / ell**2)
        for c in (0.0, 0.5, 0.9, 0.97):
            gc = g * np.where(same, 1.0, c)
            for w in (1e-3, 1e-2, 3e-2, 0.1, 0.3):
                try:
                    lc = np.linalg.cholesky((1.0 - w) * gc + w * eye)
                except np.linalg.LinAlgError:  # this grid point's covariance is not positive definite: not a model
                    continue
                y = solve_triangular(lc, z, lower=True, check_finite=False)  # O(K²), not LU
                ll = -0.5 * float(y @ y) - float(np.log(np.diag(lc)).sum())
                if ll > best[0]:
                    best = (ll, float(ell), float(c), float(w))
    if best[0] == -np.inf:  # never a silent fallback to white noise: the calibration-error part of σ depends on it
        raise ConfigError(f"calibration: no correlation model of the fit residuals has a finite likelihood "
                          f"({x.size} points; non-finite residuals, or every grid covariance singular): the "
                          "calibration-error part of σ cannot be estimated; refit with `bendsense calibrate`")
    return {"length_m": best[1], "parity_correlation": best[2], "white_fraction": best[3]}


@dataclass(frozen=True, eq=False)
class AngleCovariance:
    """Covariance of the measured tangent angles ``φ(L_i) = S_i / d``, by source.

    Attributes
    ----------
    noise : ndarray, shape (..., N, N)
        The frame's signal noise through the calibration's slopes [rad²]; diagonal.
    calibration : ndarray, shape (..., N, N)
        The calibration's error: its coefficients and offsets (from the noise of
        the recordings it was fitted to) and the polynomials' misfit [rad²].
    """

    noise: np.ndarray
    calibration: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """``noise + calibration`` [rad²], shape (..., N, N)."""
        return self.noise + self.calibration

    @property
    def std_rad(self) -> np.ndarray:
        """Standard deviation of each angle from ``total`` [rad], shape (..., N)."""
        return np.sqrt(np.diagonal(self.total, axis1=-2, axis2=-1))


@one_thread
def shift_error_table(cal) -> dict:
    """The misfit's envelopes and correlation of a calibration (``Calibration._shift_error_table``).

    Parameters
    ----------
    cal : Calibration
        The calibration, with its fitted data when the file has it.

    Returns
    -------
    dict
        ``grid_m``, ``sigma_odd_m``, ``sigma_even_m``: the envelopes σ_p(|S|) [m];
        ``length_m``: ℓ [m] (0: independent channels); ``parity_correlation``: c;
        ``white_fraction``: w (see :meth:`Calibration.shift_error_m`).
    """
    if cal.fit_delta_a is None or cal.fit_shifts_m is None:
        rms = [r.rms_shift_m for r in cal.strip_residuals]
        if not rms:
            _warn_once(cal, "misfit", "σ leaves out the calibration misfit (how far the polynomials miss the strips): "
                       "the calibration has neither fit_delta_a, fit_shifts_m nor strip_residuals; refit with "
                       "`bendsense calibrate` to include it")
        level = float(np.sqrt(np.mean(np.square(rms)))) if rms else 0.0
        flat = np.array([level, level])
        return {"grid_m": np.array([0.0, 1.0]), "sigma_odd_m": flat, "sigma_even_m": flat, "length_m": 0.0,
                "parity_correlation": 0.0}
    shifts = cal.fit_shifts_m
    resid = cal.shifts_from_delta(cal.fit_delta_a) - shifts
    odd, even = parity_masks(cal.n_channels)
    top = float(np.abs(shifts).max())
    grid = np.linspace(0.0, top, 65)
    h = 0.1 * top if top > 0 else 1.0

    def envelope(mask):
        x = np.abs(shifts[:, mask]).ravel()
        k = np.exp(-0.5 * ((grid[:, None] - x[None, :]) / h) ** 2)
        return np.sqrt(k @ resid[:, mask].ravel() ** 2 / k.sum(axis=1))

    sig_odd = envelope(odd)
    sig_even = envelope(even) if np.any(even) else sig_odd
    out = {"grid_m": grid, "sigma_odd_m": sig_odd, "sigma_even_m": sig_even, "length_m": 0.0,
           "parity_correlation": 0.0}
    level = np.where(odd, np.interp(np.abs(shifts), grid, sig_odd), np.interp(np.abs(shifts), grid, sig_even))
    if top > 0 and np.all(level > 0):
        out.update(_misfit_correlation(shifts.ravel(), (resid / level).ravel(),
                                       np.broadcast_to(odd, shifts.shape).ravel(), top))
    return out


@one_thread
def parity_correlation(cal):
    """The odd channels, and ``c_ij`` of the misfit's correlation (``Calibration._parity_correlation``).

    1 on the diagonal, 1 − w within a parity, (1 − w) c between them (w: the misfit's
    white fraction).

    Parameters
    ----------
    cal : Calibration
        The calibration; its ``_shift_error_table`` gives ``w`` and ``c``.

    Returns
    -------
    odd : ndarray of bool, shape (N,)
    c : ndarray, shape (N, N)
    """
    odd, _ = parity_masks(cal.n_channels)
    same = odd[:, None] == odd[None, :]
    table = cal._shift_error_table
    smooth = 1.0 - table.get("white_fraction", 0.0)
    c = np.where(same, smooth, smooth * table["parity_correlation"])
    np.fill_diagonal(c, 1.0)
    return odd, c


def fit_operator(cal, mask):
    """The fit's least-squares operator of one parity: ``c = op @ y[keep]`` (as :func:`polyfit_shift`).

    Parameters
    ----------
    cal : Calibration
        A calibration with its fitted data.
    mask : ndarray of bool, shape (N,)
        The channels of the parity.

    Returns
    -------
    keep : ndarray of bool
        The points with a positive weight.
    op : ndarray, shape (degree + 1, keep.sum())
        The operator, in plain ascending powers of ΔA.
    """
    k = cal.degree + 1
    x = cal.fit_delta_a[:, mask].ravel()
    y = cal.fit_shifts_m[:, mask]
    w = (_shift_weights(y) if cal.weighting == "shift" else np.ones(y.size)).ravel()
    keep = w > 0
    xs = x[keep]
    scale = float(np.max(np.abs(xs))) or 1.0
    sw = np.sqrt(w[keep])
    op = np.linalg.pinv(np.vander(xs / scale, k, increasing=True) * sw[:, None]) * sw
    return keep, op / scale ** np.arange(k)[:, None]


@one_thread
def coefficient_covariance(cal) -> np.ndarray:
    """Joint covariance of ``(a_0..a_n, b_0..b_n, A0_1..A0_N)`` (:attr:`Calibration.coefficient_covariance`).

    Parameters
    ----------
    cal : Calibration
        The calibration, with its fitted data, noise and frame counts.

    Returns
    -------
    ndarray, shape (2 (n + 1) + N, 2 (n + 1) + N)
    """
    n, k = cal.n_channels, cal.degree + 1
    if cal.fit_delta_a is None or cal.fit_shifts_m is None:
        raise ConfigError(
            "calibration: fit_delta_a, fit_shifts_m are missing (an older file without the fitted data); "
            "refit with `bendsense calibrate` to get the coefficients' covariance"
        )
    sigma = cal.noise_std_counts()
    rows = cal.fit_delta_a.shape[0]
    flat_frames = cal.meta.get("flat_frames")
    frames = [r.n_frames for r in cal.strip_residuals]
    if not isinstance(flat_frames, int) or flat_frames < 1:
        raise ConfigError("calibration: meta.flat_frames is missing (frames of the flat recording)")
    if len(frames) != rows - 1 or min(frames, default=1) < 1:
        raise ConfigError(
            f"calibration: strip_residuals[].n_frames: expected the frame count of each of the {rows - 1} "
            f"strips, got {frames}"
        )
    var_strip = np.concatenate([[0.0], 1.0 / np.asarray(frames, dtype=float)])[:, None] * sigma**2  # (R, N)
    var_offset = sigma**2 / flat_frames
    odd, even = parity_masks(n)
    q = np.zeros((2 * k + n, 2 * k + n))
    q[2 * k :, 2 * k :] = np.diag(var_offset)
    for block, (mask, coef) in enumerate(((odd, cal.coefficients_odd), (even, cal.coefficients_even))):
        if not np.any(mask):
            continue
        x = cal.fit_delta_a[:, mask]
        keep, op = cal._fit_operator(mask)
        xs = x.ravel()[keep]
        slope = np.zeros(x.size)
        slope[keep] = polyval_shift(coef[1:] * np.arange(1, k), xs) if k > 1 else 0.0
        gain = np.zeros((k, x.size))
        gain[:, keep] = op * slope[keep]  # δc = −gain · δx, per point
        cov_eps = (gain * var_strip[:, mask].ravel()) @ gain.T
        # δx = ε − δA0(channel): δc gets +gain summed over the channel's points
        channel = np.broadcast_to(np.flatnonzero(mask), x.shape).ravel()
        strip_row = np.broadcast_to(np.arange(rows)[:, None] > 0, x.shape).ravel()
        to_offset = np.zeros((k, n))
        np.add.at(to_offset.T, channel[strip_row], gain[:, strip_row].T)
        sl = slice(block * k, (block + 1) * k)
        q[sl, sl] += cov_eps + (to_offset * var_offset) @ to_offset.T
        q[sl, 2 * k :] = to_offset * var_offset
        q[2 * k :, sl] = q[sl, 2 * k :].T
    return q


def _warn_once(cal, key: str, message: str) -> None:
    """Log ``message`` as a warning the first time ``key`` is missing from this calibration.

    Through the ``bendsense`` logger (a ``WARNING:`` line on the command line, Python's
    last-resort handler in a notebook), once per calibration object: the error model is
    built once per call of ``estimate_force``, and a live run calls it per block.
    """
    import logging

    done = cal.__dict__.setdefault("_sigma_warnings", set())
    if key not in done:
        done.add(key)
        source = cal.meta.get("manifest") if isinstance(cal.meta, dict) else None
        where = f"calibration (fitted from {source})" if source else "calibration"
        logging.getLogger("bendsense").warning("%s: %s", where, message)


def error_model(cal, noise_std_counts=None):
    """The errors of a calibration's shifts as the compiled kernels take them (:meth:`Calibration.error_model`).

    Parameters
    ----------
    cal : Calibration
        The calibration.
    noise_std_counts : array_like (N,), optional
        Signal noise per channel [counts]; default the calibration's ``noise_std``.

    Returns
    -------
    bendsense.calibration.shift_errors.ShiftErrorModel
    """
    from bendsense.calibration.shift_errors import ShiftErrorModel

    noise = cal.noise_std if noise_std_counts is None else noise_std_counts
    try:
        noise = np.array(np.broadcast_to(np.asarray(noise, dtype=float), (cal.n_channels,)))
    except (TypeError, ValueError):
        raise ArgumentError(f"noise_std_counts: expected a number or {cal.n_channels} numbers [counts], got "
                            f"{check.short(noise_std_counts)}") from None
    if not (np.all(np.isfinite(noise)) and np.all(noise >= 0)):
        raise ArgumentError(f"noise_std_counts: must be finite and >= 0, got {noise.tolist()}")
    coef = np.array(cal._channel_coefficients, dtype=float)
    table = cal._shift_error_table
    odd, parity = cal._parity_correlation
    try:
        q = np.array(cal.coefficient_covariance, dtype=float)
    except ConfigError as err:  # an old file without the fitted data or frame counts: said, once, never silent
        q = np.zeros((1, 1))
        _warn_once(cal, "coefficient_covariance", f"σ leaves out the calibration-coefficient part (the uncertainty "
                   f"of the fitted polynomials and offsets): {str(err).removeprefix('calibration: ')}")
    return ShiftErrorModel(
        calibrated=True, noise_std=noise, coef=coef, dcoef=coef[:, 1:] * np.arange(1, coef.shape[1]),
        grid_m=np.array(table["grid_m"], dtype=float), sigma_odd_m=np.array(table["sigma_odd_m"], dtype=float),
        sigma_even_m=np.array(table["sigma_even_m"], dtype=float), odd=np.array(odd), parity=np.array(parity),
        length_m=float(table["length_m"]), coef_cov=q)


def angle_covariance(cal, signals, sensor=None) -> AngleCovariance:
    """Covariance of the measured angles, by source (:meth:`Calibration.angle_covariance`).

    Parameters
    ----------
    cal : Calibration
        The calibration.
    signals : array_like, shape (..., N)
        Raw signals A [counts].
    sensor : SensorConfig or Config, optional
        As in :meth:`Calibration.angles_rad`.

    Returns
    -------
    AngleCovariance
    """
    from bendsense.calibration._kernels import shift_covariances

    a = np.asarray(signals, dtype=float)
    cal._check_channels(a)
    d = cal.strip_gap_m(sensor)
    sigma = cal.noise_std_counts()  # these two raise, naming what an old file lacks
    cal.coefficient_covariance  # noqa: B018
    model = cal.error_model(sigma)
    n = cal.n_channels
    shifts = np.ascontiguousarray(cal.shifts_from_delta(a - cal.offset).reshape(-1, n))
    total, noise_var = np.empty((shifts.shape[0], n, n)), np.empty((shifts.shape[0], n))
    shift_covariances(model, shifts, total, noise_var)
    noise = np.zeros_like(total)
    noise[:, np.arange(n), np.arange(n)] = noise_var
    shape = (*a.shape[:-1], n, n)
    return AngleCovariance(noise=noise.reshape(shape) / d**2, calibration=(total - noise).reshape(shape) / d**2)
