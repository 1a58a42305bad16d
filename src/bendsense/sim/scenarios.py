"""The paper's experiments (section V) as simulated recordings with ground truth.

:func:`simulate` writes one scenario (or ``"all"``) as session CSVs (DESIGN section 3)
whose extra columns carry the ground truth, plus a ``scenario.yaml`` describing the
run (seed, options, config, frame counts, files). The output directory is written
to a hidden sibling first and swapped in at the end (:func:`bendsense.output.write_dir`).

``calibration``
    ``flat.csv`` and one recording per calibration strip, ``r040.csv`` … ``r400.csv``
    (R = 40 … 400 mm, paper section V-B), and ``manifest.yaml`` (DESIGN section 3,
    recording paths relative to it): the input of ``bendsense calibrate``. The sensor is
    pressed onto an arc of radius R, so its shifts are ``S_i = κ_cal d L_i`` with
    ``κ_cal = 1/R`` (or ``1/(R + c)`` with ``sensor.calibration_adds_sleeve``,
    :func:`~bendsense.sim.sensor.calibration_shifts`). Truth column: ``kappa_true_per_m``.
``validation``
    One recording per validation strip, ``r045_75.csv`` … ``r150_75.csv``, and
    ``validation.yaml`` listing ``radius_m``, ``kappa_true_per_m`` and ``recording``.
    The paper quotes the validation radii as ``R_val = R + c`` (Table I: 45.75 … 150.75
    mm), i.e. already at the sensor layer; the simulated sensor therefore bends with
    ``κ_true = 1/R_val`` whatever ``calibration_adds_sleeve`` says. Truth columns:
    ``radius_m``, ``kappa_true_per_m``.
``tip-loads``
    ``tip_loads.csv``: P = 20 … 120 kPa in 10 kPa steps × the paper's vertical downward
    tip loads 0, 0.1, 0.2, 0.3 N (section V-C), i.e. ``F = (0, −load)`` in the base frame
    of the upright rig (DESIGN section 2), a few frames each. Truth columns: ``load_n``,
    ``fx_n``, ``fy_n``, ``tip_x_m``, ``tip_y_m``, ``tip_angle_rad``, ``base_angle_rad``
    and ``kappa_true1_per_m`` … (mean true curvature per segment). The true shape of
    every row is in ``truth.npz``: ``s_m`` (M,) on ``[0, L_sensor]``, ``positions_m``
    (frames, M, 2), ``angle_rad`` (frames, M), rows in CSV order.
``contact``
    ``contact.csv``: 12 seeded random configurations (paper section V-D2) of pressure
    and a contact force ``f_c`` in [0, 0.4] N normal to the true loaded tip tangent,
    pushing against the bending (the fingertip of Fig. 7(d)): ``F · t_tip = 0``
    (paper eq. 21). Configurations in which the loaded tip bends less than
    ``min_tip_angle_deg`` (the finger would not be touched) are redrawn. Truth columns
    as for ``tip-loads`` plus ``config`` and ``fc_n``; ``truth.npz`` likewise. With
    ``contact_s_m`` the force acts at that arc length along the body instead, normal to
    the true loaded tangent there (a frictionless contact, ``F · t(s_c) = 0``; beyond
    ``s_c`` the finger bends freely under its weight), and the truth columns gain
    ``contact_s_m`` after ``fy_n``.
``time-varying``
    ``session.csv``: a run at ``rate_hz`` (100 Hz) for ``duration_s`` (10 s): the pressure
    ramps smoothly between 0 and 100 kPa and back with a period of 5 s while a contact
    force normal to the tip switches on and off smoothly (:func:`time_varying_profile`).
    With ``contact_s_m`` (an arc length, or ``"along-body"``: each touch somewhere else,
    :func:`touch_locations`) the touches land along the body, normal to the loaded
    tangent there. Truth columns: ``fx_n``, ``fy_n``, (``contact_s_m`` with that option),
    ``fc_n``, ``tip_x_m``, ``tip_y_m``, ``tip_angle_rad``, ``effective_pressure_pa``;
    ``truth.npz`` likewise. The same frames
    stream from :func:`time_varying_frames`, which the simulated device uses.
``free-sweep``
    ``free_sweep.csv``: a free pressure sweep, the recording ``bendsense identify
    free-bending --session`` identifies the free-bending model from: ``n_frames``
    frames at ``rate_hz`` while the pressure ramps linearly from 0 to
    ``pressure_max_pa`` and back (a time series: ``hysteresis_pa`` acts), no load but
    gravity. With ``contact_n`` > 0 a contact force of that size, normal to the tip and
    pushing against the bending, acts over the middle fifth of the way down (someone
    touched the actuator: frames the identification must reject). Truth columns as for
    ``tip-loads`` plus ``fc_n``, ``effective_pressure_pa``, ``k0_true_per_m`` (the true
    natural curvature K0) and ``ei_true_nm2``; ``truth.npz`` likewise.

Frames whose beam solve fails (``success=False``) are left out of the recordings and
counted in ``scenario.yaml`` and in the CSV's ``# excluded_frames:`` metadata line.

Seeds: one ``seed`` fixes everything. The sensor hardware (offsets, gains) is drawn from
it as :meth:`VirtualSensor.from_config` does, and is the same in every scenario of that
seed (so a calibration from ``calibration`` applies to the others); each scenario draws
its noise and random configurations from its own stream, spawned from the seed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from bendsense import output
from bendsense.calibration import strip_shifts
from bendsense.config import Config
from bendsense.errors import ArgumentError, ConfigError
from bendsense.session import Session, write_session_csv
from bendsense.sim.actuator import MODEL_ERRORS, SimulatedActuator, contact_number
from bendsense.sim.memory import BASE_BYTES, available_memory_bytes, size_text
from bendsense.sim.sensor import VirtualSensor, calibration_shifts

__all__ = [
    "SCENARIOS",
    "CALIBRATION_RADII_M",
    "VALIDATION_RADII_M",
    "TIP_LOAD_PRESSURES_PA",
    "TIP_LOADS_N",
    "simulate",
    "record_calibration",
    "time_varying_profile",
    "time_varying_frames",
    "touch_locations",
    "ALONG_BODY_FRACTIONS",
    "free_sweep_profile",
]

SCENARIOS = ("calibration", "validation", "tip-loads", "contact", "time-varying", "free-sweep")
#: Calibration strip radii R [m] (paper section V-B).
CALIBRATION_RADII_M = (0.040, 0.050, 0.060, 0.070, 0.080, 0.090, 0.100, 0.200, 0.300, 0.400)
#: Validation strip radii R_val = R + c [m], at the sensor layer (paper Table I).
VALIDATION_RADII_M = (0.04575, 0.05575, 0.06575, 0.07575, 0.08575, 0.09575, 0.15075)
#: Pressures of the tip-load experiment [Pa] (paper section V-C).
TIP_LOAD_PRESSURES_PA = tuple(float(p) for p in np.arange(20e3, 120e3 + 1.0, 10e3))
#: Vertical downward tip loads [N] (paper section V-C); ``F = (0, −load)`` here.
TIP_LOADS_N = (0.0, 0.1, 0.2, 0.3)
#: Where the touches of ``contact_s_m="along-body"`` land, as fractions of the actuator
#: length L, one touch after the other (two touches per 10 s, so the cycle repeats every 30 s).
ALONG_BODY_FRACTIONS = (0.5, 0.7, 0.85, 1.0, 0.6, 0.9)

_FORMAT = "bendsense-sim-scenario"
_FORMAT_VERSION = 1
_BLOCK_S = 0.1  # time simulated per batch of time_varying_frames (one batched beam solve) [s]
# a spawn key apart from the two that VirtualSensor.from_config uses for the same seed
_STREAM_BASE = 1000

# options each scenario accepts besides the actuator's (noise and mismatch)
_ACTUATOR_OPTIONS = ("noise_counts", *MODEL_ERRORS)
_OPTIONS = {
    "calibration": {"frames_per_strip": 50, "rate_hz": 35.0, "radii_m": CALIBRATION_RADII_M},
    "validation": {"frames_per_strip": 50, "rate_hz": 35.0, "radii_m": VALIDATION_RADII_M},
    "tip-loads": {
        "frames_per_config": 5,
        "rate_hz": 35.0,
        "pressures_pa": TIP_LOAD_PRESSURES_PA,
        "loads_n": TIP_LOADS_N,
    },
    "contact": {
        "n_configs": 12,
        "frames_per_config": 5,
        "rate_hz": 35.0,
        "pressure_range_pa": (40e3, 120e3),
        "force_range_n": (0.0, 0.4),
        "min_tip_angle_deg": 15.0,
        "contact_s_m": None,
    },
    "time-varying": {"rate_hz": 100.0, "duration_s": 10.0, "contact_n": 0.15, "contact_s_m": None},
    "free-sweep": {"n_frames": 200, "rate_hz": 35.0, "pressure_max_pa": 120e3, "contact_n": 0.0},
}


# --------------------------------------------------------------------------- profiles


def time_varying_profile(t_s, *, pressure_max_pa=100e3, period_s=5.0, contact_n=0.15):
    """Pressure and contact force of the ``time-varying`` scenario at times ``t_s``.

    The pressure ramps smoothly up and down, ``P = P_max (1 − cos(2π t / T)) / 2``; the
    contact force magnitude switches on and off with raised-cosine edges of 0.3 s, on
    over [1.5, 3.5] s and [6.5, 8.5] s of every 10 s (periodic, so the stream never ends).

    Parameters
    ----------
    t_s : array_like
        Times [s].
    pressure_max_pa : float
        Peak pressure [Pa].
    period_s : float
        Period of the pressure ramp [s].
    contact_n : float
        Contact force magnitude while on [N].

    Returns
    -------
    pressure_pa, contact_n : ndarray
        Same shape as ``t_s`` [Pa], [N].
    """
    t = np.asarray(t_s, dtype=float)
    pressure = 0.5 * pressure_max_pa * (1.0 - np.cos(2.0 * np.pi * t / period_s))
    cycle = np.mod(t, 10.0)
    edge = 0.3
    on = np.zeros_like(t)
    for start, stop in ((1.5, 3.5), (6.5, 8.5)):
        rise = np.clip((cycle - start) / edge, 0.0, 1.0)
        fall = np.clip((stop - cycle) / edge, 0.0, 1.0)
        on = np.maximum(on, np.minimum(rise, fall))
    return pressure, contact_n * 0.5 * (1.0 - np.cos(np.pi * on))


def touch_locations(t_s, length_m: float, contact_s_m=None) -> np.ndarray:
    """Where the contact force of the ``time-varying`` scenario acts at times ``t_s`` [m].

    ``None``: at the tip (``L``); a number: always there; ``"along-body"``: each touch
    (the two on-periods of every 10 s, :func:`time_varying_profile`) at the next of
    :data:`ALONG_BODY_FRACTIONS` ``· L``. The location changes only at ``t = 5 s`` and
    ``10 s`` of every cycle, while the contact force is off.

    Parameters
    ----------
    t_s : array_like
        Times [s].
    length_m : float
        Actuator length L [m].
    contact_s_m : None, float or "along-body"
        The location, or the name of the sequence of locations.

    Returns
    -------
    ndarray
        Same shape as ``t_s`` [m].
    """
    t = np.asarray(t_s, dtype=float)
    if contact_s_m is None:
        return np.full(t.shape, float(length_m))
    if isinstance(contact_s_m, str):
        if contact_s_m != "along-body":
            raise ConfigError(f"contact_s_m: must be a number in (0, L] or 'along-body', got {contact_s_m!r}")
        touch = (2 * np.floor(t / 10.0) + (np.mod(t, 10.0) >= 5.0)).astype(np.int64)
        return np.asarray(ALONG_BODY_FRACTIONS)[touch % len(ALONG_BODY_FRACTIONS)] * float(length_m)
    return np.full(t.shape, contact_number(contact_s_m, float(length_m), " or 'along-body'"))


def time_varying_frames(
    config: Config | None = None,
    rate_hz: float = 100.0,
    seed: int | None = 0,
    *,
    truth: bool = False,
    duration_s: float | None = None,
    contact_n: float = 0.15,
    contact_s_m=None,
    noise_counts: float = 1.5,
    sensor: VirtualSensor | None = None,
    **mismatch,
) -> Iterator:
    """Stream the frames of the ``time-varying`` scenario one at a time, at any rate.

    This is the default source of the simulated device (``bendsense.device.simdevice``)
    and of ``bendsense demo``. Frames are simulated in blocks of 0.1 s
    (one batched beam solve per block) and yielded one by one; the stream is endless
    unless ``duration_s`` is given. The hysteresis state carries over between blocks.
    A frame whose beam solve fails repeats the last valid shape (with fresh noise) and
    has ``valid=False`` in its truth.

    Parameters
    ----------
    config : Config, optional
        Default: the paper's prototype.
    rate_hz : float
        Frame rate [Hz]; frame ``k`` is at ``t = k / rate_hz``.
    seed : int or None
        Seed of the sensor hardware and the noise (as :func:`simulate`).
    truth : bool
        Also yield the ground truth of each frame.
    duration_s : float, optional
        Stop after this time [s].
    contact_n : float
        Contact force magnitude while on [N].
    contact_s_m : None, float or "along-body"
        Where the contact force acts (:func:`touch_locations`): the tip (default), an arc
        length s_c [m] along the body, or a sequence of touches along the body. The force
        is normal to the true loaded tangent at s_c.
    noise_counts : float
        Sensor noise [counts] (when ``sensor`` is not given).
    sensor : VirtualSensor, optional
        Sensor hardware; default from ``config`` and ``seed``.
    **mismatch
        ``ei_error``, ``k0_error``, ``base_rotation_rad_per_rad``, ``hysteresis_pa``
        (:class:`~bendsense.sim.actuator.SimulatedActuator`).

    Yields
    ------
    pressure_pa : float
        Pressure reading [Pa].
    counts : ndarray of uint16, shape (N,)
        ADC counts.
    truth : dict
        Only with ``truth=True``: ``t_s``, ``effective_pressure_pa``, ``fx_n``, ``fy_n``,
        ``contact_s_m``, ``fc_n``, ``tip_x_m``, ``tip_y_m``, ``tip_angle_rad``, ``valid``, ``angle_rad``
        (M,), ``positions_m`` (M, 2), ``s_m`` (M,).
    """
    rate = _positive_option("rate_hz", rate_hz)
    block = max(1, round(rate * _BLOCK_S))
    total = None if duration_s is None else round(rate * _positive_option("duration_s", duration_s))
    sim = _actuator(config, seed, sensor=sensor, noise_counts=noise_counts, **mismatch)
    touch_locations(0.0, sim.config.actuator.length_m, contact_s_m)  # a bad location fails here, not mid-stream
    rng = _stream(seed, "time-varying")
    return _stream_frames(sim, rate, block, total, float(contact_n), rng, truth, contact_s_m)


def _stream_frames(sim, rate, block, total, contact_n, rng, truth, where=None):
    k0 = 0
    state = None
    last_valid = None
    length = sim.config.actuator.length_m
    while total is None or k0 < total:
        n = block if total is None else min(block, total - k0)
        t = (k0 + np.arange(n)) / rate
        location = touch_locations(t, length, where)
        n = int(np.argmax(location != location[0])) or n  # one location per block: the block ends where it moves
        t, sc = t[:n], float(location[0])
        pressure, contact = time_varying_profile(t, contact_n=contact_n)
        frames = sim.frames(pressure, contact_n=contact, contact_s_m=None if where is None else sc,
                            time_series=True, initial_pa=state, noise=False)
        state = frames.effective_pressure_pa[-1]
        shifts = frames.shifts_m.copy()
        valid = frames.valid
        for i in range(n):
            if valid[i]:
                last_valid = i, frames
            elif last_valid is not None:
                shifts[i] = last_valid[1].shifts_m[last_valid[0]]
        counts = sim.sensor.measure(shifts, rng=rng).counts
        for i in range(n):
            if not truth:
                yield float(pressure[i]), counts[i]
                continue
            yield (
                float(pressure[i]),
                counts[i],
                {
                    "t_s": float(t[i]),
                    "effective_pressure_pa": float(frames.effective_pressure_pa[i]),
                    "fx_n": float(frames.force_n[i, 0]),
                    "fy_n": float(frames.force_n[i, 1]),
                    "contact_s_m": sc,
                    "fc_n": float(contact[i]),
                    "tip_x_m": float(frames.tip_position_m[i, 0]),
                    "tip_y_m": float(frames.tip_position_m[i, 1]),
                    "tip_angle_rad": float(frames.tip_angle_rad[i]),
                    "valid": bool(valid[i]),
                    "s_m": frames.s_m,
                    "angle_rad": frames.angle_rad[i],
                    "positions_m": frames.positions_m[i],
                },
            )
        k0 += n


# --------------------------------------------------------------------------- helpers


def _positive_option(name, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: must be a finite number > 0, got {value!r}")
    return float(value)


def _count_option(name, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{name}: must be an integer >= 1, got {value!r}")
    return int(value)


def _stream(seed, scenario) -> np.random.Generator:
    key = _STREAM_BASE + SCENARIOS.index(scenario)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(key,)))


def _config(config) -> Config:
    what = str(config) if isinstance(config, (str, os.PathLike)) else "config"
    if config is None or isinstance(config, (str, os.PathLike)):
        from bendsense.config import load_config

        config = load_config(config)
    if hasattr(type(config), "single_message"):  # a gripper: the scenarios simulate one actuator
        raise ConfigError(config.single_message(what))
    if not isinstance(config, Config):
        raise ConfigError(f"config: expected a Config, a path or None, got {type(config).__name__}")
    return config


def _actuator(config, seed, *, sensor=None, noise_counts=1.5, **mismatch) -> SimulatedActuator:
    unknown = sorted(set(mismatch) - set(_ACTUATOR_OPTIONS))
    if unknown:
        raise ConfigError(f"options: unknown {', '.join(unknown)}; allowed: {', '.join(_ACTUATOR_OPTIONS[1:])}")
    return SimulatedActuator.from_config(
        _config(config), sensor=sensor, noise_counts=noise_counts, seed=seed, **mismatch
    )


def _session(counts, pressure_pa, rate_hz, meta, extra) -> Session:
    n = len(counts)
    return Session(np.arange(n) / rate_hz, np.asarray(counts, dtype=float), pressure_pa, meta=meta, extra=extra)


def _meta(scenario, seed, **more) -> dict:
    meta = {"format": f"{_FORMAT} {_FORMAT_VERSION}", "scenario": scenario, "seed": "none" if seed is None else seed}
    meta.update(more)
    return meta


def _truth_columns(frames, fc=None, contact=False) -> dict:
    extra = {
        "fx_n": frames.force_n[:, 0],
        "fy_n": frames.force_n[:, 1],
    }
    if contact:
        extra["contact_s_m"] = np.full(len(frames.valid), frames.contact_s_m)
    if fc is not None:
        extra["fc_n"] = fc
    extra.update(
        tip_x_m=frames.tip_position_m[:, 0],
        tip_y_m=frames.tip_position_m[:, 1],
        tip_angle_rad=frames.tip_angle_rad,
        base_angle_rad=frames.base_angle_rad,
    )
    for i in range(frames.curvature_per_m.shape[-1]):
        extra[f"kappa_true{i + 1}_per_m"] = frames.curvature_per_m[:, i]
    return extra


def _save_truth(path: Path, frames) -> None:
    with open(path, "wb") as fh:
        np.savez(fh, s_m=frames.s_m, positions_m=frames.positions_m, angle_rad=frames.angle_rad)


def _repeat(frames, count):
    """Each of the configurations in ``frames`` repeated ``count`` times (noise is drawn later)."""
    return frames.select(np.repeat(np.arange(len(frames.valid)), count))


# --------------------------------------------------------------------------- scenarios


class _Run(NamedTuple):
    """Where a scenario records: the simulated actuator, its noise stream, the directory, the scenario, its seed."""

    sim: SimulatedActuator
    rng: np.random.Generator
    out: Path
    scenario: str
    seed: int


def _strip_recordings(run, names, shifts, kappa, radii, n, rate):
    """Record the sensor held on fixed shapes: ``n`` noisy frames per shift vector."""
    for name, shift, k, radius in zip(names, shifts, kappa, radii, strict=True):
        counts = run.sim.sensor.measure(np.broadcast_to(shift, (n, shift.size)), rng=run.rng).counts
        meta = _meta(run.scenario, run.seed, rate_hz=rate)
        extra = {"kappa_true_per_m": np.full(n, k)}
        if radius is not None:
            meta["radius_m"] = radius
            extra = {"radius_m": np.full(n, radius), **extra}
        write_session_csv(_session(counts, np.nan, rate, meta, extra), run.out / name)


def _radii(radii_m) -> list:
    radii = [float(r) for r in np.atleast_1d(np.asarray(radii_m, dtype=float))]
    if not radii or not all(math.isfinite(r) and r > 0 for r in radii):
        raise ConfigError(f"radii_m: expected positive radii, got {radii_m!r}")
    return radii


def _strip_names(radii) -> list:
    names = [f"r{round(r * 1e3):03d}.csv" for r in radii]
    if len(set(names)) != len(names) or any(abs(r * 1e3 - round(r * 1e3)) > 1e-9 for r in radii):
        names = [f"r{r * 1e3:06.2f}".replace(".", "_") + ".csv" for r in radii]
    return names


def _calibration(run, *, frames_per_strip, rate_hz, radii_m):
    n = _count_option("frames_per_strip", frames_per_strip)
    rate = _positive_option("rate_hz", rate_hz)
    radii = _radii(radii_m)
    names = _strip_names(radii)
    sensor = run.sim.config.sensor
    shifts = calibration_shifts(sensor, radii)
    # κ_cal as calibration_shifts applies it (DESIGN section 2)
    kappa = [1.0 / (r + sensor.sleeve_thickness_m if sensor.calibration_adds_sleeve else r) for r in radii]
    n_channels = sensor.n_segments
    _strip_recordings(run, ["flat.csv"], np.zeros((1, n_channels)), [0.0], [None], n, rate)
    _strip_recordings(run, names, shifts, kappa, [None] * len(radii), n, rate)
    manifest = {
        "flat": "flat.csv",
        "strips": [{"radius_m": r, "recording": name} for r, name in zip(radii, names, strict=True)],
    }
    (run.out / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False), encoding="utf-8")
    return {"frames": n * (len(radii) + 1), "excluded_frames": 0, "files": ["flat.csv", *names, "manifest.yaml"]}


def record_calibration(out_dir, config, seed: int, *, noise_counts: float = 1.5) -> dict:
    """``simulate calibration``'s recordings and manifest into the existing directory ``out_dir``; its summary.

    Parameters
    ----------
    out_dir : path
        An existing directory (being written, e.g. a simulated gripper's ``calibration/``).
    config : Config
        The sensor's and actuator's config.
    seed : int
        Seed of the sensor hardware and the noise.
    noise_counts : float
        Sensor noise std [counts].
    """
    sim = _actuator(config, seed, noise_counts=noise_counts)
    run = _Run(sim, _stream(seed, "calibration"), Path(out_dir), "calibration", seed)
    return _calibration(run, **_OPTIONS["calibration"])


def _validation(run, *, frames_per_strip, rate_hz, radii_m):
    n = _count_option("frames_per_strip", frames_per_strip)
    rate = _positive_option("rate_hz", rate_hz)
    radii = _radii(radii_m)
    names = _strip_names(radii)
    kappa = [1.0 / r for r in radii]
    # R_val is at the sensor layer already: S_i = d L_i / R_val, whatever calibration_adds_sleeve says
    shifts = strip_shifts(kappa, run.sim.sensor.lengths_m, run.sim.sensor.strip_gap_m)
    _strip_recordings(run, names, shifts, kappa, radii, n, rate)
    index = {
        "note": "radius_m is at the sensor layer (R_val = R + c, paper Table I); kappa_true_per_m = 1/radius_m",
        "strips": [
            {"radius_m": r, "kappa_true_per_m": k, "recording": name}
            for r, k, name in zip(radii, kappa, names, strict=True)
        ],
    }
    (run.out / "validation.yaml").write_text(yaml.safe_dump(index, sort_keys=False), encoding="utf-8")
    return {"frames": n * len(radii), "excluded_frames": 0, "files": [*names, "validation.yaml"]}


def _write_frames(run, name, frames, rate_hz, extra_first, fc=None, contact=False):
    """Measure (with noise) and write the valid ones of ``frames`` with their truth."""
    keep = np.asarray(frames.valid)
    excluded = int(keep.size - keep.sum())
    frames = frames.select(keep)
    extra_first = {k: np.asarray(v)[keep] for k, v in extra_first.items()}
    fc = None if fc is None else np.asarray(fc)[keep]
    counts = run.sim.sensor.measure(frames.shifts_m, rng=run.rng).counts
    meta = _meta(run.scenario, run.seed, rate_hz=rate_hz, excluded_frames=excluded)
    extra = {**extra_first, **_truth_columns(frames, fc, contact)}
    write_session_csv(_session(counts, frames.pressure_pa, rate_hz, meta, extra), run.out / name)
    _save_truth(run.out / "truth.npz", frames)
    return {"frames": int(keep.sum()), "excluded_frames": excluded, "files": [name, "truth.npz"]}


def _tip_loads(run, *, frames_per_config, rate_hz, pressures_pa, loads_n):
    n = _count_option("frames_per_config", frames_per_config)
    rate = _positive_option("rate_hz", rate_hz)
    p, load = np.meshgrid(np.asarray(pressures_pa, dtype=float), np.asarray(loads_n, dtype=float), indexing="ij")
    p, load = p.ravel(), load.ravel()
    # the paper's vertical downward load on the upright rig is -Fy (DESIGN section 2)
    force = np.stack([np.zeros_like(load), -load], axis=-1)
    frames = _repeat(run.sim.frames(p, force, noise=False), n)
    return _write_frames(run, "tip_loads.csv", frames, rate, {"load_n": np.repeat(load, n)})


def _contact(run, *, n_configs, frames_per_config, rate_hz, pressure_range_pa, force_range_n, min_tip_angle_deg,
             contact_s_m):
    sim, rng = run.sim, run.rng
    count = _count_option("n_configs", n_configs)
    sc = sim.contact_location(contact_s_m)
    n = _count_option("frames_per_config", frames_per_config)
    rate = _positive_option("rate_hz", rate_hz)
    (p_lo, p_hi), (f_lo, f_hi) = pressure_range_pa, force_range_n
    if not (0 <= p_lo <= p_hi and 0 <= f_lo <= f_hi):
        raise ConfigError(
            f"pressure_range_pa, force_range_n: expected 0 <= low <= high, got {pressure_range_pa!r}, {force_range_n!r}"
        )
    min_angle = math.radians(float(min_tip_angle_deg))
    chosen = []
    # rejection sampling in seeded batches: deterministic for a seed
    for _ in range(20):
        p = rng.uniform(p_lo, p_hi, 2 * count)
        fc = rng.uniform(f_lo, f_hi, 2 * count)
        frames = sim.frames(p, contact_n=fc, contact_s_m=sc, noise=False)
        good = np.flatnonzero(frames.valid & (frames.tip_angle_rad >= min_angle))
        chosen.extend((frames.select(slice(i, i + 1)), fc[i]) for i in good)
        if len(chosen) >= count:
            break
    else:
        raise ConfigError(
            f"contact: found only {len(chosen)} of {count} configurations with a stable contact and a tip angle "
            f">= {min_tip_angle_deg} deg; widen pressure_range_pa or lower force_range_n"
        )
    chosen = chosen[:count]
    picked = chosen[0][0]
    for f, _ in chosen[1:]:
        picked = _concat(picked, f)
    fc = np.repeat([c for _, c in chosen], n)
    frames = _repeat(picked, n)
    return _write_frames(run, "contact.csv", frames, rate, {"config": np.repeat(np.arange(count), n)}, fc,
                         contact=sc is not None)


def _concat(a, b):
    from bendsense.sim.actuator import ActuatorFrames

    whole = ("s_m", "contact_s_m")
    fields = {k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in a.__dataclass_fields__ if k not in whole}
    return ActuatorFrames(s_m=a.s_m, contact_s_m=a.contact_s_m, **fields)


def _check_contact_force(config, contact_n, pressure_max_pa, contact_s_m=None) -> None:
    """Refuse a contact force beyond what the finger can press at the sweep's pressure (a force in mN given in N)."""
    from bendsense.control.force import force_limit_n

    where = contact_s_m if isinstance(contact_s_m, (int, float)) and not isinstance(contact_s_m, bool) else None
    limit = force_limit_n(config, pressure_max_pa, where)
    if isinstance(contact_n, (int, float)) and contact_n > limit:
        hint = "; a force in mN given in N?" if contact_n / 1e3 <= limit else ""
        raise ConfigError(f"contact_n: {contact_n:g} N is beyond what the finger can press at "
                          f"{pressure_max_pa / 1e3:g} kPa (at most {limit:.3g} N, bendsense.control.force_limit_n)"
                          f"{hint}")


def _time_varying(run, *, rate_hz, duration_s, contact_n, contact_s_m):
    sim, out = run.sim, run.out
    rate = _positive_option("rate_hz", rate_hz)
    duration = _positive_option("duration_s", duration_s)
    total = round(rate * duration)
    if total < 1:
        raise ArgumentError(f"rate_hz: {rate:g} Hz over {duration:g} s gives no frame (one needs more than "
                            f"{0.5 / duration:g} Hz)")
    touch_locations(0.0, sim.config.actuator.length_m, contact_s_m)
    _check_contact_force(sim.config, contact_n, 100e3, contact_s_m)  # time_varying_profile's peak pressure
    rows = list(_stream_frames(sim, rate, max(1, round(rate * 0.1)), total, float(contact_n), run.rng, True,
                               contact_s_m))
    keep = np.array([truth["valid"] for _, _, truth in rows])
    excluded = int(keep.size - keep.sum())
    rows = [r for r, k in zip(rows, keep, strict=True) if k]
    truth_keys = ("effective_pressure_pa", "fx_n", "fy_n", *(() if contact_s_m is None else ("contact_s_m",)),
                  "fc_n", "tip_x_m", "tip_y_m", "tip_angle_rad")
    extra = {k: np.array([t[k] for _, _, t in rows]) for k in truth_keys}
    session = Session(
        np.array([t["t_s"] for _, _, t in rows]),
        np.array([c for _, c, _ in rows], dtype=float),
        np.array([p for p, _, _ in rows]),
        meta=_meta(run.scenario, run.seed, rate_hz=rate, excluded_frames=excluded),
        extra=extra,
    )
    write_session_csv(session, out / "session.csv")
    with open(out / "truth.npz", "wb") as fh:
        np.savez(
            fh,
            s_m=rows[0][2]["s_m"] if rows else sim.s_m,
            positions_m=np.array([t["positions_m"] for _, _, t in rows]).reshape(-1, sim.n_points, 2),
            angle_rad=np.array([t["angle_rad"] for _, _, t in rows]).reshape(-1, sim.n_points),
        )
    return {"frames": len(rows), "excluded_frames": excluded, "files": ["session.csv", "truth.npz"]}


def free_sweep_profile(n_frames: int, pressure_max_pa: float, contact_n: float = 0.0):
    """Pressure and contact force of the ``free-sweep`` scenario, frame by frame.

    The pressure ramps linearly from 0 to ``pressure_max_pa`` over the first half of the
    frames and back to 0 over the second; the contact force is ``contact_n`` over the
    middle fifth of the way down (frames in [0.7, 0.8) of the sweep), else 0.

    Parameters
    ----------
    n_frames : int
        Frames of the sweep (>= 2).
    pressure_max_pa : float
        Peak pressure [Pa].
    contact_n : float
        Contact force magnitude while touched [N].

    Returns
    -------
    pressure_pa, contact_n : ndarray, shape (n_frames,)
        [Pa], [N].
    """
    n = _count_option("n_frames", n_frames)
    if n < 2:
        raise ConfigError(f"n_frames: a sweep needs at least 2 frames, got {n_frames!r}")
    top = _positive_option("pressure_max_pa", pressure_max_pa)
    if isinstance(contact_n, bool) or not isinstance(contact_n, (int, float)) or not (
            math.isfinite(contact_n) and contact_n >= 0):
        raise ConfigError(f"contact_n: must be a finite number >= 0, got {contact_n!r}")
    x = np.arange(n) / (n - 1)  # 0 … 1 over the sweep
    pressure = top * (1.0 - np.abs(2.0 * x - 1.0))
    touched = (x >= 0.7) & (x < 0.8)
    return pressure, np.where(touched, float(contact_n), 0.0)


def _free_sweep(run, *, n_frames, rate_hz, pressure_max_pa, contact_n):
    rate = _positive_option("rate_hz", rate_hz)
    pressure, fc = free_sweep_profile(n_frames, pressure_max_pa, contact_n)
    _check_contact_force(run.sim.config, contact_n, pressure_max_pa)
    frames = run.sim.frames(pressure, contact_n=fc if np.any(fc > 0) else None, time_series=True, noise=False)
    first = {"effective_pressure_pa": frames.effective_pressure_pa, "k0_true_per_m": frames.tip_curvature_per_m,
             "ei_true_nm2": frames.ei_nm2}
    return _write_frames(run, "free_sweep.csv", frames, rate, first, fc)


_WRITERS = {
    "calibration": _calibration,
    "validation": _validation,
    "tip-loads": _tip_loads,
    "contact": _contact,
    "time-varying": _time_varying,
    "free-sweep": _free_sweep,
}


# --------------------------------------------------------------------------- entry point


def simulate(scenario: str, out_dir, config=None, seed: int | None = 0, *, overwrite: bool = False, **options) -> Path:
    """Write a simulated scenario (or all of them) with ground truth.

    Parameters
    ----------
    scenario : str
        One of :data:`SCENARIOS` or ``"all"`` (each in a subdirectory of ``out_dir``
        named after it).
    out_dir : path
        Directory to create; written atomically (:func:`bendsense.output.write_dir`).
    config : Config or path, optional
        The true actuator and sensor; default the paper's prototype.
    seed : int or None
        Seed of the sensor hardware, the noise and the random configurations.
    overwrite : bool
        Replace a previous bendsense output in ``out_dir`` (never files it did not write).
    **options
        ``noise_counts`` [counts]; model mismatch ``ei_error``, ``k0_error``,
        ``base_rotation_rad_per_rad``, ``hysteresis_pa`` (see
        :mod:`bendsense.sim.actuator`); per scenario: ``frames_per_strip``,
        ``radii_m`` (calibration, validation), ``frames_per_config`` (tip-loads,
        contact), ``pressures_pa``, ``loads_n`` (tip-loads), ``n_configs``,
        ``pressure_range_pa``, ``force_range_n``, ``min_tip_angle_deg``, ``contact_s_m`` (contact),
        ``duration_s``, ``contact_n``, ``contact_s_m`` (time-varying), ``n_frames``, ``pressure_max_pa``,
        ``contact_n`` (free-sweep), ``rate_hz`` (all). With ``"all"``
        each scenario takes the options it knows.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ConfigError
        An unknown scenario or option, or an invalid value.
    ArgumentError
        If the frames it would hold in memory at once do not fit the machine's free
        memory (:func:`check_memory`).
    OutputExistsError
        If ``out_dir`` exists and ``overwrite`` is false (a ``FileExistsError``).
    OutputError
        If ``out_dir`` holds files bendsense did not write, or may not be written over
        (:func:`bendsense.output.check`).
    """
    return _simulate(scenario, out_dir, config, seed, overwrite=overwrite, **options)[0]


# Peak memory per simulated frame held at once [bytes], measured with /usr/bin/time
# (`simulate SCENARIO --frames 200` vs `--frames 2000`): ~10 KB a frame for the
# scenarios with a beam solve and truth shapes (tip-loads 10.1 KB, contact 9.5 KB), well
# under 1 KB for the strip recordings (written one strip at a time); rounded up.
BYTES_PER_FRAME = {"calibration": 2_000, "validation": 2_000, "tip-loads": 12_000, "contact": 12_000,
                    "time-varying": 12_000, "free-sweep": 12_000}
def frames_in_memory(name: str, options: dict) -> tuple[int, int]:
    """Frames of scenario ``name`` held in memory at once, and frames written in all.

    Parameters
    ----------
    name : str
        One of :data:`SCENARIOS`.
    options : dict
        The scenario's options (defaults filled in from the scenario's table).
    """
    opts = {**_OPTIONS[name], **{k: v for k, v in options.items() if k in _OPTIONS[name]}}
    if name in ("calibration", "validation"):
        per = int(opts["frames_per_strip"])
        return per, per * (len(opts["radii_m"]) + (name == "calibration"))
    if name == "tip-loads":
        n = int(opts["frames_per_config"]) * len(opts["pressures_pa"]) * len(opts["loads_n"])
        return n, n
    if name == "contact":
        n = int(opts["frames_per_config"]) * int(opts["n_configs"])
        return n, n
    if name == "free-sweep":
        n = int(opts["n_frames"])
        return n, n
    n = int(math.ceil(float(opts["rate_hz"]) * float(opts["duration_s"])))
    return n, n


def check_memory(scenario: str, options: dict, field: str | None = None) -> None:
    """Refuse a simulation whose frames would not fit this machine's free memory, before any work.

    A scenario is simulated and written in memory (one recording at a time); a
    ``--frames 100000000`` would grow until the machine swaps or kills it. The
    estimate uses the measured memory per frame (:data:`BYTES_PER_FRAME`).

    Parameters
    ----------
    scenario : str
        One of :data:`SCENARIOS` or ``"all"``.
    options : dict
        The options given to :func:`simulate`.
    field : str, optional
        The option to name in the message (default: the scenario's own option name).

    Raises
    ------
    ArgumentError
        Naming the option, the memory needed and the memory available.
    """
    available = available_memory_bytes()
    if available is None:
        return
    names = list(SCENARIOS) if scenario == "all" else [scenario]
    for name in names:
        try:
            at_once, _ = frames_in_memory(name, options)
        except (TypeError, ValueError):  # an option that is not a number: the scenario's own check says so
            continue
        need = BASE_BYTES + at_once * BYTES_PER_FRAME[name]
        if need <= available:
            continue
        key = {"calibration": "frames_per_strip", "validation": "frames_per_strip",
               "time-varying": "duration_s", "free-sweep": "n_frames"}.get(name, "frames_per_config")
        per_frame = BYTES_PER_FRAME[name]
        per_what = "strip" if key == "frames_per_strip" else "configuration"
        size = max(float(options.get(key, _OPTIONS[name][key])), 1e-300)  # frames (or seconds) a strip, ...
        per_unit = at_once / size
        frames = max((available - BASE_BYTES) / per_frame, 0.0)
        if key == "duration_s":  # frames = rate × duration: either may be the option to change
            rate, seconds = float(options.get("rate_hz", _OPTIONS[name]["rate_hz"])), size
            most = f"{int(frames):,} frames: {frames / rate:.3g} s at {rate:g} Hz, or {frames / seconds:.3g} Hz for " \
                   f"{seconds:g} s"
        else:
            most = f"{int(frames / per_unit):,} frames" + ("" if key == "n_frames" else " per " + per_what)
        label = field or ("rate_hz × duration_s" if key == "duration_s" else key)
        raise ArgumentError(f"{label}: {name} would hold {at_once:,} frames in memory, about "
                            f"{size_text(need)}; this machine has {size_text(available)} available (at most {most})")


def _simulate(scenario, out_dir, config=None, seed=0, *, overwrite=False, **options):
    """Do :func:`simulate`; also return ``{scenario: summary}``."""
    if scenario != "all" and scenario not in SCENARIOS:
        raise ConfigError(f"scenario: must be one of {', '.join(SCENARIOS)}, all; got {scenario!r}")
    names = list(SCENARIOS) if scenario == "all" else [scenario]
    known = set(_ACTUATOR_OPTIONS).union(*(_OPTIONS[n] for n in names))
    unknown = sorted(set(options) - known)
    if unknown:
        raise ConfigError(f"options: unknown {', '.join(unknown)} for {scenario}; allowed: {', '.join(sorted(known))}")
    check_memory(scenario, options)
    out = Path(out_dir)
    config_path = config if isinstance(config, (str, os.PathLike)) else None
    output.check([output.directory(out, overwrite=overwrite)], [config_path])
    config = _config(config)
    actuator_options = {k: v for k, v in options.items() if k in _ACTUATOR_OPTIONS}

    summaries = {}
    with output.write_dir(out, overwrite=overwrite, inputs=[config_path], writer="bendsense simulate") as tmp:
        for name in names:
            target = tmp if scenario != "all" else tmp / name
            target.mkdir(exist_ok=True)
            sim = _actuator(config, seed, **actuator_options)
            opts = {**_OPTIONS[name], **{k: v for k, v in options.items() if k in _OPTIONS[name]}}
            summary = _WRITERS[name](_Run(sim, _stream(seed, name), target, name, seed), **opts)
            _write_description(target, name, seed, config, actuator_options, opts, summary)
            summary["files"].append("scenario.yaml")
            summaries[name] = {**summary, "path": out if scenario != "all" else out / name}
    return out, summaries


def _plain(value):
    if isinstance(value, (tuple, list, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer, int)) and not isinstance(value, bool):
        return int(value)
    return value


def _write_description(target, name, seed, config, actuator_options, options, summary):
    from bendsense import __version__

    doc = {
        "format": _FORMAT,
        "version": _FORMAT_VERSION,
        "scenario": name,
        "seed": seed,
        "bendsense": __version__,
        "options": {k: _plain(v) for k, v in {**actuator_options, **options}.items()},
        "frames": summary["frames"],
        "excluded_frames": summary["excluded_frames"],
        "files": summary["files"],
        "config": config.to_dict(),
    }
    (target / "scenario.yaml").write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True), encoding="utf-8")


