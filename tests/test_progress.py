"""evaluate's time left (tssac_core.sim.time_left; the bars: tssac_core.reporting.progress): the mean step after the
first times the steps left to the cap, not the rate of finished missions; for shards flown at once, the largest."""

from __future__ import annotations

import time

import pytest

from tssac_core.reporting.progress import ShardsBar, format_seconds, progress_bar
from tssac_core.sim.time_left import MIN_TIMED_STEPS, ShardProgress, TimeLeft


def schedule(ends: list[int]) -> list[tuple[int, int]]:
    """(flying, still flying) per step until the last mission ends; ``ends`` = each mission's last step."""
    steps = []
    for t in range(1, max(ends) + 1):
        flying = sum(e >= t for e in ends)
        steps.append((flying, sum(e > t for e in ends)))
    return steps


def test_time_left_leaves_out_the_first_step_and_tracks_a_bursty_batch():
    """100 missions: 90 end around step 1,500, a tail of 10 runs to the cap; the first step costs 30 s (every
    layout's route fields), the others 10 ms +- 40%. The estimate is unknown until MIN_TIMED_STEPS more are timed,
    then within 1.5x of the truth at every step, 0 at the end; a rate of finished missions (what tqdm used) says
    seconds where minutes are left."""
    cap = 4000
    ends = [1400 + i for i in range(90)] + [cap] * 10
    steps = schedule(ends)
    cost = [30.0] + [0.01 * (1.0 + 0.4 * ((k * 7919) % 11 - 5) / 5) for k in range(1, len(steps))]
    truth = [sum(cost[k + 1 :]) for k in range(len(steps))]
    left = TimeLeft(100, cap)
    assert left.seconds is None
    elapsed = 0.0
    for k, ((flying, still), dt) in enumerate(zip(steps, cost)):
        left.step(flying, still, dt)
        elapsed += dt
        if k < MIN_TIMED_STEPS:
            assert left.seconds is None  # the first step says nothing of the others, nor do a few after it
        elif k < len(steps) - 1:
            assert left.seconds is not None and truth[k] / 1.5 <= left.seconds <= 1.5 * truth[k], k
        if k == 1600:  # the burst is over, the tail of 10 flies on
            by_mission_rate = elapsed / (100 - still) * still
            assert by_mission_rate < 0.5 * truth[k]
    assert left.seconds == 0.0


def test_shards_flown_at_once_have_the_largest_time_left_of_theirs():
    with ShardsBar(10, 2) as bar:
        bar.update(ShardProgress(0, 1, 40.0))
        assert bar.seconds(time.perf_counter()) is None  # shard 1 has not said yet
        bar.update(ShardProgress(1, 2, None))
        assert bar.seconds(time.perf_counter()) is None  # nor does it know yet
        bar.update(ShardProgress(1, 0, 60.0))
        now = time.perf_counter()
        assert bar.seconds(now) == pytest.approx(60.0, abs=0.1)
        assert bar.seconds(now + 30.0) == pytest.approx(30.0, abs=0.1)  # each less the time since it came
        assert bar.seconds(now + 90.0) == 0.0
        bar.update(ShardProgress(1, 7, 0.0))
        assert bar.bar.n == 10


def test_format_seconds():
    assert [format_seconds(s) for s in (11.4, 185, 3723)] == ["11 s", "3:05", "1:02:03"]


def test_log_lines_print_above_the_bar_not_on_its_line(capsys):
    """A log line written while a bar is open (fly's "mission 0: started") gets a line of its own: after the bar's last
    carriage return on each line of stderr comes either the bar or the log line, never the bar then the log line."""
    import logging
    import sys

    root = logging.getLogger()
    console = logging.StreamHandler(sys.stderr)  # what basicConfig makes, on the captured stderr
    console.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    root.addHandler(console)
    old_level = root.level
    root.setLevel(logging.INFO)
    try:
        with progress_bar(total=3, desc="missions", mininterval=0) as bar:
            bar.update(1)
            logging.getLogger("tssac.test").info("mission 1: started")
            bar.update(2)
    finally:
        root.removeHandler(console)
        root.setLevel(old_level)
    lines = capsys.readouterr().err.split("\n")
    shown = [line.split("\r")[-1] for line in lines]  # what a terminal shows of each line
    assert "INFO tssac.test: mission 1: started" in shown
    assert not any("missions" in line and "INFO" in line for line in shown)
    assert any(line.startswith("missions: 100%") for line in shown)  # the bar is still drawn, and finished
