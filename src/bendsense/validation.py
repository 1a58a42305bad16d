"""Checks of user input, one message form for all of them.

Every check names the field, says what is allowed and what was received, in the form
``"field: expected ..., got ..."`` (STYLE.md), and raises the error class it is given
(:class:`~bendsense.errors.ArgumentError` by default; the config reader passes
:class:`~bendsense.errors.ConfigError`, the session readers
:class:`~bendsense.errors.SessionError`). A received value is shown through
:func:`short`, so a message never embeds an unbounded user value (a megabyte of
YAML in a field stays one short line).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from bendsense.errors import ArgumentError, ConfigError

__all__ = [
    "short",
    "fail",
    "number",
    "integer",
    "boolean",
    "choice",
    "duration_s",
    "length_m",
    "parse_number",
    "float_array",
    "key",
    "path",
    "instance",
    "MAX_LENGTH_M",
]

SHORT_LIMIT = 60
"""Longest received value a message shows [characters]."""

MAX_LENGTH_M = 1.0
"""A length of a bending actuator or its sensor beyond this is a unit mistake [m]."""


def short(value, limit: int = SHORT_LIMIT) -> str:
    """``repr`` of ``value`` cut to at most ``limit`` characters (``...`` marks the cut).

    Long sequences are cut before they are formatted, so a huge list costs nothing.

    Parameters
    ----------
    value : object
        The value to show.
    limit : int, default 60
        Longest result, in characters.
    """
    if isinstance(value, np.ndarray):
        if value.size > 8:
            head = np.array2string(value.reshape(-1)[:4], separator=", ")[:-1]
            return _cut(f"{head}, ... ({value.size} values)]", limit)
        text = np.array2string(value, separator=", ")
    elif isinstance(value, (list, tuple)) and len(value) > 8:
        head = ", ".join(short(v, limit) for v in value[:4])
        text = f"[{head}, ... ({len(value)} values)]"
    elif isinstance(value, dict) and len(value) > 8:
        text = f"{{... {len(value)} keys}}"
    elif isinstance(value, np.generic):
        text = repr(value.item())
    elif isinstance(value, (str, bytes)) and len(value) > limit:
        text = repr(value[:limit])
    else:
        text = repr(value)
    return _cut(text, limit)


def _cut(text: str, limit: int) -> str:
    text = " ".join(text.split()) if "\n" in text else text
    return text if len(text) <= limit else text[: max(limit - 3, 1)] + "..."


def fail(field: str, expected: str, got, error=ArgumentError, *, raw: bool = False):
    """The error ``field: expected <expected>, got <short(got)>`` (``raw``: ``got`` as given).

    Parameters
    ----------
    field : str
        The field or option, e.g. ``sensor.strip_gap_m``.
    expected : str
        What is allowed.
    got : object
        What was received.
    error : type, default ArgumentError
        The exception class to return.
    raw : bool, default False
        Show ``got`` as given instead of its shortened ``repr``.
    """
    return error(f"{field}: expected {expected}, got {got if raw else short(got)}")


def number(
    field: str,
    value,
    *,
    error=ArgumentError,
    positive: bool = False,
    nonnegative: bool = False,
    minimum: float | None = None,
    maximum: float | None = None,
) -> float:
    """A finite real number (not a bool, not a string), optionally bounded.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check.
    error : type, default ArgumentError
        The exception class to raise.
    positive, nonnegative : bool, default False
        Require > 0, or >= 0.
    minimum, maximum : float, optional
        Inclusive bounds.
    """
    # bool is an int subclass; a YAML "true" where a number belongs is a mistake
    if isinstance(value, bool) or not isinstance(value, Real):
        raise fail(field, "a number", value, error)
    value = float(value)
    if not math.isfinite(value):
        raise fail(field, "a finite number", value, error)
    if positive and not value > 0:
        raise fail(field, "> 0", value, error)
    if nonnegative and not value >= 0:
        raise fail(field, ">= 0", value, error)
    if minimum is not None and value < minimum:
        raise fail(field, f">= {minimum:g}", value, error)
    if maximum is not None and value > maximum:
        raise fail(field, f"<= {maximum:g}", value, error)
    return value


def integer(field: str, value, *, error=ArgumentError, minimum: int | None = None, maximum: int | None = None) -> int:
    """An integer (not a bool, not a float), optionally bounded.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check.
    error : type, default ArgumentError
        The exception class to raise.
    minimum, maximum : int, optional
        Inclusive bounds.
    """
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise fail(field, "an integer", value, error)
    value = int(value)
    if minimum is not None and maximum is not None and not minimum <= value <= maximum:
        raise fail(field, f"an integer in {minimum}..{maximum}", value, error)
    if minimum is not None and value < minimum:
        raise fail(field, f"an integer >= {minimum}", value, error)
    if maximum is not None and value > maximum:
        raise fail(field, f"an integer <= {maximum}", value, error)
    return value


def boolean(field: str, value, *, error=ArgumentError) -> bool:
    """``True`` or ``False`` (not 0/1, not a string).

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check.
    error : type, default ArgumentError
        The exception class to raise.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise fail(field, "true or false", value, error)
    return bool(value)


