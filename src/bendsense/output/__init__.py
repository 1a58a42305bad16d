"""Outputs that cannot destroy: every file and directory bendsense writes goes through here.

The promises (docs/cli.md, "Outputs"):

- A **directory output** (``save``, ``simulate``, ``reproduce``, ``demo``, each session
  of ``process``) is written into a fresh hidden sibling and swapped in at the end, so
  it is complete or absent. It holds a manifest, :data:`MANIFEST_NAME`, that lists what
  bendsense wrote there. ``overwrite`` replaces only those files: anything else inside
  makes the write refuse, naming it.
- A **file output** (calibration and config YAML, figures, session CSV) is written to a
  hidden temporary file in the same directory and renamed over the target.
- A **recording** (``record``) must survive being killed, so it is written in place: the
  manifest is written first, and an existing directory is accepted only when all its
  content is bendsense's.
- Never a target: the working directory or any of its ancestors, an input of the same
  command, a directory that holds an input, or any path that resolves to one of those
  through ``..`` or symlinks.
- Every target is checked before any work starts (:func:`reserve`), and locked until the
  command ends, so two runs writing to the same place refuse cleanly instead of
  interleaving.
- Directories and files get the permissions the umask gives; error messages name the
  user's path, never the hidden temporary one.

A command uses it in two steps::

    targets = [output.directory(out_dir, overwrite=overwrite), output.file(fig, suffixes=output.FIGURE)]
    with output.reserve(targets, inputs=[session_path]):  # check all, lock all, before any work
        ...                                                 # the work
        with output.write_dir(out_dir, overwrite=overwrite, writer="bendsense save") as tmp:
            write files into tmp                           # swapped in when the block ends
        with output.write_file(fig, suffixes=output.FIGURE) as tmp:
            figure.savefig(tmp)                            # renamed over fig when the block ends

The writers check and lock again by themselves (re-entrant within a process), so the
library functions that call them are safe without the CLI's :func:`reserve`.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import shutil
import tempfile
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from bendsense.errors import ArgumentError, OutputError, OutputExistsError
from bendsense.output.manifest import (
    _LOCK_SUFFIX,
    _OLD_MARK,
    _TMP_MARK,
    MANIFEST_FORMAT,
    MANIFEST_NAME,
    _listing,
    _litter,
    _umask,
    _write_manifest,
    add_to_manifest,
    foreign_entries,
    read_manifest,
    recorded_source,
)
from bendsense.output.paths import (
    _check_links,
    _check_names,
    _check_parent,
    _is_within,
    _resolve,
    _user_paths,
    check_steps,
    reason,
    write_error,
)

__all__ = [
    "MANIFEST_NAME",
    "MANIFEST_FORMAT",
    "FIGURE",
    "YAML",
    "CSV",
    "Target",
    "directory",
    "file",
    "recording",
    "collection",
    "check",
    "reserve",
    "write_dir",
    "write_file",
    "write_text",
    "begin_in_place",
    "add_to_manifest",
    "read_manifest",
    "recorded_source",
    "foreign_entries",
    "resolve",
    "reason",
    "write_error",
    "check_steps",
]

log = logging.getLogger("bendsense")

_SHOWN = 8  # foreign entries named in a message

YAML = (".yaml", ".yml")
CSV = (".csv",)
FIGURE = "figure"  # suffixes: the formats matplotlib can write (looked up when needed)

_KINDS = ("dir", "file", "recording", "collection")

@dataclass(frozen=True, kw_only=True)
class Target:
    """One output of a command.

    Attributes
    ----------
    path : Path
        The path as the user gave it (messages name it).
    kind : str
        ``dir`` (written aside and swapped in), ``file`` (temporary file renamed over
        it), ``recording`` (a directory written in place) or ``collection`` (a directory
        that holds the outputs of several writers, e.g. the root of ``process``; never
        replaced).
    overwrite : bool
        Whether what bendsense wrote there before may be replaced.
    suffixes : tuple of str or str
        File outputs: the allowed suffixes (lower case, with the dot), :data:`FIGURE`
        for the formats matplotlib writes, or empty for any.
    files : tuple of str
        Directory outputs: the names it writes (e.g. ``results.csv``), so that another
        output of the same command line may not be one of them (:func:`check_steps`).
    replaces : tuple of (bytes, str), optional
        File outputs: the mark of the one kind of bendsense file ``overwrite`` may replace
        (in its first 64 KiB) and its name for the message, e.g. a session CSV only over a
        session CSV; None: any bendsense file.
    """

    path: Path
    kind: str
    overwrite: bool = False
    suffixes: tuple | str = ()
    files: tuple = ()
    replaces: tuple | None = None

    def __post_init__(self):
        if self.kind not in _KINDS:
            raise ArgumentError(f"kind: must be one of {', '.join(_KINDS)}, got {self.kind!r}")
        object.__setattr__(self, "path", Path(self.path))


def directory(path, *, overwrite: bool = False, files=()) -> Target:
    """A directory output, written aside and swapped in.

    Parameters
    ----------
    path : path
        The output directory.
    overwrite : bool, default False
        Replace a previous bendsense output there.
    files : iterable of str, optional
        The names it writes, where known (for :func:`check_steps`).
    """
    return Target(path=path, kind="dir", overwrite=overwrite, files=tuple(files))


def file(path, *, overwrite: bool = False, suffixes=(), replaces=None) -> Target:
    """A file output, written to a temporary file and renamed over ``path``.

    Parameters
    ----------
    path : path
        The output file.
    overwrite : bool, default False
        Replace an existing file that bendsense wrote.
    suffixes : tuple of str or FIGURE
        Allowed suffixes (empty: any).
    replaces : tuple of (bytes, str), optional
        Replace only a file of this kind: its mark and its name (:class:`Target`).
    """
    return Target(path=path, kind="file", overwrite=overwrite, suffixes=suffixes, replaces=replaces)


def recording(path, *, overwrite: bool = False) -> Target:
    """A directory written in place (a recording that must survive being killed).

    Parameters
    ----------
    path : path
        The recording's directory.
    overwrite : bool, default False
        Replace a previous bendsense recording there.
    """
    return Target(path=path, kind="recording", overwrite=overwrite)


def collection(path) -> Target:
    """A directory that collects outputs (``process``'s root); existing content is kept.

    Parameters
    ----------
    path : path
        The collecting directory.
    """
    return Target(path=path, kind="collection")


# --------------------------------------------------------------------------- checks


def resolve(path) -> Path:
    """The absolute path with every ``..`` and symlink resolved: what the checks compare.

    Parameters
    ----------
    path : path
        Any path, relative to the working directory or absolute.
    """
    return _resolve(path)


def _figure_suffixes() -> tuple:
    from matplotlib.backend_bases import FigureCanvasBase

    return tuple(sorted("." + s for s in FigureCanvasBase.get_supported_filetypes()))


def _suffixes(target: Target) -> tuple:
    return _figure_suffixes() if target.suffixes == FIGURE else tuple(target.suffixes)


def check(targets: Iterable[Target], inputs: Iterable = ()) -> None:
    """Check every output of a command before any work starts.

    Parameters
    ----------
    targets : iterable of Target
        The outputs (:func:`directory`, :func:`file`, :func:`recording`, :func:`collection`).
    inputs : iterable of paths
        The command's inputs (files or directories); None entries are ignored.

    Raises
    ------
    OutputExistsError
        An output exists and ``overwrite`` was not given (a file, or a non-empty
        directory).
    OutputError
        An output is the working directory or one of its ancestors, an input, holds an
        input, holds files that bendsense did not write (with ``overwrite``), is a file
        where a directory is expected (or the reverse), has an unknown suffix, its parent
        is not a writable directory, or it is given twice.
    """
    targets = list(targets)
    inputs = [(Path(p), _resolve(p)) for p in inputs if p is not None]
    cwd = _resolve(os.getcwd())
    seen: dict[Path, Target] = {}
    for t in targets:
        _check_names(t.path, _aside_overhead(t))
        p, r = t.path, _resolve(t.path)
        if r in seen:
            raise OutputError(f"{p}: given as output twice")
        seen[r] = t
        if t.kind != "file" or r.is_dir():
            if r == cwd:
                raise OutputError(f"{p}: is the working directory; refusing to write over it (give a new directory)")
            if _is_within(cwd, r):
                raise OutputError(f"{p}: holds the working directory ({cwd}); refusing to write over it")
        for given, resolved in inputs:
            if r == resolved:
                raise OutputError(f"{p}: is an input of this command ({given}); choose another output")
            if t.kind != "file" and _is_within(resolved, r):
                raise OutputError(f"{p}: holds the input {given} of this command; choose another output")
        _check_links(p)
        _check_parent(p, r)
        if t.kind == "file":
            _check_file(t, r)
        else:
            _check_dir(t, r)


def _aside_overhead(t: Target) -> int:
    """Bytes that bendsense's hidden siblings of an output add to its name (``.NAME.bendsense-tmp-XXXXXXXX.SUF``)."""
    suffix = len(os.fsencode(t.path.suffix)) if t.kind == "file" else 0
    return 1 + max(len(_TMP_MARK), len(_OLD_MARK), len(_LOCK_SUFFIX)) + 8 + suffix


def _check_file(t: Target, r: Path) -> None:
    p = t.path
    if r.is_dir():
        raise OutputError(f"{p}: is a directory; give a file name")
    allowed = _suffixes(t)
    if allowed and r.suffix.lower() not in allowed:
        what = "figure format" if t.suffixes == FIGURE else "suffix"
        got = repr(r.suffix) if r.suffix else "none"
        raise OutputError(f"{p}: unknown {what} {got}; use one of {', '.join(allowed)}")
    if r.exists() or r.is_symlink():
        if not t.overwrite:
            raise OutputExistsError(f"{p}: exists (use --overwrite to replace it)")
        if not r.is_file():
            raise OutputError(f"{p}: exists and is not a regular file; refusing to replace it")
        if not _written_by_us(r):
            raise OutputError(f"{p}: exists and bendsense did not write it (no bendsense mark); refusing to replace "
                              "it even with --overwrite: remove it or choose another name")
        if t.replaces is not None and not _holds(r, t.replaces[0]):
            raise OutputError(f"{p}: exists and is not a {t.replaces[1]} (another kind of bendsense file); refusing "
                              "to replace it even with --overwrite: remove it or choose another name")


MARK = b"bendsense"
"""Every file bendsense writes carries this in its first or last 64 KiB: a header line of its
CSV and YAML files, the metadata of its figures (Software/Creator) and MCAP files."""


def _written_by_us(r: Path) -> bool:
    """Whether the existing file ``r`` is bendsense's: listed by its directory's manifest, or marked."""
    manifest = read_manifest(r.parent)
    if manifest is not None and r.name in manifest["files"]:
        return True
    return _holds(r, MARK, tail=True)


def _holds(r: Path, mark: bytes, tail: bool = False) -> bool:
    """Whether the file ``r`` holds ``mark`` in its first 64 KiB (or, with ``tail``, its last)."""
    try:
        with open(r, "rb") as fh:
            head = fh.read(1 << 16)
            if mark in head:
                return True
            if not tail:
                return False
            size = fh.seek(0, os.SEEK_END)
            fh.seek(max(size - (1 << 16), 0))
            return mark in fh.read()
    except OSError:
        return False


def figure_metadata(fmt: str) -> dict | None:
    """The bendsense mark as matplotlib's ``savefig(metadata=...)`` for ``fmt`` (None: no metadata there)."""
    key = {"png": "Software", "pdf": "Creator", "svg": "Creator", "svgz": "Creator", "eps": "Creator",
           "ps": "Creator"}.get(fmt.lower())
    return {key: "bendsense (matplotlib)"} if key else None


def _check_dir(t: Target, r: Path) -> None:
    p = t.path
    if r.exists() and not r.is_dir():
        raise OutputError(f"{p}: exists and is not a directory")
    if t.kind == "collection" or not r.is_dir():
        return
    entries = [e for e in os.listdir(r) if not _litter(e)]
    if not entries:
        return
    if not t.overwrite:
        raise OutputExistsError(
            f"{p}: exists and is not empty (use --overwrite to replace what bendsense wrote there)"
        )
    foreign = foreign_entries(r)
    if foreign:
        raise OutputError(_foreign_message(p, r, foreign))


def _foreign_message(p: Path, r: Path, foreign: list) -> str:
    shown = ", ".join(foreign[:_SHOWN]) + (f" and {len(foreign) - _SHOWN} more" if len(foreign) > _SHOWN else "")
    if read_manifest(r) is None:
        return (
            f"{p}: not a bendsense output (no {MANIFEST_NAME}); it holds {shown}; "
            "nothing was replaced (choose a new directory)"
        )
    nested = [f for f in foreign if f.endswith("/") and read_manifest(r / f) is not None]
    if nested == foreign:  # e.g. `save rec/results` inside a recording: its own output, not this one's
        return (
            f"{p}: holds another bendsense output that is not part of it: {shown}; nothing was replaced "
            "(move it away or choose a new directory)"
        )
    return (
        f"{p}: holds files bendsense did not write: {shown}; nothing was replaced "
        "(move them away or choose a new directory)"
    )


# --------------------------------------------------------------------------- manifest


# --------------------------------------------------------------------------- locks

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: an exclusive lock file instead
    fcntl = None

_held: dict[Path, list] = {}  # lock file -> [fd, count]; re-entrant within this process
_held_guard = threading.Lock()


def _lock_path(r: Path) -> Path:
    return r.parent / f".{r.name}{_LOCK_SUFFIX}"


def _try_lock(lock: Path) -> int | None:
    """Open and lock ``lock``; None if another process holds it."""
    while True:
        if fcntl is None:  # pragma: no cover
            try:
                return os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                return None
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return None
            raise
        # the holder before us may have removed the file after we opened it: lock the live one
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            same = False
        if same:  # (no pid written: a truncate-and-write makes ext4 flush on close, ~5 ms)
            return fd
        os.close(fd)


@contextlib.contextmanager
def _locked(targets: list[tuple[Path, Path]]) -> Iterator[None]:
    """Hold the locks of the resolved targets ``(user path, resolved)``; re-entrant."""
    taken: list[Path] = []
    try:
        for p, r in targets:
            lock = _lock_path(r)
            with _held_guard:
                if lock in _held:
                    _held[lock][1] += 1
                    taken.append(lock)
                    continue
            try:
                lock.parent.mkdir(parents=True, exist_ok=True)
                fd = _try_lock(lock)
            except OSError as err:
                raise OutputError(f"{p}: cannot lock the output: {reason(err)}", errno=err.errno) from None
            if fd is None:
                raise OutputError(f"{p}: another bendsense run is writing there; try again when it has finished")
            with _held_guard:
                _held[lock] = [fd, 1]
            taken.append(lock)
        yield
    finally:
        for lock in reversed(taken):
            _release(lock)


def _release(lock: Path) -> None:
    with _held_guard:
        entry = _held[lock]
        entry[1] -= 1
        if entry[1]:
            return
        del _held[lock]
    with contextlib.suppress(OSError):
        if os.path.samestat(os.fstat(entry[0]), os.stat(lock)):
            os.unlink(lock)  # while still holding it: a waiting run then locks a new file
    os.close(entry[0])


@contextlib.contextmanager
def reserve(targets: Iterable[Target], inputs: Iterable = ()) -> Iterator[None]:
    """Check all outputs of a command (:func:`check`) and lock them until the block ends.

    The CLI calls this before any work; the writers inside the block re-enter the locks.

    Parameters
    ----------
    targets : iterable of Target
        Every output of the command (:func:`directory`, :func:`file`, ...).
    inputs : iterable of paths
        The command's inputs, never to be written over.
    """
    targets, inputs = list(targets), list(inputs)
    check(targets, inputs)  # before the locks create any missing parent directory
    with _locked([(t.path, _resolve(t.path)) for t in targets]):
        check(targets, inputs)
        yield


# --------------------------------------------------------------------------- writers


@contextlib.contextmanager
def write_dir(path, *, overwrite: bool = False, inputs: Iterable = (), writer: str = "bendsense",
              source=None) -> Iterator[Path]:
    """Write a directory output: yield a fresh hidden sibling, swap it in when the block ends.

    The block writes the content into the yielded directory. On success the manifest
    (listing everything there) is added and the directory replaces ``path``; a previous
    output there is removed file by file, only what its manifest lists. On failure
    nothing at ``path`` changes and the sibling is removed.

    Parameters
    ----------
    path : path
        The output directory.
    overwrite : bool
        Replace a previous bendsense output at ``path``.
    inputs : iterable of paths
        Inputs of the command, never to be written over.
    writer : str
        Who writes, for the manifest (e.g. ``"bendsense save"``).
    source : path, optional
        The session the output was made from, for the manifest (``source``: resolved),
        which :func:`bendsense.batch.process_sessions` compares before it skips or
        replaces an output.

    Raises
    ------
    OutputExistsError, OutputError
        See :func:`check`.
    """
    target = directory(path, overwrite=overwrite)
    p, r = target.path, _resolve(path)
    inputs = list(inputs)
    check([target], inputs)
    with _locked([(p, r)]):
        check([target], inputs)
        _clear_litter(r)
        consequence = "nothing was written" + ("; the earlier output is unchanged" if r.exists() else "")
        tmp = None
        try:
            try:
                r.parent.mkdir(parents=True, exist_ok=True)
                tmp = Path(tempfile.mkdtemp(prefix=f".{r.name}{_TMP_MARK}", dir=r.parent))
                os.chmod(tmp, 0o777 & ~_umask())
            except OSError as err:
                raise write_error(p, err, consequence) from None
            with _user_paths(tmp, p, consequence):
                yield tmp
                _write_manifest(tmp, _listing(tmp), writer, source=source)
            try:
                _swap_in(tmp, target, r)
            except OutputError:
                raise
            except OSError as err:
                raise write_error(p, err, consequence) from None
        except BaseException:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            raise


def _swap_in(tmp: Path, target: Target, r: Path) -> None:
    p = target.path
    if not r.exists():
        os.replace(tmp, r)
        return
    check([target])  # again: the directory may have changed while we worked
    old = Path(tempfile.mkdtemp(prefix=f".{r.name}{_OLD_MARK}", dir=r.parent))
    os.replace(r, old)
    foreign = foreign_entries(old)
    if foreign:
        os.replace(old, r)  # something appeared meanwhile: put it all back
        raise OutputError(_foreign_message(p, r, foreign))
    try:
        os.replace(tmp, r)
    except BaseException:
        os.replace(old, r)
        raise
    _remove_ours(old, p)


def _remove_ours(d: Path, user: Path, keep_root: bool = False) -> None:
    """Remove what the manifest of ``d`` lists (and bendsense's litter); never anything else."""
    manifest = read_manifest(d)
    inside = d.resolve()
    for name in manifest["files"] if manifest else ():
        f = d / name
        if f.parent.resolve() != inside and inside not in f.parent.resolve().parents:
            continue  # reached through a symbolic link to elsewhere: never removed
        if name.endswith("/"):
            if f.is_dir() and not f.is_symlink():
                _remove_ours(f, user / name)
        elif f.is_file() or f.is_symlink():
            f.unlink()
    for entry in os.listdir(d):
        if _litter(entry):
            q = d / entry
            shutil.rmtree(q, ignore_errors=True) if q.is_dir() and not q.is_symlink() else q.unlink(missing_ok=True)
    with contextlib.suppress(FileNotFoundError):
        (d / MANIFEST_NAME).unlink()
    for sub in sorted((q for q in d.rglob("*") if q.is_dir() and not q.is_symlink()), reverse=True):
        with contextlib.suppress(OSError):
            sub.rmdir()  # only the ones left empty
    if not keep_root:
        try:
            d.rmdir()
        except OSError:
            log.warning("%s: kept %s: it holds files bendsense did not write", user, d)


def _clear_litter(r: Path) -> None:
    """Remove temporary and old siblings of ``r`` left by a killed run (we hold its lock).

    A run killed between writing ``r`` aside and renaming it leaves its temporary copy: a
    directory, or a file (``r`` a directory's manifest).
    """
    if not r.parent.is_dir():
        return
    prefix = f".{r.name}"
    for name in os.listdir(r.parent):
        if not name.startswith(prefix):
            continue
        q, rest = r.parent / name, name[len(prefix) :]
        if q.is_symlink():
            continue
        if rest.startswith(_TMP_MARK):
            with contextlib.suppress(OSError):
                shutil.rmtree(q, ignore_errors=True) if q.is_dir() else q.unlink()
        elif q.is_dir() and rest.startswith(_OLD_MARK):
            _remove_ours(q, q)


@contextlib.contextmanager
def write_file(
    path, *, overwrite: bool = False, inputs: Iterable = (), suffixes=(), writer: str = "bendsense", replaces=None
) -> Iterator[Path]:
    """Write a file output: yield a hidden temporary path beside it, rename it over ``path`` at the end.

    If the directory holds a bendsense output (a manifest), the file is added to it.
    On failure ``path`` is unchanged and the temporary file is removed.

    Parameters
    ----------
    path : path
        The output file; its parent directories are created.
    overwrite : bool
        Replace an existing file.
    inputs : iterable of paths
        Inputs of the command, never to be written over.
    suffixes : tuple of str or FIGURE
        Allowed suffixes (empty: any).
    writer : str
        Who writes, for a manifest.
    replaces : tuple of (bytes, str), optional
        Replace only a file of this kind (:class:`Target`).

    Raises
    ------
    OutputExistsError, OutputError
        See :func:`check`.
    """
    target = file(path, overwrite=overwrite, suffixes=suffixes, replaces=replaces)
    p, r = target.path, _resolve(path)
    inputs = list(inputs)
    check([target], inputs)
    with _locked([(p, r)]):
        check([target], inputs)
        existed = r.exists()
        consequence = "nothing was written" + ("; the earlier output is unchanged" if existed else "")
        tmp = None
        try:
            try:
                r.parent.mkdir(parents=True, exist_ok=True)
                fd, name = tempfile.mkstemp(prefix=f".{r.name}{_TMP_MARK}", suffix=r.suffix, dir=r.parent)
                tmp = Path(name)
                os.fchmod(fd, 0o666 & ~_umask())
                os.close(fd)
            except OSError as err:
                raise write_error(p, err, consequence) from None
            with _user_paths(tmp, p, consequence):
                yield tmp
            if r.exists() and not overwrite:  # appeared while we worked
                raise OutputExistsError(f"{p}: exists (use --overwrite to replace it)")
            try:  # first: a manifest that cannot be written leaves the file unchanged
                _register(r, writer)
            except OutputError as err:
                raise write_error(p, err, consequence) if err.errno else err from None
            try:
                os.replace(tmp, r)
            except OSError as err:
                raise write_error(p, err, consequence) from None
            tmp = None
        finally:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)


