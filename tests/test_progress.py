"""The progress line (issue 30 item 6): an ETA from the pace so far (an injected clock, no
sleeps), and ``evaluate``'s bar over all of its work (it used to end before the rig's
recordings, the first stages and the report: 0.2 s of a 36.9 s cold run)."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from pipeline.progress import ETA_AFTER_S, Progress, eta_seconds, format_eta


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class _Clock:
    """Seconds set by the test."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize(
    ("seconds", "text"),
    [
        (0.0, "ETA 0 s"),
        (0.2, "ETA 1 s"),  # rounded up: never "0 s" while work remains
        (42.0, "ETA 42 s"),
        (59.5, "ETA 1 min 00 s"),
        (185.0, "ETA 3 min 05 s"),
        (3599.0, "ETA 59 min 59 s"),
        (3600.0, "ETA 1 h 00 min"),
        (7625.0, "ETA 2 h 08 min"),  # 127.08 min, rounded up
    ],
)
def test_format_eta(seconds: float, text: str) -> None:
    assert format_eta(seconds) == text


def test_eta_is_the_pace_so_far_once_a_step_is_done_and_a_second_passed() -> None:
    assert eta_seconds(0, 10, 30.0) is None  # no step done: no pace
    assert eta_seconds(3, 10, ETA_AFTER_S / 2) is None  # too early to say
    assert eta_seconds(4, 10, 20.0) == pytest.approx(30.0)  # 5 s a step, 6 to go
    assert eta_seconds(10, 10, 50.0) is None  # done


def test_the_bar_shows_the_eta_and_ends_with_the_elapsed_time() -> None:
    clock, term = _Clock(), _Terminal()
    bar = Progress("study", 4, term, unit="batches", clock=clock)
    clock.now += 0.5
    bar.step()
    assert "ETA" not in term.getvalue()  # half a second: no ETA yet
    clock.now += 9.5
    bar.step()  # 10 s for 2 batches: 10 s to go
    assert term.getvalue().split("\r")[-1] == (
        f"{'study':14s} [{'#' * 15}{'.' * 15}] 2/4 batches   10.0 s  ETA 10 s"
    )
    clock.now += 5.0
    bar.step()
    clock.now += 5.0
    bar.step()
    *_, before, last = term.getvalue().split("\r")
    assert last.startswith(f"{'study':14s} [{'#' * 30}] 4/4 batches   20.0 s")
    assert "ETA" not in last and last.endswith("\n")
    assert "ETA" in before and len(last) - 1 >= len(before.rstrip())  # blanks over the ETA


def test_a_log_file_gets_the_final_line_without_an_eta() -> None:
    clock, log = _Clock(), io.StringIO()
    bar = Progress("fleet identify", 3, log, unit="sessions", clock=clock)
    for _ in range(3):
        clock.now += 2.0
        bar.step()
    assert log.getvalue() == f"{'fleet identify':14s} [{'#' * 30}] 3/3 sessions    6.0 s\n"


def test_evaluate_bar_covers_the_recordings_the_stages_and_the_report(
    identified_session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The rig's recordings and the report happen while the bar is short of its end."""
    import pipeline.evaluate as ev
    import pipeline.rig.evaluation as rig

    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    term = _Terminal()
    seen: list[tuple[str, str]] = []  # (what, the line drawn when it started)

    def spy(name: str, fn):
        def wrapped(*args, **kwargs):
            seen.append((name, term.getvalue().split("\r")[-1]))
            return fn(*args, **kwargs)

        return wrapped

    monkeypatch.setattr(rig, "record_evaluation", spy("record", rig.record_evaluation))
    monkeypatch.setattr(ev, "_report_if_stale", spy("report", ev._report_if_stale))
    ev.evaluate(d, progress=term)
    total = 2 + 2 + 4 + 1  # teach and program recorded, 2 + 4 stages, the report
    (_, teach), (_, program), (_, report) = seen
    assert [name for name, _ in seen] == ["record", "record", "report"]
    assert teach.startswith("identify ")  # the evaluate bar starts with the teaching
    assert program.startswith("evaluate ") and f" 3/{total} steps" in program
    assert f" {total - 1}/{total} steps" in report
    assert term.getvalue().endswith("\n") and f"{total}/{total} steps" in term.getvalue()
    assert term.getvalue().count("\n") == 2  # identify's line, then evaluate's
