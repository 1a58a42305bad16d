"""EI(P) without weights: two free sweeps in two mounts, whose gravity sags differ (issue 31, item 2).

An actuator bends under its own weight as well as its pressure: with the base down the
weight curls a bent finger further, with the base up it uncurls it, and on its side it
adds to or takes from the curl. The free bending K0(P) is the same in every mount; the
sag is the weight's moment over EI(P). One free sweep sees the sum of the two, so a
stiffer actuator looks like one that curls less (the fit trades EI against K0(P), which
is why :func:`bendsense.adapt` keeps EI at its prior); two mounts see the sag with two
signs and K0(P) once, and together they measure both.

Each frame's free-bending angle θ is found as :func:`~bendsense.identify.sessions.free_bending_angles`
finds it, with the gravity of the frame's own mount taken out by the current EI(P); θ
moves with EI by ``∂θ/∂EI``, of opposite signs in the two mounts. The config's values and
``parameter_covariance`` are the prior, as in :func:`bendsense.adapt`, and the
free-bending parameters and the stiffness are fitted together
(:func:`bendsense.identify.fit_free_bending` with ``learn_stiffness``), weighed by the
angles' joint covariance under the calibration's errors (one sensor and one calibration
for both sweeps: their errors are common to both). The sag's slope is re-taken at the
fitted EI until EI settles (the sag is not linear in EI over ±30 %).

The sweeps must be free: nothing touches the finger (the frames are not screened for
contacts, as :func:`bendsense.adapt`'s are; a touch would read as stiffness).
"""

from __future__ import annotations

import dataclasses
import datetime

import numpy as np

from bendsense.config import STIFFNESS_PARAMETERS
from bendsense.errors import ArgumentError, SessionError

__all__ = ["GravityFit", "identify_gravity"]

#: Frames of each sweep used, spread over pressure (1 kPa bins).
FRAMES_PER_MOUNT = 120
#: The fitted EI(P) farther than this many of the prior's σ from the prior (Mahalanobis) is refused: two sweeps
#: in one mount (or the same sweep twice) show no difference of sag, which only an EI far stiffer than any
#: actuator of the prior explains, with a confident posterior; a lab's actuator off by 15-30 % lies 1-2 σ away
MAX_PRIOR_SIGMA = 5.0


@dataclasses.dataclass(frozen=True, eq=False)
class GravityFit:
    """Result of :func:`identify_gravity`.

    Attributes
    ----------
    config : Config
        The config with the posterior: the free-bending values, EI(P) and the whole
        ``parameter_covariance`` updated, with provenance.
    fit : FreeBendingFit
        The last fit (``fit.posterior``: the values and the covariance section).
    frames : tuple of int
        Frames used from each mount.
    rounds : int
        Fits until EI settled.
    prior : Config
        The config the fit started from.
    """

    config: object
    fit: object
    frames: tuple
    rounds: int
    prior: object

    def to_config(self, config=None):
        """The identified config (``config`` is ignored: the fit already holds the one it updated).

        Parameters
        ----------
        config : Config, optional
            Unused; for the interface of the other fits' ``to_config``.
        """
        return self.config

    def report(self) -> str:
        """K0 and EI at three pressures, before and after, with their σ."""
        from bendsense.mechanics.actuator import FreeBendingModel

        lo, hi = self.prior.actuator.pressure_range_pa
        levels = np.array([lo + 0.15 * (hi - lo), lo + 0.3 * (hi - lo), lo + 0.5 * (hi - lo)])
        k_old = FreeBendingModel.from_config(self.prior).tip_curvature_per_m(levels)
        k_new = FreeBendingModel.from_config(self.config).tip_curvature_per_m(levels)
        lines = [f"gravity (two mounts): {self.frames[0]} + {self.frames[1]} free frames, {self.rounds} round(s)"]
        for name in STIFFNESS_PARAMETERS:
            old, new = getattr(self.prior.stiffness, name), getattr(self.config.stiffness, name)
            sd = _sd(self.config, name)
            lines.append(f"  {name:16s} {old:.4g} -> {new:.4g} (sigma {sd:.2g}, {100 * sd / abs(new):.1f} %)")
        lines.append("  K0 " + ", ".join(f"{p / 1e3:.0f} kPa {100 * (b / a - 1):+.1f} %"
                                         for p, a, b in zip(levels, k_old, k_new, strict=True)) + " (vs the prior)")
        return "\n".join(lines)


def _sd(config, name) -> float:
    section = config.parameter_covariance
    i = section.parameters.index(name)
    return float(np.sqrt(section.matrix[i, i]))


def _mounted(config, direction):
    """``config`` with gravity along ``direction`` (unit vector, base frame)."""
    return config.replace(gravity=dataclasses.replace(config.gravity, direction=tuple(float(v) for v in direction)))


