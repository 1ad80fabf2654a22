"""The package's layout says its architecture: kernels/ knows nothing of the paper, model/ knows
nothing of data files, pictures, applications or the checks around a solve, and nothing below
apps/ imports apps/."""
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


#: The checks around a solve (input validation, periodicity, photometry, direction and range,
#: collapse and retry): a layer that wraps the model, which never reaches up into it.
CHECKS = "lss_kernels.checks"


def _below(path, folder):
    return path.is_relative_to(PACKAGE / folder)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_follow_the_layers(path):
    imports = _imports(path)
    forbidden = set()
    if _below(path, "kernels"):
        forbidden = {"lss_kernels.model", "lss_kernels.apps", "lss_kernels.reference",
                     "lss_kernels.io", "lss_kernels.viz", "lss_kernels.metrics",
                     "lss_kernels.scenes", "lss_kernels.solver", "lss_kernels.params", CHECKS}
    elif _below(path, "model"):
        forbidden = {"lss_kernels.apps", "lss_kernels.reference", "lss_kernels.io",
                     "lss_kernels.viz", "lss_kernels.metrics", "lss_kernels.scenes",
                     "lss_kernels.solver", CHECKS}
    elif not _below(path, "apps"):
        forbidden = {"lss_kernels.apps"}
    bad = sorted(i for i in imports if any(i == f or i.startswith(f + ".") for f in forbidden))
    assert not bad, f"{path.relative_to(PACKAGE)} imports {bad}"


def test_the_fast_path_never_calls_the_specification():
    users = [p for p in MODULES if any(i.startswith("lss_kernels.reference")
                                       for i in _imports(p))]
    allowed = {PACKAGE / "apps" / "bench.py"}       # times the kernels against it
    assert {p for p in users if not _below(p, "reference")} <= allowed


def test_the_model_imports_no_check_and_no_app():
    """model/ imports neither the checks layer nor the apps, directly or through the modules
    it imports from the package (the start types, the parameters, the kernels)."""
    def reach(module, seen):
        path = PACKAGE.parent / (module.replace(".", "/") + ".py")
        if not path.is_file():
            path = PACKAGE.parent / module.replace(".", "/") / "__init__.py"
        if module in seen or not path.is_file():
            return seen
        seen.add(module)
        for name in _imports(path):
            reach(name, seen)
        return seen

    for path in MODULES:
        if _below(path, "model"):
            module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
            bad = sorted(m for m in reach(module, set()) if any(
                m == layer or m.startswith(layer + ".")
                for layer in (CHECKS, "lss_kernels.apps")))
            assert not bad, f"{path.relative_to(PACKAGE)} reaches {bad}"


def test_the_checks_are_one_subpackage_around_the_solver():
    """The checks live in checks/ only, and the solver takes from them no more than the
    checked pair and the checks of its own arguments and memory: direction, photometry,
    periodicity and recovery are the layer's, which :func:`lss_kernels.solve` wraps around
    it."""
    for name in ("validate", "periodicity", "photometry", "direction", "recovery"):
        assert not (PACKAGE / f"{name}.py").exists(), f"{name}.py outside checks/"
    taken = {i for i in _imports(PACKAGE / "solver.py") if i.startswith(CHECKS + ".")}
    assert {i.rsplit(".", 1)[0] if i.count(".") > 2 else i for i in taken} <= {
        "lss_kernels.checks.pair", "lss_kernels.checks.validate"}


def test_no_import_cycle():
    """No module reaches itself through the package modules it imports (anywhere in it,
    deferred imports included)."""
    names = {".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(
        ".__init__"): p for p in MODULES}
    graph = {m: {i for i in _imports(p) if i in names and i != m} for m, p in names.items()}
    state = {}                                   # 1: on the current path, 2: finished

    def visit(module, path):
        state[module] = 1
        for other in sorted(graph[module]):
            assert state.get(other) != 1, "import cycle: " + " -> ".join(
                path[path.index(other):] + [other])
            if other not in state:
                visit(other, path + [other])
        state[module] = 2

    for module in sorted(names):
        if module not in state:
            visit(module, [module])
