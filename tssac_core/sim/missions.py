"""Fly whole three-UAV missions in the batched world and score them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.reward import RewardConfig, reward
from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import ROLES, Layout, Scenario, sample_layout
from tssac_core.sim.team import Pilot, Team
from tssac_core.sim.world import World


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
    trajectories: np.ndarray | None = None
    """(M, T, 3, 2) positions in metres if recorded (NaN after a mission ended)."""

    def summary(self, cost_limit: float) -> dict[str, Any]:
        """The JSON figures: ``success_rate``, ``mean_cost`` (per UAV per episode), ``episodes``, per role."""
        per_role = {}
        for j, role in enumerate(ROLES):
            per_role[role.value] = {
                "mean_cost": float(self.cost[:, j].mean()),
                "max_cost": float(self.cost[:, j].max()),
                "within_cost_limit": float((self.cost[:, j] <= cost_limit).mean()),
                "task_success_rate": float(self.task_done[:, j].mean()),
                "left_area_rate": float(self.out_of_area[:, j].mean()),
                "mean_return": float(self.returns[:, j].mean()),
            }
        return {
            "success_rate": float(self.success.mean()),
            "mean_cost": float(self.cost.mean()),
            "episodes": int(len(self.success)),
            "mean_mission_time_s": float(self.time_s.mean()),
            "roles": per_role,
        }


def fly_missions(
    scenario: Scenario,
    pilots: Sequence[Pilot],
    episodes: int,
    seed: int,
    mode: ObservationMode = ObservationMode.EXTENDED,
    record: bool = False,
    progress: Callable[[int], None] | None = None,
    layouts: list[Layout] | None = None,
) -> MissionResults:
    """Fly ``episodes`` missions at once (one world each) on layouts drawn with ``seed``.

    ``pilots`` gives one pilot per role (see :mod:`tssac_core.sim.team`). ``progress`` is called with the
    number of missions that finished since the last call.
    """
    if layouts is None:
        rng = np.random.default_rng(seed)
        layouts = [sample_layout(scenario, rng) for _ in range(episodes)]
    world = World(scenario, len(layouts))
    active = tuple(p is not None for p in pilots)
    world.reset(np.arange(len(layouts)), layouts, active)
    returns = np.zeros((world.n, len(ROLES)))
    out = np.zeros((world.n, len(ROLES)), dtype=bool)
    track: list[np.ndarray] = []
    cfg = RewardConfig()
    routes = RouteMap()
    team = Team(pilots, mode)
    while world.running.any():
        if record:
            pos = np.stack([world.x_m, world.y_m], axis=-1)
            track.append(np.where(world.running[:, None, None], pos, np.nan))
        moving = world.active & world.running[:, None]
        was_running = world.running.copy()
        detour_prev = routes.detour_m(world)
        result = world.step(team.actions(world))
        returns += reward(result, moving, cfg, detour_prev, routes.detour_m(world))
        out |= result.out_of_area
        if progress is not None:
            finished = int((was_running & ~world.running).sum())
            if finished:
                progress(finished)
    return MissionResults(
        success=world.hit.copy(),
        cost=world.cost_total.copy(),
        returns=returns,
        task_done=world.task_done.copy(),
        time_s=world.steps * scenario.dt_s,
        out_of_area=out,
        layouts=layouts,
        trajectories=np.stack(track, axis=1) if record else None,
    )
