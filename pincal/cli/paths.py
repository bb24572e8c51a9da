"""Where the ``pincal`` commands write: one policy for every output path.

An output is never one of the run's inputs, never another output of the same
run, never a directory; its folder is created when missing (as ``calibrate``,
``diagnose``, ``plan``, ``urdf-from-dh``, ``simulate``, ``demo`` and ``study``
all do). Every refusal is one line naming the path and what to do.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from pincal.errors import PincalError
from pincal.model.urdf import same_file


def ensure_directory(path: str | Path) -> Path:
    """Create the output folder ``path`` (and its parents); one clear error if impossible."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise PincalError(f"{path}: exists and is not a directory; choose another output folder") from None
    except OSError as exc:
        raise PincalError(f"{path}: cannot create the output folder ({exc.strerror})") from None
    return path


def refuse_overwrite(output: str | Path, *inputs: str | Path, outputs: Sequence[str | Path] = ()) -> None:
    """Check the output path ``output`` of a run, and create its folder if missing.

    Args:
        output: the file to write.
        inputs: the run's input files: ``output`` must be none of them.
        outputs: the run's other outputs: ``output`` must be none of them either.

    Raises:
        PincalError: ``output`` is an input, another output or a directory, or
            its folder cannot be created.
    """
    output = Path(output)
    for path in inputs:
        if same_file(output, Path(path)):
            raise PincalError(f"{output}: is an input of this run; refusing to overwrite an input file; "
                              "choose another output path")
    for path in outputs:
        if same_file(output, Path(path)):
            raise PincalError(f"{output}: is also the path of another output of this run ({path}); "
                              "give each output its own path")
    if output.is_dir():
        raise PincalError(f"{output}: is a directory; give a file name")
    ensure_directory(output.parent)
