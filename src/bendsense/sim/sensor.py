"""The virtual sensor: shape → strip shifts → coil signals → ADC counts.

The shift of receiver ``i`` against the transmitter strip is ``S_i = d φ(L_i)``
(paper eq. 2–4, Fig. 4(a)): ``d`` is the strip gap, ``L_i`` the cumulative segment
length and ``φ`` the tangent angle relative to the base, where the strips are pinned.
With PCC segments this is ``S_i = d Σ_{j≤i} κ_j l_j``. Positive ``S`` moves the
receiver toward the tip; the signal of odd receivers (1-based) then falls and that of
even receivers rises (paper Fig. 2(c)).

:class:`VirtualSensor` turns shifts into the readings of the paper's hardware: a lock-in
amplitude per channel (:class:`~bendsense.sim.coils.CoilArrayModel`) times a gain, plus a
per-channel offset ``A0_i`` (paper eq. 1) and Gaussian noise, quantised by an ADC with
saturation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from bendsense.calibration import strip_shifts
from bendsense.errors import ConfigError
from bendsense.sim.coils import CoilArrayModel

__all__ = [
    "shifts_from_angles",
    "shifts_from_curvatures",
    "shifts_from_shape",
    "calibration_shifts",
    "SensorReading",
    "VirtualSensor",
]


def shifts_from_angles(angle_at_segment_ends_rad, strip_gap_m):
    """Total relative shifts from the tangent angles at the segment ends (paper eq. 4).

    Parameters
    ----------
    angle_at_segment_ends_rad : array_like, shape (..., N)
        Tangent angle φ(L_i) at the end of each segment, relative to the base [rad].
    strip_gap_m : float
        Strip gap d [m].

    Returns
    -------
    ndarray, shape (..., N)
        Shifts S_i = d φ(L_i) [m].
    """
    d = _positive("strip_gap_m", strip_gap_m)
    return d * np.asarray(angle_at_segment_ends_rad, dtype=float)


def shifts_from_curvatures(curvature_per_m, lengths_m, strip_gap_m):
    """Total relative shifts of PCC segments, S_i = d Σ_{j≤i} κ_j l_j (paper eq. 3–4).

    Parameters
    ----------
    curvature_per_m : array_like, shape (..., N)
        Segment curvatures κ_j [1/m].
    lengths_m : array_like, shape (N,)
        Segment lengths l_j [m].
    strip_gap_m : float
        Strip gap d [m].

    Returns
    -------
    ndarray, shape (..., N)
        Shifts S_i [m].
    """
    kappa = np.asarray(curvature_per_m, dtype=float)
    lengths = _lengths(lengths_m)
    if kappa.ndim == 0 or kappa.shape[-1] != lengths.size:
        raise ConfigError(f"curvature_per_m: expected shape (..., {lengths.size}), got {kappa.shape}")
    return shifts_from_angles(np.cumsum(kappa * lengths, axis=-1), strip_gap_m)


def shifts_from_shape(s_m, angle_rad, lengths_m, strip_gap_m):
    """Total relative shifts from a sampled continuous shape φ(s), e.g. a beam solution.

    φ is interpolated at the cumulative lengths ``L_i`` by a cubic spline along the last
    axis and taken relative to φ(0), since the strips are pinned at the base.

    Parameters
    ----------
    s_m : array_like, shape (M,)
        Increasing arc lengths, from ``s = 0`` (the base) [m], e.g. ``BeamSolution.s_m``.
    angle_rad : array_like, shape (..., M)
        Tangent angle φ(s) [rad], e.g. ``BeamSolution.angle_rad``.
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m]; their total must not exceed ``s_m[-1]``.
    strip_gap_m : float
        Strip gap d [m].

    Returns
    -------
    ndarray, shape (..., N)
        Shifts S_i = d (φ(L_i) − φ(0)) [m].
    """
    s = np.asarray(s_m, dtype=float)
    phi = np.asarray(angle_rad, dtype=float)
    if s.ndim != 1 or s.size < 2 or not np.all(np.diff(s) > 0):
        raise ConfigError(f"s_m: expected an increasing 1-D array of at least 2 arc lengths, got shape {s.shape}")
    if phi.ndim == 0 or phi.shape[-1] != s.size:
        raise ConfigError(f"angle_rad: expected shape (..., {s.size}) to match s_m, got {phi.shape}")
    ends = np.cumsum(_lengths(lengths_m))
    tol = 1e-9 * max(1.0, abs(s[-1]))
    if s[0] > tol or ends[-1] > s[-1] + tol:
        raise ConfigError(f"s_m: must cover the sensor from 0 to {ends[-1]:.6g} m, got [{s[0]:.6g}, {s[-1]:.6g}] m")
    at = np.clip(np.concatenate([[0.0], ends]), s[0], s[-1])
    if s.size == 2:
        values = phi[..., :1] + (phi[..., 1:] - phi[..., :1]) * (at - s[0]) / (s[1] - s[0])
    else:
        values = CubicSpline(s, phi, axis=-1)(at)
    return shifts_from_angles(values[..., 1:] - values[..., :1], strip_gap_m)


def calibration_shifts(sensor, radius_m):
    """Shifts on a calibration strip of radius R: S_i = κ_cal d L_i (DESIGN section 2).

    ``κ_cal = 1/R``, or ``1/(R + c)`` if ``sensor.calibration_adds_sleeve``; the shifts
    are those the calibration fits to (:func:`bendsense.calibration.strip_shifts`).

    Parameters
    ----------
    sensor : SensorConfig or Config
        The sensor.
    radius_m : array_like
        Strip radii R [m], > 0.

    Returns
    -------
    ndarray, shape (*radius_m.shape, N)
        Shifts [m].
    """
    sensor = getattr(sensor, "sensor", sensor)
    radius = np.asarray(radius_m, dtype=float)
    if not np.all(radius > 0):
        raise ConfigError(f"radius_m: must be > 0, got {radius_m!r}")
    if sensor.calibration_adds_sleeve:
        radius = radius + sensor.sleeve_thickness_m
    return strip_shifts(1.0 / radius, sensor.lengths_m, sensor.strip_gap_m)


def _positive(name, value) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: must be > 0, got {value!r}")
    return value


def _lengths(lengths_m) -> np.ndarray:
    lengths = np.asarray(lengths_m, dtype=float)
    if lengths.ndim != 1 or lengths.size == 0 or not np.all(lengths > 0):
        raise ConfigError(f"lengths_m: expected a 1-D array of positive segment lengths, got {lengths_m!r}")
    return lengths


@dataclass(frozen=True, eq=False)
class SensorReading:
    """ADC readings of the virtual sensor.

    Attributes
    ----------
    counts : ndarray of int, shape (..., N)
        Raw ADC counts in ``[0, 2**adc_bits − 1]``.
    saturated : ndarray of bool, shape (..., N)
        True where the value was clipped at 0 or at full scale.
    """

    counts: np.ndarray
    saturated: np.ndarray

    @property
    def frame_saturated(self) -> np.ndarray:
        """True for frames with any saturated channel (the wire's status bit 1), shape (...)."""
        return self.saturated.any(axis=-1)


@dataclass(frozen=True, kw_only=True, eq=False)
class VirtualSensor:
    """The paper's sensor hardware as a function of the strip shifts.

    ``counts_i = quantise(A0_i + g_i u_i(S_i) + noise)``, with ``u_i`` the normalized
    in-phase lock-in amplitude (:meth:`CoilArrayModel.signal`), ``g_i`` the gain,
    ``A0_i`` the flat-state offset (paper eq. 1) and Gaussian noise; the ADC rounds and
    clips to ``[0, 2**adc_bits − 1]``. Build with :meth:`from_config`.

    Attributes
    ----------
    model : CoilArrayModel
        Coil physics.
    lengths_m : tuple of float
        Segment lengths l_i [m].
    strip_gap_m : float
        Strip gap d [m].
    gain_counts : ndarray, shape (N,)
        Counts per unit normalized signal u.
    offset_counts : ndarray, shape (N,)
        Offsets A0_i [counts] (without the coil array's own flat-state signal).
    noise_counts : float
        Standard deviation of the Gaussian noise [counts].
    adc_bits : int
        ADC resolution.
    vref_v : float
        ADC reference voltage [V] (full scale).
    seed : int or None
        Seed the offsets and the noise stream were drawn from.
    rng : numpy.random.Generator
        The noise stream, advanced by every :meth:`measure` without an explicit ``rng``.
    """

    model: CoilArrayModel
    lengths_m: tuple
    strip_gap_m: float
    gain_counts: np.ndarray
    offset_counts: np.ndarray
    noise_counts: float
    adc_bits: int = 12
    vref_v: float = 3.3
    seed: int | None = None
    rng: np.random.Generator = field(default=None, repr=False)

    def __post_init__(self):
        n = self.model.n_receivers
        object.__setattr__(self, "gain_counts", _per_channel("gain_counts", self.gain_counts, n))
        object.__setattr__(self, "offset_counts", _per_channel("offset_counts", self.offset_counts, n))
        if self.rng is None:
            # the same noise stream as from_config draws for this seed
            stream = np.random.SeedSequence(self.seed).spawn(2)[1]
            object.__setattr__(self, "rng", np.random.default_rng(stream))

    @classmethod
    def from_config(
        cls,
        sensor_config,
        *,
        gain=None,
        offset_counts=None,
        offset_spread: float = 0.03,
        gain_spread: float = 0.0,
        noise_counts: float = 1.5,
        adc_bits: int = 12,
        vref_v: float = 3.3,
        seed: int | None = 0,
        model: CoilArrayModel | None = None,
    ) -> VirtualSensor:
        """Build a virtual sensor for a :class:`~bendsense.config.SensorConfig` (or a ``Config``).

        Parameters
        ----------
        sensor_config : SensorConfig or Config
            The sensor geometry.
        gain : float or array_like of shape (N,), optional
            Counts per unit normalized signal. Default: 90 % of the headroom between the
            offsets and the ADC rails, less 5 noise σ, divided by the largest |u| any
            shift can produce (the receiver right above a transmitter), so that no shift
            saturates and the tightest calibration strip (R = 40 mm, |S| ≤ 3.3 mm) swings
            the channels over about 80 % of the range.
        offset_counts : float or array_like of shape (N,), optional
            Offsets A0_i [counts]. Default: mid-scale times ``1 + offset_spread · U(−1, 1)``
            per channel.
        offset_spread, gain_spread : float
            Relative per-channel spread of the random offsets and gains.
        noise_counts : float
            Noise standard deviation [counts].
        adc_bits : int
            ADC resolution (paper: the STM32F407's 12-bit ADC).
        vref_v : float
            ADC reference voltage [V].
        seed : int or None
            Seed of the per-channel draws and of the noise stream.
        model : CoilArrayModel, optional
            Coil physics; default ``CoilArrayModel.from_config(sensor_config)``.
        """
        sensor = getattr(sensor_config, "sensor", sensor_config)
        n = sensor.n_segments
        if not isinstance(adc_bits, int) or not 1 <= adc_bits <= 16:
            raise ConfigError(f"adc_bits: must be an integer in 1..16, got {adc_bits!r}")
        noise_counts = float(noise_counts)
        if not (math.isfinite(noise_counts) and noise_counts >= 0):
            raise ConfigError(f"noise_counts: must be >= 0, got {noise_counts!r}")
        for name, value in (("offset_spread", offset_spread), ("gain_spread", gain_spread)):
            if not (math.isfinite(value) and 0 <= value < 1):
                raise ConfigError(f"{name}: must be in [0, 1), got {value!r}")
        model = CoilArrayModel.from_config(sensor) if model is None else model
        if model.n_receivers != n:
            raise ConfigError(f"model: expected {n} receivers to match the sensor, got {model.n_receivers}")
        setup_rng, noise_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
        full = 2**adc_bits - 1
        mid = 0.5 * (full + 1)
        if offset_counts is None:
            offsets = mid * (1.0 + offset_spread * setup_rng.uniform(-1.0, 1.0, n))
        else:
            offsets = _per_channel("offset_counts", offset_counts, n)
        spread = 1.0 + gain_spread * setup_rng.uniform(-1.0, 1.0, n)
        if gain is None:
            peak = np.abs(model.signal(np.full((2, n), 0.5 * model.pitch_m) * [[1.0], [-1.0]])).max()
            headroom = np.minimum(offsets, full - offsets).min() - 5.0 * noise_counts - 1.0
            if headroom <= 0:
                raise ConfigError(f"offset_counts: leave no headroom below {full} counts for the signal")
            gains = 0.9 * headroom / (peak * spread.max()) * spread
        else:
            gains = _per_channel("gain", gain, n) * spread
        return cls(
            model=model,
            lengths_m=sensor.segment_lengths_m,
            strip_gap_m=sensor.strip_gap_m,
            gain_counts=gains,
            offset_counts=offsets,
            noise_counts=noise_counts,
            adc_bits=adc_bits,
            vref_v=float(vref_v),
            seed=seed,
            rng=noise_rng,
        )

    @property
    def n_channels(self) -> int:
        """Number of channels N."""
        return self.model.n_receivers

    @property
    def full_scale_counts(self) -> int:
        """Largest ADC value, ``2**adc_bits − 1``."""
        return 2**self.adc_bits - 1

    def lockin(self, shifts_m) -> np.ndarray:
        """Evaluate the normalized in-phase lock-in amplitudes u_i(S_i) [-], shape (..., N).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total shifts S [m].
        """
        return self.model.signal(shifts_m)

    def signal(self, shifts_m) -> np.ndarray:
        """Noise-free, unquantised readings ``A0_i + g_i u_i(S_i)`` [counts], shape (..., N).

        The flat-sensor value of this (``S = 0``) is the calibration offset A0 of paper
        eq. 1, which includes the small flat-state signal of the end receivers.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total shifts S [m].
        """
        return self.offset_counts + self.gain_counts * self.model.signal(shifts_m)

    def quantize(self, values_counts) -> SensorReading:
        """Round to integer counts and clip to the ADC range, flagging clipped values.

        Parameters
        ----------
        values_counts : array_like, shape (..., N)
            Readings [counts], not yet rounded.
        """
        raw = np.rint(np.asarray(values_counts, dtype=float))
        saturated = (raw < 0) | (raw > self.full_scale_counts)
        dtype = np.uint16 if self.adc_bits <= 16 else np.int64
        return SensorReading(counts=np.clip(raw, 0, self.full_scale_counts).astype(dtype), saturated=saturated)

    def measure(self, shifts_m, *, rng: np.random.Generator | None = None) -> SensorReading:
        """ADC counts for shifts, with noise.

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total relative shifts S_i [m].
        rng : numpy.random.Generator, optional
            Noise source; default the sensor's own stream (:attr:`rng`).

        Returns
        -------
        SensorReading
            ``counts`` and ``saturated``, shape (..., N).
        """
        values = self.signal(shifts_m)
        if self.noise_counts > 0:
            values = values + (self.rng if rng is None else rng).normal(0.0, self.noise_counts, values.shape)
        return self.quantize(values)

    def shifts_from_curvatures(self, curvature_per_m) -> np.ndarray:
        """Shifts S_i [m] of PCC curvatures κ (..., N) [1/m] on this sensor.

        Parameters
        ----------
        curvature_per_m : array_like, shape (..., N)
            Segment curvatures κ [1/m].
        """
        return shifts_from_curvatures(curvature_per_m, self.lengths_m, self.strip_gap_m)

    def shifts_from_shape(self, s_m, angle_rad) -> np.ndarray:
        """Shifts S_i [m] of a sampled shape φ(s), e.g. a ``BeamSolution``'s ``s_m``, ``angle_rad``.

        Parameters
        ----------
        s_m : array_like, shape (M,)
            Arc lengths of the samples [m].
        angle_rad : array_like, shape (..., M)
            Tangent angles φ(s) [rad].
        """
        return shifts_from_shape(s_m, angle_rad, self.lengths_m, self.strip_gap_m)

    def volts(self, counts) -> np.ndarray:
        """ADC counts as volts at the ADC input [V].

        Parameters
        ----------
        counts : array_like
            ADC counts.
        """
        return np.asarray(counts, dtype=float) * self.vref_v / 2**self.adc_bits


def _per_channel(name: str, value, n: int) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: expected a finite number or {n} finite values, got {value!r}")
    return arr.copy()
