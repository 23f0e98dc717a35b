"""Fly whole three-UAV missions in the batched world and score them.

Every mission draws its layout from its own seed: mission ``k`` of a run seeded ``S`` is
``sample_layout(scenario, numpy.random.default_rng(S + k))``, the same rule as ``mavlink_bridge.fly`` and the
SITL world, so any one mission can be flown again alone (``--seed S --mission k``, or ``--seed S+k --mission 0``),
in either world, and a run can be split by mission index (shards) without changing any mission.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field

import numpy as np

from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.evaluation_record import (
    EvaluationRecord,
    RoleFigures,
    RoleMonitorFigures,
    WorldMonitorFigures,
)
from tssac_core.common.stats import (
    bootstrap_mean_interval,
    cvar,
    wilson_interval,
    worst_missions,
)
from tssac_core.sim.lagged_starts import varied_start_check
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilot_view import PilotView
from tssac_core.sim.pilots import PilotSpec, decision_interval
from tssac_core.sim.reward import RewardConfig, reward
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import ROLES, Layout, Scenario, StartCheck, sample_layout
from tssac_core.sim.team import Team
from tssac_core.sim.varied_airframes import AirframeVariation, VariedAirframes
from tssac_core.sim.world import World
from tssac_core.sim.world_monitor import DecisionError, MonitorCounts, WorldMonitor
from tssac_core.sim.world_state import snapshot

WORST_MISSIONS = 10
"""How many of the costliest UAV-missions a summary lists."""


def mission_seed(seed: int, index: int) -> int:
    """The seed of mission ``index``'s layout in a run seeded ``seed``."""
    return seed + index


def mission_layout(
    scenario: Scenario, seed: int, index: int, shield: ShieldConfig | None = None, starts: StartCheck | None = None
) -> Layout:
    """The layout of mission ``index``: the scenario's fixed one, or a draw from its own seed (module docstring), its
    starts admitted by the monitor with ``shield``'s margins (default :class:`ShieldConfig`) and by ``starts``, the
    further check of a monitor that predicts with the airframes the mission flies."""
    return sample_layout(scenario, np.random.default_rng(mission_seed(seed, index)), shield=shield, start_check=starts)


@dataclass
class MissionResults:
    """Per-mission outcomes, arrays over missions (M,) or missions x roles (M, 3)."""

    success: np.ndarray
    cost: np.ndarray
    returns: np.ndarray
    task_done: np.ndarray
    time_s: np.ndarray
    """Mission time (simulated seconds)."""
    out_of_area: np.ndarray
    """The UAV flew out of the area, which ended its mission, (M, 3) bool."""
    layouts: list[Layout] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    """Each mission's layout seed (`mission_seed`), when its layout came from one."""
    indices: list[int] = field(default_factory=list)
    """Each mission's index in its run (``--mission``), when its layout came from a seed."""
    trajectories: np.ndarray | None = None
    """(M, T, 3, 2) positions in metres if recorded (NaN after a mission ended)."""
    monitor: MonitorCounts | None = None
    """The runtime-assurance monitor's counts per mission and UAV, when it flew (``shield``)."""
    backup_track: np.ndarray | None = None
    """(M, T, 3) bool: the backup flew that step, if recorded with the monitor."""

    def record(self, cost_limit: float) -> EvaluationRecord:
        """The figures: the success rate with its 95% Wilson interval, the mean cost (per UAV per episode) with its 95%
        bootstrap interval over missions, per role the tail (within C, worst, CVaR_0.95), the costliest UAV-missions
        (:mod:`tssac_core.common.stats`), and the monitor's figures when it flew."""
        roles = {
            role.value: RoleFigures(
                mean_cost=float(self.cost[:, j].mean()),
                max_cost=float(self.cost[:, j].max()),
                within_cost_limit=float((self.cost[:, j] <= cost_limit).mean()),
                cvar95_cost=cvar(self.cost[:, j]),
                task_success_rate=float(self.task_done[:, j].mean()),
                left_area_rate=float(self.out_of_area[:, j].mean()),
                mean_return=float(self.returns[:, j].mean()),
            )
            for j, role in enumerate(ROLES)
        }
        rate = wilson_interval(int(self.success.sum()), int(len(self.success)))
        mean = bootstrap_mean_interval(self.cost)
        worst = worst_missions(self.cost, self.seeds, [r.value for r in ROLES], WORST_MISSIONS) if self.seeds else []
        return EvaluationRecord(
            success_rate=float(self.success.mean()),
            success_interval95=(rate.low, rate.high),
            mean_cost=float(self.cost.mean()),
            mean_cost_interval95=(mean.low, mean.high),
            episodes=int(len(self.success)),
            mean_mission_time_s=float(self.time_s.mean()),
            roles=roles,
            worst_missions=[dataclasses.replace(w, mission=self.indices[w.mission]) for w in worst],
            monitor=None if self.monitor is None else monitor_figures(self.monitor, self.cost, self.out_of_area),
        )


