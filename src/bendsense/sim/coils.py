"""Coil physics of the inductive curvature sensor: mutual inductances and receiver signals.

The sensor (paper section II, Fig. 2) has ``N`` receiver coils on one strip and ``N + 1``
transmitter coils of alternating polarity on a second strip a distance ``d`` below it.
Receiver ``i`` (0-based here) sits at ``x_i = i p`` above the midpoint of transmitters
``i`` and ``i + 1`` at ``X_j = (j - 1/2) p`` (pitch ``p``). Bending slides the receiver
strip along the transmitter strip by the shift ``S_i`` (paper eq. 2–4); the in-phase
lock-in amplitude of receiver ``i`` is then

    V_i = ω I Σ_j (−1)^j M_coil(x_i + S_i − X_j),

with ``M_coil(ρ)`` the mutual inductance of two parallel coaxial-axis coils at lateral
offset ``ρ``. Flat (``S = 0``) the two nearest transmitters cancel; the odd and even
receivers (1-based) have opposite monotonic trends in ``S`` (paper Fig. 2(c)).

Coil model
----------
Each flat FPCB spiral is a set of concentric circular filament loops
(:class:`CoilGeometry`): by default 20 turns split over two layers 0.1 mm apart,
10 loops per layer with radii evenly spaced from 1.2 mm to the 3 mm outer radius.

Filament loops
--------------
The mutual inductance of two parallel loops uses the vector potential of a loop written
with Maxwell's Landen-transformed modulus, ``M_coax = μ0 (r1 + r2) [K(γ) − E(γ)]``
with ``r1, r2`` the largest and smallest wire-to-wire distances and
``γ = (r1 − r2)/(r1 + r2)``. With ``K − E = γ² D(γ²)`` this gives the potential per unit
radius ``A_φ / (I r) = 8 μ0 a² D(γ²) / (π (r1 + r2)³)``, free of the ``0/0`` of the usual
``(2/k − k) K − (2/k) E`` form both on the axis and in the far field, and an even
analytic function of ``r``. Integrating it along the second loop (Neumann's formula
with one angle done analytically) leaves a smooth periodic integral over one angle,
for which the trapezoidal rule converges exponentially.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.constants import mu_0
from scipy.interpolate import CubicSpline
from scipy.special import ellipe, ellipk

from bendsense.errors import ConfigError

__all__ = [
    "MU0_H_PER_M",
    "coaxial_loop_mutual_inductance",
    "loop_mutual_inductance",
    "CoilGeometry",
    "coil_mutual_inductance",
    "CoilArrayModel",
]

MU0_H_PER_M = mu_0
"""Vacuum permeability μ0 [H/m] (CODATA, as in :mod:`scipy.constants`)."""

# Below this parameter m = γ² the difference K − E is taken from its power series:
# K and E themselves are accurate to ~1e-16 absolute, so (K − E)/m would lose digits.
_SERIES_BELOW = 1e-2
_SERIES_TERMS = 12


def _series_coefficients(n_terms: int) -> np.ndarray:
    # (K − E)/m = (π/2) Σ_{n≥1} c_n² · 2n/(2n − 1) · m^(n−1),  c_n = (2n)! / (4^n n!²)
    out = []
    c = 1.0
    for n in range(1, n_terms + 1):
        c *= (2 * n - 1) / (2 * n)
        out.append(0.5 * math.pi * c * c * 2 * n / (2 * n - 1))
    return np.array(out)


_D_SERIES = _series_coefficients(_SERIES_TERMS)


def _k_minus_e_over_m(m: np.ndarray) -> np.ndarray:
    """(K(m) − E(m)) / m for parameter 0 <= m < 1, accurate to ~1e-15 relative."""
    m = np.asarray(m, dtype=float)
    small = m < _SERIES_BELOW
    out = np.empty_like(m)
    ms = m[small]
    acc = np.full_like(ms, _D_SERIES[-1])
    for c in _D_SERIES[-2::-1]:
        acc = acc * ms + c
    out[small] = acc
    ml = m[~small]
    out[~small] = (ellipk(ml) - ellipe(ml)) / ml
    return out


def _potential_per_radius(a: np.ndarray, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """A_φ / (I r) of a loop of radius ``a`` at radius ``r``, height ``z`` [H/m²]."""
    s = np.sqrt((a + r) ** 2 + z * z) + np.sqrt((a - r) ** 2 + z * z)  # r1 + r2
    gamma = 4.0 * a * r / (s * s)  # (r1 − r2)/(r1 + r2) without cancellation
    return 8.0 * MU0_H_PER_M * a * a * _k_minus_e_over_m(gamma * gamma) / (math.pi * s**3)


def _default_n_quad(max_radius: float, min_z: float) -> int:
    # the integrand's nearest complex singularity is ~ z / b away from the real ψ axis
    if not min_z > 0:
        return 4096
    return int(min(4096, max(64, math.ceil(16.0 * max_radius / min_z))))


def coaxial_loop_mutual_inductance(radius1_m, radius2_m, z_m):
    """Mutual inductance of two coaxial circular filament loops (Maxwell).

    Uses Maxwell's form ``M = μ0 (r1 + r2) [K(γ) − E(γ)]``, ``γ = (r1 − r2)/(r1 + r2)``,
    with ``r1, r2`` the largest and smallest distances between the two circles; it is
    the Landen transform of ``μ0 √(ab) [(2/k − k) K(k) − (2/k) E(k)]`` and stays accurate
    from touching loops to the dipole far field.

    Parameters
    ----------
    radius1_m, radius2_m : array_like
        Loop radii a, b [m], > 0.
    z_m : array_like
        Axial separation [m].

    Returns
    -------
    ndarray
        Mutual inductance [H], broadcast over the inputs.
    """
    a, b, z = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (radius1_m, radius2_m, z_m)))
    return 2.0 * math.pi * b * b * _potential_per_radius(a, b, z)


def loop_mutual_inductance(radius1_m, radius2_m, z_m, rho_m=0.0, *, n_quad: int | None = None):
    """Mutual inductance of two parallel circular filament loops with lateral offset.

    Neumann's double line integral with the angle around the first loop done in closed
    form (its vector potential) and the angle ψ around the second loop by the
    trapezoidal rule on ``[0, π]`` (the integrand is even, smooth and periodic):

        M = 2 ∫₀^π b (b + ρ cos ψ) · A_φ(r(ψ), z) / (I r(ψ)) dψ,
        r² = ρ² + b² + 2 ρ b cos ψ.

    Parameters
    ----------
    radius1_m, radius2_m : array_like
        Loop radii a (source) and b [m], > 0. M is symmetric in them (reciprocity).
    z_m : array_like
        Axial separation of the loop planes [m]; the loops must not intersect.
    rho_m : array_like, optional
        Lateral offset of the loop axes [m]; M is even in ``rho_m``.
    n_quad : int, optional
        Number of trapezoidal intervals on ``[0, π]``. The error falls like
        ``exp(−2 n z / b)``; the default, ``max(64, 16 max(a, b) / min|z|)`` (at most
        4096), gives ~1e-13 relative accuracy for any loops that do not nearly touch.

    Returns
    -------
    ndarray
        Mutual inductance [H], broadcast over the inputs.
    """
    a, b, z, rho = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (radius1_m, radius2_m, z_m, rho_m)))
    if n_quad is None:
        n_quad = _default_n_quad(max(a.max(initial=0.0), b.max(initial=0.0)), np.abs(z).min(initial=np.inf))
    if int(n_quad) < 2:
        raise ConfigError(f"n_quad: must be >= 2, got {n_quad!r}")
    psi = np.linspace(0.0, math.pi, int(n_quad) + 1)
    weights = np.full(psi.shape, math.pi / n_quad)
    weights[[0, -1]] *= 0.5
    a_, b_, z_, rho_ = (v[..., None] for v in (a, b, z, rho))
    cos_psi = np.cos(psi)
    r = np.sqrt(np.maximum(rho_ * rho_ + b_ * b_ + 2.0 * rho_ * b_ * cos_psi, 0.0))
    integrand = b_ * (b_ + rho_ * cos_psi) * _potential_per_radius(a_, r, z_)
    return 2.0 * (integrand @ weights)


@dataclass(frozen=True, kw_only=True)
class CoilGeometry:
    """A flat multi-turn coil as concentric circular filament loops.

    Parameters
    ----------
    radii_m : tuple of float
        Radius of each loop (turn) [m].
    z_m : tuple of float
        Axial position of each loop relative to the strip's mid-plane [m].
    """

    radii_m: tuple
    z_m: tuple

    def __post_init__(self):
        radii = tuple(float(r) for r in self.radii_m)
        zs = tuple(float(z) for z in self.z_m)
        if not radii:
            raise ConfigError("coil.radii_m: expected at least one loop, got none")
        if len(zs) != len(radii):
            raise ConfigError(f"coil.z_m: expected {len(radii)} values (one per loop), got {len(zs)}")
        for i, r in enumerate(radii):
            if not (math.isfinite(r) and r > 0):
                raise ConfigError(f"coil.radii_m[{i}]: must be > 0, got {r!r}")
        for i, z in enumerate(zs):
            if not math.isfinite(z):
                raise ConfigError(f"coil.z_m[{i}]: must be finite, got {z!r}")
        object.__setattr__(self, "radii_m", radii)
        object.__setattr__(self, "z_m", zs)

    @classmethod
    def flat_spiral(
        cls,
        *,
        outer_radius_m: float = 0.003,
        turns: int = 20,
        inner_radius_m: float | None = None,
        layers: int = 2,
        layer_spacing_m: float = 1e-4,
    ) -> CoilGeometry:
        """Build a PCB spiral: ``turns`` loops over ``layers`` layers, radii evenly spaced.

        Parameters
        ----------
        outer_radius_m : float
            Outer radius [m] (paper: 3 mm, for a 6 mm coil diameter).
        turns : int
            Total number of turns (paper: 20), divided evenly over the layers.
        inner_radius_m : float, optional
            Radius of the innermost turn [m]; default 0.4 × ``outer_radius_m``.
        layers : int
            Number of copper layers (paper: two FPCB layers).
        layer_spacing_m : float
            Distance between adjacent layers [m]; the layers are centred on the strip.
        """
        if not isinstance(turns, int) or turns < 1:
            raise ConfigError(f"coil.turns: must be a positive integer, got {turns!r}")
        if not isinstance(layers, int) or layers < 1 or turns % layers:
            raise ConfigError(f"coil.layers: must be a positive divisor of turns={turns}, got {layers!r}")
        if inner_radius_m is None:
            inner_radius_m = 0.4 * outer_radius_m
        if not 0 < inner_radius_m <= outer_radius_m:
            raise ConfigError(
                f"coil.inner_radius_m: must be in (0, outer_radius_m={outer_radius_m}], got {inner_radius_m!r}"
            )
        per_layer = turns // layers
        radii = np.linspace(inner_radius_m, outer_radius_m, per_layer) if per_layer > 1 else np.array([outer_radius_m])
        offsets = (np.arange(layers) - 0.5 * (layers - 1)) * layer_spacing_m
        return cls(radii_m=tuple(np.tile(radii, layers)), z_m=tuple(np.repeat(offsets, per_layer)))

    @classmethod
    def from_sensor_config(cls, sensor, **kwargs) -> CoilGeometry:
        """Build the paper's spiral model of a :class:`~bendsense.config.SensorConfig`'s coils.

        Parameters
        ----------
        sensor : SensorConfig or Config
            The sensor.
        **kwargs
            Passed to :meth:`flat_spiral` (e.g. ``layers``).
        """
        turns = sensor.coil_turns
        kwargs.setdefault("layers", 2 if turns % 2 == 0 else 1)
        return cls.flat_spiral(outer_radius_m=0.5 * sensor.coil_diameter_m, turns=turns, **kwargs)

    @property
    def n_turns(self) -> int:
        """Number of loops."""
        return len(self.radii_m)


def coil_mutual_inductance(coil_a: CoilGeometry, coil_b: CoilGeometry, gap_m, rho_m, *, n_quad: int | None = None):
    """Mutual inductance of two parallel multi-turn coils: the sum over all loop pairs.

    Parameters
    ----------
    coil_a, coil_b : CoilGeometry
        The coils; ``coil_b`` lies ``gap_m`` above ``coil_a``.
    gap_m : float
        Distance between the strips' mid-planes [m] (paper: d).
    rho_m : array_like
        Lateral offsets of the coil axes [m].
    n_quad : int, optional
        Trapezoidal intervals, see :func:`loop_mutual_inductance`.

    Returns
    -------
    ndarray
        Mutual inductance [H], the shape of ``rho_m``.
    """
    rho = np.asarray(rho_m, dtype=float)
    ra = np.asarray(coil_a.radii_m)[:, None]
    rb = np.asarray(coil_b.radii_m)[None, :]
    z = float(gap_m) + np.asarray(coil_b.z_m)[None, :] - np.asarray(coil_a.z_m)[:, None]
    pairs_a, pairs_b, pairs_z = (v.ravel() for v in np.broadcast_arrays(ra, rb, z))
    flat = rho.ravel()
    out = np.empty(flat.shape)
    # chunks keep the (offsets × pairs × nodes) temporary around 20 MB
    if n_quad is None:
        n_quad = _default_n_quad(max(pairs_a.max(), pairs_b.max()), np.abs(pairs_z).min())
    chunk = max(1, 2_500_000 // (pairs_a.size * (n_quad + 1)))
    for start in range(0, flat.size, chunk):
        part = flat[start : start + chunk, None]
        out[start : start + chunk] = loop_mutual_inductance(pairs_a, pairs_b, pairs_z, part, n_quad=n_quad).sum(axis=1)
    return out.reshape(rho.shape)


@functools.lru_cache(maxsize=8)
def _coil_spline(coil_a: CoilGeometry, coil_b: CoilGeometry, gap_m: float, rho_max_m: float, n_quad: int | None):
    # M_coil is even and analytic in ρ with features on the scale of the gap near the
    # coils and of ρ itself far away: fine uniform knots near, geometric knots far.
    near = 2.0 * (max(coil_a.radii_m) + max(coil_b.radii_m))
    h = min(gap_m, min(coil_a.radii_m + coil_b.radii_m)) / 20.0
    knots = np.linspace(0.0, near, int(math.ceil(near / h)) + 1)
    if rho_max_m > near:
        n_far = int(math.ceil(math.log(rho_max_m / near) / 0.025))
        knots = np.concatenate([knots, np.geomspace(near, rho_max_m, n_far + 1)[1:]])
    values = _stored(("coil_spline", coil_a.radii_m, coil_a.z_m, coil_b.radii_m, coil_b.z_m, gap_m, knots, n_quad),
                     lambda: coil_mutual_inductance(coil_a, coil_b, gap_m, knots, n_quad=n_quad))
    return CubicSpline(knots, values, bc_type=((1, 0.0), "not-a-knot"))


#: where computed coil tables are kept between processes (beside numba's cache of the compiled kernels)
CACHE_DIR = Path(__file__).resolve().parent / "__pycache__"


def _stored(key: tuple, compute) -> np.ndarray:
    """``compute()``, kept in :data:`CACHE_DIR` under a hash of ``key`` (its arrays' bytes included).

    A simulated sensor's coil spline takes ~1 s to compute and every ``simulate``,
    ``sim-device`` and ``demo`` process needs it: the first one writes it (atomically, by
    a rename), the others read it. A file that cannot be read or written (a read-only
    install, a full disk) is no error: the values are computed as without a cache.
    """
    digest = hashlib.sha256(Path(__file__).read_bytes())  # any change of this module's code: computed anew
    for part in key:
        digest.update(np.ascontiguousarray(part).tobytes() if isinstance(part, np.ndarray | tuple | list)
                      else repr(part).encode())
        digest.update(b"|")
    path = CACHE_DIR / f"coils-{digest.hexdigest()[:24]}.npy"
    with contextlib.suppress(OSError, ValueError, EOFError):
        return np.load(path, allow_pickle=False)
    values = np.asarray(compute(), dtype=float)
    with contextlib.suppress(OSError):
        CACHE_DIR.mkdir(exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=CACHE_DIR, prefix=".coils-", suffix=".npy")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.save(fh, values, allow_pickle=False)
            os.replace(tmp, path)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return values


@dataclass(frozen=True, kw_only=True, eq=False)
class CoilArrayModel:
    """Receiver signals of the sensor's coil arrays versus shift, with a fast interpolant.

    Build with :meth:`build` or :meth:`from_config`. The per-channel normalized signal
    ``u_i(S) = Σ_j (−1)^j M_coil(x_i + S − X_j) / M_ref`` (``M_ref = M_coil(0) −
    M_coil(p)``, the nearest-pair difference with the receiver right above a
    transmitter) is tabulated on a uniform grid of shifts over ``±shift_max_m``, with
    exact derivatives, and evaluated by cubic Hermite interpolation; shifts outside the
    table are evaluated directly. All transmitters are included, so the end receivers
    see the asymmetry of the array's ends.

    Attributes
    ----------
    n_receivers : int
        N.
    pitch_m : float
        Coil pitch p on both strips [m].
    gap_m : float
        Strip gap d [m].
    receiver_coil, transmitter_coil : CoilGeometry
        Coil models.
    shift_max_m : float
        Half-range of the tabulated shifts [m].
    n_samples : int
        Samples of the table per channel.
    mutual_ref_h : float
        M_ref [H].
    """

    n_receivers: int
    pitch_m: float
    gap_m: float
    receiver_coil: CoilGeometry
    transmitter_coil: CoilGeometry
    shift_max_m: float
    n_samples: int
    mutual_ref_h: float
    _spline: CubicSpline = field(repr=False)
    _table: np.ndarray = field(repr=False)  # (N, n_samples − 1, 4): cubic coefficients per interval
    _offsets_m: np.ndarray = field(repr=False)  # (N, N + 1): x_i − X_j
    _polarity: np.ndarray = field(repr=False)  # (N + 1,)

    @classmethod
    def build(
        cls,
        *,
        n_receivers: int,
        pitch_m: float,
        gap_m: float,
        receiver_coil: CoilGeometry,
        transmitter_coil: CoilGeometry | None = None,
        shift_max_m: float | None = None,
        n_samples: int = 4001,
        n_quad: int | None = None,
    ) -> CoilArrayModel:
        """Precompute the model (its coil spline cached per geometry, on disk too: about a second the first time).

        Parameters
        ----------
        n_receivers : int
            Number of receiver coils N; there are N + 1 transmitters.
        pitch_m, gap_m : float
            Coil pitch p and strip gap d [m].
        receiver_coil, transmitter_coil : CoilGeometry
            Coil models (the transmitters default to the receivers' model).
        shift_max_m : float, optional
            Half-range of the table [m]; default one pitch.
        n_samples : int
            Table samples per channel (default 4001: a 4 µm step at the paper's pitch).
        n_quad : int, optional
            Trapezoidal intervals of the loop integrals (default: automatic).
        """
        if not isinstance(n_receivers, int) or n_receivers < 1:
            raise ConfigError(f"n_receivers: must be a positive integer, got {n_receivers!r}")
        for name, value in (("pitch_m", pitch_m), ("gap_m", gap_m)):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{name}: must be > 0, got {value!r}")
        if not isinstance(n_samples, int) or n_samples < 3:
            raise ConfigError(f"n_samples: must be an integer >= 3, got {n_samples!r}")
        transmitter_coil = receiver_coil if transmitter_coil is None else transmitter_coil
        shift_max_m = float(pitch_m if shift_max_m is None else shift_max_m)
        if not (math.isfinite(shift_max_m) and shift_max_m > 0):
            raise ConfigError(f"shift_max_m: must be > 0, got {shift_max_m!r}")
        n = n_receivers
        x_rx = np.arange(n) * pitch_m
        x_tx = (np.arange(n + 1) - 0.5) * pitch_m
        offsets = x_rx[:, None] - x_tx[None, :]
        polarity = np.where(np.arange(n + 1) % 2 == 0, 1.0, -1.0)
        rho_max = float(np.abs(offsets).max() + shift_max_m + pitch_m)
        spline = _coil_spline(transmitter_coil, receiver_coil, float(gap_m), rho_max, n_quad)
        mutual_ref = float(spline(0.0) - spline(pitch_m))

        grid = np.linspace(-shift_max_m, shift_max_m, n_samples)
        rho = offsets[:, None, :] + grid[None, :, None]  # (N, samples, N + 1)
        # M_coil is even: M(ρ) = M(|ρ|) and dM/dρ = sign(ρ) M'(|ρ|)
        values = (spline(np.abs(rho)) * polarity).sum(axis=-1) / mutual_ref
        slopes = (spline(np.abs(rho), 1) * np.sign(rho) * polarity).sum(axis=-1) / mutual_ref
        step = grid[1] - grid[0]
        y0, y1 = values[:, :-1], values[:, 1:]
        d0, d1 = slopes[:, :-1] * step, slopes[:, 1:] * step
        table = np.stack([y0, d0, 3 * (y1 - y0) - 2 * d0 - d1, 2 * (y0 - y1) + d0 + d1], axis=-1)
        return cls(
            n_receivers=n,
            pitch_m=float(pitch_m),
            gap_m=float(gap_m),
            receiver_coil=receiver_coil,
            transmitter_coil=transmitter_coil,
            shift_max_m=shift_max_m,
            n_samples=n_samples,
            mutual_ref_h=mutual_ref,
            _spline=spline,
            _table=np.ascontiguousarray(table.reshape(-1, 4)),
            _offsets_m=offsets,
            _polarity=polarity,
        )

    @classmethod
    def from_config(cls, sensor, **kwargs) -> CoilArrayModel:
        """Build the model of a :class:`~bendsense.config.SensorConfig` (or a whole ``Config``).

        Parameters
        ----------
        sensor : SensorConfig or Config
            The sensor.
        **kwargs
            Passed to :meth:`build` (e.g. ``receiver_coil``).
        """
        sensor = getattr(sensor, "sensor", sensor)
        coil = kwargs.pop("receiver_coil", None) or CoilGeometry.from_sensor_config(sensor)
        return cls.build(
            n_receivers=sensor.n_segments,
            pitch_m=sensor.coil_pitch_m,
            gap_m=sensor.strip_gap_m,
            receiver_coil=coil,
            **kwargs,
        )

    @property
    def step_m(self) -> float:
        """Spacing of the table's shift grid [m]."""
        return 2.0 * self.shift_max_m / (self.n_samples - 1)

    def _check(self, shifts_m) -> np.ndarray:
        s = np.asarray(shifts_m, dtype=float)
        if s.ndim == 0 or s.shape[-1] != self.n_receivers:
            raise ConfigError(f"shifts_m: expected shape (..., {self.n_receivers}), got {s.shape}")
        return s

    def coil_mutual_inductance(self, rho_m) -> np.ndarray:
        """M_coil(ρ) of one transmitter–receiver pair from the precomputed spline [H].

        Parameters
        ----------
        rho_m : float or array_like
            Lateral distance ρ between the coils' axes [m].
        """
        rho = np.abs(np.asarray(rho_m, dtype=float))
        out = self._spline(np.minimum(rho, self._spline.x[-1]))
        far = rho > self._spline.x[-1]
        if np.any(far):
            out[far] = coil_mutual_inductance(self.transmitter_coil, self.receiver_coil, self.gap_m, rho[far])
        return out

    def direct(self, shifts_m) -> np.ndarray:
        """Compute the normalized signals by the full transmitter sum (slower; no table) [-].

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total shifts S [m].
        """
        s = self._check(shifts_m)
        rho = self._offsets_m + s[..., None]
        return (self.coil_mutual_inductance(rho) * self._polarity).sum(axis=-1) / self.mutual_ref_h

    def signal(self, shifts_m) -> np.ndarray:
        """Evaluate the normalized in-phase receiver signals u_i(S_i) (paper Fig. 2(c)).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total relative shifts S_i [m] (paper eq. 2), receiver toward the tip > 0.

        Returns
        -------
        ndarray, shape (..., N)
            ``Σ_j (−1)^j M(receiver i, transmitter j) / M_ref`` [-]; odd receivers
            (1-based) decrease with S, even ones increase.
        """
        s = self._check(shifts_m)
        t = (s + self.shift_max_m) / self.step_m
        inside = (t >= 0.0) & (t <= self.n_samples - 1)
        k = np.clip(t.astype(np.int64), 0, self.n_samples - 2)
        f = t - k
        rows = k + np.arange(self.n_receivers) * (self.n_samples - 1)
        c = self._table[rows]
        out = c[..., 0] + f * (c[..., 1] + f * (c[..., 2] + f * c[..., 3]))
        if not np.all(inside):
            outside = np.broadcast_to(~inside, s.shape)
            idx = np.nonzero(outside)
            rho = self._offsets_m[idx[-1]] + s[idx][:, None]
            out[idx] = (self.coil_mutual_inductance(rho) * self._polarity).sum(axis=-1) / self.mutual_ref_h
        return out

    def derivative(self, shifts_m) -> np.ndarray:
        """Evaluate the slopes d u_i / d S_i from the spline of M_coil [1/m], shape (..., N).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total shifts S [m].
        """
        s = self._check(shifts_m)
        rho = self._offsets_m + s[..., None]
        dm = self._spline(np.abs(rho), 1) * np.sign(rho)
        return (dm * self._polarity).sum(axis=-1) / self.mutual_ref_h

    def emf_v(self, shifts_m, *, frequency_hz: float = 1e6, current_a: float = 0.01) -> np.ndarray:
        """In-phase EMF amplitude ω I Σ_j (−1)^j M_ij of each receiver [V].

        ``frequency_hz`` is the excitation frequency (paper: 1 MHz) and ``current_a``
        the transmitter current amplitude [A] (not given in the paper; a placeholder).

        Parameters
        ----------
        shifts_m : array_like, shape (..., N)
            Total shifts S [m].
        frequency_hz : float, default 1e6
            Excitation frequency [Hz].
        current_a : float, default 0.01
            Transmitter current amplitude [A].
        """
        return 2.0 * math.pi * frequency_hz * current_a * self.mutual_ref_h * self.signal(shifts_m)

    def monotonic_range_m(self, *, step_m: float | None = None) -> np.ndarray:
        """Per channel, the interval of shifts around 0 where u_i is strictly monotonic.

        Parameters
        ----------
        step_m : float, optional
            Sampling step of the shifts [m]; default the table step.

        Returns
        -------
        ndarray, shape (N, 2)
            ``[lowest, highest]`` shift [m] of the interval containing S = 0 on which
            the slope keeps the sign it has at 0, sampled with ``step_m`` (default the
            table step), within the table range.
        """
        step = self.step_m if step_m is None else float(step_m)
        n_half = int(self.shift_max_m / step)
        grid = np.arange(-n_half, n_half + 1) * step
        slope = self.derivative(np.repeat(grid[:, None], self.n_receivers, axis=1))
        sign0 = np.sign(slope[n_half])
        good = slope * sign0 > 0
        out = np.empty((self.n_receivers, 2))
        for i in range(self.n_receivers):
            bad_hi = np.nonzero(~good[n_half:, i])[0]
            bad_lo = np.nonzero(~good[: n_half + 1, i][::-1])[0]
            out[i, 1] = grid[n_half + bad_hi[0] - 1] if bad_hi.size else grid[-1]
            out[i, 0] = grid[n_half - bad_lo[0] + 1] if bad_lo.size else grid[0]
        return out
