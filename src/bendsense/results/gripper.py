"""A gripper's results: ``OUT/<finger>/results.csv`` and ``shape.npz``, one directory per finger.

Each finger's directory holds exactly what a single-actuator ``save`` of that finger's
part of the board writes (:meth:`bendsense.results.Results.write_files`); ``OUT`` is
written complete or not at all, with one manifest covering every finger's files
(:func:`bendsense.output.write_dir`).
"""

from __future__ import annotations

import re
from pathlib import Path

from bendsense.config.gripper import FINGER_NAME
from bendsense.errors import SessionError
from bendsense.results import Results, read_results

__all__ = ["write_gripper_results", "read_gripper_results", "is_gripper_results", "RESULTS_FILES"]

RESULTS_FILES = ("results.csv", "shape.npz")


def write_gripper_results(out_dir, parts: dict, *, overwrite: bool = False, inputs=(), source=None) -> Path:
    """Write each finger's results into ``out_dir/<finger>/`` (one output directory, one manifest).

    Parameters
    ----------
    out_dir : path
        The output directory (:func:`bendsense.results.write_results`'s rules).
    parts : dict
        ``{finger name: (session, shape, estimate or None, track or None)}``, each the
        finger's single-actuator session and its results.
    overwrite : bool, default False
        Replace a previous bendsense output in ``out_dir``.
    inputs : iterable of paths
        Inputs never to be written over (every session's source is one).
    source : path, optional
        The board's session the results were made from, named in the manifest (default:
        the fingers' one source, if they share one).
    """
    from bendsense import output

    out_dir = Path(out_dir)
    results = {name: Results.from_state(*part) for name, part in parts.items()}
    sources = {getattr(part[0], "source", None) for part in parts.values()}
    sources = [s for s in sources if s and Path(s).exists()]
    inputs = [*inputs, *sources]
    if source is None and len(sources) == 1:
        source = sources[0]
    output.check([output.directory(out_dir, overwrite=overwrite)], inputs)
    with output.write_dir(out_dir, overwrite=overwrite, inputs=inputs, writer="bendsense save",
                          source=source) as tmp:
        for name, result in results.items():
            (tmp / name).mkdir()
            result.write_files(tmp / name)
    return out_dir


def is_gripper_results(out_dir) -> bool:
    """Whether ``out_dir`` holds a gripper's results (finger directories with results.csv, none at its top).

    Parameters
    ----------
    out_dir : path
        A directory.
    """
    out_dir = Path(out_dir)
    return out_dir.is_dir() and not (out_dir / "results.csv").exists() and bool(_finger_dirs(out_dir))


def _finger_dirs(out_dir: Path) -> list:
    return sorted(d for d in out_dir.iterdir()
                  if d.is_dir() and re.fullmatch(FINGER_NAME, d.name) and (d / "results.csv").is_file())


def read_gripper_results(out_dir, names=None) -> dict:
    """Read a gripper's results directory: ``{finger name: Results}``.

    Parameters
    ----------
    out_dir : path
        Written by :func:`write_gripper_results` (``save`` of a gripper's chain).
    names : sequence of str, optional
        The fingers, in this order (a gripper's ``names``); None: every finger
        directory found, in name order.
    """
    out_dir = Path(out_dir)
    if names is None:
        found = _finger_dirs(out_dir) if out_dir.is_dir() else []
        if not found:
            raise SessionError(f"{out_dir}: no finger directory with a results.csv (not a gripper's results)")
        names = [d.name for d in found]
    return {name: read_results(out_dir / name) for name in names}