def _register(r: Path, writer: str) -> None:
    """Add the file ``r`` to the manifest of its directory, when that is a bendsense output.

    A directory another run is writing is left alone; a manifest the file system refuses
    (a full disk) stops the write.
    """
    parent = r.parent
    manifest = read_manifest(parent)
    if manifest is None or r.name in manifest["files"]:
        return
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(_locked([(parent, parent)]))
        except OutputError:
            return  # another run is writing that directory: left alone
        add_to_manifest(parent, [r.name], writer=writer)


def write_text(path, text: str, **options) -> None:
    """Write ``text`` (UTF-8) to the file ``path`` (options of :func:`write_file`).

    Parameters
    ----------
    path : path
        The output file.
    text : str
        The text to write.
    **options
        ``overwrite``, ``inputs``, ``suffixes``, ``writer`` of :func:`write_file`.
    """
    with write_file(path, **options) as tmp:
        tmp.write_text(text, encoding="utf-8")


class InPlace:
    """A directory output written in place (a recording); holds its lock until :meth:`close`."""

    def __init__(self, path, files, *, overwrite: bool = False, inputs: Iterable = (), writer: str = "bendsense"):
        target = recording(path, overwrite=overwrite)
        p, r = target.path, _resolve(path)
        self.path = r
        inputs = list(inputs)
        check([target], inputs)
        self._stack = contextlib.ExitStack()
        self._stack.enter_context(_locked([(p, r)]))
        self._user, self._created = p, not r.exists()
        try:
            check([target], inputs)
            with _user_paths(r, p):
                if r.is_dir():
                    _remove_ours(r, p, keep_root=True)
                r.mkdir(parents=True, exist_ok=True)
                _write_manifest(r, list(files), writer)
        except BaseException:
            self.abandon()
            raise

    def close(self) -> None:
        """Release the lock."""
        self._stack.close()

    def abandon(self) -> None:
        """Remove what was written (nothing was recorded: a start the file system refused) and release the lock."""
        try:
            if self.path.is_dir():
                _remove_ours(self.path, self._user, keep_root=not self._created)
        finally:
            self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def begin_in_place(path, files, *, overwrite: bool = False, inputs: Iterable = (),
                   writer: str = "bendsense") -> InPlace:
    """Start a directory output written in place (a recording).

    Checks and locks ``path``, removes a previous output there (only what its manifest
    lists; anything else makes it refuse) and writes the manifest listing ``files``
    first, so that a recording killed at any moment is still recognised as bendsense's.
    The returned :class:`InPlace` holds the lock until its ``close()``.

    Parameters
    ----------
    path : path
        The output directory.
    files : iterable of str
        Names of the files the writer will create there.
    overwrite : bool, default False
        Replace a previous bendsense output there.
    inputs : iterable of paths
        The command's inputs, never to be written over.
    writer : str, default "bendsense"
        Who writes, for the manifest.
    """
    return InPlace(path, files, overwrite=overwrite, inputs=inputs, writer=writer)