def monitor_figures(counts: MonitorCounts, cost: np.ndarray, out_of_area: np.ndarray) -> WorldMonitorFigures:
    """The monitor's figures: interventions per UAV-mission, the fraction of flight time under the backup,
    and the hazards that the guarantee is about (UAV-missions with any cost, UAVs that left the area)."""
    flown = counts.flown_steps.sum()
    roles = {
        role.value: RoleMonitorFigures(
            interventions_per_mission=float(counts.interventions[:, j].mean()),
            backup_time_fraction=float(counts.backup_steps[:, j].sum() / max(1, counts.flown_steps[:, j].sum())),
        )
        for j, role in enumerate(ROLES)
    }
    return WorldMonitorFigures(
        interventions_per_uav_mission=float(counts.interventions.mean()),
        max_interventions_per_uav_mission=int(counts.interventions.max()),
        max_switches_per_uav_mission=int(counts.switches.max()),
        backup_time_fraction=float(counts.backup_steps.sum() / max(1, flown)),
        adjusted_time_fraction=float(counts.adjusted_steps.sum() / max(1, flown)),
        held_time_fraction=float(counts.held_steps.sum() / max(1, flown)),
        unprotected_time_fraction=float(counts.unprotected_steps.sum() / max(1, flown)),
        uav_missions_with_cost=int((cost > 0).sum()),
        uavs_left_area=int(out_of_area.sum()),
        roles=roles,
    )


def hold_nonfinite(actions: np.ndarray) -> np.ndarray:
    """The actions (N, 3, 2) with every UAV whose action is not finite given the hold [0, 0] (no turn, no
    acceleration), as a companion computer's failsafe does (``mavlink_bridge.companion``). Without it a NaN
    action (a policy with NaN weights, the ``nan`` adversary) would make the UAV's state NaN, which no radar
    and no edge ever counts. With the monitor on, the monitor has already put its backup there."""
    finite = np.isfinite(actions).all(axis=-1, keepdims=True)
    return actions if finite.all() else np.where(finite, actions, 0.0)


AIRFRAME_STREAM = 58
"""The random stream of the varied airframes of a run (``default_rng([seed, AIRFRAME_STREAM])``): apart from the
layouts' and the pilots'."""


