"""Shape: curvatures and the continuous shape of the finger from the sensor's shifts (paper section III).

:mod:`~bendsense.shape.pcc` is the piecewise-constant-curvature reconstruction.
"""

from bendsense.shape.pcc import Shape, reconstruct

__all__ = ["Shape", "reconstruct"]
