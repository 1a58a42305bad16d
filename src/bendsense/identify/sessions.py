"""Identification from sessions recorded with bendsense: a free pressure sweep, and learning while running (adapt).

The fits are those of :mod:`bendsense.identify`; this module turns a recorded session
into their data.

**Free bending** (:func:`fit_free_bending_session`). A session of the actuator moving
freely through its pressure range (``bendsense simulate free-sweep`` makes one). Each
frame's shape is reconstructed with the calibration; its free-bending angle
``θ = K0 L`` is the natural curvature K0 that, in the beam model with gravity
(``config.weight_per_length_n_per_m``, EI(P) of the config) and no tip load, fits the
measured coil angles ``φ(L_i) = S_i / d`` best (least squares over the coils,
:func:`free_bending_angles`): gravity is taken out, so the free-bending model (which
has none) is fitted to what it describes. :func:`bendsense.identify.fit_free_bending`
then fits μ̄, μ_s and the prebend to these angles over pressure.

Which frames are free is decided by the force estimator itself
(:func:`bendsense.estimate_force` with the calibration): a frame is used when its
status is ``ok`` and its force lies inside the 2σ ellipse of zero,
``Fᵀ C⁻¹ F ≤ χ²₂(0.9545) = 6.18`` with C its covariance. With wrong free-bending
parameters the free frames look loaded (a K0 error of 8 % is a force of tens of mN), so
the selection is iterated: fit, re-estimate with the fitted config (and the fit's
covariance, which widens C by what the fit does not know), re-select, refit, until the
selection repeats (at most ``rounds`` times). If fewer than half of the usable frames
pass with the starting config, the first fit uses all usable frames (a free sweep is
mostly free; a touch in a minority of frames is then rejected in the next round).
Usable frames: a reconstructed shape inside the calibrated range (status not
``extrapolated``) and a pressure inside ``actuator.pressure_range_pa``.

**Adapt** (:func:`adapt`): the same selection and the same fit, as a Bayesian update of
the config's prior (``fit_free_bending(..., prior=True)``), on frames of any session:
no fall back to all frames, and a frame must also pass the free-shape test.

The covariance of the fit is not the residual scatter's ``s² (JᵀJ)⁻¹``: the calibration
error is one error common to all frames of a session (the same polynomials map every
frame), so it does not average down over the frames. The angles' joint covariance over
all used frames comes from the calibration's error model
(:func:`bendsense.calibration._kernels.shift_covariance` over the frames' shifts stacked into
one vector: noise independent per frame, coefficient and misfit errors correlated
across frames as across channels), through each frame's angle weights; the fit's
covariance is the sandwich ``A Σ_θ Aᵀ`` (``A = (JᵀJ)⁻¹Jᵀ``), scaled up when the
residuals scatter more than Σ_θ says (:func:`bendsense.identify.fit_free_bending`,
``data_covariance``).

**Stiffness** from hanging weights: :mod:`bendsense.identify.weights`.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
from dataclasses import dataclass

import numpy as np

from bendsense.config import STIFFNESS_PARAMETERS
from bendsense.errors import ArgumentError, SessionError
from bendsense.identify import fit_free_bending
from bendsense.identify.covariance import session_covariance

__all__ = [
    "ADAPT_FRAMES", "FREE_CHI2_2SIGMA", "FREE_P", "MAX_FRAMES", "Adaptation", "FreeBendingSessionFit", "adapt",
    "adapt_session", "free_bending_angles", "k0_with_sigma", "fit_free_bending_session", "session_shapes",
]

#: χ² with 2 degrees of freedom at the 2σ level (95.45 %): the free frames' force ellipse.
FREE_CHI2_2SIGMA = -2.0 * math.log(1.0 - math.erf(2.0 / math.sqrt(2.0)))
#: A frame whose free-beam fit has a p-value below this is not free (:func:`adapt`).
FREE_P = 1e-3
#: Usable frames a free-bending fit considers at most (spread over pressure, :func:`_thin`).
MAX_FRAMES = 400
#: Frames :func:`adapt` learns from at most (spread over pressure): past ~100 the calibration's error, common to
#: all, bounds what more frames add, and their joint covariance costs the square of their number.
ADAPT_FRAMES = 160


def _source(session) -> str:
    return session.source or "session"


def session_shapes(session, calibration, config, *, need_pressure: bool = True):
    """The session's shapes at the coils and its usable frames (module docstring).

    Parameters
    ----------
    session : Session
        The recording (:func:`bendsense.read_session`).
    calibration : Calibration
        Signal → shift calibration of its sensor.
    config : Config
        Sensor and actuator.
    need_pressure : bool
        Refuse a session whose frames lack a pressure reading.

    Returns
    -------
    shape : Shape
        Reconstructed at the coils (``s_m`` = the cumulative segment lengths).
    usable : ndarray of bool, shape (frames,)
        Inside the calibrated range, a finite shape and a pressure in the working range.
    """
    from bendsense.estimation.plausibility import check_channels
    from bendsense.shape.pcc import reconstruct

    if len(session) == 0:
        raise SessionError(f"{_source(session)}: no frames")
    check_channels(session, calibration, config.sensor)
    p = np.asarray(session.pressure_pa, dtype=float)
    if p.ndim != 1:
        raise SessionError(f"{_source(session)}: pressure of {p.shape[-1]} lines per frame; identification takes "
                           "one actuator on one pressure line (export that finger's frames to a session CSV)")
    if need_pressure and not np.all(np.isfinite(p)):
        missing = int(np.count_nonzero(~np.isfinite(p)))
        raise SessionError(f"{_source(session)}: {missing} of {len(session)} frames have no pressure reading; "
                           "identification needs the pressure of every frame (a pressure_pa or pressure_kpa column)")
    coils = np.cumsum(config.sensor.segment_lengths_m)
    shape = reconstruct(session.signals, calibration, config.sensor, s_m=coils)
    return shape, _usable(shape, p, config)


def _usable(shape, p, config) -> np.ndarray:
    """Frames with a finite shape inside the calibrated range and a pressure in the working range."""
    lo, hi = config.actuator.pressure_range_pa
    return (~np.asarray(shape.extrapolated, dtype=bool) & np.all(np.isfinite(shape.curvature_per_m), axis=-1)
            & (p >= lo) & (p <= hi))


def free_bending_angles(shape, pressure_pa, config, *, max_iter: int = 8, with_misfit: bool = False):
    """The free-bending angle θ = K0 L of each frame, gravity taken out, and its weights.

    K0 minimises ``Σ_i (φ_i − φ_model(L_i; K0))²`` over the coils, with ``φ_i`` the
    measured coil angles of ``shape`` and ``φ_model`` the beam (:func:`bendsense.solve_beam`)
    with EI(P) of the config, its gravity load and no tip force; Gauss–Newton from the
    tip angle over the sensor length, the derivative by a central difference.

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes (frames,) on ``config.sensor``.
    pressure_pa : array_like, shape (frames,)
        Pressure of each frame [Pa].
    config : Config
        Actuator, stiffness and gravity.
    max_iter : int
        Gauss–Newton steps.
    with_misfit : bool
        Also return the residuals of the coil angles about the fitted free beam
        (frames, N) [rad], ∂φ/∂K0 and ∂φ/∂EI (frames, N), as a fourth item (the free
        frames' test of :func:`adapt`).

    Returns
    -------
    angle_rad : ndarray, shape (frames,)
        θ = K0 L [rad] (NaN where the beam solve failed).
    weights : ndarray, shape (frames, N)
        ∂θ/∂φ_i: θ's linear response to the measured coil angles [rad/rad].
    slope_ei : ndarray, shape (frames,)
        ∂θ/∂EI at the frame's pressure [rad/(N·m²)]: how the angle moves with the
        stiffness the gravity correction assumes.
    """
    from bendsense.mechanics.beam import solve_beam

    lengths = np.asarray(config.sensor.segment_lengths_m, dtype=float)
    coils = np.cumsum(lengths)
    phi = np.cumsum(np.asarray(shape.curvature_per_m, dtype=float) * lengths, axis=-1)
    p = np.asarray(pressure_pa, dtype=float)
    length = float(config.actuator.length_m)
    ei = config.stiffness.ei_nm2(p)
    w = config.weight_per_length_n_per_m

    def model(k0, ei=ei):
        sol = solve_beam(length, ei, k0, (0.0, 0.0), w, s_m=coils, warn=False)
        return np.asarray(sol.angle_rad), np.asarray(sol.success)

    k0 = phi[:, -1] / coils[-1]
    h = 1e-3
    for _ in range(max_iter):
        (lo, ok_lo), (hi, ok_hi) = model(k0 - h), model(k0 + h)
        mid, ok = model(k0)
        j = (hi - lo) / (2.0 * h)
        jj = np.einsum("bi,bi->b", j, j)
        step = np.einsum("bi,bi->b", j, phi - mid) / jj
        k0 = k0 + step
        if np.all(np.abs(step) <= 1e-10 * np.maximum(1.0, np.abs(k0))):
            break
    mid, ok = model(k0)
    dei = 1e-4 * ei
    (ei_hi, ok_ei), (ei_lo, _) = model(k0, ei + dei), model(k0, ei - dei)
    good = ok & ok_lo & ok_hi & ok_ei & np.isfinite(k0)
    angle = np.where(good, k0 * length, np.nan)
    weights = length * j / jj[:, None]
    # at the optimum K0 moves by −(jᵀ ∂φ/∂EI)/(jᵀj) per unit of EI
    dphi_dei = (ei_hi - ei_lo) / (2.0 * dei[:, None])
    slope_ei = -np.einsum("bi,bi->b", weights, dphi_dei)
    if not with_misfit:
        return angle, weights, slope_ei
    return angle, weights, slope_ei, (phi - mid, j, dphi_dei)


def _slope_ei_at_model(pressure_pa, config) -> np.ndarray:
    """∂θ/∂EI (:func:`free_bending_angles`' ``slope_ei``) of the free beam the config predicts at ``pressure_pa``.

    The model's K0(P), the config's EI(P) and gravity, no tip load: the slope as a function of pressure
    alone, free of the frames' measurement errors (NaN where the beam solve failed).
    """
    from bendsense.mechanics.actuator import FreeBendingModel
    from bendsense.mechanics.beam import solve_beam
    from bendsense.shape.pcc import Shape

    p = np.asarray(pressure_pa, dtype=float)
    lengths = np.asarray(config.sensor.segment_lengths_m, dtype=float)
    k0 = FreeBendingModel.from_config(config).tip_curvature_per_m(p)
    sol = solve_beam(float(config.actuator.length_m), config.stiffness.ei_nm2(p), k0, (0.0, 0.0),
                     config.weight_per_length_n_per_m, s_m=np.cumsum(lengths), warn=False)
    phi = np.where(np.asarray(sol.success)[:, None], np.asarray(sol.angle_rad), np.nan)
    kappa = np.diff(phi, axis=-1, prepend=0.0) / lengths
    return free_bending_angles(Shape.from_curvatures(kappa, lengths), p, config)[2]


def _free_p_value(misfit, shape, p, config, calibration):
    """The p-value of each frame's free-beam fit: whether its shape is a free beam's for some K0.

    The residual r of the measured coil angles about the free beam at the frame's own
    K0 (:func:`free_bending_angles`) is tested against the angles' covariance C (the
    calibration's error model at the frame's shifts, and the config's uncertainty of
    EI(P) through the gravity sag): ``χ² = rᵀC⁻¹r − (jᵀC⁻¹r)² / (jᵀC⁻¹j)`` with N − 1
    degrees of freedom (j = ∂φ/∂K0). A tip load bends the actuator unlike any K0 (its
    moment grows toward the base), so a loaded frame fails this test where its force
    still lies inside the prior's wide ellipse.
    """
    from scipy.stats import chi2

    from bendsense.calibration._kernels import shift_covariances
    from bendsense.sim.sensor import shifts_from_curvatures

    r, j, dphi_dei = misfit
    gap = float(calibration.strip_gap_m(config.sensor))
    shifts = np.ascontiguousarray(shifts_from_curvatures(shape.curvature_per_m, config.sensor.lengths_m, gap))
    cov = np.empty(shifts.shape + shifts.shape[-1:])
    shift_covariances(calibration.error_model(), shifts, cov, np.empty(shifts.shape))
    cov /= gap**2
    g = np.stack([np.ones(len(p)), p], axis=-1)
    var_ei = np.einsum("bi,ij,bj->b", g, _block(config, STIFFNESS_PARAMETERS), g)
    cov += var_ei[:, None, None] * np.einsum("bi,bj->bij", dphi_dei, dphi_dei)
    ci_r = np.linalg.solve(cov, r[..., None])[..., 0]
    ci_j = np.linalg.solve(cov, j[..., None])[..., 0]
    stat = np.einsum("bi,bi->b", r, ci_r) - np.einsum("bi,bi->b", j, ci_r) ** 2 / np.einsum("bi,bi->b", j, ci_j)
    return chi2.sf(stat, r.shape[-1] - 1)


@dataclass(frozen=True, eq=False)
class FreeBendingSessionFit:
    """Result of :func:`fit_free_bending_session`: the fit and the frames behind it.

    Attributes
    ----------
    fit : FreeBendingFit
        The free-bending fit on the used frames (:func:`bendsense.identify.fit_free_bending`).
    pressure_pa : ndarray, shape (frames,)
        Every frame's pressure [Pa].
    bending_angle_rad : ndarray, shape (frames,)
        Every frame's free-bending angle θ = K0 L, gravity taken out [rad]; NaN where
        the shape is not usable.
    used : ndarray of bool, shape (frames,)
        The frames of the final fit.
    reason : ndarray of str, shape (frames,)
        ``used``, or why a frame was not: ``loaded`` (its force outside the 2σ ellipse),
        its estimate's status (``model_misfit``, …), ``unusable`` (no shape in the
        calibrated range, or a pressure outside the working range) or ``thinned`` (not
        considered: beyond ``max_frames``).
    rounds : int
        Fit and re-selection rounds run.
    note : str
        How the first fit's frames were chosen.
    caveats : tuple of str
        What the fit takes as exact that may not be (printed by :meth:`report`).
    unsettled : str
        Why the selection did not settle, in a few words ("" when it did: :attr:`settled`).
    """

    fit: object
    pressure_pa: np.ndarray
    bending_angle_rad: np.ndarray
    used: np.ndarray
    reason: np.ndarray
    rounds: int
    note: str
    caveats: tuple = ()
    unsettled: str = ""

    @property
    def settled(self) -> bool:
        """Whether the selection repeated in the last round."""
        return not self.unsettled

    def to_config(self, config):
        """A copy of ``config`` with the fitted values and covariance (:meth:`FreeBendingFit.to_config`).

        Parameters
        ----------
        config : Config
            The config to copy.
        """
        return self.fit.to_config(config)

    def report(self) -> str:
        """The fit's report with the frame selection."""
        counts = {r: int(np.count_nonzero(self.reason == r)) for r in dict.fromkeys(self.reason.tolist())}
        thinned = counts.pop("thinned", 0)
        rejected = ", ".join(f"{c} {r}" for r, c in counts.items() if r != "used") or "none"
        more = f"; {thinned} more frames thinned out (not considered)" if thinned else ""
        lines = [
            f"free frames: {int(self.used.sum())} of {len(self.used) - thinned} used (status ok, force inside its "
            f"2-sigma ellipse); rejected: {rejected}{more}",
            f"  selection: {self.rounds} round(s), {'settled' if self.settled else 'NOT settled'}; {self.note}",
            *(f"  note: {c}" for c in self.caveats),
            self.fit.report(),
        ]
        if not self.settled:
            lines.append("  WARNING: the frame selection changed in the last round; check the figure")
        return "\n".join(lines)

    def plot(self, ax=None, config=None):
        """Free-bending angle over pressure: used and rejected frames, the fitted and the prior model.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; None makes a new figure.
        config : Config, optional
            The starting (prior) config, drawn as the prior model; default the paper's.
        """
        import matplotlib.pyplot as plt

        from bendsense.config import load_config
        from bendsense.mechanics.actuator import FreeBendingModel

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4.5))
        prior = config if config is not None else load_config()
        p_kpa = self.pressure_pa / 1e3
        deg = np.degrees(self.bending_angle_rad)
        ax.plot(p_kpa[self.used], deg[self.used], ".", color="C0", label=f"used ({int(self.used.sum())})")
        for i, reason in enumerate(r for r in dict.fromkeys(self.reason.tolist()) if r not in ("used", "thinned")):
            sel = self.reason == reason
            hidden = int(np.count_nonzero(sel & ~np.isfinite(deg)))  # no angle to draw (a frame not reconstructed)
            note = f"; {hidden} without an angle, not drawn" if hidden else ""
            ax.plot(p_kpa[sel], deg[sel], "x", color=f"C{3 + i}", label=f"rejected: {reason} ({int(sel.sum())}{note})")
        grid = np.linspace(0.0, max(float(np.nanmax(self.pressure_pa)), 1.0), 200)
        fitted = FreeBendingModel.from_config(self.to_config(prior)).bending_angle_rad(grid)
        ax.plot(grid / 1e3, np.degrees(FreeBendingModel.from_config(prior).bending_angle_rad(grid)), "--",
                color="0.5", label="prior model (the starting config)")
        ax.plot(grid / 1e3, np.degrees(fitted), "-", color="C1", label="fitted model")
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel("free-bending angle K0 L [deg]")
        ax.set_title("free-bending fit from a session (gravity taken out)")
        ax.legend(fontsize="small")
        return ax