def identify_gravity(sessions, config, calibration, *, turned=None, max_rounds: int = 4) -> GravityFit:
    """The free bending and EI(P) from two free sweeps, in the config's mount and turned (module docstring).

    Parameters
    ----------
    sessions : sequence of two Session or path
        Free pressure sweeps of the same actuator and sensor: the first mounted as
        ``config.gravity.direction`` says, the second turned.
    config : Config
        The actuator with its prior (``parameter_covariance``, stating EI's variance).
    calibration : Calibration
        The sensor's calibration (its error model weighs the frames).
    turned : sequence of 2 floats, optional
        Gravity's direction in the base frame in the second mount; default the
        opposite of the first (the rig upside down).
    max_rounds : int
        Fits at most, each at the last one's EI.

    Returns
    -------
    GravityFit

    Raises
    ------
    ArgumentError
        Not two sessions, a config without a prior on EI, a turned mount that is not turned.
    SessionError
        A sweep without four usable frames.
    """
    from bendsense.identify import fit_free_bending
    from bendsense.identify.covariance import session_covariance
    from bendsense.identify.sessions import _check_prior, _take, _thin, free_bending_angles, session_shapes
    from bendsense.session.inputs import process_inputs
    from bendsense.sim.sensor import shifts_from_curvatures

    sessions = list(sessions)
    if len(sessions) != 2:
        raise ArgumentError(f"sessions: expected two free sweeps (two mounts), got {len(sessions)}")
    _check_prior(config)
    first = np.asarray(config.gravity.direction, dtype=float)
    second = -first if turned is None else np.asarray(turned, dtype=float)
    if second.shape != (2,) or not np.all(np.isfinite(second)) or np.hypot(*second) == 0:
        raise ArgumentError(f"turned: expected a direction (x, y), got {turned!r}")
    second = second / np.hypot(*second)
    if float(first @ second) > 0.9:
        raise ArgumentError(f"turned: ({second[0]:g}, {second[1]:g}) is nearly the first mount's gravity "
                            f"({first[0]:g}, {first[1]:g}): the two sweeps must see the weight from different sides")
    data = []
    for session, direction in zip(sessions, (first, second), strict=True):
        mounted = _mounted(config, direction)
        session, _, _, _ = process_inputs(session, mounted, calibration, "")
        shape, usable = session_shapes(session, calibration, mounted)
        p = np.asarray(session.pressure_pa, dtype=float)
        rows = _thin(np.flatnonzero(usable), p, FRAMES_PER_MOUNT)
        if rows.size < 4:
            raise SessionError(f"{session.source or 'a session'}: {rows.size} usable frame(s); need a free sweep")
        data.append((direction, _take(shape, rows), p[rows]))
    gap = float(calibration.strip_gap_m(config.sensor))
    b0 = np.array([getattr(config.stiffness, n) for n in STIFFNESS_PARAMETERS])
    current, rounds, fit = config, 0, None
    while rounds < max_rounds:
        rounds += 1
        parts = [(*free_bending_angles(shape, p, _mounted(current, direction))[:3], p, shape.curvature_per_m)
                 for direction, shape, p in data]
        a, w, s, p, kappa = (np.concatenate(x) for x in zip(*parts, strict=True))
        ok = np.isfinite(a) & np.isfinite(s)
        a, w, s, p, kappa = a[ok], w[ok], s[ok], p[ok], kappa[ok]
        # the angle taken out with EI b_lin is the true θ0 − g (b − b_lin): the data, moved to the prior's b0
        response = -s[:, None] * np.stack([np.ones(p.size), p], axis=-1)
        b_lin = np.array([getattr(current.stiffness, n) for n in STIFFNESS_PARAMETERS])
        shifts = shifts_from_curvatures(kappa, config.sensor.lengths_m, gap)
        cov = session_covariance(calibration, shifts, w / gap, np.arange(p.size), p.size)
        fit = fit_free_bending(p, a + response @ (b_lin - b0), config, data_covariance=cov, prior=True,
                               stiffness_response=response, learn_stiffness=True)
        new = fit.to_config(config)
        b_new = np.array([getattr(new.stiffness, n) for n in STIFFNESS_PARAMETERS])
        current = new
        if np.all(np.abs(b_new - b_lin) <= 1e-3 * np.abs(b0)):
            break
    _check_sag_seen(config, current)
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    provenance = (f"identify gravity {when}: free sweeps in two mounts (gravity ({first[0]:g}, {first[1]:g}) and "
                  f"({second[0]:g}, {second[1]:g})); the prior: "
                  f"{config.parameter_covariance.source or 'not named'}")
    current = current.replace(parameter_covariance=dataclasses.replace(current.parameter_covariance,
                                                                       source=provenance))
    return GravityFit(config=current, fit=fit, frames=tuple(len(d[2]) for d in data), rounds=rounds, prior=config)


def _check_sag_seen(prior, fitted) -> None:
    """Refuse an EI(P) more than :data:`MAX_PRIOR_SIGMA` of the prior's σ from it (two mounts that were not)."""
    section = prior.parameter_covariance
    names = [n for n in STIFFNESS_PARAMETERS if n in section.parameters]
    idx = [section.parameters.index(n) for n in names]
    moved = np.array([getattr(fitted.stiffness, n) - getattr(prior.stiffness, n) for n in names])
    distance = float(np.sqrt(moved @ np.linalg.pinv(section.matrix[np.ix_(idx, idx)]) @ moved))
    if not distance <= MAX_PRIOR_SIGMA:
        raise SessionError(f"the two sweeps put EI(P) {distance:.0f} σ of the config's prior from it (ei0_nm2 "
                           f"{prior.stiffness.ei0_nm2:.3g} -> {fitted.stiffness.ei0_nm2:.3g}): the two mounts show "
                           "less difference of sag than any actuator of the prior would; were they really two mounts "
                           "(not one sweep twice)? An actuator this far from the prior: widen its "
                           "parameter_covariance, or identify stiffness with weights")
