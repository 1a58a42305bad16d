"""Atomic file output: write to a temporary file in the same directory, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_text", "load_yaml", "parse_yaml"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; rename it over ``path`` if the block succeeds.

    On any exception the temporary file is removed and ``path`` is left untouched,
    so a failed write never leaves a half-written output file.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    # mkstemp creates 0600; give the file the permissions an ordinary open() would
    os.fchmod(fd, 0o666 & ~_umask())
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def load_yaml(path: str | os.PathLike, what: str, parse):
    """Read the YAML file ``path`` and return ``parse(data)``.

    Every problem is a :class:`~bendsense.errors.ConfigError` whose message starts with
    the path: the file cannot be read (``cannot read <what>``), is not YAML, or
    ``parse`` rejects a field.
    """
    from bendsense.errors import ConfigError

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read {what}: {err.strerror or err}") from None
    return parse_yaml(text, str(path), parse)


def parse_yaml(text: str, source: str, parse):
    """``parse`` the YAML ``text``; errors are ConfigErrors prefixed with ``source``."""
    import yaml

    from bendsense.errors import ConfigError

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"{source}: not valid YAML: {err}") from None
    try:
        return parse(data)
    except ConfigError as err:
        raise ConfigError(f"{source}: {err}") from None