def fly_missions(
    scenario: Scenario,
    pilots: Sequence[PilotSpec],
    episodes: int,
    seed: int,
    mode: ObservationMode = ObservationMode.EXTENDED,
    record: bool = False,
    progress: Callable[[int], None] | None = None,
    layouts: list[Layout] | None = None,
    indices: Sequence[int] | None = None,
    shield: ShieldConfig | None = None,
    on_step: Callable[[int, int], None] | None = None,
    start_check: ShieldConfig | None = None,
    airframes: AirframeVariation | None = None,
    monitor_sees_airframes: bool = True,
    loiter: LoiterBound | None = None,
    decision_error: DecisionError | None = None,
) -> MissionResults:
    """Fly missions at once (one world each): missions ``indices`` (default ``range(episodes)``) of the run
    seeded ``seed``, each on its own layout (`mission_layout`), or the given ``layouts``.

    ``pilots`` gives one pilot per role (see :mod:`tssac_core.sim.team`); a callable without ``observation_mode`` and
    ``action_repeat`` attributes sees ``mode`` and decides every step: a policy trained elsewhere is stated and
    checked first (:mod:`tssac_core.deploy.any_policy`, ``tssac_core.evaluate.evaluate_policy``). ``progress`` is
    called with the number of missions that finished since the last call, ``on_step`` after every step of the batch
    with the missions that flew it and those still flying (:class:`tssac_core.reporting.progress.TimeLeft`).
    ``shield``: fly every UAV through the runtime-assurance monitor (:mod:`tssac_core.assurance.monitor`) with these
    margins.
    ``start_check``: the margins the drawn starts are admitted with (default: ``shield``'s, else the default ones).
    ``airframes``: the vehicles fly airframes drawn from these ranges (:mod:`tssac_core.sim.varied_airframes`, seeded
    from ``seed``), and the monitor predicts with each one's lag (``monitor_sees_airframes`` False: with eq. 5, the
    negative control); None: eq. 5-6. ``loiter``: with them, the monitor's backups end in the ground loiter that this
    bounds (the wind's backup, :mod:`tssac_core.assurance.ground_loiter`; e.g.
    :meth:`~tssac_core.sim.varied_airframes.AirframeVariation.loiter_bound`), not in a constant turn.
    ``decision_error``: the monitor keeps this error bound off every decision's clearance, as a companion deciding from
    its filter's estimate would (:class:`~tssac_core.sim.world_monitor.DecisionError`; None: the true state's 0).
    """
    missions = iter_missions(
        scenario,
        pilots,
        episodes,
        seed,
        mode,
        record,
        layouts,
        indices,
        shield,
        on_step,
        start_check,
        airframes,
        monitor_sees_airframes,
        loiter,
        decision_error,
    )
    try:
        while True:
            finished = next(missions)
            if progress is not None:
                progress(finished)
    except StopIteration as end:
        results: MissionResults = end.value
        return results


def world_monitor(
    world: World,
    pilots: Sequence[PilotSpec],
    shield: ShieldConfig,
    airframes: VariedAirframes | None,
    loiter: LoiterBound | None,
    decision_error: DecisionError | None = None,
) -> WorldMonitor:
    """The monitor of a batch of missions: deciding at each pilot's decisions, predicting with the ``airframes`` the
    vehicles fly (None: eq. 5), its backups ending in the ground loiter ``loiter`` bounds where it sees them, keeping
    ``decision_error`` off its clearance."""
    repeats = [decision_interval(p) for p in pilots]
    seen_loiter = loiter if airframes is not None else None
    return WorldMonitor(world, repeats, shield, airframes, seen_loiter, decision_error)


def _varied_airframes(
    world: World, airframes: AirframeVariation | None, seed: int
) -> tuple[VariedAirframes | None, np.random.Generator]:
    """The missions' airframes drawn from ``airframes`` (None: eq. 5-6 exactly) and the stream that shapes their
    actions, both from the run's seed."""
    rng = np.random.default_rng([seed, AIRFRAME_STREAM])
    if airframes is None:
        return None, rng
    varied = VariedAirframes(airframes, world)
    varied.reset(np.arange(world.n), rng)
    return varied, rng


def _admit_starts(
    scenario: Scenario,
    seed: int,
    index_list: list[int],
    layouts: list[Layout],
    world: World,
    varied: VariedAirframes,
    loiter: LoiterBound | None,
    shield: ShieldConfig,
    active: tuple[bool, ...],
) -> None:
    """Draw again, in place, each layout whose starts the monitor predicting with its mission's airframes and wind
    cannot protect (:func:`tssac_core.sim.lagged_starts.varied_start_check`): from the mission's own seed, the next
    draw both checks admit. The airframes and winds are drawn after the layouts and do not depend on them."""
    for i, k in enumerate(index_list):
        check = varied_start_check(scenario, world, varied, loiter, i, shield)
        if check(layouts[i]) is not None:
            layouts[i] = mission_layout(scenario, seed, k, shield, check)
            world.reset([i], [layouts[i]], active)


