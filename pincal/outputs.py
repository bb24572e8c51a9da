"""Every file pincal writes, written so that a fault never leaves half of it.

A file is written to a temporary sibling in the destination's folder (same
filesystem, so the rename is atomic), flushed and fsync'ed, then renamed over
the destination with :func:`os.replace`; the folder is fsync'ed after the
rename where the platform allows. A run killed at any moment therefore leaves
either the old file or the complete new one. A write that fails (an exception,
Ctrl-C) removes its temporary file and leaves the old file untouched; only a
hard kill (SIGKILL, power loss) can leave a temporary file behind, and its name
— hidden, ending in :data:`TEMP_SUFFIX` — never looks like an output.

``durable=False`` skips the two fsyncs (~1–5 ms each on a busy disk) for files
that are a cache checked on reading, such as the study's per-task checkpoints:
the rename still makes a killed process leave the old file or the new one whole;
only a crash of the machine itself may leave the new file empty or truncated.

Permissions are those a plain ``open(path, "w")`` would give: a new file gets
0o666 minus the umask, an existing file keeps its mode. Writing through a
symbolic link replaces the file it points to, not the link.

Layer 0: imports nothing of pincal. Errors are the ``OSError`` of the failing
call; callers translate them to their own error kind where they did before.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import secrets
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

__all__ = ["TEMP_SUFFIX", "is_temporary", "replacing", "write_text", "write_bytes", "file_sha256"]

#: Every temporary file ends with this (and starts with a dot): ``.REPORT.json.1a2b3c4d.pincal-tmp``.
TEMP_SUFFIX = ".pincal-tmp"

_MODES = ("w", "wt", "wb")
_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0) | getattr(os, "O_CLOEXEC", 0)


def is_temporary(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a temporary file of this module (one a killed write left behind)."""
    name = Path(path).name
    return name.startswith(".") and name.endswith(TEMP_SUFFIX)


def _open_temporary(target: Path) -> tuple[int, Path]:
    """Create a new, empty temporary sibling of ``target``; its mode follows the umask (0o666 base)."""
    for _ in range(100):
        temporary = target.with_name(f".{target.name}.{secrets.token_hex(4)}{TEMP_SUFFIX}")
        try:
            return os.open(temporary, _FLAGS, 0o666), temporary
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {target}")


def _naming(exc: OSError, path: str | os.PathLike[str]) -> OSError:
    """The same error, naming the destination the user asked for instead of the temporary file."""
    return type(exc)(exc.errno, exc.strerror, os.fspath(path))


def _sync_directory(folder: Path) -> None:
    """Make the rename durable (POSIX); a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(
    path: str | os.PathLike[str],
    mode: str = "w",
    *,
    encoding: str | None = "utf-8",
    newline: str | None = None,
    verify: Callable[[Path], None] | None = None,
    durable: bool = True,
) -> Iterator[IO[Any]]:
    """A file object whose content replaces ``path`` when the block ends without an exception.

    Args:
        path: the destination; its folder must exist.
        mode: ``"w"`` (text) or ``"wb"`` (bytes).
        encoding, newline: as for :func:`open`, text mode only (``newline=""``
            for the :mod:`csv` module).
        verify: called with the complete temporary file before it replaces
            ``path``; whatever it raises cancels the write (the old file stays).
        durable: fsync the file before the rename and the folder after it
            (False: atomic against a killed process, not against a machine crash).

    Raises:
        ValueError: ``mode`` is not a write-whole-file mode.
        OSError: the temporary file cannot be created, written or renamed
            (e.g. the folder does not exist); nothing is left behind, and the
            error names ``path``, not the temporary file.
    """
    if mode not in _MODES:
        raise ValueError(f"mode must be one of {', '.join(_MODES)}, not {mode!r}")
    target = Path(os.path.realpath(path))
    try:
        fd, temporary = _open_temporary(target)
    except OSError as exc:
        raise _naming(exc, path) from None
    try:
        text: dict[str, Any] = {"encoding": encoding, "newline": newline} if "b" not in mode else {}
        try:
            handle = os.fdopen(fd, mode, **text)
        except BaseException:
            os.close(fd)
            raise
        with handle:
            yield handle
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        if verify is not None:
            verify(temporary)
        with contextlib.suppress(FileNotFoundError):
            os.chmod(temporary, stat.S_IMODE(os.stat(target).st_mode))  # keep an existing file's mode
        os.replace(temporary, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        if isinstance(exc, OSError) and (exc.filename is None or is_temporary(exc.filename)):
            raise _naming(exc, path) from None
        raise
    if durable:
        _sync_directory(target.parent)


def write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8", *, durable: bool = True) -> None:
    """Replace ``path`` by ``text`` (see :func:`replacing`)."""
    with replacing(path, "w", encoding=encoding, durable=durable) as handle:
        handle.write(text)


def write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Replace ``path`` by ``data`` (see :func:`replacing`)."""
    with replacing(path, "wb") as handle:
        handle.write(data)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes: what a report records of the file written beside it."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
