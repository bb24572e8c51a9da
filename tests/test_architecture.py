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
import dataclasses
import functools
import importlib
from pathlib import Path

import pytest
from conftest import package_files
from sources import nodes, parsed

PACKAGE = Path(__file__).resolve().parents[1] / "pincal"

#: Bottom to top; the rooms of one layer are peers and never import each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("_version", "errors", "outputs", "progress", "palette", "figure_margins"),
    ("measurements", "robots", "datasets"),
    ("model",),
    ("simulation",),
    ("residuals",),
    ("fit",),
    ("paper", "diagnosis", "planning"),
    ("study",),
    ("report",),
    ("workflows",),
    ("cli",),
)
#: The package root and ``python -m pincal`` sit on top of the CLI.
ENTRY_POINTS = ("pincal", "pincal.__main__")


def source(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def parsed_file(path: Path) -> ast.Module:
    """The tree of a module, parsed once per text (tests/sources.py: the checks below each read every module)."""
    return parsed(source(path))


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def pincal_imports(path: Path, name: str) -> set[str]:
    """The pincal modules ``path`` (module ``name``) imports, anywhere in its body."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in nodes(source(path), ast.Import, ast.ImportFrom):
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


MODULES: dict[str, Path] = {module_name(p): p for p in package_files()}


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
    """One concept per module (docs/architecture.md); a module is capped at about 500 lines."""
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
# the identifiability rule also orders a plan's columns and the mass-moment loads of a compliance of unknown masses
PIPELINE_STEPS = {"order_parameters": {"pincal.fit.pipeline", "pincal.planning.design",
                                       "pincal.diagnosis.moment_candidates"},
                  "select_subset": {"pincal.fit.pipeline"}, "map_outcome": {"pincal.fit.pipeline"}}


def step_callers(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Which modules call each of :data:`PIPELINE_STEPS` (as ``f(...)``, ``m.f(...)`` or under an
    imported alias)."""
    callers: dict[str, set[str]] = {step: set() for step in PIPELINE_STEPS}
    for name, path in modules.items():
        text = source(path)
        aliases = {a.asname: a.name for node in nodes(text, ast.ImportFrom) for a in node.names if a.asname}
        for node in nodes(text, ast.Call):
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


def declared_all(path: Path) -> list[str] | None:
    """The names of the module's ``__all__ = [...]`` (a literal list or tuple of strings), or None."""
    found = _declared_all(path, path.stat().st_mtime_ns)
    return None if found is None else list(found)


@functools.cache
def _declared_all(path: Path, modified_ns: int) -> tuple[str, ...] | None:
    """:func:`declared_all` parsed once per file version (the public-name check asks once per import)."""
    for node in parsed_file(path).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return tuple(ast.literal_eval(element) for element in node.value.elts)  # type: ignore[attr-defined]
    return None


def top_level_names(tree: ast.Module) -> tuple[set[str], set[str]]:
    """The names a module binds at top level (also inside ``if``/``try``): defined, and imported."""
    defined: set[str] = set()
    imported: set[str] = set()
    body = list(tree.body)
    while body:
        node = body.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            defined.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            imported.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.If, ast.Try)):
            body.extend(node.body + node.orelse + getattr(node, "finalbody", []))
            body.extend(stmt for handler in getattr(node, "handlers", []) for stmt in handler.body)
    return defined, imported


def names_imported_across_rooms(modules: dict[str, Path]) -> list[tuple[str, str, str]]:
    """(importer, module, name) of every ``from pincal.<room>... import name`` whose module is in
    another room than the importer's (the package root counts as a room of its own), anywhere in its body."""
    found = []
    for importer, path in modules.items():
        package = importer if path.name == "__init__.py" else importer.rpartition(".")[0]
        for node in nodes(source(path), ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - (node.level - 1)] if node.level else []
            module = ".".join(base + [node.module]) if node.level else node.module or ""
            if module in MODULES and (room(module) != room(importer) or importer in ENTRY_POINTS):
                found.extend((importer, module, a.name) for a in node.names if f"{module}.{a.name}" not in MODULES)
    return found


def private_imports(modules: dict[str, Path]) -> list[str]:
    """Names imported from another room that the defining module does not list in its ``__all__``."""
    bad = []
    for importer, module, name in names_imported_across_rooms(modules):
        exported = declared_all(MODULES[module]) or []
        if name not in exported:
            bad.append(f"{importer} imports {name} from {module}, whose __all__ does not list it")
    return bad