def iter_missions(
    scenario: Scenario,
    pilots: Sequence[PilotSpec],
    episodes: int,
    seed: int,
    mode: ObservationMode = ObservationMode.EXTENDED,
    record: bool = False,
    layouts: list[Layout] | None = None,
    indices: Sequence[int] | None = None,
    shield: ShieldConfig | None = None,
    on_step: Callable[[int, int], None] | None = None,
    start_check: ShieldConfig | None = None,
    airframes: AirframeVariation | None = None,
    monitor_sees_airframes: bool = True,
    loiter: LoiterBound | None = None,
    decision_error: DecisionError | None = None,
) -> Generator[int, None, MissionResults]:
    """:func:`fly_missions` as a generator: it yields the number of missions that finished whenever some did, and
    returns the results (``yield from`` hands them on; a Ray task streams the counts to its driver)."""
    seeds: list[int] = []
    index_list: list[int] = []
    if layouts is None:
        index_list = list(range(episodes) if indices is None else indices)
        seeds = [mission_seed(seed, k) for k in index_list]
        check = start_check if start_check is not None else shield
        layouts = [mission_layout(scenario, seed, k, check) for k in index_list]
    world = World(scenario, len(layouts))
    active = tuple(p is not None for p in pilots)
    world.reset(np.arange(len(layouts)), layouts, active)
    returns = np.zeros((world.n, len(ROLES)))
    out = np.zeros((world.n, len(ROLES)), dtype=bool)
    track: list[np.ndarray] = []
    cfg = RewardConfig()
    team = Team(pilots, mode, PilotView.asked_by(shield))
    # The reward's route fields are the route observation's when the pilots see the truth: one field per layout.
    routes = team.routes if team.view.is_truth else RouteMap()
    varied, airframe_rng = _varied_airframes(world, airframes, seed)
    seen = varied if monitor_sees_airframes else None
    if shield is not None and seen is not None and index_list:
        _admit_starts(scenario, seed, index_list, layouts, world, seen, loiter, check or ShieldConfig(), active)
    monitor = None if shield is None else world_monitor(world, pilots, shield, seen, loiter, decision_error)
    backup_track: list[np.ndarray] = []
    while world.running.any():
        if record:
            pos = np.stack([world.x_m, world.y_m], axis=-1)
            track.append(np.where(world.running[:, None, None], pos, np.nan))
        moving = world.active & world.running[:, None]
        was_running = world.running.copy()
        detour_prev = routes.detour_m(snapshot(world))
        actions = team.actions(world)
        if monitor is not None:
            actions = monitor.actions(world, actions)
            if record:
                backup_track.append(monitor.engaged & moving)
        actions = hold_nonfinite(actions)
        if varied is not None:
            actions = varied.shape(actions, airframe_rng)
        result = world.step(actions)
        returns += reward(result, moving, cfg, detour_prev, routes.detour_m(snapshot(world)))
        out |= result.out_of_area
        finished = int((was_running & ~world.running).sum())
        if on_step is not None:
            flying = int(was_running.sum())
            on_step(flying, flying - finished)
        if finished:
            yield finished
    return MissionResults(
        success=world.hit.copy(),
        cost=world.cost_total.copy(),
        returns=returns,
        task_done=world.task_done.copy(),
        time_s=world.steps * scenario.dt_s,
        out_of_area=out,
        layouts=layouts,
        seeds=seeds,
        indices=index_list,
        trajectories=np.stack(track, axis=1) if record else None,
        monitor=None if monitor is None else monitor.counts,
        backup_track=np.stack(backup_track, axis=1) if record and monitor is not None else None,
    )
