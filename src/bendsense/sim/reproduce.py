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
   reconstructed (:func:`~bendsense.pcc.reconstruct`) and scored by κ_recon (eq. 19) and
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
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bendsense import output
from bendsense.config import Config, GravityConfig, MaterialConfig, StiffnessConfig

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
]

#: The published numbers of paper section V (Table I, Fig. 9, Fig. 10, Table II, timing).
PAPER = {
    "table_i": {
        "radius_mm": (45.75, 55.75, 65.75, 75.75, 85.75, 95.75, 150.75),
        "kappa_val_per_m": (21.86, 17.94, 15.21, 13.20, 11.66, 10.44, 6.63),
        1: {
            "kappa_recon_per_m": (21.65, 17.60, 14.99, 12.98, 11.50, 10.20, 6.74),
            "dkappa_pct": (0.94, 1.88, 1.43, 1.71, 1.39, 2.29, 1.63),
            "dp_max_pct": (3.98, 2.61, 1.67, 1.42, 1.77, 2.62, 1.21),
            "dkappa_all_pct": (1.61, 0.42),
            "dp_max_all_pct": (2.19, 0.96),
        },
        2: {
            "kappa_recon_per_m": (21.77, 17.73, 15.11, 13.07, 11.58, 10.26, 6.69),
            "dkappa_pct": (0.38, 1.13, 0.65, 0.99, 0.74, 1.80, 0.87),
            "dp_max_pct": (3.66, 2.65, 1.85, 1.24, 1.19, 2.10, 0.98),
            "dkappa_all_pct": (0.94, 0.45),
            "dp_max_all_pct": (1.95, 0.95),
        },
        3: {
            "kappa_recon_per_m": (21.69, 17.75, 15.20, 13.20, 11.71, 10.40, 6.74),
            "dkappa_pct": (0.76, 1.04, 0.08, 0.08, 0.46, 0.41, 1.69),
            "dp_max_pct": (3.01, 2.05, 1.50, 1.22, 1.19, 1.27, 0.89),
            "dkappa_all_pct": (0.65, 0.58),
            "dp_max_all_pct": (1.59, 0.72),
        },
    },
    # Fig. 9(a): upper bounds quoted in the text
    "fig9_model_max_pct": 6.0,
    "fig9_sensor_max_pct": 6.32,
    # Fig. 10: mean ± std of the tip-load error in % of 0.3 N
    "fig10_all_pct": (11.9, 14.4),
    "fig10_0_to_0p2_pct": (5.49, 4.99),
    # Table II: mean errors in % of the largest contact force, per force range
    "table_ii": {
        "ranges_n": ((0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4)),
        "none": {
            "fx": (4.13, 8.13, 17.70, 6.29, 14.90),
            "fy": (2.93, 2.51, 13.18, 42.95, 12.91),
            "fc": (4.27, 4.40, 9.04, 12.19, 7.21),
        },
        "normal": {
            "fx": (1.57, 3.02, 7.42, 9.15, 5.15),
            "fy": (3.91, 3.43, 4.29, 21.01, 6.77),
            "fc": (2.61, 1.35, 7.52, 8.17, 4.86),
        },
    },
    "reconstruction_hz": 35.0,
    "force_none_s": 0.42,
    "force_constrained_s": 1.38,
}

#: Free-bending parameters of the simulated ("true") actuator; the nominal config has
#: the placeholders μ̄ = 0.18 MPa, μ_s = 1.5e-3 N·m/rad and no prebend.
TRUE_MATERIAL = {"shear_modulus_pa": 0.20e6, "sensor_stiffness_nm_per_rad": 1.2e-3, "prebend_angle_rad": 0.05}
#: Stiffness of the true actuator; the nominal config has the paper's γ0 = 2.53e-3 N·m²,
#: γ1 = 1.25e-8 N·m²/Pa.
TRUE_STIFFNESS = {"ei0_nm2": 2.30e-3, "ei1_nm2_per_pa": 1.40e-8}
#: Sensor noise [counts] and unmodelled base rotation [rad per rad of bending].
MISMATCH = {"noise_counts": 1.5, "base_rotation_rad_per_rad": 0.03}
#: Noise of the camera's free-bending angle [rad] (0.5°).
CAMERA_ANGLE_STD_RAD = math.radians(0.5)
#: Noise of the camera's marker positions, per coordinate [m].
CAMERA_POINT_STD_M = 0.3e-3
#: Colour markers along the actuator (paper V-A).
CAMERA_MARKERS = 14
#: Tip-load range of the paper [N]; Fig. 10 errors are relative to its maximum.
MAX_TIP_LOAD_N = 0.3
#: Contact forces are drawn from [0, 0.4] N; Table II errors are relative to 0.4 N.
MAX_CONTACT_N = 0.4
#: Force ranges of Table II [N].
FORCE_RANGES_N = ((0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4))
#: Pressure of Fig. 9(b) [Pa].
FIG9B_PRESSURE_PA = 40e3
#: Contact estimation modes: (label, constraint, options).
CONTACT_MODES = (
    ("without constraint", "none", {}),
    ("normal, tip angle from the model (paper)", "normal", {"tip_angle_source": "model"}),
    ("normal, tip angle from the shape", "normal", {"tip_angle_source": "shape"}),
)
_DPI = 100
#: The objectives compared side by side, with their names in the report.
OBJECTIVE_NAMES = {"angles": "coil angles (default)", "positions": "PCC positions (paper eq. 18)"}
#: The levels of the coverage table and the calibration figure [σ].
SIGMA_LEVELS = (1.0, 2.0, 3.0)


# --------------------------------------------------------------------------- plan


@dataclass(frozen=True, kw_only=True)
class Plan:
    """How much to simulate: the full evaluation or a quick one (tests).

    Attributes
    ----------
    strip_frames : int
        Frames per calibration and validation strip.
    tip_pressures_pa : tuple of float
        Pressures of the tip-load experiment [Pa].
    tip_frames : int
        Frames per pressure-load combination.
    free_pressures_pa : tuple of float
        Pressures of the free-bending experiment [Pa].
    free_frames : int
        Frames (camera shots) per free-bending pressure.
    contact_configs : int
        Random contact configurations.
    contact_frames : int
        Frames per contact configuration.
    paper_frames : int
        Most frames timed with the paper's (slow) estimation method, per constraint;
        0 skips it.
    paper_budget_s : float
        No further frame of the paper's method is started after this time [s], per
        constraint (the first one always runs).
    reconstruction_frames : int
        Frames of the batched reconstruction timing.
    """

    strip_frames: int
    tip_pressures_pa: tuple
    tip_frames: int
    free_pressures_pa: tuple
    free_frames: int
    contact_configs: int
    contact_frames: int
    paper_frames: int
    paper_budget_s: float
    reconstruction_frames: int

    @classmethod
    def full(cls) -> Plan:
        """The paper's experiments: 50 frames per strip, 20–120 kPa in 10 kPa steps, 12 contacts."""
        return cls(
            strip_frames=50,
            tip_pressures_pa=tuple(float(p) for p in np.arange(20e3, 120e3 + 1, 10e3)),
            tip_frames=5,
            free_pressures_pa=tuple(float(p) for p in np.arange(0.0, 120e3 + 1, 10e3)),
            free_frames=3,
            contact_configs=12,
            contact_frames=5,
            paper_frames=2,
            paper_budget_s=10.0,
            reconstruction_frames=100_000,
        )

    @classmethod
    def quick(cls) -> Plan:
        """Fewer frames and configurations, no timing of the paper's method; still every table and figure."""
        return cls(
            strip_frames=8,
            tip_pressures_pa=(20e3, 40e3, 80e3, 120e3),
            tip_frames=2,
            free_pressures_pa=tuple(float(p) for p in np.arange(0.0, 120e3 + 1, 20e3)),
            free_frames=1,
            contact_configs=6,
            contact_frames=2,
            paper_frames=0,
            paper_budget_s=0.0,
            reconstruction_frames=10_000,
        )


