"""The package's layout says its architecture: kernels/ knows nothing of the paper, model/ knows
nothing of data files, pictures or applications, nothing below apps/ imports apps/, and no
module grows past ~500 lines."""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "lss_kernels"
MODULES = sorted(p for p in PACKAGE.rglob("*.py"))


def _imports(path):
    """Absolute dotted names of the package modules that ``path`` imports (anywhere in it)."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    package = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target + "." + a.name for a in node.names]
            found |= {n for n in [target] + names if n.startswith("lss_kernels")}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("lss_kernels")}
    return found


def _below(path, folder):
    return path.is_relative_to(PACKAGE / folder)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_follow_the_layers(path):
    imports = _imports(path)
    forbidden = set()
    if _below(path, "kernels"):
        forbidden = {"lss_kernels.model", "lss_kernels.apps", "lss_kernels.reference",
                     "lss_kernels.io", "lss_kernels.viz", "lss_kernels.metrics",
                     "lss_kernels.scenes", "lss_kernels.solver", "lss_kernels.params"}
    elif _below(path, "model"):
        forbidden = {"lss_kernels.apps", "lss_kernels.reference", "lss_kernels.io",
                     "lss_kernels.viz", "lss_kernels.metrics", "lss_kernels.scenes",
                     "lss_kernels.solver"}
    elif not _below(path, "apps"):
        forbidden = {"lss_kernels.apps"}
    bad = sorted(i for i in imports if any(i == f or i.startswith(f + ".") for f in forbidden))
    assert not bad, f"{path.relative_to(PACKAGE)} imports {bad}"


def test_the_fast_path_never_calls_the_specification():
    users = [p for p in MODULES if any(i.startswith("lss_kernels.reference")
                                       for i in _imports(p))]
    allowed = {PACKAGE / "apps" / "bench.py"}       # times the kernels against it
    assert {p for p in users if not _below(p, "reference")} <= allowed


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_over_500_lines(path):
    assert len(path.read_text().splitlines()) <= 500
