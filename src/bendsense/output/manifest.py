"""The manifest of an output directory: what bendsense wrote there (:mod:`bendsense.output`).

A directory output holds :data:`MANIFEST_NAME`, a small JSON file listing the files
bendsense wrote into it; ``overwrite`` replaces only those. Here: reading and writing
it, and listing what a directory holds beyond it.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from bendsense.errors import OutputError
from bendsense.output.paths import _resolve, write_error

MANIFEST_NAME = ".bendsense-output.json"
MANIFEST_FORMAT = "bendsense-output"
MANIFEST_VERSION = 1
_LOCK_SUFFIX = ".bendsense-lock"
_TMP_MARK = ".bendsense-tmp-"
_OLD_MARK = ".bendsense-old-"


def _litter(name: str) -> bool:
    """Names of bendsense's own working files: locks, temporary and old directories."""
    return name.startswith(".") and (name.endswith(_LOCK_SUFFIX) or _TMP_MARK in name or _OLD_MARK in name)


def _entries(d: str | os.PathLike, rel: str):
    """``(entry, relative name)`` of directory ``d`` in name order, without its manifest and litter.

    ``rel`` is ``d``'s path relative to the output directory (``""`` at its top, where
    the manifest lies; else ending in ``/``).
    """
    for entry in sorted(os.scandir(d), key=lambda e: e.name):
        if not ((not rel and entry.name == MANIFEST_NAME) or _litter(entry.name)):
            yield entry, rel + entry.name


def _umask() -> int:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def recorded_source(path) -> str | None:
    """The session whose results the output directory ``path`` holds, as its manifest names it (None: not named).

    Parameters
    ----------
    path : path
        The output directory.
    """
    source = (read_manifest(path) or {}).get("source")
    return source if isinstance(source, str) else None


def read_manifest(path) -> dict | None:
    """The manifest of the output directory ``path``, or None if it has none (or a broken one).

    Parameters
    ----------
    path : path
        The output directory.
    """
    from bendsense._io import open_regular

    try:
        # a FIFO in its place must not block: not a regular file, not a manifest
        with open_regular(Path(path) / MANIFEST_NAME, "manifest of an output directory", OutputError) as fh:
            data = json.loads(fh.read(1 << 20).decode("utf-8"))
    except (OSError, ValueError):
        return None
    if not (isinstance(data, dict) and data.get("format") == MANIFEST_FORMAT and isinstance(data.get("files"), list)):
        return None
    if not all(_inside_entry(f) for f in data["files"]):
        return None  # an edited manifest that names something outside its directory is not ours
    return data


def _inside_entry(name) -> bool:
    """Whether a manifest entry is a plain relative path inside its directory (no ``..``, not absolute)."""
    if not isinstance(name, str) or not name or "\\" in name or "\0" in name or name.startswith("/"):
        return False
    parts = name[:-1].split("/") if name.endswith("/") else name.split("/")
    return all(part not in ("", ".", "..") for part in parts)


def foreign_entries(path) -> list[str]:
    """Entries of the directory ``path`` that its manifest does not list (all, if it has none).

    Relative POSIX paths, sorted; a directory none of whose content is listed is one
    entry ``name/``. An entry ``name/`` in the manifest is a nested output with its own
    manifest, checked in turn. bendsense's lock files and temporary directories are
    never foreign.

    Parameters
    ----------
    path : path
        The directory to list.
    """
    root = Path(path)
    manifest = read_manifest(root)
    listed = {str(f) for f in manifest["files"]} if manifest else set()
    foreign: list[str] = []

    def walk(d: Path, rel: str) -> None:
        for entry, relname in _entries(d, rel):
            if entry.is_dir(follow_symlinks=False):
                if relname + "/" in listed:
                    foreign.extend(relname + "/" + f for f in foreign_entries(entry.path))
                elif any(f.startswith(relname + "/") for f in listed):
                    walk(Path(entry.path), relname + "/")
                else:
                    foreign.append(relname + "/")
            elif relname not in listed:
                foreign.append(relname)

    walk(root, "")
    return foreign


def _listing(root: Path) -> list[str]:
    """What a finished output directory holds, for its manifest (nested outputs as ``name/``)."""
    files: list[str] = []

    def walk(d: Path, rel: str) -> None:
        for entry, relname in _entries(d, rel):
            if entry.is_dir(follow_symlinks=False):
                if (Path(entry.path) / MANIFEST_NAME).exists():
                    files.append(relname + "/")
                else:
                    walk(Path(entry.path), relname + "/")
            else:
                files.append(relname)

    walk(root, "")
    return files


def _write_manifest(directory: Path, files: list[str], writer: str, previous: dict | None = None,
                    source=None) -> None:
    from bendsense import __version__

    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    doc = {
        "format": MANIFEST_FORMAT,
        "version": MANIFEST_VERSION,
        "writer": (previous or {}).get("writer", writer),
        "bendsense": __version__,
        "created_utc": (previous or {}).get("created_utc", now),
        "files": files,
    }
    if previous is not None:
        doc["updated_utc"] = now
    if source is not None:  # the session a results directory was made from
        doc["source"] = str(_resolve(source))
    path = directory / MANIFEST_NAME
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{MANIFEST_NAME}{_TMP_MARK}", dir=directory)
    except OSError as err:
        raise write_error(path, err) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=1)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise write_error(path, err) from None
        raise


def add_to_manifest(path, names: Iterable[str], *, writer: str = "bendsense") -> None:
    """Add ``names`` (relative paths; ``name/`` for a nested output) to the manifest of ``path``.

    Creates the manifest if there is none. The caller holds the lock of ``path``
    (:func:`reserve` or a writer).

    Parameters
    ----------
    path : path
        The output directory.
    names : iterable of str
        Entries to add.
    writer : str, default "bendsense"
        Who writes, for a new manifest.
    """
    path = _resolve(path)
    previous = read_manifest(path)
    files = list(previous["files"]) if previous else []
    new = [n for n in names if n not in files]
    if previous is not None and not new:
        return  # nothing to add: not rewritten (a full disk may refuse even that)
    _write_manifest(path, files + new, writer, previous)
