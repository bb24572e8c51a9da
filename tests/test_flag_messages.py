"""A message of pincal that suggests a flag ("rerun with --reject-outliers", "give --tool",
"--select aic", "leave it out with --joint-names" …) names one the command that prints it accepts
(or the command it names: "calibrate with --tool", "next: pincal calibrate … --tip-link"), and no
misspelt choice ("--select aicc"): read from every string literal of pincal/ (docstrings left out)
against the parser of :func:`pincal.cli.parser.build_parser`. pip's flags ("pip install
--force-reinstall") are pip's."""

from __future__ import annotations

import argparse
import ast
import difflib
import functools
import re
from pathlib import Path

from conftest import package_files, subcommand_actions
from sources import nodes

PACKAGE = Path(__file__).resolve().parents[1] / "pincal"

#: The commands that can print the messages of a module (the first matching prefix); a module not
#: listed here (pincal/report/, pincal/model/ …) is shared, and its flags are checked against every command.
PRINTED_BY = {
    "cli/extract.py": {"extract"},
    "cli/detect.py": {"detect"},
    "workflows/detection.py": {"detect"},
    "measurements/charuco.py": {"detect"},
    "measurements/images.py": {"detect"},
    "measurements/camera_csv.py": {"detect"},
    "measurements/image_bags.py": {"extract"},
    "workflows/extract.py": {"extract"},
    "measurements/bags.py": {"extract"},
    "measurements/plateaus.py": {"extract"},
    "workflows/evaluation.py": {"evaluate"},
    "cli/fixture.py": {"calibrate", "evaluate"},
    "workflows/fixture.py": {"calibrate", "evaluate"},
    "workflows/settings.py": {"calibrate", "diagnose", "evaluate", "plan"},
    "measurements/couplings.py": {"calibrate", "diagnose", "evaluate"},
    "planning/": {"plan"},
    "diagnosis/": {"diagnose"},
    "model/effects.py": {"diagnose"},
    "model/dh/files.py": {"urdf-from-dh"},
    "fit/": {"calibrate", "diagnose", "evaluate", "plan"},
}
_SUGGESTION = re.compile(r"(?<![\w-])(--[a-z][\w-]*)(?:[ =](\w+))?")


@functools.cache  # a module's text is read twice by the scan (its count, its problems): parsed once
def _messages(source: str) -> tuple[tuple[int, str], ...]:
    """(line, text) of every string literal of a module but its docstrings, in order (an f-string whole,
    ``{}`` for each field)."""
    skipped = {id(node.body[0].value) for node in nodes(source, ast.Module, ast.ClassDef, ast.FunctionDef,
                                                          ast.AsyncFunctionDef)
               if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
               and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    messages = []
    for node in nodes(source, ast.JoinedStr, ast.Constant):  # an f-string before its parts, as ast.walk goes
        if isinstance(node, ast.JoinedStr):
            skipped.update(id(part) for part in node.values)
            messages.append((node.lineno, "".join(part.value if isinstance(part, ast.Constant) else "{}"
                                                  for part in node.values)))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skipped:
            messages.append((node.lineno, node.value))
    return tuple(sorted(messages))


def suggested_flags(source: str) -> list[tuple[int, str, str | None, str]]:
    """(line, flag, the word after it, the message's text before it) of every ``--flag`` a message of
    ``source`` names."""
    return [(line, match[1], match[2], text[:match.start()]) for line, text in _messages(source)
            for match in _SUGGESTION.finditer(text)]


def _named_command(before: str, names: set[str]) -> str | None:
    """The command a message names for the flag that follows ``before``: the last ``pincal NAME``,
    or ``NAME with`` right before the flag; ``pip`` for a pip command line."""
    alternatives = "|".join(sorted(map(re.escape, names), key=len, reverse=True))
    named = re.findall(rf"\bpincal ({alternatives})\b", before) + re.findall(rf"\b({alternatives}) with $", before)
    return "pip" if re.search(r"\bpip install\b[^'\"]*$", before) else (named[-1] if named else None)


def wrong_suggestions(module: str, source: str, parsers: dict[str, dict[str, argparse.Action]]) -> list[str]:
    printers = next((names for prefix, names in PRINTED_BY.items() if module.startswith(prefix)), set(parsers))
    problems = []
    for line, flag, word, before in suggested_flags(source):
        named = _named_command(before, set(parsers))
        if named == "pip":
            continue
        commands = {named} if named else printers
        actions = [parsers[name][flag] for name in sorted(commands) if flag in parsers[name]]
        choices = {str(choice) for action in actions for choice in action.choices or ()}
        if not actions:
            problems.append(f"pincal/{module}:{line}: {flag} is no flag of pincal {'|'.join(sorted(commands))}")
        elif word and choices and word not in choices and difflib.get_close_matches(word, choices, cutoff=0.6):
            problems.append(f"pincal/{module}:{line}: {flag} {word}: {word!r} is not one of its choices")
    return problems


def test_every_flag_a_message_suggests_is_one_the_printing_command_accepts():
    parsers = subcommand_actions()
    problems, seen = [], 0
    for path in package_files():
        module = path.relative_to(PACKAGE).as_posix()
        if module == "cli/parser.py":  # the flags' own definitions and help
            continue
        source = path.read_text(encoding="utf-8")
        seen += len(suggested_flags(source))
        problems += wrong_suggestions(module, source, parsers)
    assert seen > 150  # the check reads the messages at all
    assert problems == []


def test_the_check_sees_a_flag_no_command_has_one_of_another_command_and_a_wrong_choice():
    parsers = subcommand_actions()
    source = ('"""Docstring: --not-checked."""\n'
              'def f(x):\n'
              '    raise ValueError(f"{x}: rerun with --reject-outlier; --level must be full")\n'
              'NOTE = "give --payload-kg KG, or --select aicc, or --level auto; calibrate with --tool"\n'
              'NEXT = "pincal calibrate U D --tip-link L, pincal diagnose --sed 1; pip install --upgrade x"\n')
    assert wrong_suggestions("planning/x.py", source, parsers) == [
        "pincal/planning/x.py:3: --reject-outlier is no flag of pincal plan",
        "pincal/planning/x.py:4: --payload-kg is no flag of pincal plan",  # diagnose's, not plan's
        "pincal/planning/x.py:4: --select aicc: 'aicc' is not one of its choices",
        "pincal/planning/x.py:5: --sed is no flag of pincal diagnose",
    ]
    assert wrong_suggestions("report/x.py", source, parsers)[1:] == [
        "pincal/report/x.py:4: --select aicc: 'aicc' is not one of its choices",
        "pincal/report/x.py:5: --sed is no flag of pincal diagnose"]
