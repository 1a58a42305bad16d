"""What the file system allows an output: its names, its links, one writer per file, its refusals in words.

The checks of :mod:`bendsense.output` that concern the path itself, before any work:

- every name fits the file system (:func:`_check_names`; ``ENAMETOOLONG`` never reaches
  a half-done command);
- no symbolic link on the path leads elsewhere (:func:`_check_links`): a dangling link
  would make bendsense create directories at its target;
- no two steps of one command line write one file (:func:`check_steps`).

And the words for the file system's refusals on the way (:func:`reason`,
:func:`write_error`): a full disk, a quota, a file-size limit, a read-only disk, too many
open files, each as one line naming the user's path.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator
from pathlib import Path

from bendsense.errors import BendsenseError, OutputError

__all__ = ["reason", "write_error", "check_steps"]


def _resolve(path) -> Path:
    """The absolute path with every ``..`` and symlink resolved: what the checks compare."""
    return Path(os.path.abspath(path)).resolve()


def _is_within(inner: Path, outer: Path) -> bool:
    """Whether the resolved ``inner`` is ``outer`` or inside it."""
    return inner == outer or inner.is_relative_to(outer)


# the file system's refusals in words, for one-line messages (strerror is capitalised, and
# says nothing of the limit behind EFBIG or EMFILE)
_REASONS = {
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large (beyond the file-size limit, see 'ulimit -f', or the file system's largest file)",
    errno.ENAMETOOLONG: "file name too long",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EISDIR: "is a directory",
    errno.ENOTDIR: "a part of the path is not a directory",
    errno.EMFILE: "too many open files (the per-process limit, see 'ulimit -n')",
    errno.ENFILE: "too many open files on this system",
    errno.EIO: "input/output error (a failing disk or a disconnected drive?)",
    errno.ENOENT: "no such file or directory",
    errno.ELOOP: "too many levels of symbolic links",
}
# refusals that concern the file being written even when the OSError names no file (a write or
# close of an open file): they are about the output, not about an input
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO, errno.EMFILE,
                           errno.ENFILE, errno.ENAMETOOLONG})


def reason(err: OSError) -> str:
    """The file system's refusal ``err`` in words, for a message (``"no space left on device"``).

    Parameters
    ----------
    err : OSError
        The error.
    """
    text = _REASONS.get(getattr(err, "errno", None))
    if text is None:
        text = str(getattr(err, "strerror", None) or err)
        text = text[:1].lower() + text[1:]
    return text


def write_error(path, err: OSError, consequence: str = "") -> OutputError:
    """An :class:`~bendsense.errors.OutputError` ``"PATH: reason[; consequence]"`` for the OSError ``err``.

    The error keeps ``err.errno`` (e.g. ``errno.ENOSPC``).

    Parameters
    ----------
    path : path
        The path to name: the user's, never a hidden temporary one.
    err : OSError
        The file system's refusal.
    consequence : str, optional
        What it means for the output, e.g. ``"nothing was written"``.
    """
    tail = f"; {consequence}" if consequence else ""
    refusal = OutputError(f"{path}: {reason(err)}{tail}", errno=getattr(err, "errno", None))
    refusal.path = str(path)  # (not .filename: OSError's str() would show it)
    return refusal


def _existing_ancestor(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (or is a link)."""
    anc = path
    while not os.path.lexists(anc) and anc != anc.parent:
        anc = anc.parent
    return anc


def _read_only(path: Path) -> bool:
    """Whether ``path`` lies on a file system mounted read-only."""
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def _check_parent(p: Path, r: Path) -> None:
    """Refuse an output (user path ``p``, resolved ``r``) whose nearest existing ancestor cannot hold it."""
    anc = _existing_ancestor(r.parent)
    if not anc.is_dir():
        raise OutputError(f"{p}: {anc} is not a directory", errno=errno.ENOTDIR)
    if not os.access(anc, os.W_OK | os.X_OK):
        if _read_only(anc):
            raise OutputError(f"{p}: cannot write in {anc} (read-only file system)", errno=errno.EROFS)
        raise OutputError(f"{p}: cannot write in {anc} (permission denied)", errno=errno.EACCES)


