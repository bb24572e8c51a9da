"""Finished study tasks kept on disk, so that a study killed mid-run resumes where it stopped.

While a study runs, each finished task's rows are written, atomically
(:func:`pincal.outputs.write_text`, without fsync: a file that a machine crash
truncated fails to parse and its task simply runs again), to one JSON file in a hidden folder
(:data:`CHECKPOINT_FOLDER`) of the output folder, named by the SHA-256 of the
pincal version, a digest of pincal's own source files and the task's full ``repr`` — the task kind, its key and seed,
and the whole :class:`pincal.study.protocol.StudyConfig`. A rerun of the same
command finds them and runs only the missing tasks; a file is reused only when
the version, the source digest and the task it records equal the task asked for, character for
character, so a changed protocol never reuses a result. Floats are stored as
:func:`repr` writes them (JSON), so a reused row is the same number to the bit.
The command line removes the folder once the study's files are written.

Whatever dies — a Dask worker (its tasks are rerun by the scheduler), the
scheduler, or the ``pincal study`` process itself — at most the tasks that
were running are lost.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from pincal._version import __version__
from pincal.outputs import TEMP_SUFFIX, write_text

__all__ = ["CHECKPOINT_FOLDER", "source_digest", "TaskStore"]

#: Hidden folder of the output folder holding the finished tasks of an unfinished study.
CHECKPOINT_FOLDER = ".pincal-study-tasks"


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 of every ``.py`` file of the installed pincal package (path and bytes), so that
    results stored by edited code are never reused, even under the same version string."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode("utf-8") + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


class TaskStore:
    """Rows of finished tasks in ``folder`` (created on the first save), one JSON file per task."""

    def __init__(self, folder: str | os.PathLike[str]) -> None:
        self.folder = Path(folder)

    @staticmethod
    def identity(task: Any) -> str:
        """What a stored result must match: the pincal version, its source digest and the task's ``repr``."""
        return f"pincal {__version__} {source_digest()}\n{task!r}"

    def path(self, task: Any) -> Path:
        return self._file(self.identity(task))

    def _file(self, identity: str) -> Path:
        return self.folder / f"{hashlib.sha256(identity.encode('utf-8')).hexdigest()}.json"

    def load(self, task: Any) -> list[dict[str, Any]] | None:
        """The stored rows of ``task``, or None if it has none (or a file that does not match it)."""
        identity = self.identity(task)
        try:
            document = json.loads(self._file(identity).read_text(encoding="utf-8"))
        except (OSError, ValueError):  # absent, or unreadable: run the task again
            return None
        if not isinstance(document, dict) or document.get("task") != identity:
            return None
        rows = document.get("rows")
        return rows if isinstance(rows, list) else None

    def save(self, task: Any, rows: list[dict[str, Any]]) -> None:
        """Keep the rows of a finished task (NaN as JSON's ``NaN``; floats exact)."""
        identity = self.identity(task)
        path, text = self._file(identity), json.dumps({"task": identity, "rows": rows}) + "\n"
        try:
            write_text(path, text, durable=False)
        except FileNotFoundError:  # no folder yet (the first save): create it, not once per save
            self.folder.mkdir(exist_ok=True)
            write_text(path, text, durable=False)

    def clear(self) -> None:
        """Remove the stored tasks (and temporary files a kill left) and the folder if nothing else is in it."""
        if not self.folder.is_dir():
            return
        for entry in self.folder.iterdir():
            if entry.is_file() and (entry.suffix == ".json" or entry.name.endswith(TEMP_SUFFIX)):
                entry.unlink()
        try:
            self.folder.rmdir()
        except OSError:  # something of the user's is in it: leave it
            pass
