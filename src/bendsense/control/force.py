"""The controlled quantity: the contact normal force F · n at the contact, from a processed block.

A finger pressed against an object feels the object's push, normal to its body at the
contact ``s_c`` (frictionless): ``F = N n`` with the unit normal

    n(s_c) = (−cos φ_c, sin φ_c),   φ_c = φ(s_c),

the tangent ``t = (sin φ, cos φ)`` turned by −90°: it points away from the centre of
curvature, i.e. out of the object into the finger (``−x`` for a straight finger). A
finger that closes on an object bends toward ``+x`` and is held back by it, so the
object's push has ``N = F · n > 0`` while the finger presses; ``N < 0`` would be a pull
(an object pulling the finger closed), which a frictionless contact cannot give. This is
the convention of the simulator's contact (:meth:`bendsense.sim.SimulatedActuator.solve_contact`,
``F_c = f_c (−cos φ_c, sin φ_c)`` with ``f_c ≥ 0``). φ_c is the estimated shape's tangent
angle at ``s_c`` (the PCC reconstruction; for ``s_c`` beyond the sensor, the sensor's tip
angle: the last segment carries on straight), ``s_c`` the estimate's contact location
(``load="contact"``) or the tip ``L``.

:func:`force_limit_n` bounds what a finger can press with at a pressure limit: a target
beyond it is no grasp this actuator makes (a force in mN given as N), refused before the
board is driven.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bendsense import _jit
from bendsense.control._kernels import normal_components
from bendsense.errors import ArgumentError
from bendsense.status import words

__all__ = ["NormalForce", "contact_normal", "normal_force", "force_limit_n", "BLOCKED_FORCE_MARGIN"]

#: :func:`force_limit_n` is this many blocked forces
BLOCKED_FORCE_MARGIN = 2.0


def contact_normal(angle_rad) -> np.ndarray:
    """The unit normal n = (−cos φ, sin φ) of a finger at tangent angle φ: the object's push direction.

    Parameters
    ----------
    angle_rad : array_like, shape (...)
        Tangent angle φ at the contact, from ``+y`` toward ``+x`` [rad].

    Returns
    -------
    ndarray, shape (..., 2)
        The unit normal in the base frame.
    """
    phi = np.asarray(angle_rad, dtype=float)
    return np.stack((-np.cos(phi), np.sin(phi)), axis=-1)


@dataclass(frozen=True)
class NormalForce:
    """The contact normal force of the frames of a block.

    Attributes
    ----------
    force_n : ndarray, shape (n,)
        N = F · n [N] (positive: the finger presses the object); NaN where the frame has
        no force.
    std_n : ndarray, shape (n,)
        Its standard deviation sqrt(nᵀ C n) [N] (C the force's covariance).
    contact_s_m : ndarray, shape (n,)
        The contact location used [m].
    angle_rad : ndarray, shape (n,)
        The tangent angle φ_c there [rad].
    status_code : ndarray of int8, shape (n,)
        The frame's status code (:class:`bendsense.status.Status`; the tracked one where the
        force is tracked); :attr:`status` its words.
    """

    force_n: np.ndarray
    std_n: np.ndarray
    contact_s_m: np.ndarray
    angle_rad: np.ndarray
    status_code: np.ndarray

    @property
    def status(self) -> np.ndarray:
        """The frames' status words (n,) of str (results.csv's ``status``)."""
        return words(self.status_code)


def normal_force(block, *, tracked: bool = True, tip_s_m: float | None = None) -> NormalForce:
    """The contact normal force N = F · n of every frame of a processed block (module docstring).

    Parameters
    ----------
    block : LiveBlock
        A block of one finger (:meth:`bendsense.pipeline.LiveProcessor.process_readings`).
    tracked : bool, default True
        Use the tracked force (the causal filter) where the block has one; False (or a
        processor that does not track): the per-frame estimate.
    tip_s_m : float, optional
        The contact location reported for a tip load [m]: the actuator's length ``L``
        (default: the end of the shape's grid, the sensor's length).

    Returns
    -------
    NormalForce
    """
    # a control loop calls this for every finger and block: one compiled call, no objects; its inputs as copies,
    # writable and contiguous whatever the block holds (read-only or strided arrays would be another compiled version)
    n = len(block)
    s_grid = np.array(block.s_m, dtype=float)
    track_status = block.track_status if tracked else None
    if track_status is not None:
        force, cov, status = block.track_force_n, block.track_covariance_n2, track_status
    else:
        force, cov, status = block.force_n, block.covariance_n2, block.status
    value, std, s_out, phi = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    # a tip load, or a frame without a location: the end of the body (the sensor's tip angle holds beyond it)
    tip = float(s_grid[-1] if tip_s_m is None else tip_s_m)
    _jit.call(normal_components, s_grid, np.array(block.contact_s_m, dtype=float),
              np.array(block.angle_rad, dtype=float), np.array(force, dtype=float), np.array(cov, dtype=float), tip,
              value, std, s_out, phi)
    return NormalForce(value, std, s_out, phi, status)


def _limits(config, max_pressure_pa, contact_s_m=None) -> tuple:
    """(pressure limit [Pa], s_c [m]) checked against the finger's config, or ArgumentError; s_c None: the tip L.

    The limit within (0, the end of ``actuator.pressure_range_pa``], where the actuator model
    ends; s_c within (0, L].
    """
    length, top = config.actuator.length_m, config.actuator.pressure_range_pa[1]
    s_c = length if contact_s_m is None else contact_s_m
    number = (int, float, np.integer, np.floating)
    if isinstance(s_c, bool) or not isinstance(s_c, number) or not 0.0 < s_c <= length:
        raise ArgumentError(f"contact_s_m: expected 0 < s_c <= L = {length:g} m, got {contact_s_m!r}")
    if isinstance(max_pressure_pa, bool) or not isinstance(max_pressure_pa, number) or not 0.0 < max_pressure_pa <= top:
        raise ArgumentError(f"max_pressure_pa: expected a pressure in (0, {top:g}] Pa (the config's "
                            f"actuator.pressure_range_pa, where the actuator model ends), got {max_pressure_pa!r}")
    return float(max_pressure_pa), float(s_c)


def force_limit_n(config, max_pressure_pa: float, contact_s_m: float | None = None) -> float:
    """The most normal force a finger can press with at s_c, at pressures up to ``max_pressure_pa`` [N].

    :data:`BLOCKED_FORCE_MARGIN` (2) times the finger's **blocked force** there: the force
    normal to the finger at ``s_c`` that holds that point at its place at rest. Free, the
    pressure curls the finger by ``ΔK0 = K0(P) − K0(0)`` (the free-bending model), which
    moves the point at ``s_c`` by ``ΔK0 s_c² / 2``; a force ``F`` there moves it back by
    ``F s_c³ / (3 EI(P))`` (a cantilever, DESIGN section 2), so

        F_b(P) = 3 EI(P) ΔK0(P) / (2 s_c),

    0.70 N at the tip and 1.05 N at 0.1 m for the paper's finger at 100 kPa. A finger
    that touches its object already curled presses harder than one blocked straight (its
    normal at ``s_c`` passes nearer the base): up to 1.25 ``F_b`` on the simulated board
    (rigid objects at 15–134 mm touched at 2–60 kPa, pressures to 120 kPa); twice ``F_b``
    leaves room beyond that. A target in mN given in N is a thousand times beyond.

    Parameters
    ----------
    config : Config
        The finger (its actuator, free-bending and stiffness sections).
    max_pressure_pa : float
        The pressure limit [Pa] (``F_b`` grows with the pressure).
    contact_s_m : float, optional
        Where the finger touches [m]; None: the tip ``L``.

    Returns
    -------
    float
        The bound [N].
    """
    from bendsense.mechanics.actuator import FreeBendingModel

    p, s_c = _limits(config, max_pressure_pa, contact_s_m)
    k0 = FreeBendingModel.from_config(config).tip_curvature_per_m(np.array([0.0, p]))
    blocked = 3.0 * float(config.stiffness.ei_nm2(p)) * float(k0[1] - k0[0]) / (2.0 * s_c)
    return BLOCKED_FORCE_MARGIN * blocked
