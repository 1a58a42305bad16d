"""The inputs of a run on a session, as objects: a session, a config and a calibration, each given or its path."""

from __future__ import annotations

import os

from bendsense.errors import ArgumentError

__all__ = ["process_inputs"]


def process_inputs(session, config, calibration, calibration_source):
    """:func:`bendsense.process`'s inputs as objects: each may be given as the path of its file; checked types.

    Parameters
    ----------
    session : Session or path
        The recording, or its file (:func:`bendsense.read_session`).
    config : Config, path or None
        The config, its YAML file, or None for the shipped paper config.
    calibration : Calibration or path
        The sensor's calibration, or its YAML file.
    calibration_source : str
        Where the calibration came from, for the results' provenance ("" for unknown: the
        path, when one is given).

    Returns
    -------
    session, config, calibration, calibration_source
    """
    from bendsense import validation as check
    from bendsense.calibration import Calibration
    from bendsense.config import Config, load_config
    from bendsense.session import Session, read_session

    if isinstance(session, (str, os.PathLike)):
        session = read_session(session)
    if isinstance(config, (str, os.PathLike)):
        config = load_config(config)
    if isinstance(calibration, (str, os.PathLike)):
        calibration_source = calibration_source or str(calibration)
        calibration = Calibration.load(calibration)
    check.instance("session", session, Session, "bendsense.read_session(path), or the path")
    if config is None:
        config = load_config()
    check.instance("config", config, Config, "bendsense.load_config(path), or the path")
    if not isinstance(calibration, Calibration):
        raise ArgumentError(f"calibration: expected a Calibration (Calibration.load(path), or the path), got "
                            f"{type(calibration).__name__}")
    return session, config, calibration, calibration_source
