"""Applications at the edges: ``bendsense.apps``, the import paths they had before, and who may import them."""

import ast
import importlib
from pathlib import Path

import pytest

import bendsense
import bendsense.pipeline

SRC = Path(bendsense.__file__).parent
#: Old import path → the application module that replaced it.
ALIASES = {
    "bendsense.device.live": "bendsense.apps.live_view",
    "bendsense.device.demo": "bendsense.apps.demo",
    "bendsense.sim.reproduce": "bendsense.apps.evaluation",
}
ALIAS_FILES = ("device/live.py", "device/demo.py", "sim/reproduce.py")


def imported_modules(path: Path) -> set:
    """Every module ``path`` imports, at the top or inside functions, as an absolute name."""
    package = ".".join(("bendsense", *path.relative_to(SRC).parent.parts))
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join([*package.split(".")[: len(package.split(".")) - node.level + 1], base]).rstrip(".")
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


@pytest.mark.parametrize(("old", "new"), ALIASES.items())
def test_old_import_paths_give_the_same_objects(old, new):
    before, after = importlib.import_module(old), importlib.import_module(new)
    assert before.__all__
    for name in before.__all__:
        # the live window's module also named the live core's classes
        assert getattr(before, name) is getattr(after, name, None) or getattr(before, name) is getattr(
            bendsense.pipeline, name), name


def test_only_applications_and_the_command_line_import_the_applications():
    offenders = sorted(
        p.relative_to(SRC).as_posix() for p in SRC.rglob("*.py")
        if not p.relative_to(SRC).as_posix().startswith(("apps/", "cli/"))
        and p.relative_to(SRC).as_posix() not in ALIAS_FILES
        and any(within(m, "bendsense.apps") for m in imported_modules(p))
    )
    assert offenders == []


def test_the_pipeline_and_the_simulator_stay_below_the_applications():
    edges = ("bendsense.cli", "bendsense.plots", "bendsense.device", "bendsense.apps")
    assert not [m for m in imported_modules(SRC / "pipeline.py") if any(within(m, e) for e in edges)]
    sim = [p for p in (SRC / "sim").glob("*.py") if p.name != "reproduce.py"]
    assert not [m for p in sim for m in imported_modules(p) if within(m, "bendsense.apps")]
    assert {p.name for p in (SRC / "device").glob("*.py")} - {"live.py", "demo.py"} == {
        "__init__.py", "driver.py", "estimator.py", "ports.py", "recorder.py", "replay.py", "simdevice.py"}


def test_applications_are_short_modules_of_short_functions():
    long = []
    for path in [*(SRC / "apps").rglob("*.py"), SRC / "pipeline.py", SRC / "batch.py"]:
        text = path.read_text(encoding="utf-8")
        if path.parent.name == "evaluation":
            assert len(text.splitlines()) <= 500, path.name
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and node.end_lineno - node.lineno > 100:
                long.append(f"{path.name}:{node.name}")
    assert long == []
