"""The protocol of the evaluation: the simulated rig, how much is simulated, and the stages that run it.

The true actuator differs from the nominal config (:data:`TRUE_MATERIAL`,
:data:`TRUE_STIFFNESS`), the rig has unmodelled physics (:data:`MISMATCH`) and the camera
that "measures" the truth has noise (:data:`CAMERA_ANGLE_STD_RAD`,
:data:`CAMERA_POINT_STD_M`); :class:`Plan` says how many frames and configurations are
simulated. The stages: the simulated experiments (:func:`simulate_experiments`), the
calibrations of degree 1–3 (:func:`calibrate_degrees`), the identification of the model
parameters from camera data (:func:`identify_parameters`) and the timing of every stage
(:func:`time_stages`). The package docstring (:mod:`bendsense.apps.evaluation`) describes
the whole protocol.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bendsense.config import Config, GravityConfig, MaterialConfig, StiffnessConfig

__all__ = [
    "TRUE_MATERIAL",
    "TRUE_STIFFNESS",
    "MISMATCH",
    "CAMERA_ANGLE_STD_RAD",
    "CAMERA_POINT_STD_M",
    "CAMERA_MARKERS",
    "MAX_TIP_LOAD_N",
    "MAX_CONTACT_N",
    "FORCE_RANGES_N",
    "FIG9B_PRESSURE_PA",
    "CONTACT_MODES",
    "OBJECTIVE_NAMES",
    "SIGMA_LEVELS",
    "Plan",
    "true_config",
    "simulate_experiments",
    "calibrate_degrees",
    "identify_parameters",
    "parameters",
    "combinations",
    "time_stages",
    "timed",
]

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
#: The objectives compared side by side, with their names in the report.
OBJECTIVE_NAMES = {"angles": "coil angles (default)", "positions": "PCC positions (paper eq. 18)"}
#: The levels of the coverage table and the calibration figure [σ].
SIGMA_LEVELS = (1.0, 2.0, 3.0)




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
    """The simulated actuator: ``nominal`` with :data:`TRUE_MATERIAL` and :data:`TRUE_STIFFNESS`.

    Parameters
    ----------
    nominal : Config, optional
        The nominal config; None takes the paper's (:func:`bendsense.load_config`).
    """
    if nominal is None:
        from bendsense.config import load_config

        nominal = load_config()
    return nominal.replace(
        material=MaterialConfig(**TRUE_MATERIAL),
        stiffness=StiffnessConfig(**TRUE_STIFFNESS),
        name="reproduce: simulated actuator",
    )


def timed(fn, *args, **kwargs) -> tuple:
    """``fn(*args, **kwargs)`` and its wall time [s].

    Parameters
    ----------
    fn : callable
        The function to time.
    *args, **kwargs
        Its arguments.
    """
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def combinations(pressure, load) -> tuple:
    """First frame and label index of each (pressure, load) combination.

    Parameters
    ----------
    pressure : array_like, shape (frames,)
        Pressure of each frame [Pa].
    load : array_like, shape (frames,)
        Tip load of each frame [N].

    Returns
    -------
    first : ndarray of int
        The first frame of each combination.
    inverse : ndarray of int, shape (frames,)
        The combination of each frame (an index into ``first``).
    """
    keys = np.stack([np.asarray(pressure, float), np.asarray(load, float)], axis=-1)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, inverse.reshape(-1)


# --------------------------------------------------------------------------- stages


def simulate_experiments(tmp: Path, config: Config, seed: int, plan: Plan) -> dict:
    """Write the simulated experiments into ``tmp``; return their paths.

    Parameters
    ----------
    tmp : Path
        Directory to write into.
    config : Config
        The simulated (true) actuator and sensor.
    seed : int
        Seed of the simulation.
    plan : Plan
        How many frames and combinations to simulate.
    """
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


def calibrate_degrees(manifest: Path, sensor) -> tuple:
    """Calibrations of degree n = 1, 2, 3 from one manifest (paper V-B), and the seconds each fit took.

    Parameters
    ----------
    manifest : Path
        The calibration manifest of the simulated strips.
    sensor : SensorConfig
        The sensor the calibration is for.

    Returns
    -------
    tuple of dict
        Degree → :class:`~bendsense.calibration.Calibration`, degree → fit time [s].
    """
    from bendsense.calibration import Calibration

    cals, seconds = {}, {}
    for n in (1, 2, 3):
        cals[n], seconds[n] = timed(Calibration.fit, manifest, sensor, degree=n)
    return cals, seconds


def _camera_points(truth_s, truth_positions, rng):
    """The 14 colour markers of the camera: true points along the actuator plus pixel noise."""
    s_dots = np.linspace(0.0, truth_s[-1], CAMERA_MARKERS + 1)[1:]
    x = np.array([np.interp(s_dots, truth_s, p[:, 0]) for p in truth_positions])
    y = np.array([np.interp(s_dots, truth_s, p[:, 1]) for p in truth_positions])
    points = np.stack([x, y], axis=-1)
    return s_dots, points + rng.normal(0.0, CAMERA_POINT_STD_M, points.shape)


def parameters(config: Config) -> dict:
    """The identified parameters of ``config``: μ̄, μ_s, prebend, ei0 (γ0) and ei1 (γ1), by field name.

    Parameters
    ----------
    config : Config
        The config to read.
    """
    return {
        "shear_modulus_pa": config.material.shear_modulus_pa,
        "sensor_stiffness_nm_per_rad": config.material.sensor_stiffness_nm_per_rad,
        "prebend_angle_rad": config.material.prebend_angle_rad,
        "ei0_nm2": config.stiffness.ei0_nm2,
        "ei1_nm2_per_pa": config.stiffness.ei1_nm2_per_pa,
    }


def identify_parameters(free, tips, tip_truth, nominal: Config, rng) -> tuple:
    """Identify μ̄, μ_s, prebend (free bending) and EI(P) (loaded shapes) as in paper V-C.

    Uses :func:`bendsense.identify.fit_free_bending` on camera angles of the free-bending
    frames, then :func:`bendsense.identify.fit_stiffness` on camera markers of two randomly
    chosen loaded combinations per pressure. Returns the identified config and a dict:
    ``free_pressure_pa``, ``free_angle_rad`` (the camera data), ``ei_pressure_pa``,
    ``ei_nm2``, ``ei_stderr_nm2`` (EI per pressure level), ``stderr`` (of every
    identified parameter), ``correlation_mu_mus`` (of μ̄ and μ_s), ``stiffness_frames``
    (the chosen tip-load frames), ``fits`` (the two fit objects).

    Parameters
    ----------
    free : Session
        The free-bending session.
    tips : Session
        The tip-load session.
    tip_truth : dict
        The simulated truth of the tip-load frames (``truth.npz``).
    nominal : Config
        The nominal config the fit starts from.
    rng : numpy.random.Generator
        Draws the camera noise and the chosen frames.
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
    first, _ = combinations(p_tip, load)
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


def time_stages(tips, contact_shape, contact, cal, model_config, plan, say) -> dict:
    """Time per frame of reconstruction and force estimation, fast and the paper's method.

    Parameters
    ----------
    tips : Session
        The tip-load session (its signals and pressures are timed).
    contact_shape : Shape
        Reconstructed shapes of the contact frames.
    contact : Session
        The contact session.
    cal : Calibration
        The sensor calibration.
    model_config : Config
        The identified model of the actuator.
    plan : Plan
        How many frames to time.
    say : callable
        Progress messages, ``say(text)``.
    """
    from bendsense.estimation import estimate_force
    from bendsense.shape.pcc import reconstruct

    sensor = model_config.sensor
    out = {}
    reps = math.ceil(plan.reconstruction_frames / len(tips.signals))
    batch = np.tile(tips.signals, (reps, 1))
    reconstruct(batch[:100], cal, sensor)  # warm the caches
    _, seconds = timed(reconstruct, batch, cal, sensor)
    out["reconstruction_batched_s_per_frame"] = seconds / len(batch)
    single = []
    for i in range(50):
        single.append(timed(reconstruct, tips.signals[i % len(tips.signals)], cal, sensor)[1])
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
