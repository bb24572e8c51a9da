"""Outputs survive faults: every file pincal writes is replaced atomically.

Unit tests of :mod:`pincal.outputs`, a scan that no module of pincal writes a
file around it, and kill tests: ``pincal calibrate`` and ``pincal study`` run in
processes of their own (forked by a launcher that loaded pincal once, :data:`LAUNCHER`)
and are SIGKILLed at seeded random moments; after every kill each
output present must be whole (it parses and has the structure of a complete
run's file) and every other file must be a temporary one that no output name
or pattern can match. When the kill lands is machine dependent; what is
asserted is not: it holds whatever the moment.
"""

from __future__ import annotations

import ast
import csv
import json
import os
import select
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import package_files
from lxml import etree
from sources import nodes, parsed

from pincal import outputs
from pincal.cli.commands import main
from pincal.errors import MeasurementError
from pincal.outputs import TEMP_SUFFIX, is_temporary, replacing, write_bytes, write_text
from pincal.study.checkpoints import CHECKPOINT_FOLDER

PACKAGE = Path(__file__).resolve().parents[1] / "pincal"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # empty IEND chunk with its CRC
OUTPUT_SUFFIXES = (".urdf", ".json", ".csv", ".md", ".png")
#: A safety net against a hung subprocess, never an assertion about speed.
HANG_S = 300.0
#: The environment of pincal's processes: one BLAS thread (as ``main`` sets it), figures without a display.
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}


# --- the writer ----------------------------------------------------------------

def test_write_text_and_bytes_replace_the_file_and_leave_nothing_else(tmp_path):
    target = tmp_path / "REPORT.json"
    write_text(target, "old\n")
    write_text(target, "new ü\n")
    assert target.read_text(encoding="utf-8") == "new ü\n"
    write_bytes(tmp_path / "fig.png", PNG_SIGNATURE + PNG_END)
    assert (tmp_path / "fig.png").read_bytes() == PNG_SIGNATURE + PNG_END
    assert sorted(os.listdir(tmp_path)) == ["REPORT.json", "fig.png"]


class Boom(Exception):
    pass


def _fail_in_block(path: Path) -> None:
    with replacing(path, "w") as handle:
        handle.write("half of the new ")
        handle.flush()
        raise Boom


def _interrupt_in_block(path: Path) -> None:
    with replacing(path, "wb") as handle:
        handle.write(b"half")
        raise KeyboardInterrupt


def _unencodable(path: Path) -> None:
    write_text(path, "ok so far \udcff", encoding="utf-8")


@pytest.mark.parametrize("fail, kind", [(_fail_in_block, Boom), (_interrupt_in_block, KeyboardInterrupt),
                                        (_unencodable, UnicodeEncodeError)])
def test_a_failing_write_keeps_the_old_file_and_removes_its_temporary(tmp_path, fail, kind):
    target = tmp_path / "study.csv"
    target.write_text("a,b\n1,2\n", encoding="utf-8")
    with pytest.raises(kind):
        fail(target)
    assert target.read_text(encoding="utf-8") == "a,b\n1,2\n"
    assert os.listdir(tmp_path) == ["study.csv"]


def test_a_failing_first_write_leaves_no_file(tmp_path):
    with pytest.raises(Boom):
        _fail_in_block(tmp_path / "new.csv")
    assert os.listdir(tmp_path) == []


def test_data_reach_the_disk_before_the_rename(tmp_path, monkeypatch):
    calls = []
    fsync, rename = os.fsync, os.replace
    monkeypatch.setattr(outputs.os, "fsync", lambda fd: (calls.append("fsync"), fsync(fd))[1])
    monkeypatch.setattr(outputs.os, "replace", lambda a, b: (calls.append("replace"), rename(a, b))[1])
    write_text(tmp_path / "a.json", "{}\n")
    assert calls[:2] == ["fsync", "replace"]  # then the folder's fsync, where the platform allows


