"""The curved cantilever under a tip force, solved by bendsense and by the exact elastica.

Run it as a script::

    python examples/beam_solver.py --out figures

The actuator under pressure is a cantilever with natural curvature K0 (paper eq.
13–16, DESIGN section 2): ``EI φ'' = sin φ · Fy − cos φ · Fx``, ``φ(0) = 0``,
``φ'(L) = K0``. Without a distributed load the equation has a first integral,

    φ'(s)² = K0² + (2 / EI) [Fy (cos φ_L − cos φ) + Fx (sin φ_L − sin φ)],

so as long as the curvature keeps its sign the exact shape is a quadrature over the
angle: ``s(φ) = ∫₀^φ dψ / φ'(ψ)``, ``x(φ) = ∫ sin ψ / φ'(ψ) dψ``, ``y(φ) = ∫ cos ψ / φ'(ψ) dψ``,
with the tip angle φ_L the root of ``s(φ_L) = L``. This script computes that exact
elastica with adaptive quadrature and compares the tip with ``bendsense.solve_beam``
(the fast spectral solver, and the paper's shooting method), then plots the shapes.
"""

# %% Set-up
import argparse
import math
import tempfile
import time
from pathlib import Path

import matplotlib

if __name__ == "__main__" and matplotlib.get_backend().lower() not in ("agg", "pdf", "svg"):
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq

import bendsense

parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
parser.add_argument("--out", type=Path, default=None, help="output directory (default: a new temporary one)")
args, _ = parser.parse_known_args()
out = args.out if args.out is not None else Path(tempfile.mkdtemp(prefix="bendsense-example-"))
out.mkdir(parents=True, exist_ok=True)

# %% The actuator at 60 kPa (paper's prototype)
config = bendsense.load_config()
from bendsense.mechanics.actuator import FreeBendingModel  # noqa: E402  (kept next to its use in a cell)

pressure_pa = 60e3
length_m = config.actuator.length_m
ei = float(config.stiffness.ei_nm2(pressure_pa))
k0 = float(FreeBendingModel.from_config(config).tip_curvature_per_m(pressure_pa))
print(f"L = {length_m * 1e3:.0f} mm, EI = {ei:.5f} N m^2, K0 = {k0:.3f} 1/m (free bending angle "
      f"{math.degrees(k0 * length_m):.1f} deg)")

# Tip forces [N] in the base frame: along +x bends further, along -x straightens, and
# two oblique loads. Each keeps the curvature positive along the beam (checked below).
forces = np.array([(0.0, 0.0), (0.2, 0.0), (-0.05, 0.0), (0.1, -0.1), (-0.1, 0.1), (0.05, 0.2)])


# %% The exact elastica by quadrature
def curvature_squared(psi, phi_tip, force):
    """φ'(ψ)² from the first integral [1/m²]."""
    fx, fy = force
    return k0**2 + 2.0 / ei * (fy * (math.cos(phi_tip) - math.cos(psi)) + fx * (math.sin(phi_tip) - math.sin(psi)))


def integral(fun, phi_tip, force):
    """∫₀^φ_L fun(ψ) / φ'(ψ) dψ."""
    value, _ = quad(lambda p: fun(p) / math.sqrt(curvature_squared(p, phi_tip, force)), 0.0, phi_tip,
                    epsabs=1e-15, epsrel=1e-13, limit=200)
    return value


def exact_point(phi, phi_tip, force):
    """Position (x, y) [m] of the point with tangent angle φ on the exact elastica."""
    inv = lambda p: 1.0 / math.sqrt(curvature_squared(p, phi_tip, force))  # noqa: E731
    return [quad(lambda p: math.sin(p) * inv(p), 0.0, phi, epsabs=1e-15, limit=200)[0],
            quad(lambda p: math.cos(p) * inv(p), 0.0, phi, epsabs=1e-15, limit=200)[0]]


