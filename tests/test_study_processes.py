"""The study's serial tail and start-up: forked workers (same results, one BLAS thread, only when
safe), figures drawn by other processes (the same PNG bytes), checkpoints without fsync (a
truncated one only reruns its task), and a progress bar that starts no thread.

No test is timed: each checks where the work ran, what it wrote, or what the fork inherited.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import pincal.outputs as outputs
from pincal.cli.progress import progress_bar
from pincal.study.checkpoints import CHECKPOINT_FOLDER, TaskStore
from pincal.study.executors import execute, fork_is_safe

# The study itself and its figures (matplotlib: ~2 s of a core to import) are imported where a test draws them:
# every worker a test spawns imports this module afresh, and so does each test's own Python process.

#: Set by a test before its workers start: a forked worker sees the new value, a spawned one
#: (which imports this module afresh) the old one.
_PARENT_MARK = "imported"
_ON_LINUX = sys.platform.startswith("linux")


class _WhereAmI:
    """A task reporting the process that ran it, what it inherited, and its BLAS threads."""

    def __init__(self, number: int) -> None:
        self.number = number

    def __repr__(self) -> str:
        return f"_WhereAmI({self.number})"

    def run(self) -> list[dict]:
        pools = {api: sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == api})
                 for api in ("blas", "openmp")}
        return [{"number": self.number, "pid": os.getpid(), "mark": _PARENT_MARK, **pools}]


@pytest.fixture
def marked(monkeypatch):
    monkeypatch.setattr(f"{__name__}._PARENT_MARK", "set by the parent")


def _forked_rows(folder: str) -> dict:
    """What :func:`test_local_workers_are_forked_with_one_blas_thread` checks, run in a process of
    its own: threads other tests leave behind (a Dask client's) would make the pool spawn."""
    global _PARENT_MARK
    _PARENT_MARK = "set by the parent"
    store = TaskStore(Path(folder) / CHECKPOINT_FOLDER)
    # the parent's BLAS and OpenMP pools keep two threads, as a library caller's would: the forked
    # workers must still run with one, as spawned ones do (OPENBLAS_NUM_THREADS=1, OMP_NUM_THREADS=1)
    with threadpool_limits(limits=2):
        results, executor = execute([_WhereAmI(n) for n in range(4)], workers=2, store=store)
    return {"executor": executor, "rows": [rows[0] for rows in results], "pid": os.getpid(),
            "stored": len(list(store.folder.glob("*.json")))}


@pytest.mark.skipif(not _ON_LINUX, reason="workers are forked on Linux only")
@pytest.mark.parametrize("user_setting", [{}, {"MKL_NUM_THREADS": "1"}])
def test_local_workers_are_forked_with_one_blas_thread(tmp_path, user_setting):
    """Also when the user set one of the variables (here MKL's, which OpenBLAS ignores): the
    pools whose variables are unset still get one thread."""
    script = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
              f"import test_study_processes as t; print(json.dumps(t._forked_rows({str(tmp_path)!r})))")
    environment = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                                     "MKL_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env={**environment, **user_setting}, timeout=300, check=True)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    rows = out["rows"]
    assert out["executor"] == "2 local processes"
    assert [r["number"] for r in rows] == [0, 1, 2, 3]
    assert all(r["pid"] != out["pid"] for r in rows)
    assert {r["mark"] for r in rows} == {"set by the parent"}  # forked: the parent's state, no re-import
    assert {tuple(r["blas"]) for r in rows} <= {(1,), ()}, rows
    assert {tuple(r["openmp"]) for r in rows} <= {(1,), ()}, rows
    assert out["stored"] == 4


def test_workers_are_spawned_while_another_thread_runs(marked):
    """A fork copies only the calling thread: with another thread alive the workers start afresh."""
    safe_before = fork_is_safe()  # False if other tests left threads (a Dask client's)
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not fork_is_safe()
        results, _ = execute([_WhereAmI(n) for n in range(2)], workers=2)
    finally:
        stop.set()
        other.join()
    assert {rows[0]["mark"] for rows in results} == {"imported"}  # a fresh interpreter imported it
    assert fork_is_safe() == (_ON_LINUX and safe_before)  # safe again once that thread ended