def _lazy_exports() -> dict[str, tuple[str, ...]]:
    """``pincal``'s public names by defining module (imported on first use, so no import statement)."""
    import pincal

    return pincal._DEFINED_IN


def test_every_module_states_its_public_names():
    """A module that binds a public name (no leading underscore) at top level declares ``__all__``:
    what other rooms, the tests and the users may import from it. Every listed name exists."""
    for name, path in MODULES.items():
        defined, imported = top_level_names(parsed_file(path))
        exported = declared_all(path)
        public = {n for n in defined if not n.startswith("_")}
        if path.name == "__init__.py" and name != "pincal" and not public:
            continue  # a subpackage's docstring
        assert exported is not None or not public, f"{name} binds {sorted(public)} but declares no __all__"
        lazy = {n for names in _lazy_exports().values() for n in names} if name == "pincal" else set()
        missing = set(exported or ()) - defined - imported - lazy
        assert not missing, f"{name}'s __all__ lists names it does not bind: {sorted(missing)}"


def test_rooms_import_only_public_names():
    """Across rooms, a module imports only what the defining module lists in ``__all__`` (a room's
    modules may share the rest among themselves). The lazy exports of ``pincal`` count as imports."""
    assert private_imports(MODULES) == []
    lazy = [(module, name) for module, names in _lazy_exports().items() for name in names]
    assert [(m, n) for m, n in lazy if n not in (declared_all(MODULES[m]) or [])] == []


def test_the_public_name_check_catches_a_private_import(tmp_path):
    """Importing a room's underscore helper, or a name a module only imported, from another room fails."""
    planted = tmp_path / "planner.py"
    planted.write_text("from pincal.fit.solver import _cost_summary\nfrom pincal.fit.solver import np\n"
                       "from pincal.planning.design import QUADRATURE\n", encoding="utf-8")
    bad = private_imports({"pincal.planning.planner": planted})
    assert len(bad) == 2 and all("pincal.fit.solver" in line for line in bad)


def private_attributes_by_room(modules: dict[str, Path]) -> dict[str, set[str]]:
    """The underscore attributes each room defines: ``self._x = …`` and methods or class attributes
    ``_x`` in its modules' classes (dunder names aside)."""
    out: dict[str, set[str]] = {}
    for name, path in modules.items():
        found = out.setdefault(room(name), set())
        for node in nodes(source(path), ast.ClassDef, ast.Attribute):
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        found.add(item.name)
                    elif isinstance(item, (ast.Assign, ast.AnnAssign)):
                        targets = item.targets if isinstance(item, ast.Assign) else [item.target]
                        found.update(t.id for t in targets if isinstance(t, ast.Name))
            elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and \
                    isinstance(node.value, ast.Name) and node.value.id == "self":
                found.add(node.attr)
    return {r: {n for n in names if n.startswith("_") and not n.startswith("__")} for r, names in out.items()}


