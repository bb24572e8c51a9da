"""Progress of long commands on stderr, drawn by tqdm.

The library reports progress through plain ``progress(done, total)`` callbacks
(:mod:`pincal.progress`); only the command line draws it:

* stderr is a terminal: a live bar with done/total, rate and time left, shown
  once the work has taken :data:`TERMINAL_DELAY_S` (a quick command leaves no bar);
* stderr is a file or a pipe (CI logs): a plain line once the work has taken
  :data:`LOG_INTERVAL_S`, then at most one per :data:`LOG_INTERVAL_S`, and a
  last one at the end if any was written (work shorter than that writes nothing,
  so a quick command's log, or its one-line error, stays as it was);
* ``--quiet``: nothing.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

from tqdm import tqdm

__all__ = ["LOG_INTERVAL_S", "TERMINAL_DELAY_S", "progress_bar"]

#: Seconds between two progress lines when stderr is not a terminal (and before the first).
LOG_INTERVAL_S = 10.0
#: Seconds of work before a terminal shows the bar.
TERMINAL_DELAY_S = 1.0


class _Bar(tqdm):
    """tqdm without its monitor thread (``monitor_interval = 0``), so that the process drawing
    the bar keeps one Python thread and may fork its workers
    (:func:`pincal.study.executors.fork_is_safe`). The monitor's job, redrawing when reports
    slow down after a fast start, is done by an explicit ``miniters=0`` (no adaptive skipping of reports:
    ``mininterval`` alone limits the redraws)."""

    monitor_interval = 0


class _LogLines:
    """A stream for logs: each status tqdm draws becomes one line of its own
    (tqdm redraws with carriage returns, which a log file would run together)."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> None:
        line = text.replace("\r", "").strip()
        if line:
            self.stream.write(line + "\n")

    def flush(self) -> None:
        self.stream.flush()


@contextmanager
def progress_bar(label: str, quiet: bool = False, stream: TextIO | None = None,
                 interactive: bool | None = None, unit: str = "task") -> Iterator[Callable[[int, int], None]]:
    """A ``progress(done, total)`` callback that draws on ``stream`` (default stderr).

    Args:
        label: what is counted, shown before the counts (e.g. ``"study tasks"``).
        quiet: draw nothing.
        stream: where to draw (default ``sys.stderr``).
        interactive: force the terminal (True) or log (False) style; default:
            whether ``stream`` is a terminal.
        unit: the name of one count (shown in the rate, e.g. ``task/s``).
    """
    stream = sys.stderr if stream is None else stream
    if interactive is None:
        interactive = bool(getattr(stream, "isatty", lambda: False)())
    bar: tqdm | None = None
    if not quiet:  # started now: the delays count from the start of the work, not from its first report
        if interactive:
            bar = _Bar(total=None, desc=label, file=stream, unit=unit, dynamic_ncols=True, leave=True,
                       delay=TERMINAL_DELAY_S, miniters=0)
        else:
            bar = _Bar(total=None, desc=label, file=_LogLines(stream), unit=unit, ncols=80, ascii=True,
                       mininterval=LOG_INTERVAL_S, maxinterval=LOG_INTERVAL_S, delay=LOG_INTERVAL_S,
                       miniters=0)
    started = False

    def report(done: int, total: int) -> None:
        nonlocal started
        if bar is None:
            return
        bar.total = total
        if not started:  # work done before the first report (study tasks resumed) starts the bar, not its rate
            started = True
            bar.initial = bar.n = bar.last_print_n = done
        bar.update(done - bar.n)

    try:
        yield report
    finally:
        if bar is not None:
            bar.close()