def true_config(nominal: Config | None = None) -> Config:
    """The simulated actuator: ``nominal`` with :data:`TRUE_MATERIAL` and :data:`TRUE_STIFFNESS`."""
    if nominal is None:
        from bendsense.config import load_config

        nominal = load_config()
    return nominal.replace(
        material=MaterialConfig(**TRUE_MATERIAL),
        stiffness=StiffnessConfig(**TRUE_STIFFNESS),
        name="reproduce: simulated actuator",
    )


# --------------------------------------------------------------------------- result


@dataclass(frozen=True, kw_only=True, eq=False)
class ReproduceResult:
    """Numbers of one :func:`reproduce` run.

    Attributes
    ----------
    table_i : dict
        Per degree n (1, 2, 3): ``kappa_recon_per_m``, ``dkappa_pct``, ``dp_max_pct``
        (arrays over the validation strips) and ``dkappa_all_pct``, ``dp_max_all_pct``
        (mean, sample std); plus ``radius_m`` and ``kappa_val_per_m``.
    static : dict
        ``pressure_pa`` (P,), ``model_error_pct`` (P,), ``sensor_error_pct`` (P,):
        max position error relative to L, averaged across loads (Fig. 9(a)).
    tip_load : dict
        Per objective (:data:`OBJECTIVE_NAMES`): :func:`tip_load_errors` (``error_pct``,
        ``all_pct``, ``low_pct``, ``z``, ``coverage``, ``failed``, ...).
    contact : dict
        Per objective: :func:`contact_errors`, per mode label ``fx``, ``fy``, ``fc`` mean
        errors [%] and ``coverage`` per force range then the full range, ``counts``, ``failed``.
    identification : dict
        ``true``, ``nominal``, ``identified``: parameter dicts (``shear_modulus_pa``,
        ``sensor_stiffness_nm_per_rad``, ``prebend_angle_rad``, ``ei0_nm2``,
        ``ei1_nm2_per_pa``); ``stderr`` of the identified ones; per-pressure EI.
    timings : dict
        Stage name → seconds (see the report).
    report_path : Path
        ``report.md``.
    figures : tuple of Path
        The PNG figures.
    wall_time_s : float
        Run time of the whole evaluation [s].
    """

    table_i: dict
    static: dict
    tip_load: dict
    contact: dict
    identification: dict
    timings: dict
    report_path: Path
    figures: tuple
    wall_time_s: float
    seed: int = 0
    quick: bool = False
    extra: dict = field(default_factory=dict, repr=False)


# --------------------------------------------------------------------------- helpers


def _mean_std(values) -> tuple:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (math.nan, math.nan)
    return (float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan)


def _timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def _read(path: Path):
    from bendsense.session import read_session_csv

    return read_session_csv(path)


def _configs(pressure, load) -> tuple:
    """First frame and label index of each (pressure, load) combination, in order of appearance."""
    keys = np.stack([np.asarray(pressure, float), np.asarray(load, float)], axis=-1)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, inverse.reshape(-1)


# --------------------------------------------------------------------------- stages


def _simulate(tmp: Path, config: Config, seed: int, plan: Plan) -> dict:
    """Write the simulated experiments into ``tmp``; return their paths."""
    from bendsense.sim.scenarios import simulate

    def run(name, scenario=None, cfg=config, **options):
        return simulate(scenario or name, tmp / name, cfg, seed, **options, **MISMATCH)

    # actuator on its side: the bending plane is horizontal, gravity does not bend it
    flat = config.replace(gravity=GravityConfig(g_m_per_s2=0.0, direction=config.gravity.direction))
    return {
        "calibration": run("calibration", frames_per_strip=plan.strip_frames),
        "validation": run("validation", frames_per_strip=plan.strip_frames),
        "tip-loads": run("tip-loads", pressures_pa=plan.tip_pressures_pa, frames_per_config=plan.tip_frames),
        "free-bending": run(
            "free-bending",
            "tip-loads",
            flat,
            pressures_pa=plan.free_pressures_pa,
            loads_n=(0.0,),
            frames_per_config=plan.free_frames,
        ),
        "contact": run("contact", n_configs=plan.contact_configs, frames_per_config=plan.contact_frames),
    }


def _calibrate(manifest: Path, sensor) -> tuple:
    from bendsense.calibration import Calibration

    cals, seconds = {}, {}
    for n in (1, 2, 3):
        cals[n], seconds[n] = _timed(Calibration.fit, manifest, sensor, degree=n)
    return cals, seconds


def shape_accuracy(calibration, strips, sensor, s_m) -> dict:
    """Table I for one calibration: κ_recon, δκ and (δp)_max of each validation strip.

    Parameters
    ----------
    calibration : Calibration
        Signal → shift calibration (paper eq. 1–2).
    strips : sequence of (signals (frames, N), κ_val [1/m])
        The recordings of the validation strips and their true curvatures.
    sensor : SensorConfig
        Segment lengths and strip gap.
    s_m : ndarray, shape (M,)
        Arc lengths of the compared points on ``[0, L_sensor]`` [m].

    Returns
    -------
    dict
        ``kappa_recon_per_m`` (strips,): mean over the frames of κ_recon (paper eq. 19);
        ``dkappa_pct``: ``|κ_recon − κ_val| / κ_val · 100``; ``dp_max_pct``: mean over the
        frames of (δp)_max (paper eq. 20, relative to the sensor length); ``shapes``:
        the reconstructed positions of each strip's first frame (strips, M, 2) [m].
    """
    from bendsense.pcc import fit_arc_curvature, max_position_error, reconstruct

    length = float(np.sum(sensor.lengths_m))
    kappa, dkappa, dp, shapes = [], [], [], []
    for signals, kappa_val in strips:
        shape = reconstruct(signals, calibration, sensor, s_m)
        k = fit_arc_curvature(shape.positions_m, s_m)
        kappa.append(float(np.mean(k)))
        dkappa.append(abs(kappa[-1] - kappa_val) / kappa_val * 100.0)
        dp.append(float(np.mean(max_position_error(shape.positions_m, s_m, kappa_val, length))))
        shapes.append(shape.positions_m[0])
    return {
        "kappa_recon_per_m": np.array(kappa),
        "dkappa_pct": np.array(dkappa),
        "dp_max_pct": np.array(dp),
        "dkappa_all_pct": _mean_std(dkappa),
        "dp_max_all_pct": _mean_std(dp),
        "shapes": np.array(shapes),
    }


def _camera_points(truth_s, truth_positions, rng):
    """The 14 colour markers of the camera: true points along the actuator plus pixel noise."""
    s_dots = np.linspace(0.0, truth_s[-1], CAMERA_MARKERS + 1)[1:]
    x = np.array([np.interp(s_dots, truth_s, p[:, 0]) for p in truth_positions])
    y = np.array([np.interp(s_dots, truth_s, p[:, 1]) for p in truth_positions])
    points = np.stack([x, y], axis=-1)
    return s_dots, points + rng.normal(0.0, CAMERA_POINT_STD_M, points.shape)