def private_attribute_reads(modules: dict[str, Path], defined: dict[str, set[str]]) -> list[str]:
    """Reads ``x._name`` (x not ``self`` or ``cls``) of an underscore attribute that only other rooms define:
    another layer's internals, reached through an object instead of an import."""
    bad = []
    for name, path in modules.items():
        own = defined.get(room(name), set())
        elsewhere = set().union(*(names for r, names in defined.items() if r != room(name)))
        for node in nodes(source(path), ast.Attribute):
            if isinstance(node, ast.Attribute) and node.attr in elsewhere - own and not (
                    isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                bad.append(f"{name}:{node.lineno} reads {node.attr}, private to another room")
    return bad


def test_no_module_reads_another_rooms_private_attributes():
    """Across rooms only public names are used: imports (above) and attributes read off objects alike."""
    assert private_attribute_reads(MODULES, private_attributes_by_room(MODULES)) == []


def test_the_private_attribute_check_catches_a_read(tmp_path):
    planted = tmp_path / "verdicts.py"
    planted.write_text("def f(objective):\n    return objective._hidden_slices[-1]\n", encoding="utf-8")
    defined = {"residuals": {"_hidden_slices"}, "diagnosis": set()}
    bad = private_attribute_reads({"pincal.diagnosis.verdicts": planted}, defined)
    assert len(bad) == 1 and "_hidden_slices" in bad[0]
    assert private_attribute_reads({"pincal.residuals.sensor": planted}, defined) == []  # its own room's


#: Calls that change a chain in place (pincal.model.chain.KinematicChain).
CHAIN_MUTATORS = ("set_placements", "set_tool")
#: Pieces of an assignment target that write into a chain's Pinocchio model or its tool.
CHAIN_STATE = ("jointPlacements", ".frames[", "._tool")


def chain_mutations(text: str, label: str) -> list[str]:
    """Statements in the source ``text`` that change a chain in place: a call of
    :data:`CHAIN_MUTATORS`, ``.apply(…)`` on a parameter set (a receiver whose source names
    ``param``), and an assignment into :data:`CHAIN_STATE`; in the order of the source."""
    found: list[tuple[int, str]] = []
    for node in nodes(text, ast.Call, ast.Assign, ast.AugAssign, ast.AnnAssign):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            name = node.func.attr
            if name in CHAIN_MUTATORS or (name == "apply" and "param" in ast.unparse(node.func.value).lower()):
                found.append((node.lineno, f"{label}:{node.lineno}: {ast.unparse(node.func)}(...)"))
        elif isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            found += [(node.lineno, f"{label}:{node.lineno}: {ast.unparse(t)} = ...") for t in targets
                      if any(piece in ast.unparse(t) for piece in CHAIN_STATE)]
    return [line for _, line in sorted(found)]


def test_only_the_model_changes_a_chain():
    """Values, not a shared mutable chain: outside ``pincal/model/`` a chain is
    evaluated with another model, tool or parameter vector only inside ``chain.placed(...)``."""
    outside = {name: path for name, path in MODULES.items() if room(name) != "model"}
    found = [line for name, path in outside.items() for line in chain_mutations(path.read_text(encoding="utf-8"), name)]
    assert not found, ("evaluate a model with `with chain.placed(placements, tool=...):` instead of changing "
                       "the chain:\n" + "\n".join(found))
    assert {room(name) for name in outside} >= {"cli", "workflows", "report", "diagnosis", "fit", "paper", "simulation",
                                                "study"}


def test_the_chain_check_catches_each_mutation():
    """Not vacuous: each kind of change it guards is found, a registration's ``apply`` is not."""
    text = ("def f(chain, params, result, registration):\n    chain.set_placements(x)\n    chain.set_tool(t)\n"
            "    result.params.apply(v)\n    registration.apply(p)\n"
            "    chain.model.jointPlacements[3] = s\n    chain.model.frames[chain.tip_frame_id].placement = s\n"
            "    chain._tool = t\n")
    found = [line.split(": ", 1)[1] for line in chain_mutations(text, "sample.py")]
    assert found == ["chain.set_placements(...)", "chain.set_tool(...)", "result.params.apply(...)",
                     "chain.model.jointPlacements[3] = ...", "chain.model.frames[chain.tip_frame_id].placement = ...",
                     "chain._tool = ..."]


#: The fit problems and the model the diagnosis grows (module, class): values, frozen dataclasses.
PROBLEM_CLASSES = (("pincal.fit.chain_calibration", "FitProblem"), ("pincal.fit.fixture_calibration", "FixtureProblem"),
                   ("pincal.diagnosis.effect_fits", "EffectModel"))
#: Where a problem's attribute may be set: its constructor.
CONSTRUCTORS = ("__init__", "__post_init__")


def problem_fields() -> set[str]:
    """Every attribute a problem of :data:`PROBLEM_CLASSES` holds (its dataclass fields)."""
    return {f.name for module, name in PROBLEM_CLASSES
            for f in dataclasses.fields(getattr(importlib.import_module(module), name))}


def problem_assignments(text: str, label: str, fields: set[str]) -> list[str]:
    """Statements in the source ``text`` that set an attribute named in ``fields`` after construction:
    an assignment to it on anything but ``self`` (``problem.prior = ...``, ``a, problem.sigma_pos = ...``,
    ``problem.noise += ...``) or a ``setattr(problem, "prior", ...)`` (not on a module's ``_UPPER_CASE``
    holder); and on ``self`` too in a method of a :data:`PROBLEM_CLASSES` class other than its constructor
    (:data:`CONSTRUCTORS`); in the order of the source."""
    classes = {name for _, name in PROBLEM_CLASSES}
    method_of: dict[int, str] = {}  # node → the problem class's method it is in
    for node in nodes(text, ast.ClassDef):
        if isinstance(node, ast.ClassDef) and node.name in classes:
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    method_of.update({id(inner): item.name for inner in ast.walk(item)})
    found: list[tuple[int, str]] = []
    for node in nodes(text, ast.Assign, ast.AugAssign, ast.AnnAssign, ast.Call):
        setting: list[tuple[str, str]] = []  # (owner, attribute)
        if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign)):
            pending = list(node.targets) if isinstance(node, ast.Assign) else [node.target]
            while pending:
                target = pending.pop()
                if isinstance(target, (ast.Tuple, ast.List)):
                    pending += target.elts
                elif isinstance(target, ast.Starred):
                    pending.append(target.value)
                elif isinstance(target, ast.Attribute):
                    setting.append((ast.unparse(target.value), target.attr))
        elif (isinstance(node, ast.Call) and ast.unparse(node.func) in ("setattr", "object.__setattr__")
              and len(node.args) > 1 and isinstance(node.args[1], ast.Constant)):
            setting.append((ast.unparse(node.args[0]), str(node.args[1].value)))
        for owner, attribute in setting:
            method = method_of.get(id(node))
            constructing = owner == "self" and (method is None or method in CONSTRUCTORS)
            module_state = owner.lstrip("_").isupper()  # a module's own holder (a threading.local), never a problem
            if attribute in fields and not constructing and not module_state:
                found.append((node.lineno, f"{label}:{node.lineno}: {owner}.{attribute} = ..."))
    return [line for _, line in sorted(found)]


