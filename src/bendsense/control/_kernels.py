"""The control loop's per-frame arithmetic, compiled: a loop calls it for every finger and block.

:func:`normal_components` is :func:`bendsense.control.force.normal_force`'s arithmetic,
frame by frame: a block of one frame costs a call, not the ~40 numpy operations (~35 µs)
of the same formulas on arrays of one element.
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit


@njit(cache=True, nogil=True)
def normal_components(s_grid, s_c, angle, force, cov, tip_s, value, std, s_out, phi):
    """N = F · n and its σ at each frame's contact (module :mod:`bendsense.control.force`), into the outputs (n,).

    ``s_grid`` (M,) the shapes' arc lengths, ``angle`` (n, M) their tangent angles (linear
    between the points); ``s_c`` (n,) the contact location [m] (NaN: the end of the grid,
    reported as ``tip_s``); ``force`` (n, 2), ``cov`` (n, 2, 2) the force and its
    covariance. Writes N, sqrt(nᵀ C n), the location reported and φ_c.
    """
    m = s_grid.size
    length = s_grid[m - 1]
    for i in range(s_c.size):
        located = math.isfinite(s_c[i])
        at = min(s_c[i], length) if located else length
        j = min(max(np.searchsorted(s_grid, at, side="right") - 1, 0), m - 2)
        w = (at - s_grid[j]) / (s_grid[j + 1] - s_grid[j])
        a = (1.0 - w) * angle[i, j] + w * angle[i, j + 1]
        nx, ny = -math.cos(a), math.sin(a)
        value[i] = force[i, 0] * nx + force[i, 1] * ny
        var = cov[i, 0, 0] * nx * nx + (cov[i, 0, 1] + cov[i, 1, 0]) * nx * ny + cov[i, 1, 1] * ny * ny
        std[i] = math.sqrt(0.0 if var < 0.0 else var)  # NaN stays NaN: a frame without a force
        s_out[i] = s_c[i] if located else tip_s
        phi[i] = a


def warm() -> None:
    """Compile or load :func:`normal_components` for the arrays a live block gives (a controller, before its loop)."""
    one = np.zeros(1)
    _jit.call(normal_components, np.linspace(0.0, 1.0, 3), np.full(1, np.nan), np.zeros((1, 3)), np.zeros((1, 2)),
              np.zeros((1, 2, 2)), 1.0, one, one.copy(), one.copy(), one.copy())


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
