"""The calibration manifest (DESIGN.md section 3): the flat recording and one per strip."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bendsense import validation as check
from bendsense._io import file_kind, read_yaml
from bendsense.errors import ConfigError

log = logging.getLogger("bendsense")

__all__ = ["Manifest", "read_manifest"]


@dataclass(frozen=True)
class Manifest:
    """A parsed calibration manifest: absolute recording paths and strip radii [m]."""

    flat: Path
    strips: tuple  # of (radius_m, Path)
    source: str = ""


_STRIP_KEYS = ("radius_m", "radius_mm", "recording")


#: Smallest strip radius [m]: a sensor bent tighter than about its strip gap (1 mm) measures nothing
#: the shifts' model holds for (the tightest curvature it resolves is ~1/d, bendsense.mechanics.bounds).
MIN_RADIUS_M = 1e-3


def _radius_m(where: str, item: dict) -> float:
    """The strip radius of a manifest entry [m]: ``radius_m``, or ``radius_mm`` converted."""
    if "radius_m" in item:
        # a strip radius over 1 m is millimetres written as metres
        radius = check.length_m(f"{where}.radius_m", item["radius_m"], error=ConfigError)
        if radius < MIN_RADIUS_M:
            raise ConfigError(f"{where}.radius_m: expected a strip radius of at least 1 mm (0.001 m), got "
                              f"{radius:g} m; no sensor bends that tightly")
        return radius
    radius_mm = check.number(f"{where}.radius_mm", item["radius_mm"], error=ConfigError, positive=True)
    if radius_mm < 1:
        raise ConfigError(f"{where}.radius_mm: expected a radius in millimetres >= 1, got {radius_mm:g}; "
                          f"looks like metres (did you mean radius_m: {radius_mm:g}?)")
    return check.length_m(f"{where}.radius_mm", radius_mm * 1e-3, error=ConfigError)


def read_manifest(path: str | os.PathLike) -> Manifest:
    """Read and check a calibration manifest (DESIGN.md section 3).

    Parameters
    ----------
    path : str or path-like
        The manifest YAML file; recording paths in it are relative to it.

    Raises
    ------
    ConfigError
        Naming the file and the field, e.g. ``strips[2].radius_cm: unknown key``.
    """
    path = Path(path)
    return read_yaml(path, "manifest", lambda data: _parse_manifest(data, path.parent, str(path)))


def _recording(where: str, value: Any, base: Path) -> Path:
    if not isinstance(value, str) or not value:
        raise check.fail(where, "a file name", value, ConfigError)
    full = base / value
    if not full.exists():
        raise ConfigError(f"{where}: no such recording {check.short(value)} ({check.short(str(full), 200)})")
    kind = file_kind(full.stat().st_mode)
    if kind is not None:
        raise ConfigError(f"{where}: recording {check.short(value)} is {kind}, not a session CSV; "
                          f"give a regular file ({check.short(str(full), 200)})")
    return full


def _parse_manifest(data: Any, base: Path, source: str) -> Manifest:
    if not isinstance(data, dict):
        raise check.fail("manifest", "a mapping with keys flat, strips", data, ConfigError)
    for key in data:
        if key not in ("flat", "strips"):
            raise ConfigError(f"{check.key(key)}: unknown key; allowed: flat, strips")
    for key in ("flat", "strips"):
        if key not in data:
            raise ConfigError(f"{key}: missing key")
    flat = _recording("flat", data["flat"], base)
    strips = data["strips"]
    if not isinstance(strips, list) or not strips:
        raise check.fail("strips", "a non-empty list of {radius_m: ..., recording: ...}", strips, ConfigError)
    out = []
    for i, item in enumerate(strips):
        where = f"strips[{i}]"
        if not isinstance(item, dict):
            raise check.fail(where, "a mapping with radius_m or radius_mm and recording", item, ConfigError)
        for key in item:
            if key not in _STRIP_KEYS:
                raise ConfigError(f"{where}.{check.key(key)}: unknown key; allowed: {', '.join(_STRIP_KEYS)}")
        if "radius_m" in item and "radius_mm" in item:
            raise ConfigError(f"{where}: give exactly one of radius_m, radius_mm, got both")
        if "radius_m" not in item and "radius_mm" not in item:
            raise ConfigError(f"{where}: missing key radius_m or radius_mm")
        radius = _radius_m(where, item)
        if "recording" not in item:
            raise ConfigError(f"{where}: missing key recording")
        recording = _recording(f"{where}.recording", item["recording"], base)
        # one recording counted twice would weigh its strip double; the flat as a strip is a mix-up
        if recording.resolve() == flat.resolve():
            raise ConfigError(f"{where}.recording: {recording.name} is the flat recording too")
        for j, (seen_radius, seen) in enumerate(out):
            if recording.resolve() == seen.resolve():
                raise ConfigError(f"{where}.recording: {recording.name} is listed twice (strips[{j}] too)")
            if seen_radius == radius:  # a repeated strip is fine; a mistyped radius is the common cause
                log.warning("%s: strips[%d] and strips[%d] have the same radius %g m (%s, %s): a repeated "
                            "measurement, or a mistyped radius?", source, j, len(out), radius, seen.name,
                            recording.name)
        out.append((radius, recording))
    return Manifest(flat=flat, strips=tuple(out), source=source)
