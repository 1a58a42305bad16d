"""The paper's method, kept as the in-run baseline (paper section IV-C).

The shooting beam solver (``scipy.integrate.solve_ivp``) inside ``scipy.optimize.minimize``:
Nelder–Mead (MATLAB's fminsearch) on (Fx, Fy) for ``none``, SLSQP (fmincon) with the
equality constraint ``D⊥ · F = 0`` (and ``D · F ≥ 0`` for ``push_only``) otherwise; a
Python loop over frames.
"""

import numpy as np

from bendsense.mechanics.beam import solve_beam
from bendsense.status import Status

_PAPER_ODE_TOL = 1e-9
_PAPER_BOUND_N = 5.0  # far beyond what bends (or buckles) a soft actuator of this size


def paper_fit(problem, frames, D_all, Lc):
    """Shooting beam solver inside Nelder–Mead (free) or SLSQP (constrained), frame by frame.

    Each frame starts at ``u = max(0, lower)`` (zero force, where fminsearch/fmincon would).

    Parameters
    ----------
    problem : Problem
        The estimate's constants (:class:`~bendsense.estimation.problem.Problem`): the
        comparison arc lengths ``s`` and weights ``w``, the length ``L``, the distributed
        load ``wload``, the fixed force ``ffix`` and the bounds ``lower`` of ``u``.
    frames : Frames
        The frames' inputs (:class:`~bendsense.estimation.problem.Frames`): the reference
        points ``p0`` (B, M, 2) [m], ``ei`` (B,) [N·m²] and ``k0`` (B,) [1/m].
    D_all : ndarray, shape (B, 2, k)
        Each frame's constraint basis: ``F = ffix + D u``.
    Lc : float
        Length of the compared arc [m] (the objective is the mean squared distance in mm²).

    Returns
    -------
    u : ndarray, shape (B, k)
        The fitted force coordinates.
    status : ndarray of int, shape (B,)
        ``Status.OK`` or ``Status.NOT_CONVERGED`` per frame.
    nfev : ndarray of int, shape (B,)
        Objective evaluations per frame.
    """
    from scipy.optimize import minimize

    L, s, wq, wload, ffix, lower = problem.L, problem.s, problem.w, problem.wload, problem.ffix, problem.lower
    p0_all, ei_all, k0_all = frames.p0, frames.ei, frames.k0
    B, k = len(D_all), lower.size
    u0 = np.maximum(np.zeros((B, k)), lower)
    scale = 1.0 / (Lc * 1e-6)  # objective in mm² (mean squared distance)
    u_out = np.empty((B, k))
    status = np.full(B, int(Status.OK))
    nfev = np.zeros(B, dtype=int)
    for b in range(B):
        p0, D = p0_all[b], D_all[b]
        ei, k0 = float(ei_all[b]), float(k0_all[b])

        def objective(F, p0=p0, ei=ei, k0=k0):
            # the shooting solver at tolerances like MATLAB's ode45 would be used with,
            # tight enough for 1e-9 m shapes; its 1e-12 default is for the beam tests
            sol = solve_beam(L, ei, k0, F, wload, 0.0, s, method="shooting", warn=False,
                                   rtol=_PAPER_ODE_TOL, atol=_PAPER_ODE_TOL)
            if not sol.success:
                return 1e12
            d = sol.positions_m - p0
            return float(scale * (wq @ np.einsum("mi,mi->m", d, d)))

        x0 = ffix + D @ u0[b]
        if k == 2:
            res = minimize(objective, x0, method="Nelder-Mead",
                           options={"xatol": 1e-8, "fatol": 1e-16, "maxiter": 4000, "maxfev": 4000,
                                    "initial_simplex": x0 + np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]])})
            u_out[b] = D.T @ (res.x - ffix)
        else:
            d = D[:, 0]
            perp = np.array([-d[1], d[0]])
            cons = [{"type": "eq", "fun": lambda F, perp=perp, ffix=ffix: perp @ (F - ffix),
                     "jac": lambda F, perp=perp: perp}]
            if np.isfinite(lower[0]):
                cons.append({"type": "ineq", "fun": lambda F, d=d, ffix=ffix: d @ (F - ffix),
                             "jac": lambda F, d=d: d})
            # box bounds as fmincon would be given them: without them SLSQP's first line
            # search tries loads of hundreds of newtons, where every shooting solve fails slowly
            res = minimize(objective, x0, method="SLSQP", constraints=cons,
                           bounds=[(-_PAPER_BOUND_N, _PAPER_BOUND_N)] * 2, options={"ftol": 1e-14, "maxiter": 500})
            u_out[b] = [max(d @ (res.x - ffix), lower[0])]
        nfev[b] = res.nfev
        if not res.success and objective(ffix + D @ u_out[b]) >= 1e12:
            status[b] = Status.NOT_CONVERGED
        elif not res.success and k == 2:
            status[b] = Status.NOT_CONVERGED
    return u_out, status, nfev
