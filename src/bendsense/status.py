"""Per-frame status: one integer code per frame, its word in results.csv and its label.

The compiled kernels write the codes of the beam solver and the force estimator; the
estimator's checks at the edges (the pressure range, the force bound, a contact the
data cannot place) and the reconstruction (a signal outside the calibrated range, a
shape from non-finite signals) add theirs. :attr:`ForceEstimate.status
<bendsense.ForceEstimate>`, :attr:`Track.status <bendsense.Track>` and a live block's
statuses are arrays of these codes; :func:`words` turns them into the ``status`` column
of results.csv (DESIGN.md section 3) and :data:`LABELS` into what a person reads.
Messages (``ForceEstimate.message``) say more about a frame, for people: nothing
parses them.

Several codes share a word: the beam solver's reasons a force estimate failed are all
``not_converged`` in results.csv (the message tells them apart).
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

__all__ = ["Status", "LABELS", "WORDS", "words", "code_of", "MISFIT_P"]

#: χ² p-value below which a converged fit, or a window of frames, is ``model_misfit``
MISFIT_P = 1e-3


class Status(IntEnum):
    """Outcome of one frame: the beam solve, the force estimate, the shape, the checks around them."""

    RUNNING = 0
    #: converged to a stable equilibrium (beam) or to the best-fitting force (estimate)
    OK = 1
    #: beam: the equilibrium loses stability along the load path (buckling)
    UNSTABLE = 2
    #: beam: the branch from the unloaded shape ends (limit point) or Newton failed
    LOST_BRANCH = 3
    #: beam: a warm start beyond the convexity bound landed on an unstable equilibrium
    WARM_UNSTABLE = 4
    #: estimate: the beam model fails at every trial force
    BEAM_FAILED = 5
    #: estimate: no convergence within the iteration limit (or the trust region collapsed)
    NOT_CONVERGED = 6
    #: estimate: stopped at the stability boundary, the load along one direction is not
    #: identifiable (a success, with std inf along that direction)
    NOT_IDENTIFIABLE = 7
    #: estimate: stopped at the stability boundary far from the shape (a failure)
    NO_STABLE_MATCH = 8
    #: estimate: converged, but the model shape stays far from the measured one (over 5 % of
    #: the length), or a χ² beyond chance: the force is reported, not ok
    MODEL_MISFIT = 9
    #: estimate (load="contact", location estimated): the force is reported, but the data cannot place the
    #: contact (its σ beyond one segment length, or the force nearly along the tangent there): contact_std_m inf
    CONTACT_UNRESOLVED = 10
    #: estimate: the pressure lies outside the actuator's working range: no force
    PRESSURE_OUT_OF_RANGE = 11
    #: estimate: a force beyond what the actuator can carry (a unit or calibration mistake): force kept, not ok
    IMPLAUSIBLE_FORCE = 12
    #: a frame without a finite force (whatever the solver said)
    NO_FORCE = 13
    #: shape: a signal outside the calibrated range
    EXTRAPOLATED = 14
    #: shape: non-finite signals
    NO_SHAPE = 15
    #: shape: a tip angle beyond a full turn (a unit or calibration mistake)
    IMPLAUSIBLE_SHAPE = 16
    #: a frame without a pressure reading (and no fallback pressure): shape only
    NO_PRESSURE = 17

    @property
    def word(self) -> str:
        """The code's word in results.csv."""
        return str(WORDS[self])

    @property
    def label(self) -> str:
        """What the code means, for people."""
        return LABELS[self]


_NOT_CONVERGED = "not_converged"
#: The word of each code in results.csv's ``status`` column, indexed by code.
WORDS = np.array([
    _NOT_CONVERGED,  # RUNNING never reaches a result; a frame left running failed
    "ok",
    _NOT_CONVERGED,  # UNSTABLE
    _NOT_CONVERGED,  # LOST_BRANCH
    _NOT_CONVERGED,  # WARM_UNSTABLE
    _NOT_CONVERGED,  # BEAM_FAILED
    _NOT_CONVERGED,
    "not_identifiable",
    _NOT_CONVERGED,  # NO_STABLE_MATCH
    "model_misfit",
    "contact_unresolved",
    "pressure_out_of_range",
    "implausible_force",
    "no_force",
    "extrapolated",
    "no_shape",
    "implausible_shape",
    "no_pressure",
], dtype=object)

#: What each code means, for people.
LABELS = {
    Status.RUNNING: "still running (never a result)",
    Status.OK: "ok",
    Status.UNSTABLE: "beam: the equilibrium loses stability along the load path",
    Status.LOST_BRANCH: "beam: the branch from the unloaded shape ends",
    Status.WARM_UNSTABLE: "beam: a warm start landed on an unstable equilibrium",
    Status.BEAM_FAILED: "the beam model fails at every trial force",
    Status.NOT_CONVERGED: "no convergence in the iteration limit",
    Status.NOT_IDENTIFIABLE: "the shape does not determine the load along one direction (σ inf along it)",
    Status.NO_STABLE_MATCH: "no stable equilibrium matches the shape",
    Status.MODEL_MISFIT: "the model does not explain the shape",
    Status.CONTACT_UNRESOLVED: "the data do not place the contact",
    Status.PRESSURE_OUT_OF_RANGE: "the pressure lies outside the actuator's range",
    Status.IMPLAUSIBLE_FORCE: "a force beyond what the actuator can carry",
    Status.NO_FORCE: "no finite force",
    Status.EXTRAPOLATED: "a signal outside the calibrated range",
    Status.NO_SHAPE: "non-finite signals",
    Status.IMPLAUSIBLE_SHAPE: "a tip angle beyond a full turn",
    Status.NO_PRESSURE: "no pressure reading",
}

_CODE = {}
for _status in reversed(Status):  # a word shared by several codes names the first of them
    _CODE[str(WORDS[_status])] = _status
_CODE[_NOT_CONVERGED] = Status.NOT_CONVERGED
del _status


def words(codes) -> np.ndarray:
    """The results.csv words of status codes, same shape (ndarray of str).

    Parameters
    ----------
    codes : int or array_like of int
        Status codes (:class:`Status`).
    """
    return WORDS[np.asarray(codes, dtype=np.intp)].astype(str)


def code_of(word: str) -> Status:
    """The code of a results.csv status word (of several codes with one word: the general one).

    Parameters
    ----------
    word : str
        A word of results.csv's ``status`` or ``track_status`` column.

    Raises
    ------
    KeyError
        For a word that is no status.
    """
    return _CODE[word]
