"""The status rules of a frame, compiled: one definition for the offline outputs and the live step.

:func:`estimate_code`, :func:`frame_code` and :func:`track_code` decide one frame's code
(:class:`bendsense.status.Status`); the ``*_codes_into`` kernels apply them to every frame
of a batch for :func:`bendsense.results.estimate_codes`, :func:`bendsense.results.frame_codes`
and :func:`bendsense.tracking.track.track_status`, and the live step
(:func:`bendsense.pipeline._kernels.live_block`) calls them per frame.
"""

import math

import numpy as np
from numba import njit

from bendsense import _jit
from bendsense.status import MISFIT_P, Status

_OK = int(Status.OK)
_NOT_IDENTIFIABLE = int(Status.NOT_IDENTIFIABLE)
_CONTACT_UNRESOLVED = int(Status.CONTACT_UNRESOLVED)
_NOT_CONVERGED = int(Status.NOT_CONVERGED)
_NO_FORCE = int(Status.NO_FORCE)
_MODEL_MISFIT = int(Status.MODEL_MISFIT)
_EXTRAPOLATED = int(Status.EXTRAPOLATED)
_NO_SHAPE = int(Status.NO_SHAPE)
_IMPLAUSIBLE_SHAPE = int(Status.IMPLAUSIBLE_SHAPE)
_TURN = 2.0 * math.pi


@njit(cache=True)
def estimate_code(status, success, fx, fy, unresolved):
    """A frame's status code from its estimate alone (:func:`bendsense.results.estimate_codes`).

    Its own status; ``NOT_CONVERGED`` for a failed frame whose code reads as a success,
    ``NO_FORCE`` for an ``OK`` frame without a finite force, ``CONTACT_UNRESOLVED`` for an
    ``OK`` frame whose contact location the data cannot place.
    """
    code = status
    if not success and (code == _OK or code == _NOT_IDENTIFIABLE or code == _CONTACT_UNRESOLVED):
        code = _NOT_CONVERGED
    if code == _OK and not (math.isfinite(fx) and math.isfinite(fy)):
        code = _NO_FORCE
    if code == _OK and unresolved:
        code = _CONTACT_UNRESOLVED
    return code


@njit(cache=True)
def frame_code(extrapolated, shape_finite, tip_angle, has_estimate, own, success):
    """A frame's status code (:func:`bendsense.results.frame_codes`): the shape's, then the estimate's ``own``.

    ``EXTRAPOLATED``, the estimate's code where the shape is ok or the estimate failed,
    ``NO_SHAPE`` (a non-finite curvature: nothing to estimate from) and
    ``IMPLAUSIBLE_SHAPE`` (a tip turned by more than a full turn) over all.
    """
    code = _OK
    if extrapolated:
        code = _EXTRAPOLATED
    if has_estimate and (not success or code == _OK):
        code = own
    if not shape_finite:  # nothing to estimate from
        code = _NO_SHAPE
    if abs(tip_angle) > _TURN:
        code = _IMPLAUSIBLE_SHAPE
    return code


@njit(cache=True)
def track_code(own, window_p, fx, fy, sx, sy):
    """A tracked frame's status (:func:`bendsense.tracking.track.track_status`): its own, or what the track adds."""
    if own != _OK:
        return own
    if window_p < MISFIT_P:
        return _MODEL_MISFIT
    if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(sx) and math.isfinite(sy)):
        return _NO_FORCE
    return own


@njit(cache=True)
def estimate_codes_into(status, success, force, unresolved, out):
    """:func:`estimate_code` of every frame: ``status``, ``success``, ``unresolved`` (n,), ``force`` (n, 2)."""
    for i in range(out.size):
        out[i] = estimate_code(status[i], success[i], force[i, 0], force[i, 1], unresolved[i])


@njit(cache=True)
def frame_codes_into(extrapolated, kappa, tip_angle, has_estimate, own, success, out):
    """:func:`frame_code` of every frame: ``kappa`` (n, N), the others (n,) (``own``, ``success``: with an estimate)."""
    for i in range(out.size):
        finite = True
        for j in range(kappa.shape[1]):
            finite = finite and math.isfinite(kappa[i, j])
        out[i] = frame_code(extrapolated[i], finite, tip_angle[i], has_estimate, own[i], success[i])


@njit(cache=True)
def track_codes_into(own, window_p, force, std, out):
    """:func:`track_code` of every frame: ``own``, ``window_p`` (n,), ``force`` and ``std`` (n, 2)."""
    for i in range(out.size):
        out[i] = track_code(own[i], window_p[i], force[i, 0], force[i, 1], std[i, 0], std[i, 1])


def compile_kernels() -> None:
    """Compile (or load from the cache) the batch kernels, with the types :mod:`bendsense.results` calls them with.

    ``bendsense demo`` calls it while the estimation kernels compile in a second process.
    """
    codes, ok, one = np.zeros(1, dtype=np.int8), np.zeros(1, dtype=bool), np.zeros(1)
    _jit.call(estimate_codes_into, codes, ok, np.zeros((1, 2)), ok, np.empty(1, dtype=np.int8))
    _jit.call(frame_codes_into, ok, np.zeros((1, 1)), one, True, codes, ok, np.empty(1, dtype=np.int8))
    _jit.call(track_codes_into, codes, one, np.zeros((1, 2)), np.zeros((1, 2)), np.empty(1, dtype=np.int8))


_jit.guard_cache(globals())  # no two processes write these kernels to numba's cache at once
