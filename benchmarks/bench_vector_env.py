"""Steps/s of ``gym.make_vec("tssac/<Role>-v0", num_envs=64)`` (the batched world behind gymnasium's vector API)
against ``SyncVectorEnv`` of 64 single envs (issue 42's target: >= 10x).

Both step the detect role with the guidance controller flying the teammates, the env's defaults (route
observation, one decision per second = 10 world steps), random actions, autoreset in the same step. A step of
the vector env is 64 env steps. Prints the figures and writes them as JSON
(``--json``, benchmarks/output.py).

    python benchmarks/bench_vector_env.py [--envs 64] [--seconds 10]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import tssac_core.sim.env  # noqa: F401  (registers tssac/<Role>-v0)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parent.parent
ENV_ID = "tssac/Detect-v0"


def env_steps_per_s(env: gym.vector.VectorEnv, seconds: float) -> float:
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    actions = rng.uniform(-1.0, 1.0, (256, env.num_envs, 2)).astype(np.float32)
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(actions[calls % 256])
        calls += 1
    return calls * env.num_envs / (time.perf_counter() - start)


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--seconds", type=float, default=10.0, help="measuring time per variant")
    add_json_option(p, "vector_env")
    args = p.parse_args()
    vector = gym.make_vec(ENV_ID, num_envs=args.envs, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(
        ENV_ID, num_envs=args.envs, vectorization_mode="sync", vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}
    )
    fast = env_steps_per_s(vector, args.seconds)
    slow = env_steps_per_s(sync, args.seconds)
    result = {
        "env_id": ENV_ID,
        "num_envs": args.envs,
        "action_repeat": 10,
        "vector_entry_point_env_steps_per_s": round(fast, 1),
        "sync_vector_env_env_steps_per_s": round(slow, 1),
        "speedup": round(fast / slow, 2),
        "world_steps_per_env_step": 10,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg_1m": os.getloadavg()[0]},
    }
    print(f"{ENV_ID}, {args.envs} envs, 10 world steps per env step, {args.seconds:g} s each:")
    print(f"  make_vec (vector_entry_point, batched world)  {fast:10.0f} env steps/s")
    print(f"  SyncVectorEnv of {args.envs} single envs            {slow:10.0f} env steps/s")
    print(f"  speed-up {fast / slow:.1f}x   (1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    write_figures(args.json, result)


if __name__ == "__main__":
    main()
