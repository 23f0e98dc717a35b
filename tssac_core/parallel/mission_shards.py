"""``evaluate --workers N``: the batched missions split by index into shards, one Ray task each, merged.

Mission ``k`` flies the layout of its own seed (:func:`tssac_core.sim.missions.mission_layout`, seed
``S + k``), whichever shard flies it, and the batched world steps each mission apart from the others: so a
shard flies exactly its missions of the serial run, and concatenating the shards in index order gives the
serial run's results, figure for figure (tests/test_ray.py checks the JSON). The pilots (actors or the guidance
controller) and the scenario travel to the workers with the task: no shared filesystem needed.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Generator, Sequence

import numpy as np

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.parallel.ray_map import map_on_ray
from tssac_core.sim.missions import MissionResults, iter_missions
from tssac_core.sim.pilots import PilotSpec
from tssac_core.sim.scenario import Scenario
from tssac_core.sim.time_left import ShardProgress, TimeLeft
from tssac_core.sim.world_monitor import MonitorCounts

PROGRESS_EVERY_S = 0.5
"""How often a shard reports the missions it finished and its time left."""
SHARDS_PER_WORKER = 1
"""Shards per worker: one keeps each batch as large as it can be (the batched world's speed)."""


def shard(indices: Sequence[int], shards: int) -> list[list[int]]:
    """``indices`` cut into at most ``shards`` contiguous pieces whose sizes differ by at most one."""
    count = len(indices)
    shards = max(1, min(shards, count))
    bounds = [count * k // shards for k in range(shards + 1)]
    return [list(indices[a:b]) for a, b in zip(bounds, bounds[1:])]


def shard_count(missions: int, workers: int) -> int:
    """How many shards :func:`fly_missions_sharded` cuts ``missions`` missions into for ``workers`` workers."""
    return len(shard(range(missions), workers * SHARDS_PER_WORKER))


def merge(parts: Sequence[MissionResults]) -> MissionResults:
    """Shards' results, in index order, as one MissionResults."""

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    return MissionResults(
        success=cat("success"),
        cost=cat("cost"),
        returns=cat("returns"),
        task_done=cat("task_done"),
        time_s=cat("time_s"),
        out_of_area=cat("out_of_area"),
        layouts=[x for p in parts for x in p.layouts],
        seeds=[x for p in parts for x in p.seeds],
        indices=[x for p in parts for x in p.indices],
        monitor=merge_counts([p.monitor for p in parts]) if all(p.monitor is not None for p in parts) else None,
    )


def merge_counts(parts: Sequence[MonitorCounts | None]) -> MonitorCounts:
    """The runtime-assurance monitor's per-mission counts of the shards, in index order."""
    return MonitorCounts(
        **{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(MonitorCounts)}
    )


Shard = tuple[int, Scenario, Sequence[PilotSpec], int, list[int], ShieldConfig | None]
"""What a shard's task gets: its number, the scenario, the pilots, the run's seed, its mission indices, the monitor's
margins."""


def fly_shard(piece: Shard) -> Generator[ShardProgress, None, MissionResults]:
    """The Ray task: fly one shard's missions in one batched world, reporting the missions finished since its last
    report and its time left (:class:`~tssac_core.reporting.progress.TimeLeft`) at most every PROGRESS_EVERY_S;
    returns the results."""
    number, scenario, pilots, seed, indices, shield = piece
    left = TimeLeft(len(indices), scenario.episode_steps)
    missions = iter_missions(scenario, pilots, len(indices), seed, indices=indices, shield=shield, on_step=left.tick)
    pending, since = 0, time.monotonic()
    try:
        while True:
            pending += next(missions)
            if time.monotonic() - since >= PROGRESS_EVERY_S:
                yield ShardProgress(number, pending, left.seconds)
                pending, since = 0, time.monotonic()
    except StopIteration as end:
        results: MissionResults = end.value
    yield ShardProgress(number, pending, 0.0)
    return results


def fly_missions_sharded(
    scenario: Scenario,
    pilots: Sequence[PilotSpec],
    indices: Sequence[int],
    seed: int,
    workers: int,
    target: RayTarget,
    progress: Callable[[ShardProgress], None] | None = None,
    shield: ShieldConfig | None = None,
) -> MissionResults:
    """:func:`tssac_core.sim.missions.fly_missions` of missions ``indices`` (through the runtime-assurance monitor
    with ``shield``) over ``workers`` Ray workers: the same results."""
    shards: list[Shard] = [
        (number, scenario, list(pilots), seed, piece, shield)
        for number, piece in enumerate(shard(indices, workers * SHARDS_PER_WORKER))
    ]
    parts: list[MissionResults] = map_on_ray(fly_shard, shards, workers, target, on_event=progress or (lambda n: None))
    return merge(parts)