def _select(shape, pressure, usable, config, calibration, nsigma2, thinned, shaped):
    """Frames whose estimate is ``ok`` with the force inside its χ² ellipse; the reason for every frame.

    ``shaped``: frames whose shape is a free beam's (:func:`_free_p_value`); the others
    are ``load_shape``.
    """
    from bendsense.estimation import estimate_force
    from bendsense.results import frame_status

    reason = np.where(thinned, "thinned", "unusable").astype(object)
    idx = np.flatnonzero(usable)
    part = _take(shape, idx)
    est = estimate_force(part, pressure[idx], config, calibration=calibration)
    status = frame_status(part, est)
    F = np.asarray(est.force_n)
    C = np.asarray(est.covariance_n2)
    finite = np.all(np.isfinite(C), axis=(-2, -1)) & np.all(np.isfinite(F), axis=-1)
    d2 = np.full(len(idx), np.inf)
    if finite.any():
        d2[finite] = np.einsum("bi,bij,bj->b", F[finite], np.linalg.pinv(C[finite]), F[finite])
    free = (status == "ok") & (d2 <= nsigma2) & shaped[idx]
    reason[idx] = np.where(free, "used", np.where(status != "ok", status, np.where(shaped[idx], "loaded",
                                                                                     "load_shape")))
    return reason == "used", reason


