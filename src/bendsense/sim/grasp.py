"""A finger pressing an object: the contact force from the static equilibrium of the beam model.

The object, seen from one finger (:class:`GraspObject`), is given by where it touches the
finger, ``s_c`` (an arc length along the body), by when: the pressure ``p_touch`` at which
the free finger's point ``r(s_c)`` reaches it, and by its stiffness ``k`` (rigid: ``k =
∞``). Its face near the contact is the line through ``q = r_free(s_c; p_touch)``
perpendicular to ``n_0``, the finger's normal there at first touch (``n = (cos φ, −sin φ)``,
the side the finger bends to). The finger's point at ``s_c`` penetrates the face by

    d(P, f) = n_0 · (r(s_c; P, f) − q)

where ``r(s_c; P, f)`` is the finger at pressure ``P`` under a contact force of magnitude
``f`` normal to the finger at ``s_c`` (``F = f (−cos φ_c, sin φ_c)``, frictionless, as
bendsense's contact load model assumes; beyond ``s_c`` the finger bends freely under its
weight: :meth:`~bendsense.sim.actuator.SimulatedActuator.solve_contact`). The force is 0
while the free finger has not reached the face (``d(P, 0) <= 0``); otherwise it is the
root of ``d(P, f) = f / k`` (a compliant object gives way by ``f / k``; a rigid one not at
all: ``d = 0``). ``d`` falls with ``f`` (the force pushes the point back), so the root is
unique on the branch connected to the unloaded finger; it is found by bracketed secant
steps (Illinois), one batched beam solve per step over all pressures.

The force is normal to the finger, not to the face: the two differ by the finger's turn at
``s_c`` after first touch (the finger keeps curling around the contact), which is the
price of a fixed contact location.

:class:`FingerGrasp` tabulates the equilibrium over pressure once (force, the sensor's
noise-free readings) and interpolates it linearly per frame, so that a simulated board
with several fingers keeps up with 1 kHz; the table has a node at ``p_touch``, where the
force starts.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ConfigError
from bendsense.sim.actuator import SimulatedActuator, contact_number

__all__ = ["GraspObject", "FingerGrasp", "GraspState"]


@dataclass(frozen=True)
class GraspObject:
    """The object as one finger meets it.

    Attributes
    ----------
    contact_s_m : float
        Arc length s_c of the finger that touches the object [m], in ``(0, L]``.
    touch_pressure_pa : float
        Pressure at which the free finger's point at s_c reaches the object's face [Pa].
    stiffness_n_per_m : float
        Contact stiffness k [N/m]; ``math.inf``: a rigid object.
    """

    contact_s_m: float
    touch_pressure_pa: float
    stiffness_n_per_m: float = math.inf

    def __post_init__(self):
        p = self.touch_pressure_pa
        if isinstance(p, bool) or not isinstance(p, (int, float, np.integer, np.floating)) or not (
                math.isfinite(p) and p >= 0):
            raise ConfigError(f"touch_pressure_pa: must be a finite number >= 0, got {p!r}")
        k = self.stiffness_n_per_m
        if isinstance(k, bool) or not isinstance(k, (int, float, np.integer, np.floating)) or not (
                k > 0 and not math.isnan(k)):
            raise ConfigError(f"stiffness_n_per_m: must be a number > 0 (inf: rigid), got {k!r}")
        object.__setattr__(self, "touch_pressure_pa", float(p))
        object.__setattr__(self, "stiffness_n_per_m", float(k))

    @property
    def rigid(self) -> bool:
        """True for a rigid object (k = ∞)."""
        return math.isinf(self.stiffness_n_per_m)


@dataclass(frozen=True, eq=False)
class GraspState:
    """The equilibrium of a finger on the object, batched over pressures ``...``.

    Attributes
    ----------
    pressure_pa : ndarray, shape (...)
        Pressure [Pa].
    contact_n : ndarray, shape (...)
        Magnitude f of the contact force [N] (0 before touch).
    force_n : ndarray, shape (..., 2)
        Contact force in the base frame [N], normal to the finger at s_c.
    penetration_m : ndarray, shape (...)
        d = n_0 · (r(s_c) − q) [m]: f / k in contact, <= 0 before touch.
    contact_position_m : ndarray, shape (..., 2)
        The finger's point r(s_c) [m].
    contact_angle_rad : ndarray, shape (...)
        The finger's tangent angle φ(s_c) [rad].
    solution : BeamSolution
        The loaded finger on the simulator's grid (the sensor's points, then the tip).
    valid : ndarray of bool, shape (...)
        The beam solves converged.
    """

    pressure_pa: np.ndarray
    contact_n: np.ndarray
    force_n: np.ndarray
    penetration_m: np.ndarray
    contact_position_m: np.ndarray
    contact_angle_rad: np.ndarray
    solution: object
    valid: np.ndarray


class FingerGrasp:
    """One finger of the simulated gripper on its object: exact equilibrium and its table over pressure.

    Parameters
    ----------
    actuator : SimulatedActuator
        The true finger with its sensor.
    obj : GraspObject or None
        The object as this finger meets it; None: a free finger (no object, force 0).
    max_pressure_pa : float
        Highest pressure of the table [Pa] (the regulators' limit).
    step_pa : float
        Node spacing of the table [Pa].
    tol_m : float
        The root solve stops when ``|d − f/k| < tol_m`` [m].

    Attributes
    ----------
    contact_s_m : float
        s_c [m]; NaN for a free finger.
    surface_point_m : ndarray, shape (2,)
        q, the free finger's point at s_c at the touch pressure [m] (None for a free finger).
    surface_normal : ndarray, shape (2,)
        n_0, the finger's normal there (pointing into the object; None for a free finger).
    table_pressure_pa : ndarray, shape (G,)
        Nodes of the table [Pa].
    table_force_n : ndarray, shape (G, 2)
        Contact force at the nodes [N].
    table_signal_counts : ndarray, shape (G, N)
        The sensor's noise-free, unquantised readings at the nodes [counts].

    Raises
    ------
    ConfigError
        If the equilibrium is not found at some pressure of the table.
    """

    def __init__(self, actuator: SimulatedActuator, obj: GraspObject, *, max_pressure_pa: float = 120e3,
                 step_pa: float = 500.0, tol_m: float = 1e-9):
        self.actuator = actuator
        self.object = obj
        self.tol_m = float(tol_m)
        n = max(2, math.ceil(max_pressure_pa / step_pa) + 1)
        nodes = np.linspace(0.0, max_pressure_pa, n)
        self.contact_s_m, self.surface_point_m, self.surface_normal = math.nan, None, None
        self._grid = actuator._s_beam
        if obj is not None:
            self.contact_s_m = contact_number(obj.contact_s_m, actuator.config.actuator.length_m)
            if not obj.touch_pressure_pa <= max_pressure_pa:
                raise ConfigError(f"touch_pressure_pa: {obj.touch_pressure_pa:g} Pa is above the pressure limit "
                                  f"{max_pressure_pa:g} Pa: the finger would never touch the object")
            self._grid = np.append(actuator._s_beam, self.contact_s_m)
            free = actuator.solve(obj.touch_pressure_pa, (0.0, 0.0), s_m=self._grid)
            phi0 = float(free.angle_rad[-1])
            self.surface_point_m = np.array(free.positions_m[-1], dtype=float)
            self.surface_normal = np.array([math.cos(phi0), -math.sin(phi0)])
            nodes = np.union1d(nodes, [obj.touch_pressure_pa])
        state = self.solve(nodes)
        if not state.valid.all():  # never a table with holes: a force that drops to 0 would be a lie
            bad = nodes[~state.valid]
            where = "free" if obj is None else (f"on the object (s_c = {self.contact_s_m:g} m, touch at "
                                                f"{obj.touch_pressure_pa / 1e3:g} kPa)")
            raise ConfigError(f"object: no equilibrium of the finger {where} at {bad.size} pressures from "
                              f"{bad[0] / 1e3:g} kPa; lower the pressure limit or move the object")
        self.table_pressure_pa = nodes
        self.table_force_n = state.force_n
        self.table_valid = state.valid
        frames = actuator.frames(nodes, state.force_n, solution=state.solution, noise=False)
        self.table_signal_counts = actuator.sensor.signal(frames.shifts_m)
        # per-frame lookups of one pressure (the board's): plain floats and slopes, no array bookkeeping
        self._nodes = nodes.tolist()
        self._force_rows = [(float(fx), float(fy)) for fx, fy in self.table_force_n]
        self._force_slopes = [(float(a), float(b)) for a, b in np.diff(self.table_force_n, axis=0)]
        self._signal_slopes = np.diff(self.table_signal_counts, axis=0)

    # ------------------------------------------------------------------ exact

    def _loaded(self, pressure_pa, contact_n):
        """The finger under a normal contact force f at s_c: (solution, penetration)."""
        _, sol = self.actuator.solve_contact(pressure_pa, contact_n, contact_s_m=self.contact_s_m, s_m=self._grid)
        d = (np.asarray(sol.positions_m)[..., -1, :] - self.surface_point_m) @ self.surface_normal
        return sol, d

    def solve(self, pressure_pa) -> GraspState:
        """The exact equilibrium at these pressures (one root solve in f, batched).

        Parameters
        ----------
        pressure_pa : array_like, shape (P,)
            Pressures [Pa].

        Returns
        -------
        GraspState
        """
        p = np.atleast_1d(np.asarray(pressure_pa, dtype=float))
        f = np.zeros_like(p)
        if self.object is None:  # a free finger: no contact
            sol = self.actuator.solve(p, (0.0, 0.0), s_m=self._grid)
            nan = np.full_like(p, np.nan)
            return GraspState(pressure_pa=p, contact_n=f, force_n=np.zeros((p.size, 2)), penetration_m=nan,
                              contact_position_m=np.full((p.size, 2), np.nan), contact_angle_rad=nan, solution=sol,
                              valid=np.asarray(sol.success))
        sol0, d0 = self._loaded(p, np.zeros_like(p))
        touching = np.flatnonzero(d0 > 0)
        if touching.size:
            f[touching] = self._root(p[touching], d0[touching], self.object.stiffness_n_per_m)
        ok = np.isfinite(f)
        f = np.where(ok, f, 0.0)
        sol, d = self._loaded(p, f)
        phi = np.asarray(sol.angle_rad)[:, -1]
        force = f[:, None] * np.stack([-np.cos(phi), np.sin(phi)], axis=-1)
        return GraspState(
            pressure_pa=p, contact_n=f, force_n=force, penetration_m=d,
            contact_position_m=np.asarray(sol.positions_m)[:, -1, :], contact_angle_rad=phi,
            solution=sol, valid=np.asarray(sol.success) & ok,
        )

    def _gap(self, p, f, inv_k) -> np.ndarray:
        """g(f) = d(P, f) − f/k [m]; NaN where the beam solve failed."""
        sol, d = self._loaded(p, f)
        return np.where(np.asarray(sol.success), d - f * inv_k, np.nan)

    def _root(self, p, d0, k, max_iter: int = 60) -> np.ndarray:
        """The force f > 0 with g(f) = d(P, f) − f/k = 0, bracketed from g(0) = d0 > 0 (Illinois steps).

        A failed beam solve counts as beyond the root (the force was too large): the
        bracket's upper end moves down to it.
        """
        inv_k = 0.0 if math.isinf(k) else 1.0 / k
        # compliance of the point along n_0 under a small force: the first guess of the upper end
        probe = np.full_like(p, 1e-3)
        compliance = np.maximum((d0 - self._gap(p, probe, 0.0)) / probe, 1e-3)
        compliance = np.where(np.isfinite(compliance), compliance, 1e-3)
        lo, glo = np.zeros_like(p), d0.copy()
        hi = d0 / (compliance + inv_k)
        ghi = self._gap(p, hi, inv_k)
        for _ in range(40):  # widen (still short of the root) or shrink (solve failed) until g(hi) <= 0
            out, failed = ghi > 0, np.isnan(ghi)
            if not (out.any() or failed.any()):
                break
            lo[out], glo[out] = hi[out], ghi[out]
            hi[out] *= 1.5
            hi[failed] = lo[failed] + 0.5 * (hi[failed] - lo[failed])
            redo = out | failed
            ghi[redo] = self._gap(p[redo], hi[redo], inv_k)
        f = np.full_like(p, np.nan)
        side = np.zeros(p.shape, dtype=int)
        todo = np.flatnonzero(ghi <= 0)
        for _ in range(max_iter):
            if todo.size == 0:
                break
            a, b, ga, gb = lo[todo], hi[todo], glo[todo], ghi[todo]
            x = b - gb * (b - a) / (gb - ga)
            gx = self._gap(p[todo], x, inv_k)
            failed = np.isnan(gx)
            gx = np.where(failed, -np.inf, gx)  # beyond the root: the upper end
            f[todo] = np.where(failed, np.nan, x)
            done = np.abs(gx) < self.tol_m
            left = gx > 0  # the root is in (x, b]
            lo[todo[left]], glo[todo[left]] = x[left], gx[left]
            hi[todo[~left]] = x[~left]
            ghi[todo[~left]] = np.where(failed[~left], 0.5 * gb[~left], gx[~left])
            # Illinois: halve the stale end's value when the same end moved twice
            ghi[todo[left & (side[todo] == 1)]] *= 0.5
            glo[todo[~left & (side[todo] == -1)]] *= 0.5
            side[todo] = np.where(left, 1, -1)
            todo = todo[~done]
        f[todo] = np.nan
        return f

    # ------------------------------------------------------------------ table

    def lookup_one(self, pressure_pa: float):
        """Interpolate the table at one pressure (:meth:`lookup` for the board's per-frame path).

        Parameters
        ----------
        pressure_pa : float
            Pressure [Pa], clipped to the table's range.

        Returns
        -------
        fx_n, fy_n : float
            Contact force [N].
        signal_counts : ndarray, shape (N,)
            The sensor's noise-free readings [counts].
        """
        nodes = self._nodes
        x = min(max(float(pressure_pa), nodes[0]), nodes[-1])
        i = min(max(bisect.bisect_right(nodes, x) - 1, 0), len(nodes) - 2)
        w = (x - nodes[i]) / (nodes[i + 1] - nodes[i])
        (fx, fy), (dx, dy) = self._force_rows[i], self._force_slopes[i]
        return fx + w * dx, fy + w * dy, self.table_signal_counts[i] + w * self._signal_slopes[i]

    def lookup(self, pressure_pa):
        """Interpolate the table at these pressures.

        Parameters
        ----------
        pressure_pa : array_like, shape (...)
            Pressures [Pa], clipped to the table's range.

        Returns
        -------
        force_n : ndarray, shape (..., 2)
            Contact force [N].
        signal_counts : ndarray, shape (..., N)
            The sensor's noise-free readings [counts] (noise and quantisation not applied).
        """
        p = np.asarray(pressure_pa, dtype=float)
        nodes = self.table_pressure_pa
        x = np.clip(p, nodes[0], nodes[-1])
        i = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
        w = ((x - nodes[i]) / (nodes[i + 1] - nodes[i]))[..., None]
        force = self.table_force_n[i] * (1.0 - w) + self.table_force_n[i + 1] * w
        signal = self.table_signal_counts[i] * (1.0 - w) + self.table_signal_counts[i + 1] * w
        return force, signal