def test_the_progress_bar_starts_no_thread():
    """tqdm's monitor thread would make every study spawn its workers (fork_is_safe)."""
    for interactive in (True, False):
        before = set(threading.enumerate())  # other tests may leave threads (a Dask client's)
        with progress_bar("study tasks", stream=io.StringIO(), interactive=interactive) as report:
            report(1, 2)  # tqdm starts its monitor when a bar is created
            assert set(threading.enumerate()) <= before


def test_checkpoints_skip_fsync_and_a_truncated_one_reruns_its_task(tmp_path, monkeypatch):
    synced = []
    monkeypatch.setattr(outputs.os, "fsync", lambda fd: synced.append(fd))
    store = TaskStore(tmp_path / CHECKPOINT_FOLDER)
    rows = [{"number": 1, "third": 1 / 3}]
    store.save(_WhereAmI(1), rows)
    assert synced == []  # a cache checked on reading: no fsync (~1-5 ms each, 875 per study)
    assert store.load(_WhereAmI(1)) == rows
    assert not any(outputs.is_temporary(p) for p in os.listdir(store.folder))  # renamed into place
    # what a machine crash may leave of a file renamed before its data reached the disk
    path = store.path(_WhereAmI(1))
    for cut in (b"", path.read_bytes()[:-3]):
        path.write_bytes(cut)
        assert store.load(_WhereAmI(1)) is None
    # every other output still reaches the disk before its rename
    outputs.write_text(tmp_path / "study.csv", "a\n")
    assert synced  # the file (and its folder, where the platform allows)


def _recording(name, draw):
    """``draw`` that also writes which process drew figure ``name``: ``NAME.pid`` beside it."""
    def wrapper(result, path):
        (path.parent / f"{name}.pid").write_text(str(os.getpid()))
        return draw(result, path)
    return wrapper


def _figures_twice(folder: str) -> dict:
    """A small study's figures drawn here (``here/``) and by forked processes (``forked/``, each figure's
    drawing process recorded), in a process of its own: no threads other tests left, so the fork is safe."""
    from pincal.study import figures
    from pincal.study.protocol import StudyConfig
    from pincal.study.run import run_study

    result = run_study(StudyConfig(deviations=("large",), levels=2, repeats=1, restarts=0, limit_pose_sets=0),
                       workers=1)  # small enough for seconds, its summary draws every figure (no noise limit)
    here = figures.write_figures(result, Path(folder) / "here", workers=1)
    figures.FIGURES = {name: _recording(name, draw) for name, draw in figures.FIGURES.items()}  # forked: inherited
    forked = figures.write_figures(result, Path(folder) / "forked", workers=2)
    return {"pid": os.getpid(), "fork_is_safe": fork_is_safe(), "here": [p.name for p in here],
            "forked": [p.name for p in forked]}


@pytest.mark.skipif(not _ON_LINUX, reason="figures are drawn by forked processes on Linux only")
def test_figures_drawn_by_forked_processes_are_the_same_bytes(tmp_path):
    """One drawing by this process's code path, one by forked processes (the study's tables are written
    meanwhile): the same PNG bytes, and none drawn by the process that forked them."""
    from pincal.study import figures

    script = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
              f"import test_study_processes as t; print(json.dumps(t._figures_twice({str(tmp_path)!r})))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=True)
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["here"] == out["forked"] == list(figures.FIGURES)
    for name in out["here"]:
        assert (tmp_path / "here" / name).read_bytes() == (tmp_path / "forked" / name).read_bytes(), name
    drawn_by = {int((tmp_path / "forked" / f"{name}.pid").read_text()) for name in out["forked"]}
    assert out["fork_is_safe"] and len(drawn_by) >= 1 and out["pid"] not in drawn_by
    assert sorted(figures._LONGEST_FIRST) == sorted(figures.FIGURES)