def _take(shape, idx):
    from bendsense.shape.pcc import Shape

    return Shape.from_curvatures(np.asarray(shape.curvature_per_m)[idx], shape.lengths_m, s_m=shape.s_m,
                                 extrapolated=np.asarray(shape.extrapolated)[idx])


def fit_free_bending_session(session, calibration, config=None, *, fix=None, rounds: int = 5,
                             chi2_limit: float = FREE_CHI2_2SIGMA, max_frames: int = MAX_FRAMES
                             ) -> FreeBendingSessionFit:
    """Fit μ̄, μ_s and the prebend to the free frames of a recorded pressure sweep (module docstring).

    Parameters
    ----------
    session : Session or path
        A free pressure sweep (:func:`bendsense.read_session`), with the pressure of
        every frame.
    calibration : Calibration or path
        The sensor's calibration (``bendsense calibrate``).
    config : Config or path, optional
        The starting config (its free-bending parameters start the fit and the first
        selection); default the paper's.
    fix : iterable of str or mapping, optional
        Parameters to hold (:func:`bendsense.identify.fit_free_bending`).
    rounds : int
        At most this many fit and re-selection rounds.
    chi2_limit : float
        A frame is free when ``Fᵀ C⁻¹ F`` is at most this (default the 2σ level of χ²₂).
    max_frames : int
        Consider at most this many usable frames, spread evenly over pressure and each
        pressure's over time (a sweep recorded at 2 kHz has tens of thousands; the
        calibration's error, common to all, bounds what more frames could add); the
        others have the reason ``thinned``.

    Returns
    -------
    FreeBendingSessionFit

    Raises
    ------
    SessionError
        No pressure, channels that do not match, or too few free frames.
    """
    from bendsense.session.inputs import process_inputs

    session, config, calibration, _ = process_inputs(session, config, calibration, "")
    shape, usable = session_shapes(session, calibration, config)
    return _free_frames_fit(shape, np.asarray(session.pressure_pa, dtype=float), usable, config, calibration,
                            _source(session), fix=fix, limits=_Limits(rounds, chi2_limit, max_frames))


