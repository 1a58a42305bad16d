"""Per-frame status codes, one meaning in the beam solver and in the force estimator.

The compiled kernels write these integers; the Python layer turns them into ``success``
flags and messages. ``RUNNING`` is a kernel's working value and never reaches a user.
"""

from enum import IntEnum

__all__ = ["Status"]


class Status(IntEnum):
    """Outcome of one frame (beam solve or force estimate)."""

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
    #: the length): the shape is no bending of this actuator (wrong units, calibration or
    #: config); the force is reported, not ok
    MODEL_MISFIT = 9
    #: estimate (load="contact", location estimated): the force is reported, but the data cannot place the
    #: contact (its σ beyond one segment length, or the force nearly along the tangent there): contact_std_m inf
    CONTACT_UNRESOLVED = 10
