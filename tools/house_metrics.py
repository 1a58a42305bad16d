"""The house's numbers of issue 32: how the package is laid out, counted from the source.

    python tools/house_metrics.py

Prints top-level modules, prefix families (``x.py`` beside ``x_y.py``), modules that only
re-export another, status words parsed back from text, functions with more than ten
parameters outside the compiled kernels, public names, test files and API reference pages.
"""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src" / "bendsense"


def _modules():
    return [p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts]


def _prefix_families():
    families = []
    for directory in {p.parent for p in _modules()}:
        stems = {p.stem for p in directory.glob("*.py")} | {p.name for p in directory.iterdir() if p.is_dir()}
        for stem in sorted(stems):
            if not stem.startswith("_") and any(other.startswith(stem + "_") for other in stems):
                families.append(f"{directory.relative_to(SRC.parent)}/{stem}")
    return families


def _is_compiled(node):
    for dec in node.decorator_list:
        name = ast.unparse(dec)
        if "njit" in name or "jit" in name.split("(")[0].split(".")[-1]:
            return True
    return False


def _many_parameters():
    found = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_compiled(node):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
                n -= bool(a.args and a.args[0].arg in ("self", "cls"))
                if n > 10:
                    found.append((n, f"{path.relative_to(SRC.parent)}:{node.name}"))
    return sorted(found, reverse=True)


def _shims():
    shims = []
    for path in _modules():
        tree = ast.parse(path.read_text())
        body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
        text = path.read_text()
        if path.name != "__init__.py" and body and all(
                isinstance(n, (ast.Import, ast.ImportFrom))
                or (isinstance(n, ast.Assign) and ast.unparse(n.targets[0]) == "__all__") for n in body):
            shims.append(str(path.relative_to(SRC.parent)))
        elif re.search(r"^Compatibility", ast.get_docstring(tree) or "", re.M):
            shims.append(str(path.relative_to(SRC.parent)))
        elif "_PRIVATE" in text or "_DATA_HELPERS" in text:
            shims.append(str(path.relative_to(SRC.parent)) + " (re-exports)")
    return sorted(shims)


def main():
    """Print the numbers."""
    import bendsense

    text = {p: p.read_text() for p in _modules()}
    parsed = sum(len(re.findall(r"np\.char\.startswith|\.startswith\(\s*(STATUS|_STATUS|\"not_|'not_)", t))
                 for t in text.values())
    many = _many_parameters()
    rows = [
        ("modules directly under src/bendsense", len(list(SRC.glob("*.py")))),
        ("prefix families (x beside x_y)", len(_prefix_families())),
        ("shims (modules that only re-export)", len(_shims())),
        ("status text matches (np.char.startswith ...)", parsed),
        ("functions with > 10 parameters (not compiled)", len(many)),
        ("  of them private", sum(1 for _, name in many
                                  if name.split(":")[1].startswith("_") and not name.endswith("__"))),
        ("public names (bendsense.__all__)", len(bendsense.__all__)),
        ("test files", len(list((ROOT / "tests").rglob("test_*.py")))),
        ("  directly in tests/ (not in a package's folder)", len(list((ROOT / "tests").glob("test_*.py")))),
        ("API reference pages (docs/api)", len(list((ROOT / "docs" / "api").glob("*.md")))),
        ("`::: module` blocks in the API reference", sum(
            len(re.findall(r"^::: ", p.read_text(), re.M)) for p in (ROOT / "docs" / "api").glob("*.md"))),
    ]
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    print("\nprefix families:", ", ".join(_prefix_families()) or "none")
    print("shims:", ", ".join(_shims()) or "none")
    print("functions with > 10 parameters:", ", ".join(f"{name} ({n})" for n, name in many) or "none")


if __name__ == "__main__":
    main()
