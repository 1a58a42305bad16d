"""The result object of a force estimate and the messages of its per-frame status codes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bendsense._batched import brief_repr, quick_init
from bendsense.status import MISFIT_P, Status

__all__ = ["ForceEstimate", "messages"]

OK_MESSAGE = "converged"
BUDGET = ("noise", "calibration", "model")  # the parts of the force covariance, in ForceEstimate.covariance_parts_n2
_OK = int(Status.OK)


def messages(status, residual_m, chi2_per_dof, p_value, direction, method):
    """Per-frame messages (B,) of str from the status codes (:class:`~bendsense.status.Status`)."""
    if (status == _OK).all():
        return np.full(status.shape, OK_MESSAGE)
    out = np.full(status.shape, OK_MESSAGE, dtype=object)
    out[status == Status.BEAM_FAILED] = "beam model fails (buckling or no equilibrium) at every trial force"
    out[status == Status.NOT_CONVERGED] = ("no convergence in the iteration limit" if method == "fast"
                                           else "optimizer did not converge")
    for i in np.flatnonzero(status == Status.NOT_IDENTIFIABLE):
        x, y = direction[i]
        out[i] = (f"not identifiable along ({x:.3f}, {y:.3f}): trial loads leave the stable branch "
                  "(buckling) or the shape's linear range; best stable estimate, std inf")
    for i in np.flatnonzero(status == Status.MODEL_MISFIT):
        if not p_value[i] < MISFIT_P:
            out[i] = (f"model_misfit: the model shape stays {residual_m[i] * 1e3:.3g} mm (RMS) from the measured one, "
                      "over 5 % of the length: check the calibration, the config's units and the pressure")
        else:
            out[i] = (f"model_misfit: chi2/dof = {chi2_per_dof[i]:.3g}, p = {p_value[i]:.2g} < {MISFIT_P:g}: the model "
                      "does not explain the shape within the stated noise (a load not at the tip, contact along the "
                      "body, or a mis-identified actuator)")
    for i in np.flatnonzero(status == Status.NO_STABLE_MATCH):
        out[i] = (f"no stable equilibrium matches the shape: stopped at the stability boundary "
                  f"{residual_m[i] * 1e3:.3g} mm from it (a load beyond buckling?)")
    return out.astype(str)


@quick_init
@dataclass(frozen=True, eq=False)
class ForceEstimate:
    """Estimated tip force (paper eq. 18), batched over leading axes ``...``.

    Attributes
    ----------
    force_n : ndarray, shape (..., 2)
        Tip force (Fx, Fy) in the base frame [N].
    std_n : ndarray, shape (..., 2)
        Standard deviation of each component [N] from the propagated shift errors
        (signal noise, calibration error and the config's ``parameter_covariance``,
        scaled by ``max(1, χ²/dof)``; module
        docstring, Uncertainty); ``inf`` for a component the shape cannot determine.
    covariance_n2 : ndarray, shape (..., 2, 2)
        Covariance of ``force_n`` [N²].
    residual_m : ndarray, shape (...)
        RMS distance between the reconstructed and the model shape over ``[0, Lc]`` [m].
    success : ndarray of bool, shape (...)
        Converged, with a stable beam equilibrium; or stopped at the best stable point
        where the load along one direction is not identifiable (message
        ``"not identifiable along ..."``, ``std_n`` inf along it).
    status : ndarray of int8, shape (...)
        Each frame's code (:class:`bendsense.status.Status`): ``OK``,
        ``NOT_IDENTIFIABLE``, ``CONTACT_UNRESOLVED`` (successes), ``NOT_CONVERGED``,
        ``BEAM_FAILED``, ``NO_STABLE_MATCH``, ``MODEL_MISFIT``, ``PRESSURE_OUT_OF_RANGE``,
        ``IMPLAUSIBLE_FORCE``. :func:`bendsense.status.words` gives their results.csv words.
    message : str or ndarray of str, shape (...)
        For people: ``"converged"``, ``"not identifiable along (x, y): ..."`` or the
        reason for ``success=False``, with the numbers that tell it (nothing parses it:
        the status is ``status``).
    iterations : ndarray of int, shape (...)
        Beam solves spent on each frame (objective evaluations for ``paper``).
    wall_time_s : float
        Wall time of the whole call [s].
    method : str
        ``"fast"`` or ``"paper"``.
    constraint : str
        The constraint (see the module docstring).
    uncertainty : str
        ``"propagated"`` (sensor noise, calibration error and parameter covariance through the fit) or ``"none"``
        (no noise model: ``std_n`` and ``covariance_n2`` NaN).
    tip_position_m : ndarray, shape (..., 2)
        Tip of the model shape at the estimate [m].
    state : ndarray, shape (..., n_nodes) or None
        Beam state at the estimate: the tangent angle [rad] at the
        :data:`~bendsense.estimation.problem.N_NODES` Chebyshev–Lobatto nodes
        (:func:`~bendsense.estimation.chebyshev_nodes_m`); for ``load="contact"`` at
        s_c < L, the nodes of the two domains split at s_c
        (:func:`bendsense.mechanics._beam_kernels.contact_grid`).
    guess_n : ndarray, shape (..., 2) or None
        The moment-balance starting force; with ``force_n`` it corrects the start of
        the next frame (``initial=`` of the next call).
    chi2_per_dof : ndarray, shape (...) or None
        Misfit of the fit against the propagated shift errors, χ²/dof (about 1 when
        the errors are as modelled); ``std_n`` includes the factor ``max(1, χ²/dof)``
        on the variance. NaN without a noise model and for failed frames.
    objective : str
        What the fit compared: ``"angles"`` (the coil angles) or ``"positions"``.
    covariance_parts_n2 : ndarray, shape (..., 3, 2, 2) or None
        The parts of ``covariance_n2`` [N²] in the order of :data:`BUDGET` (sensor noise,
        calibration error, model parameters); see :attr:`budget`.
    p_value : ndarray, shape (...) or None
        Probability of a χ² at least as large as the frame's under the stated covariance;
        below 0.001 a converged frame is ``model_misfit``. NaN where χ² is.
    residual_rad : ndarray, shape (..., R) or None
        Measured − model coil angle at the optimum [rad], at the R coils on the actuator
        (``coils``); NaN for a frame without a force. What a window test
        (:func:`bendsense.check_windows`) needs, with the next four fields: None unless
        the fast method fitted the coil angles of a PCC shape (``objective="angles"``),
        so that a window test is not available (``window_p_value`` NaN).
    jacobian_rad_per_n : ndarray, shape (..., R, 2) or None
        ∂(model angle)/∂u [rad/N] of the constraint's parameters u (``F = F_fixed + D u``);
        the columns beyond the constraint's k are 0.
    model_factor_rad : ndarray, shape (..., R, 2) or None
        ∂(model angle)/∂(K0, EI) · chol(Σ_(K0,EI)) [rad]: its outer product is the angles'
        covariance from the model parameters (zeros without ``parameter_covariance``).
    shifts_m : ndarray, shape (..., N) or None
        The measured shifts S of the frame [m] (a PCC shape only).
    shift_errors : tuple or None
        The shift error model the estimate used, as a plain tuple of
        :class:`~bendsense.calibration.shift_errors.ShiftErrorModel` (``ShiftErrorModel(*shift_errors)``).
    coils : tuple of int or None
        The channels (0-based) whose coils lie on the actuator: the rows of ``residual_rad``.
    strip_gap_m : float
        The sensor's strip gap d [m]: a coil angle is S / d.
    window_p_value : ndarray, shape (...) or None
        The p-value of the frame's window test (:func:`bendsense.check_windows`); None
        until a window test ran, NaN where none is available.
    load : str
        The load model: ``"tip"`` (the paper's tip force) or ``"contact"`` (one point
        force at arc length ``contact_s_m``; DESIGN section 2b).
    contact_s_m : ndarray, shape (...) or None
        Arc length of the contact [m]; NaN for ``load="tip"``.
    contact_std_m : ndarray, shape (...) or None
        Standard deviation of ``contact_s_m`` [m]: 0 for a known location, ``inf`` where
        the data cannot resolve it (status ``contact_unresolved``), NaN for ``load="tip"``.
    contact_jacobian_rad_per_m : ndarray, shape (..., R) or None
        ∂(model coil angle)/∂s_c [rad/m] at the optimum (force fixed), at the coils of
        ``residual_rad``: how the fit's angles change when the contact point moves toward
        the tip (at s_c = L the one-sided derivative). None for ``load="tip"`` and
        where ``residual_rad`` is None; NaN for a frame without a force.
    """

    __repr__ = brief_repr  # a line or two, not every value of every frame

    force_n: np.ndarray
    std_n: np.ndarray
    covariance_n2: np.ndarray
    residual_m: np.ndarray
    success: np.ndarray
    status: np.ndarray
    message: object
    iterations: np.ndarray
    wall_time_s: float
    method: str
    constraint: str
    uncertainty: str = "propagated"
    tip_position_m: np.ndarray | None = None
    state: np.ndarray | None = field(default=None, repr=False)
    guess_n: np.ndarray | None = field(default=None, repr=False)
    chi2_per_dof: np.ndarray | None = None
    p_value: np.ndarray | None = None
    objective: str = "angles"
    covariance_parts_n2: np.ndarray | None = field(default=None, repr=False)
    residual_rad: np.ndarray | None = field(default=None, repr=False)
    jacobian_rad_per_n: np.ndarray | None = field(default=None, repr=False)
    model_factor_rad: np.ndarray | None = field(default=None, repr=False)
    shifts_m: np.ndarray | None = field(default=None, repr=False)
    shift_errors: tuple | None = field(default=None, repr=False)
    coils: tuple | None = field(default=None, repr=False)
    strip_gap_m: float = field(default=float("nan"), repr=False)
    window_p_value: np.ndarray | None = None
    load: str = "tip"
    contact_s_m: np.ndarray | None = None
    contact_std_m: np.ndarray | None = None
    contact_jacobian_rad_per_m: np.ndarray | None = field(default=None, repr=False)

    @property
    def budget(self) -> dict:
        """The uncertainty budget: the standard deviation (..., 2) [N] of each part.

        ``noise`` (the signal noise of the flat recording), ``calibration`` (the
        calibration polynomials' error) and ``model`` (the identified parameters'
        covariance, ``config.parameter_covariance``); their variances add up to
        ``std_n**2`` (each scaled by the same misfit factor ``max(1, χ²/dof)``).
        """
        parts = np.asarray(self.covariance_parts_n2)
        diag = np.sqrt(np.maximum(np.diagonal(parts, axis1=-2, axis2=-1), 0.0))
        return {name: diag[..., i, :] for i, name in enumerate(BUDGET)}

    @property
    def batch_shape(self) -> tuple:
        """Shape of the leading frame axes (``()`` for one frame)."""
        return np.shape(self.force_n)[:-1]

    def to_dict(self) -> dict:
        """Plain lists and scalars, for JSON/YAML."""
        return {
            "force_n": np.asarray(self.force_n).tolist(),
            "std_n": np.asarray(self.std_n).tolist(),
            "covariance_n2": np.asarray(self.covariance_n2).tolist(),
            "residual_m": np.asarray(self.residual_m).tolist(),
            "success": np.asarray(self.success).tolist(),
            "status": np.asarray(self.status).tolist(),
            "message": np.asarray(self.message).tolist(),
            "iterations": np.asarray(self.iterations).tolist(),
            "wall_time_s": float(self.wall_time_s),
            "method": self.method,
            "constraint": self.constraint,
            "uncertainty": self.uncertainty,
            "objective": self.objective,
            "chi2_per_dof": None if self.chi2_per_dof is None else np.asarray(self.chi2_per_dof).tolist(),
            "p_value": None if self.p_value is None else np.asarray(self.p_value).tolist(),
            "window_p_value": None if self.window_p_value is None else np.asarray(self.window_p_value).tolist(),
            "load": self.load,
            "contact_s_m": None if self.contact_s_m is None else np.asarray(self.contact_s_m).tolist(),
            "contact_std_m": None if self.contact_std_m is None else np.asarray(self.contact_std_m).tolist(),
        }

    def plot(self, ax=None, *, shape=None, t_s=None, scale_mm_per_n: float = 100.0):
        """Draw the estimate (:func:`bendsense.plots.plot_force`); returns the matplotlib axes.

        One frame: the force as an arrow at the model tip (``scale_mm_per_n`` mm per
        newton), over ``shape`` if given, in mm. A batch: Fx and Fy against ``t_s``
        (default the frame index) with ±2σ bands.
        """
        from bendsense.plots import plot_force

        return plot_force(self, ax, shape=shape, t_s=t_s, scale_mm_per_n=scale_mm_per_n)
