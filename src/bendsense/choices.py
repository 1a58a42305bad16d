"""The named options of the estimator, each declared once.

Plain Python without imports, so that the command line offers these choices without
loading numpy: the config validates against them (:mod:`bendsense.config`), the
estimator dispatches on them (:mod:`bendsense.estimation`) and the CLI's ``--constraint``,
``--method``, ``--objective`` and ``--tip-angle-source`` list them.
"""

__all__ = ["ANGLE_SOURCES", "CONSTRAINTS", "METHODS", "OBJECTIVES"]

#: Force constraints ``F = F_fixed + D u`` (:func:`bendsense.estimation.constraint_basis`).
CONSTRAINTS = ("none", "vertical", "horizontal", "direction", "normal", "follower")
#: Estimators: the compiled Gauss–Newton core, or the paper's shooting + Nelder–Mead / SLSQP.
METHODS = ("fast", "paper")
#: What the fit compares: the coil angles S/d the sensor measures, or the PCC positions (paper eq. 18).
OBJECTIVES = ("angles", "positions")
#: Where the tip angle of the normal and follower constraints comes from.
ANGLE_SOURCES = ("model", "shape")
