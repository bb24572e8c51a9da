"""A study survives faults: a lost Dask worker loses nothing, and a study whose
scheduler dies — here the whole ``pincal study --scheduler local`` process, SIGKILLed — resumes from
the tasks it finished (:mod:`pincal.study.checkpoints`).

"Same study.csv" is checked byte for byte on every column but ``fit_ms``, the fit's wall time, which
differs from run to run whatever happens; restarts.csv has no timing and must be byte-identical.
Which task a kill interrupts depends on the machine; what is asserted does not.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import ClassVar

import dask
import distributed
import distributed.utils
import pytest

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.study.checkpoints import CHECKPOINT_FOLDER, TaskStore
from pincal.study.executors import execute
from pincal.study.run import StudyConfig, run_study, study_tasks, write_study

#: Small enough for seconds, big enough that tasks remain when the first ones finish:
#: 2 deviation sets x 2 levels x 2 repeats = 8 trials, 3 restart cases x 3 estimators, Figure 2 (18 tasks).
ARGUMENTS = ["--reps", "2", "--levels", "2", "--restarts", "2", "--limit-pose-sets", "0",
             "--scheduler", "local", "--workers", "2"]
CONFIG = StudyConfig(repeats=2, levels=2, restarts=2, limit_pose_sets=0)  # what the CLI makes of them
#: A safety net against a hung subprocess, never an assertion about speed.
HANG_S = 300.0


@pytest.fixture(autouse=True)
def _workers_from_a_forkserver(monkeypatch):
    """Dask's worker processes forked from a server process instead of each started afresh (Dask's default,
    ``spawn``: seconds of imports per worker, up to four workers a test). The server of this process has
    imported Dask and pincal's study tasks; the processes a test starts (``pincal study``, ``dask worker``)
    read the method from the environment and preload Dask's own list. How a worker process starts changes
    nothing these tests check: what a lost worker's tasks become, what a killed scheduler leaves behind."""
    method = "forkserver"
    monkeypatch.setenv("DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD", method)
    with dask.config.set({"distributed.worker.multiprocessing-method": method}):
        context = distributed.utils.get_mp_context()  # Dask sets its own preload on its first call
        context.set_forkserver_preload(["distributed", "pincal.study.tasks"])  # read when the server starts
        yield


def _without_fit_times(path: Path) -> bytes:
    """study.csv's bytes with the ``fit_ms`` column (a wall time) cut out."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    column = lines[0].rstrip("\n").split(",").index("fit_ms")
    kept = [",".join(c for i, c in enumerate(line.rstrip("\n").split(",")) if i != column) + "\n" for line in lines]
    return "".join(kept).encode("utf-8")


def _outputs(folder: Path) -> tuple[bytes, bytes]:
    return _without_fit_times(folder / "study.csv"), (folder / "restarts.csv").read_bytes()


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory) -> tuple[bytes, bytes]:
    """study.csv and restarts.csv of an undisturbed run (``pincal study`` ARGUMENTS, without figures), run in
    this process: every executor gives the same rows (tests/test_study.py), and a cluster costs seconds to start."""
    out = tmp_path_factory.mktemp("undisturbed")
    write_study(run_study(CONFIG, workers=1), out, figures=False)
    return _outputs(out)


def test_a_killed_worker_loses_nothing(undisturbed, tmp_path):
    """SIGKILL one of the LocalCluster's two worker processes while it runs a task: the nanny starts a
    new one, the scheduler reruns what was lost, and study.csv is the undisturbed run's."""
    killed: list[tuple[int, int]] = []  # (pid, tasks it was running)
    counts: list[int] = []

    def progress(done: int, total: int) -> None:
        counts.append(done)
        if not killed:  # tasks have started: one has finished, others run
            client = distributed.get_client()  # the client run_study started
            pids = client.run(os.getpid)
            busy = sorted((address, keys) for address, keys in client.processing().items() if keys)
            address, keys = busy[0]
            os.kill(pids[address], signal.SIGKILL)
            killed.append((pids[address], len(keys)))

    result = run_study(CONFIG, workers=2, scheduler="local", progress=progress)
    assert len(killed) == 1 and killed[0][1] >= 1, killed  # a worker died with a task in hand
    assert result.executor == "Dask LocalCluster (2 processes)"
    assert counts == list(range(1, len(study_tasks(CONFIG)) + 1))  # every task once
    write_study(result, tmp_path, figures=False)
    assert _outputs(tmp_path) == undisturbed


