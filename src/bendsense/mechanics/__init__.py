"""Mechanics of the actuator: its free bending, the curved beam under load, the bounds of its values.

:mod:`~bendsense.mechanics.actuator` (free bending and stiffness, paper eq. 8-12, 15),
:mod:`~bendsense.mechanics.beam` (the curved cantilever, eq. 13-17; compiled kernels in
``_beam_kernels``) and :mod:`~bendsense.mechanics.bounds` (physical bounds of a config).
"""
