"""The README and the docs site (docs/, mkdocs.yml) stay usable: links resolve, the README stays a
front door that still carries CI's test command, every ``pincal SUBCOMMAND --flag`` the pages show
is one the command accepts, and ``mkdocs build --strict`` passes where mkdocs is installed."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import subcommand_actions

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]

#: CI (.ci/run) runs the second non-empty line of the README's first fenced block.
TEST_COMMAND = 'pip install ".[test]" && python -m pytest'
README_MAX_LINES = 250

_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE_SPAN = re.compile(r"(`+)(.+?)\1", re.DOTALL)
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_EXPLICIT_ID = re.compile(r"\{#([\w-]+)\}")
_FLAG = re.compile(r"(?<![\w-])--[A-Za-z][\w-]*")


def _split(text: str) -> tuple[list[str], list[list[str]]]:
    """The prose lines (fenced blocks blanked) and the fenced blocks' lines of a Markdown text."""
    prose, blocks, block = [], [], None
    for line in text.splitlines():
        if _FENCE.match(line):
            if block is None:
                block = []
            else:
                blocks.append(block)
                block = None
            prose.append("")
        elif block is not None:
            block.append(line)
            prose.append("")
        else:
            prose.append(line)
    return prose, blocks


def _slug(heading: str) -> str:
    """A heading's id as GitHub makes it, and as mkdocs.yml's toc slugify (pymdownx.slugs, case lower)."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link keeps its text
    text = re.sub(r"<[^>]*>", "", text).replace("`", "").replace("**", "").strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    prose, _ = _split(page.read_text(encoding="utf-8"))
    ids = set()
    for line in prose:
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if heading:
            ids.add(_slug(_EXPLICIT_ID.sub("", heading[1])))
        ids.update(_EXPLICIT_ID.findall(line))
    return ids


def _links(page: Path) -> list[tuple[int, str]]:
    """(line, target) of every Markdown link and image outside code."""
    prose, _ = _split(page.read_text(encoding="utf-8"))
    text = _CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m[0]), "\n".join(prose))  # lines kept
    return [(text.count("\n", 0, m.start()) + 1, m[1]) for m in _LINK.finditer(text)]


def broken_links(page: Path, root: Path = ROOT) -> list[str]:
    """Each relative link of ``page`` whose file is missing, whose anchor names no heading of the
    target page, or (for a page under ``root``/docs) that leaves docs/, where mkdocs cannot follow it."""
    docs = root / "docs"
    problems = []
    for line, target in _links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("//"):
            continue  # https:, mailto:: not checked here
        path, _, anchor = target.partition("#")
        where = f"{page.relative_to(root)}:{line}: {target}"
        resolved = (page.parent / path).resolve() if path else page
        if path.startswith("/"):
            problems.append(f"{where}: absolute path")
        elif not resolved.exists():
            problems.append(f"{where}: no such file")
        elif page.is_relative_to(docs) and not resolved.is_relative_to(docs):
            problems.append(f"{where}: outside docs/ (the site has only docs/)")
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            problems.append(f"{where}: no heading #{anchor} in {resolved.relative_to(root)}")
    return problems


def _subcommands() -> dict[str, set[str]]:
    """Each subcommand of ``pincal`` and the flags its --help lists."""
    return {name: set(actions) for name, actions in subcommand_actions().items()}


def commands(text: str, names: set[str]) -> list[tuple[str, str]]:
    """(subcommand, the text of its arguments) for every ``pincal SUBCOMMAND ...`` of a Markdown
    text — in fenced blocks (continuation lines joined, ``# comments`` dropped) and in code spans —
    and every code span that starts ``SUBCOMMAND --flag`` (prose such as `calibrate --level dh`)."""
    prose, blocks = _split(text)
    pieces = []
    for block in blocks:
        for line in "\n".join(block).replace("\\\n", " ").splitlines():
            pieces.append(re.sub(r"(^|\s)#.*", "", re.sub(r'"[^"]*"', '""', line)))  # quotes: $(python -c "...")
    spans = [m[2] for m in _CODE_SPAN.finditer("\n".join(prose))]
    pieces += spans
    alternatives = "|".join(sorted(map(re.escape, names), key=len, reverse=True))
    invocation = re.compile(rf"\bpincal\s+({alternatives})(?![\w-])")
    found = []
    for piece in pieces:
        starts = list(invocation.finditer(piece))
        for i, match in enumerate(starts):
            end = starts[i + 1].start() if i + 1 < len(starts) else len(piece)
            found.append((match[1], re.split(r"&&|;\s", piece[match.end():end])[0]))
    for span in spans:
        bare = re.match(rf"({alternatives})\s+--", span)
        if bare and not invocation.search(span):
            found.append((bare[1], span[bare.end(1):]))
    return found


def unknown_flags(text: str, accepted: dict[str, set[str]]) -> list[str]:
    return [f"pincal {name} {flag}" for name, arguments in commands(text, set(accepted))
            for flag in _FLAG.findall(arguments) if flag not in accepted[name]]


# --- (a) links ------------------------------------------------------------------------------------


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_relative_link_resolves(page):
    assert broken_links(page) == []


def test_the_link_check_sees_a_broken_file_an_anchor_and_a_link_out_of_docs(tmp_path):
    (tmp_path / "docs").mkdir()
    good = tmp_path / "docs" / "a.md"
    good.write_text("# A page\n\n## Choosing the level: `--level auto`\n\nText.\n", encoding="utf-8")
    page = tmp_path / "docs" / "b.md"
    page.write_text("# B\n\n[ok](a.md#choosing-the-level---level-auto) [gone](c.md) [bad](a.md#nope)\n"
                    "`[in code](c.md)`\n\n```\n[in a block](c.md)\n```\n", encoding="utf-8")
    problems = broken_links(page, tmp_path)
    (tmp_path / "README.md").write_text("[docs](docs/a.md#a-page)\n", encoding="utf-8")
    page.write_text("[out](../README.md)\n", encoding="utf-8")
    outside = broken_links(page, tmp_path)
    assert broken_links(tmp_path / "README.md", tmp_path) == []
    assert [p.split(": ", 2)[2] for p in problems] == ["no such file", "no heading #nope in docs/a.md"]
    assert len(outside) == 1 and "outside docs/" in outside[0]


# --- (b) the README as front door -----------------------------------------------------------------


def test_readme_is_a_front_door_that_keeps_the_ci_test_command():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines: move detail into docs/"
    first, inside = [], False  # as .ci/run reads it: awk '/^```/{if (inside) exit; inside=1; next} inside && NF'
    for line in lines:
        if line.startswith("```"):
            if inside:
                break
            inside = True
        elif inside and line.split():
            first.append(line)
    assert len(first) >= 2 and first[1] == TEST_COMMAND  # sed -n 2p


# --- (c) flags ------------------------------------------------------------------------------------


def test_every_flag_shown_is_one_the_command_accepts():
    accepted = _subcommands()
    assert {"simulate", "calibrate", "evaluate", "diagnose", "plan", "report", "demo", "study",
            "urdf-from-dh", "example"} <= set(accepted)
    seen, unknown = 0, []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        seen += len(commands(text, set(accepted)))
        unknown += [f"{page.relative_to(ROOT)}: {u}" for u in unknown_flags(text, accepted)]
    assert seen > 50  # the check reads the commands at all
    assert unknown == []


def test_the_flag_check_sees_a_misspelt_flag():
    accepted = _subcommands()
    text = ("```\npincal calibrate URDF DATA --tip-link L \\\n    --levle full --out o.urdf --report r.json"
            "  # --not-a-flag in a comment\npincal evaluate o.urdf r.json d.csv --max-pos-mm 1 && pincal plan U "
            "--tip-link L --count 3 --out p.csv --report p.json --bogus\n```\n"
            "Prose: `calibrate --selct aic`, `pincal diagnose URDF D --payload-kg 1 --plotz d`, `--free-flag`.\n")
    assert unknown_flags(text, accepted) == ["pincal calibrate --levle", "pincal plan --bogus",
                                             "pincal diagnose --plotz", "pincal calibrate --selct"]


# --- (d) the site ---------------------------------------------------------------------------------


def _missing(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is None
    except ModuleNotFoundError:  # its parent package is missing
        return True


def test_mkdocs_build_strict(tmp_path):
    """``mkdocs build --strict`` passes and the site has its pages. Where the run's environment names a site
    already built that way from this checkout (``PINCAL_STRICT_SITE``: .ci/run builds it before the tests, and
    stops on a failed build), its pages are checked instead of building the same site a second time."""
    built = os.environ.get("PINCAL_STRICT_SITE")
    if built:
        site = Path(built)
        assert (site / "index.html").exists() and (site / "report.png").exists(), f"{site}: not a built site"
        return
    missing = [name for name in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python")
               if _missing(name)]
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed: pip install \".[docs]\" to build the site")
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
               "--site-dir", str(tmp_path / "site")]
    run = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})  # no Material end-of-life banner
    warnings = [line for line in (run.stdout + run.stderr).splitlines() if "WARNING" in line or "ERROR" in line]
    assert run.returncode == 0, "\n".join(warnings) or run.stderr[-2000:]
    assert (tmp_path / "site" / "index.html").exists() and (tmp_path / "site" / "report.png").exists()


def undocumented_packages(index: str, package: Path) -> list[str]:
    """pincal's subpackages that the "Every package" table of docs/api/index.md (``index``) does not name."""
    table = index.split("## Every package", 1)[-1].split("\n## ", 1)[0]
    named = set(re.findall(r"^\| `(pincal(?:\.\w+)?)`", table, re.MULTILINE))
    return sorted(f"pincal.{p.parent.name}" for p in package.glob("*/__init__.py")
                  if f"pincal.{p.parent.name}" not in named)


def test_every_package_has_an_api_page_or_a_reason(tmp_path):
    """docs/api/index.md names each subpackage with its page or why it has none; a new package fails here."""
    index = (DOCS / "api" / "index.md").read_text(encoding="utf-8")
    assert undocumented_packages(index, ROOT / "pincal") == []
    (tmp_path / "newroom").mkdir()
    (tmp_path / "newroom" / "__init__.py").write_text("", encoding="utf-8")
    assert undocumented_packages(index, tmp_path) == ["pincal.newroom"]


def test_the_report_example_is_made_by_the_documented_diagnose_command():
    """scripts/make_report_example.py runs docs/diagnose.md's TIAGo command as written there (the URDF, its
    first argument, as the $(python -c ...) prints it), so the example page follows the page's command."""
    spec = importlib.util.spec_from_file_location("make_report_example", ROOT / "scripts" / "make_report_example.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    page = (DOCS / "diagnose.md").read_text(encoding="utf-8")
    documented = [args.split() for name, args in commands(page, set(_subcommands())) if name == "diagnose"
                  and "tiago_mocap" in args]
    assert len(documented) == 1, "docs/diagnose.md: one TIAGo diagnose command expected"
    assert documented[0][:3] == ['$(python', '-c', '"")'] and documented[0][3:] == script.DIAGNOSE[1:]