def _parameters(config: Config) -> dict:
    return {
        "shear_modulus_pa": config.material.shear_modulus_pa,
        "sensor_stiffness_nm_per_rad": config.material.sensor_stiffness_nm_per_rad,
        "prebend_angle_rad": config.material.prebend_angle_rad,
        "ei0_nm2": config.stiffness.ei0_nm2,
        "ei1_nm2_per_pa": config.stiffness.ei1_nm2_per_pa,
    }


def _identify(free, tips, tip_truth, nominal: Config, rng) -> tuple:
    """Identify μ̄, μ_s, prebend (free bending) and EI(P) (loaded shapes) as in paper V-C.

    Uses :func:`bendsense.identify.fit_free_bending` on camera angles of the free-bending
    frames, then :func:`bendsense.identify.fit_stiffness` on camera markers of two randomly
    chosen loaded combinations per pressure. Returns the identified config and a dict:
    ``free_pressure_pa``, ``free_angle_rad`` (the camera data), ``ei_pressure_pa``,
    ``ei_nm2``, ``ei_stderr_nm2`` (EI per pressure level), ``stderr`` (of every
    identified parameter), ``correlation_mu_mus`` (of μ̄ and μ_s), ``stiffness_frames``
    (the chosen tip-load frames), ``fits`` (the two fit objects).
    """
    from bendsense.identify import StiffnessData, fit_free_bending, fit_stiffness

    # free bending: one camera angle per frame
    pressure = np.asarray(free.pressure_pa)
    angle = np.asarray(free.extra["tip_angle_rad"]) + rng.normal(0.0, CAMERA_ANGLE_STD_RAD, pressure.size)
    fb = fit_free_bending(pressure, angle, nominal)
    config = fb.to_config(nominal)

    # stiffness: two randomly chosen loaded combinations per pressure, one camera shot each
    p_tip = np.asarray(tips.pressure_pa)
    load = np.asarray(tips.extra["load_n"])
    first, _ = _configs(p_tip, load)
    chosen = []
    for p in np.unique(p_tip):
        loaded = [i for i in first if p_tip[i] == p and load[i] > 0]
        chosen.extend(rng.choice(loaded, size=min(2, len(loaded)), replace=False).tolist())
    chosen = np.sort(np.array(chosen, dtype=int))
    s_dots, points = _camera_points(tip_truth["s_m"], tip_truth["positions_m"][chosen], rng)
    force = np.stack([tips.extra["fx_n"][chosen], tips.extra["fy_n"][chosen]], axis=-1)
    data = StiffnessData(p_tip[chosen], force, np.broadcast_to(s_dots, points.shape[:-1]), points)
    st = fit_stiffness(data, config)
    config = st.to_config(config)
    names = list(fb.free)
    corr = (float(fb.correlation[names.index("shear_modulus_pa"), names.index("sensor_stiffness_nm_per_rad")])
            if {"shear_modulus_pa", "sensor_stiffness_nm_per_rad"} <= set(names) else math.nan)
    return config, {
        "free_pressure_pa": pressure,
        "free_angle_rad": angle,
        "ei_pressure_pa": st.level_pressure_pa,
        "ei_nm2": st.level_ei_nm2,
        "ei_stderr_nm2": st.level_ei_stderr_nm2,
        "stderr": {**fb.stderr, **st.stderr},
        "correlation_mu_mus": corr,
        "stiffness_frames": chosen,
        "fits": (fb, st),
    }


def static_model_errors(tips, truth, calibration, model_config: Config) -> dict:
    """Fig. 9: max position errors of the static model and of the sensor against the truth.

    Parameters
    ----------
    tips : Session
        The tip-load recording (``pressure_pa``, ``load_n``, ``fx_n``, ``fy_n``).
    truth : mapping
        ``s_m`` (M,) on the sensor line and ``positions_m`` (frames, M, 2) of the true
        shapes [m].
    calibration : Calibration
        For the sensor reconstruction.
    model_config : Config
        The identified model: free bending, EI(P), gravity.

    Returns
    -------
    dict
        Per pressure level (``pressure_pa`` (P,)): ``model_error_pct``, ``sensor_error_pct``
        (max over the sensor line of the distance to the true shape, relative to the
        actuator length, averaged across loads); per combination (``config_pressure_pa``,
        ``config_load_n``): ``config_model_error_pct``, ``config_sensor_error_pct``, and the
        shapes (``model_positions_m``, ``sensor_positions_m``, ``truth_positions_m``).
    """
    from bendsense.actuator import FreeBendingModel
    from bendsense.beam import solve_beam
    from bendsense.pcc import reconstruct

    s = np.asarray(truth["s_m"])
    true_pos = np.asarray(truth["positions_m"])
    length = model_config.actuator.length_m
    pressure = np.asarray(tips.pressure_pa)
    load = np.asarray(tips.extra["load_n"])
    first, config_of = _configs(pressure, load)
    p_c, load_c = pressure[first], load[first]
    force = np.stack([tips.extra["fx_n"][first], tips.extra["fy_n"][first]], axis=-1)
    free = FreeBendingModel.from_config(model_config)
    model = solve_beam(
        length,
        model_config.stiffness.ei_nm2(p_c),
        free.tip_curvature_per_m(p_c),
        force,
        model_config.weight_per_length_n_per_m,
        s_m=s,
        warn=False,
    )
    model_err = np.max(np.linalg.norm(model.positions_m - true_pos[first], axis=-1), axis=-1) / length * 100.0
    model_err = np.where(model.success, model_err, np.nan)
    shape = reconstruct(tips.signals, calibration, model_config.sensor, s)
    frame_err = np.max(np.linalg.norm(shape.positions_m - true_pos, axis=-1), axis=-1) / length * 100.0
    sensor_err = np.array([frame_err[config_of == c].mean() for c in range(first.size)])
    levels = np.unique(p_c)
    return {
        "pressure_pa": levels,
        "model_error_pct": np.array([np.nanmean(model_err[p_c == p]) if np.any(np.isfinite(model_err[p_c == p]))
                                     else np.nan for p in levels]),
        "sensor_error_pct": np.array([sensor_err[p_c == p].mean() for p in levels]),
        "config_pressure_pa": p_c,
        "config_load_n": load_c,
        "config_model_error_pct": model_err,
        "config_sensor_error_pct": sensor_err,
        "model_positions_m": model.positions_m,
        "sensor_positions_m": shape.positions_m[first],
        "truth_positions_m": true_pos[first],
        "model_failed": int(np.count_nonzero(~np.asarray(model.success))),
    }


def tip_load_errors(shape, tips, calibration, model_config: Config, objective: str = "angles") -> dict:
    """Fig. 10: tip-load estimates with the vertical constraint, errors in % of 0.3 N.

    Returns ``pressure_pa``, ``load_n``, ``error_pct`` per frame (NaN where the estimate
    failed), ``all_pct`` and ``low_pct`` (mean, std over all frames and over loads of
    0–0.2 N), ``z`` (the error of F̂y in units of its σ), ``coverage`` (fraction of the
    frames with |z| ≤ 2), ``failed`` and the :class:`~bendsense.estimation.ForceEstimate`.
    """
    from bendsense.estimation import estimate_force

    est = estimate_force(shape, tips.pressure_pa, model_config, constraint="vertical", calibration=calibration,
                         objective=objective)
    load = np.asarray(tips.extra["load_n"])
    diff = est.force_n[:, 1] - np.asarray(tips.extra["fy_n"])
    err = np.abs(diff) / MAX_TIP_LOAD_N * 100.0
    z = diff / est.std_n[:, 1]
    return {
        "pressure_pa": np.asarray(tips.pressure_pa),
        "load_n": load,
        "error_pct": err,
        "all_pct": _mean_std(err),
        "low_pct": _mean_std(err[load <= 0.2 + 1e-9]),
        "z": z,
        "coverage": _coverage(z),
        "failed": int(np.count_nonzero(~np.asarray(est.success))),
        "estimate": est,
    }


