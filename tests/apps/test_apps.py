"""Applications at the edges: ``bendsense.apps``, and who may import them."""

import ast
from pathlib import Path

import bendsense
import bendsense.pipeline

SRC = Path(bendsense.__file__).parent


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


def test_only_applications_and_the_command_line_import_the_applications():
    offenders = sorted(
        p.relative_to(SRC).as_posix() for p in SRC.rglob("*.py")
        if not p.relative_to(SRC).as_posix().startswith(("apps/", "cli/"))
        and any(within(m, "bendsense.apps") for m in imported_modules(p))
    )
    assert offenders == []


def test_the_pipeline_and_the_simulator_stay_below_the_applications():
    edges = ("bendsense.cli", "bendsense.plots", "bendsense.device", "bendsense.apps")
    pipeline = (SRC / "pipeline").glob("*.py")
    assert not [m for p in pipeline for m in imported_modules(p) if any(within(m, e) for e in edges)]
    assert not [m for p in (SRC / "sim").glob("*.py") for m in imported_modules(p) if within(m, "bendsense.apps")]
    assert {p.name for p in (SRC / "device").glob("*.py")} == {
        "__init__.py", "driver.py", "estimator.py", "ports.py", "recorder.py", "replay.py", "simdevice.py"}


def test_applications_are_short_modules_of_short_functions():
    long = []
    for path in [*(SRC / "apps").rglob("*.py"), *(SRC / "pipeline").glob("*.py"), *(SRC / "batch").glob("*.py")]:
        text = path.read_text(encoding="utf-8")
        if path.parent.name == "evaluation":
            assert len(text.splitlines()) <= 500, path.name
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and node.end_lineno - node.lineno > 100:
                long.append(f"{path.name}:{node.name}")
    assert long == []
