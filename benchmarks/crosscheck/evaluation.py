"""The detect UAV on the evaluation layouts: mission k flies the layout of seed ``seed + k`` (tssac_core.sim.missions)
in the batched world, the shipped decoy (models/tssac) beside it, the strike UAV parked, as both sides trained.

Both sides' actors fly here, in the project's environment: ours from the run's ``detect.npz`` (its deterministic
actor), OmniSafe's from the exported ``actor.npz`` (its deterministic actor mean; benchmarks.crosscheck.actor_file).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.crosscheck.actor_file import OmniSafeActor
from benchmarks.crosscheck.settings import SCENARIO, TEAMMATES
from tssac_core.deploy.numpy_actor import NumpyPolicy, team_pilots
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilots import PilotSpec
from tssac_core.sim.scenario import Role, load


@dataclass(frozen=True)
class DetectMissions:
    """Per mission: the detect role's task was done (eq. 9), and its hazard cost (eq. 11: world steps of 0.1 s
    inside a radar)."""

    task_done: list[bool]
    cost: list[float]


def detect_pilot(impl: str, run_dir: Path) -> PilotSpec:
    """The trained detect actor of a run: ours (``detect.npz``) or OmniSafe's (``actor.npz``)."""
    if impl == "ours":
        return NumpyPolicy.load(run_dir / "detect.npz", Role.DETECT)
    return OmniSafeActor.load(run_dir / "actor.npz")


def fly_detect(pilot: PilotSpec, episodes: int, seed: int, teammates: Path = TEAMMATES) -> DetectMissions:
    """Fly ``episodes`` missions (layout seeds ``seed`` .. ``seed + episodes - 1``) with ``pilot`` as the detect UAV."""
    scenario = load(SCENARIO)
    decoy = team_pilots(teammates, ["decoy"])["decoy"]
    results = fly_missions(scenario, [decoy, pilot, None], episodes, seed, mode=ObservationMode.ROUTE)
    j = Role.DETECT.index
    return DetectMissions(
        task_done=[bool(x) for x in np.asarray(results.task_done)[:, j]],
        cost=[float(x) for x in np.asarray(results.cost)[:, j]],
    )
