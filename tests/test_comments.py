"""Comments explain the why in the code's own terms, and docs/architecture.md names every module.

An issue number or a commit hash points outside the repository: a reader cannot follow it, and the
rationale it stands for is lost when the tracker moves. Reference data keep their provenance: a
revision named as the source of a committed reference file or as a benchmark's baseline is data,
listed in :data:`PROVENANCE`.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Every Python file of the package, its scripts and tests (this one, which lists the forms, aside).
SOURCES = sorted(path for path in [*(ROOT / "pincal").rglob("*.py"), *(ROOT / "scripts").glob("*.py"),
                                   *(ROOT / "tests").glob("*.py")] if path != Path(__file__).resolve())
#: "issue 20", "Issue 12's", "issue #9"
ISSUE = re.compile(r"\bissues? #?\d+", re.IGNORECASE)
#: "commit 384bd79", "at fe7e23b", "6975758's code": a 7-40 digit hexadecimal word with a digit and a letter
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
#: Revisions that are the provenance of reference data or a benchmark's baseline, by file.
PROVENANCE = {
    "scripts/benchmark.py": {"6975758"},
    "tests/test_study_reference.py": {"6975758"},
    "pincal/outputs.py": {"1a2b3c4d"},  # a temporary file's random part, shown
}


def _comments_and_docstrings(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of every comment and string literal of ``path`` (docstrings among them)."""
    import tokenize

    out = []
    with open(path, encoding="utf-8") as handle:
        for token in tokenize.generate_tokens(handle.readline):
            if token.type in (tokenize.COMMENT, tokenize.STRING):
                out.append((token.start[0], token.string))
    return out


def test_no_issue_numbers_or_commit_hashes_as_rationale():
    found = []
    for path in SOURCES:
        rel = path.relative_to(ROOT).as_posix()
        allowed = PROVENANCE.get(rel, set())
        whole = path.read_text(encoding="utf-8")
        if not ISSUE.search(whole) and all(match.group(0) in allowed for match in HASH.finditer(whole)):
            # a comment or string is a piece of the file, cut at a quote, "#" or a line's end (never inside a
            # word): a finding in one is a match in the whole text, so a file with none needs no tokenizing
            continue
        for line, text in _comments_and_docstrings(path):
            for match in ISSUE.finditer(text):
                found.append(f"{rel}:{line}: {match.group(0)!r}")
            for match in HASH.finditer(text):
                if match.group(0) not in allowed and not re.search(r"sha256|[0-9a-f]{41,}", text):
                    found.append(f"{rel}:{line}: {match.group(0)!r}")
    assert not found, "say the why in the code's own terms:\n" + "\n".join(found)


def test_the_checks_find_what_they_look_for():
    """The patterns catch the forms removed from the code, and leave the ordinary words alone."""
    assert ISSUE.search("the bound of issue 12's Done when") and ISSUE.search("Issue #9: planned")
    assert HASH.search("a numpy evaluation (commit 384bd79) was no faster")
    assert not HASH.search("a deadbeef-free 1234567 row count") and not ISSUE.search("the issues it raises")


def named_modules(doc: str) -> set[str]:
    """The modules docs/architecture.md's table names: a room's row names its modules by their path in the
    room (`solver.py`, `dh/table.py`), a top-level module is named by its file name anywhere."""
    named = {n for n in re.findall(r"`([\w.]+\.py)`", doc)}
    for line in doc.splitlines():
        cells = [cell.strip() for cell in line.split("|")]
        if len(cells) < 4 or not cells[1].isdigit():
            continue
        for room in re.findall(r"`(\w+)/`", cells[2]):
            named.update(f"{room}/{n}" for n in re.findall(r"`([\w/.]+\.py)`", line))
    return named


def test_architecture_names_every_module():
    """Every module of pincal is named in docs/architecture.md, in its room's row."""
    named = named_modules((ROOT / "docs" / "architecture.md").read_text(encoding="utf-8"))
    missing = [rel for path in sorted((ROOT / "pincal").rglob("*.py")) if path.name != "__init__.py"
               and (rel := path.relative_to(ROOT / "pincal").as_posix()) not in named]
    assert not missing, f"docs/architecture.md does not name: {', '.join(missing)}"


def test_a_file_name_counts_only_in_its_rooms_row():
    doc = ("| 5 | `fit/` | the solver (`solver.py`) | layers |\n"
           "| 7 | `study/` | files, figures (`checkpoints.py`) | layers |\n| 0 | `errors.py` | errors | - |\n")
    named = named_modules(doc)
    assert {"fit/solver.py", "study/checkpoints.py", "errors.py"} <= named
    assert "study/solver.py" not in named and "study/files.py" not in named
