"""Bounded, one-line-error readers of text and YAML files (outputs: :mod:`bendsense.output`)."""

from __future__ import annotations

import os
import stat

__all__ = ["check_regular_file", "file_kind", "read_yaml", "open_regular", "parse_yaml", "read_text", "safe_load"]


MAX_YAML_BYTES = 2 * 2**20
"""Largest YAML file (config, calibration, manifest, meta.yaml) a reader accepts [bytes]."""
MAX_YAML_NODES = 50_000
"""Most YAML nodes a document may expand to, aliases counted at every use."""


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def file_kind(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is, for a message (``"a FIFO (named pipe)"``); None: a regular file."""
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _not_regular(path, kind: str, what: str, error):
    return error(f"{path}: {kind}, not a {what}; give a regular file")


def _checked(path, error):
    """The reader's ``path`` (a checked path) and ``error`` class (default :class:`~bendsense.errors.ConfigError`)."""
    from bendsense.errors import ConfigError
    from bendsense.validation import path as _path

    error = error or ConfigError
    return _path("path", path, error=error), error


def _cannot_read(path, what: str, err: OSError, error):
    """The one-line error for a file the system refuses to stat or open."""
    if isinstance(err, FileNotFoundError):
        return error(f"{path}: cannot read {what}: no such file")
    return error(f"{path}: cannot read {what}: {err.strerror or err}")


def check_regular_file(path: str | os.PathLike, what: str, error=None) -> os.stat_result:
    """``os.stat`` of ``path``, refusing anything but a regular file with one line naming what it is.

    A FIFO blocks its reader until something writes to it, ``/dev/zero`` never ends,
    a socket cannot be read as a file: every reader of a user's file (session,
    config, calibration, manifest, recording) checks its path here, or opens it with
    :func:`open_regular`, before reading a byte.

    Parameters
    ----------
    path : str or path-like
        The file.
    what : str
        What the file should be, for the message (``"session CSV"``).
    error : type, optional
        The exception class (default :class:`~bendsense.errors.ConfigError`).
    """
    path, error = _checked(path, error)
    try:
        st = os.stat(path)
    except OSError as err:
        raise _cannot_read(path, what, err, error) from None
    kind = file_kind(st.st_mode)
    if kind is not None:
        raise _not_regular(path, kind, what, error)
    return st


def open_regular(path: str | os.PathLike, what: str, error=None):
    """``path`` opened for binary reading, if it is a regular file (else one line naming what it is).

    The file is opened non-blocking and checked on the open descriptor, so that a
    FIFO neither blocks the open nor can be swapped in between a check and the open.

    Parameters
    ----------
    path : str or path-like
        The file.
    what : str
        What the file should be, for the message (``"session CSV"``).
    error : type, optional
        The exception class (default :class:`~bendsense.errors.ConfigError`).

    Returns
    -------
    file object
        Binary, buffered; the caller closes it.
    """
    path, error = _checked(path, error)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except IsADirectoryError:  # (platforms that cannot open a directory)
        raise _not_regular(path, "a directory", what, error) from None
    except OSError as err:
        raise _cannot_read(path, what, err, error) from None
    try:
        kind = file_kind(os.fstat(fd).st_mode)
        if kind is not None:
            raise _not_regular(path, kind, what, error)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_text(path: str | os.PathLike, what: str, error=None, *, max_bytes: int | None = None) -> str:
    """The UTF-8 text of ``path`` (a leading byte-order mark dropped).

    Every problem is one line that starts with the path: the file cannot be read,
    is not a regular file (a FIFO, a device, a directory: :func:`open_regular`), is
    larger than ``max_bytes`` (None: no bound; session CSVs of hours are large),
    holds NUL bytes (binary, not text), or is not UTF-8 (with the byte offset and
    line of the first bad byte).
    """
    from bendsense.errors import ConfigError

    error = error or ConfigError
    try:
        with open_regular(path, what, error) as fh:
            data = fh.read() if max_bytes is None else fh.read(max_bytes + 1)
    except OSError as err:
        raise error(f"{path}: cannot read {what}: {err.strerror or err}") from None
    if max_bytes is not None and len(data) > max_bytes:
        raise error(f"{path}: too large for a {what} (over {max_bytes / 2**20:g} MiB)")
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise error(f"{path}: UTF-16 text, not UTF-8; save the file as UTF-8")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # a UTF-8 byte-order mark (spreadsheet exports) is harmless
    nul = data.find(b"\x00")
    if nul >= 0:
        raise error(f"{path}: binary data, not a {what} (NUL byte at byte offset {nul})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        raise error(f"{path}: not UTF-8 text (byte offset {err.start}, line {line}); "
                    "save the file as UTF-8") from None


def read_yaml(path: str | os.PathLike, what: str, parse, error=None):
    """Read the YAML file ``path`` and return ``parse(data)``.

    Every problem is a :class:`~bendsense.errors.ConfigError` (or ``error``) whose
    message starts with the path: the file cannot be read (``cannot read <what>``),
    is too large, binary or not UTF-8 (:func:`read_text`), is not YAML (with line and
    column), expands beyond :data:`MAX_YAML_NODES` through aliases, or ``parse``
    rejects a field.
    """
    text = read_text(path, what, error, max_bytes=MAX_YAML_BYTES)
    return parse_yaml(text, str(path), parse, error)


def parse_yaml(text: str, source: str, parse, error=None):
    """``parse`` the YAML ``text``; errors are ConfigErrors (or ``error``) prefixed with ``source``."""
    from bendsense.errors import BendsenseError, ConfigError

    error = error or ConfigError
    data = safe_load(text, source, error)
    try:
        return parse(data)
    except BendsenseError as err:
        if str(err).startswith(source):
            raise
        raise type(err)(f"{source}: {err}") from None


def safe_load(text: str, source: str, error=None):
    """``yaml.safe_load`` with bounded alias expansion and one-line errors naming ``source``.

    Aliases are counted at every use (a "billion laughs" document of a few hundred
    bytes expands to 10^9 nodes); a document that expands beyond
    :data:`MAX_YAML_NODES` is refused before anything is built from it.
    """
    import yaml

    from bendsense.errors import ConfigError

    error = error or ConfigError
    loader_class = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    loader = loader_class(text)
    try:
        # count the events first: composing nodes costs ~7 us each, so a large flat
        # document is refused before it is composed (an error within a second)
        for count, _ in enumerate(yaml.parse(text, Loader=loader_class)):
            if count > MAX_YAML_NODES + 4:  # + stream and document start and end
                raise error(f"{source}: YAML has more than {MAX_YAML_NODES:,} nodes; refused")
        node = loader.get_single_node()
        if node is None:
            return None
        _check_expansion(node, source, error)
        return loader.construct_document(node)
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = " ".join(str(err.problem or err.context or "syntax error").split())
        raise error(f"{source}: not valid YAML: {problem}{where}") from None
    except yaml.YAMLError as err:
        raise error(f"{source}: not valid YAML: {' '.join(str(err).split())[:200]}") from None
    except RecursionError:
        raise error(f"{source}: not valid YAML: nested too deeply") from None
    finally:
        loader.dispose()


def _check_expansion(root, source: str, error) -> None:
    """Refuse a node graph that expands beyond MAX_YAML_NODES, refers to itself or repeats a key."""
    import yaml

    size: dict[int, int] = {}
    # iterative post-order walk: each distinct node is sized once, its size counts at every use
    stack = [(root, False)]
    active: set[int] = set()
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            active.discard(key)
            if isinstance(node, yaml.SequenceNode):
                children = node.value
            else:
                children = [n for pair in node.value for n in pair]
            total = 1 + sum(size[id(c)] for c in children)
            size[key] = total
            if total > MAX_YAML_NODES:
                raise error(f"{source}: YAML expands to more than {MAX_YAML_NODES:,} nodes through aliases "
                            "(an alias bomb?); refused")
            continue
        if key in size:
            continue
        if not isinstance(node, (yaml.SequenceNode, yaml.MappingNode)):
            size[key] = 1
            continue
        if key in active:
            raise error(f"{source}: YAML alias refers to itself (a recursive structure); refused")
        if isinstance(node, yaml.MappingNode):
            # YAML lets a repeated key silently replace the first one: a copy-paste mistake
            seen = {}
            for k, _ in node.value:
                if isinstance(k, yaml.ScalarNode):
                    if k.value in seen and k.value != "<<":
                        raise error(f"{source}: duplicate key {k.value[:40]!r} (line {k.start_mark.line + 1}; "
                                    f"first on line {seen[k.value]})")
                    seen[k.value] = k.start_mark.line + 1
        active.add(key)
        stack.append((node, True))
        children = node.value if isinstance(node, yaml.SequenceNode) else [n for pair in node.value for n in pair]
        for child in children:
            if id(child) in active:
                raise error(f"{source}: YAML alias refers to itself (a recursive structure); refused")
            if id(child) not in size:
                stack.append((child, False))


def check_csv_header(header: list[str], line: int, error=None) -> None:
    """Refuse a CSV header that is really another separator's (``;`` or tab) in one cell.

    Spreadsheets in many locales export ``;``-separated files (with ``,`` as the
    decimal mark); reading one as CSV gives a single column, so say what happened.
    """
    from bendsense.errors import ConfigError

    error = error or ConfigError
    if len(header) == 1:
        for sep, name in ((";", "';'"), ("\t", "tabs")):
            if sep in header[0]:
                raise error(f"line {line}: columns are separated by {name}, expected ',' "
                            "(save the file as comma-separated CSV with '.' as the decimal mark)")
