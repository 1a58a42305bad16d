"""A finger pressing a rigid object: the contact force of the model at each pressure after first touch.

The finger (its config's actuator: natural curvature K0(P), stiffness EI(P), its weight)
meets a rigid object at the arc length ``s_c`` when the pressure reaches ``P_c``: the
object's face is the line through the free finger's point ``q = r(s_c; P_c, 0)``,
perpendicular to its normal there, ``n_0 = (cos φ_0, −sin φ_0)`` (the side it bends to).
At a higher pressure ``P`` the face holds the point back with a force ``f`` normal to the
finger at ``s_c`` (frictionless: ``F = −f n(φ_c)``, the object's push, DESIGN.md's contact
load), and ``f`` is the root of the penetration

    d(P, f) = n_0 · (r(s_c; P, −f n(φ_c)) − q) = 0.

Newton steps on ``f`` with the compliance ``−∂d/∂f = n_0 · (∂r/∂F) n(φ_c)`` from the beam
solver's own sensitivities, the force's direction following the finger's angle φ_c at each
step; all pressures in one batched solve per step. A few steps converge to 1e-6 N: the
equilibrium is smooth and starts at ``f = 0``.

This is what a force controller that knows the finger expects (:class:`bendsense.control.ModelController`:
its feed-forward): the force rises with the pressure beyond first touch at a slope that
depends on where the object is (closer to the base: stiffer) and on ``P_c``. The simulator
(:class:`bendsense.sim.grasp.FingerGrasp`) solves the same equilibrium for its true finger,
compliant objects included, with a bracketed root: the tests compare the two.
"""

from __future__ import annotations

import numpy as np

from bendsense.errors import ArgumentError

__all__ = ["pressing_force"]

#: Newton stops when a step changes the force by less than this [N]
FORCE_TOL_N = 1e-6
#: Newton steps at most
MAX_STEPS = 30


def pressing_force(config, contact_s_m: float, touch_pressure_pa, pressure_pa) -> np.ndarray:
    """The normal force f [N] with which the config's finger presses a rigid object it first touched at P_c.

    Parameters
    ----------
    config : Config
        The finger's actuator (free bending, stiffness, weight).
    contact_s_m : float
        Arc length s_c where the object touches the finger [m], ``0 < s_c <= L``.
    touch_pressure_pa : array_like, shape (G,)
        First-touch pressures P_c [Pa].
    pressure_pa : array_like, shape (G, J) or (J,)
        Pressures P [Pa] per touch pressure (broadcast against ``(G, 1)``); ``P <= P_c``
        gives 0.

    Returns
    -------
    ndarray, shape (G, J)
        f >= 0 [N]; NaN where the model has no stable equilibrium (a force beyond buckling,
        a pressure outside the actuator's range).
    """
    from bendsense.mechanics.actuator import FreeBendingModel
    from bendsense.mechanics.beam import solve_beam

    length = config.actuator.length_m
    if not 0.0 < float(contact_s_m) <= length:
        raise ArgumentError(f"contact_s_m: expected 0 < s_c <= L = {length:g} m, got {contact_s_m!r}")
    pc = np.atleast_1d(np.asarray(touch_pressure_pa, dtype=float))
    p = np.broadcast_to(np.asarray(pressure_pa, dtype=float), np.broadcast_shapes(
        pc[:, None].shape, np.shape(pressure_pa))).copy()
    bending = FreeBendingModel.from_config(config)
    s_m = np.array([float(contact_s_m)])

    def solve(pressure, force, sensitivities=False):  # a failed solve is a NaN of the result, not a warning
        return solve_beam(length, config.stiffness.ei_nm2(pressure), bending.tip_curvature_per_m(pressure), force,
                          config.weight_per_length_n_per_m, 0.0, s_m=s_m, contact_s_m=float(contact_s_m),
                          sensitivities=sensitivities, warn=False)

    free = solve(pc, np.zeros((pc.size, 2)))
    g, j = p.shape
    q = np.repeat(free.positions_m[:, 0], j, axis=0)
    phi0 = np.repeat(free.angle_rad[:, 0], j)
    n0 = np.stack((np.cos(phi0), -np.sin(phi0)), axis=-1)  # into the object
    flat = p.reshape(-1)
    f = np.zeros(flat.size)
    todo = np.flatnonzero(flat > np.repeat(pc, j))  # beyond the touch: still to solve
    direction = n0.copy()  # n(φ_c): the object's push is −f n
    for _ in range(MAX_STEPS):
        if todo.size == 0:
            break
        sol = solve(flat[todo], -f[todo, None] * direction[todo], sensitivities=True)
        ok = np.asarray(sol.success)
        d = np.sum((sol.positions_m[:, 0] - q[todo]) * n0[todo], axis=-1)
        compliance = np.einsum("ki,kij,kj->k", n0[todo], sol.dpositions_dforce[:, 0], direction[todo])
        step = d / compliance
        f[todo] = np.where(ok, np.maximum(f[todo] + step, 0.0), np.nan)
        phi = sol.angle_rad[:, 0]
        direction[todo] = np.stack((np.cos(phi), -np.sin(phi)), axis=-1)
        todo = todo[ok & ~(np.abs(step) < FORCE_TOL_N)]
    f[todo] = np.nan  # not converged
    return f.reshape(g, j)
