"""Training layouts with the hard ones drawn more often.

The UAV-missions that cross a radar for hundreds of steps are not spread evenly over the layouts: they fall
on layouts whose radars stand between the starts and the SAM, so that the way around them is much longer
than the straight line (of 11 of the costliest UAV-missions of three trained teams on evaluation layouts, 7 had
a start detour above the 87th percentile of random layouts, 5 above the 97th; docs/decisions.md). A policy
trained on the scenario's own draw meets such layouts rarely, and learns them last. :class:`LayoutSource` draws a
share of the training episodes from those layouts only (rejection sampling on the start detour), and the
rest from the scenario as it is. Validation, selection and evaluation keep the scenario's own draw: the
figures a team is judged by stay those of the layouts it will meet.

The *start detour* of a UAV is :meth:`tssac_core.sim.routes.RouteMap.detour_m` at its start: how much
longer its way to the SAM's detection disk around the radars (kept 3 km clear) is than the straight line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tssac_core.sim.routes import RouteMap
from tssac_core.sim.scenario import ROLES, Layout, Scenario, sample_layout
from tssac_core.sim.world import World
from tssac_core.sim.world_state import snapshot


@dataclass(frozen=True)
class HardLayouts:
    """Which training layouts count as hard, and how often the training draws them."""

    fraction: float = 0.0
    """Share of training episodes drawn from hard layouts only (0: the scenario's own draw, to the bit)."""
    detour_km: float = 20.0
    """Hard: some UAV's start detour is at least this long (on random.yaml the top quarter of layouts)."""
    max_draws: int = 200
    """Draws per hard episode before settling for the hardest one drawn (a scenario with few hard layouts)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.fraction <= 1.0:
            raise ValueError(f"hard layout fraction must be in [0, 1], got {self.fraction:g}")
        if not self.detour_km >= 0.0 or self.max_draws < 1:
            raise ValueError("hard layout detour must be >= 0 km and max_draws >= 1")


def start_detours_km(
    scenario: Scenario, layouts: list[Layout], world: World | None = None, routes: RouteMap | None = None
) -> np.ndarray:
    """Every UAV's start detour in kilometres, (len(layouts), 3) in role order (module docstring); ``world``
    (of len(layouts) worlds) and ``routes`` may be given to be reused."""
    world = world or World(scenario, len(layouts))
    world.reset(np.arange(len(layouts)), layouts, (True,) * len(ROLES))
    return (routes or RouteMap()).detour_m(snapshot(world)) / 1000.0


class LayoutSource:
    """Draws the layouts of training episodes: the scenario's own, or hard ones for ``hard.fraction`` of them."""

    def __init__(self, scenario: Scenario, hard: HardLayouts = HardLayouts()) -> None:
        self.scenario = scenario
        self.hard = hard
        self._probe: tuple[World, RouteMap] | None = None
        """One world and its route map, reused to measure candidate layouts."""

    def draw(self, rng: np.random.Generator) -> Layout:
        """One episode's layout. With ``hard.fraction == 0`` (or a fixed layout) exactly ``sample_layout``'s
        training draw (unprotected starts kept): the same draws from ``rng``, so runs without hard layouts are
        unchanged."""
        if self.hard.fraction == 0.0 or self.scenario.random is None:
            return sample_layout(self.scenario, rng, protected_starts=False)
        if rng.random() >= self.hard.fraction:
            return sample_layout(self.scenario, rng, protected_starts=False)
        hardest, hardest_km = None, -np.inf
        for _ in range(self.hard.max_draws):
            layout = sample_layout(self.scenario, rng, protected_starts=False)
            detour_km = float(self._start_detours_km(layout).max())
            if detour_km >= self.hard.detour_km:
                return layout
            if detour_km > hardest_km:
                hardest, hardest_km = layout, detour_km
        assert hardest is not None
        return hardest

    def _start_detours_km(self, layout: Layout) -> np.ndarray:
        if self._probe is None:
            self._probe = (World(self.scenario, 1), RouteMap())
        return start_detours_km(self.scenario, [layout], *self._probe)
