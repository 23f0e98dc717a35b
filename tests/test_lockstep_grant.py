"""The lockstep grant (tssac_core.wire.lockstep): a companion answers a lockstep world only when its setpoint may
change, and the world flies the same missions as with an answer at every tick."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from sitl_helpers import GUIDED, REPO, Client, lockstep, mavlink2, sitl
from test_mission_reset import _fly_json, _steps

from mavlink_bridge.companion.cli import main as companion_main
from mavlink_bridge.fly.config import config_from_args
from tssac_core.common.cli import UsageError
from tssac_core.sim.scenario import dump, load
from tssac_core.wire.lockstep import GRANT_NAME, granted_through_ms

RANDOM = REPO / "scenarios" / "random.yaml"
M = mavlink2


def test_a_grant_reaches_the_tick_before_the_next_change_within_the_longest_grant() -> None:
    assert granted_through_ms(1000, 100, 2000, 1000) == 1900  # a decision every 10 ticks: the 9 between
    assert granted_through_ms(1000, 100, 2000, 500) == 1500  # no further than the longest grant
    assert granted_through_ms(1000, 100, 2000, 550) == 1500  # on the tick grid
    assert granted_through_ms(1000, 100, 1100, 1000) is None  # the next tick may change: answer it
    assert granted_through_ms(1000, 100, 5000, 0) is None  # no grants


def _setpoint(c: Client, stamp_ms: int) -> mavlink2.MAVLink_message:
    return c.mav.set_position_target_local_ned_encode(
        stamp_ms, 0, 0, M.MAV_FRAME_BODY_FRD, 1087, 0, 0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0.0
    )


def _grant(c: Client, stamp_ms: int, through_ms: int) -> mavlink2.MAVLink_message:
    return c.mav.named_value_int_encode(stamp_ms, GRANT_NAME.encode(), through_ms)


def _ticks_until_quiet(c: Client, quiet_s: float) -> list[int]:
    """The step ticks (SYSTEM_TIME) that arrive until none has for ``quiet_s``."""
    ticks = []
    while (m := c.wait(lambda m: m.get_type() == "SYSTEM_TIME", quiet_s)) is not None:
        if not ticks or m.time_boot_ms > ticks[-1]:
            ticks.append(m.time_boot_ms)
    return ticks


@pytest.mark.timeout(60)
def test_a_lockstep_world_steps_through_the_ticks_a_setpoint_grants_and_waits_after_them() -> None:
    with sitl(**lockstep(setpoint_timeout_s=30.0)) as s, Client(s.ports[0]) as c:
        c.connect()
        c.arm()
        c.set_mode(GUIDED)
        vehicle = s.vehicle(0)
        # A setpoint for tick 0 granting the ticks up to 0.4 s: five steps (to the tick 0.5 s), then the world waits.
        # The granted ticks' telemetry leaves with the tick's it waits at: one datagram (COALESCE_BYTES permitting).
        datagrams = s.endpoint(0).tx.packets
        c.send_together(_setpoint(c, 0), _grant(c, 0, 400))
        assert _ticks_until_quiet(c, 0.5) == [100, 200, 300, 400, 500]
        assert int(s.runner.world.steps[0]) == 5
        assert s.endpoint(0).tx.packets - datagrams <= 2
        # A grant on its own, or beside a setpoint stamped otherwise, answers nothing: the setpoint alone steps once.
        c.send_together(_grant(c, 500, 900))
        assert _ticks_until_quiet(c, 0.4) == []
        c.send_together(_setpoint(c, 500), _grant(c, 400, 900))
        assert _ticks_until_quiet(c, 0.5) == [600]
        # The flown setpoint holds through the granted ticks: the vehicle speeds up at 1 m/s^2 at every step.
        speed_before = vehicle.truth.speed_m_s
        c.send_together(_setpoint(c, 600), _grant(c, 600, 900))
        assert _ticks_until_quiet(c, 0.5) == [700, 800, 900, 1000]
        assert vehicle.truth.speed_m_s == pytest.approx(speed_before + 4 * 1.0 * 0.1, abs=1e-6)
        assert vehicle.counters.setpoints_accepted == 3 and not vehicle.failsafe
        s.stop()


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_grants_fly_the_missions_of_an_answer_at_every_tick_also_with_gps_dropouts_and_latency(tmp_path: Path) -> None:
    """The shipped team through the monitor, over a link that loses no frame but drops GPS fixes and delays
    everything 50 ms: a gap in the fixes cuts a grant short before the hold could fire, so the flight is the same."""
    base = load(RANDOM)
    link = dataclasses.replace(base.link, gps_dropout_prob=0.3, latency_ms=50.0)
    scenario = tmp_path / "dropouts.yaml"
    # Each mission cut at 60 s of flight (600 steps; a whole one is 250 s): the step-by-step comparison and the
    # counters' proportions do not depend on its length.
    dump(dataclasses.replace(base, name="dropouts", link=link, episode_steps=600), scenario)
    every = _fly_json(tmp_path, "every", "--shield", "--lockstep-grant-s", "0", scenario=scenario, episodes=1, seed=41)
    granted = _fly_json(tmp_path, "granted", "--shield", scenario=scenario, episodes=1, seed=41)
    steps = _steps(tmp_path / "granted" / "mission-000" / "truth.jsonl")
    assert len(steps) > 100 and steps == _steps(tmp_path / "every" / "mission-000" / "truth.jsonl")
    for role, status in granted["missions"][0]["companions"].items():
        counters, before = status, every["missions"][0]["companions"][role]
        assert before["ticks_granted"] == 0 and before["setpoints_sent"] >= before["control_steps"]
        assert counters["control_steps"] == before["control_steps"], role
        assert counters["ticks_granted"] > counters["control_steps"] // 2, role  # most ticks were granted ...
        assert counters["setpoints_sent"] + counters["ticks_granted"] == counters["control_steps"], role
        # ... and the dropouts cut grants short: more answers than the decisions (one in 10 ticks)
        assert counters["setpoints_sent"] > counters["control_steps"] // 10 + 1, role


@pytest.mark.parametrize("value", ["-0.1", "nan", "inf", "60.5", "1e308"])
def test_a_bad_grant_is_one_clear_line_in_both_commands(value: str, capsys: pytest.CaptureFixture[str]) -> None:
    says = f"--lockstep-grant-s must be 0 to 60 seconds, got {float(value):g}"
    strike = str(REPO / "scenarios" / "strike.yaml")
    with pytest.raises(UsageError, match=re.escape(says)):
        config_from_args(["--scenario", strike, "--lockstep-grant-s", value])
    argv = ["--connect", "udpout:127.0.0.1:9", "--role", "strike", "--scenario", strike, "--pilot", "guidance"]
    assert companion_main([*argv, "--lockstep-grant-s", value]) == 2
    assert capsys.readouterr().err.strip().endswith(says)
