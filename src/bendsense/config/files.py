"""Reading and writing config YAML files: a single actuator's, or a gripper's (``fingers:``)."""

from __future__ import annotations

import os
from importlib import resources

import yaml

from bendsense.config.gripper import GripperConfig
from bendsense.config.sections import PAPER_CONFIG, Config

__all__ = ["load_config", "save_config", "parse_config"]


def parse_config(data) -> Config | GripperConfig:
    """A :class:`GripperConfig` when the YAML mapping ``data`` has ``fingers:``, else a :class:`Config`.

    Parameters
    ----------
    data : dict
        The YAML layout, as read by ``yaml.safe_load``.
    """
    if isinstance(data, dict) and "fingers" in data:
        return GripperConfig.from_dict(data)
    return Config.from_dict(data)


def load_config(path: str | os.PathLike | None = None) -> Config | GripperConfig:
    """Load a config YAML; ``None`` loads the paper's prototype shipped with the package.

    A YAML with ``fingers:`` is a gripper (:class:`~bendsense.config.GripperConfig`);
    otherwise it is one actuator's :class:`~bendsense.config.Config`.

    Parameters
    ----------
    path : str or path-like, optional
        Config YAML file; None loads the paper's prototype shipped with bendsense.

    Raises
    ------
    ConfigError
        If the file cannot be read or parsed, or a value is invalid.
    """
    from bendsense._io import parse_yaml, read_yaml

    if path is None:
        text = resources.files("bendsense.data").joinpath(PAPER_CONFIG).read_text(encoding="utf-8")
        return parse_yaml(text, "paper.yaml (built in)", Config.from_dict)
    return read_yaml(path, "config", parse_config)


def save_config(config: Config | GripperConfig, path: str | os.PathLike, *, overwrite: bool = True,
                note: str | None = None) -> None:
    """Write ``config`` (one actuator's or a gripper's) as YAML atomically (:func:`bendsense.output.write_text`).

    ``overwrite=False`` refuses an existing file (:class:`~bendsense.errors.OutputExistsError`).

    Parameters
    ----------
    config : Config or GripperConfig
        The configuration to write.
    path : str or path-like
        Output YAML file.
    overwrite : bool, default True
        Replace an existing file; False refuses one.
    note : str, optional
        A comment line under the header (where the values come from: ``identify`` writes
        its data, the command and the date).
    """
    from bendsense import output
    from bendsense.validation import instance
    from bendsense.validation import path as _path

    if not isinstance(config, GripperConfig):
        instance("config", config, Config, "bendsense.load_config(path)")
    path = _path("path", path)
    if isinstance(config, Config):  # a single actuator's file stays as it was
        text = "# bendsense config (actuator, sensor and model parameters; docs/formats.md)\n"
    else:
        text = "# bendsense config (a gripper: each finger's channels, pressure line and model; docs/gripper.md)\n"
    if note:
        text += "".join(f"# {line}\n" for line in str(note).splitlines())
    output.write_text(path, text + yaml.safe_dump(config.to_dict(), sort_keys=False), overwrite=overwrite,
                      writer="bendsense identify")
