"""An independent forward model for validation tests: shapes, exact sensor shifts, a hidden sensor.

Nothing here calls the library's solvers: the beam is scipy's ``solve_bvp`` on the
DESIGN.md equation, the free bending K0(P) is eq. 8–12 solved with its own quadrature
and ``brentq``, and the sensor is a nonlinear map the calibration polynomials do not
contain. Used by the force-validation tests (issue 12) and tested in
``tests/integration/test_forward_model.py`` against closed forms and the library.

- :func:`free_bending_k0` — K0(P) (paper eq. 8–12), Gauss–Legendre 40 × 40 × 40, brentq.
- :func:`solve_beam_bvp` — ``EI φ'' = sin φ G_y − cos φ G_x``, ``G = F [s < s_c] +
  w (L − s)`` (a point load at ``s_c ≤ L``: the BVP is split there exactly), ``φ(0) = 0``
  or a compliant base ``φ(0) = c M_base``, ``φ'(L) = K0``, positions integrated as two
  more states; continuation in the load.
- :func:`forward` — for a config, pressure and force: φ at the coil positions L_i,
  the exact shifts ``S_i = d (φ(L_i) − φ(0))``, positions; the true actuator may depart
  from the config (K0, EI, load point, base compliance).
- :class:`HiddenSensor` — exact shifts → ADC-like signals through a monotone nonlinear
  odd/even map (not a polynomial), per-channel offsets and Gaussian noise; writes the
  flat and strip recordings and the manifest that ``bendsense calibrate`` reads.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq

# --------------------------------------------------------------------------- free bending


@functools.lru_cache(maxsize=8)
def _unit_moment_nodes(a, b, t, order=40):
    """Nodes of eq. 10 per unit μ̄: M = Σ w (λ − λ⁻³) with λ = 1 + θ0 h / L (eq. 11, R = L/θ0)."""
    x, w = np.polynomial.legendre.leggauss(order)
    beta = 0.5 * b * (x + 1)
    wb = 0.5 * b * w * 2 * (a + t) * beta  # ∫0^b s_β 2(a+t) β dβ
    tau = 0.5 * t * (x[:, None, None] + 1)
    phi = 0.25 * math.pi * (x[None, :, None] + 1)
    weight = (0.5 * t * w[:, None, None]) * (0.25 * math.pi * w[None, :, None])
    # 2 ∫0^t ∫0^{π/2} s ((a+τ)² sin φ + b (a+τ)) dφ dτ
    lever = (a + tau) ** 2 * np.sin(phi) + b * (a + tau)
    h_wall = b + np.sin(phi) * (a + tau)  # (R + b + sin φ (a+τ)) / R − 1 = θ0 h / L
    h = np.concatenate([beta, h_wall.ravel()])
    wt = np.concatenate([wb, (2 * weight * lever).ravel()])
    return h, wt


def free_bending_k0(config, pressure_pa, material=None):
    """K0(P) = (θ0 + θ_pre) / L with ``M_a(P) = μ̄ m(θ0) + μ_s θ0`` (paper eq. 8–12).

    ``material``: a mapping overriding ``shear_modulus_pa``,
    ``sensor_stiffness_nm_per_rad``, ``prebend_angle_rad``.
    """
    act, mat = config.actuator, dict(vars(config.material))
    mat.update(material or {})
    a, b, t, L = act.chamber_radius_m, act.bottom_thickness_m, act.wall_thickness_m, act.length_m
    h, w = _unit_moment_nodes(a, b, t)
    mu, mu_s = mat["shear_modulus_pa"], mat["sensor_stiffness_nm_per_rad"]
    moment = (4 * a**3 + 3 * math.pi * a**2 * b) / 6 * float(pressure_pa)

    def balance(theta0):
        lam = 1 + theta0 * h / L
        return mu * float(w @ (lam - lam**-3)) + mu_s * theta0 - moment

    if moment <= 0:
        theta0 = 0.0
    else:
        hi = 1.0
        while balance(hi) < 0:
            hi *= 2
        theta0 = brentq(balance, 0.0, hi, xtol=1e-15, rtol=1e-15)
    return (theta0 + mat["prebend_angle_rad"]) / L


# --------------------------------------------------------------------------- beam


@dataclass(frozen=True)
class BeamShape:
    """A solved beam: angles, curvature and positions at the requested arc lengths."""

    s_m: np.ndarray
    angle_rad: np.ndarray
    curvature_per_m: np.ndarray
    positions_m: np.ndarray  # (M, 2)
    tip_position_m: np.ndarray
    tip_angle_rad: float


def solve_beam_bvp(length_m, ei_nm2, k0_per_m, force_n=(0.0, 0.0), load_n_per_m=(0.0, 0.0), s_m=None, tol=1e-7,
                   *, contact_s_m=None, base_compliance_rad_per_nm=0.0):
    """Solve ``EI φ'' = sin φ G_y − cos φ G_x``, ``G = F [s < s_c] + w (L − s)``, ``φ'(L) = K0``.

    The base is clamped (``φ(0) = 0``) or compliant: ``φ(0) = c M_b`` with ``c =
    base_compliance_rad_per_nm`` and ``M_b = EI (φ'(0) − K0)`` the moment the loads put on
    the base (positive when it bends toward ``+x``: the base turns with the load), so an
    unloaded arc keeps ``φ(0) = 0``.
    ``contact_s_m`` (default ``L``): the force acts at ``s_c``; beyond it the beam carries
    only its weight. The BVP is split exactly at ``s_c``: each part is mapped onto
    ``τ ∈ [0, 1]`` and the two are joined by continuity of ``φ``, ``φ'`` (the moment is
    continuous at a point force) and position, a two-point problem of 8 states.

    States ``(φ, φ', x, y)`` per part with ``x' = sin φ``, ``y' = cos φ``,
    ``x(0) = y(0) = 0``. Started from the free arc and continued in the load (0 → 1 in
    steps that halve on failure), so the solution is the branch connected to the unloaded
    shape.

    ``tol``: ``solve_bvp``'s relative residual tolerance. The default 1e-7 puts the
    coil angles within ~1e-10 rad of a 1e-9 solve (far below any sensor's noise); 1e-9
    is near what round-off lets the residual reach, and for some contact loads the mesh
    then grows for a minute (one frame took 52 s) where 1e-7 takes 10 ms.

    Raises
    ------
    RuntimeError
        If ``solve_bvp`` does not converge.
    """
    L, ei, k0 = float(length_m), float(ei_nm2), float(k0_per_m)
    sc = L if contact_s_m is None else float(contact_s_m)
    if not 0.0 < sc <= L:
        raise ValueError(f"contact_s_m: expected 0 < s_c <= L = {L}, got {sc}")
    comp = float(base_compliance_rad_per_nm)
    F = np.asarray(force_n, dtype=float)
    w = np.asarray(load_n_per_m, dtype=float)
    s_out = np.linspace(0.0, L, 41) if s_m is None else np.asarray(s_m, dtype=float)
    split = sc < L
    # part a: s = sc τ (force and weight), part b: s = sc + (L − sc) τ (weight only)
    parts = [(0.0, sc, 1.0)] + ([(sc, L - sc, 0.0)] if split else [])

    def make(scale):
        f, q = scale * F, scale * w

        def fun(tau, y):
            out = np.empty_like(y)
            for k, (s0, h, on) in enumerate(parts):
                s = s0 + h * tau
                gx = on * f[0] + q[0] * (L - s)
                gy = on * f[1] + q[1] * (L - s)
                z = y[4 * k: 4 * k + 4]
                sn, cs = np.sin(z[0]), np.cos(z[0])
                out[4 * k: 4 * k + 4] = h * np.vstack([z[1], (sn * gy - cs * gx) / ei, sn, cs])
            return out

        def jac(tau, y):
            out = np.zeros((y.shape[0], y.shape[0], tau.size))
            for k, (s0, h, on) in enumerate(parts):
                s = s0 + h * tau
                gx = on * f[0] + q[0] * (L - s)
                gy = on * f[1] + q[1] * (L - s)
                sn, cs = np.sin(y[4 * k]), np.cos(y[4 * k])
                i = 4 * k
                out[i, i + 1] = h
                out[i + 1, i] = h * (cs * gy + sn * gx) / ei
                out[i + 2, i] = h * cs
                out[i + 3, i] = -h * sn
            return out

        return fun, jac

    def bc(ya, yb):
        # compliant base: φ(0) − c EI (φ'(0) − K0) = 0
        res = [ya[0] - comp * ei * (ya[1] - k0), ya[2], ya[3]]
        if split:
            res += [yb[0] - ya[4], yb[1] - ya[5], yb[2] - ya[6], yb[3] - ya[7]]
        res.append(yb[-3] - k0)
        return np.array(res)

    n = 4 * len(parts)

    def bc_jac(ya, yb):
        da, db = np.zeros((n, n)), np.zeros((n, n))
        da[0, 0], da[0, 1] = 1.0, -comp * ei
        da[1, 2] = da[2, 3] = 1.0
        if split:
            for j in range(4):
                db[3 + j, j] = 1.0
                da[3 + j, 4 + j] = -1.0
        db[n - 1, n - 3] = 1.0
        return da, db

    tau_out = [np.clip((s_out - s0) / h, 0.0, 1.0) for s0, h, _ in parts]
    mesh = np.unique(np.concatenate([np.linspace(0.0, 1.0, 81), *tau_out]))
    mesh = mesh[np.concatenate([[True], np.diff(mesh) > 1e-9])]  # no near-duplicate nodes
    rows = []
    for s0, h, _ in parts:
        s = s0 + h * mesh
        arc = k0 * s
        with np.errstate(invalid="ignore", divide="ignore"):
            x0 = np.where(abs(k0) > 1e-12, (1 - np.cos(arc)) / (k0 if k0 else 1.0), 0.0)
            y0 = np.where(abs(k0) > 1e-12, np.sin(arc) / (k0 if k0 else 1.0), s)
        rows += [arc, np.full_like(mesh, k0), x0, y0]
    guess = np.vstack(rows)
    done, step, sol = 0.0, 1.0, None
    while done < 1.0:
        target = min(1.0, done + step)
        fun, jac = make(target)
        trial = solve_bvp(fun, bc, mesh, guess, fun_jac=jac, bc_jac=bc_jac, tol=tol, bc_tol=1e-12, max_nodes=200000)
        if trial.status == 0:
            done, sol = target, trial
            mesh = trial.x
            guess = trial.y
            step = min(1.0, 2 * step)
        else:
            step /= 2
            if step < 1e-3:
                raise RuntimeError(f"solve_bvp did not converge at load fraction {target:.4g}: {trial.message}")
    y = np.empty((4, s_out.size))
    for k in range(len(parts)):
        here = (s_out <= sc) if k == 0 else (s_out > sc)
        z = sol.sol(tau_out[k][here])[4 * k: 4 * k + 4]
        y[:, here] = z  # the states are φ and dφ/ds in both parts
    tip = sol.sol(1.0)[-4:]
    return BeamShape(
        s_m=s_out,
        angle_rad=y[0],
        curvature_per_m=y[1],
        positions_m=np.stack([y[2], y[3]], axis=-1),
        tip_position_m=np.array([tip[2], tip[3]]),
        tip_angle_rad=float(tip[0]),
    )


@dataclass(frozen=True)
class Truth:
    """The forward model's answer for one frame."""

    pressure_pa: float
    force_n: np.ndarray
    angles_rad: np.ndarray  # φ(L_i), (N,)
    shifts_m: np.ndarray  # S_i = d φ(L_i), (N,)
    positions_m: np.ndarray  # r(L_i), (N, 2)
    shape: BeamShape
    base_angle_rad: float = 0.0  # φ(0): the base's turn under load (a compliant base)


def forward(config, pressure_pa, force_n, *, material=None, stiffness=None, s_m=None, k0_scale=1.0,
            contact_s_m=None, base_compliance_rad_per_nm=0.0, tol=1e-7):
    """Exact sensor shifts of the beam at pressure P under the force F and gravity.

    ``material`` / ``stiffness``: mappings overriding the config's parameters (the
    "true" actuator differs from the identified one); ``k0_scale``: the true natural
    curvature is ``k0_scale K0(P)``. ``contact_s_m``: the force acts at ``s_c`` (default
    the tip). ``base_compliance_rad_per_nm``: the base turns by ``c M_b`` under the base
    moment (:func:`solve_beam_bvp`); the strips are pinned at the base and turn with it, so
    the sensor sees ``S_i = d (φ(L_i) − φ(0))`` and ``angles_rad`` are those relative angles.
    ``tol``: :func:`solve_beam_bvp`'s (1e-7 keeps the angles within ~1e-10 rad of 1e-9's, and is
    up to 20× faster on soft or heavily loaded beams).
    """
    stiff = dict(vars(config.stiffness))
    stiff.update(stiffness or {})
    ei = stiff["ei0_nm2"] + stiff["ei1_nm2_per_pa"] * float(pressure_pa)
    k0 = k0_scale * free_bending_k0(config, pressure_pa, material)
    ends = np.cumsum(config.sensor.lengths_m)
    s_all = np.unique(np.concatenate([ends, [0.0], [] if s_m is None else np.asarray(s_m, dtype=float)]))
    q = config.actuator.mass_kg * config.gravity.g_m_per_s2 / config.actuator.length_m
    shape = solve_beam_bvp(
        config.actuator.length_m, ei, k0, force_n, q * np.asarray(config.gravity.direction), s_m=s_all,
        contact_s_m=contact_s_m, base_compliance_rad_per_nm=base_compliance_rad_per_nm, tol=tol,
    )
    idx = np.searchsorted(shape.s_m, ends)
    base = float(shape.angle_rad[0])
    angles = shape.angle_rad[idx] - base
    return Truth(
        pressure_pa=float(pressure_pa),
        force_n=np.asarray(force_n, dtype=float),
        angles_rad=angles,
        shifts_m=config.sensor.strip_gap_m * angles,
        positions_m=shape.positions_m[idx],
        shape=shape,
        base_angle_rad=base,
    )


# --------------------------------------------------------------------------- hidden sensor


@dataclass(frozen=True)
class HiddenSensor:
    """Exact shifts → ADC-like signals, through a map the calibration does not know.

    ``ΔA_i = −g_odd h_odd(S_i / s0)`` for odd channels (1-based: the signal falls as the
    receiver moves toward the tip, paper Fig. 2(c)), ``+g_even h_even(S_i / s0)`` for
    even ones, with monotone non-polynomial ``h``; ``A = A0_i + ΔA + noise``.
    """

    noise_counts: float = 1.5
    n_channels: int = 16
    s0_m: float = 2e-3
    gain_odd: float = 5200.0
    gain_even: float = 4700.0
    wobble: float = 0.01
    seed: int = 0
    quantize: bool = False

    @property
    def offsets(self) -> np.ndarray:
        return 30000.0 + 400.0 * np.random.default_rng(self.seed).standard_normal(self.n_channels)

    def _h_odd(self, u):
        return u + 0.15 * u**2 - 0.05 * u**3 + self.wobble * np.sin(2 * u)

    def _h_even(self, u):
        return np.log1p(0.3 * u) / 0.3 + 0.5 * self.wobble * np.sin(2.5 * u)

    def delta(self, shifts_m) -> np.ndarray:
        """Noise-free offset-free signals ΔA (..., N) [counts] of the shifts S (..., N) [m]."""
        u = np.asarray(shifts_m, dtype=float) / self.s0_m
        odd = np.arange(self.n_channels) % 2 == 0
        return np.where(odd, -self.gain_odd * self._h_odd(u), self.gain_even * self._h_even(u))

    def signals(self, shifts_m, rng=None) -> np.ndarray:
        """Signals A (..., N) [counts] with Gaussian noise of ``noise_counts`` (and rounding if asked)."""
        a = self.offsets + self.delta(shifts_m)
        if self.noise_counts and rng is not None:
            a = a + self.noise_counts * rng.standard_normal(a.shape)
        return np.round(a) if self.quantize else a

    def write_calibration(self, directory, config, radii_m=None, frames=100, flat_frames=200, rng=None):
        """Write the flat and strip recordings (session CSV) and ``manifest.yaml``; return its path.

        Strip shifts are exact: ``S_i = κ_cal d L_i`` with ``κ_cal = 1/R`` or ``1/(R + c)``
        as the config's ``sensor.calibration_adds_sleeve`` states (DESIGN section 2).
        """
        import yaml

        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(self.seed + 1) if rng is None else rng
        sensor = config.sensor
        radii = [0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.10, 0.20, 0.30, 0.40] if radii_m is None else list(radii_m)
        extra = sensor.sleeve_thickness_m if sensor.calibration_adds_sleeve else 0.0
        cumulative = np.cumsum(sensor.lengths_m)

        def write(name, shifts, n):
            a = self.signals(np.tile(shifts, (n, 1)), rng)
            header = "t_s," + ",".join(f"ch{i + 1}" for i in range(self.n_channels))
            rows = [f"{k * 0.01!r}," + ",".join(repr(float(v)) for v in row) for k, row in enumerate(a)]
            (directory / name).write_text(header + "\n" + "\n".join(rows) + "\n", encoding="utf-8")

        write("flat.csv", np.zeros(self.n_channels), flat_frames)
        strips = []
        for r in radii:
            name = f"r{r * 1e3:06.2f}.csv"
            write(name, sensor.strip_gap_m * cumulative / (r + extra), frames)
            strips.append({"radius_m": float(r), "recording": name})
        manifest = directory / "manifest.yaml"
        manifest.write_text(yaml.safe_dump({"flat": "flat.csv", "strips": strips}), encoding="utf-8")
        return manifest


def free_sweep(config, n, *, nodes=13, p_max=110e3, **truth):
    """A free sweep 0 → ``p_max`` → 0 over ``n`` frames: pressures [Pa] and true coil angles [rad] (n, N).

    :func:`forward` at ``nodes`` Chebyshev–Lobatto pressures, interpolated in P (barycentric); ``truth``:
    :func:`forward`'s options of the true actuator (``k0_scale``, ``stiffness``, ...)."""
    from scipy.interpolate import BarycentricInterpolator

    x = 0.5 * (1 - np.cos(np.pi * np.arange(nodes) / (nodes - 1))) * p_max
    angles = np.array([forward(config, p, (0.0, 0.0), **truth).angles_rad for p in x])
    p = 0.5 * p_max * (1 - np.cos(2 * np.pi * np.arange(n) / n))
    return p, BarycentricInterpolator(x, angles)(p)