@dataclass(frozen=True)
class _Limits:
    """How the free frames are chosen: rounds of selection and fit, the χ² limit of a free frame, the most frames."""

    rounds: int = 5
    chi2_limit: float = FREE_CHI2_2SIGMA
    max_frames: int = MAX_FRAMES


def _free_frames_fit(shape, p, usable, config, calibration, source, *, fix=None, limits=_Limits(),
                     prior=False) -> FreeBendingSessionFit:
    """The free frames of a session and the free-bending fit on them, iterated (module docstring).

    ``prior``: the fit updates the config's prior (:func:`adapt`); the first selection is
    then the starting config's alone (no fall back to every usable frame: a session
    need not be a free sweep) and fewer than four free frames raise :class:`SessionError`.
    """
    rounds, chi2_limit, max_frames = limits.rounds, limits.chi2_limit, limits.max_frames
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ArgumentError(f"rounds: expected an integer >= 1, got {rounds!r}")
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 4:
        raise ArgumentError(f"max_frames: expected an integer >= 4, got {max_frames!r}")
    thinned = usable.copy()
    usable = np.zeros_like(usable)
    usable[_thin(np.flatnonzero(thinned), p, max_frames)] = True
    thinned &= ~usable
    angle = np.full(len(p), np.nan)
    weights = np.full((len(p), config.sensor.n_segments), np.nan)
    slope_ei = np.full(len(p), np.nan)
    idx = np.flatnonzero(usable)
    shaped = np.ones(len(p), dtype=bool)  # a free beam's shape (the test of a prior's update)
    if idx.size:
        part = _take(shape, idx)
        out = free_bending_angles(part, p[idx], config, with_misfit=prior)
        angle[idx], weights[idx], slope_ei[idx] = out[:3]
        if prior:
            shaped[idx] = _free_p_value(out[3], part, p[idx], config, calibration) >= FREE_P
            # ∂θ/∂EI at the prior's free beam, not at each frame's measured angle: its stiffness response and the
            # covariance R Σ_b Rᵀ it gives the angles (weighed against the prior) must not depend on the angles'
            # own errors, or the fit lands below the data (Peelle's pertinent puzzle)
            model = _slope_ei_at_model(p[idx], config)
            slope_ei[idx] = np.where(np.isfinite(model), model, slope_ei[idx])
    usable &= np.isfinite(angle)
    if not usable.any():
        raise SessionError(f"{source}: no frame with a usable shape (all outside the calibrated range, "
                           "or their pressure outside actuator.pressure_range_pa)")
    used, reason = _select(shape, p, usable, config, calibration, chi2_limit, thinned, shaped)
    note = "the first selection by the starting config"
    if used.sum() < 0.5 * usable.sum() and not prior:
        used, note = usable.copy(), (f"the starting config found {int(used.sum())} of {int(usable.sum())} usable "
                                     "frames free; the first fit used all usable frames")
    frames = _FreeFrames(shape, p, angle, weights, slope_ei, calibration, config, source)
    fit, settled, done, caveats, unsettled = None, False, 0, (), ""
    while done < rounds:
        done += 1
        fit = frames.fit(used, fix, prior)
        current = fit.to_config(config)
        new_used, new_reason = _select(shape, p, usable, current, calibration, chi2_limit, thinned, shaped)
        if new_used.sum() < 0.5 * used.sum():  # the fitted model describes few of its own frames: keep them
            unsettled = (f"the fitted config finds only {int(new_used.sum())} of the {int(used.sum())} frames it was "
                         "fitted to free")
            caveats = (f"{unsettled}: the model does not describe the free sweep to within its sigma (is EI(P) "
                       "right? identify stiffness, then this again); the fit keeps those frames",)
            reason = np.where(used, "used", reason)
            break
        settled = bool(np.array_equal(new_used, used))
        used, reason = new_used, new_reason
        if settled:
            break
    if not settled and not caveats:  # the final fit is on the final selection
        fit = frames.fit(used, fix, prior)
        unsettled = f"the frame selection still changed in round {done}"
    if not prior and not np.any(_block(config, STIFFNESS_PARAMETERS)):
        caveats += ("the config states no covariance of ei0_nm2, ei1_nm2_per_pa: the gravity correction takes its "
                    "EI(P) as exact; identify stiffness, then free bending again with that config",)
    return FreeBendingSessionFit(fit=fit, pressure_pa=p, bending_angle_rad=angle, used=used,
                                 reason=np.asarray(reason, dtype=str), rounds=done, note=note, caveats=caveats,
                                 unsettled=unsettled)


