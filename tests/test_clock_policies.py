"""The SITL world's clock policies (sim_vehicles.clock), one per mode, on stand-in links and a stand-in world: when a
step is due, what the world waits for, how the link clock runs, the linger after the end. No sockets: the world runner
that asks these policies is flown end to end in tests/test_sim_vehicles.py."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.autopilot.modes import FlightMode
from sim_vehicles.clock import ClockPolicy, LockstepClock, PacedClock, Phase
from sim_vehicles.clock.policy import KEEPALIVE_S, MAX_CATCHUP_STEPS
from tssac_core.sim.sitl_config import LockstepStart

DT_S = 0.1
START_WALL_S = 100.0


@dataclass
class StandInVehicle:
    armed: bool = False
    mode: FlightMode = FlightMode.MANUAL
    setpoint_timeout_s: float = 3.0
    loop_since_wall_s: float = 0.0
    failsafe: str | None = None

    def enter_failsafe(self, reason: str) -> None:
        self.failsafe = reason


@dataclass
class StandInLink:
    """A vehicle's link as a clock policy sees it: whether it holds the world, whether its client has answered, when
    its link next delivers, and what the policy did with it."""

    vehicle: StandInVehicle = field(default_factory=StandInVehicle)
    in_loop: bool = False
    has_answered: bool = False
    due_s: float | None = None
    snapshots: int = 0
    incoming: int = 0
    flushes: int = 0
    ticks: list[bool] = field(default_factory=list)

    @property
    def holds_world(self) -> bool:
        return self.in_loop and self.vehicle.failsafe is None

    def answered(self) -> bool:
        return self.has_answered

    def next_link_due_s(self) -> float | None:
        return self.due_s

    def process_incoming(self) -> None:
        self.incoming += 1

    def flush(self) -> None:
        self.flushes += 1

    def publish(self, tick: bool = False) -> None:
        self.ticks.append(tick)

    def send_snapshot(self) -> None:
        self.snapshots += 1


class StandInWorld:
    """Steps as the world runner does: sets the policy's simulated time, and its links' clients see the new tick (so
    they have not answered it yet, unless ``answers_ahead``). The mission ends at step ``end_at``."""

    def __init__(
        self, links: list[StandInLink], end_at: int | None = None, answers_ahead: bool = False, dt_s: float = DT_S
    ) -> None:
        self.links = links
        self.dt_s = dt_s
        self.end_at = end_at
        self.answers_ahead = answers_ahead
        self.steps = 0
        self.policy: ClockPolicy | None = None

    def step(self) -> int | None:
        assert self.policy is not None and self.policy.phase is Phase.RUN
        self.steps += 1
        self.policy.at_sim_time(self.steps * self.dt_s)
        for link in self.links:
            link.has_answered = self.answers_ahead
        return self.steps if self.steps == self.end_at else None


def started(
    policy_of: type[PacedClock] | type[LockstepClock],
    links: list[StandInLink],
    world: StandInWorld,
    speedup: float = 1.0,
    start: LockstepStart = LockstepStart.ALL,
    linger_s: float = 1.0,
    hold_start: bool = False,
) -> tuple[ClockPolicy, Clock]:
    """A policy over ``links`` and ``world`` whose loop starts at :data:`START_WALL_S`."""
    clock = Clock(wall_s=START_WALL_S, lockstep=policy_of is LockstepClock)
    policy: ClockPolicy
    if policy_of is LockstepClock:
        policy = LockstepClock(clock, links, world.step, world.dt_s, speedup, start, linger_s)
    else:
        policy = PacedClock(clock, links, world.step, world.dt_s, speedup, start, linger_s, hold_start)
    world.policy = policy
    policy.start(START_WALL_S)
    return policy, clock


def at(policy: ClockPolicy, wall_s: float) -> float | None:
    """One loop iteration's clock work at ``wall_s``: the clock ticks, the due steps are taken."""
    policy.tick(wall_s)
    return policy.advance(wall_s)


# ---------------------------------------------------------------------------------------------- real time


def test_paced_steps_are_due_on_the_real_time_schedule_and_the_link_runs_on_wall_time():
    links = [StandInLink() for _ in range(3)]
    world = StandInWorld(links)
    policy, clock = started(PacedClock, links, world, speedup=10.0)
    assert policy.phase is Phase.RUN and not policy.ticks
    assert at(policy, START_WALL_S) == pytest.approx(START_WALL_S + 0.01)  # step 1 is due dt / speedup later
    assert world.steps == 0
    assert at(policy, START_WALL_S + 0.035) == pytest.approx(START_WALL_S + 0.04)
    assert world.steps == 3 and clock.sim_s == pytest.approx(0.3)
    assert clock.link_s == pytest.approx(0.35)  # wall seconds x speedup, not the steps taken


