"""The named options of the estimator, each declared once, and the options of a run.

Plain Python without numpy, so that the command line offers these choices fast: the
config validates against them (:mod:`bendsense.config`), the estimator dispatches on
them (:mod:`bendsense.estimation`) and the CLI's ``--constraint``, ``--method``,
``--objective``, ``--load`` and ``--tip-angle-source`` list them.

:class:`Options` is what one run of the chain over sessions does to each of them,
built once and passed down (``bendsense process`` → :func:`bendsense.batch.process_sessions`
→ each task → :func:`bendsense.pipeline.process`), instead of a dozen keywords forwarded
by hand through every layer.
"""

import dataclasses
from dataclasses import dataclass

__all__ = ["ANGLE_SOURCES", "BEAM_METHODS", "CALIBRATION_DEGREES", "CALIBRATION_WEIGHTINGS", "CONSTRAINTS", "LOADS",
           "METHODS", "OBJECTIVES", "TRACK_MODES", "Options"]

#: Force constraints ``F = F_fixed + D u`` (:func:`bendsense.estimation.constraint_basis`).
CONSTRAINTS = ("none", "vertical", "horizontal", "direction", "normal", "follower")
#: Load models: one force at the tip (the paper), or at arc length s_c along the body (DESIGN section 2b).
LOADS = ("tip", "contact")
#: Estimators: the compiled Gauss–Newton core, or the paper's shooting + Nelder–Mead / SLSQP.
METHODS = ("fast", "paper")
#: What the fit compares: the coil angles S/d the sensor measures, or the PCC positions (paper eq. 18).
OBJECTIVES = ("angles", "positions")
#: Where the tip angle of the normal and follower constraints comes from.
ANGLE_SOURCES = ("model", "shape")
#: The calibration model: degrees n of the polynomials f_odd, f_even (paper eq. 2) and the fit's weightings.
CALIBRATION_DEGREES = (1, 2, 3, 4, 5)
CALIBRATION_WEIGHTINGS = ("none", "shift")
#: Beam solvers of ``identify``: the spectral collocation, or the paper's shooting.
BEAM_METHODS = ("fast", "shooting")
#: Tracking over time (:func:`bendsense.track`): the RTS smoother (offline) or the causal Kalman filter.
TRACK_MODES = ("smooth", "filter")


@dataclass(frozen=True)
class Options:
    """What a run does to each session, beside its config and calibration.

    Attributes
    ----------
    constraint, method, objective : str, optional
        The force estimate's (:func:`bendsense.estimate_force`); None: the config's.
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa]; None: such frames get a shape only.
    estimate : bool
        Estimate the forces; False: the shapes only.
    track : str, optional
        Track the forces over time (``"smooth"``, ``"filter"``); None: not tracked.
    bandwidth_hz : float, optional
        The track's bandwidth [Hz]; None: chosen from the data.
    window_s : float
        The window of the model check [s].
    load : str
        The load model (:data:`bendsense.choices.LOADS`).
    contact_s_m : float, optional
        A known contact location [m] (``load="contact"``).
    adapt : bool
        First adapt the config to each session's own free frames (:func:`bendsense.adapt`).
    """

    constraint: str | None = None
    method: str | None = None
    objective: str | None = None
    pressure_pa: float | None = None
    estimate: bool = True
    track: str | None = None
    bandwidth_hz: float | None = None
    window_s: float = 0.05
    load: str = "tip"
    contact_s_m: float | None = None
    adapt: bool = False

    def process_keywords(self) -> dict:
        """The keywords of :func:`bendsense.pipeline.process` (all but ``adapt``, which runs before it)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "adapt"}