def _coverage(z, k: float = 2.0) -> float:
    """Fraction of the finite ``z`` (errors in units of their σ) with |z| ≤ k."""
    z = np.asarray(z, dtype=float).ravel()
    z = z[~np.isnan(z)]
    return float(np.mean(np.abs(z) <= k)) if z.size else math.nan


def contact_errors(shape, contact, calibration, model_config: Config, objective: str = "angles") -> dict:
    """Table II: contact-force errors with and without the normal constraint (eq. 21).

    Errors ``|F̂x − Fx|``, ``|F̂y − Fy|`` and ``| ‖F̂‖ − f_c |`` in % of
    :data:`MAX_CONTACT_N`, averaged per range of the true ``f_c`` and over all frames.
    Returns, per mode label of :data:`CONTACT_MODES`: ``fx``, ``fy``, ``fc`` (5 values:
    the four ranges of :data:`FORCE_RANGES_N`, then the full range), ``coverage`` (the
    fraction of the components F̂x, F̂y within ±2σ, likewise), ``z`` (frames, 2), ``counts``
    (frames per range), ``failed`` and ``seconds_per_frame``; and ``tip_angle_offset_deg``: mean
    and max of |φ_free(P) − φ_L|, how far the free-motion tip angle of the model (which
    sets the paper's constraint direction) is from the true loaded tip angle [deg].
    """
    from bendsense.actuator import FreeBendingModel
    from bendsense.estimation import estimate_force

    true_f = np.stack([contact.extra["fx_n"], contact.extra["fy_n"]], axis=-1)
    fc = np.asarray(contact.extra["fc_n"])
    bins = [(fc >= lo) & (fc < hi if i < len(FORCE_RANGES_N) - 1 else fc <= hi)
            for i, (lo, hi) in enumerate(FORCE_RANGES_N)]
    out = {}
    for label, constraint, opts in CONTACT_MODES:
        est = estimate_force(shape, contact.pressure_pa, model_config, constraint=constraint,
                             calibration=calibration, objective=objective, **opts)
        # a component the constraint fixes exactly (σ = 0 and no error) is not a claim to test
        z = np.where(est.std_n > 0, (est.force_n - true_f) / np.where(est.std_n > 0, est.std_n, 1.0), np.nan)
        errors = {
            "fx": np.abs(est.force_n[:, 0] - true_f[:, 0]),
            "fy": np.abs(est.force_n[:, 1] - true_f[:, 1]),
            "fc": np.abs(np.linalg.norm(est.force_n, axis=-1) - fc),
        }
        row = {"counts": [int(np.count_nonzero(b)) for b in bins]}
        for key, e in errors.items():
            e = e / MAX_CONTACT_N * 100.0
            row[key] = [_mean_std(e[b])[0] for b in bins] + [_mean_std(e)[0]]
        row["coverage"] = [_coverage(z[b]) for b in bins] + [_coverage(z)]
        row["z"] = z
        row["failed"] = int(np.count_nonzero(~np.asarray(est.success)))
        row["seconds_per_frame"] = est.wall_time_s / len(fc)
        out[label] = row
    free_tip = FreeBendingModel.from_config(model_config).tip_angle_rad(np.asarray(contact.pressure_pa))
    offset = np.degrees(np.abs(free_tip - np.asarray(contact.extra["tip_angle_rad"])))
    out["tip_angle_offset_deg"] = (float(offset.mean()), float(offset.max()))
    return out


def _timings(tips, contact_shape, contact, cal, model_config, plan, say) -> dict:
    """Time per frame of reconstruction and force estimation, fast and the paper's method."""
    from bendsense.estimation import estimate_force
    from bendsense.pcc import reconstruct

    sensor = model_config.sensor
    out = {}
    reps = math.ceil(plan.reconstruction_frames / len(tips.signals))
    batch = np.tile(tips.signals, (reps, 1))
    reconstruct(batch[:100], cal, sensor)  # warm the caches
    _, seconds = _timed(reconstruct, batch, cal, sensor)
    out["reconstruction_batched_s_per_frame"] = seconds / len(batch)
    single = []
    for i in range(50):
        single.append(_timed(reconstruct, tips.signals[i % len(tips.signals)], cal, sensor)[1])
    out["reconstruction_single_s"] = float(np.median(single))

    for _, constraint, opts in CONTACT_MODES[:2]:
        key = "none" if constraint == "none" else "normal"
        est = estimate_force(contact_shape, contact.pressure_pa, model_config, constraint=constraint,
                             calibration=cal, **opts)
        out[f"force_fast_{key}_batched_s_per_frame"] = est.wall_time_s / len(contact.pressure_pa)
        single = [estimate_force(contact_shape[i], contact.pressure_pa[i], model_config, constraint=constraint,
                                 calibration=cal, **opts).wall_time_s for i in range(min(10, len(contact.pressure_pa)))]
        out[f"force_fast_{key}_single_s"] = float(np.median(single))
        # the paper's method: one frame per contact configuration, the first ones, until
        # the time budget is spent (its time per frame varies a lot between frames)
        candidates = np.unique(contact.extra["config"], return_index=True)[1][: plan.paper_frames]
        paper, frames = [], []
        for i in candidates:
            if sum(e.wall_time_s for e in paper) >= plan.paper_budget_s:
                break
            say(f"  the paper's method ({constraint}), frame {i} ...")
            paper.append(estimate_force(contact_shape[i], contact.pressure_pa[i], model_config,
                                        constraint=constraint, method="paper", calibration=cal, **opts))
            frames.append(i)
        out[f"force_paper_{key}_frames"] = len(frames)
        if not frames:
            out[f"force_paper_{key}_s"] = out[f"force_paper_{key}_max_diff_n"] = math.nan
            continue
        fast = estimate_force(contact_shape[frames], contact.pressure_pa[frames], model_config,
                              constraint=constraint, calibration=cal, objective="positions", **opts)
        out[f"force_paper_{key}_s"] = float(np.mean([e.wall_time_s for e in paper]))
        diff = [np.max(np.abs(e.force_n - f)) for e, f in zip(paper, fast.force_n)]
        out[f"force_paper_{key}_max_diff_n"] = float(np.max(diff))
    return out


# --------------------------------------------------------------------------- figures


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=_DPI)
    return path


def _fig8(path, table, radii, kappa_val, s_m) -> Path:
    from bendsense.pcc import arc_positions
    from bendsense.plots import plot_shape_comparison

    fig = _figure(figsize=(7.6, 5.4))
    ax = fig.add_subplot()
    # the actual strips at marker spacing: dots on every point would hide the lines
    plot_shape_comparison(
        table[3]["shapes"],
        arc_positions(np.asarray(kappa_val), np.linspace(0.0, s_m[-1], CAMERA_MARKERS + 1)),
        ax,
        labels=[f"R = {r * 1e3:.2f} mm" for r in radii],
        names=("reconstructed (n = 3)", "model", "actual strip"),
    )
    legend = ax.get_legend()
    ax.legend(handles=legend.legend_handles, fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0))
    ax.set_title("Validation strips: reconstructed (n = 3) vs actual shapes", fontsize="medium")
    return _save(fig, path)


