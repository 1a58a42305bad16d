"""Piecewise-constant-curvature (PCC) shape reconstruction (paper section III, eq. 3–7).

The numerical core is pure functions on numpy arrays, vectorised over leading batch
(frame) axes:

- :func:`shifts_to_curvatures` — total shifts S → segment curvatures κ (paper eq. 3–4);
- :func:`forward_kinematics` — κ → positions and tangent angles at arc lengths s
  (paper eq. 5–7);
- :func:`tip_pose` — κ → tip position and tip angle;
- :func:`arc_positions`, :func:`fit_arc_curvature`, :func:`max_position_error` — the
  shape metrics of the paper's validation (paper eq. 19, 20).

:func:`reconstruct` chains calibration (signals → shifts) and the above into a
:class:`Shape`.

Frame convention (DESIGN section 2): base at the origin, ``+y`` the base tangent,
tangent angle φ measured from ``+y`` toward ``+x``, unit tangent ``(sin φ, cos φ)``,
κ = dφ/ds > 0 bends toward ``+x``. A segment of length l and bending angle θ = κ l has
its tip at ``(l/θ (1 − cos θ), l/θ sin θ)`` in its base frame, and the next frame is
rotated by ``R_z(−θ)`` (paper eq. 5).

All arcs are evaluated through the chord form, exact and stable as θ → 0: an arc of
length σ and curvature κ starting at angle φ0 ends at
``σ · sinc(κσ/2) · (sin(φ0 + κσ/2), cos(φ0 + κσ/2))`` with ``sinc(u) = sin(u)/u``,
which equals the paper's ``(1/κ (1 − cos κσ), 1/κ sin κσ)`` for φ0 = 0.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from bendsense import _jit
from bendsense._batched import brief_repr, quick_init
from bendsense.errors import ArgumentError
from bendsense.shape import _kernels
from bendsense.validation import float_array, short

if TYPE_CHECKING:  # pragma: no cover
    from bendsense.calibration import Calibration
    from bendsense.config import SensorConfig

__all__ = [
    "Shape",
    "reconstruct",
    "shifts_to_curvatures",
    "forward_kinematics",
    "tip_pose",
    "arc_positions",
    "fit_arc_curvature",
    "max_position_error",
    "default_s_m",
]

DEFAULT_N_POINTS = 101


def _sinc(u):
    """sin(u)/u, exactly 1 at u = 0 (unnormalised sinc)."""
    # a tiny stand-in for 0 gives sin(y)/y == 1.0 exactly, without a branch per element
    y = np.where(u == 0.0, 1e-20, u)
    return np.sin(y) / y


def _dsinc(v):
    """Differentiate sin(v)/v, with a series near 0 where (cos v − sinc v)/v cancels."""
    v = np.asarray(v, dtype=float)
    small = np.abs(v) < 1e-2
    safe = np.where(small, 1.0, v)
    direct = (np.cos(safe) - np.sin(safe) / safe) / safe
    v2 = v * v
    series = v * (-1.0 / 3.0 + v2 * (1.0 / 30.0 - v2 / 840.0))
    return np.where(small, series, direct)


# --- geometry of the sample points ------------------------------------------------------


class _Grid:
    """Per-(lengths, s) precomputation: segment index and local arc length of every point."""

    __slots__ = ("lengths", "s", "seg", "sigma", "half_sigma", "total", "scale", "scale_one", "half_lengths")

    def __init__(self, lengths_m, s_m):
        lengths = float_array("lengths_m", lengths_m)
        if lengths.ndim != 1 or lengths.size == 0 or not np.all(lengths > 0):
            raise ArgumentError(f"lengths_m: expected a 1-D array of positive segment lengths, got {short(lengths_m)}")
        s = float_array("s_m", s_m)
        if s.ndim != 1:
            raise ArgumentError(f"s_m: expected a 1-D array of arc lengths, got shape {s.shape}")
        bounds = np.concatenate(([0.0], np.cumsum(lengths)))
        total = float(bounds[-1])
        tol = 1e-12 * total
        if s.size and (not np.all(np.isfinite(s)) or s.min() < -tol or s.max() > total + tol):
            bad = s[~((s >= -tol) & (s <= total + tol))][0]
            raise ArgumentError(f"s_m: arc lengths must lie in [0, {total:g}] m (the sensor length), got {bad:g}")
        s = np.clip(s, 0.0, total)
        # s in (L_{i-1}, L_i] belongs to segment i (paper eq. 7); s = 0 to the first one
        seg = np.searchsorted(bounds[1:-1], s, side="left")
        self.lengths = lengths
        self.s = s
        self.seg = seg
        self.sigma = s - bounds[seg]
        self.half_sigma = 0.5 * self.sigma
        self.total = total
        self.scale = np.concatenate([lengths, self.sigma])[:, None]  # chord lengths of unit sinc
        self.scale_one = self.scale[:, 0].copy()
        self.half_lengths = 0.5 * lengths
        for a in (self.lengths, self.s, self.seg, self.sigma, self.half_sigma, self.scale, self.scale_one,
                  self.half_lengths):
            a.setflags(write=False)


def _grid(lengths_m, s_m) -> _Grid:
    lengths = np.ascontiguousarray(float_array("lengths_m", lengths_m))
    s = np.ascontiguousarray(float_array("s_m", s_m))
    return _grid_of_bytes(lengths.tobytes(), lengths.shape, s.tobytes(), s.shape)


@functools.lru_cache(maxsize=64)  # bounded: callers with ever-changing s_m must not leak
def _grid_of_bytes(lengths: bytes, lengths_shape: tuple, s: bytes, s_shape: tuple) -> _Grid:
    # rebuilt from the key's bytes: the grid never holds (nor makes read-only) a caller's array
    return _Grid(np.frombuffer(lengths).reshape(lengths_shape), np.frombuffer(s).reshape(s_shape))


def default_s_m(lengths_m, n_points: int = DEFAULT_N_POINTS) -> np.ndarray:
    """``n_points`` equally spaced arc lengths over 0 ≤ s ≤ L_N [m].

    Parameters
    ----------
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    n_points : int, default 101
        Number of arc lengths.
    """
    return np.linspace(0.0, float(np.sum(lengths_m)), n_points)


# --- pure functions ---------------------------------------------------------------------


def shifts_to_curvatures(shifts_m, lengths_m, strip_gap_m):
    """Segment curvatures from total relative shifts (paper eq. 3–4).

    Parameters
    ----------
    shifts_m : array_like, shape (..., N)
        Total relative shifts S_i of the reference points [m].
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    strip_gap_m : float
        Distance d between receiver and transmitter strips [m].

    Returns
    -------
    curvature_per_m : ndarray, shape (..., N)
        κ_i = ΔS_i / (d l_i) with ΔS_1 = S_1, ΔS_i = S_i − S_(i−1) [1/m].
    """
    shifts = np.asarray(shifts_m, dtype=float)
    local = shifts.copy()
    np.subtract(shifts[..., 1:], shifts[..., :-1], out=local[..., 1:])
    local /= strip_gap_m * np.asarray(lengths_m, dtype=float)
    return local


def _kinematics(kappa, grid: _Grid, base_angle_rad, points=True, theta=None):
    """Run the kinematics kernels over any batch shape (on numba's threads from ``_jit.PARALLEL_MIN`` frames)."""
    n = grid.lengths.size
    if kappa.shape[-1:] != (n,):
        raise ArgumentError(f"curvature_per_m: expected {n} values on the last axis, got {kappa.shape}")
    base = float_array("base_angle_rad", base_angle_rad)
    if not np.isfinite(base).all():
        raise ArgumentError(f"base_angle_rad: must be finite, got {base[~np.isfinite(base)].ravel()[0]!r}")
    try:
        batch = np.broadcast_shapes(kappa.shape[:-1], base.shape)
    except ValueError:
        raise ArgumentError(f"base_angle_rad: shape {base.shape} does not broadcast against the frames "
                            f"{kappa.shape[:-1]}") from None
    frames = math.prod(batch)
    k2 = np.ascontiguousarray(np.broadcast_to(kappa, (*batch, n)).reshape(frames, n), dtype=float)
    th2 = k2 * grid.lengths if theta is None else np.ascontiguousarray(
        np.broadcast_to(theta, (*batch, n)).reshape(frames, n), dtype=float)
    b2 = np.ascontiguousarray(np.broadcast_to(base, batch).reshape(frames))
    seg, sigma = (grid.seg, grid.sigma) if points else (grid.seg[:0], grid.sigma[:0])
    m = seg.size
    pos, ang = np.empty((frames, m, 2)), np.empty((frames, m))
    tip, tip_ang = np.empty((frames, 2)), np.empty(frames)
    if not _jit.parallel(frames):  # a live block: in this thread
        _jit.call(_kernels.kinematics_block, 0, frames, k2, th2, b2, seg, sigma, grid.lengths, pos, ang, tip, tip_ang)
    else:
        _jit.call(_kernels.kinematics_frames, k2, th2, b2, seg, sigma, grid.lengths, pos, ang, tip, tip_ang)
    tip = tip.reshape(*batch, 2)
    tip_ang = tip_ang.reshape(batch)
    if not points:
        return None, None, tip, tip_ang
    return pos.reshape(*batch, m, 2), ang.reshape(*batch, m), tip, tip_ang


def forward_kinematics(curvature_per_m, lengths_m, s_m, base_angle_rad=0.0):
    """Positions and tangent angles of a PCC curve at arc lengths ``s_m`` (paper eq. 5–7).

    Parameters
    ----------
    curvature_per_m : array_like, shape (..., N)
        Segment curvatures κ_i [1/m]; leading axes are frames.
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    s_m : array_like, shape (M,)
        Arc lengths from the base, any order, each 0 ≤ s ≤ L_N [m].
    base_angle_rad : float or array_like, shape (...)
        Tangent angle φ at the base, from ``+y`` toward ``+x`` [rad].

    Returns
    -------
    positions_m : ndarray, shape (..., M, 2)
        Points (x, y) in the base frame [m].
    angle_rad : ndarray, shape (..., M)
        Tangent angles φ(s) [rad].

    Raises
    ------
    ArgumentError
        If an arc length lies outside [0, L_N] (no silent extrapolation).
    """
    grid = _grid(lengths_m, s_m)
    pos, ang, _, _ = _kinematics(np.asarray(curvature_per_m, dtype=float), grid, base_angle_rad)
    return pos, ang


def tip_pose(curvature_per_m, lengths_m, base_angle_rad=0.0):
    """Tip position and tip tangent angle of a PCC curve (paper eq. 5–6 at s = L_N).

    Parameters
    ----------
    curvature_per_m : array_like, shape (..., N)
        Segment curvatures κ_i [1/m].
    lengths_m : array_like, shape (N,)
        Segment lengths l_i [m].
    base_angle_rad : float or array_like, shape (...)
        Tangent angle at the base [rad].

    Returns
    -------
    tip_position_m : ndarray, shape (..., 2)
        Tip (x, y) in the base frame [m].
    tip_angle_rad : ndarray, shape (...)
        Tip tangent angle φ(L_N) = φ_base + Σ κ_i l_i [rad].
    """
    grid = _grid(lengths_m, ())
    _, _, tip, tip_angle = _kinematics(np.asarray(curvature_per_m, dtype=float), grid, base_angle_rad, points=False)
    return tip, tip_angle


def arc_positions(kappa, s_m):
    """Points of a circular arc from the origin along ``+y`` (paper eq. 19, ``p_con``).

    Parameters
    ----------
    kappa : float or array_like, shape (...)
        Arc curvature κ [1/m]; 0 gives the straight line along ``+y``.
    s_m : array_like, shape (M,)
        Arc lengths [m].

    Returns
    -------
    positions_m : ndarray, shape (..., M, 2)
        ``(1/κ (1 − cos κs), 1/κ sin κs)``, evaluated in the stable chord form [m].
    """
    k = np.asarray(kappa, dtype=float)[..., None]
    s = np.asarray(s_m, dtype=float)
    half = 0.5 * k * s
    c = s * _sinc(half)
    return np.stack((c * np.sin(half), c * np.cos(half)), axis=-1)


def _arc_and_derivative(k, s):
    """p_con(s, κ) and ∂p_con/∂κ, both stable at κ = 0; k (..., 1), s (M,)."""
    u = 0.5 * k * s
    s1u = _sinc(u)
    s12u = _sinc(2.0 * u)
    p = np.stack((s * s1u * np.sin(u), s * s12u), axis=-1)
    # p = s (sin²u/u, sin 2u / 2u): d/du gives (2 sinc 2u − sinc² u, 2 sinc'(2u)), du/dκ = s/2
    scale = 0.5 * s * s
    dp = np.stack((scale * (2.0 * s12u - s1u * s1u), scale * 2.0 * _dsinc(2.0 * u)), axis=-1)
    return p, dp


def _trapezoid_weights(s):
    w = np.zeros_like(s)
    if s.size > 1:
        ds = np.diff(s)
        w[:-1] += 0.5 * ds
        w[1:] += 0.5 * ds
    return w


def fit_arc_curvature(positions_m, s_m, *, kappa_max_per_m=None, n_grid=129, max_iter=100):
    """Curvature of the circular arc closest to a shape (paper eq. 19, κ_recon).

    Minimises ``J(κ) = ∫ ||p⁰(s) − p_con(s, κ)||² ds`` with the trapezoid rule over
    ``s_m``: a grid search over [−κ_max, κ_max] picks the basin, then damped
    Gauss–Newton iterations (analytic ∂p_con/∂κ) converge to machine precision. A
    straight shape gives exactly κ = 0 (the gradient vanishes there by symmetry).

    Parameters
    ----------
    positions_m : array_like, shape (..., M, 2)
        Shape points p⁰(s) in the base frame [m].
    s_m : array_like, shape (M,)
        Their arc lengths from the base, ascending [m].
    kappa_max_per_m : float, optional
        Search bound [1/m]; default 4π / s_max (two full turns).
    n_grid : int
        Grid points of the initial search.
    max_iter : int
        Gauss–Newton iterations at most.

    Returns
    -------
    kappa : ndarray, shape (...)
        κ_recon [1/m].
    """
    p0 = np.asarray(positions_m, dtype=float)
    s = np.asarray(s_m, dtype=float)
    if p0.shape[-2:] != (s.size, 2):
        raise ArgumentError(f"positions_m: expected shape (..., {s.size}, 2) to match s_m, got {p0.shape}")
    if s.size < 2 or np.any(np.diff(s) <= 0):
        raise ArgumentError("s_m: expected at least 2 strictly ascending arc lengths")
    w = _trapezoid_weights(s)
    kmax = 4.0 * np.pi / s[-1] if kappa_max_per_m is None else float(kappa_max_per_m)
    batch = p0.shape[:-2]

    def cost(k):  # k (..., G) -> (..., G)
        diff = arc_positions(k, s) - p0[..., None, :, :]
        return np.einsum("...gm,m->...g", np.sum(diff * diff, axis=-1), w)

    grid = np.linspace(-kmax, kmax, n_grid)
    grid = np.concatenate((grid, [0.0]))
    j_grid = cost(np.broadcast_to(grid, (*batch, grid.size)))
    k = grid[np.argmin(j_grid, axis=-1)]
    j = np.min(j_grid, axis=-1)
    for _ in range(max_iter):
        p, dp = _arc_and_derivative(k[..., None], s)
        r = p - p0
        g = np.einsum("...mi,...mi,m->...", r, dp, w)
        h = np.einsum("...mi,...mi,m->...", dp, dp, w)
        step = -g / np.where(h > 0, h, 1.0)
        # halve the step until the cost does not increase (frames independently)
        new_k, new_j = k + step, None
        for _ in range(30):
            new_j = cost(new_k[..., None])[..., 0]
            worse = new_j > j
            if not np.any(worse):
                break
            step = np.where(worse, 0.5 * step, step)
            new_k = k + step
        accept = new_j <= j
        done = np.all(np.abs(np.where(accept, step, 0.0)) <= 1e-15 * np.maximum(1.0, np.abs(k)))
        k = np.where(accept, new_k, k)
        j = np.where(accept, new_j, j)
        if done:
            break
    return k


def max_position_error(positions_m, s_m, kappa, length_m):
    """Largest distance from an arc, relative to the length (paper eq. 20, δp_max).

    Parameters
    ----------
    positions_m : array_like, shape (..., M, 2)
        Shape points p⁰(s) [m].
    s_m : array_like, shape (M,)
        Their arc lengths [m].
    kappa : float or array_like, shape (...)
        Curvature of the reference arc p_con(s, κ), e.g. κ_val [1/m].
    length_m : float
        Length L used for the normalisation [m].

    Returns
    -------
    ndarray, shape (...)
        ``max_s ||p⁰(s) − p_con(s, κ)|| / L · 100`` [%].
    """
    diff = np.asarray(positions_m, dtype=float) - arc_positions(kappa, s_m)
    return np.max(np.hypot(diff[..., 0], diff[..., 1]), axis=-1) / float(length_m) * 100.0


# --- result object and the chain ---------------------------------------------------------


@quick_init
@dataclass(frozen=True, kw_only=True, eq=False)
class Shape:
    """A reconstructed PCC shape for one frame or a batch of frames.

    Attributes
    ----------
    curvature_per_m : ndarray, shape (..., N)
        Segment curvatures κ_i [1/m].
    s_m : ndarray, shape (M,)
        Arc lengths of the sample points [m].
    positions_m : ndarray, shape (..., M, 2)
        Sample points p⁰(s) in the base frame [m].
    angle_rad : ndarray, shape (..., M)
        Tangent angles φ(s) [rad].
    tip_position_m : ndarray, shape (..., 2)
        Tip position [m].
    tip_angle_rad : ndarray, shape (...)
        Tip tangent angle [rad].
    lengths_m : ndarray, shape (N,)
        Segment lengths l_i [m].
    extrapolated : ndarray of bool, shape (...)
        True where a signal lay outside the calibrated range (the curvature is an
        extrapolation of the calibration polynomials); False if unknown.
    """

    __repr__ = brief_repr  # a line or two, not every value of every frame

    curvature_per_m: np.ndarray
    s_m: np.ndarray
    positions_m: np.ndarray
    angle_rad: np.ndarray
    tip_position_m: np.ndarray
    tip_angle_rad: np.ndarray
    lengths_m: np.ndarray
    extrapolated: Any = False

    @classmethod
    def from_curvatures(cls, curvature_per_m, lengths_m, s_m=None, base_angle_rad=0.0, extrapolated=None) -> Shape:
        """Build a shape from segment curvatures (paper eq. 5–7).

        Parameters
        ----------
        curvature_per_m : array_like, shape (..., N)
            Segment curvatures κ [1/m].
        lengths_m : array_like, shape (N,)
            Segment lengths l_i [m].
        s_m : array_like, shape (M,), optional
            Arc lengths of the output points [m]; default :func:`default_s_m`.
        base_angle_rad : float or array_like, default 0.0
            Tangent angle at the base [rad].
        extrapolated : array_like of bool, shape (...), optional
            Frames whose signals lay outside the calibrated range.
        """
        kappa = np.asarray(curvature_per_m, dtype=float)
        lengths = np.asarray(lengths_m, dtype=float)
        s = default_s_m(lengths) if s_m is None else np.asarray(s_m, dtype=float)
        return _shape(kappa, _grid(lengths, s), base_angle_rad, extrapolated)

    @property
    def batch_shape(self) -> tuple:
        """Shape of the leading frame axes (``()`` for a single frame)."""
        return self.curvature_per_m.shape[:-1]

    @property
    def length_m(self) -> float:
        """Total length L_N [m]."""
        return float(np.sum(self.lengths_m))

    def __len__(self) -> int:
        if not self.batch_shape:
            raise TypeError("a single-frame Shape has no length")
        return self.batch_shape[0]

    def __getitem__(self, index) -> Shape:
        """Select frames along the leading batch axes, e.g. ``shape[3]`` or ``shape[::10]``."""
        if not self.batch_shape:
            raise IndexError("a single-frame Shape cannot be indexed")
        idx = index if isinstance(index, tuple) else (index,)
        extra = np.broadcast_to(np.asarray(self.extrapolated, dtype=bool), self.batch_shape)
        return Shape(
            curvature_per_m=self.curvature_per_m[idx],
            s_m=self.s_m,
            positions_m=self.positions_m[idx],
            angle_rad=self.angle_rad[idx],
            tip_position_m=self.tip_position_m[idx],
            tip_angle_rad=self.tip_angle_rad[idx],
            lengths_m=self.lengths_m,
            extrapolated=extra[idx],
        )

    def frame(self, i) -> Shape:
        """One frame (index into the first batch axis).

        Parameters
        ----------
        i : int
            Index into the first batch axis.
        """
        return self[i]

    def to_dict(self) -> dict:
        """Plain lists, for JSON/YAML."""
        return {
            "curvature_per_m": self.curvature_per_m.tolist(),
            "s_m": self.s_m.tolist(),
            "positions_m": self.positions_m.tolist(),
            "angle_rad": np.asarray(self.angle_rad).tolist(),
            "tip_position_m": self.tip_position_m.tolist(),
            "tip_angle_rad": np.asarray(self.tip_angle_rad).tolist(),
            "lengths_m": self.lengths_m.tolist(),
            "extrapolated": np.asarray(self.extrapolated).tolist(),
        }

    def plot(self, ax=None, *, max_frames: int = 50, **kwargs):
        """Plot the shape(s) in the base frame in mm (:func:`bendsense.plots.plot_shapes`).

        Up to ``max_frames`` frames, evenly spaced; frames flagged ``extrapolated`` are
        dashed (and explained in the legend). ``kwargs`` go to ``Axes.plot``. Returns
        the axes.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; None makes a new figure.
        max_frames : int, default 50
            Most frames drawn, evenly spaced.
        **kwargs
            Passed to ``Axes.plot``.
        """
        from bendsense.plots import plot_shapes

        frames = int(np.prod(self.batch_shape)) if self.batch_shape else 1
        return plot_shapes(self, ax, max_frames=max_frames, legend=frames <= 8, **kwargs)


def _shape(kappa, grid: _Grid, base_angle_rad, extrapolated, theta=None) -> Shape:
    positions, angles, tip, tip_angle = _kinematics(kappa, grid, base_angle_rad, theta=theta)
    if extrapolated is None:
        extrapolated = np.zeros(kappa.shape[:-1], dtype=bool)
    return Shape(
        curvature_per_m=kappa,
        s_m=grid.s,
        positions_m=positions,
        angle_rad=angles,
        tip_position_m=tip,
        tip_angle_rad=tip_angle,
        lengths_m=grid.lengths,
        extrapolated=extrapolated,
    )


@functools.lru_cache(maxsize=1)
def _paper_sensor() -> SensorConfig:
    from bendsense.config import load_config

    return load_config().sensor


def _resolve_sensor(sensor):
    if sensor is None:
        return _paper_sensor()
    from bendsense.config import SensorConfig

    sensor = getattr(sensor, "sensor", sensor)  # a whole Config is accepted too
    if not isinstance(sensor, SensorConfig):
        raise ArgumentError(f"sensor: expected a SensorConfig or a Config (bendsense.load_config(path)), got "
                            f"{type(sensor).__name__}")
    return sensor


def reconstruct(
    signals,
    calibration: Calibration,
    sensor: SensorConfig | None = None,
    s_m=None,
    *,
    base_angle_rad=0.0,
) -> Shape:
    """Shape from raw sensor signals: ΔA → S → κ → PCC shape (paper eq. 1–7).

    Parameters
    ----------
    signals : array_like, shape (..., N)
        Raw coil signals A [signal units]; leading axes are frames.
    calibration : Calibration
        Offset A0 and the odd/even shift polynomials (paper eq. 1–2).
    sensor : SensorConfig or Config, optional
        Segment lengths and strip gap; ``None`` uses the paper's sensor.
    s_m : array_like, shape (M,), optional
        Arc lengths of the output points, 0 ≤ s ≤ L_N [m]; default 101 equally spaced.
    base_angle_rad : float or array_like, shape (...)
        Base tangent angle [rad].

    Returns
    -------
    Shape
        With ``extrapolated`` set per frame from ``calibration.in_range``.
    """
    from bendsense.calibration import Calibration
    from bendsense.errors import ConfigError

    if not isinstance(calibration, Calibration):
        raise ArgumentError(f"calibration: expected a Calibration (Calibration.load(path)), got "
                            f"{type(calibration).__name__}")
    sensor = _resolve_sensor(sensor)
    n = sensor.n_segments
    if calibration.n_channels != n:
        raise ConfigError(f"calibration.n_channels: expected {n} (sensor.n_segments), got {calibration.n_channels}")
    a = float_array("signals", signals)
    if a.shape[-1:] != (n,):
        raise ArgumentError(f"signals: expected {n} channels on the last axis, got shape {a.shape}")
    lengths = sensor.lengths_m
    grid = _grid(lengths, default_s_m(lengths) if s_m is None else s_m)
    if isinstance(base_angle_rad, (float, int)) and not math.isfinite(base_angle_rad):
        raise ArgumentError(f"base_angle_rad: must be finite, got {base_angle_rad!r}")
    if not isinstance(base_angle_rad, (float, int)):
        delta = a - calibration.offset
        kappa = shifts_to_curvatures(calibration.shifts_from_delta(delta), lengths, sensor.strip_gap_m)
        return _shape(kappa, grid, base_angle_rad, calibration.extrapolated_delta(delta))
    # fused: signals → ΔA → S → θ = ΔS/d, κ = θ/l → shape (paper eq. 1–7)
    batch = a.shape[:-1]
    frames, m = math.prod(batch), grid.s.size
    a2 = np.ascontiguousarray(a.reshape(frames, n))
    kappa = np.empty((frames, n))
    pos, ang = np.empty((frames, m, 2)), np.empty((frames, m))
    tip, tip_ang = np.empty((frames, 2)), np.empty(frames)
    extrapolated = np.empty(frames, dtype=bool)
    args = calibration_args(calibration, sensor)
    out = (np.full(frames, float(base_angle_rad)), grid.seg, grid.sigma, kappa, pos, ang, tip, tip_ang, extrapolated)
    if not _jit.parallel(frames):  # a live block: in this thread
        _jit.call(_kernels.reconstruct_block, 0, frames, a2, *args, *out)
    else:
        _jit.call(_kernels.reconstruct_frames, a2, *args, *out)
    return shape_of((kappa, pos, ang, tip, tip_ang, extrapolated), grid, batch)


def calibration_args(calibration, sensor) -> tuple:
    """The calibration and the sensor as the reconstruction kernels take them.

    (offset A0, each channel's polynomial, the calibrated ΔA range lo and hi, the segment
    lengths, the strip gap): :func:`bendsense.shape._kernels.reconstruct_block`, which the
    live step calls too.
    """
    lo, hi = calibration._channel_range
    arrays = (calibration.offset, calibration._channel_coefficients, lo, hi, sensor.lengths_m)
    return (*(np.ascontiguousarray(x, dtype=float) for x in arrays), float(sensor.strip_gap_m))


def shape_of(arrays, grid: _Grid, batch: tuple) -> Shape:
    """The :class:`Shape` of the reconstruction kernels' outputs (κ, positions, angles, tip, tip angle, extrapolated).

    ``batch``: the frames' batch shape (the kernels' frame axis is flat).
    """
    kappa, pos, ang, tip, tip_ang, extrapolated = arrays
    m = grid.s.size
    return Shape(
        curvature_per_m=kappa.reshape(*batch, kappa.shape[-1]),
        s_m=grid.s,
        positions_m=pos.reshape(*batch, m, 2),
        angle_rad=ang.reshape(*batch, m),
        tip_position_m=tip.reshape(*batch, 2),
        tip_angle_rad=tip_ang.reshape(batch),
        lengths_m=grid.lengths,
        extrapolated=extrapolated.reshape(batch),
    )

