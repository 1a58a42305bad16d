"""The frozen result dataclasses' quick ``__init__`` (``bendsense._batched.quick_init``): the generated one's terms."""

import copy
import dataclasses
import inspect
import pickle

import numpy as np
import pytest

from bendsense._batched import quick_init
from bendsense.estimation.result import ForceEstimate
from bendsense.shape.pcc import Shape
from bendsense.tracking.track import Track


def _record(name):
    """A frozen dataclass with positional, defaulted and keyword-only fields (one declared among the others)."""
    cls = dataclasses.make_dataclass(name, [
        ("a", object),
        ("d", object, dataclasses.field(default="x", kw_only=True)),
        ("b", object, dataclasses.field(default=2.0)),
        ("c", object, dataclasses.field(default=None, repr=False)),
        ("e", object, dataclasses.field(kw_only=True, default=None)),
    ], frozen=True, eq=False)
    cls.__module__ = __name__  # pickled by name, as a module's class
    return cls


Plain = _record("Plain")  # as dataclasses writes it
Quick = quick_init(_record("Quick"))


def test_the_quick_init_takes_what_the_generated_one_takes_and_sets_the_same_fields():
    plain, quick = Plain, Quick
    assert inspect.signature(quick) == inspect.signature(plain)
    for args, kwargs in [((1,), {}), ((1, 3, 4), {"d": "y"}), ((), {"a": 1, "e": 5})]:
        want, got = plain(*args, **kwargs), quick(*args, **kwargs)
        assert vars(got) == vars(want)
    for args, kwargs in [((), {}), ((1, 2, 3, 4), {}), ((1,), {"f": 0}), ((1,), {"a": 2})]:
        with pytest.raises(TypeError) as want:
            plain(*args, **kwargs)
        with pytest.raises(TypeError) as got:
            quick(*args, **kwargs)
        assert str(got.value).split("__init__()")[-1] == str(want.value).split("__init__()")[-1]


def test_a_quickly_made_result_is_still_frozen_and_replaces_copies_and_pickles():
    r = Quick(np.arange(3.0), d="z")
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.a = 1
    assert dataclasses.replace(r, b=7).b == 7 and dataclasses.replace(r, b=7).d == "z"
    for twin in (copy.deepcopy(r), pickle.loads(pickle.dumps(r))):
        assert np.array_equal(twin.a, r.a) and (twin.b, twin.c, twin.d, twin.e) == (2.0, None, "z", None)
    assert "c=" not in repr(r) and "d='z'" in repr(r)  # the fields' repr flags are the dataclass's own


def test_the_library_results_use_it_and_a_post_init_is_refused():
    for cls in (ForceEstimate, Shape, Track):
        names = cls.__init__.__code__.co_names
        assert "update" in names and "__setattr__" not in names  # one dict update, no object.__setattr__ per field
        assert list(inspect.signature(cls).parameters) == [f.name for f in dataclasses.fields(cls)]

    @dataclasses.dataclass(frozen=True)
    class Checked:
        a: float

        def __post_init__(self):
            pass

    with pytest.raises(TypeError, match="__post_init__"):
        quick_init(Checked)
