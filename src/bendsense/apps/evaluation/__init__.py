"""The paper's evaluation (section V) on simulated experiments: ``bendsense reproduce``.

:func:`reproduce` runs the whole method of the paper on experiments simulated by
:mod:`bendsense.sim.scenarios`, and writes ``report.md`` with PNG figures that are
analogues of the paper's Table I, Fig. 8, Fig. 9, Fig. 10 and Table II, beside the
published numbers (:data:`PAPER`), plus the identified model parameters against the true
ones and the time each stage takes.

The evaluation is not circular: the simulated actuator is not the model the estimator
uses.

- **Unknown material.** The true actuator (:data:`TRUE_MATERIAL`, :data:`TRUE_STIFFNESS`)
  differs from the nominal config the evaluation starts from (the paper's prototype with
  its placeholder μ̄, μ_s and the paper's γ0, γ1). The estimator only gets the parameters
  it identifies from simulated measurements, as in paper section V-C: μ̄, μ_s and the
  prebend from free-bending angles, EI per pressure level and then ei0, ei1 from loaded
  shapes.
- **Unmodelled physics** (:data:`MISMATCH`): the base of the actuator turns with the
  bending (``base_rotation_rad_per_rad``, the cross-section deformation the paper blames
  for its 0.3 N errors), which neither the PCC reconstruction nor the beam model knows.
- **Sensor** (:class:`~bendsense.sim.sensor.VirtualSensor`): the coil physics make the
  signal a nonlinear function of the shift, fitted by polynomials of degree n; per-channel
  offsets; Gaussian noise of :data:`MISMATCH` ``noise_counts``; a 12-bit ADC.
- **Measurements of the truth**: the free-bending angle is "measured" with a camera noise
  of :data:`CAMERA_ANGLE_STD_RAD`, the loaded shapes for the stiffness fit as 14 dots (the
  paper's colour markers) with :data:`CAMERA_POINT_STD_M` noise per coordinate.

Protocol (simulated experiments, one ``seed``):

1. ``calibration`` and ``validation`` strips (paper V-B); calibrations of degree n = 1, 2,
   3 (:meth:`~bendsense.calibration.Calibration.fit`); every validation frame is
   reconstructed (:func:`~bendsense.shape.pcc.reconstruct`) and scored by κ_recon (eq. 19) and
   (δp)_max (eq. 20, relative to the sensor length). κ_recon of a strip is the mean over
   its frames, δκ the error of that mean, (δp)_max the mean over its frames.
2. Free bending with the actuator lying on its side (bending plane horizontal, so gravity
   plays no part, as the free-bending model assumes): the tip angle over 0–120 kPa.
3. Tip loads (paper V-C): 20–120 kPa × 0, 0.1, 0.2, 0.3 N downward on the upright rig.
   Stiffness identification from two randomly chosen loaded combinations per pressure.
   The static model (K0 and EI identified, gravity, known load) and the sensor
   reconstruction (n = 3) are compared with the true shape: max distance over the
   sensor line relative to the actuator length L, averaged across loads (Fig. 9(a)).
   Force estimation with the vertical constraint ``Fx = 0`` (Fig. 10): error
   ``|F̂y − Fy|`` in % of 0.3 N.
4. Contact (paper V-D2): random pressures and contact forces normal to the loaded tip;
   estimates without constraint and with the normal constraint (eq. 21), with the tip
   angle from the free-bending model (the paper's choice) and from the reconstructed
   shape. Errors in % of the largest contact force of the experiment (0.4 N), by force
   range (Table II).

Fig. 10 and Table II are computed for both objectives (the coil angles, the default, and
the paper's PCC positions), each with the ±2σ coverage of the true force; a last section
and figure compare the nominal with the observed coverage at 1σ, 2σ and 3σ.

The package, an application on the library and the simulator (:mod:`bendsense.sim`):

- :mod:`~bendsense.apps.evaluation.published`: the paper's numbers, as data;
- :mod:`~bendsense.apps.evaluation.protocol`: the simulated rig and how much is simulated
  (:class:`Plan`), and the stages: simulation, calibration, identification, timing;
- :mod:`~bendsense.apps.evaluation.metrics`: the scores against the truth (reusable on
  any data with a truth) and the ±kσ coverage;
- :mod:`~bendsense.apps.evaluation.figures` and :mod:`~bendsense.apps.evaluation.report`:
  the PNG figures and ``report.md``, a function per figure and per section;
- :mod:`~bendsense.apps.evaluation.run`: :func:`reproduce`, which runs it all.
"""

from bendsense.apps.evaluation.metrics import (
    contact_errors,
    coverage,
    mean_std,
    shape_accuracy,
    static_model_errors,
    tip_load_errors,
)
from bendsense.apps.evaluation.protocol import (
    CAMERA_ANGLE_STD_RAD,
    CAMERA_POINT_STD_M,
    MISMATCH,
    TRUE_MATERIAL,
    TRUE_STIFFNESS,
    Plan,
    true_config,
)
from bendsense.apps.evaluation.published import PAPER
from bendsense.apps.evaluation.run import ReproduceResult, reproduce

__all__ = [
    "PAPER",
    "TRUE_MATERIAL",
    "TRUE_STIFFNESS",
    "MISMATCH",
    "CAMERA_ANGLE_STD_RAD",
    "CAMERA_POINT_STD_M",
    "Plan",
    "ReproduceResult",
    "reproduce",
    "true_config",
    "shape_accuracy",
    "static_model_errors",
    "tip_load_errors",
    "contact_errors",
    "mean_std",
    "coverage",
]