def test_a_study_killed_with_its_scheduler_resumes_to_the_same_files(undisturbed, tmp_path, monkeypatch, capsys):
    """SIGKILL the whole ``pincal study --scheduler local`` process group (the scheduler lives in the
    process) once it has finished a few tasks; the rerun reuses them and writes the same files."""
    out = tmp_path / "killed"
    out.mkdir()
    checkpoints = out / CHECKPOINT_FOLDER
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    with open(tmp_path / "stderr.log", "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "pincal", "study", *ARGUMENTS, "--out", str(out)],
                                env=env, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True)
    try:
        deadline = time.monotonic() + HANG_S
        while proc.poll() is None and len(list(checkpoints.glob("*.json"))) < 2:
            assert time.monotonic() < deadline, "the study neither finished a task nor exited"
            time.sleep(0.002)
        os.killpg(proc.pid, signal.SIGKILL)  # the study, its scheduler, nannies, forkserver and workers
        proc.wait(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    log_text = (tmp_path / "stderr.log").read_text(encoding="utf-8", errors="replace")
    assert proc.returncode == -signal.SIGKILL, f"finished before the kill: {log_text}"
    assert not (out / "study.csv").exists()
    kept = len(list(checkpoints.glob("*.json")))
    assert kept >= 2

    monkeypatch.setattr("pincal.study.figures.start_figures", lambda *args: lambda: [])  # seconds of drawing
    assert main(["study", *ARGUMENTS, "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert f"; {kept} of {len(study_tasks(CONFIG))} tasks resumed from an interrupted run" in printed, printed
    assert _outputs(out) == undisturbed
    assert not checkpoints.exists()  # removed once the files are written


def test_a_lost_remote_scheduler_stops_the_study_in_one_line_keeping_what_finished(tmp_path):
    """``--scheduler ADDRESS``: SIGKILL the scheduler (a ``dask scheduler`` process, with one ``dask worker``)
    once the study has finished a few tasks: exit 2, one line saying how to resume, the tasks kept."""
    scheduler_file = tmp_path / "scheduler.json"
    out = tmp_path / "remote"
    checkpoints = out / CHECKPOINT_FOLDER
    started: list[subprocess.Popen] = []

    def start(*argv: str, **options) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-m", *argv], start_new_session=True, **options)
        started.append(proc)
        return proc

    try:
        scheduler = start("distributed.cli.dask_scheduler", "--scheduler-file", str(scheduler_file), "--port", "0",
                          "--no-dashboard", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        start("distributed.cli.dask_worker", "--scheduler-file", str(scheduler_file), "--nworkers", "1",
              "--nthreads", "1", "--no-dashboard", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + HANG_S
        address = None
        while address is None:  # the scheduler writes its file in place: it may exist and be empty or partial
            assert time.monotonic() < deadline and scheduler.poll() is None, "the scheduler did not start"
            try:
                address = json.loads(scheduler_file.read_text(encoding="utf-8"))["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                time.sleep(0.01)
        arguments = [a if a != "local" else address for a in ARGUMENTS]
        # --quiet: a loaded machine takes over the progress interval (10 s) per task, and the bar's lines
        # would join the one error line on stderr
        study = start("pincal", "study", *arguments, "--quiet", "--out", str(out), stdout=subprocess.PIPE,
                      stderr=subprocess.PIPE, text=True)
        while study.poll() is None and len(list(checkpoints.glob("*.json"))) < 2:
            assert time.monotonic() < deadline, "the study neither finished a task nor exited"
            time.sleep(0.002)
        os.killpg(scheduler.pid, signal.SIGKILL)
        _, err = study.communicate(timeout=HANG_S)
    finally:
        for proc in started:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    kept = len(list(checkpoints.glob("*.json")))
    assert study.returncode == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("pincal: error: lost the Dask scheduler") and f"the {kept} finished are kept in" in err
    assert "rerun the same command to resume" in err and kept >= 2 and not (out / "study.csv").exists()


# --- the store and the executor, in process ------------------------------------------------


class _Task:
    """A picklable task whose rows record that it ran (``ran`` counts runs in this process)."""

    ran: ClassVar[list[int]] = []

    def __init__(self, number: int) -> None:
        self.number = number

    def __repr__(self) -> str:
        return f"_Task(number={self.number})"

    def run(self) -> list[dict]:
        _Task.ran.append(self.number)
        return [{"number": self.number, "third": self.number / 3.0, "nan": math.nan, "flag": True, "none": None}]


def test_the_store_gives_back_exactly_what_was_kept_and_only_for_the_same_task(tmp_path):
    store = TaskStore(tmp_path / CHECKPOINT_FOLDER)
    rows = _Task(7).run()
    assert store.load(_Task(7)) is None
    store.save(_Task(7), rows)
    back = store.load(_Task(7))
    assert repr(back[0]["third"]) == repr(rows[0]["third"]) and math.isnan(back[0]["nan"])
    assert {k: v for k, v in back[0].items() if k != "nan"} == {k: v for k, v in rows[0].items() if k != "nan"}
    assert store.load(_Task(8)) is None
    # a file that records another task (a hash collision, a hand-copied file) is not reused
    store.path(_Task(8)).write_text(store.path(_Task(7)).read_text(encoding="utf-8"), encoding="utf-8")
    assert store.load(_Task(8)) is None
    store.path(_Task(9)).write_text('{"task": "cut', encoding="utf-8")  # unreadable: run again
    assert store.load(_Task(9)) is None
    store.clear()
    assert not store.folder.exists()


def test_execute_runs_only_the_tasks_the_store_lacks_and_counts_the_rest_as_done(tmp_path):
    store = TaskStore(tmp_path / CHECKPOINT_FOLDER)
    tasks = [_Task(n) for n in range(5)]
    for task in tasks[1:3]:
        store.save(task, task.run())
    _Task.ran.clear()
    calls: list[tuple[int, int]] = []
    results, executor = execute(tasks, workers=1, progress=lambda done, total: calls.append((done, total)),
                                store=store)
    assert _Task.ran == [0, 3, 4]
    assert [rows[0]["number"] for rows in results] == [0, 1, 2, 3, 4]
    assert calls == [(2, 5), (3, 5), (4, 5), (5, 5)]
    assert executor == "in-process; 2 of 5 tasks resumed from an interrupted run"
    assert len(list(store.folder.glob("*.json"))) == 5


def test_a_lost_scheduler_is_one_line_saying_how_to_resume(tmp_path):
    """The client cancels every future when its scheduler is gone: the finished tasks are kept."""
    store = TaskStore(tmp_path / CHECKPOINT_FOLDER)

    class Lost(_Task):
        def run(self):
            raise AssertionError("not run")

    class CancellingClient:  # what a client whose scheduler died hands back: cancelled futures
        scheduler = type("Scheduler", (), {"address": "tcp://gone:8786"})()

        def map(self, function, tasks, pure):
            raise distributed.client.FutureCancelledError("a-key", reason="scheduler-disconnected")

    store.save(_Task(0), _Task(0).run())
    with pytest.raises(PincalError) as error:
        execute([_Task(0), Lost(1)], scheduler=CancellingClient(), store=store)
    message = str(error.value)
    assert "lost the Dask scheduler" in message and "after 1 of 2 study tasks" in message
    assert "rerun the same command to resume" in message and "\n" not in message