def _thin(candidates, pressure_pa, max_frames: int) -> np.ndarray:
    """At most ``max_frames`` of ``candidates``, spread evenly over pressure (1 kPa bins), each bin's over time.

    The model is a function of pressure, and the calibration's error, common to the
    frames at one pressure, does not average down over them: a hold at one pressure
    (thousands of frames, loaded or not) gets no more than a bin of the sweep.
    """
    if candidates.size <= max_frames:
        return candidates
    _, inverse, counts = np.unique(np.round(pressure_pa[candidates] / 1e3), return_inverse=True, return_counts=True)
    bins = np.unique(np.linspace(0, counts.size - 1, min(counts.size, max_frames)).round().astype(int))
    quota = 1
    while np.minimum(counts, quota + 1).sum() <= max_frames:  # the most frames per bin that fit
        quota += 1
    keep = []
    for k, b in enumerate(bins):
        rows = np.flatnonzero(inverse == b)
        if quota == 1:  # one frame per bin: the first and the last in time by turns (a sweep's up and down)
            keep.append(rows[[0 if k % 2 == 0 else -1]])
        else:
            keep.append(rows[np.unique(np.linspace(0, rows.size - 1, min(rows.size, quota)).round().astype(int))])
    return candidates[np.sort(np.concatenate(keep))]