def _fig9(path, static) -> Path:
    from bendsense.plots import plot_shape_comparison

    fig = _figure(figsize=(11.0, 5.0))
    ax_a, ax_b = fig.subplots(1, 2, width_ratios=(1.2, 1.0))
    p = static["pressure_pa"] * 1e-3
    ax_a.plot(p, static["model_error_pct"], "o-", label="static model (identified)")
    ax_a.plot(p, static["sensor_error_pct"], "s-", label="sensor reconstruction (n = 3)")
    ax_a.axhline(PAPER["fig9_model_max_pct"], color="C0", linestyle=":", linewidth=1,
                 label=f"paper: model below {PAPER['fig9_model_max_pct']:g} %")
    ax_a.axhline(PAPER["fig9_sensor_max_pct"], color="C1", linestyle="--", linewidth=1,
                 label=f"paper: sensor below {PAPER['fig9_sensor_max_pct']:g} %")
    ax_a.set_xlabel("pressure [kPa]")
    ax_a.set_ylabel("max position error [% of L], mean over tip loads")
    ax_a.set_ylim(bottom=0)
    ax_a.grid(True, alpha=0.3)
    ax_a.legend(fontsize="small")
    ax_a.set_title("(a) max position error vs pressure", fontsize="medium")
    pick = np.flatnonzero(np.isclose(static["config_pressure_pa"], FIG9B_PRESSURE_PA))
    if pick.size == 0:  # a plan without 40 kPa: the lowest pressure above it
        level = static["pressure_pa"][np.argmin(np.abs(static["pressure_pa"] - FIG9B_PRESSURE_PA))]
        pick = np.flatnonzero(static["config_pressure_pa"] == level)
    pick = pick[np.argsort(static["config_load_n"][pick])]
    level_kpa = static["config_pressure_pa"][pick[0]] * 1e-3
    truth = static["truth_positions_m"][pick]
    markers = np.linspace(0, truth.shape[1] - 1, CAMERA_MARKERS + 1).round().astype(int)
    plot_shape_comparison(
        static["sensor_positions_m"][pick],
        truth[:, markers],
        ax_b,
        model=static["model_positions_m"][pick],
        labels=[f"{f:.1f} N" for f in static["config_load_n"][pick]],
        names=("sensor", "model", "truth"),
    )
    ax_b.set_title(f"(b) shapes at {level_kpa:g} kPa, tip loads 0–0.3 N", fontsize="medium")
    return _save(fig, path)


def _fig10(path, tips) -> Path:
    from bendsense.plots import plot_force_error_map

    fig = _figure(figsize=(8.0, 7.0))
    axes = fig.subplots(len(tips), 1, sharex=True, sharey=True)
    for ax, (objective, tip) in zip(axes, tips.items(), strict=True):
        plot_force_error_map(tip["pressure_pa"], tip["load_n"], tip["error_pct"], ax,
                             error_label="|F̂y − Fy| [% of 0.3 N]")
        mean, std = tip["all_pct"]
        ax.set_title(f"{OBJECTIVE_NAMES[objective]}: {mean:.2f} % ± {std:.2f} %, ±2σ covers "
                     f"{tip['coverage']:.0%} of the frames", fontsize="medium")
        ax.label_outer()
    pm, ps = PAPER["fig10_all_pct"]
    fig.suptitle(f"Tip-load estimation error, vertical constraint (paper {pm:g} % ± {ps:g} %)")
    return _save(fig, path)


