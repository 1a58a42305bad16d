"""``bendsense simulate gripper``: the simulated gripper's config, a calibration and a board session with truth.

:func:`simulate_gripper` writes, into one directory:

``gripper.yaml``
    The gripper's config (:func:`~bendsense.sim.gripper.gripper_config`): K paper fingers
    ``thumb, index, middle, ring``, finger ``i`` on channels ``16 i + 1..16 i + 16`` and
    pressure line ``i``.
``calibration.yaml``
    The sensor calibration fitted (as ``bendsense calibrate``) from the simulated
    calibration recordings in ``calibration/`` (as ``bendsense simulate calibration``
    with the same seed). The fingers share one sensor hardware, so it serves every
    finger (``--calibration calibration.yaml``).
``session.csv``
    The board's session: the closing scenario of ``sim-device --fingers K`` (the
    regulators follow the closing profile; each finger presses the object), with
    ``line<k>_pressure_pa`` per line, ``ch1..ch<16K>`` and the truth per finger
    ``<finger>_fx_n, <finger>_fy_n, <finger>_contact_s_m`` and per line
    ``line<k>_setpoint_pa``.
``scenario.yaml``
    What was simulated: seed, the objects, the regulators.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from bendsense import output
from bendsense.errors import ConfigError

__all__ = ["simulate_gripper"]

_FORMAT = "bendsense-simulated-gripper"


DEFAULT_RATE_HZ = 200.0  # the session's frame rate [Hz]
DEFAULT_DURATION_S = 8.0  # one closing cycle [s]


def simulate_gripper(out_dir, fingers: int = 3, *, seed: int | None = 0, rate_hz: float = DEFAULT_RATE_HZ,
                     duration_s: float = DEFAULT_DURATION_S, stiffness_n_per_m: float = math.inf, contact_s_m=None,
                     touch_pressure_pa=None, overwrite: bool = False, **board) -> dict:
    """Write the simulated gripper's config, calibration and a recorded board session with truth.

    Parameters
    ----------
    out_dir : path
        Directory to create (written atomically; :mod:`bendsense.output`).
    fingers : int
        Fingers K, 1..4.
    seed : int, optional
        Seed of the sensor hardware and the noise (None: 0).
    rate_hz : float
        Frame rate of the session [Hz].
    duration_s : float
        Length of the session [s] (one closing cycle: 8 s).
    stiffness_n_per_m : float
        The object's contact stiffness [N/m]; ``math.inf``: rigid.
    contact_s_m, touch_pressure_pa : float or sequence, optional
        Where the object touches each finger [m] and at which pressure [Pa]
        (:func:`~bendsense.sim.gripper.default_objects`).
    overwrite : bool
        Replace a previous bendsense output in ``out_dir``.
    **board
        ``regulation`` (:class:`~bendsense.sim.gripper.Regulation`: the regulators' ``tau_s``
        and ``max_pressure_pa``, the closing profile's ``close_pa`` and ``period_s``) and
        ``noise_counts`` of :class:`~bendsense.sim.gripper.GraspBoard`.

    Returns
    -------
    dict
        ``path``, ``frames``, ``files``.
    """
    from bendsense.config import load_config, save_config
    from bendsense.sim.gripper import GraspBoard, default_objects, gripper_config

    if isinstance(duration_s, bool) or not (isinstance(duration_s, (int, float)) and 0 < duration_s < math.inf):
        raise ConfigError(f"duration_s: must be a finite number > 0, got {duration_s!r}")
    check_memory(round(duration_s * rate_hz), fingers, rate_hz)
    seed = 0 if seed is None else seed
    out = Path(out_dir)
    output.check([output.directory(out, overwrite=overwrite)])
    paper = load_config()
    gripper = gripper_config(fingers, paper)
    objects = default_objects(fingers, stiffness_n_per_m, contact_s_m, touch_pressure_pa)
    board = GraspBoard(gripper, objects, rate_hz=rate_hz, seed=seed, **board)
    session = _board_session(board, round(duration_s * rate_hz), seed)
    with output.write_dir(out, overwrite=overwrite, writer="bendsense simulate gripper") as tmp:
        save_config(gripper, tmp / "gripper.yaml")
        _calibration(paper, seed, board.noise_counts, tmp)
        from bendsense.session.csvfile import write_session_csv

        write_session_csv(session, tmp / "session.csv")
        _describe(tmp / "scenario.yaml", board, objects, seed, fingers, rate_hz, duration_s)
    files = ["gripper.yaml", "calibration.yaml", "calibration/", "session.csv", "scenario.yaml"]
    return {"path": out, "frames": len(session.t_s), "files": files}


#: Memory per frame and finger of a gripper session [bytes]: ~660 measured building it (200,000 frames of 3
#: fingers, peak RSS), the rest for writing it.
_BYTES_PER_FINGER_FRAME = 1_500


def check_memory(n_frames: int, fingers: int, rate_hz: float, field: str = "duration_s") -> None:
    """Refuse a gripper session whose frames would not fit this machine's free memory, before any work.

    The session is simulated and written in memory: ``--seconds 1e6`` would grow until the
    machine swaps or kills it. ``field`` is the option to name (``--seconds`` in the CLI);
    :func:`bendsense.sim.memory.check_fits` says it.
    """
    from bendsense.sim.memory import check_fits

    if isinstance(fingers, int) and isinstance(rate_hz, (int, float)) and rate_hz > 0:  # else the board refuses
        check_fits(field, f"gripper of {fingers} fingers", n_frames, fingers * _BYTES_PER_FINGER_FRAME, rate_hz)


def _board_session(board, n_frames: int, seed):
    """The board's frames 0..n-1 as a session with the truth columns."""
    from bendsense.session import Session

    if n_frames < 1:
        raise ConfigError("duration_s: shorter than one frame period")
    board.reset()
    pressures, counts, truths = [], [], []
    for k in range(n_frames):
        p, c, truth = board(k)
        pressures.append(p)
        counts.append(c)
        truths.append(truth)
    extra = {}
    for name in truths[0]:
        if name.endswith("_pressure_pa") or name == "pressure_pa":
            continue  # the session's own pressure columns
        extra[name] = np.array([t[name] for t in truths])
    meta = {"format": f"{_FORMAT} 1", "scenario": "gripper", "seed": seed, "rate_hz": board.rate_hz,
            "fingers": ", ".join(board.truth_fingers or ["(one actuator)"])}
    t = np.arange(n_frames) / board.rate_hz
    return Session(t, np.asarray(counts, dtype=float), np.asarray(pressures, dtype=float), meta=meta, extra=extra)


def _calibration(config, seed, noise_counts, tmp: Path) -> None:
    """``calibration/`` as ``simulate calibration`` writes it, and ``calibration.yaml`` fitted from it."""
    from bendsense.calibration import Calibration
    from bendsense.sim.scenarios import record_calibration

    target = tmp / "calibration"
    target.mkdir()
    record_calibration(target, config, seed, noise_counts=noise_counts)
    Calibration.fit(target / "manifest.yaml", config.sensor).save(tmp / "calibration.yaml")


def _describe(path: Path, board, objects, seed, fingers, rate_hz, duration_s) -> None:
    from bendsense import __version__

    regulators = board.regulators
    doc = {
        "format": _FORMAT,
        "version": 1,
        "bendsense": __version__,
        "seed": seed,
        "fingers": int(fingers),
        "rate_hz": float(rate_hz),
        "duration_s": float(duration_s),
        "regulators": {"tau_s": regulators.tau_s, "max_pressure_pa": regulators.max_pressure_pa,
                       "closing_profile": {"close_pa": board.profile.close_pa, "period_s": board.profile.period_s}},
        "objects": [
            {"finger": name, "contact_s_m": o.contact_s_m, "touch_pressure_pa": o.touch_pressure_pa,
             "stiffness_n_per_m": "rigid" if o.rigid else o.stiffness_n_per_m}
            for name, o in zip(board.truth_fingers, objects, strict=True)
        ],
    }
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
