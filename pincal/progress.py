"""Progress of long library work, reported through plain ``progress(done, total)`` callbacks.

A library function that can take more than a few seconds — the study's tasks,
the parameter selection of a calibration, the candidate search of ``diagnose``,
the search of ``plan`` — takes ``progress: Progress | None = None`` and never
prints; the command line draws the counts (:mod:`pincal.cli.progress`: a tqdm
bar on a terminal, a line every 10 s in a log, nothing with ``--quiet``).

The calls promise: ``done`` never decreases, ``done <= total``, and the last
call has ``done == total``. ``total`` may grow while the work is discovered
(another exchange pass of ``plan``, another step of ``diagnose``).

Layer 0: imports nothing of pincal.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["Progress", "Counter", "Stages"]

#: ``progress(done, total)``: units of work done so far, of ``total`` known so far.
Progress = Callable[[int, int], None]


class Counter:
    """Counts units of work for a ``progress`` callback (None: counts silently).

    ``expect`` announces work, ``tick`` reports work done, ``settle`` counts
    what was announced but turned out unnecessary (a search that stopped early)
    as done. A call is made only when the counts changed.
    """

    def __init__(self, progress: Progress | None) -> None:
        self.progress = progress
        self.done = 0
        self.total = 0
        self._reported: tuple[int, int] | None = None

    def expect(self, units: int) -> None:
        """``units`` more units of work to do (not reported until something is done)."""
        self.total += max(int(units), 0)

    def tick(self, units: int = 1) -> None:
        """``units`` more done (never beyond the total announced), reported."""
        self.done = min(self.done + max(int(units), 0), self.total)
        if self.progress is not None and (self.done, self.total) != self._reported:
            self._reported = (self.done, self.total)
            self.progress(self.done, self.total)

    def settle(self) -> None:
        """Everything announced is done (what was not needed counts as done), reported."""
        self.tick(self.total - self.done)


class Stages:
    """One ``progress`` over work done in stages (e.g. calibrate, then diagnose): each stage's
    counts follow the totals of the stages before it, so ``done`` still never decreases."""

    def __init__(self, progress: Progress | None) -> None:
        self.progress = progress
        self._offset = 0
        self._last_total = 0

    def next(self) -> Progress | None:
        """The callback of the next stage (None when nothing is reported)."""
        if self.progress is None:
            return None
        self._offset += self._last_total
        self._last_total = 0
        offset, report = self._offset, self.progress

        def stage(done: int, total: int) -> None:
            self._last_total = total
            report(offset + done, offset + total)

        return stage
