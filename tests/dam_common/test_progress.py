"""dam_common.progress: a line on stderr every few seconds while a command works."""

from __future__ import annotations

import io
import re
import threading

import pytest

from dam_common.progress import PERIOD_ENV, Progress, current, period_s


def test_lines_come_while_the_work_runs_and_stop_after_it() -> None:
    stream = io.StringIO()
    with Progress('bag plot', 'working', period=0.01, stream=stream) as progress:
        assert current() is progress
        progress.stage('reading messages of grasp', total=400)
        progress.advance(100)
        # wait for the reporting thread's first line (however long the machine takes)
        while progress.lines < 1:
            threading.Event().wait(0.005)
    assert current() is None
    lines = stream.getvalue().splitlines()
    after = len(lines)
    assert re.fullmatch(r'bag plot: reading messages of grasp 100 of 400 \(25 %\), \d+ s',
                        lines[0]), lines
    threading.Event().wait(0.05)
    assert len(stream.getvalue().splitlines()) == after  # the thread ended with the work


def test_stage_end_falls_back_to_the_description_with_a_note() -> None:
    progress = Progress('bag export', 'writing CSV', period=0.0)
    progress.stage('reading messages', total=1_234_567)
    progress.advance(1_000_000)
    assert progress.line().startswith('bag export: reading messages 1,000,000 of 1,234,567 '
                                      '(81 %), ')
    progress.end_stage('read 1,234,567 messages')
    assert re.fullmatch(r'bag export: writing CSV \(read 1,234,567 messages\), \d+ s',
                        progress.line())


def test_period_zero_prints_nothing() -> None:
    stream = io.StringIO()
    with Progress('plan_lift', 'waiting', period=0.0, stream=stream) as progress:
        assert current() is progress
    assert stream.getvalue() == '' and progress.lines == 0


@pytest.mark.parametrize(('text', 'expected'), [('', 5.0), ('0.5', 0.5), ('0', 0.0),
                                                ('-1', 5.0), ('nan', 5.0), ('soon', 5.0)])
def test_the_period_comes_from_the_environment(text: str, expected: float,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(PERIOD_ENV, text)
    assert period_s() == expected
