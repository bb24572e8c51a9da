"""The folder layout is the architecture (docs/architecture.md): data flows one way.

Every import between pincal's modules — at module level, inside functions and
under ``TYPE_CHECKING`` alike — is read from the source with :mod:`ast`, so a
lazy import cannot hide a cycle or a climb. The layers, bottom to top, are
:data:`LAYERS`; a module may import its own subpackage, any lower layer, and
nothing else: not a higher layer, not a peer of its own layer, not the package
root ``pincal`` (which re-exports the public API and so sits above everything).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pincal"

#: Bottom to top; the rooms of one layer are peers and never import each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("_version", "errors", "outputs", "progress", "palette"),
    ("measurements", "robots", "datasets"),
    ("model",),
    ("simulation",),
    ("residuals",),
    ("fit",),
    ("paper", "diagnosis", "planning"),
    ("study",),
    ("report",),
    ("cli",),
)
#: The package root and ``python -m pincal`` sit on top of the CLI.
ENTRY_POINTS = ("pincal", "pincal.__main__")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def pincal_imports(path: Path, name: str) -> set[str]:
    """The pincal modules ``path`` (module ``name``) imports, anywhere in its body."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.split(".")[0] == "pincal")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module.split(".")[0] != "pincal":
                continue
            found.add(module)
            # ``from pincal.fit import solver`` imports the module pincal.fit.solver
            found.update(f"{module}.{a.name}" for a in node.names if f"{module}.{a.name}" in MODULES)
    return found


MODULES: dict[str, Path] = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def import_graph() -> dict[str, set[str]]:
    return {name: {m for m in pincal_imports(path, name) if m in MODULES} - {name} for name, path in MODULES.items()}


def room(module: str) -> str:
    """The top-level subpackage or module a module belongs to (``pincal.fit.solver`` -> ``fit``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer(module: str) -> int:
    if module in ENTRY_POINTS:
        return len(LAYERS)
    for index, rooms in enumerate(LAYERS):
        if room(module) in rooms:
            return index
    raise AssertionError(f"{module} is in no layer: add its room to LAYERS and to docs/architecture.md")


def layering_violations(graph: dict[str, set[str]]) -> list[str]:
    bad = []
    for importer, imported in sorted(graph.items()):
        for target in sorted(imported):
            if target == "pincal" and importer not in ENTRY_POINTS:
                bad.append(f"{importer} imports the package root (import from the defining module instead)")
            elif layer(target) > layer(importer):
                bad.append(f"{importer} (layer {layer(importer)}) climbs to {target} (layer {layer(target)})")
            elif layer(target) == layer(importer) and room(target) != room(importer) and importer not in ENTRY_POINTS:
                bad.append(f"{importer} imports its peer {target}")
    return bad


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_every_module_is_in_a_layer():
    for name in MODULES:
        layer(name)


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_no_import_climbs_a_layer_or_crosses_to_a_peer():
    assert layering_violations(import_graph()) == []


def test_the_checks_catch_what_they_guard():
    """The checkers themselves flag a planted cycle, a climb, a peer import and a root import."""
    graph = {name: set(deps) for name, deps in import_graph().items()}
    assert cycles({**graph, "pincal.model.chain": graph["pincal.model.chain"] | {"pincal.model.effects"}})
    assert any("climbs" in v for v in layering_violations({"pincal.model.chain": {"pincal.fit.solver"}}))
    assert any("peer" in v for v in layering_violations({"pincal.planning.planner": {"pincal.diagnosis.diagnose"}}))
    assert any("root" in v for v in layering_violations({"pincal.fit.solver": {"pincal"}}))


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_stay_small(name):
    """One concept per module (docs/architecture.md); issue 8 caps a module at about 500 lines."""
    lines = len(MODULES[name].read_text(encoding="utf-8").splitlines())
    assert lines <= 520, f"{name} has {lines} lines: split it by concept"


def test_no_module_repeats_its_folder_name():
    """``study/tasks.py``, not ``study/study_tasks.py``; ``model/dh/robot.py``, not ``model/dh/dh_robot.py``."""
    for name in MODULES:
        parts = name.split(".")
        if len(parts) >= 3 and MODULES[name].name != "__init__.py":
            assert not parts[-1].startswith(parts[-2].rstrip("s")), name


#: The steps of a calibration (pincal.fit.pipeline): only the pipeline calls them, so a kind of
#: measurement brings its residual and nothing else (issue: one calibration pipeline). The planner
#: orders candidate poses (pincal.planning.design) without calibrating.
PIPELINE_STEPS = {"order_parameters": {"pincal.fit.pipeline", "pincal.planning.design"},
                  "select_subset": {"pincal.fit.pipeline"}, "map_outcome": {"pincal.fit.pipeline"}}


def step_callers(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Which modules call each of :data:`PIPELINE_STEPS` (as ``f(...)``, ``m.f(...)`` or under an
    imported alias)."""
    callers: dict[str, set[str]] = {step: set() for step in PIPELINE_STEPS}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases = {a.asname: a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                   for a in node.names if a.asname}
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                called = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
                called = aliases.get(called, called)
                if called in callers:
                    callers[called].add(name)
    return callers


def test_one_calibration_pipeline(tmp_path):
    outside = {step: callers - PIPELINE_STEPS[step] for step, callers in step_callers(MODULES).items()}
    assert outside == {step: set() for step in PIPELINE_STEPS}  # modules that run a step themselves
    twice = tmp_path / "fixture_calibration.py"  # a kind that selects on its own is caught
    for call in ("from pincal.fit.selection import select_subset as pick\nchosen = pick(1, 2)\n",
                 "from pincal.fit import selection\nchosen = selection.map_outcome(3)\n"):
        twice.write_text(call, encoding="utf-8")
        assert set().union(*step_callers({"pincal.fit.fixture_calibration": twice}).values()) == {
            "pincal.fit.fixture_calibration"}