def choice(field: str, value, choices: Iterable[str], *, error=ArgumentError) -> str:
    """One of ``choices``.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check.
    choices : iterable of str
        The allowed values.
    error : type, default ArgumentError
        The exception class to raise.
    """
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise fail(field, f"one of {', '.join(choices)}", value, error)
    return value


def duration_s(field: str, value, *, error=ArgumentError, allow_zero: bool = False) -> float:
    """A time span: finite and > 0 (``allow_zero``: >= 0) [s]; NaN, inf and negatives are refused.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check [s].
    error : type, default ArgumentError
        The exception class to raise.
    allow_zero : bool, default False
        Accept 0.
    """
    if allow_zero:
        return number(field, value, error=error, nonnegative=True)
    return number(field, value, error=error, positive=True)


def length_m(field: str, value, *, error=ArgumentError, max_m: float = MAX_LENGTH_M, positive: bool = True) -> float:
    """A length of the actuator or sensor [m]: finite, > 0 and at most ``max_m``.

    A value over ``max_m`` is almost always millimetres written where metres belong,
    and the message says so.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : object
        The value to check [m].
    error : type, default ArgumentError
        The exception class to raise.
    max_m : float, default 1.0
        Largest length accepted [m].
    positive : bool, default True
        Require > 0 (False: >= 0).
    """
    value = number(field, value, error=error, positive=positive, nonnegative=not positive)
    if value > max_m:
        raise error(
            f"{field}: expected a length in metres <= {max_m:g}, got {value:g}; "
            f"looks like millimetres (did you mean {value / 1e3:g}?)"
        )
    return value


def parse_number(field: str, text: str, *, error=ArgumentError) -> float:
    """The number written in ``text`` (e.g. a command-line value), finite.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    text : str
        The text to parse.
    error : type, default ArgumentError
        The exception class to raise.
    """
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise fail(field, "a number", text, error) from None
    return number(field, value, error=error)


def key(value, limit: int = 40) -> str:
    """A mapping key or column name for a message: as written, cut to ``limit`` characters.

    Parameters
    ----------
    value : object
        The key or column name.
    limit : int, default 40
        Longest result, in characters.
    """
    text = value if isinstance(value, str) else short(value, limit)
    return _cut(text, limit)


def float_array(field: str, value, *, error=ArgumentError) -> np.ndarray:
    """``value`` as a float array; text, complex numbers or objects that are not numbers are refused.

    Parameters
    ----------
    field : str
        The field or option, for the message.
    value : array_like
        The value to convert.
    error : type, default ArgumentError
        The exception class to raise.
    """
    if isinstance(value, complex) or getattr(getattr(value, "dtype", None), "kind", "") == "c":
        raise fail(field, "real numbers", value, error)  # numpy would drop the imaginary part with a warning
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise fail(field, "numbers", value, error) from None


def path(field: str, value, *, error=ArgumentError) -> Path:
    """``value`` as a :class:`~pathlib.Path`: a non-empty ``str`` or ``os.PathLike`` without NUL characters.

    Parameters
    ----------
    field : str
        The argument, for the message.
    value : object
        The value to check.
    error : type, default ArgumentError
        The exception class to raise.
    """
    if isinstance(value, (str, os.PathLike)):
        text = os.fspath(value)
        if isinstance(text, str) and text and "\x00" not in text:
            return Path(text)
    raise fail(field, "a file path (str or os.PathLike)", value if isinstance(value, str) else _type(value), error,
               raw=not isinstance(value, str))


def instance(field: str, value, cls: type, how: str = "", *, error=ArgumentError):
    """``value`` if it is a ``cls``; else the error ``field: expected a <cls> (<how>), got <type>``.

    Parameters
    ----------
    field : str
        The argument, for the message.
    value : object
        The value to check.
    cls : type or tuple of type
        The class (or classes) expected.
    how : str, optional
        How to get one, for the message (``"bendsense.read_session(path)"``).
    error : type, default ArgumentError
        The exception class to raise.
    """
    if isinstance(value, cls):
        return value
    names = " or ".join(c.__name__ for c in cls) if isinstance(cls, tuple) else cls.__name__
    if names == "Config" and hasattr(type(value), "single_message"):  # a gripper where one actuator belongs
        raise ConfigError(value.single_message(field))
    hint = f" ({how})" if how else ""
    raise fail(field, f"a {names}{hint}", _type(value), error, raw=True)


def _type(value) -> str:
    """What ``value`` is, for a message: its type, with the shape of an array."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    if value is None:
        return "None"
    return type(value).__name__


def broadcasts(field: str, shape: tuple, to: tuple, what: str = "the frames", *, error=ArgumentError) -> None:
    """Refuse an argument of ``shape`` that does not broadcast to ``to`` (one line naming it and both shapes).

    Parameters
    ----------
    field : str
        The argument, for the message.
    shape : tuple of int
        Its shape (a batch shape, or an array's).
    to : tuple of int
        The shape it must broadcast to.
    what : str, default "the frames"
        What ``to`` is the shape of, for the message.
    error : type, default ArgumentError
        The exception class to raise.
    """
    try:
        if np.broadcast_shapes(shape, to) == tuple(to):
            return
    except ValueError:
        pass
    raise error(f"{field}: shape {tuple(shape)} does not broadcast against {what} {tuple(to)}")