def _check_names(p: Path, overhead: int) -> None:
    """Refuse a path the file system cannot hold, before anything is created (ENAMETOOLONG).

    Parameters
    ----------
    p : Path
        The output path as the user gave it.
    overhead : int
        Bytes that the hidden siblings of the output add to its own name.
    """
    full = os.path.abspath(p)
    anc = _existing_ancestor(Path(full))
    try:
        name_max = os.pathconf(anc, "PC_NAME_MAX")
        path_max = os.pathconf(anc, "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):
        name_max, path_max = 255, 4096
    if len(os.fsencode(full)) + overhead >= path_max:
        raise OutputError(f"{_short_path(p)}: path too long ({len(os.fsencode(full)):,} bytes; this file system "
                          f"allows {path_max - 1 - overhead:,} for an output)", errno=errno.ENAMETOOLONG)
    parts = Path(full).parts
    for i, part in enumerate(parts):
        n = len(os.fsencode(part))
        last = i == len(parts) - 1
        limit = name_max - overhead if last else name_max
        if n > limit:
            extra = "" if not last or n > name_max else " (bendsense writes a hidden temporary file beside it first)"
            where = "" if last else f" in {_short_name(part)}"
            raise OutputError(f"{_short_path(p)}: file name too long ({n} bytes{where}; at most {limit} here{extra})",
                              errno=errno.ENAMETOOLONG)


def _short_name(name: str) -> str:
    return repr(name) if len(name) <= 40 else repr(name[:16] + "..." + name[-16:])


def _short_path(p: Path) -> str:
    """The user's path for a message, its overlong names shortened."""
    text = str(p)
    if len(text) <= 200:
        return text
    return os.sep.join(part if len(part) <= 40 else part[:16] + "..." + part[-16:] for part in text.split(os.sep))


def _check_links(p: Path) -> None:
    """Refuse symbolic links on an output path that lead out of the directory that holds them.

    A dangling link anywhere on the path would make bendsense create directories at its
    target; the output itself as a link out of its directory would write there. A link
    within its directory (``out -> results-v2``) is followed, and links among the existing
    ancestors of the path the user typed (a data directory on another disk) are part
    of where the user works.
    """
    parts = p.parts
    for i in range(1, len(parts) + 1):
        q = Path(*parts[:i])
        if not q.is_symlink():
            if not os.path.lexists(q):
                return  # the rest is to be created
            continue
        target = os.readlink(q)
        if not q.exists():
            raise OutputError(f"{q}: a symbolic link to {target}, which does not exist; refusing to write through it "
                              "(it would create directories at its target): remove the link or give another path")
        res, home = _resolve(q), _resolve(q.parent)
        if i == len(parts) and (res == home or not res.is_relative_to(home)):
            raise OutputError(f"{q}: a symbolic link to {target}, outside its directory; refusing to write through "
                              "it: give the path it points to, or another name")


def check_steps(steps) -> None:
    """Refuse a command line two of whose steps write one file, before any work.

    Two outputs collide when they are one path, when a later step writes into the
    directory of an earlier step one of the names that step writes there (``save out``
    then ``export out/results.csv``), or when a later step replaces a directory that
    holds an earlier step's output (``plot out/fig.png`` then ``save out``). A file
    that a later step adds to an earlier step's results directory (``save out`` then
    ``plot out/fig.png``) joins its manifest and is fine.

    Parameters
    ----------
    steps : iterable of (str, iterable of bendsense.output.Target)
        Each step's label (e.g. ``"save"``) and outputs, in the order they run.

    Raises
    ------
    OutputError
        Naming both steps and the path.
    """
    seen: list = []
    for i, (label, targets) in enumerate(steps, 1):
        for t in targets:
            r = _resolve(t.path)
            for j, other, o, ro in seen:
                if j == i and r != ro:
                    continue  # one step's own outputs: check() compares them
                clash = r == ro
                if not clash and _is_within(r, ro) and o.kind != "file":  # into an earlier directory
                    first = r.relative_to(ro).parts[0]
                    clash = o.kind != "dir" or not o.files or first in o.files
                if not clash and _is_within(ro, r) and t.kind != "file":  # replaces what an earlier step wrote
                    clash = True
                if clash:
                    where = t.path if _is_within(r, ro) else o.path
                    steps_text = (f"'{other}' (step {j}) and '{label}' (step {i})" if other == label
                                  else f"'{other}' and '{label}'")
                    raise OutputError(f"{where}: written by two steps of this command line, {steps_text}; "
                                      "give each step its own output")
            seen.append((i, label, t, r))


@contextlib.contextmanager
def _user_paths(tmp: Path, user: Path, consequence: str = "") -> Iterator[None]:
    """Re-raise an error about the hidden ``tmp`` as one naming ``user``.

    An OSError about ``tmp`` (or about no file, when it is a refusal to write: a full
    disk, a file-size limit, ...) becomes an OutputError that ends with ``consequence``;
    a bendsense error keeps its class.
    """
    try:
        yield
    except BendsenseError as err:
        if str(tmp) not in str(err) or len(err.args) != 1:
            raise
        inner = getattr(err, "path", None)
        if isinstance(err, OutputError) and err.errno and inner and str(tmp) in inner:
            # a refusal inside (a file of a directory output): what it means for the whole output
            raise write_error(inner.replace(str(tmp), str(user), 1), err, consequence) from None
        text = str(err).replace(str(tmp), str(user))
        if isinstance(err, OutputError):
            raise type(err)(text, errno=err.errno) from None
        raise type(err)(text) from None
    except OSError as err:
        hidden = str(tmp)
        names = [str(n) for n in (err.filename, getattr(err, "filename2", None)) if n is not None]
        ours = [n for n in names if n.startswith(hidden)]
        if names and not ours:
            raise  # about another file (an input): not the output's
        if not names and err.errno not in _WRITE_ERRNOS:
            raise
        # a write or close names no file: the output as a whole
        where = ours[0].replace(hidden, str(user), 1) if ours else str(user)
        raise write_error(where, err, consequence) from None
