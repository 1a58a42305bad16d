"""``process`` over a gripper's board sessions: each finger's part of each session, as a single actuator.

:func:`bendsense.batch.process_sessions` with a :class:`~bendsense.config.GripperConfig`
sends the same tasks as for one actuator; a task reads the board session, splits it
(:func:`bendsense.session.fingers.split_session`), runs each finger's part through
:func:`bendsense.pipeline.process` with the finger's config and calibration, and writes
``OUT/<session>/<finger>/results.csv`` and ``shape.npz`` in one output directory
(:func:`bendsense.results.gripper.write_gripper_results`). The session's row counts the
board's frames; its flagged frames are summed over the fingers.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from bendsense.config import GripperConfig
from bendsense.errors import DataWarning

__all__ = ["prepare", "run_gripper", "warm_up_finger"]


def prepare(config, calibration, estimate: bool):
    """The batch's calibration for ``config``: one :class:`Calibration`, or a gripper's ``{finger: Calibration}``.

    Parameters
    ----------
    config : Config or GripperConfig
        The batch's config.
    calibration : Calibration, path, or dict
        A single actuator's calibration (or its YAML), or for a gripper what
        :func:`bendsense.session.fingers.calibrations` takes.
    estimate : bool
        Whether forces are estimated: each calibration's error model is then made once
        here (it travels with the pickled calibration, not once per session).
    """
    from bendsense.calibration import Calibration
    from bendsense.errors import SessionError

    if calibration is None or (isinstance(calibration, dict) and not calibration):
        raise SessionError("calibration: a Calibration or a calibration YAML is required")
    if isinstance(config, GripperConfig):
        from bendsense.session.fingers import calibrations

        calibration = calibrations(config, calibration)
        cals = list(calibration.values())
    else:
        if not isinstance(calibration, Calibration):
            calibration = Calibration.load(calibration)
        cals = [calibration]
    if estimate:
        for cal in {id(c): c for c in cals}.values():
            cal.error_model()
    return calibration


def warm_up_finger(config, calibration) -> tuple:
    """The config and calibration a batch's warm-up runs: a gripper's first finger's.

    Parameters
    ----------
    config : Config or GripperConfig
        The batch's config.
    calibration : Calibration or dict
        Its calibration (:func:`prepare`).
    """
    if isinstance(config, GripperConfig):
        finger = config.fingers[0]
        return finger.config, calibration[finger.name]
    return config, calibration


def run_gripper(path, out_dir, gripper: GripperConfig, calibrations: dict, options, overwrite: bool):
    """Process one board session of a gripper and write each finger's results (a batch task's work).

    Parameters
    ----------
    path : path
        The board session.
    out_dir : path
        Its output directory: ``out_dir/<finger>/results.csv`` and ``shape.npz``.
    gripper : GripperConfig
        The fingers.
    calibrations : dict
        ``{finger: Calibration}``.
    options : Options
        What to do to each finger's part (:class:`bendsense.choices.Options`).
    overwrite : bool
        Replace a previous bendsense output in ``out_dir``.

    Returns
    -------
    tuple
        ``(counts, frames_lost, tx_drops, pressure_ignored)`` as a single actuator's task
        returns them: the board's frames, each flagged count summed over the fingers.
    """
    from bendsense import output
    from bendsense.pipeline import process
    from bendsense.results.gripper import write_gripper_results
    from bendsense.session.fingers import split_session

    output.check([output.directory(out_dir, overwrite=overwrite)], [path])
    session = read_noted(path)
    ignored = options.pressure_pa is not None and bool(np.isfinite(session.pressure_pa).all())
    parts, counts = {}, None
    for name, part in split_session(session, gripper).items():
        processed = process(part, gripper.finger(name).config, calibrations[name], **options.process_keywords())
        parts[name] = (processed.session, processed.shape, processed.estimate, processed.track)
        c = processed.counts()
        counts = c if counts is None else dataclasses.replace(counts, **{
            f.name: getattr(counts, f.name) + getattr(c, f.name) for f in dataclasses.fields(c) if f.name != "frames"})
    write_gripper_results(out_dir, parts, overwrite=overwrite, inputs=[path], source=path)
    return (counts, int(session.meta.get("frames_lost", 0)), int(session.meta.get("tx_drops", 0)), ignored)


def read_noted(path):
    """:func:`bendsense.session.read_session`, an unfinished recording a DataWarning (the session's note in a batch).

    The reader logs it, which a batch's worker cannot show: the report's row says it instead.
    Here, beside the gripper's run, for both runs: :mod:`bendsense.batch` imports this module,
    not the other way round.
    """
    from bendsense.session import read_session

    session = read_session(path)
    if session.meta.get("finished") is False:
        warnings.warn("unfinished recording (no clean stop: killed, crashed or still recording)", DataWarning,
                      stacklevel=2)
    return session