def exact_tip(force):
    """Tip position (x, y) [m] and angle φ_L [rad] of the exact elastica."""

    def excess_length(phi_tip):
        if min(curvature_squared(p, phi_tip, force) for p in np.linspace(0, phi_tip, 201)) <= 0:
            return math.inf  # the curvature would change sign: outside this formula's reach
        return integral(lambda p: 1.0, phi_tip, force) - length_m

    # bracket the tip angle around the free arc's
    lo, hi = 0.2 * k0 * length_m, min(2.5 * k0 * length_m, 3.0)
    grid = np.linspace(lo, hi, 60)
    values = [excess_length(p) for p in grid]
    i = next(i for i in range(len(grid) - 1) if np.isfinite(values[i]) and np.isfinite(values[i + 1])
             and values[i] * values[i + 1] <= 0)
    phi_tip = brentq(excess_length, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15)
    return np.array([integral(math.sin, phi_tip, force), integral(math.cos, phi_tip, force)]), phi_tip


exact = [exact_tip(f) for f in forces]
exact_pos = np.array([e[0] for e in exact])
exact_angle = np.array([e[1] for e in exact])

# %% bendsense: the fast solver (one batched call) and the paper's shooting method
t0 = time.perf_counter()
fast = bendsense.solve_beam(length_m, ei, k0, force_n=forces)
t_fast = time.perf_counter() - t0
t0 = time.perf_counter()
shooting = bendsense.solve_beam(length_m, ei, k0, force_n=forces, method="shooting")
t_shoot = time.perf_counter() - t0

print(f"{'force [N]':>16} {'tip angle [deg]':>16} {'fast |dr|/L':>12} {'shooting |dr|/L':>16}")
for f, pos, ang, rf, rs in zip(forces, exact_pos, exact_angle, fast.tip_position_m, shooting.tip_position_m):
    print(f"{f[0]:7.2f} {f[1]:7.2f}  {math.degrees(ang):16.4f} {np.linalg.norm(rf - pos) / length_m:12.2e} "
          f"{np.linalg.norm(rs - pos) / length_m:16.2e}")
worst = np.max(np.linalg.norm(fast.tip_position_m - exact_pos, axis=-1)) / length_m
print(f"fast solver: worst tip error {worst:.1e} L (target 1e-6 L), all converged: {bool(np.all(fast.success))}, "
      f"{t_fast * 1e3:.1f} ms for {len(forces)} load cases; shooting {t_shoot * 1e3:.0f} ms")

# %% Plot: the solver's shapes with the exact elastica's points along them
fig, ax = plt.subplots(figsize=(5.5, 5.5), layout="constrained")
for k, (f, sol) in enumerate(zip(forces, fast.positions_m)):
    line, = ax.plot(sol[:, 0] * 1e3, sol[:, 1] * 1e3, label=f"F = ({f[0]:g}, {f[1]:g}) N")
    # exact points at ten angles along the elastica
    phis = np.linspace(0.0, exact_angle[k], 10)[1:]
    pts = np.array([exact_point(p, exact_angle[k], f) for p in phis])
    ax.plot(pts[:, 0] * 1e3, pts[:, 1] * 1e3, "o", color=line.get_color(), markersize=4, markerfacecolor="none")
    tip = sol[-1] * 1e3
    head = tip + 150.0 * f  # the force as an arrow, 150 mm per N
    ax.annotate("", xy=head, xytext=tip, arrowprops={"arrowstyle": "->", "color": line.get_color()})
    ax.update_datalim([head])
ax.plot([0], [0], "ks")
ax.autoscale_view()
ax.set_aspect("equal")
ax.set_xlabel("x [mm]")
ax.set_ylabel("y [mm]")
ax.set_title(f"curved cantilever at {pressure_pa / 1e3:g} kPa: solver (lines), exact elastica (circles),\n"
             "tip force (150 mm per N)", fontsize="small")
ax.legend(fontsize="x-small", loc="lower right")
fig.savefig(out / "beam_vs_elastica.png", dpi=120)
print(f"wrote {out / 'beam_vs_elastica.png'}")
