"""``pincal report``: the HTML page of a REPORT.json, an ``evaluate --json`` or a PLAN.json, written whole."""

from __future__ import annotations

from pathlib import Path

from pincal.report.html import write_html
from pincal.report.reading import PAGE_KINDS, load_report
from pincal.workflows.paths import refuse_overwrite

__all__ = ["report_file"]


def report_file(document_path: str | Path, out: str | Path) -> Path:
    """Write the page of ``document_path`` to ``out`` (:func:`pincal.report.html.write_html`; the plots a
    diagnose report names are looked up beside it) and return ``out``.

    Raises:
        PincalError: a file that is none of those documents, or malformed (one line naming it and the key);
            ``out`` the document itself. Nothing is written then.
    """
    document_path, out = Path(document_path), Path(out)
    document = load_report(document_path, PAGE_KINDS)
    refuse_overwrite(out, document_path)
    write_html(out, document, base=document_path.parent, source=document_path)
    return out
