"""What the package imports is what it declares: every third-party module imported anywhere in
``pnlviz/`` comes from a distribution named in ``pyproject.toml`` (the dependencies, or an extra
for the modules only an extra's commands import); and the licence it declares ships."""

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def imported_modules() -> set[str]:
    """Top-level names of every ``import`` in the package (lazy ones inside functions too)."""
    mods = set()
    for path in (REPO / "pnlviz").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                mods |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods.add(node.module.split(".")[0])
    return {m for m in mods if m not in sys.stdlib_module_names and m != "pnlviz"}


def declared(requirements) -> set[str]:
    return {re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0].strip().lower() for r in requirements}


def test_every_imported_module_is_declared():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    base = declared(project["dependencies"])
    extras = set().union(*(declared(v) for v in project["optional-dependencies"].values()))
    dists = packages_distributions()
    missing, extra_only = [], []
    for module in sorted(imported_modules()):
        names = {d.lower() for d in dists.get(module, [module])}
        if not names & (base | extras):
            missing.append(module)
        elif not names & base:
            extra_only.append(module)
    assert missing == [], f"imported but not declared in pyproject.toml: {missing}"
    assert {"viser", "websockets", "cv2", "numpy"} <= imported_modules()
    assert set(extra_only) <= {"torch", "distributed", "dask"}, extra_only  # only an extra's commands need them


def test_the_declared_licence_ships():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    assert (REPO / "LICENSE").read_text().startswith("MIT License")