@dataclass(frozen=True, eq=False)
class _FreeFrames:
    """A session's free-bending angles and what :func:`fit_free_bending` needs of them."""

    shape: object
    pressure_pa: np.ndarray
    angle_rad: np.ndarray
    weights: np.ndarray
    slope_ei: np.ndarray
    calibration: object
    config: object
    source: str

    def fit(self, used, fix, prior):
        """:func:`fit_free_bending` on the ``used`` frames, with their angles' joint covariance.

        The covariance: the calibration's errors over the frames (:func:`session_covariance`).
        The config's uncertainty of EI(P) enters through the gravity correction: as a
        systematic covariance of the angles, or, with a prior, as the stiffness
        parameters' response (the posterior keeps their cross-covariances).
        """
        from bendsense.sim.sensor import shifts_from_curvatures

        rows = np.flatnonzero(used)
        if rows.size < 4:
            raise SessionError(f"{self.source}: {rows.size} free frame(s) found (status ok and the force inside "
                               "its 2-sigma ellipse); need at least 4 over the pressure range: record a free sweep")
        config = self.config
        p = self.pressure_pa[rows]
        gap = float(self.calibration.strip_gap_m(config.sensor))
        shifts = shifts_from_curvatures(np.asarray(self.shape.curvature_per_m)[rows], config.sensor.lengths_m, gap)
        cov = session_covariance(self.calibration, shifts, self.weights[rows] / gap, np.arange(rows.size),
                                 rows.size)
        g = self.slope_ei[rows, None] * np.stack([np.ones(rows.size), p], axis=-1)  # ∂θ/∂(ei0, ei1)
        if prior:  # θ was taken out with the config's EI: the true EI moves it by −g
            return fit_free_bending(p, self.angle_rad[rows], config, data_covariance=cov, prior=True,
                                    stiffness_response=-g)
        return fit_free_bending(p, self.angle_rad[rows], config, fix=fix, data_covariance=cov,
                                systematic_covariance=g @ _block(config, STIFFNESS_PARAMETERS) @ g.T)


def _block(config, names) -> np.ndarray:
    """The covariance of ``names`` stated by ``config.parameter_covariance`` (zeros where it states none)."""
    out = np.zeros((len(names), len(names)))
    section = config.parameter_covariance
    if section is None:
        return out
    idx = [section.parameters.index(n) if n in section.parameters else -1 for n in names]
    for a, i in enumerate(idx):
        for b, j in enumerate(idx):
            if i >= 0 and j >= 0:
                out[a, b] = section.matrix[i, j]
    return out


@dataclass(frozen=True, eq=False)
class Adaptation:
    """Result of :func:`adapt`: the config updated by a session's own free frames.

    Attributes
    ----------
    config : Config
        The config with the posterior of its model parameters: the free-bending values
        and the whole ``parameter_covariance`` updated (the stiffness keeps its values
        and variances, its cross-covariances with the free-bending parameters are the
        posterior's); the config unchanged when it refused.
    free : ndarray of bool, shape (frames,)
        The frames it learned from.
    report : str
        One paragraph: frames used of how many, what was learned (σ before → after),
        what it refused and why.
    fit : FreeBendingSessionFit or None
        The fit behind it (None when it refused).
    why : str
        Why it refused, in a few words ("" when it learned).
    """

    config: object
    free: np.ndarray
    report: str
    fit: object = None
    why: str = ""

    @property
    def refused(self) -> bool:
        """It learned nothing: no free frames it could tell from loaded ones."""
        return self.fit is None


