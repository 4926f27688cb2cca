"""The layers import one way: evaluation -> tamp.app -> tamp.sim -> tamp.planning -> (symbolic, learned) -> guarded."""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

from tests.paths import ROOT

DRAKE_SIDE = ("pydrake", "ompl", "ur_analytic_ik")
# package -> module prefixes it must never import (anywhere in a file, function-local imports included)
FORBIDDEN = {
    "tamp/planning": ("tamp.sim", "tamp.app", "evaluation", *DRAKE_SIDE),
    "tamp/sim": ("tamp.app", "evaluation"),
    "tamp/app": ("evaluation",),
    "learned": ("tamp", "symbolic", "evaluation", *DRAKE_SIDE),
    "symbolic": ("tamp", "learned", "evaluation", "torch", *DRAKE_SIDE),
    "guarded": ("tamp", "learned", "symbolic", "evaluation", "numpy", "torch", *DRAKE_SIDE),
}


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at top level or inside functions."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_no_package_imports_a_layer_above_it(package):
    offenders = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for name in imported_modules(path):
            if any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN[package]):
                offenders.append(f"{path.relative_to(ROOT)} imports {name}")
    assert not offenders, "\n".join(offenders)


def test_the_planner_loads_no_drake():
    modules = [p.relative_to(ROOT).with_suffix("").as_posix().replace("/", ".")
               for p in sorted((ROOT / "tamp" / "planning").glob("*.py")) if p.stem != "__init__"]
    code = (f"import sys, tamp.planning, {', '.join(modules)}\n"
            f"loaded = [m for m in {DRAKE_SIDE!r} if m in sys.modules]\n"
            "assert not loaded, loaded")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert len(modules) >= 6  # bilevel, search, verify, models, domain, validate, structs
