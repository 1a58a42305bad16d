"""The frozen result dataclasses: made quickly, and their frames taken, put back, expanded to a larger batch.

The live processor (:class:`bendsense.pipeline.LiveProcessor`) estimates the frames of a
block that have a pressure, retries those that failed, and keeps one frame as the next
block's warm start: these helpers cut and join the frozen result dataclasses
(``Shape``, ``ForceEstimate``) along their leading frame axis, field by field.
:func:`quick_init` gives them an ``__init__`` that costs under half of the generated one.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["take_frames", "put_frames", "expand_frames", "concat_frames", "quick_init", "brief_repr", "STATIC_FIELDS"]

#: Fields that are never per frame, whatever their length: a shape's points along the body
#: and its segment lengths. A block of as many frames (41 points, 16 segments) must not cut them.
STATIC_FIELDS = frozenset({"s_m", "lengths_m"})


def quick_init(cls):
    """Give the frozen dataclass ``cls`` an ``__init__`` that fills the instance's dict in one update.

    The ``__init__`` that :func:`dataclasses.dataclass` writes for a frozen class sets each
    field through ``object.__setattr__``, ~0.3 µs a field: 8.5 µs for a ``ForceEstimate``'s
    31 fields, 3.7 µs with this one. It has the same signature (the same names, order,
    defaults and keyword-only fields) and sets the same attributes; the instances stay
    frozen (assignment raises). Use as a decorator above ``@dataclass(frozen=True)``; a
    class with ``__post_init__`` or a ``default_factory`` is refused (TypeError).
    """
    fields = [f for f in dataclasses.fields(cls) if f.init]
    if hasattr(cls, "__post_init__") or any(f.default_factory is not dataclasses.MISSING for f in fields):
        raise TypeError(f"quick_init: {cls.__name__} has __post_init__ or a default_factory")
    defaults = {f"_d_{f.name}": f.default for f in fields if f.default is not dataclasses.MISSING}

    def param(f):
        return f.name if f.default is dataclasses.MISSING else f"{f.name}=_d_{f.name}"

    # as dataclasses orders them: the keyword-only fields after the others, wherever declared
    params = [param(f) for f in fields if not f.kw_only]
    keywords = [param(f) for f in fields if f.kw_only]
    params += ["*", *keywords] if keywords else []
    source = (f"def __init__(self, {', '.join(params)}):\n"
              f"    self.__dict__.update({', '.join(f'{f.name}={f.name}' for f in fields)})\n")
    namespace = {}
    exec(source, defaults, namespace)  # as dataclasses writes its own: one function of the fields' names
    init = namespace["__init__"]
    init.__annotations__ = dict(cls.__init__.__annotations__)
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__module__ = cls.__module__
    cls.__init__ = init
    return cls


def brief_repr(obj) -> str:
    """A result dataclass in a line or two: each field's value, or an array's shape and range, a dict's keys.

    A notebook that prints a session of 1,000 frames got every time and pressure (numpy
    shows arrays of up to 1,000 values whole) and every extra column: 136 kB.
    """
    def brief(value) -> str:
        if isinstance(value, np.ndarray) and value.size > 6:
            finite = value[np.isfinite(value)] if value.dtype.kind == "f" else None
            span = f", {finite.min():.4g}..{finite.max():.4g}" if finite is not None and finite.size else ""
            kind = {"U": "str", "S": "bytes", "O": "object"}.get(value.dtype.kind, value.dtype.name)
            return f"<{kind} array {value.shape}{span}>"
        if isinstance(value, dict) and (len(value) > 6 or any(isinstance(v, np.ndarray) and v.size > 6
                                                              for v in value.values())):
            keys = list(value)
            return "{" + ", ".join(map(str, keys[:8])) + (", ..." if len(keys) > 8 else "") + f"}} ({len(keys)} keys)"
        if isinstance(value, (tuple, list)) and len(value) > 8:
            return f"<{type(value).__name__} of {len(value)}>"
        text = repr(value)
        return text if len(text) <= 80 else text[:77] + "..."

    fields = ", ".join(f"{f.name}={brief(getattr(obj, f.name))}" for f in dataclasses.fields(obj) if f.repr)
    return f"{type(obj).__name__}({fields})"


def _per_frame(name: str, value, n: int) -> bool:
    """Whether field ``name`` holding ``value`` has the leading frame axis of ``n`` frames."""
    return name not in STATIC_FIELDS and isinstance(value, np.ndarray) and value.ndim > 0 and value.shape[0] == n


def take_frames(obj, index, n: int):
    """The frames ``index`` of a batched result object (every field with leading axis ``n``).

    Parameters
    ----------
    obj : dataclass
        A result batched over ``n`` frames (``Shape``, ``ForceEstimate``, ``Track``).
    index : int, slice, array of int or bool
        The frames.
    n : int
        The batch size: the fields whose leading axis has this length are cut (never
        those of :data:`STATIC_FIELDS`).
    """
    changes = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if _per_frame(f.name, value, n):
            changes[f.name] = value[index]
    return dataclasses.replace(obj, **changes)


def put_frames(obj, index, part, n: int):
    """``obj`` (batch axis ``n``) with the frames ``index`` replaced by those of ``part``.

    Parameters
    ----------
    obj : dataclass
        A result batched over ``n`` frames.
    index : array of int
        The frames to replace.
    part : dataclass
        The same kind of result for those frames.
    n : int
        The batch size of ``obj``.
    """
    changes = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if _per_frame(f.name, value, n):
            new = np.array(value, dtype=object if value.dtype.kind in "US" else value.dtype)
            new[index] = getattr(part, f.name)
            changes[f.name] = new
    return dataclasses.replace(obj, **changes)


def expand_frames(est, mask: np.ndarray, *, message: str = "no pressure reading", status: int = 0):
    """A ForceEstimate for all frames of ``mask`` from one for the frames where it is True.

    The other frames get NaN forces, ``success=False``, ``message`` and the code ``status``.

    Parameters
    ----------
    est : ForceEstimate
        The estimates of the frames where ``mask`` is True.
    mask : ndarray of bool, shape (n,)
        The frames that have an estimate.
    message : str, default "no pressure reading"
        The other frames' message.
    status : int, default 0
        The other frames' status code (:class:`~bendsense.status.Status`; 0: none).
    """
    n, m = mask.size, int(mask.sum())
    changes = {}
    for f in dataclasses.fields(est):
        value = getattr(est, f.name)
        if _per_frame(f.name, value, m):
            if value.dtype.kind == "b":
                full = np.zeros((n, *value.shape[1:]), dtype=bool)
            elif value.dtype.kind in "US":
                full = np.full((n, *value.shape[1:]), message, dtype=object)
            elif value.dtype.kind in "iu":
                full = np.full((n, *value.shape[1:]), status if f.name == "status" else 0, dtype=value.dtype)
            else:
                full = np.full((n, *value.shape[1:]), np.nan, dtype=value.dtype if value.dtype.kind == "f" else object)
            full[mask] = value
            changes[f.name] = full
    return dataclasses.replace(est, **changes)


def concat_frames(parts):
    """One result of the frames of ``parts`` in order (every field with a leading frame axis joined).

    Parameters
    ----------
    parts : sequence of dataclass
        Results of the same kind (``Track``), each batched over its own frames (the length
        of its ``force_n``); the other fields are those of the first.
    """
    counts = [np.shape(part.force_n)[0] for part in parts]
    changes = {}
    for f in dataclasses.fields(parts[0]):
        values = [getattr(part, f.name) for part in parts]
        if all(_per_frame(f.name, v, k) for v, k in zip(values, counts)):
            changes[f.name] = np.concatenate(values)
    return dataclasses.replace(parts[0], **changes)