def adapt(shape, pressure_pa, config, *, calibration=None, t_s=None, source=None) -> Adaptation:
    """Learn the actuator's free bending from a session's own free frames: the prior updated by them.

    The free frames are found as ``identify free-bending --session`` finds them (module
    docstring): the force estimator's status ``ok`` and the force inside its 2σ ellipse,
    first with the config's prior, then with each round's posterior, until the
    selection repeats. Each one's free-bending angle (gravity taken out) and the angles'
    joint covariance under the calibration's errors are the data; the config's values
    and ``parameter_covariance`` are the prior; :func:`bendsense.identify.fit_free_bending`
    with ``prior=True`` gives the posterior (the prior's rows in the same least squares).
    The stiffness the prior states enters through the gravity correction: it keeps its
    values and variances (free frames are too weak a lever on EI), its uncertainty weighs
    the data and the posterior holds the cross-covariances it implies. Besides the
    force ellipse, a frame must pass the free-shape test (:func:`_free_p_value`: its
    coil angles a free beam's for some K0), which rejects loads the prior's wide
    ellipse would let through. Frames at one pressure teach K0 at that
    pressure only: the posterior keeps the prior's split between μ̄ and μ_s there.

    It refuses to learn (the config returned unchanged, ``refused`` True, the report
    says why) from fewer than four free frames (a session whose frames are all loaded,
    or none in the calibrated range and the pressure range), and when the selection does
    not settle: a posterior that finds few of its own frames free, or a selection that
    still changes after the last round, learned from frames that are not free (a light
    touch, a load the prior's wide ellipse let through; a few such frames move the
    posterior by tens of percent, since the calibration's error, common to all frames,
    leaves their per-frame noise as the measure of a misfit).

    Parameters
    ----------
    shape : Shape or array_like, shape (frames, N)
        Reconstructed shapes (:func:`bendsense.reconstruct`) or segment curvatures [1/m]
        on ``config.sensor``.
    pressure_pa : array_like, shape (frames,)
        Pressure of each frame [Pa].
    config : Config
        The actuator, with the prior to update (``parameter_covariance``).
    calibration : Calibration
        The sensor's calibration: its noise and error model weigh the data (required).
    t_s : array_like, shape (frames,), optional
        Time of each frame [s]: the report gives the free frames' time span.
    source : str, optional
        The session's name, for the provenance the adapted config carries
        (``parameter_covariance.source``: the session, the frames used, the date).

    Returns
    -------
    Adaptation

    Raises
    ------
    ArgumentError
        No calibration, a config without a prior, shapes that do not match.
    """
    from bendsense import validation as check
    from bendsense.calibration import Calibration
    from bendsense.config import Config
    from bendsense.shape.pcc import Shape

    check.instance("config", config, Config, "bendsense.load_config(path)")
    if not isinstance(calibration, Calibration):
        raise ArgumentError("calibration: adapt needs the sensor's Calibration (its noise and error model weigh the "
                            f"free frames against the prior), got {type(calibration).__name__}")
    _check_prior(config)
    if not isinstance(shape, Shape):
        shape = Shape.from_curvatures(np.asarray(shape, dtype=float), config.sensor.segment_lengths_m)
    kappa = np.asarray(shape.curvature_per_m, dtype=float)
    p = np.asarray(pressure_pa, dtype=float)
    if kappa.ndim != 2 or kappa.shape[-1] != config.sensor.n_segments or p.shape != kappa.shape[:1]:
        raise ArgumentError(f"shape, pressure_pa: expected ({config.sensor.n_segments} curvatures) per frame and one "
                            f"pressure per frame, got {kappa.shape} and {p.shape}")
    t = None if t_s is None else np.asarray(t_s, dtype=float)
    if t is not None and t.shape != p.shape:
        raise ArgumentError(f"t_s: expected one time per frame {p.shape}, got {t.shape}")
    try:
        fit = _free_frames_fit(shape, p, _usable(shape, p, config), config, calibration, "adapt", prior=True,
                               limits=_Limits(max_frames=ADAPT_FRAMES))
    except SessionError as err:
        why = str(err).removeprefix("adapt: ")
        report = (f"adapt: learned nothing from {len(p)} frames and kept the config's prior: {why}. "
                  "It learns only from frames it can tell from loaded ones (the force estimate ok and inside its "
                  "2-sigma ellipse of zero); record a moment of free motion (a sweep, the approach before a "
                  "grasp, a rest between touches).")
        return Adaptation(config=config, free=np.zeros(len(p), dtype=bool), report=report, why=why)
    if not fit.settled:  # a posterior that does not describe its own free frames: nothing to believe
        why = f"{fit.unsettled} (frames taken for free that are not: a light touch, a load inside the prior's ellipse)"
        report = (f"adapt: learned nothing from {len(p)} frames and kept the config's prior: {why}. It learns from "
                  "sessions whose free frames it can tell from loaded ones: record a moment of free motion over the "
                  "pressure range (a sweep, the approach before a grasp).")
        return Adaptation(config=config, free=np.zeros(len(p), dtype=bool), report=report, why=why)
    new = fit.to_config(config)
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    provenance = (f"adapt {when} from {source or 'a session'}: {int(fit.used.sum())} of {len(p)} frames free; "
                  f"the prior: {config.parameter_covariance.source or 'not named'}")
    new = new.replace(parameter_covariance=dataclasses.replace(new.parameter_covariance, source=provenance))
    return Adaptation(config=new, free=fit.used.copy(), report=_adapt_report(fit, config, new, t), fit=fit)


