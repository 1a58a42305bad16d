"""A gripper: several named fingers on one board, each a complete single-actuator config.

A config YAML with ``fingers:`` is a gripper (DESIGN section 2b). Its top-level
sections (``sensor``, ``actuator``, ``material``, ``stiffness``, ``gravity``,
``estimation``, ``parameter_covariance``) are defaults that each finger inherits whole;
a finger may give any of them itself (a whole-section override). Each finger names its
board ``channels`` (1-based, one per sensor segment, in the sensor's order) and its
``pressure_line`` (0-based; fingers may share a line)::

    name: two-finger gripper
    sensor: {...}            # defaults of every finger
    actuator: {...}
    material: {...}
    stiffness: {...}
    fingers:
      - {name: thumb, channels: [1, 2, ..., 16], pressure_line: 0}
      - name: index
        channels: [17, 18, ..., 32]
        pressure_line: 1
        stiffness: {ei0_nm2: 0.0021}   # this finger's own section

A finger's :class:`Finger.config` is the :class:`~bendsense.config.Config` that a
single-actuator run of that finger takes; a gripper is its fingers, each run through
the single-actuator code.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from bendsense import validation as check
from bendsense.config.sections import _OPTIONAL, _SECTIONS, Config, _names
from bendsense.errors import ConfigError

__all__ = ["Finger", "GripperConfig", "MAX_CHANNEL", "MAX_LINE", "FINGER_NAME"]

MAX_CHANNEL = 64
"""Highest board channel (1-based): a SAMPLE frame carries at most 64 channels."""
MAX_LINE = 254
"""Highest pressure line (0-based): a SAMPLE frame's ``n_lines`` is a u8."""
FINGER_NAME = r"[A-Za-z][A-Za-z0-9_-]*"
"""A finger's name: used in paths, stream names and topics."""
_FINGER_KEYS = ("name", "channels", "pressure_line")
_REQUIRED = ("sensor", "actuator", "material", "stiffness")


def _prefixed(path: str, err: ConfigError) -> ConfigError:
    """``err`` with its field path under ``path`` (``sensor.n_segments`` → ``fingers[1].sensor.n_segments``)."""
    return ConfigError(f"{path}.{err}")


def _check_finger(finger: Finger, path: str) -> None:
    """The checks of one finger, naming ``path`` (``finger`` or ``fingers[i]``)."""
    name = finger.name
    if not isinstance(name, str) or not re.fullmatch(FINGER_NAME, name):
        raise check.fail(f"{path}.name", f"a name matching {FINGER_NAME} (letters, digits, _ and -, a letter "
                                         f"first)", name, ConfigError)
    if not isinstance(finger.config, Config):
        raise check.fail(f"{path}.config", "a Config", type(finger.config).__name__, ConfigError, raw=True)
    channels = finger.channels
    if not isinstance(channels, (list, tuple)):
        raise check.fail(f"{path}.channels", "a list of board channels (1-based)", channels, ConfigError)
    channels = tuple(check.integer(f"{path}.channels[{i}]", c, error=ConfigError, minimum=1, maximum=MAX_CHANNEL)
                     for i, c in enumerate(channels))
    n = finger.config.sensor.n_segments
    if len(channels) != n:
        raise ConfigError(f"{path}.channels: {len(channels)} channel{'s' if len(channels) != 1 else ''} for a "
                          f"{n}-segment sensor (one board channel per segment, in the sensor's order)")
    seen = set()
    for c in channels:
        if c in seen:
            raise ConfigError(f"{path}.channels: channel {c} is given twice")
        seen.add(c)
    line = check.integer(f"{path}.pressure_line", finger.pressure_line, error=ConfigError, minimum=0,
                         maximum=MAX_LINE)
    object.__setattr__(finger, "channels", channels)
    object.__setattr__(finger, "pressure_line", line)


