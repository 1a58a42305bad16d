"""Every public function and class of bendsense has a numpydoc docstring.

Public: the names in a public module's ``__all__`` (or, without one, its names without a
leading underscore that it defines itself); a module is public when no part of its
dotted name starts with an underscore. Each has a summary line, and so has each public
method of a public class; a function or method with parameters has a ``Parameters``
section.
"""

import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import bendsense

# Functions and methods in modules another engineer is optimising (estimation/,
# shift_errors.py): their Parameters sections are filled when that work lands.
NO_PARAMETERS_YET = {
    "bendsense.estimation.problem.reference",
    "bendsense.estimation.problem.points",
    "bendsense.estimation.result.messages",
    "bendsense.estimation.uncertainty.tip_angle_weights",
    "bendsense.estimation.uncertainty.tip_angle_shift_gradient",
    "bendsense.estimation.uncertainty.noise_std",
    "bendsense.calibration.shift_errors.noise_only",
    "bendsense.estimation.result.ForceEstimate.plot",
}


def _public_modules():
    names = ["bendsense"]
    for info in pkgutil.walk_packages(bendsense.__path__, "bendsense."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _public_objects():
    """``{qualified name: object}`` of every public function and class, each once (at its home)."""
    found = {}
    for name in _public_modules():
        module = importlib.import_module(name)
        names = getattr(module, "__all__", None)
        if names is None:
            names = [n for n, o in vars(module).items()
                     if not n.startswith("_") and getattr(o, "__module__", "") == name]
        for n in names:
            obj = getattr(module, n)
            if (inspect.isfunction(obj) or inspect.isclass(obj)) and obj.__module__.startswith("bendsense"):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


OBJECTS = _public_objects()
FUNCTIONS = sorted(k for k, o in OBJECTS.items() if inspect.isfunction(o))
CLASSES = sorted(k for k, o in OBJECTS.items() if inspect.isclass(o))
SECTION = r"^Parameters\n-{10}$"


def _summary(doc: str | None) -> str:
    lines = (inspect.cleandoc(doc or "") + "\n").splitlines()
    return lines[0].strip() if len(lines) < 2 or not lines[1].strip() else ""


def test_the_walk_finds_the_public_api():
    assert {"bendsense.estimation.estimate_force", "bendsense.mechanics.beam.solve_beam",
            "bendsense.shape.pcc.reconstruct", "bendsense.calibration.model.Calibration",
            "bendsense.results.read_results", "bendsense.output.write_file"} <= set(OBJECTS)
    assert len(FUNCTIONS) > 150 and len(CLASSES) > 50
    assert NO_PARAMETERS_YET <= set(FUNCTIONS) | set(_methods())  # the allow-list names real functions


def _api_reference() -> dict:
    """``{module: names shown, or None for all}`` of the ``::: module`` directives in docs/api."""
    shown = {}
    for page in (Path(__file__).resolve().parents[2] / "docs" / "api").glob("*.md"):
        for m in re.finditer(r"^::: ([\w.]+)\n((?:[ \t]+.*\n)*)", page.read_text(encoding="utf-8"), re.M):
            members = re.search(r"members:\s*\[([^\]]*)\]", m.group(2))
            shown[m.group(1)] = None if members is None else {n.strip() for n in members.group(1).split(",")}
    return shown


def test_the_api_reference_shows_every_public_function_and_class():
    """Each one is rendered by mkdocstrings: in its own module's section, or re-exported by a package's."""
    shown = _api_reference()

    def rendered(module, name):
        return module in shown and (shown[module] is None or name in shown[module])

    missing = [
        qualname for qualname, obj in OBJECTS.items()
        if not rendered(obj.__module__, obj.__qualname__)
        and not any(rendered(package, obj.__name__) and obj.__name__ in getattr(importlib.import_module(package),
                                                                                "__all__", ())
                    for package in shown)
    ]
    assert missing == [], f"not in the API reference (docs/api/*.md): {missing}"


def test_every_function_and_class_has_a_summary_line():
    missing = [name for name in FUNCTIONS + CLASSES if not _summary(OBJECTS[name].__doc__)]
    assert missing == [], f"no docstring with a one-line summary: {missing}"


def test_functions_with_parameters_document_them():
    missing = []
    for name in FUNCTIONS:
        fn = OBJECTS[name]
        params = [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]
        if params and name not in NO_PARAMETERS_YET and not re.search(SECTION, inspect.getdoc(fn), re.M):
            missing.append(f"{name}({', '.join(params)})")
    assert missing == [], f"no Parameters section: {missing}"


def _methods():
    """``{qualified name: function}`` of the public methods (and properties) of the public classes."""
    found = {}
    for name in CLASSES:
        for attr, value in vars(OBJECTS[name]).items():
            fn = value.__func__ if isinstance(value, (classmethod, staticmethod)) else value
            fn = fn.fget if isinstance(fn, property) else fn
            if not attr.startswith("_") and inspect.isfunction(fn):
                found[f"{name}.{attr}"] = (fn, isinstance(value, property))
    return found


def test_public_methods_have_a_summary_line():
    missing = [name for name, (fn, _) in _methods().items() if not _summary(fn.__doc__)]
    assert missing == [], f"no docstring with a one-line summary: {missing}"


def test_public_methods_with_parameters_document_them():
    missing = []
    for name, (fn, is_property) in _methods().items():
        params = [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]
        if params and not is_property and name not in NO_PARAMETERS_YET \
                and not re.search(SECTION, inspect.getdoc(fn), re.M):
            missing.append(f"{name}({', '.join(params)})")
    assert missing == [], f"no Parameters section: {missing}"


def test_the_section_check_sees_a_missing_section():
    def documented(x):
        """Do it.

        Parameters
        ----------
        x : float
            A value [m].
        """

    def undocumented(x):
        """Do it."""

    assert re.search(SECTION, inspect.getdoc(documented), re.M)
    assert not re.search(SECTION, inspect.getdoc(undocumented), re.M)
    assert _summary(undocumented.__doc__) == "Do it." and _summary("Two\nlines") == ""
