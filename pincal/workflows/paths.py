"""Where the ``pincal`` commands write: one policy for every output path.

An output is never one of the run's inputs (a xacro description's included
files count as inputs: :func:`description_inputs`), never another output of the same
run, never a directory; its folder is created when missing (as ``calibrate``,
``diagnose``, ``plan``, ``urdf-from-dh``, ``simulate``, ``demo`` and ``study``
all do). Every refusal is one line naming the path and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence
from fnmatch import fnmatch
from pathlib import Path

from pincal.errors import PincalError
from pincal.model.description import is_xacro, read_description
from pincal.model.urdf import same_file

__all__ = ["ensure_directory", "input_paths", "description_inputs", "refuse_overwrite", "refuse_overwrite_matching",
           "paths_in"]


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


def input_paths(given: str | Path | Sequence[str | Path]) -> list[Path]:
    """One input file or several (the sessions of a calibration) as a list of paths."""
    return [Path(p) for p in ([given] if isinstance(given, (str, Path)) else given)]


def description_inputs(urdf: str | Path, xacro_args: Sequence[tuple[str, str]] | None = ()) -> list[Path]:
    """A robot description and, for a ``.xacro``, every file it includes: all inputs of the run.

    The xacro file is expanded here, before any output is checked or any fit runs
    (:func:`pincal.model.description.read_description` caches the expansion, so
    loading the chain afterwards does not expand it again); a description that does
    not expand is its one-line error now rather than after the fit.
    """
    urdf = Path(urdf)
    if not (is_xacro(urdf) and urdf.is_file()):
        return [urdf]
    return [urdf, *read_description(urdf, xacro_args or None).included]


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


def refuse_overwrite_matching(folder: str | Path, pattern: str, *inputs: str | Path) -> None:
    """Refuse a run that writes files named ``pattern`` (a glob, e.g. ``diagnose_*.png``)
    into ``folder`` when one of its ``inputs`` is such a file in that folder."""
    folder = Path(folder)
    for path in map(Path, inputs):
        if fnmatch(path.name, pattern) and same_file(folder, path.parent):
            raise PincalError(f"{path}: is an input of this run, and {folder} gets files named {pattern}; "
                              "refusing to overwrite an input file; choose another output folder")


def paths_in(value: object, *names: str) -> None:
    """In a frozen outputs value's ``__post_init__``: make each named attribute that is given (not None)
    a :class:`~pathlib.Path`, so that a caller may pass ``str``."""
    for name in names:
        given = getattr(value, name)
        if given is not None:
            object.__setattr__(value, name, Path(given))
