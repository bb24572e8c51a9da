"""The Jinja2 environment of the HTML pages: the templates in ``pincal/report/templates``, autoescaped, strict
about undefined values, with the ``num`` filter (:func:`pincal.report.sections.num`)."""

from __future__ import annotations

from functools import cache

from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

from pincal.report.sections import num

__all__ = ["environment"]


@cache
def environment() -> Environment:
    """The pages' template environment (:mod:`pincal.report.html`, :mod:`pincal.report.camera_figures`): one per
    process, so each template is compiled once (compiling the report page's templates was a fifth of a TIAGo
    diagnosis page's rendering); its loader still recompiles a template whose file changed."""
    env = Environment(loader=PackageLoader("pincal.report", "templates"),
                      autoescape=select_autoescape(enabled_extensions=("html", "j2"), default=True),
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = num
    return env