NO_PRIOR = ("no parameter_covariance: adapt updates a prior; state one (the shipped config's) or identify free "
            "bending from a free sweep")  # why a config without a prior is refused (the CLI names its file)


def _check_prior(config) -> None:
    """Refuse a config without ``parameter_covariance`` (:func:`adapt` and live ``--adapt`` update a prior)."""
    if config.parameter_covariance is None:
        raise ArgumentError(f"config {config.name!r}: {NO_PRIOR}")


def adapt_session(session, config, calibration, pressure_pa=None) -> Adaptation:
    """:func:`adapt` on a recorded session (``process --adapt``): its shapes, pressures, times and name.

    Parameters
    ----------
    session : Session
        The recording.
    config : Config
        The actuator, with the prior to update.
    calibration : Calibration
        The sensor's calibration.
    pressure_pa : float, optional
        Pressure of frames without a reading [Pa].
    """
    if pressure_pa is not None:
        session = session.with_pressure(pressure_pa)
    shape, _ = session_shapes(session, calibration, config, need_pressure=False)
    return adapt(shape, session.pressure_pa, config, calibration=calibration, t_s=session.t_s,
                 source=_source(session))


def k0_with_sigma(config, pressure_pa):
    """K0 [1/m] at ``pressure_pa`` and its standard deviation under ``config.parameter_covariance``.

    Parameters
    ----------
    config : Config
        The actuator, with its prior or posterior.
    pressure_pa : ndarray
        Pressures [Pa].
    """
    from bendsense.mechanics.actuator import FreeBendingModel, model_jacobian

    J = model_jacobian(config, pressure_pa, config.parameter_covariance.parameters)
    sigma = np.sqrt(np.einsum("bi,ij,bj->b", J[:, 0], config.parameter_covariance.matrix, J[:, 0]))
    return FreeBendingModel.from_config(config).tip_curvature_per_m(pressure_pa), sigma


def _adapt_report(fit, prior, posterior, t_s) -> str:
    """One paragraph: frames used of how many, what was learned (σ before → after), what was refused."""
    used = fit.used
    p = fit.pressure_pa[used]
    span = f"{p.min() / 1e3:.0f}-{p.max() / 1e3:.0f} kPa" if np.ptp(p) > 1e3 else f"{np.median(p) / 1e3:.0f} kPa"
    when = ""
    if t_s is not None:
        when = f" between {t_s[used].min():.2f} and {t_s[used].max():.2f} s"
    levels = np.unique(np.round(np.percentile(p, [5, 50, 95]), -3))
    k0, sig = zip(*(k0_with_sigma(c, levels) for c in (prior, posterior)), strict=True)
    learned = ", ".join(f"{lv / 1e3:.0f} kPa {100 * (b / a - 1):+.1f} % (sigma {100 * sa / abs(a):.1f} % -> "
                        f"{100 * sb / abs(b):.1f} %)" for lv, a, b, sa, sb in zip(levels, *k0, *sig, strict=True))
    before, after = prior.parameter_covariance.std, posterior.parameter_covariance.std
    old, new = prior.model_parameters(), posterior.model_parameters()
    params = "; ".join(f"{n} {old[n]:.4g} +- {before[n]:.2g} -> {new[n]:.4g} +- {after[n]:.2g}"
                       for n in prior.parameter_covariance.parameters if before[n] > 0)
    counts = {r: int(np.count_nonzero(fit.reason == r)) for r in dict.fromkeys(fit.reason.tolist())}
    considered = len(used) - counts.pop("thinned", 0)
    refused = ", ".join(f"{c} {r}" for r, c in counts.items() if r != "used") or "none"
    one = "" if np.ptp(p) > 10e3 else (" Its free frames lie at one pressure: they teach K0 there, and the split "
                                       "between shear_modulus_pa and sensor_stiffness_nm_per_rad stays the prior's.")
    return (f"adapt: learned from {int(used.sum())} free frames of {considered} considered ({len(used)} in the "
            f"session, spread over pressure, at most {ADAPT_FRAMES}) at {span}{when}; K0 moved by {learned}; "
            f"{params}. Frames left out: {refused} (loaded: the force outside its 2-sigma ellipse of zero; "
            f"load_shape: a shape no free beam has, p < {FREE_P:g}; unusable: outside the calibrated or pressure "
            f"range), in {fit.rounds} round(s) of selection.{one}")
