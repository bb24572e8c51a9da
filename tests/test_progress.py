"""Progress on stderr (pincal.cli.progress): a tqdm bar in a terminal, sparse lines in logs, nothing with --quiet."""

from __future__ import annotations

import io

import pytest

from pincal.cli import progress as progress_module
from pincal.cli.commands import main
from pincal.cli.progress import progress_bar


def _draw(**options) -> str:
    stream = io.StringIO()
    with progress_bar("study tasks", stream=stream, **options) as report:
        for done in range(1, 201):
            report(done, 200)
    return stream.getvalue()


def test_terminal_bar_shows_counts_rate_and_time_left():
    text = _draw(interactive=True)
    assert "\r" in text  # redrawn in place
    final = text.split("\r")[-1]
    assert "study tasks" in final and "200/200" in final and "task/s" in final and "<" in final  # elapsed<left


def test_log_lines_are_whole_lines_at_most_one_per_interval():
    """Not a terminal: no carriage returns, and fast updates within one interval
    give only the opening and the closing line (LOG_INTERVAL_S = 10 s)."""
    text = _draw(interactive=False)
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith("study tasks:") and "0/200" in lines[0] and "200/200" in lines[-1]


def test_log_lines_follow_the_interval(monkeypatch):
    """With the interval at zero every update is a line: the interval is what thins them."""
    monkeypatch.setattr(progress_module, "LOG_INTERVAL_S", 0.0)
    assert len(_draw(interactive=False).splitlines()) > 2


def test_quiet_draws_nothing():
    assert _draw(quiet=True) == "" and _draw(quiet=True, interactive=True) == ""


def test_study_command_reports_progress_on_stderr_and_quiet_silences_it(tmp_path, capsys):
    arguments = ["study", "--reps", "1", "--levels", "2", "--restarts", "0", "--limit-pose-sets", "0", "--workers", "1"]
    assert main(arguments + ["--out", str(tmp_path / "a")]) == 0
    captured = capsys.readouterr()
    assert "study tasks" in captured.err and "study tasks" not in captured.out
    assert main(arguments + ["--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert "study tasks" not in capsys.readouterr().err


@pytest.mark.parametrize("total", [1, 7])
def test_total_is_reached(total):
    stream = io.StringIO()
    with progress_bar("x", stream=stream, interactive=False) as report:
        for done in range(1, total + 1):
            report(done, total)
    assert f"{total}/{total}" in stream.getvalue().splitlines()[-1]