def test_problems_are_values():
    """A fit problem is a value: everything it needs is given at construction and a variant is a new problem
    (``with_prior``, ``with_scales``, ``rescaled``, ``dataclasses.replace``); no attribute of a problem is set,
    swapped or restored after its constructor, anywhere in pincal (their ``models`` caches are shared dicts:
    filling one is not setting an attribute)."""
    for module, name in PROBLEM_CLASSES:
        cls = getattr(importlib.import_module(module), name)
        assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen, f"{module}.{name} is not frozen"
    fields = problem_fields()
    found = [line for name, path in MODULES.items()
             for line in problem_assignments(path.read_text(encoding="utf-8"), name, fields)]
    assert not found, ("derive a new problem (problem.with_prior(...), dataclasses.replace(problem, ...)) and pass "
                       "it on instead of setting an attribute of one:\n" + "\n".join(found))


def test_the_problem_check_catches_each_assignment():
    """Not vacuous: each way of setting a problem's attribute is found; a constructor's, another class's
    ``self`` and a local name are not."""
    text = ("class FitProblem:\n    def __post_init__(self):\n        object.__setattr__(self, 'sessions', 1)\n"
            "        self.prior = None\n    def rescale(self, s):\n        self.sigma_pos = s\n"
            "class Other:\n    def __init__(self):\n        self.prior = 1\n"
            "def f(problem, model, prior):\n    prior, problem.prior = problem.prior, None\n"
            "    problem.point_basis = b\n    model.sigma_pos, model.sigma_rot = scales\n    problem.noise += 1\n"
            "    setattr(problem, 'registration_basis', b)\n    prior = 2\n")
    fields = {"prior", "point_basis", "registration_basis", "sigma_pos", "sigma_rot", "noise", "sessions"}
    found = [line.split(": ", 1)[1] for line in problem_assignments(text, "sample.py", fields)]
    assert found == ["self.sigma_pos = ...", "problem.prior = ...", "problem.point_basis = ...",
                     "model.sigma_pos = ...", "model.sigma_rot = ...", "problem.noise = ...",
                     "problem.registration_basis = ..."]


def test_level_literals_agree():
    """The command levels extend the any-chain levels, in the same order (each a Literal type)."""
    from pincal.model.parameter_sets import CHAIN_LEVELS, LEVELS
    from pincal.workflows.settings import CALIBRATE_LEVELS, DIAGNOSE_LEVELS

    assert CHAIN_LEVELS == ("registration", *LEVELS)
    assert CALIBRATE_LEVELS == (*CHAIN_LEVELS, "auto", "dh")
    assert DIAGNOSE_LEVELS == (*CHAIN_LEVELS, "auto")