def _fig_coverage(path, zs) -> Path:
    """Nominal against observed coverage of |z| ≤ k (k from 0 to 3.5), one curve per objective."""
    fig = _figure(figsize=(5.6, 5.0))
    ax = fig.add_subplot()
    k = np.linspace(0.0, 3.5, 141)
    nominal = np.array([math.erf(v / math.sqrt(2.0)) for v in k])
    ax.plot([0, 1], [0, 1], "k--", lw=1, label="calibrated (Gaussian)")
    for i, (objective, z) in enumerate(zs.items()):
        ax.plot(nominal, [_coverage(z, v) for v in k], color=f"C{i}", label=OBJECTIVE_NAMES[objective])
        marks = [math.erf(v / math.sqrt(2.0)) for v in SIGMA_LEVELS]
        ax.plot(marks, [_coverage(z, v) for v in SIGMA_LEVELS], "o", color=f"C{i}")
    for v in SIGMA_LEVELS:
        nom = math.erf(v / math.sqrt(2.0))
        ax.annotate(f"{v:g}σ", (nom, nom), textcoords="offset points", xytext=(6, -12), fontsize="small")
    ax.set_xlabel("nominal coverage of ±kσ")
    ax.set_ylabel("observed coverage (tip loads and contact, F̂x and F̂y)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title("Calibration of the force uncertainty", fontsize="medium")
    return _save(fig, path)


def _pooled_z(tip, contact) -> np.ndarray:
    """Every tested z of one objective: the tip loads' F̂y and each contact mode's F̂x, F̂y."""
    parts = [np.asarray(tip["z"]).ravel()]
    parts += [np.asarray(contact[label]["z"]).ravel() for label, _, _ in CONTACT_MODES]
    return np.concatenate(parts)


def _fig_identification(path, ident, nominal, true, identified) -> Path:
    from bendsense.actuator import FreeBendingModel

    fig = _figure(figsize=(11.0, 4.4))
    ax_a, ax_b = fig.subplots(1, 2)
    p = np.linspace(0.0, 125e3, 126)
    models = (("identified", identified, "-"), ("true", true, "--"), ("nominal", nominal, ":"))
    ax_a.plot(ident["free_pressure_pa"] * 1e-3, np.degrees(ident["free_angle_rad"]), "k.", markersize=5,
              label="measured (camera)")
    for name, config, style in models:
        ax_a.plot(p * 1e-3, np.degrees(FreeBendingModel.from_config(config).bending_angle_rad(p)), style,
                  label=f"{name} model")
    ax_a.set_xlabel("pressure [kPa]")
    ax_a.set_ylabel("free bending angle θ [deg]")
    ax_a.grid(True, alpha=0.3)
    ax_a.legend(fontsize="small")
    ax_a.set_title("(a) free bending (paper eq. 8–12)", fontsize="medium")
    ax_b.errorbar(ident["ei_pressure_pa"] * 1e-3, ident["ei_nm2"] * 1e3, yerr=ident["ei_stderr_nm2"] * 1e3,
                  fmt="k.", capsize=2, label="EI per pressure level")
    for name, config, style in models:
        ax_b.plot(p * 1e-3, config.stiffness.ei_nm2(p) * 1e3, style, label=f"{name} γ0 + γ1 P")
    ax_b.set_xlabel("pressure [kPa]")
    ax_b.set_ylabel("flexural rigidity EI [10⁻³ N·m²]")
    ax_b.grid(True, alpha=0.3)
    ax_b.legend(fontsize="small")
    ax_b.set_title("(b) stiffness (paper eq. 15)", fontsize="medium")
    return _save(fig, path)


# --------------------------------------------------------------------------- report


def _f(value, digits=2) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def _pct(fraction) -> str:
    """A fraction as a percentage with one decimal, "–" if unknown."""
    return "–" if fraction is None or not np.isfinite(fraction) else f"{100 * fraction:.1f} %"


def _pm(pair, digits=2) -> str:
    return f"{_f(pair[0], digits)} ± {_f(pair[1], digits)}"


def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _report(res: ReproduceResult, names: dict, command: str) -> str:
    from bendsense import __version__

    paper_i = PAPER["table_i"]
    t1 = res.table_i
    radii = t1["radius_m"]
    lines = [
        "# The paper's evaluation on simulated data",
        "",
        f"Written by `{command}` (bendsense {__version__}, seed {res.seed}"
        f"{', quick' if res.quick else ''}) in {res.wall_time_s:.1f} s on a machine with {os.cpu_count()} CPUs. "
        "Every number below comes from simulated experiments (`bendsense.sim`), beside the numbers the paper "
        "published for its prototype. How the experiments are simulated and scored is in the docstring of "
        "`bendsense.sim.reproduce`; in short:",
        "",
        "- **Unknown material.** The simulated actuator has other free-bending and stiffness parameters than the "
        "nominal config the evaluation starts from (the paper's prototype with its placeholders); the estimator "
        "only uses what it identifies from simulated measurements (section *Identification*).",
        f"- **Unmodelled physics.** The base turns toward the bending by {MISMATCH['base_rotation_rad_per_rad']:g} "
        "rad per rad of free bending angle (the cross-section deformation the paper blames for its 0.3 N errors); "
        "neither the PCC reconstruction nor the beam model knows it.",
        f"- **Sensor.** Coil physics (nonlinear signal vs shift, fitted by polynomials of degree n), per-channel "
        f"offsets, {MISMATCH['noise_counts']:g} counts of Gaussian noise, a 12-bit ADC.",
        f"- **Camera.** Free-bending angles with {math.degrees(CAMERA_ANGLE_STD_RAD):g}° noise; loaded shapes as "
        f"{CAMERA_MARKERS} markers with {CAMERA_POINT_STD_M * 1e3:g} mm noise per coordinate (stiffness fit only).",
        "",
        "## Table I: shape reconstruction on the validation strips (paper section V-B)",
        "",
        "κ_recon is the curvature of the arc closest to the reconstructed shape (paper eq. 19), the mean over "
        "the frames of a strip; δκ = |κ_recon − κ_val| / κ_val; (δp)_max is the largest distance between the "
        "reconstructed and the actual strip relative to the sensor length (eq. 20), the mean over the frames. "
        "*All*: mean ± sample standard deviation over the strips. Paper values in parentheses.",
        "",
    ]
    header = ["n", "quantity"] + [f"{r * 1e3:.2f} mm" for r in radii] + ["All"]
    rows = [["", "κ_val [1/m]"] + [f"{k:.2f}" for k in t1["kappa_val_per_m"]] + [""]]
    for n in (1, 2, 3):
        ours, paper = t1[n], paper_i[n]
        rows.append([f"{n}", "κ_recon [1/m]"] + [f"{a:.2f} ({b:.2f})" for a, b in
                                                 zip(ours["kappa_recon_per_m"], paper["kappa_recon_per_m"])] + ["–"])
        rows.append(["", "δκ [%]"] + [f"{a:.2f} ({b:.2f})" for a, b in zip(ours["dkappa_pct"], paper["dkappa_pct"])]
                    + [f"{_pm(ours['dkappa_all_pct'])} ({_pm(paper['dkappa_all_pct'])})"])
        rows.append(["", "(δp)_max [%]"]
                    + [f"{a:.2f} ({b:.2f})" for a, b in zip(ours["dp_max_pct"], paper["dp_max_pct"])]
                    + [f"{_pm(ours['dp_max_all_pct'])} ({_pm(paper['dp_max_all_pct'])})"])
    lines += [_table(header, rows), ""]
    lines += [
        "## Fig. 8: reconstructed vs actual validation shapes (n = 3)",
        "",
        f"![Fig. 8 analogue]({names['fig8']})",
        "",
    ]

    ident = res.identification
    lines += [
        "## Identification (paper section V-C)",
        "",
        "μ̄, μ_s and the prebend from the free-bending angles (actuator on its side, 0–120 kPa); EI per pressure "
        "level from two randomly chosen loaded combinations per pressure (camera markers), then γ0, γ1 by linear "
        "regression (paper eq. 15), with `bendsense.identify`. Standard errors from the fits. The camera also "
        "sees the unmodelled base rotation, which the identified parameters absorb in part; at small angles μ̄ "
        f"and μ_s act alike (fitted correlation {_f(ident['correlation_mu_mus'], 3)}).",
        "",
    ]
    rows = []
    for key, label in (
        ("shear_modulus_pa", "μ̄ [MPa]"),
        ("sensor_stiffness_nm_per_rad", "μ_s [10⁻³ N·m/rad]"),
        ("prebend_angle_rad", "prebend [deg]"),
        ("ei0_nm2", "γ0 = ei0 [10⁻³ N·m²]"),
        ("ei1_nm2_per_pa", "γ1 = ei1 [10⁻⁵ N·m²/kPa]"),
    ):
        scale = {"shear_modulus_pa": 1e-6, "sensor_stiffness_nm_per_rad": 1e3, "prebend_angle_rad": 180 / math.pi,
                 "ei0_nm2": 1e3, "ei1_nm2_per_pa": 1e8}[key]
        true, nom, got = ident["true"][key], ident["nominal"][key], ident["identified"][key]
        se = ident["stderr"].get(key, math.nan)
        rel = (got - true) / true * 100 if true else math.nan
        rows.append([label, f"{true * scale:.4g}", f"{nom * scale:.4g}", f"{got * scale:.4g} ± {se * scale:.2g}",
                     _f(rel, 1)])
    lines += [_table(["parameter", "true (simulated)", "nominal (start)", "identified ± s.e.", "error [%]"], rows), ""]
    lines += [f"![identification]({names['identification']})", ""]

    st = res.static
    lines += [
        "## Fig. 9: static model and sensor against the true shapes (paper section V-C)",
        "",
        "Max distance between the predicted and the true shape along the sensor line, relative to the actuator "
        "length L, averaged across the tip loads 0–0.3 N at each pressure. Model: beam (eq. 13–17) with the "
        "identified K0(P) and EI(P), gravity and the known load. Sensor: PCC reconstruction with n = 3. "
        f"The paper reports both below {PAPER['fig9_model_max_pct']:g} % (model) and "
        f"{PAPER['fig9_sensor_max_pct']:g} % (sensor).",
        "",
    ]
    rows = [[f"{p * 1e-3:g}", _f(m), _f(s)] for p, m, s in
            zip(st["pressure_pa"], st["model_error_pct"], st["sensor_error_pct"])]
    rows.append(["max", _f(np.nanmax(st["model_error_pct"])), _f(np.nanmax(st["sensor_error_pct"]))])
    lines += [_table(["pressure [kPa]", "model [% of L]", "sensor [% of L]"], rows), ""]
    if st["model_failed"]:
        lines += [f"The beam model found no stable equilibrium for {st['model_failed']} combination(s).", ""]
    lines += [f"![Fig. 9 analogue]({names['fig9']})", ""]

    tips = res.tip_load
    objectives = list(tips)
    lines += [
        "## Fig. 10: tip-load estimation (paper section V-D1)",
        "",
        "The vertical constraint Fx = 0; error |F̂y − Fy| in % of the largest load, 0.3 N, over every frame, for "
        "both objectives: the coil angles S/d the sensor measures (the default) and the PCC positions of paper "
        "eq. 18. Coverage: the fraction of the frames whose true Fy lies within ±2σ of the estimate.",
        "",
        _table(
            ["loads"] + [f"{OBJECTIVE_NAMES[o]}: mean ± std [%]" for o in objectives] + ["paper [%]"]
            + [f"±2σ coverage, {o}" for o in objectives],
            [
                ["0–0.3 N"] + [_pm(tips[o]["all_pct"]) for o in objectives] + [_pm(PAPER["fig10_all_pct"])]
                + [_pct(tips[o]["coverage"]) for o in objectives],
                ["0–0.2 N"] + [_pm(tips[o]["low_pct"]) for o in objectives] + [_pm(PAPER["fig10_0_to_0p2_pct"])]
                + [_pct(_coverage(tips[o]["z"][tips[o]["load_n"] <= 0.2 + 1e-9])) for o in objectives],
            ],
        ),
        "",
    ]
    failed = {o: tips[o]["failed"] for o in objectives if tips[o]["failed"]}
    if failed:
        lines += ["Frames without a converged estimate (left out): "
                  + ", ".join(f"{o}: {n}" for o, n in failed.items()) + ".", ""]
    lines += [f"![Fig. 10 analogue]({names['fig10']})", ""]

    lines += [
        "## Table II: contact force estimation (paper section V-D2)",
        "",
        f"Mean errors in % of the largest contact force ({MAX_CONTACT_N:g} N) per range of the true contact force; "
        f"{res.extra['contact_configs']} random configurations × {res.extra['contact_frames']} frames. F̂c is the "
        "magnitude of the estimated force. The paper's constrained mode takes the tip angle from the free-bending "
        "model; the last mode takes it from the reconstructed shape. Coverage: the fraction of the components "
        "F̂x, F̂y (those the constraint leaves free) whose truth lies within ±2σ.",
        "",
    ]
    labels = [label for label, _, _ in CONTACT_MODES]
    shorts = ("none", "normal (model)", "normal (shape)")
    header = (["force range [N]", "frames"] + [f"{short} {c}" for short in shorts for c in ("F̂x", "F̂y", "F̂c")]
              + [f"{short} ±2σ" for short in shorts])
    ranges = [f"{lo:g}–{hi:g}" for lo, hi in FORCE_RANGES_N] + ["mean of full range"]
    for objective in objectives:
        contact = res.contact[objective]
        counts = contact[labels[0]]["counts"]
        rows = []
        for i, name in enumerate(ranges):
            row = [name, str(counts[i]) if i < len(counts) else str(sum(counts))]
            for label in labels:
                row += [_f(contact[label][c][i]) for c in ("fx", "fy", "fc")]
            row += [_pct(contact[label]["coverage"][i]) for label in labels]
            rows.append(row)
        lines += [f"Here, {OBJECTIVE_NAMES[objective]}:", "", _table(header, rows), ""]
    p2 = PAPER["table_ii"]
    rows = [[name] + [f"{p2[m][c][i]:.2f}" for m in ("none", "normal") for c in ("fx", "fy", "fc")]
            for i, name in enumerate(ranges)]
    lines += ["Paper (12 configurations):", "",
              _table(["force range [N]"] + [f"{m} {c}" for m in ("none", "normal") for c in ("F̂x", "F̂y", "F̂c")], rows),
              ""]
    first = res.contact[objectives[0]]
    mean, worst = first["tip_angle_offset_deg"]
    lines += [
        "The paper's constraint direction is normal to the free-motion tip angle of the model; a contact force "
        f"turns the tip away from it (here by {mean:.1f}° on average, up to {worst:.1f}°, including the model's "
        "error in free bending), so the constrained estimate is forced along a wrong direction, more so the "
        "larger the force. With the tip angle from the reconstructed shape the mean F̂c error "
        f"({OBJECTIVE_NAMES[objectives[0]]}) is {_f(first[labels[2]]['fc'][-1])} % instead of "
        f"{_f(first[labels[1]]['fc'][-1])} % (unconstrained: {_f(first[labels[0]]['fc'][-1])} %).",
        "",
    ]
    failed = {f"{o}, {label}": res.contact[o][label]["failed"] for o in objectives for label in labels
              if res.contact[o][label]["failed"]}
    if failed:
        lines += ["Frames without a converged estimate (left out): "
                  + ", ".join(f"{k}: {v}" for k, v in failed.items()) + ".", ""]

    zs = {o: _pooled_z(tips[o], res.contact[o]) for o in objectives}
    lines += [
        "## Calibration of the uncertainty",
        "",
        "How often the truth lies within ±kσ of the estimate, against the Gaussian's nominal probability, over "
        "every tested force component (the tip loads' F̂y and the contact modes' F̂x, F̂y; "
        f"{', '.join(f'{o}: {np.count_nonzero(np.isfinite(zs[o]))}' for o in objectives)} components). The σ "
        "is the estimator's complete budget: sensor noise, calibration error and the identified parameters' "
        "covariance (docs/theory.md). " + _miss_note(res.identification),
        "",
        _table(["level", "nominal"] + [f"observed, {OBJECTIVE_NAMES[o]}" for o in objectives],
               [[f"±{k:g}σ", _pct(math.erf(k / math.sqrt(2.0)))]
                + [_pct(_coverage(zs[o], k)) for o in objectives] for k in SIGMA_LEVELS]),
        "",
        f"![calibration of the uncertainty]({names['coverage']})",
        "",
    ]

    tm = res.timings
    ms = 1e3
    lines += [
        "## Timing",
        "",
        f"Measured in this run on a machine with {os.cpu_count()} CPUs (shared; load average "
        f"{res.extra['load_average']}). The paper's numbers are from MATLAB on an Intel i7-11800H laptop.",
        "",
        _table(
            ["stage", "here", "paper"],
            [
                ["calibration fit, n = 3 (10 strips + flat, incl. reading the CSVs)",
                 f"{tm['calibration_s'] * ms:.1f} ms", "–"],
                ["shape reconstruction, one frame", f"{tm['reconstruction_single_s'] * 1e6:.0f} µs "
                 f"({1 / tm['reconstruction_single_s']:,.0f} Hz)",
                 f"≥ {PAPER['reconstruction_hz']:g} Hz (hardware bound)"],
                ["shape reconstruction, batched, per frame",
                 f"{tm['reconstruction_batched_s_per_frame'] * 1e6:.2f} µs "
                 f"({1 / tm['reconstruction_batched_s_per_frame']:,.0f} frames/s)", "–"],
                ["identification (free bending + stiffness)", f"{tm['identification_s']:.2f} s", "–"],
                ["force estimate, unconstrained, fast, one frame", f"{tm['force_fast_none_single_s'] * ms:.1f} ms",
                 f"{PAPER['force_none_s']:g} s"],
                ["force estimate, unconstrained, fast, batched per frame",
                 f"{tm['force_fast_none_batched_s_per_frame'] * ms:.2f} ms", "–"],
                ["force estimate, normal constraint, fast, one frame",
                 f"{tm['force_fast_normal_single_s'] * ms:.1f} ms",
                 f"{PAPER['force_constrained_s']:g} s"],
                ["force estimate, normal constraint, fast, batched per frame",
                 f"{tm['force_fast_normal_batched_s_per_frame'] * ms:.2f} ms", "–"],
                _paper_row(tm, "none", "unconstrained, paper's method (shooting + Nelder–Mead)",
                           PAPER["force_none_s"]),
                _paper_row(tm, "normal", "normal constraint, paper's method (shooting + SLSQP)",
                           PAPER["force_constrained_s"]),
                ["whole evaluation (simulation, all stages, figures)", f"{res.wall_time_s:.1f} s", "–"],
            ],
        ),
        "",
    ]
    if tm["force_paper_none_frames"] or tm["force_paper_normal_frames"]:
        diff = np.nanmax([tm["force_paper_none_max_diff_n"], tm["force_paper_normal_max_diff_n"]])
        ratio = [tm[f"force_paper_{k}_s"] / tm[f"force_fast_{k}_single_s"] for k in ("none", "normal")
                 if tm[f"force_paper_{k}_frames"]]
        lines += [
            f"On the frames timed with both, the fast method and the paper's agree to {diff:.1e} N; the fast one "
            f"is {min(ratio):,.0f}–{max(ratio):,.0f} times faster per frame. The paper's method here runs the "
            "shooting reference solver of `bendsense.beam` in every objective evaluation, and its time per frame "
            "varies a lot between frames.",
            "",
        ]
    return "\n".join(lines)


def _miss_note(ident) -> str:
    """Why the coverage may fall short: how far the identified parameters are from the truth, in their s.e."""
    z = {key: (ident["identified"][key] - ident["true"][key]) / se
         for key, se in ident["stderr"].items() if key in ident["true"] and se and np.isfinite(se) and se > 0}
    if not z:
        return ""
    key = max(z, key=lambda k: abs(z[k]))
    return (f"The budget covers what it is told: here the simulated rig has effects the model lacks (the base "
            f"rotation), which the identification absorbs into biased parameters; the worst, {key}, lies "
            f"{abs(z[key]):.1f} standard errors from the truth. Coverage well below nominal means such a "
            "model-form error, which no parameter covariance describes.")


def _paper_row(tm, key, what, paper_s):
    frames = tm[f"force_paper_{key}_frames"]
    if not frames:
        return [f"force estimate, {what}", "not timed (--quick)", f"{paper_s:g} s"]
    return [f"force estimate, {what}, mean of {frames} frame(s)", f"{tm[f'force_paper_{key}_s']:.2f} s",
            f"{paper_s:g} s"]


# --------------------------------------------------------------------------- entry point


def reproduce(
    out_dir,
    *,
    seed: int = 0,
    quick: bool = False,
    overwrite: bool = False,
    progress: Callable[[str], None] | None = None,
    command: str | None = None,
) -> ReproduceResult:
    """Run the paper's evaluation on simulated experiments and write the report.

    Parameters
    ----------
    out_dir : path
        Report directory: ``report.md`` and the PNG figures. Written to a hidden sibling
        first and swapped in at the end (:func:`bendsense.output.write_dir`).
    seed : int
        Seed of the simulated sensor, noise, random configurations and camera noise.
    quick : bool
        :meth:`Plan.quick` (for tests: fewer frames and configurations, every table and
        figure) instead of :meth:`Plan.full`.
    overwrite : bool
        Replace a previous report in ``out_dir`` (never files bendsense did not write).
    progress : callable, optional
        Called with one line of text at the start of each stage.
    command : str, optional
        The command line to quote in the report.

    Returns
    -------
    ReproduceResult

    Raises
    ------
    OutputExistsError
        If ``out_dir`` exists, is not empty and ``overwrite`` is false (a ``FileExistsError``).
    OutputError
        If ``out_dir`` holds files bendsense did not write, or may not be written over.
    """
    from bendsense.config import load_config
    from bendsense.pcc import reconstruct

    t_start = time.perf_counter()
    out = Path(out_dir)
    output.check([output.directory(out, overwrite=overwrite)])
    say = progress or (lambda text: None)
    plan = Plan.quick() if quick else Plan.full()
    nominal = load_config()
    true = true_config(nominal)
    sensor = nominal.sensor
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2000,)))
    timings = {}
    with output.write_dir(out, overwrite=overwrite, writer="bendsense reproduce") as work:
        data = work / "data"
        say("simulating the experiments (calibration, validation, free bending, tip loads, contact) ...")
        paths, timings["simulation_s"] = _timed(_simulate, data, true, seed, plan)

        say("calibration, n = 1, 2, 3 ...")
        cals, seconds = _calibrate(paths["calibration"] / "manifest.yaml", sensor)
        timings["calibration_s"] = seconds[3]

        say("reconstruction of the validation strips (Table I, Fig. 8) ...")
        import yaml

        index = yaml.safe_load((paths["validation"] / "validation.yaml").read_text(encoding="utf-8"))
        strips = [(_read(paths["validation"] / s["recording"]).signals, float(s["kappa_true_per_m"]))
                  for s in index["strips"]]
        s_val = np.linspace(0.0, float(np.sum(sensor.lengths_m)), 133)
        table_i = {n: shape_accuracy(cals[n], strips, sensor, s_val) for n in (1, 2, 3)}
        table_i["radius_m"] = np.array([float(s["radius_m"]) for s in index["strips"]])
        table_i["kappa_val_per_m"] = np.array([k for _, k in strips])

        say("identification: free bending, stiffness ...")
        free = _read(paths["free-bending"] / "tip_loads.csv")
        tips = _read(paths["tip-loads"] / "tip_loads.csv")
        with np.load(paths["tip-loads"] / "truth.npz") as npz:
            tip_truth = {k: npz[k] for k in npz.files}
        (model_config, ident_info), timings["identification_s"] = _timed(
            _identify, free, tips, tip_truth, nominal, rng
        )

        say("static model and sensor vs truth (Fig. 9) ...")
        static = static_model_errors(tips, tip_truth, cals[3], model_config)

        say("tip-load estimation (Fig. 10), both objectives ...")
        tip_shape = reconstruct(tips.signals, cals[3], sensor)
        tip = {obj: tip_load_errors(tip_shape, tips, cals[3], model_config, obj) for obj in OBJECTIVE_NAMES}

        say("contact force estimation (Table II) ...")
        contact = _read(paths["contact"] / "contact.csv")
        contact_shape = reconstruct(contact.signals, cals[3], sensor)
        table_ii = {obj: contact_errors(contact_shape, contact, cals[3], model_config, obj) for obj in OBJECTIVE_NAMES}

        say("timing ...")
        timings.update(_timings(tips, contact_shape, contact, cals[3], model_config, plan, say))
        shutil.rmtree(data)

        say("figures and report ...")
        identification = {
            "true": _parameters(true),
            "nominal": _parameters(nominal),
            "identified": _parameters(model_config),
            **ident_info,
        }
        names = {
            "fig8": "fig8_validation_shapes.png",
            "fig9": "fig9_static_model.png",
            "fig10": "fig10_tip_load_error.png",
            "coverage": "coverage_calibration.png",
            "identification": "identification.png",
        }
        figures = (
            _fig8(work / names["fig8"], table_i, table_i["radius_m"], table_i["kappa_val_per_m"], s_val),
            _fig9(work / names["fig9"], static),
            _fig10(work / names["fig10"], tip),
            _fig_coverage(work / names["coverage"], {o: _pooled_z(tip[o], table_ii[o]) for o in OBJECTIVE_NAMES}),
            _fig_identification(work / names["identification"], identification, nominal, true, model_config),
        )
        result = ReproduceResult(
            table_i=table_i,
            static=static,
            tip_load=tip,
            contact=table_ii,
            identification=identification,
            timings=timings,
            report_path=out / "report.md",
            figures=tuple(out / f.name for f in figures),
            wall_time_s=math.nan,
            seed=seed,
            quick=quick,
            extra={
                "contact_configs": plan.contact_configs,
                "contact_frames": plan.contact_frames,
                "load_average": ", ".join(f"{v:.1f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "?",
            },
        )
        result = dataclasses.replace(result, wall_time_s=time.perf_counter() - t_start)
        if command is None:
            command = f"bendsense reproduce -o {out.name} --seed {seed}" + (" --quick" if quick else "")
        (work / "report.md").write_text(_report(result, names, command) + "\n", encoding="utf-8")
    return result