@dataclass(frozen=True, kw_only=True)
class Finger:
    """One finger of a gripper: a named actuator on some of the board's channels.

    Parameters
    ----------
    name : str
        The finger's name (``[A-Za-z][A-Za-z0-9_-]*``), used in output paths
        (``OUT/<name>/results.csv``), LSL stream names and MCAP topics.
    channels : tuple of int
        The board channels (1-based, 1..64) of its sensor's segments, base to tip:
        ``config.sensor.n_segments`` of them.
    pressure_line : int
        The board's pressure line (0-based, 0..254) that drives it.
    config : Config
        The complete single-actuator config of this finger.
    """

    name: str
    channels: tuple
    pressure_line: int
    config: Config

    def __post_init__(self):
        _check_finger(self, "finger")

    @property
    def columns(self) -> list:
        """The 0-based board columns of its channels (``channels − 1``), as a list."""
        return [c - 1 for c in self.channels]

    @classmethod
    def from_dict(cls, data: Any, defaults: dict | None = None, path: str = "finger") -> Finger:
        """A finger from its YAML mapping; the sections it lacks come from ``defaults``.

        Parameters
        ----------
        data : dict
            ``name``, ``channels``, ``pressure_line`` and any of the config sections.
        defaults : dict, optional
            The gripper's top-level sections (YAML layout), inherited whole.
        path : str, default "finger"
            The field path of this finger in messages (``fingers[1]``).
        """
        if not isinstance(data, dict):
            raise check.fail(path, "a mapping (name, channels, pressure_line and sections)", data, ConfigError)
        allowed = [*_FINGER_KEYS, *_SECTIONS]
        unknown = sorted(set(data) - set(allowed), key=str)
        if unknown:
            raise ConfigError(f"{path}: unknown keys {_names(unknown)}; allowed: {', '.join(allowed)}")
        missing = [k for k in _FINGER_KEYS if k not in data]
        if missing:
            raise ConfigError(f"{path}: missing keys {', '.join(missing)}")
        defaults = defaults or {}
        sections = {}
        for key in _SECTIONS:
            if key in data:
                _check_whole(data[key], defaults.get(key), f"{path}.{key}")
                sections[key] = (data[key], path)
            elif key in defaults:
                sections[key] = (defaults[key], None)
        absent = [k for k in _REQUIRED if k not in sections]
        if absent:
            raise ConfigError(f"{path}: missing sections {', '.join(absent)} (give them in the finger or at the top "
                              f"level, for every finger)")
        name = data["name"]
        config = _finger_config(name, sections, path)
        finger = object.__new__(cls)  # checked below under the finger's path
        for key, value in (("name", name), ("channels", data["channels"]), ("pressure_line", data["pressure_line"]),
                           ("config", config)):
            object.__setattr__(finger, key, value)
        _check_finger(finger, path)
        return finger

    def to_dict(self, defaults: dict | None = None) -> dict:
        """The YAML layout: name, channels, pressure_line and the sections not equal to ``defaults``.

        Parameters
        ----------
        defaults : dict, optional
            The gripper's top-level sections (YAML layout); a section equal to its
            default is left out.
        """
        defaults = defaults or {}
        out = {"name": self.name, "channels": list(self.channels), "pressure_line": self.pressure_line}
        sections = self.config.to_dict()
        sections.pop("name", None)
        for key in _SECTIONS:
            if key in sections and defaults.get(key) != sections[key]:
                out[key] = sections[key]
            elif key not in sections and key in defaults:
                out[key] = None  # an optional section the finger lacks while the gripper gives it
        return out


def _check_whole(section, inherited, path: str) -> None:
    """A finger's section replaces the gripper's whole: a key the gripper's gives and the finger's lacks is an error."""
    if not (isinstance(section, dict) and isinstance(inherited, dict)):
        return
    missing = [k for k in inherited if k not in section]
    if missing:
        raise ConfigError(f"{path}: missing keys {', '.join(map(str, missing))} (a finger's section replaces the "
                          "gripper's whole: give them too, or leave the section out to inherit it)")


def _finger_config(name, sections: dict, path: str) -> Config:
    """The finger's Config from its sections ``{key: (data, path or None for a default)}``."""
    kwargs = {}
    for key, (data, where) in sections.items():
        if key in _OPTIONAL and data is None:
            continue
        try:
            kwargs[key] = _SECTIONS[key].from_dict(data)
        except ConfigError as err:
            raise (_prefixed(where, err) if where else err) from None
    try:
        return Config(**kwargs, name=name if isinstance(name, str) else "")
    except ConfigError as err:  # the bounds that need several sections
        raise _prefixed(path, err) from None


