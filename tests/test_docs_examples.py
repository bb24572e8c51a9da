"""Every fenced block of the README and docs/ runs, so none goes stale.

Each page's blocks run in order in one temporary directory prepared like a user's: ``pincal example
tiago_mocap|mukca|lwr_bag --out data`` and the KUKA URDF at ``urdf/kuka_lwr4plus.urdf`` (a clone's
path). A ```` ```bash ```` (``sh``, ``shell``, ``console``: ``$ `` lines) block's commands run
in-process — ``pincal ...`` through :func:`pincal.cli.commands.main`, ``python FILE`` through
:mod:`runpy` (a file of the clone, scripts/, when the directory has none), and
``$(python -c "...")`` is replaced by what the code prints — and each must exit 0, or the code a
marker right before the block states for every command of it (a command that shows a refusal)::

    <!-- exits 3: REASON -->

A ```` ```python ```` block runs in a fresh namespace. A block that cannot run in a test says why
right before it::

    <!-- not run: REASON -->

and a listing of what the block above prints says so (each of its lines is checked to be one the
block printed)::

    <!-- output of the block above -->

A block that is neither runnable nor marked, or a command the runner cannot run, fails the test.
"""

from __future__ import annotations

import io
import re
import runpy
import shlex
import shutil
import sys
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

import pytest

from pincal.cli.commands import main
from pincal.robots import kuka_lwr4plus_urdf

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
SHELL = {"bash", "sh", "shell", "console"}
PYTHON = {"python", "py"}
EXAMPLES = ("tiago_mocap", "mukca", "lwr_bag")

_FENCE = re.compile(r"^(```|~~~)\s*([\w+-]*)")
_NOT_RUN = re.compile(r"^<!--\s*not run:\s*(\S.*?)\s*-->$")
_OUTPUT = re.compile(r"^<!--\s*output of the block above\s*-->$")
_EXITS = re.compile(r"^<!--\s*exits (\d+):\s*(\S.*?)\s*-->$")
_PYTHON_C = re.compile(r'\$\(python -c "([^"]*)"\)')


