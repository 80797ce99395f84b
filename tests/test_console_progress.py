"""Progress in a log (stderr not a terminal): lines at every tenth and at least every so often
for item batches (`count_bar`); for staged computations (`stage_bars`) nothing while short, then
lines at tenths, at most one every few seconds, at least one every half minute."""

from __future__ import annotations

import pytest

import wtcli.console as C


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def log(monkeypatch, capsys):
    clock = Clock()
    monkeypatch.setattr(C.time, "monotonic", clock)
    monkeypatch.setattr(type(C.err_console), "is_terminal", property(lambda self: False))
    return clock, lambda: [ln for ln in capsys.readouterr().err.splitlines() if ln]


def test_a_short_staged_computation_says_nothing_in_a_log(log):
    clock, lines = log
    with C.stage_bars({"turbines": "trajectories"}, "plan") as progress:
        for k in range(41):
            progress("turbines", k, 40)
            clock.t += 0.2  # 8 s in all, under LOG_QUIET_S
    assert lines() == []


def test_a_long_staged_computation_says_where_it_is(log):
    clock, lines = log
    with C.stage_bars({"turbines": "trajectories", "coverage": "coverage check"}, "plan") as progress:
        for k in range(101):
            progress("turbines", k, 100)
            clock.t += 1.0  # 100 s
        for k in range(3):
            progress("coverage", k, 2)
            clock.t += 40.0  # one slow job after another
    got = lines()
    assert got[0] == "plan: trajectories: 10/100 (10 %), 10 s"  # after LOG_QUIET_S
    assert all(ln.startswith("plan: trajectories: ") for ln in got[:-2])
    assert len(got) - 2 == 10  # 10 %, 20 %, ... 100 %
    assert got[-2:] == ["plan: coverage check: 1/2 (50 %), 40 s",
                        "plan: coverage check: 2/2 (100 %), 80 s"]


def test_a_large_batch_in_a_log_says_where_it_is_at_least_every_minute(log):
    clock, lines = log
    with C.count_bar("segment", 5000) as advance:
        for k in range(700):
            clock.t += 4.3  # a 12 MP photo on a 2-core CPU
            advance(f"p{k}.jpg ok")
    got = lines()
    # A tenth is 500 photos (36 min): besides it, a line once 60 s have passed (14 photos).
    done = [int(ln.split()[1].split("/")[0]) for ln in got]
    assert done[0] == 14 and 500 in done and done[-1] == 696
    assert all(0 < b - a <= 14 for a, b in zip(done, done[1:]))
    assert got[-1] == "segment: 696/5000 (14 %), 2993 s, 4.30 s each, last: p695.jpg ok"
