"""HTML pages: ``pincal report`` (the page of a REPORT.json, an ``evaluate --json`` or a PLAN.json,
written whole) and the ``--html`` page calibrate and diagnose write beside their report.

A command's page is rendered from the report it is about to write, before anything is written, and then
written after the report (:func:`render_page`, :func:`write_page`): a report the page cannot be made of
stops the run with no output rather than leaving a report without the page asked for.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pincal.outputs import write_text
from pincal.report.reading import PAGE_KINDS, load_report
from pincal.workflows.paths import refuse_overwrite

__all__ = ["report_file", "refuse_page", "render_page", "write_page"]


def refuse_page(html: str | Path | None, inputs: Sequence[str | Path], outputs: Sequence[str | Path]) -> Path | None:
    """Check a command's ``--html`` path before the run: none of its ``inputs`` or other ``outputs``
    (:func:`pincal.workflows.paths.refuse_overwrite`). Returns it as a Path (None: no page asked for)."""
    if html is None:
        return None
    refuse_overwrite(html, *inputs, outputs=outputs)
    return Path(html)


def render_page(html: Path | None, report: Mapping[str, Any], report_path: Path) -> str | None:
    """The page of ``report`` as it will be written to ``report_path`` (the plots it names are looked up
    beside it: :func:`pincal.report.html.render_html`); None when no page was asked for."""
    if html is None:
        return None
    from pincal.report.html import render_html  # Jinja2 and the figures only when a page is asked for

    return render_html(dict(report), base=report_path.parent)


def write_page(html: Path | None, page: str | None) -> Path | None:
    """Write a page :func:`render_page` rendered, whole (:func:`pincal.outputs.write_text`); returns its path."""
    if html is None or page is None:
        return None
    write_text(html, page)
    return html


def report_file(document_path: str | Path, out: str | Path) -> Path:
    """Write the page of ``document_path`` to ``out`` (:func:`pincal.report.html.write_html`; the plots a
    diagnose report names are looked up beside it) and return ``out``.

    Raises:
        PincalError: a file that is none of those documents, or malformed (one line naming it and the key);
            ``out`` the document itself. Nothing is written then.
    """
    document_path, out = Path(document_path), Path(out)
    document = load_report(document_path, PAGE_KINDS, hints={
        "camera evaluation": "its page is the report's with these images: pincal evaluate ... --html REPORT.html",
        "tree evaluation": "each target's errors are its evaluated_targets; the page with them: pincal evaluate ... "
                           "--html PAGE.html; the calibration's: pincal report REPORT.json"})
    refuse_overwrite(out, document_path)
    from pincal.report.html import write_html

    write_html(out, document, base=document_path.parent, source=document_path)
    return out