@dataclass(frozen=True)
class Block:
    """A fenced block of a page: where it starts, its language, its text and what its marker says."""

    page: Path
    line: int  # of the opening fence, 1-based
    language: str
    text: str
    not_run: str | None = None  # the reason given
    output: bool = False  # a listing of the previous block's output
    exits: int = 0  # every command's exit code (<!-- exits N: REASON -->)

    def __str__(self) -> str:
        return f"{self.page.relative_to(ROOT) if self.page.is_relative_to(ROOT) else self.page}:{self.line}"

    @property
    def runs(self) -> bool:
        return self.not_run is None and not self.output and self.language in SHELL | PYTHON


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of a Markdown page, each with the marker on the last non-blank line before it."""
    lines = page.read_text(encoding="utf-8").splitlines()
    found, start = [], None
    for i, line in enumerate(lines):
        fence = _FENCE.match(line.strip())
        if fence and start is None:
            start, language = i, fence[2].lower()
        elif fence and line.strip() == fence[1]:
            before = next((lines[j].strip() for j in range(start - 1, -1, -1) if lines[j].strip()), "")
            not_run, exits = _NOT_RUN.match(before), _EXITS.match(before)
            found.append(Block(page, start + 1, language, "\n".join(lines[start + 1:i]),
                               not_run[1] if not_run else None, bool(_OUTPUT.match(before)),
                               int(exits[1]) if exits else 0))
            start = None
    return found


def unmarked(block: Block) -> str | None:
    """Why ``block`` is neither run nor marked, or None."""
    if block.runs or block.not_run is not None or block.output:
        return None
    return (f"{block}: a ```{block.language} block neither runs nor says why: tag it ```bash or ```python, "
            "or put <!-- not run: REASON --> (or <!-- output of the block above -->) right before it")


class Unrunnable(Exception):
    """A command of a block the runner cannot run: the block needs a ``not run`` marker."""


def _captured(run) -> tuple[int, str]:
    """(exit code, stdout and stderr) of ``run()``; SystemExit is an exit code."""
    buffer = io.StringIO()
    with redirect_stdout(buffer), redirect_stderr(buffer):
        try:
            code = run()
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return code or 0, buffer.getvalue()


def _exec(source: str, where: str) -> None:
    exec(compile(source, where, "exec"), {"__name__": "__main__"})  # noqa: S102 - the docs' own code


def _substituted(line: str, where: str) -> str:
    """``line`` with each ``$(python -c "CODE")`` replaced by what CODE prints."""
    def value(match: re.Match) -> str:
        code, printed = _captured(lambda: _exec(match[1], where))
        assert code == 0, f"{where}: $(python -c ...) failed:\n{printed}"
        return shlex.quote(printed.strip())
    return _PYTHON_C.sub(value, line)


def shell_commands(block: Block) -> list[list[str]]:
    """The argument vectors of a shell block, in order (continuations joined, comments dropped,
    ``&&`` split; in a ``console`` block only the ``$ `` lines)."""
    commands = []
    for line in block.text.replace("\\\n", " ").splitlines():
        if block.language == "console":
            if not line.startswith("$ "):
                continue
            line = line[2:]
        words: list[str] = []
        for word in [*shlex.split(_substituted(line, str(block)), comments=True), "&&"]:
            if word == "&&":
                commands += [words] if words else []
                words = []
            elif word in {"|", "||", ";", ">", "<", "&"}:
                raise Unrunnable(f"{block}: the runner runs commands joined by && only: {line.strip()}")
            else:
                words.append(word)
    return commands


def run_command(argv: list[str], where: str) -> tuple[int, str]:
    """Run one command of a block in-process: (exit code, output)."""
    if argv[0] == "pincal":
        return _captured(lambda: main(argv[1:]))
    if argv[0] == "python" and argv[1:2] == ["-c"]:
        return _captured(lambda: _exec(argv[2], where))
    if argv[0] == "python" and len(argv) > 1 and argv[1].endswith(".py"):
        script = Path(argv[1]) if Path(argv[1]).exists() else ROOT / argv[1]  # scripts/: a clone's
        if not script.exists():
            raise Unrunnable(f"{where}: no such script: {argv[1]}")
        def run_script() -> int:
            runpy.run_path(str(script), run_name="__main__")
            return 0

        saved, sys.argv = sys.argv, [str(script), *argv[2:]]
        try:
            return _captured(run_script)
        finally:
            sys.argv = saved
    raise Unrunnable(f"{where}: cannot run {shlex.join(argv)!r}: mark the block <!-- not run: REASON -->")


def run_block(block: Block) -> str:
    """Run a runnable block in the current directory; its output. AssertionError on a failure."""
    if block.language in PYTHON:
        code, output = _captured(lambda: _exec(block.text, str(block)))
        assert code == 0, f"{block}: the Python block exited {code}:\n{output[-3000:]}"
        return output
    outputs = []
    for argv in shell_commands(block):
        code, output = run_command(argv, str(block))
        assert code == block.exits, (f"{block}: {shlex.join(argv)[:300]} exited {code}"
                                     f"{f' (the page says {block.exits})' if block.exits else ''}:\n{output[-3000:]}")
        outputs.append(output)
    return "".join(outputs)


def run_page(page: Path) -> int:
    """Run the blocks of ``page`` in order in the current directory; how many ran."""
    problems = [problem for block in blocks(page) if (problem := unmarked(block))]
    assert problems == [], "\n".join(problems)
    ran, previous = 0, None
    for block in blocks(page):
        if block.output:
            assert previous is not None, f"{block}: an output listing after no block that ran"
            printed = {line.strip() for line in previous.splitlines()}
            missing = [line for line in block.text.splitlines() if line.strip() and line.strip() not in printed]
            assert missing == [], f"{block}: lines the block above did not print:\n" + "\n".join(missing)
        elif block.runs:
            previous = run_block(block)
            ran += 1
        else:
            previous = None
    return ran


@pytest.fixture(scope="session")
def user_directory(tmp_path_factory):
    """A directory as a user's: the shipped measurement sets under data/, the KUKA URDF under urdf/, the
    example scripts under examples/."""
    folder = tmp_path_factory.mktemp("user")
    for name in EXAMPLES:
        out = folder if name == "examples" else folder / "data"
        code, output = _captured(lambda name=name, out=out: main(["example", name, "--out", str(out)]))
        assert code == 0, output
    (folder / "urdf").mkdir()
    shutil.copy(kuka_lwr4plus_urdf(), folder / "urdf" / "kuka_lwr4plus.urdf")
    return folder


RUN_PAGES = [page for page in PAGES if any(block.runs for block in blocks(page))]


@pytest.mark.parametrize("page", RUN_PAGES, ids=[str(p.relative_to(ROOT)) for p in RUN_PAGES])
def test_the_blocks_of_a_page_run_in_order(page, user_directory, tmp_path, monkeypatch):
    """A docs page runs as written in an empty folder after ``pip install`` (its own ``pincal example``
    blocks fetch what it reads); the README, whose commands run in a clone, in a folder laid out as one."""
    if page == ROOT / "README.md":
        shutil.copytree(user_directory, tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    assert run_page(page) >= 1


def test_every_block_runs_or_says_why():
    every = [block for page in PAGES for block in blocks(page)]
    assert [problem for block in every if (problem := unmarked(block))] == []
    assert sum(block.runs for block in every) >= 12  # the runner sees the blocks at all
    assert all(block.not_run.strip() for block in every if block.not_run is not None)


def test_the_runner_fails_on_a_wrong_flag_an_unmarked_block_and_a_wrong_output(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    page = tmp_path / "page.md"

    def failure(text: str) -> str:
        page.write_text(text, encoding="utf-8")
        with pytest.raises((AssertionError, Unrunnable)) as caught:
            run_page(page)
        return str(caught.value)

    wrong_flag = failure("```bash\npincal demo --sed 1 --out demo\n```\n")
    assert "exited 2" in wrong_flag and "unrecognized arguments: --sed" in wrong_flag
    assert "neither runs nor says why" in failure("```\npincal demo\n```\n")
    assert "cannot run 'rm -rf x'" in failure("```bash\nrm -rf x\n```\n")
    assert "exited 0 (the page says 3)" in failure('<!-- exits 3: a refusal -->\n```bash\npython -c "print(1)"\n'
                                                   "```\n")
    assert "did not print" in failure('```bash\npython -c "print(1)"\n```\n<!-- output of the block above -->\n'
                                      "```text\n2\n```\n")
    page.write_text('```sh\npython -c "print(1)" && python -c "print($(python -c "print(2)"))"  # a comment\n```\n\n'
                    "<!-- output of the block above -->\n```text\n1\n2\n```\n\n```python\nprint('a')\n```\n\n"
                    "<!-- not run: a synopsis -->\n```\npincal calibrate URDF DATA\n```\n", encoding="utf-8")
    assert run_page(page) == 2
