"""The named options of the estimator, each declared once.

Plain Python without imports, so that the command line offers these choices without
loading numpy: the config validates against them (:mod:`bendsense.config`), the
estimator dispatches on them (:mod:`bendsense.estimation`) and the CLI's ``--constraint``,
``--method``, ``--objective`` and ``--tip-angle-source`` list them.
"""

__all__ = ["ANGLE_SOURCES", "BEAM_METHODS", "CALIBRATION_DEGREES", "CALIBRATION_WEIGHTINGS", "CONSTRAINTS", "LOADS",
           "METHODS", "OBJECTIVES", "TRACK_MODES"]

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
