"""Progress of long commands on stderr, drawn by tqdm.

The library reports progress through plain ``progress(done, total)`` callbacks
(:data:`pincal.study.executors.Progress`); only the command line draws it:

* stderr is a terminal: a live bar with done/total, rate and time left;
* stderr is a file or a pipe (CI logs): one plain line at most every
  :data:`LOG_INTERVAL_S` seconds, and one at the end;
* ``--quiet``: nothing.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from typing import Callable, Iterator, TextIO

from tqdm import tqdm

#: Seconds between two progress lines when stderr is not a terminal.
LOG_INTERVAL_S = 10.0


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
                 interactive: bool | None = None) -> Iterator[Callable[[int, int], None]]:
    """A ``progress(done, total)`` callback that draws on ``stream`` (default stderr).

    Args:
        label: what is counted, shown before the counts (e.g. ``"study tasks"``).
        quiet: draw nothing.
        stream: where to draw (default ``sys.stderr``).
        interactive: force the terminal (True) or log (False) style; default:
            whether ``stream`` is a terminal.
    """
    stream = sys.stderr if stream is None else stream
    if interactive is None:
        interactive = bool(getattr(stream, "isatty", lambda: False)())
    bar: tqdm | None = None

    def report(done: int, total: int) -> None:
        nonlocal bar
        if quiet:
            return
        if bar is None:
            if interactive:
                bar = tqdm(total=total, desc=label, file=stream, unit="task", dynamic_ncols=True, leave=True)
            else:
                bar = tqdm(total=total, desc=label, file=_LogLines(stream), unit="task", ncols=80, ascii=True,
                           mininterval=LOG_INTERVAL_S, maxinterval=LOG_INTERVAL_S)
        bar.total = total
        bar.update(done - bar.n)

    try:
        yield report
    finally:
        if bar is not None:
            bar.close()
