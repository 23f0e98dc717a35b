"""evaluate's time left (tssac_core.reporting.progress): a bound from a fitted step cost, not from the rate of finished
missions."""

from __future__ import annotations

import pytest

from tssac_core.reporting.progress import StepCostModel, TimeLeft, format_seconds, progress_bar


def schedule(missions: int, cap: int, ends: list[int]) -> list[tuple[int, int]]:
    """(flying, still flying) per step until the last mission ends; ``ends`` = each mission's last step."""
    steps = []
    for t in range(1, max(ends) + 1):
        flying = sum(e >= t for e in ends)
        steps.append((flying, sum(e > t for e in ends)))
    return steps


def test_the_fit_recovers_overhead_and_share_per_mission():
    model = StepCostModel()
    for running in (100, 100, 60, 20, 5, 1):
        model.add(running, 0.002 + 0.0001 * running)
    assert model.step_s(1) == pytest.approx(0.0021)
    assert model.step_s(50) == pytest.approx(0.007)


def test_time_left_is_a_bound_that_tracks_a_bursty_batch():
    """100 missions: 90 end around step 1,500, a tail of 10 runs to 3,800; a step costs 2 ms + 0.1 ms per mission.
    Once missions have ended, the estimate is never below the truth and never far above it in the tail; a rate of
    finished missions (what tqdm used) says seconds where minutes are left."""
    cap = 4000
    ends = [1400 + i for i in range(90)] + [3800] * 10
    steps = schedule(100, cap, ends)
    cost = [0.002 + 0.0001 * flying for flying, _ in steps]
    truth = [sum(cost[k + 1 :]) for k in range(len(steps))]
    left = TimeLeft(100, cap)
    elapsed = 0.0
    for k, ((flying, still), dt) in enumerate(zip(steps, cost)):
        left.step(flying, still, dt)
        elapsed += dt
        assert left.seconds >= truth[k] - 1e-9
        if k == 1600:  # the burst is over, the tail of 10 flies on
            assert left.seconds <= 1.2 * truth[k]
            finished = 100 - still
            by_mission_rate = elapsed / finished * still
            assert by_mission_rate < 0.3 * truth[k]  # the old estimate: far too short
    assert left.seconds == 0.0


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