def test_temporary_file_is_a_hidden_sibling_no_output_pattern_matches(tmp_path):
    target = tmp_path / "summary.csv"
    target.write_text("old\n", encoding="utf-8")
    with replacing(target, "w") as handle:
        handle.write("new\n")
        handle.flush()
        others = [name for name in os.listdir(tmp_path) if name != "summary.csv"]
        assert len(others) == 1
        temporary = others[0]
        assert target.read_text(encoding="utf-8") == "old\n"  # not replaced before the block ends
        assert list(tmp_path.glob("*.csv")) == [target]
    assert temporary.startswith(".summary.csv.") and temporary.endswith(TEMP_SUFFIX)
    assert is_temporary(temporary) and not is_temporary("summary.csv")
    assert target.read_text(encoding="utf-8") == "new\n" and os.listdir(tmp_path) == ["summary.csv"]


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_permissions_are_those_of_a_plain_open(tmp_path):
    plain = tmp_path / "plain.txt"
    with open(plain, "w", encoding="utf-8") as handle:
        handle.write("x")
    write_text(tmp_path / "new.txt", "x")
    assert stat.S_IMODE(os.stat(tmp_path / "new.txt").st_mode) == stat.S_IMODE(os.stat(plain).st_mode)
    kept = tmp_path / "kept.txt"
    kept.write_text("old", encoding="utf-8")
    os.chmod(kept, 0o640)
    write_text(kept, "new")
    assert stat.S_IMODE(os.stat(kept).st_mode) == 0o640


@pytest.mark.skipif(os.name != "posix", reason="symbolic links")
def test_writing_through_a_symlink_replaces_its_target(tmp_path):
    real = tmp_path / "real.json"
    real.write_text("old", encoding="utf-8")
    link = tmp_path / "link.json"
    link.symlink_to(real)
    write_text(link, "new")
    assert link.is_symlink() and real.read_text(encoding="utf-8") == "new"