def test_paced_steps_catch_up_at_most_max_catchup_steps_per_iteration():
    links = [StandInLink()]
    world = StandInWorld(links, dt_s=0.01)
    policy, _ = started(PacedClock, links, world, speedup=1.0)
    late_wall_s = START_WALL_S + 0.5  # 50 steps due (less than the lag at which the schedule is re-anchored)
    assert at(policy, late_wall_s) == late_wall_s  # more are due: no waiting
    assert world.steps == MAX_CATCHUP_STEPS
    assert at(policy, late_wall_s) == late_wall_s and world.steps == 2 * MAX_CATCHUP_STEPS


@pytest.mark.parametrize("start", [LockstepStart.ALL, LockstepStart.ANY])
def test_a_held_real_time_world_starts_when_its_vehicles_are_armed_in_guided(start: LockstepStart):
    links = [StandInLink() for _ in range(3)]
    world = StandInWorld(links)
    policy, _ = started(PacedClock, links, world, speedup=2.0, start=start, hold_start=True)
    assert policy.phase is Phase.HOLD
    assert at(policy, START_WALL_S + 0.5) == START_WALL_S + KEEPALIVE_S  # holding: the next snapshot
    assert at(policy, START_WALL_S + 1.2) == START_WALL_S + 1.2 + KEEPALIVE_S
    assert [link.snapshots for link in links] == [1, 1, 1]
    links[0].vehicle.armed, links[0].vehicle.mode = True, FlightMode.GUIDED
    links[1].vehicle.armed = True  # armed, not in GUIDED
    gate_wall_s = START_WALL_S + 5.0
    next_wall_s = at(policy, gate_wall_s)
    if start is LockstepStart.ALL:
        assert policy.phase is Phase.HOLD
        for link in links[1:]:
            link.vehicle.armed, link.vehicle.mode = True, FlightMode.GUIDED
        next_wall_s = at(policy, gate_wall_s)
    assert policy.phase is Phase.RUN and world.steps == 0
    assert next_wall_s == pytest.approx(gate_wall_s + DT_S / 2.0)  # the schedule starts at the gate


def test_a_real_time_linger_is_paced_and_ends_the_run():
    links = [StandInLink() for _ in range(2)]
    world = StandInWorld(links, end_at=2)
    policy, clock = started(PacedClock, links, world, speedup=1.0, linger_s=0.3)
    at(policy, START_WALL_S + 0.25)
    assert policy.phase is Phase.LINGER and world.steps == 2 and clock.sim_s == pytest.approx(0.2)
    assert at(policy, START_WALL_S + 0.34) == pytest.approx(START_WALL_S + 0.35)  # on the schedule from the end
    assert clock.sim_s == pytest.approx(0.2) and links[0].ticks == []
    assert at(policy, START_WALL_S + 0.36) == pytest.approx(START_WALL_S + 0.45)
    assert clock.sim_s == pytest.approx(0.3) and links[0].ticks == [False]  # one linger step, the world frozen
    assert at(policy, START_WALL_S + 0.6) is None
    assert policy.phase is Phase.DONE and world.steps == 2 and clock.sim_s == pytest.approx(0.5)
    assert links[0].ticks == [False, False, False]


# ------------------------------------------------------------------------------------------------ lockstep


def in_loop(n: int, answered: bool = False) -> list[StandInLink]:
    return [StandInLink(StandInVehicle(True, FlightMode.GUIDED), in_loop=True, has_answered=answered) for _ in range(n)]


