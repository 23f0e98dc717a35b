"""Who flies each UAV: the guidance controller, a policy, or nobody (parked).

A *pilot* is one of:
- ``"guidance"``: the rule-based controller (:mod:`tssac_core.guidance`);
- a callable ``obs (N, d) -> action (N, 2)`` on the observations of its role; if it has an attribute
  ``observation_mode`` (an :class:`ObservationMode`, as trained policies do), it gets observations in
  that mode, else in the mode of whoever asks;
- ``None``: the UAV is parked (inactive): it does not move and no task or cost of it counts.
"""

from __future__ import annotations

from typing import Callable, Sequence, Union

import numpy as np

from tssac_core.guidance import Guidance
from tssac_core.observation import ObservationMode, observe
from tssac_core.scenario import ROLES
from tssac_core.world import World

GUIDANCE = "guidance"
Pilot = Union[str, Callable[[np.ndarray], np.ndarray], None]


def check_pilot(pilot: Pilot, role_name: str) -> None:
    if pilot is None or callable(pilot) or pilot == GUIDANCE:
        return
    raise ValueError(f"pilot for {role_name} must be 'guidance', None or a callable obs -> action, got {pilot!r}")


def team_actions(
    world: World, pilots: Sequence[Pilot], default_mode: ObservationMode, guidance: Guidance, skip: int | None = None
) -> np.ndarray:
    """Actions (N, 3, 2) of every flown vehicle; vehicle ``skip`` (the learner) is left at zero."""
    actions = np.zeros((world.n, len(ROLES), 2))
    guided = None
    for j, pilot in enumerate(pilots):
        if j == skip or pilot is None:
            continue
        if pilot == GUIDANCE:
            if guided is None:
                guided = guidance.actions(world)
            actions[:, j] = guided[:, j]
        elif callable(pilot):
            mode = getattr(pilot, "observation_mode", default_mode)
            actions[:, j] = np.asarray(pilot(observe(world, j, mode)), dtype=np.float64)
    return actions