@dataclass(frozen=True, kw_only=True)
class GripperConfig:
    """A gripper: several named fingers on one board (DESIGN section 2b).

    Parameters
    ----------
    name : str
        The gripper's name.
    fingers : tuple of Finger
        Its fingers: unique names, no board channel in two fingers (fingers may share
        a pressure line).
    """

    name: str = ""
    fingers: tuple = ()

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise check.fail("name", "a string", self.name, ConfigError)
        fingers = self.fingers
        if not isinstance(fingers, (list, tuple)) or not fingers:
            raise check.fail("fingers", "a non-empty list of fingers", fingers, ConfigError)
        owner, names = {}, set()
        for i, finger in enumerate(fingers):
            path = f"fingers[{i}]"
            if not isinstance(finger, Finger):
                raise check.fail(path, "a Finger", type(finger).__name__, ConfigError, raw=True)
            if finger.name in names:
                raise ConfigError(f"{path}.name: finger {finger.name!r} is named twice (names are unique: they "
                                  f"name output directories, streams and topics)")
            names.add(finger.name)
            for c in finger.channels:
                if c in owner:
                    raise ConfigError(f"{path}.channels: channel {c} is already finger {owner[c]}'s")
                owner[c] = finger.name
        object.__setattr__(self, "fingers", tuple(fingers))

    def __getattr__(self, name):
        # a single-actuator function reading a section of a gripper: one clear line
        if name in _SECTIONS or name in ("weight_per_length_n_per_m", "model_parameters", "with_model_parameters"):
            raise ConfigError(self.single_message())
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def single_message(self, what: str = "config") -> str:
        """The message of a single-actuator function given this gripper.

        Parameters
        ----------
        what : str, default "config"
            The argument or file, named at the start of the message.
        """
        name = f" {self.name!r}" if self.name else ""
        return (f"{what}: the config{name} is a gripper config (fingers {', '.join(self.names)}); this takes one "
                f"actuator's config: one finger's (gripper.finger(NAME).config in Python; on the command line a "
                f"config without fingers:)")

    @property
    def names(self) -> tuple:
        """The fingers' names, in config order."""
        return tuple(f.name for f in self.fingers)

    @property
    def n_channels(self) -> int:
        """The highest board channel any finger uses (a session needs at least as many)."""
        return max(max(f.channels) for f in self.fingers)

    @property
    def n_lines(self) -> int:
        """The number of pressure lines the fingers use: the highest ``pressure_line`` + 1."""
        return max(f.pressure_line for f in self.fingers) + 1

    def finger(self, name: str) -> Finger:
        """The finger called ``name``; an unknown name is a ConfigError listing the fingers.

        Parameters
        ----------
        name : str
            The finger's name.
        """
        for f in self.fingers:
            if f.name == name:
                return f
        raise ConfigError(f"finger {check.short(name)}: not a finger of this gripper; its fingers: "
                          f"{', '.join(self.names)}")

    def with_finger_config(self, name: str, config: Config) -> GripperConfig:
        """A copy whose finger ``name`` has the single-actuator config ``config`` (e.g. identified).

        Parameters
        ----------
        name : str
            The finger.
        config : Config
            Its new config (the same sensor segment count as its channels).
        """
        self.finger(name)  # an unknown name: the error listing the fingers
        fingers = tuple(Finger(name=f.name, channels=f.channels, pressure_line=f.pressure_line,
                               config=config if f.name == name else f.config) for f in self.fingers)
        return GripperConfig(name=self.name, fingers=fingers)

    @classmethod
    def from_dict(cls, data: Any) -> GripperConfig:
        """Build a gripper from the YAML layout; raises `ConfigError` naming the bad field.

        Parameters
        ----------
        data : dict
            ``name``, ``fingers`` and the default sections, as read by ``yaml.safe_load``.
        """
        if not isinstance(data, dict):
            raise check.fail("config", "a mapping of sections", data, ConfigError)
        allowed = ["name", "fingers", *_SECTIONS]
        unknown = sorted(set(data) - set(allowed), key=str)
        if unknown:
            raise ConfigError(f"config: unknown keys {_names(unknown)}; allowed: {', '.join(allowed)}")
        fingers = data.get("fingers")
        if not isinstance(fingers, list) or not fingers:
            raise check.fail("fingers", "a non-empty list of fingers", fingers, ConfigError)
        defaults = {k: data[k] for k in _SECTIONS if k in data}
        for key in _SECTIONS:  # a default is checked once, under its own path, even if every finger overrides it
            if key in defaults and not (key in _OPTIONAL and defaults[key] is None):
                _SECTIONS[key].from_dict(defaults[key])
        built = [Finger.from_dict(f, defaults, f"fingers[{i}]") for i, f in enumerate(fingers)]
        return cls(name=data.get("name", ""), fingers=tuple(built))

    def to_dict(self) -> dict:
        """The YAML layout: sections shared by every finger at the top level, the rest in the fingers."""
        per_finger = [f.config.to_dict() for f in self.fingers]
        defaults = {}
        for key in _SECTIONS:
            values = [d.get(key) for d in per_finger]
            if values[0] is not None and all(v == values[0] for v in values):
                defaults[key] = values[0]
        out = {"name": self.name} if self.name else {}
        out.update(defaults)
        out["fingers"] = [f.to_dict(defaults) for f in self.fingers]
        return out
