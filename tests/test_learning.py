"""Learning: a short SAC-Lagrangian run on an easy scenario raises the return (a threshold)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest

from tssac_core.deploy.policy import Policy
from tssac_core.sim.env import RoleTask
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.scenario import Layout, Radar, Role, Start, dump, load
from tssac_core.train.cli import main

REPO = Path(__file__).resolve().parents[1]


def easy_scenario(tmp: Path) -> Path:
    """The decoy alone, 6 km outside its ring and flying away from it; one radar far off; short episodes."""
    base = load(REPO / "scenarios" / "strike.yaml")
    layout = Layout(
        sam_km=(50.0, 50.0),
        target_km=(51.0, 49.0),
        radars=(Radar((88.0, 12.0), 8.0),),
        starts={
            "decoy": Start((76.0, 50.0), 90.0),
            "detect": Start((10.0, 90.0), 0.0),
            "strike": Start((12.0, 90.0), 0.0),
        },
    )
    path = tmp / "easy.yaml"
    dump(dataclasses.replace(base, name="easy", episode_steps=1200, layout=layout), path)
    return path


def greedy_return(policy: Policy | None, scenario: Path) -> float:
    mode = policy.observation_mode if policy is not None else ObservationMode.EXTENDED
    task = RoleTask(load(scenario), Role.DECOY, n=1, observation=mode, teammates="none", seed=0)
    obs = task.reset()
    total = 0.0
    for _ in range(120):
        action = np.zeros((1, 2)) if policy is None else policy.act(obs)
        step = task.step(action, repeat=10)
        total += float(step.reward[0])
        if step.terminated[0] or step.truncated[0]:
            break
        obs = step.obs
    return total


@pytest.mark.slow
def test_short_training_raises_the_return(tmp_path: Path) -> None:
    """Five epochs of 600 decisions, an update every second decision (about 1,400 updates): the trained decoy beats
    flying straight on by 38 on this seed and by 42, 43 and 58 on seeds 2-4, against the 25 asserted."""
    scenario = easy_scenario(tmp_path)
    out = tmp_path / "run"
    start = time.monotonic()
    assert (
        main(
            [
                "--algo",
                "sac_lag",
                "--seed",
                "1",
                "--roles",
                "decoy",
                "--scenario",
                str(scenario),
                "--epochs",
                "5",
                "--validation-episodes",
                "0",
                "--steps-per-epoch",
                "600",
                "--envs",
                "2",
                "--action-repeat",
                "10",
                "--update-every",
                "2",
                "--start-steps",
                "0",
                "--update-after",
                "200",
                "--set",
                "hidden_sizes=[64,64]",
                "--set",
                "alpha_init=0.2",
                "--threads",
                "1",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    elapsed = time.monotonic() - start
    straight_on = greedy_return(None, scenario)  # flying straight on never reaches the ring: -0.1 per step
    trained = greedy_return(Policy.load(out / "decoy.pt"), scenario)
    assert straight_on < -100
    # Turning back towards the ring earns the approach term and, once there, +10 and no step penalty:
    # a learner that learned nothing stays near flying straight on (or worse).
    assert trained > straight_on + 25, (trained, straight_on, elapsed)
