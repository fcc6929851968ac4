"""Progress lines: stage start/end with counts and time, a rate-limited bar, the heartbeat."""

import io
import time

import pytest

from pipeline import progress


@pytest.fixture
def out(monkeypatch):
    buf = io.StringIO()
    progress.enable(True, buf)
    yield buf
    progress.enable(None, None)


def test_stage_prints_start_and_done_with_items(out):
    with progress.stage("structures") as st:
        for _ in progress.bar(range(5), label="fit"):
            pass
    lines = out.getvalue().splitlines()
    assert lines[0] == "[structures] ..."
    assert lines[-2].startswith("[structures] fit [") and "5/5" in lines[-2]
    assert lines[-1].startswith("[structures] ... done (5 items, ") and lines[-1].endswith(" s)")
    assert st.items == 5


class _Clock:
    """A stand-in for the ``time`` module in :mod:`pipeline.progress`: the test advances it, so a loaded
    machine (whose sleeps overrun) cannot change how many lines a bar prints."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now


def test_bar_prints_at_most_every_interval(out, monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(progress, "time", clock)
    monkeypatch.setattr(progress, "BAR_INTERVAL_S", 0.05)
    monkeypatch.setattr(progress, "HEARTBEAT_S", 100.0)
    with progress.stage("mcmc"):
        for _ in progress.bar(range(20), 20, "steps"):
            clock.now += 0.011
    bars = [line for line in out.getvalue().splitlines() if "steps" in line]
    # 20 items of 11 ms = 0.22 s, at most one line per 50 ms: 4 intermediate lines and the final 20/20
    # (one line per item, the behaviour this guards against, would print 20)
    assert 2 <= len(bars) <= 6 and "20/20" in bars[-1]


def test_heartbeat_breaks_silence(out, monkeypatch):
    monkeypatch.setattr(progress, "HEARTBEAT_S", 0.1)
    with progress.stage("diagnose"):
        deadline = time.monotonic() + 10.0     # a loaded machine may schedule the heartbeat late
        while "still running" not in out.getvalue() and time.monotonic() < deadline:
            time.sleep(0.05)
        silent_for = time.monotonic() - (deadline - 10.0)
    assert "[diagnose] ... still running" in out.getvalue()
    assert silent_for >= 0.1                    # not before HEARTBEAT_S of silence


def test_failed_stage_says_failed(out):
    with pytest.raises(ValueError):
        with progress.stage("x"):
            raise ValueError
    assert "[x] ... failed" in out.getvalue()


def test_silent_under_pytest_by_default(capsys, monkeypatch):
    monkeypatch.delenv("SYSID_PROGRESS", raising=False)
    with progress.stage("quiet"):
        pass
    assert capsys.readouterr().err == ""


def test_a_stage_stopped_by_ctrl_c_says_interrupted_not_failed(out):
    with pytest.raises(KeyboardInterrupt):
        with progress.stage("structures"):
            raise KeyboardInterrupt
    with pytest.raises(ValueError):
        with progress.stage("fit"):
            raise ValueError
    lines = out.getvalue().splitlines()
    assert lines[1].startswith("[structures] ... interrupted (") and lines[3].startswith("[fit] ... failed (")