@pytest.mark.parametrize("start", [LockstepStart.ALL, LockstepStart.ANY])
def test_a_lockstep_world_holds_until_its_vehicles_hold_the_world_and_its_links_cross_at_once(start: LockstepStart):
    links = [StandInLink(due_s=0.4), StandInLink(), StandInLink(due_s=0.7)]
    world = StandInWorld(links)
    policy, clock = started(LockstepClock, links, world, start=start)
    assert policy.phase is Phase.HOLD and policy.ticks
    assert policy.link_wait_s() == 0.0  # something in flight: the next iteration delivers it
    assert at(policy, START_WALL_S + 0.1) == START_WALL_S + KEEPALIVE_S
    assert clock.link_s == 0.7 and clock.sim_s == 0.0  # fast-forwarded: no simulated time passes
    links[0].in_loop = links[0].has_answered = True
    at(policy, START_WALL_S + 0.2)
    if start is LockstepStart.ALL:
        assert policy.phase is Phase.HOLD
        for link in links[1:]:
            link.in_loop = link.has_answered = True
        at(policy, START_WALL_S + 0.2)
    assert policy.phase is Phase.RUN and world.steps == 1
    assert [link.flushes for link in links] == [1, 1, 1]  # the last answers cross before step 1
    assert [link.incoming for link in links] == [2, 2, 2]  # then what arrives at step 1 is read


def test_a_lockstep_world_steps_when_every_vehicle_in_the_loop_has_answered():
    links = in_loop(3, answered=True)
    links[2].in_loop = False  # out of the loop: never waited for
    world = StandInWorld(links)
    policy, clock = started(LockstepClock, links, world, start=LockstepStart.ANY)
    assert at(policy, START_WALL_S) == START_WALL_S + 3.0  # one step, then the first silence deadline
    assert world.steps == 1 and clock.sim_s == pytest.approx(DT_S) and clock.link_s == pytest.approx(DT_S)
    links[0].has_answered = True
    assert at(policy, START_WALL_S + 0.5) == START_WALL_S + 1.0  # waiting for links[1]: the next snapshot first
    assert world.steps == 1 and clock.link_s == pytest.approx(DT_S)  # the link clock stands still at the barrier
    links[1].has_answered = True
    at(policy, START_WALL_S + 0.6)
    assert world.steps == 2 and clock.link_s == pytest.approx(2 * DT_S)


def test_a_lockstep_world_steps_on_while_the_answers_already_answer_the_new_step():
    links = in_loop(2, answered=True)
    world = StandInWorld(links, answers_ahead=True)
    policy, _ = started(LockstepClock, links, world)
    assert at(policy, START_WALL_S) == START_WALL_S  # more steps may be due: no waiting
    assert world.steps == MAX_CATCHUP_STEPS
    assert [link.incoming for link in links] == [MAX_CATCHUP_STEPS] * 2  # at the gate, then at each step but the last


def test_a_vehicle_silent_for_its_setpoint_timeout_of_wall_time_fails_safe_and_no_longer_holds_the_world():
    links = in_loop(2, answered=True)
    world = StandInWorld(links)
    policy, _ = started(LockstepClock, links, world)
    at(policy, START_WALL_S)  # step 1; nobody has answered it
    links[0].has_answered = True
    assert at(policy, START_WALL_S + 2.9) == pytest.approx(START_WALL_S + 3.0)
    assert links[1].vehicle.failsafe is None and world.steps == 1
    at(policy, START_WALL_S + 3.1)
    assert links[1].vehicle.failsafe == "no setpoint for 3 s wall"
    assert world.steps == 2  # the others step on without it


def test_a_lockstep_world_with_nobody_in_the_loop_runs_paced_with_the_link_on_wall_time():
    links = in_loop(2, answered=True)
    world = StandInWorld(links)
    policy, clock = started(LockstepClock, links, world, speedup=2.0)
    at(policy, START_WALL_S)
    for link in links:
        link.vehicle.enter_failsafe("test")
    assert at(policy, START_WALL_S + 1.0) == pytest.approx(START_WALL_S + 1.0 + DT_S / 2.0)
    assert world.steps == 1  # the schedule counts from here
    at(policy, START_WALL_S + 1.2)
    assert world.steps == 1 + 4 and clock.link_s == pytest.approx(DT_S + 0.2 * 2.0)


def test_a_lockstep_linger_runs_at_once_each_step_with_its_tick_and_the_link_on_simulated_time():
    links = in_loop(3, answered=True)
    world = StandInWorld(links, end_at=1)
    policy, clock = started(LockstepClock, links, world, linger_s=1.0)
    assert at(policy, START_WALL_S) == START_WALL_S  # the mission ended: no waiting before its linger
    assert policy.phase is Phase.LINGER and policy.link_wait_s() is None
    assert at(policy, START_WALL_S) is None
    assert policy.phase is Phase.DONE and world.steps == 1
    assert clock.sim_s == pytest.approx(1.1) and clock.link_s == pytest.approx(1.1)
    assert links[0].ticks == [True] * 10
