"""Environment speed: single-env steps/s through the gymnasium API and batched world-steps/s.

    python benchmarks/bench_env.py [--json benchmarks/results/env.json]

Both run on one core (torch is not involved; numpy's own threads are not used by these element-wise
operations). The single env is the batched world with N = 1.
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

import tssac_core.sim.env  # noqa: F401  (registers the environments)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.output
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description
from tssac_core.sim.scenario import load, sample_layout
from tssac_core.sim.world import World

ROOT = Path(__file__).resolve().parent.parent


def gym_steps_per_s(teammates: str, seconds: float) -> float:
    # One world step per env step, extended observation: the figures of RESULTS.md (the env's defaults now decide once
    # per second in the route observation, as the shipped team does).
    env = gym.make(
        "tssac/Strike-v0",
        scenario=str(ROOT / "scenarios" / "random.yaml"),
        teammates=teammates,
        observation="extended",
        action_repeat=1,
    )
    env.reset(seed=0)
    action = np.array([0.1, 0.0], dtype=np.float32)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(500):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()
        steps += 500
    return steps / (time.perf_counter() - start)


def world_steps_per_s(n: int, seconds: float) -> float:
    s = load(ROOT / "scenarios" / "random.yaml")
    rng = np.random.default_rng(0)
    layouts = [sample_layout(s, rng) for _ in range(64)]
    w = World(s, n)
    w.reset(np.arange(n), [layouts[i % 64] for i in range(n)])
    action = np.zeros((n, 3, 2))
    action[..., 0] = 0.2  # circling: nobody leaves, every world keeps running
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(100):
            w.step(action)
        steps += 100
        if not w.running.all():
            w.reset(np.arange(n), [layouts[i % 64] for i in range(n)])
    return steps * n / (time.perf_counter() - start)


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    add_json_option(p, "env")
    p.add_argument("--seconds", type=float, default=3.0)
    args = p.parse_args()
    figures = {
        "gym_steps_per_s_teammates_none": gym_steps_per_s("none", args.seconds),
        "gym_steps_per_s_teammates_guidance": gym_steps_per_s("guidance", args.seconds),
        "world_steps_per_s_n1024": world_steps_per_s(1024, args.seconds),
        "world_steps_per_s_n1": world_steps_per_s(1, args.seconds),
    }
    figures["targets"] = {"gym_steps_per_s": 10_000, "world_steps_per_s_n1024": 5_000_000}
    # The load average says whether other work shared the cores (the figures are per wall-clock second).
    figures["machine"] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
    }
    for key, value in figures.items():
        if isinstance(value, float):
            print(f"{key:40s} {value:14,.0f}")
    write_figures(args.json, figures)


if __name__ == "__main__":
    main()
