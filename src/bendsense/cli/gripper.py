"""The chain for a gripper: every step runs on each finger's part of the board.

``load`` with a gripper's config (``fingers:``) splits the board session
(:func:`bendsense.session.fingers.split_session`) and keeps one single-actuator state per
finger in ``state["fingers"]``; :func:`per_finger` runs a step of the single-actuator
chain on each of them in turn (its warnings and errors name the finger). The board's
own state keeps ``session`` (the whole board), ``config`` and ``gripper`` (the
:class:`~bendsense.config.GripperConfig`), for the steps that write the whole gripper
(``save``, ``mcap``, ``plot``) and for ``export``.
"""

from __future__ import annotations

import contextlib
import functools
import logging

import click

from bendsense.errors import BendsenseError

__all__ = ["load_fingers", "per_finger", "finger_context", "is_gripper", "finger_parts", "identify_inputs"]


def is_gripper(state: dict) -> bool:
    """Whether the chain's ``state`` holds a gripper (``load`` with a config with fingers:).

    Parameters
    ----------
    state : dict
        The chain's state.
    """
    return state.get("gripper") is not None


def load_fingers(state: dict, session, gripper, calibration_paths, name: str) -> dict:
    """The state of ``load`` for a gripper: the board, and each finger's single-actuator state.

    Parameters
    ----------
    state : dict
        The chain's state (updated and returned).
    session : Session
        The whole board's session.
    gripper : GripperConfig
        The fingers.
    calibration_paths : dict or None
        ``{finger or None: path}`` (:func:`bendsense.cli._common.calibration_paths`);
        empty or None: no calibration (a chain that only exports).
    name : str
        The session's name (its file stem).
    """
    from bendsense.session.fingers import calibrations, split_session

    parts = split_session(session, gripper)
    cals = calibrations(gripper, calibration_paths) if calibration_paths else {}
    fingers = {}
    for finger in gripper.fingers:
        path = None
        if calibration_paths:
            path = calibration_paths.get(finger.name, calibration_paths.get(None))
        fingers[finger.name] = {"session": parts[finger.name], "config": finger.config,
                                "calibration": cals.get(finger.name), "calibration_path": path, "name": name,
                                "finger": finger.name}
    state.update(session=session, config=gripper, gripper=gripper, calibration=None, calibration_path=None,
                 name=name, fingers=fingers)
    logging.getLogger("bendsense").info("loaded a gripper's board: %d frames, fingers %s", len(session),
                                        ", ".join(gripper.names))
    return state


@contextlib.contextmanager
def finger_context(name: str):
    """Within the block, bendsense's log lines and errors start with ``finger NAME: ``.

    Parameters
    ----------
    name : str
        The finger's name.
    """
    factory = logging.getLogRecordFactory()

    def named(*args, **kwargs):
        record = factory(*args, **kwargs)
        if record.name == "bendsense" or record.name.startswith("bendsense."):
            record.msg = f"finger {name}: {record.msg}"
        return record

    logging.setLogRecordFactory(named)
    try:
        yield
    except BendsenseError as err:
        raise click.ClickException(f"finger {name}: {err}") from None
    finally:
        logging.setLogRecordFactory(factory)


def per_finger(step):
    """The chain step ``step`` (a function of the state), run on each finger's state for a gripper.

    A single actuator's state goes to ``step`` unchanged; the step's ``precheck`` (if
    any) is run per finger in the same way.

    Parameters
    ----------
    step : callable
        A step of the single-actuator chain.
    """
    @functools.wraps(step)
    def run(state):
        if not is_gripper(state):
            return step(state)
        for name, sub in state["fingers"].items():
            with finger_context(name):
                state["fingers"][name] = step(sub) or sub
        return state

    if hasattr(step, "precheck"):
        check = step.precheck

        def precheck(state):
            if not is_gripper(state):
                return check(state)
            for name, sub in state["fingers"].items():
                with finger_context(name):
                    check(sub)

        run.precheck = precheck
    return run


def finger_parts(state: dict, step: str) -> dict:
    """``{finger: (session, shape, estimate, track)}`` of a gripper's state, for the steps that write it.

    Parameters
    ----------
    state : dict
        The chain's state, of a gripper.
    step : str
        The step, for the message when no finger has a shape yet.
    """
    parts = {}
    for name, sub in state["fingers"].items():
        if sub.get("shape") is None:
            raise click.UsageError(f"'{step}' needs 'reconstruct' earlier in the chain")
        parts[name] = (sub["session"], sub["shape"], sub.get("estimate"), sub.get("track"))
    return parts


def identify_inputs(config, finger, session_path, calibration_paths) -> tuple:
    """What ``identify`` fits and writes: one actuator's config, or one finger of a gripper.

    Parameters
    ----------
    config : Config or GripperConfig
        ``--config``.
    finger : str or None
        ``--finger``: with a gripper, the finger identified.
    session_path : Path or None
        ``--session``: for a gripper the whole board's session (the finger's part is taken).
    calibration_paths : tuple
        ``--calibration`` values (:func:`bendsense.cli._common.calibration_paths`).

    Returns
    -------
    tuple
        ``(actuator config, inputs, written)``: the config the fit starts from, a function
        returning ``(session, calibration)`` of ``--session``, and a function of the fitted
        config returning the config to write (a gripper's: with the finger's fitted config).
    """
    from bendsense.cli._common import calibration_paths as for_config
    from bendsense.cli._common import checked_calibration
    from bendsense.config import GripperConfig
    from bendsense.session import read_session

    paths = for_config(calibration_paths, config)
    if not isinstance(config, GripperConfig):
        if finger is not None:
            raise click.BadParameter("a finger needs a gripper's config (--config G.yaml with fingers:)",
                                     param_hint="'--finger'")
        return config, lambda: (read_session(session_path), checked_calibration(paths, config)), lambda fitted: fitted
    if finger is None:
        raise click.UsageError(f"the config is a gripper (fingers {', '.join(config.names)}): give --finger NAME, "
                               f"the finger to identify")
    chosen = config.finger(finger)

    def inputs():
        from bendsense.session.fingers import calibrations, split_session

        session = split_session(read_session(session_path), config)[chosen.name]
        wanted = {k: v for k, v in paths.items() if k in (None, chosen.name)}
        unknown = [k for k in paths if k is not None and k not in config.names]
        return session, calibrations(GripperConfig(name=config.name, fingers=(chosen,)),
                                     {**wanted, **{k: paths[k] for k in unknown}})[chosen.name]

    return chosen.config, inputs, lambda fitted: config.with_finger_config(chosen.name, fitted)
