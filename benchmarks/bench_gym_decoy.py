"""The shipped decoy flown in ``gym.make("tssac/Decoy-v0")`` against the same decoy in ``evaluate`` (issue 42).

Mission k of ``evaluate --seed S`` flies the layout of ``reset(seed=S + k)`` here, so both fly the same layouts.
In ``evaluate`` the whole shipped team flies; here the decoy learns-role env flies with the guidance controller
for the teammates (the env's default) and, second, with the shipped detect and strike actors. Prints the decoy's
task success in each and writes them as JSON (``--json``, benchmarks/output.py).

    python benchmarks/bench_gym_decoy.py [--episodes 100] [--seed 800001]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import tssac_core.sim.env  # noqa: F401  (registers tssac/<Role>-v0)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description
from tssac_core.deploy.numpy_actor import load_policy, team_pilots
from tssac_core.deploy.policy import load_team
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import load

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models" / "tssac"


def gym_task_success(episodes: int, seed: int, teammates: object) -> float:
    policy = load_policy(MODELS / "decoy.npz")
    env = gym.make("tssac/Decoy-v0", teammates=teammates)
    done = 0
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(policy.predict(obs))
        done += bool(info["task_done"])
    return done / episodes


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=800001)
    add_json_option(p, "gym_decoy")
    args = p.parse_args()
    scenario = load(ROOT / "scenarios" / "random.yaml")
    t0 = time.perf_counter()
    evaluated = fly_missions(scenario, list(load_team(MODELS)), args.episodes, args.seed)
    evaluate_rate = float(evaluated.task_done[:, 0].mean())
    t1 = time.perf_counter()
    guidance = gym_task_success(args.episodes, args.seed, "guidance")
    t2 = time.perf_counter()
    shipped = gym_task_success(args.episodes, args.seed, team_pilots(MODELS, ["detect", "strike"]))
    t3 = time.perf_counter()
    result = {
        "episodes": args.episodes,
        "seed": args.seed,
        "evaluate_decoy_task_success": evaluate_rate,
        "gym_make_decoy_task_success_guidance_teammates": guidance,
        "gym_make_decoy_task_success_shipped_teammates": shipped,
        "wall_s": {"evaluate": round(t1 - t0, 1), "gym_guidance": round(t2 - t1, 1), "gym_shipped": round(t3 - t2, 1)},
    }
    print(f"decoy task success on {args.episodes} layouts (seed {args.seed}):")
    print(f"  evaluate (shipped team, batched world)        {evaluate_rate:.1%}")
    print(f"  gym.make, guidance teammates (env default)    {guidance:.1%}")
    print(f"  gym.make, shipped detect and strike actors    {shipped:.1%}")
    write_figures(args.json, result)
    assert np.isfinite(evaluate_rate)


if __name__ == "__main__":
    main()