def test_missing_folder_and_bad_mode_are_refused(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_text(tmp_path / "absent" / "x.json", "{}")
    with pytest.raises(ValueError, match="mode"), replacing(tmp_path / "x.csv", "a"):
        pass
    assert os.listdir(tmp_path) == []


def test_a_failed_check_keeps_the_old_file(tmp_path):
    """``verify`` sees the whole new file before the rename; what it raises cancels the write."""
    target = tmp_path / "robot.urdf"
    target.write_text("old")
    seen = []

    def verify(written: Path) -> None:
        seen.append(written.read_text())
        raise ValueError("wrong kinematics")

    with pytest.raises(ValueError, match="wrong kinematics"):
        with replacing(target, verify=verify) as handle:
            handle.write("new")
    assert seen == ["new"] and target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.urdf"]


@pytest.mark.parametrize("where", ["open", "replace"])
def test_errors_name_the_destination_not_the_temporary(tmp_path, monkeypatch, where):
    """A user reads 'REPORT.json: Permission denied', never the hidden temporary's name."""
    target = tmp_path / "REPORT.json"

    def refuse(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", os.fspath(path))

    monkeypatch.setattr(outputs.os, where, refuse)
    with pytest.raises(PermissionError) as info:
        write_text(target, "{}")
    assert info.value.filename == str(target) and not is_temporary(info.value.filename)


def test_csv_writer_keeps_its_error_kind(tmp_path, noisy_large_experiment):
    from pincal.measurements.csv_v1 import write_measurements

    data = noisy_large_experiment.validation
    with pytest.raises(MeasurementError, match="cannot write"):
        write_measurements(tmp_path / "absent" / "v.csv", data)
    write_measurements(tmp_path / "v.csv", data)
    lines = (tmp_path / "v.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith(",".join(data.joint_names)) and len(lines) == data.n_rows + 1
    assert os.listdir(tmp_path) == ["v.csv"]


# --- no write around the writer --------------------------------------------------

_SAVERS = {"savefig", "savetxt", "save", "tofile", "to_csv", "dump"}
#: In-memory files: a saver writing into one writes no file.
_MEMORY_FILES = {"BytesIO", "StringIO"}
#: pincal's own classes whose saving methods write through pincal.outputs (checked by
#: test_atomic_savers_write_through_outputs): a call on a receiver annotated with one is atomic.
ATOMIC_SAVERS = {"TaskStore": ("pincal/study/checkpoints.py", {"save"})}


def _called(func: ast.expr) -> str:
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""


def _inside(source: str, context: str) -> set[int]:
    """ids of the nodes in the body of every ``with context(...)`` of ``source``."""
    return {
        id(sub)
        for node in nodes(source, ast.With)
        if isinstance(node, ast.With)
        and any(isinstance(i.context_expr, ast.Call) and _called(i.context_expr.func) == context for i in node.items)
        for child in node.body
        for sub in ast.walk(child)
    }


_FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)
#: Annotation names that only wrap the class that matters (``Optional[TaskStore]``).
_WRAPPERS = {"Optional", "Union"}


def _scopes(source: str):
    """The module and every function, each as (scope, the nodes of its own body, not of nested functions)."""
    for scope in [parsed(source), *nodes(source, *_FUNCTIONS)]:
        own, stack = [], list(ast.iter_child_nodes(scope))
        while stack:
            node = stack.pop()
            own.append(node)
            if not isinstance(node, _FUNCTIONS):
                stack.extend(ast.iter_child_nodes(node))
        yield scope, own


def _in_memory(source: str) -> set[int]:
    """ids of saver calls whose target is a name bound, in the same scope, only to ``io.BytesIO()`` / ``StringIO()``."""
    found = set()
    for _, own in _scopes(source):
        bound: dict[str, bool] = {}  # name -> every binding in the scope is an in-memory file
        for node in own:
            if isinstance(node, ast.Assign):
                memory = isinstance(node.value, ast.Call) and _called(node.value.func) in _MEMORY_FILES
                for target in node.targets:
                    for name in ast.walk(target):
                        if isinstance(name, ast.Name):
                            bound[name.id] = bound.get(name.id, True) and memory and isinstance(target, ast.Name)
            elif isinstance(node, (ast.AnnAssign, ast.AugAssign, ast.For, ast.With, ast.NamedExpr, ast.arg)):
                targets = [node.arg] if isinstance(node, ast.arg) else [
                    n.id for n in ast.walk(getattr(node, "target", None) or node)
                    if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)]
                bound.update({name: False for name in targets})
        memory_names = {name for name, memory in bound.items() if memory}
        for node in own:
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _SAVERS:
                target = node.args[0] if node.args else next((k.value for k in node.keywords if k.arg == "fname"), None)
                if isinstance(target, ast.Name) and target.id in memory_names:
                    found.add(id(node))
    return found


def _annotation_names(annotation: ast.expr) -> set[str]:
    if isinstance(annotation, ast.Constant) and isinstance(annotation.value, str):  # a string annotation
        annotation = ast.parse(annotation.value, mode="eval")
    return {n.id for n in ast.walk(annotation) if isinstance(n, ast.Name)} - _WRAPPERS


def _scope_types(scope: ast.AST, own: list) -> dict[str, set[str]]:
    """Receivers of one scope (``store``, ``self.store``) and the classes their annotations name:
    its annotated arguments and assignments, and what is assigned one of those (``self.store = store``)."""
    types: dict[str, set[str]] = {}
    arguments = scope.args.args + scope.args.kwonlyargs + scope.args.posonlyargs if isinstance(
        scope, _FUNCTIONS) else []
    for arg in arguments:
        types[arg.arg] = _annotation_names(arg.annotation) if arg.annotation is not None else {"?"}
    for node in own:
        if isinstance(node, ast.AnnAssign):
            types.setdefault(ast.unparse(node.target), set()).update(_annotation_names(node.annotation))
    for node in own:
        if isinstance(node, ast.Assign):
            for target in node.targets:
                pairs = (zip(target.elts, node.value.elts) if isinstance(target, ast.Tuple)
                         and isinstance(node.value, ast.Tuple) else [(target, node.value)])
                for left, right in pairs:
                    known = types.get(right.id) if isinstance(right, ast.Name) else None
                    types.setdefault(ast.unparse(left), set()).update(known or {"?"})  # "?": not known
    return types


def _atomic_calls(source: str) -> set[int]:
    """ids of calls of an :data:`ATOMIC_SAVERS` method on a receiver every binding of which,
    in its scope (``self.X``: in its class), is annotated with that method's class."""
    attributes: dict[int, dict[str, set[str]]] = {}  # method -> the ``self.X`` of its class
    scopes = list(_scopes(source))
    for cls in nodes(source, ast.ClassDef):
        methods = [n for n in cls.body if isinstance(n, _FUNCTIONS)]
        merged: dict[str, set[str]] = {}
        for scope, own in scopes:
            if scope in methods:
                for key, names in _scope_types(scope, own).items():
                    if key.startswith("self."):
                        merged.setdefault(key, set()).update(names)
        attributes.update({id(m): merged for m in methods})
    found = set()
    for scope, own in scopes:
        types = {**attributes.get(id(scope), {}), **_scope_types(scope, own)}
        for node in own:
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                names = types.get(ast.unparse(node.func.value), set())
                if names and all(c in ATOMIC_SAVERS and node.func.attr in ATOMIC_SAVERS[c][1] for c in names):
                    found.add(id(node))
    return found


def raw_writes(source: str, filename: str) -> list[str]:
    """Calls in ``source`` that write a file without :mod:`pincal.outputs`.

    A saver given the file object of ``with replacing(...)`` is atomic; anything
    written in ``with tempfile.TemporaryDirectory()`` is a scratch file deleted
    with it, never an output; a saver whose target is a name bound only to an
    ``io.BytesIO()`` in its scope writes no file; a method of :data:`ATOMIC_SAVERS`
    called on a receiver annotated with its class writes through :mod:`pincal.outputs`.
    """
    calls = nodes(source, ast.Call)  # the module parsed and walked once per process (tests/sources.py)
    if not calls:
        return []
    scratch = _inside(source, "TemporaryDirectory")
    guarded = None  # what writes atomically: worked out only for a module that calls a saver (most call none)
    bad = []
    for node in calls:
        if id(node) in scratch:
            continue
        name, where = _called(node.func), f"{filename}:{node.lineno}"
        method = isinstance(node.func, ast.Attribute) and not (
            isinstance(node.func.value, ast.Name) and node.func.value.id == "outputs")
        mode = node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"), None)
        if method and name in ("write_text", "write_bytes"):
            bad.append(f"{where}: Path.{name}")
        elif name == "open" and isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
            bad.append(f"{where}: open(..., {mode.value!r})")
        elif ((method and name in _SAVERS)  # lxml's tree.write(path, xml_declaration=...) too
              or (name == "write" and any(k.arg in ("xml_declaration", "pretty_print") for k in node.keywords))):
            if guarded is None:
                guarded = _inside(source, "replacing") | _in_memory(source) | _atomic_calls(source)
            if id(node) not in guarded:
                bad.append(f"{where}: {name} outside `with replacing(...)`")
    return bad


def test_every_write_of_pincal_goes_through_outputs():
    found = []
    for path in package_files():
        if path.name != "outputs.py":
            found += raw_writes(path.read_text(encoding="utf-8"), str(path.relative_to(PACKAGE.parent)))
    assert found == []


def test_the_scan_catches_what_it_guards():
    planted = (
        "Path(p).write_text(t)\n"
        "open(p, 'w')\n"
        "open(p, mode='ab')\n"
        "fig.savefig(p, dpi=1)\n"
        "tree.write(p, xml_declaration=True)\n"
        "json.dump(d, handle)\n"
    )
    assert len(raw_writes(planted, "planted")) == 6
    allowed = (
        "write_text(p, t)\n"
        "open(p, newline='')\n"
        "with replacing(p, 'wb') as h:\n"
        "    fig.savefig(h, format='png')\n"
        "    tree.write(h, xml_declaration=True)\n"
        "with tempfile.TemporaryDirectory() as tmp:\n"
        "    tree.write(tmp + '/scratch.urdf', xml_declaration=True)\n"
        "    open(tmp + '/scratch.txt', 'w')\n"
    )
    assert raw_writes(allowed, "allowed") == []


def test_the_scan_tells_memory_files_and_atomic_savers_from_files():
    allowed = (
        "def svg(fig):\n"
        "    buffer = io.BytesIO()\n"
        "    fig.savefig(buffer, format='svg')\n"
        "class Results:\n"
        "    def __init__(self, store: TaskStore | None):\n"
        "        self.tasks, self.store = [], store\n"
        "    def add(self, task, rows):\n"
        "        self.store.save(task, rows)\n"
        "def keep(store: 'TaskStore', task):\n"
        "    store.save(task, [])\n"
    )
    assert raw_writes(allowed, "allowed") == []
    planted = (
        "def svg(fig, path):\n"
        "    buffer = io.BytesIO()\n"
        "    fig.savefig(path, format='svg')\n"  # a path, though a buffer is at hand
        "def other(fig):\n"
        "    fig.savefig(buffer)\n"  # the buffer of another function's scope
        "def rebound(fig, path):\n"
        "    buffer = io.BytesIO()\n"
        "    buffer = path\n"
        "    fig.savefig(buffer)\n"  # a name once bound to a file path
        "def untyped(store, task):\n"
        "    store.save(task, [])\n"  # not known to be a TaskStore
        "def other_type(store: Path, task):\n"
        "    store.save(task)\n"
        "def also_open(store: TaskStore, path):\n"
        "    open(path, 'w')\n"  # a raw write beside an atomic saver is still caught
    )
    assert [line.split(": ", 1)[0] for line in raw_writes(planted, "planted")] == [
        "planted:3", "planted:5", "planted:9", "planted:11", "planted:13", "planted:15"]


def test_atomic_savers_write_through_outputs():
    """Each :data:`ATOMIC_SAVERS` method writes only through pincal.outputs (so allowing calls of it is sound)."""
    for cls, (path, methods) in ATOMIC_SAVERS.items():
        tree = ast.parse((PACKAGE.parent / path).read_text(encoding="utf-8"))
        imported = {alias.asname or alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                    and node.module == "pincal.outputs" for alias in node.names}
        (body,) = [n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == cls]
        for method in methods:
            (function,) = [n for n in body.body if isinstance(n, ast.FunctionDef) and n.name == method]
            calls = {_called(n.func) for n in ast.walk(function) if isinstance(n, ast.Call)}
            assert calls & imported & {"write_text", "write_bytes", "replacing"}, f"{cls}.{method}"
            assert raw_writes(ast.unparse(function), f"{cls}.{method}") == []


# --- kill tests --------------------------------------------------------------------

def _snapshot(folder: Path) -> dict[str, tuple[int, int, int]]:
    found = {}
    for entry in os.scandir(folder):
        if entry.name == CHECKPOINT_FOLDER:  # a running study's finished tasks, not an output
            continue
        try:
            info = entry.stat()
        except FileNotFoundError:  # a temporary file renamed away meanwhile
            continue
        found[entry.name] = (info.st_ino, info.st_mtime_ns, info.st_size)
    return found


#: A kill round's launcher: a clean ``python -c`` process (started by the test, so it has none of pytest's
#: threads) that runs the round's SETUP (argv[1]) once, then, per line ``[ARGV, CWD]`` read on stdin, forks a
#: child that runs ``main(ARGV)`` in CWD with stdout to /dev/null and stderr to ``CWD/stderr.log``, as ``pincal
#: ARGV`` run there would, and ends with ``os._exit``; it replies the child's pid, then its exit code as
#: :attr:`subprocess.Popen.returncode` gives it (-9: SIGKILLed). A run then costs its own work: a fresh ``python
#: -m pincal calibrate`` of the round spends ~1.5 s of a core, ~0.2 s of it on the fit and the writes that the
#: kills aim at, the rest importing numpy, scipy, Pinocchio and pincal. The launcher forks only while it
#: has one thread (a lock or a thread's state copied half-way would make the child another program), and it
#: keeps each child a zombie until the next line, so a SIGKILL sent after the child ended reaches no other process.
LAUNCHER = ("-c", r"""
import json, os, sys, threading, traceback

replies = os.fdopen(os.dup(1), "w", buffering=1)  # the protocol's channel; what the setup prints goes to the log
os.dup2(2, 1)
exec(sys.argv[1])
from pincal.cli.commands import main


def threads():
    return len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else threading.active_count()


def run(argv, cwd):
    code = 1
    try:
        replies.close()
        os.chdir(cwd)
        null, log = os.open(os.devnull, os.O_RDWR), os.open("stderr.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(null, 0)
        os.dup2(null, 1)
        os.dup2(log, 2)
        code = main(argv)
    except SystemExit as stop:  # as the interpreter exits: None is 0, another non-integer 1
        code = 0 if stop.code is None else stop.code if isinstance(stop.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else 1)  # never back into the launcher's loop


replies.write("ready\n")
pid = None
for line in sys.stdin:
    if pid is not None:
        os.waitpid(pid, 0)
    argv, cwd = json.loads(line)
    assert threads() == 1, f"{threads()} threads in the launcher: no fork"
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        run(argv, cwd)
    replies.write(f"{pid}\n")
    ended = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)  # reaped at the next line
    replies.write(f"{-ended.si_status if ended.si_code in (os.CLD_KILLED, os.CLD_DUMPED) else ended.si_status}\n")
if pid is not None:
    os.waitpid(pid, 0)
""")
#: What ``pincal calibrate`` loads once its arguments are valid: loaded by the launcher, not by each run.
CALIBRATE_SETUP = "import pincal.cli.progress, pincal.paper.methods, pincal.workflows.calibration"
#: ``pincal study`` whose figures are small ones written through the study's own writer
#: (:func:`pincal.study.figures._save`), each held open 0.2 s as a real figure's rendering holds it: the same
#: files written the same way, at less than half a run's CPU (the seven real figures take ~2.5 s of a core, and
#: tests/test_study_processes.py and tests/test_study.py draw them); with what the study loads.
QUICK_FIGURES = """
import time
import matplotlib.backends.backend_agg
import matplotlib.pyplot as plt
import pincal.cli.progress, pincal.study.run
from pincal.study import figures

def quick(result, path):
    fig = plt.figure(figsize=(1, 1))
    render = fig.savefig
    def slowly(*args, **kwargs):
        time.sleep(0.2)
        return render(*args, **kwargs)
    fig.savefig = slowly
    return figures._save(fig, path)

figures.FIGURES = {name: quick for name in figures.FIGURES}
"""


class Launcher:
    """A started :data:`LAUNCHER` (its stderr to ``log``); :meth:`close` ends it and the run it forked last."""

    def __init__(self, setup: str, log: Path) -> None:
        self.log = log
        with open(log, "wb") as handle:  # a pipe nobody reads could block it
            self.proc = subprocess.Popen([sys.executable, *LAUNCHER, setup], env=ENV, stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, stderr=handle, bufsize=0)
        self.last: Run | None = None
        try:
            assert self.reply(HANG_S) == "ready", "the launcher did not start"
        except BaseException:
            self.close()
            raise

    def reply(self, timeout_s: float) -> str | None:
        """The launcher's next line, or None if none came within ``timeout_s``."""
        if not select.select([self.proc.stdout], [], [], timeout_s)[0]:
            return None
        line = self.proc.stdout.readline()
        assert line, f"the launcher ended: {self.log.read_text(encoding='utf-8', errors='replace')}"
        return line.decode().strip()

    def close(self) -> None:
        try:
            if self.last is not None and self.last.poll() is None:
                self.last.kill()
            self.proc.stdin.close()
            self.proc.wait(timeout=HANG_S)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self.proc.stdout.close()


class Run:
    """``pincal ARGV`` in ``cwd``, forked by ``launcher``: what a round uses of :class:`subprocess.Popen`."""

    def __init__(self, launcher: Launcher, argv: list[str], cwd: Path) -> None:
        self.launcher, self.returncode = launcher, None
        launcher.proc.stdin.write(f"{json.dumps([argv, str(cwd)])}\n".encode())
        pid = launcher.reply(HANG_S)
        assert pid is not None, "the launcher did not fork"
        self.pid = int(pid)
        launcher.last = self

    def wait(self, timeout: float = HANG_S) -> int:
        if self.returncode is None:
            code = self.launcher.reply(timeout)
            if code is None:
                raise subprocess.TimeoutExpired(f"pincal (pid {self.pid})", timeout)
            self.returncode = int(code)
        return self.returncode

    def poll(self) -> int | None:
        try:
            return self.wait(0.0)
        except subprocess.TimeoutExpired:
            return None

    def send_signal(self, signum: int) -> None:
        os.kill(self.pid, signum)  # the pid is this run's, a zombie once it ended, until the launcher's next run

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def _stderr(cwd: Path) -> str:
    return (cwd / "stderr.log").read_text(encoding="utf-8", errors="replace")


def _wait_for_first_write(proc: Run, folder: Path, before: dict) -> None:
    """Return once ``folder`` changes (a file created, renamed or grown) or ``proc`` has exited."""
    deadline = time.monotonic() + HANG_S
    while proc.poll() is None and _snapshot(folder) == before:
        assert time.monotonic() < deadline, "the command neither wrote nor exited"
        time.sleep(0.002)


def _reference_run(argv: list[str], cwd: Path, folder: Path, launcher: Launcher) -> tuple[float, float]:
    """Run to completion; return (seconds to the first write, seconds to the exit) to aim the kills."""
    before = _snapshot(folder)
    start = time.monotonic()
    proc = Run(launcher, argv, cwd)
    _wait_for_first_write(proc, folder, before)
    first = time.monotonic() - start
    proc.wait(timeout=HANG_S)
    assert proc.returncode == 0, _stderr(cwd)
    return first, time.monotonic() - start


def _killed_run(argv: list[str], cwd: Path, folder: Path, after_first_write: bool, delay_s: float,
                launcher: Launcher) -> tuple[int, bool]:
    """Kill ``pincal ARGV`` after ``delay_s`` (from its first write, or from its start); returns its exit
    code (-SIGKILL, or 0 if it finished first) and whether it had changed ``folder`` by then."""
    before = _snapshot(folder)
    proc = Run(launcher, argv, cwd)
    try:
        if after_first_write:
            _wait_for_first_write(proc, folder, before)
        time.sleep(delay_s)
        proc.send_signal(signal.SIGKILL)  # nothing happens if it has already finished
        proc.wait(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode in (0, -signal.SIGKILL), _stderr(cwd)
    return proc.returncode, _snapshot(folder) != before


def whole_file(path: Path) -> tuple:
    """The structure of a complete output; raises (or differs from a complete run's) if it is cut."""
    data = path.read_bytes()
    suffix = path.suffix
    if suffix == ".png":
        assert data.startswith(PNG_SIGNATURE) and data.endswith(PNG_END), "PNG without its IEND chunk"
        return ("png", data[16:24])  # width and height from IHDR
    text = data.decode("utf-8")
    assert text.endswith("\n"), "no final newline"
    if suffix == ".json":
        return ("json", tuple(json.loads(text)))
    if suffix == ".csv":
        rows = list(csv.reader(text.splitlines()))
        assert all(len(row) == len(rows[0]) for row in rows), "a row is cut"
        return ("csv", tuple(rows[0]), len(rows))
    if suffix == ".urdf":
        root = etree.fromstring(data)
        model = pin.buildModelFromUrdf(str(path))
        return ("urdf", root.get("name"), tuple(j.get("name") for j in root.iter("joint")), model.nq)
    if suffix == ".md":
        return ("md", len(text.splitlines()))
    raise AssertionError(f"unknown output {path.name}")


def _check_outputs(folder: Path, reference: dict[str, tuple], what: str) -> list[str]:
    """Every output present is whole; every other file is a temporary no output pattern matches."""
    leftovers = []
    for name in sorted(os.listdir(folder)):
        if name == CHECKPOINT_FOLDER:  # a killed study's finished tasks, for its rerun
            continue
        if is_temporary(name):
            assert not name.endswith(OUTPUT_SUFFIXES), f"{what}: temporary {name} looks like an output"
            leftovers.append(name)
            continue
        assert name in reference, f"{what}: unexpected file {name}"
        try:
            found = whole_file(folder / name)
        except Exception as exc:  # noqa: BLE001 - any failure to parse is the finding
            pytest.fail(f"{what}: {name} is not whole ({type(exc).__name__}: {exc})")
        assert found == reference[name], f"{what}: {name} is cut ({found} != {reference[name]})"
    return leftovers


def _kill_round(argv: list[str], cwd: Path, folder: Path, seed: int, in_writes: int, anywhere: int,
                setup: str) -> dict[str, tuple]:
    """Kill ``pincal ARGV`` ``in_writes`` times after its first write and ``anywhere`` times after its start
    (forked by a launcher that ran ``setup``); the structure of its complete outputs."""
    launcher = Launcher(setup, cwd / "launcher.log")
    try:
        return _aimed_kills(argv, cwd, folder, seed, in_writes, anywhere, launcher)
    finally:
        launcher.close()


def _aimed_kills(argv: list[str], cwd: Path, folder: Path, seed: int, in_writes: int, anywhere: int,
                 launcher: Launcher) -> dict[str, tuple]:
    first_write_s, total_s = _reference_run(argv, cwd, folder, launcher)
    reference = {name: whole_file(folder / name) for name in os.listdir(folder)}
    assert reference and not any(is_temporary(n) for n in reference)
    rng = np.random.default_rng(seed)
    kinds = rng.permutation([True] * in_writes + [False] * anywhere)
    write_span_s = max(total_s - first_write_s, 0.05)
    landed = 0
    for number, after_first_write in enumerate(kinds):
        delay = rng.uniform(0.0, 1.2 * write_span_s) if after_first_write else rng.uniform(0.0, total_s)
        what = f"kill {number} ({'after the first write + ' if after_first_write else 'after '}{delay:.3f} s)"
        code, wrote = _killed_run(argv, cwd, folder, bool(after_first_write), delay, launcher)
        landed += code == -signal.SIGKILL and wrote
        _check_outputs(folder, reference, what)
    # at least one kill cut a run that had begun writing (else the round tested only whole runs); kills aimed
    # at uniform moments of 1.2 write spans miss all together with probability (0.2/1.2)^in_writes (< 5e-3 at
    # 3), and the seeds below draw at least two of them within 0.6 of the span: those miss only if a run
    # writes over 1.6 times as fast as its reference run
    assert landed >= 1, f"no kill landed after a write began ({len(kinds)} tried)"
    return reference


#: The launcher forks after numpy, SciPy, Pinocchio and matplotlib are loaded: sound on Linux, not on macOS
#: (pincal.study.executors.fork_is_safe), where these rounds do not run.
ON_LINUX = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kill rounds fork their runs: Linux only")


@pytest.fixture(scope="module")
def simulated_kuka(tmp_path_factory):
    folder = tmp_path_factory.mktemp("kill")
    assert main(["simulate", "--out", str(folder / "sim"), "--deviations", "large",
                 "--sigma-pos", "0.055", "--sigma-rot", "0.055", "--seed", "1"]) == 0
    return folder


@ON_LINUX
def test_killed_calibrate_leaves_old_or_whole_outputs(simulated_kuka, kuka_urdf):
    out = simulated_kuka / "calibrated"
    out.mkdir()
    argv = ["calibrate", str(kuka_urdf), "sim/calibration.csv", "--method", "2",
            "--tool", "0.045,-0.043,0.118,0.12,-0.25,0.4", "--tool-parent", "lwr_flange",
            "--out", "calibrated/kuka_calibrated.urdf", "--report", "calibrated/REPORT.json"]
    reference = _kill_round(argv, simulated_kuka, out, seed=11_3, in_writes=4, anywhere=2, setup=CALIBRATE_SETUP)
    # the console script's own way in (python -m pincal: a fresh interpreter, console(), its exit) ends 0 and
    # replaces the outputs the forked runs left by the same whole files
    done = subprocess.run([sys.executable, "-m", "pincal", *argv], cwd=simulated_kuka, env=ENV, capture_output=True,
                          timeout=HANG_S)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    assert set(reference) <= set(os.listdir(out))
    _check_outputs(out, reference, "python -m pincal")


@ON_LINUX
def test_killed_study_leaves_old_or_whole_outputs(tmp_path):
    out = tmp_path / "study"
    out.mkdir()
    # no noise limit and no restart cases (--limit-pose-sets 0, --restarts 0): the same 12 files written, a
    # tenth less work for each run; three kills aimed inside the writes (each run costs the study's own work, ~1 s
    # of a core with QUICK_FIGURES, whose seven 0.2 s renderings keep the write span over a second)
    argv = ["study", "--reps", "1", "--levels", "2", "--restarts", "0", "--workers", "1", "--limit-pose-sets", "0",
            "--out", str(out)]
    _kill_round(argv, tmp_path, out, seed=11_3_2, in_writes=3, anywhere=1, setup=QUICK_FIGURES)
