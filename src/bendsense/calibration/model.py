"""The calibration object: signals → shifts, their inverse, and the errors of both (paper eq. 1–2).

:class:`Calibration` holds the offset A0 and the polynomials ``f_odd``, ``f_even`` with
what was measured when they were fitted. Its methods are the measurement model the
estimator uses: shifts and slopes per channel, the inverse (signals from shifts), the
angles ``φ(L_i) = S_i / d``, the signal noise, and the shifts' errors
(:mod:`bendsense.calibration.error_model`). Fitting (:mod:`bendsense.calibration.fit`)
and the file (:mod:`bendsense.calibration.io`) are modules of their own, which the class
methods call.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from bendsense import validation as check
from bendsense._blas import one_thread
from bendsense._io import read_yaml
from bendsense.calibration import error_model as errors
from bendsense.calibration import io, report
from bendsense.calibration.error_model import AngleCovariance
from bendsense.calibration.fit import StripResidual, fit_fields, read_recordings
from bendsense.calibration.io import _array, _range
from bendsense.calibration.polynomials import WEIGHTINGS, parity_masks
from bendsense.errors import ArgumentError, ConfigError

__all__ = ["Calibration"]

RANGE_MARGIN_STD = 3.0


@dataclass(frozen=True, kw_only=True, eq=False)
class Calibration:
    """Signal → shift calibration of the sensor (paper eq. 1–2).

    Attributes
    ----------
    offset : ndarray, shape (N,)
        A0, the mean signal of the flat sensor [signal units] (paper eq. 1).
    coefficients_odd, coefficients_even : ndarray, shape (n + 1,)
        Coefficients a_k, b_k of f_odd and f_even in ascending powers [m / unit^k].
    degree : int
        Polynomial degree n.
    delta_a_range_odd, delta_a_range_even : tuple of float
        (min, max) of the fitted ΔA per parity [signal units].
    noise_std : ndarray, shape (N,)
        Per-channel signal noise, the flat recording's frame standard deviation.
    strip_residuals : tuple of StripResidual
        Fit quality on every calibration strip.
    cv_errors_m : dict of int to float or None
        Leave-one-strip-out RMS shift error per degree [m], when computed.
    weighting : str
        ``"none"`` or ``"shift"`` (see :mod:`bendsense.calibration`).
    sleeve : bool
        Whether κ_cal = 1/(R + c) was used.
    sensor : SensorConfig or None
        Snapshot of the sensor the calibration was fitted for.
    fit_delta_a, fit_shifts_m : ndarray, shape (R, N), optional
        The fitted data (flat first, then one row per strip), for plots.
    meta : dict
        Free-form metadata (creation time, manifest).
    finger : str or None
        The gripper finger it was fitted for (``calibrate --config G --finger NAME``);
        using it for another finger is an error naming both. None: any actuator.
    """

    offset: np.ndarray
    coefficients_odd: np.ndarray
    coefficients_even: np.ndarray
    degree: int
    delta_a_range_odd: tuple
    delta_a_range_even: tuple
    noise_std: np.ndarray | None = None
    strip_residuals: tuple = ()
    cv_errors_m: dict | None = None
    weighting: str = "none"
    sleeve: bool = False
    sensor: Any = None
    fit_delta_a: np.ndarray | None = None
    fit_shifts_m: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    finger: str | None = None

    def __post_init__(self):
        set_ = object.__setattr__
        if self.finger is not None:
            from bendsense.config.gripper import FINGER_NAME

            if not isinstance(self.finger, str) or not re.fullmatch(FINGER_NAME, self.finger):
                raise ConfigError(f"finger: expected a finger's name matching {FINGER_NAME}, got "
                                  f"{check.short(self.finger)}")
        offset = _array("offset", self.offset)
        n = offset.size
        if n == 0:
            raise ConfigError("offset: expected at least one channel, got 0")
        set_(self, "offset", offset)
        c_odd = _array("coefficients_odd", self.coefficients_odd)
        c_even = _array("coefficients_even", self.coefficients_even)
        if isinstance(self.degree, bool) or not isinstance(self.degree, (int, np.integer)) or self.degree < 0:
            raise ConfigError(f"degree: expected an integer >= 0, got {check.short(self.degree)}")
        for name, c in (("coefficients_odd", c_odd), ("coefficients_even", c_even)):
            if c.size != self.degree + 1:
                raise ConfigError(
                    f"{name}: expected {self.degree + 1} coefficients (degree {self.degree}), got {c.size}"
                )
        set_(self, "degree", int(self.degree))
        set_(self, "coefficients_odd", c_odd)
        set_(self, "coefficients_even", c_even)
        set_(self, "delta_a_range_odd", _range("delta_a_range_odd", self.delta_a_range_odd))
        set_(self, "delta_a_range_even", _range("delta_a_range_even", self.delta_a_range_even))
        # noise_std stays an array (zeros when not measured) for the range margin;
        # noise_known tells a measured zero from a missing value
        set_(self, "_noise_known", self.noise_std is not None)
        noise = np.zeros(n) if self.noise_std is None else _array("noise_std", self.noise_std, n)
        if np.any(noise < 0):
            raise ConfigError(f"noise_std: values must be >= 0, got {noise.tolist()}")
        wide = max(hi - lo for lo, hi in (self.delta_a_range_odd, self.delta_a_range_even))
        if np.any(noise > wide):  # σ would swamp every signal (and overflow its squares at 1e300)
            raise ConfigError(f"noise_std: {check.short(float(noise.max()))} is wider than the calibrated signal "
                              f"range ({wide:g}): a flat recording's noise is a fraction of it (units?)")
        set_(self, "noise_std", noise)
        if self.weighting not in WEIGHTINGS:
            raise ConfigError(f"weighting: must be one of {', '.join(WEIGHTINGS)}, got {check.short(self.weighting)}")
        if not isinstance(self.sleeve, bool):
            raise ConfigError(f"sleeve: expected true or false, got {check.short(self.sleeve)}")
        if self.sensor is not None and getattr(self.sensor, "n_segments", n) != n:
            raise ConfigError(
                f"sensor.n_segments: expected {n} (the calibration's channels), got {self.sensor.n_segments}"
            )
        set_(self, "strip_residuals", tuple(self.strip_residuals))
        for i, r in enumerate(self.strip_residuals):
            # the strip means' variance is σ²/n_frames: a count that is no count would drop it or blow it up
            if not isinstance(r, StripResidual):
                raise ConfigError(f"strip_residuals[{i}]: expected a StripResidual, got {type(r).__name__}")
            if isinstance(r.n_frames, bool) or not isinstance(r.n_frames, (int, np.integer)) or r.n_frames < 0:
                raise ConfigError(f"strip_residuals[{i}].n_frames: expected an integer >= 1 (0: not recorded), got "
                                  f"{check.short(r.n_frames)}")
        for name in ("fit_delta_a", "fit_shifts_m"):
            value = getattr(self, name)
            if value is not None:
                try:
                    arr = np.asarray(value, dtype=float)
                except (TypeError, ValueError):
                    raise ConfigError(f"{name}: expected a (recordings, {n}) array of numbers, got "
                                      f"{check.short(value)}") from None
                if arr.ndim != 2 or arr.shape[1] != n:
                    raise ConfigError(f"{name}: expected shape (recordings, {n}), got {arr.shape}")
                if not np.all(np.isfinite(arr)):
                    raise ConfigError(f"{name}: values must be finite")
                set_(self, name, arr)
        if self.fit_delta_a is not None and self.fit_shifts_m is not None:
            rows = (self.fit_delta_a.shape[0], self.fit_shifts_m.shape[0])
            if rows[0] != rows[1]:
                raise ConfigError(f"fit_delta_a, fit_shifts_m: expected the same recordings, got {rows[0]} and "
                                  f"{rows[1]} rows")

    # -- the hot path: per-channel arrays precomputed once ---------------------------

    @property
    def n_channels(self) -> int:
        """Number of channels N."""
        return self.offset.size

    @cached_property
    def _channel_coefficients(self) -> np.ndarray:
        odd, _ = parity_masks(self.n_channels)
        return np.where(odd[:, None], self.coefficients_odd, self.coefficients_even)  # (N, n+1)

    @cached_property
    def _channel_range(self):
        odd, _ = parity_masks(self.n_channels)
        lo = np.where(odd, self.delta_a_range_odd[0], self.delta_a_range_even[0])
        hi = np.where(odd, self.delta_a_range_odd[1], self.delta_a_range_even[1])
        margin = RANGE_MARGIN_STD * self.noise_std
        return lo - margin, hi + margin

    @cached_property
    def _coefficient_columns(self) -> tuple:
        # per-channel coefficients of each power, highest first, contiguous (Horner's rule)
        c = self._channel_coefficients
        return tuple(np.ascontiguousarray(c[:, k]) for k in range(self.degree, -1, -1))

    @cached_property
    def _slope_columns(self) -> tuple:
        # the same for the slopes f'(ΔA) (highest power first); () for degree 0
        c = self._channel_coefficients
        return tuple(np.ascontiguousarray(k * c[:, k]) for k in range(self.degree, 0, -1))

    @cached_property
    def _noise_positive(self) -> bool:
        return bool(np.any(self.noise_std > 0))

    @cached_property
    def _linear_slope(self):
        # the linear coefficient per channel: where it is nonzero, and it with 1 elsewhere
        slope = self._channel_coefficients[:, 1] if self.degree > 0 else np.zeros(self.n_channels)
        nonzero = slope != 0
        return nonzero, np.where(nonzero, slope, 1.0)

    def shifts_from_delta(self, delta_a):
        """Shifts S (..., N) [m] from offset-free signals ΔA (..., N) (paper eq. 2).

        Parameters
        ----------
        delta_a : array_like, shape (..., N)
            Signal changes ΔA = A − A0 [signal units].
        """
        cols = self._coefficient_columns
        out = cols[0] + 0.0 * delta_a
        for ck in cols[1:]:
            out = out * delta_a + ck
        return out

    def shifts_m(self, signals):
        """Total relative shifts S (..., N) [m] from raw signals A (..., N) (paper eq. 1–2).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [signal units].
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return self.shifts_from_delta(a - self.offset)

    def shift_error_m(self, shifts_m, *, covariance: bool = False):
        """Model error of the calibration polynomials at shifts ``shifts_m`` [m].

        The polynomials of eq. 2 do not fit the coil response exactly; the misfit
        ``r(S) = f(ΔA) − S`` is a smooth function of the shift that grows with ``|S|``,
        one per parity. It is treated as a random smooth function: zero mean, standard
        deviation ``σ_p(|S|)`` the kernel-smoothed RMS of the fit residuals of the
        channels of parity p (Gaussian kernel, bandwidth a tenth of the largest fitted
        shift; constant beyond the largest fitted shift), and correlation
        ``ρ_ij = (1 − w) c_ij exp(−(S_i − S_j)² / 2ℓ²)`` between channels i ≠ j, with
        ``c_ij = 1`` within a parity and ``c`` between the odd and even polynomials.
        ``ℓ``, ``c`` and the white fraction ``w`` are maximum-likelihood fits of that
        Gaussian process to the residuals scaled by ``σ`` (:func:`_misfit_correlation`).
        So channels whose shifts are close err together, which independent errors miss.
        Without the fitted data (an old calibration file) ``σ`` is the RMS of the
        per-strip residuals for both parities and the channels are independent.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S of the N channels [m].
        covariance : bool
            Return the covariance between the channels instead of ``σ``.

        Returns
        -------
        ndarray, shape (..., N) or (..., N, N)
            ``σ(|S|)`` [m], or the covariance ``σ_i σ_j ρ_ij`` [m²].
        """
        s = np.asarray(shifts_m, dtype=float)
        n = self.n_channels
        if s.ndim == 0 or s.shape[-1] != n:
            raise ArgumentError(f"shifts_m: expected shape (..., {n}), got {s.shape}")
        if covariance:  # the misfit part of the one shift-covariance kernel (no noise, exact coefficients)
            from bendsense.calibration._kernels import shift_covariances

            model = self.error_model(0.0)._replace(coef_cov=np.zeros((1, 1)))
            flat = np.ascontiguousarray(np.broadcast_to(s, s.shape).reshape(-1, n))
            out, noise_var = np.empty((flat.shape[0], n, n)), np.empty((flat.shape[0], n))
            shift_covariances(model, flat, out, noise_var)
            return out.reshape(*s.shape, n)
        model = self._shift_error_table
        odd, _ = self._parity_correlation
        grid = model["grid_m"]
        a = np.abs(s)
        return np.where(odd, np.interp(a, grid, model["sigma_odd_m"]), np.interp(a, grid, model["sigma_even_m"]))

    @cached_property
    def _parity_correlation(self):
        # the odd channels, and c_ij of shift_error_m (error_model.parity_correlation)
        return errors.parity_correlation(self)

    @cached_property
    def _shift_error_table(self) -> dict:
        # the misfit's envelopes σ_p(|S|) and correlation (error_model.shift_error_table)
        return errors.shift_error_table(self)

    def extrapolated_delta(self, delta_a):
        """Per frame: True if any channel's ΔA lies outside the calibrated range.

        Parameters
        ----------
        delta_a : array_like, shape (..., N)
            Signal changes ΔA = A − A0 [signal units].
        """
        lo, hi = self._channel_range
        return np.any((delta_a < lo) | (delta_a > hi), axis=-1)

    def in_range(self, signals):
        """Per frame (...,): True if every channel's ΔA lies in the fitted range.

        The range is the (min, max) of the fitted ΔA of the channel's parity, widened
        by 3 × the channel's flat-recording noise so that a flat, noisy sensor is not
        flagged. Outside it the polynomials extrapolate and the shape is not to be
        trusted; :func:`bendsense.shape.pcc.reconstruct` reports this as ``Shape.extrapolated``.

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [signal units].
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return ~self.extrapolated_delta(a - self.offset)

    def _check_channels(self, a):
        if a.shape[-1:] != (self.n_channels,):
            raise ArgumentError(f"signals: expected {self.n_channels} channels on the last axis, got shape {a.shape}")

    # -- the measurement model: public methods for the estimator ------------------------

    @property
    def noise_known(self) -> bool:
        """Whether the per-channel noise was measured (False for an old file without ``noise_std``)."""
        return self._noise_known

    def noise_std_counts(self) -> np.ndarray:
        """Per-channel signal noise σ_A [counts], the flat recording's frame standard deviation.

        Returns
        -------
        ndarray, shape (N,)
            ``noise_std`` as measured at fit time (a measured zero stays zero).

        Raises
        ------
        ConfigError
            If the calibration does not hold a measured noise (a file without
            ``noise_std``, or a flat recording of a single frame).
        """
        if not self._noise_known:
            raise ConfigError(
                "calibration: noise_std is missing (not measured: an older file or a one-frame flat "
                "recording); refit with `bendsense calibrate` from a flat recording of many frames"
            )
        return self.noise_std

    def shift_slopes(self, signals) -> np.ndarray:
        """Slopes dS/dA of the calibration at raw signals A, per channel (paper eq. 2).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].

        Returns
        -------
        ndarray, shape (..., N)
            ``f_i'(A_i − A0_i)`` [m/count], with f_odd for odd and f_even for even channels.
        """
        a = np.asarray(signals, dtype=float)
        self._check_channels(a)
        return self._slopes_from_delta(a - self.offset)

    def _slopes_from_delta(self, delta_a):
        cols = self._slope_columns
        if not cols:
            return np.zeros(np.shape(delta_a))
        out = cols[0] + 0.0 * delta_a
        for ck in cols[1:]:
            out = out * delta_a + ck
        return out

    def delta_from_shifts(self, shifts_m) -> np.ndarray:
        """Offset-free signals ΔA with ``f_i(ΔA_i) = S_i``: the inverse of :meth:`shifts_from_delta`.

        Per channel, a safeguarded Newton iteration inside the fitted ΔA range of its
        parity widened by its width on both sides, where the root is bracketed (the
        polynomials are monotone there for a sensible calibration); elsewhere plain
        Newton from the linear inverse. Converges to ~1e-13 relative.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S [m].

        Returns
        -------
        ndarray, shape (..., N)
            ΔA [counts]; NaN where no inverse was found (a shift the polynomial
            never reaches, or a non-finite shift).
        """
        s = np.asarray(shifts_m, dtype=float)
        if s.ndim == 0 or s.shape[-1] != self.n_channels:
            raise ArgumentError(f"shifts_m: expected shape (..., {self.n_channels}), got {s.shape}")
        s = np.broadcast_to(s, s.shape).copy()
        lo_r, hi_r = self._channel_range
        width = np.maximum(hi_r - lo_r, 1e-12)
        lo = np.broadcast_to(lo_r - width, s.shape).copy()
        hi = np.broadcast_to(hi_r + width, s.shape).copy()
        g_lo = self.shifts_from_delta(lo) - s
        g_hi = self.shifts_from_delta(hi) - s
        sign = np.where(g_hi >= g_lo, 1.0, -1.0)
        bracketed = (g_lo * sign <= 0) & (g_hi * sign >= 0)
        nonzero, safe = self._linear_slope
        c0 = self._channel_coefficients[:, 0]
        x = np.where(nonzero, (s - c0) / safe, 0.0)  # the linear inverse, kept inside the bracket
        x = np.where(bracketed, np.clip(x, lo, hi), x)
        done = ~np.isfinite(s)
        tol_s = 1e-14 * np.maximum(np.abs(s), 1e-6)  # round-off of the shift [m]
        for _ in range(200):
            g = self.shifts_from_delta(x) - s
            done |= np.abs(g) <= tol_s
            if done.all():
                break
            fp = self._slopes_from_delta(x)
            h = g * sign
            lo = np.where(bracketed & (h < 0), x, lo)
            hi = np.where(bracketed & (h > 0), x, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                new = x - g / fp
            bad = ~np.isfinite(new) | (bracketed & ~((new >= lo) & (new <= hi)))
            new = np.where(bad, np.where(bracketed, 0.5 * (lo + hi), x), new)
            step = np.abs(new - x)
            x = np.where(done, x, new)
            done |= step <= 1e-13 * np.maximum(np.abs(x), width)
        ok = np.abs(self.shifts_from_delta(x) - s) <= 1e-9 * np.maximum(np.abs(s), 1e-9)
        return np.where(ok & np.isfinite(s), x, np.nan)

    def signals_from_shifts(self, shifts_m) -> np.ndarray:
        """Raw signals A = A0 + ΔA that the calibration maps to the shifts S (inverse of :meth:`shifts_m`).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Shifts S [m].

        Returns
        -------
        ndarray, shape (..., N)
            Signals A [counts]; NaN where the polynomial has no inverse
            (:meth:`delta_from_shifts`).
        """
        return self.delta_from_shifts(shifts_m) + self.offset

    def strip_gap_m(self, sensor=None) -> float:
        """The strip gap d the calibration's shifts were labelled with (``S = κ_cal d L_i``) [m].

        The calibration's own sensor snapshot wins: its shifts are ``d_cal`` times an
        angle, whatever gap another config states (docs/theory.md, "What the sensor
        measures"). Without a snapshot (an old file) the ``sensor`` given is used.

        Parameters
        ----------
        sensor : SensorConfig or Config, optional
            The sensor to use when the calibration has no snapshot of its own.

        Raises
        ------
        ConfigError
            Without a snapshot and without ``sensor``; or if ``sensor`` has another
            channel count or other segment lengths than the snapshot.
        """
        sensor = getattr(sensor, "sensor", sensor)
        if sensor is not None:
            if sensor.n_segments != self.n_channels:
                raise ConfigError(
                    f"sensor.n_segments: expected {self.n_channels} (the calibration's channels), "
                    f"got {sensor.n_segments}"
                )
            if self.sensor is not None and not np.allclose(sensor.lengths_m, self.sensor.lengths_m, rtol=1e-9):
                raise ConfigError(
                    f"sensor.segment_lengths_m: {list(sensor.segment_lengths_m)} differ from the calibration's "
                    f"{list(self.sensor.segment_lengths_m)}; the coil positions L_i would be ambiguous"
                )
        if self.sensor is not None:
            return float(self.sensor.strip_gap_m)
        if sensor is None:
            raise ConfigError(
                "calibration: sensor is missing (no snapshot of the sensor it was fitted for); "
                "pass the sensor (config) the calibration was fitted with"
            )
        return float(sensor.strip_gap_m)

    def angles_rad(self, signals, sensor=None) -> np.ndarray:
        """Tangent angle at each receiver coil, ``φ(L_i) = S_i / d`` (DESIGN "What the sensor measures").

        The shift of segment i is ``S_i = d φ(L_i)`` (paper eq. 3–4 read backwards);
        the calibration labelled its strips ``S_i = κ_cal d L_i`` with its own ``d``
        (:meth:`strip_gap_m`), so ``S_i / d`` is ``κ_cal L_i`` on a strip whatever
        the physical gap, and ``κ_cal`` (1/R, or 1/(R + c) with ``sleeve``) is the
        curvature of the receiver strip by the calibration's convention. Tangent
        angles of parallel curves agree at corresponding points, so no sleeve term
        enters here; docs/theory.md derives this and what a wrong convention costs.

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].
        sensor : SensorConfig or Config, optional
            Checked against the calibration's sensor snapshot; gives ``d`` for an
            old calibration without a snapshot.

        Returns
        -------
        ndarray, shape (..., N)
            φ(L_i) relative to the base [rad], L_i the cumulative segment lengths.
        """
        return self.shifts_m(signals) / self.strip_gap_m(sensor)

    def error_model(self, noise_std_counts=None):
        """The errors of this calibration's shifts as the compiled kernels take them.

        Parameters
        ----------
        noise_std_counts : array_like (N,), optional
            Signal noise per channel [counts]; default the flat recording's
            (``noise_std``, zero where unknown).

        Returns
        -------
        bendsense.calibration.shift_errors.ShiftErrorModel
            The channels' polynomials, the noise, the misfit envelopes with their
            correlation (:meth:`shift_error_m`) and the coefficients' and offsets'
            covariance (:attr:`coefficient_covariance`; zeros when the file lacks what
            it needs). :func:`bendsense.calibration._kernels.shift_covariance` evaluates it.
        """
        return errors.error_model(self, noise_std_counts)

    def angle_covariance(self, signals, sensor=None) -> AngleCovariance:
        """Covariance of the measured angles :meth:`angles_rad`, by source (docs/theory.md).

        - ``noise``: the frame's signal noise through the slopes,
          ``diag(f_i'(ΔA_i)² σ_i²) / d²``, σ from :meth:`noise_std_counts`;
        - ``calibration``: the calibration's own error, the same for every frame
          that sees the same signals: the uncertainty of the coefficients and offsets
          (:attr:`coefficient_covariance`; the odd channels share f_odd's
          coefficients and so err together) through ``∂S_i/∂(a, b, A0)``, plus the
          polynomials' misfit from the fit residuals (:meth:`shift_error_m`).

        Parameters
        ----------
        signals : array_like, shape (..., N)
            Raw signals A [counts].
        sensor : SensorConfig or Config, optional
            As in :meth:`angles_rad`.

        Returns
        -------
        AngleCovariance
            ``noise`` and ``calibration``, each (..., N, N) [rad²]; ``total`` their sum.

        Raises
        ------
        ConfigError
            Naming what the calibration lacks (``noise_std``, the fitted data
            ``fit_delta_a``/``fit_shifts_m``, frame counts) — never a silent zero.
        """
        return errors.angle_covariance(self, signals, sensor)

    def _fit_operator(self, mask):
        """The fit's least-squares operator of one parity: ``c = op @ y[keep]`` (as :func:`polyfit_shift`)."""
        return errors.fit_operator(self, mask)

    @cached_property
    def coefficient_covariance(self) -> np.ndarray:
        """Joint covariance of ``(a_0..a_n, b_0..b_n, A0_1..A0_N)`` from the fit's data noise.

        The strip means and the offsets are averages of noisy frames: strip k's
        ΔA has the error ``ε_k − δA0`` (``Var ε = σ²/frames_k``, ``Var δA0 =
        σ²/flat_frames``, σ = :meth:`noise_std_counts`), while its shift label is
        exact. Moving a point's ΔA by δx moves its residual like a shift error
        ``−f'(x) δx``, so the coefficients, linear in the labels, move by
        ``δc = −A diag(f') δx`` with ``A`` the fit's (weighted) least-squares
        operator. The offsets enter every later frame as well, which makes them part
        of the vector. The odd and even blocks are independent (no channel is in
        both); within a block all channels of that parity share the error.

        Returns
        -------
        ndarray, shape (2 (n + 1) + N, 2 (n + 1) + N)
            [m²/count^(j+k)] for the coefficient entries, [counts²] for the offsets.

        Raises
        ------
        ConfigError
            If the fitted data, the noise or the frame counts are not stored.
        """
        return errors.coefficient_covariance(self)

    # -- fitting (bendsense.calibration.fit) ---------------------------------------------

    @classmethod
    @one_thread
    def fit(
        cls,
        manifest_path: str | os.PathLike,
        sensor=None,
        degree: int | str = 3,
        weighting: str = "none",
        sleeve: bool | None = None,
        finger=None,
    ) -> Calibration:
        """Fit a calibration from a manifest of session CSV recordings (DESIGN.md section 3).

        Parameters
        ----------
        manifest_path : path
            Calibration manifest YAML; recording paths are relative to it.
        sensor : SensorConfig or Config, optional
            ``None``: the paper's sensor (``bendsense.load_config().sensor``).
        degree : int or "auto"
            Polynomial degree 1..5, or ``"auto"`` for leave-one-strip-out CV.
        weighting : str
            ``"none"`` (the paper's) or ``"shift"``.
        sleeve : bool, optional
            Override ``sensor.calibration_adds_sleeve`` (κ_cal = 1/(R + c)).
        finger : Finger, optional
            A gripper's finger (``gripper.finger(name)``): the recordings are the whole
            board's; its channels are fitted, with its sensor (``sensor`` must be None),
            and the calibration records its name (``finger``).

        Raises
        ------
        ConfigError
            For a bad manifest, a missing recording or a channel count that does not
            match the sensor; the message names the field and file.
        SessionError
            For a malformed recording (line and column in the message).
        """
        manifest_path = check.path("manifest_path", manifest_path)
        if finger is None:
            return cls.from_data(**read_recordings(manifest_path, sensor), degree=degree, weighting=weighting,
                                 sleeve=sleeve)
        from bendsense.config import Finger

        check.instance("finger", finger, Finger, "gripper.finger(name)")
        if sensor is not None:
            raise ConfigError("sensor: give the finger or the sensor, not both (a finger's sensor is its own)")
        data = read_recordings(manifest_path, finger.config.sensor, channels=finger.channels)
        return cls(**fit_fields(**data, degree=degree, weighting=weighting, sleeve=sleeve), finger=finger.name)

    @classmethod
    def from_data(
        cls,
        flat_signals,
        strip_signals_list,
        radii_m,
        sensor=None,
        *,
        degree: int | str = 3,
        weighting: str = "none",
        sleeve: bool | None = None,
        recordings=None,
        meta: dict | None = None,
    ) -> Calibration:
        """Fit a calibration from in-memory recordings.

        Parameters
        ----------
        flat_signals : array_like, shape (frames, N)
            Recording of the flat sensor.
        strip_signals_list : sequence of array_like, each (frames_k, N)
            One recording per calibration strip.
        radii_m : sequence of float
            Strip radii R [m].
        sensor : SensorConfig or Config, optional
            ``None``: the paper's sensor.
        degree, weighting, sleeve
            As in :meth:`fit`.
        recordings : sequence of str, optional
            Names of the strip recordings, for the report.
        meta : dict, optional
            Extra metadata to store.
        """
        return cls(**fit_fields(flat_signals, strip_signals_list, radii_m, sensor, degree=degree, weighting=weighting,
                                sleeve=sleeve, recordings=recordings, meta=meta))

    # -- files (bendsense.calibration.io) -------------------------------------------------

    def to_dict(self) -> dict:
        """Return the calibration YAML layout (plain lists, floats and strings)."""
        return io.to_dict(self)

    def save(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        """Write the calibration YAML atomically (``format: bendsense-calibration``, ``version: 1``).

        ``overwrite=False`` refuses an existing file (:class:`~bendsense.errors.OutputExistsError`).

        Parameters
        ----------
        path : str or path-like
            Output YAML file.
        overwrite : bool, default True
            Replace an existing file; False refuses one.
        """
        io.save(self, check.path("path", path), overwrite=overwrite)

    @classmethod
    def from_dict(cls, data: Any) -> Calibration:
        """Build a calibration from its YAML layout; raises `ConfigError` naming the field.

        Parameters
        ----------
        data : dict
            The calibration YAML's layout, as read by ``yaml.safe_load``.
        """
        return cls(**io.fields_from_dict(data))

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        """Read a calibration YAML written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
            Calibration YAML file.

        Raises
        ------
        ConfigError
            If the file cannot be read, is not a bendsense calibration, or a field is
            invalid; the message names the file and the field.
        """
        return read_yaml(path, "calibration", cls.from_dict)

    # -- reporting ----------------------------------------------------------------------

    def report(self) -> str:
        """Summarise as text: degree, coefficients, ranges, per-strip residuals, CV table."""
        return report.report(self)

    def plot(self, ax=None):
        """Plot the fitted polynomials over the data (S [mm] vs ΔA) and the residuals.

        With ``ax=None`` a figure with two panels (fit, residuals) is created and both
        axes are returned; with an ``ax`` only the fit is drawn on it.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes for the fit; None makes a figure with fit and residual panels.
        """
        return report.plot(self, ax)
