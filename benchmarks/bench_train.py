"""Training speed: our SAC-Lagrangian update against Stable-Baselines3's SAC and this machine's bound.

    python benchmarks/bench_train.py [--seconds 3] [--threads 1,2] [--json benchmarks/results/train.json]

Figures, each at every thread count of ``--threads`` (set with ``torch.set_num_threads``):

* **ours**: updates/s of ``SacLagrangian.update`` with Table 3's sizes (batch 256, 256x256 ReLU
  networks, twin reward critics + cost critic + actor), replay sampling included as the training loop
  does it: TSSAC with the multiplier's recent batch (``multiplier_window``), and plain SAC (no recent
  batch, cost critic trained but not in the actor's loss). The synthetic buffer's costs keep Q^c above
  the limit, so TSSAC's multiplier is positive and the cost critic's gradient reaches the actor.
* **loop**: env-steps/s of a training loop as ``tssac_core.train`` runs it (decoy role, teammates parked,
  ``TrainConfig``'s defaults: 4 worlds, one update per env step), with its split into env and update time.
* **sb3**: updates/s of Stable-Baselines3's ``SAC.train`` on ``tssac/Decoy-v0`` (teammates ``"none"``)
  with the same sizes (net_arch [256, 256], batch 256, lr 1e-3, one gradient step per call of its
  loop), its buffer first filled by ``learn`` with random actions. Skipped if SB3 is not installed
  (``pip install -e .[bench]``).
* **bound**: the matmuls of one update (forward, and backward as weight and input gradients, each
  2 m k n FLOPs), timed shape by shape with ``torch.mm`` at the same thread count (best of a few runs,
  hot caches): bound = 1 / that time = achieved FLOP/s / FLOPs per update. Everything else (activations,
  losses, Adam, Python) is taken as free, so the bound is not reachable.

Rates are medians over ``--rounds`` rounds in which ours and SB3 alternate, so that a change in the
machine's load hits both. Wall-clock rates are what training sees; "per CPU-s" divides by this
process's CPU time instead (for one thread it ignores time lost to other processes).

On a shared machine, GNU OpenMP's spinning threads collapse when another process holds the other core
(2 threads: below 1 update/s measured here); run with ``OMP_WAIT_POLICY=PASSIVE`` then, and read the
2-thread figures as the machine's leftovers, not its capacity.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import tssac_core.sim.env  # noqa: E402,F401  (registers tssac/Decoy-v0)
from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.algos.replay import ReplayBuffer  # noqa: E402
from tssac_core.algos.sac_lagrangian import SacConfig, SacLagrangian, Variant  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402
from tssac_core.sim.env import RoleTask  # noqa: E402
from tssac_core.sim.observation import ObservationMode  # noqa: E402
from tssac_core.sim.scenario import Role, load  # noqa: E402
from tssac_core.train.config import DEFAULT_SCENARIO, TrainConfig  # noqa: E402

OBS_DIM = ObservationMode.EXTENDED.size
ACT_DIM = 2
HIDDEN = (256, 256)
BATCH = 256
LR = 1e-3
FILL = 4000
"""Transitions in the replay buffers before timing (one of Table 3's epochs; SB3's come from the env)."""

Matmul = tuple[int, int, int]
"""(m, k, n): an (m, k) @ (k, n) product, 2 m k n FLOPs."""


# --- timing ---------------------------------------------------------------------------------------


def timed_rounds(
    blocks: dict[str, Callable[[], int]], threads: int, seconds: float, rounds: int
) -> dict[str, dict[str, float]]:
    """Run each block (returns how many units it did) for seconds / rounds per round, alternating the
    blocks within each round; median rates per wall second and per CPU second of this process."""
    torch.set_num_threads(threads)
    wall: dict[str, list[float]] = {name: [] for name in blocks}
    cpu: dict[str, list[float]] = {name: [] for name in blocks}
    for name, block in blocks.items():  # warm-up: allocator, caches, lazy state
        for _ in range(3):
            block()
    for _ in range(rounds):
        for name, block in blocks.items():
            units, w0, c0 = 0, time.perf_counter(), time.process_time()
            while time.perf_counter() - w0 < seconds / rounds:
                units += block()
            wall[name].append(units / (time.perf_counter() - w0))
            cpu[name].append(units / max(time.process_time() - c0, 1e-9))
    return {
        name: {"per_s": statistics.median(wall[name]), "per_cpu_s": statistics.median(cpu[name])} for name in blocks
    }


# --- ours -----------------------------------------------------------------------------------------


def synthetic_buffer(n: int, seed: int = 0) -> ReplayBuffer:
    """n random transitions; cost 1 in half of them (Q^c far above the limit: the multiplier is active)."""
    rng = np.random.default_rng(seed)
    buffer = ReplayBuffer(OBS_DIM, ACT_DIM, n)
    buffer.add_batch(
        rng.normal(size=(n, OBS_DIM)).astype(np.float32),
        rng.uniform(-1.0, 1.0, (n, ACT_DIM)).astype(np.float32),
        rng.normal(size=n).astype(np.float32),
        (rng.random(n) < 0.5).astype(np.float32),
        rng.normal(size=(n, OBS_DIM)).astype(np.float32),
        (rng.random(n) < 0.01).astype(np.float32),
    )
    return buffer


def our_update_block(variant: Variant, buffer: ReplayBuffer) -> Callable[[], int]:
    """One update with its replay sampling, as tssac_core.train calls it."""
    torch.manual_seed(0)
    config = SacConfig(variant=variant, hidden_sizes=HIDDEN, batch_size=BATCH, lr=LR)
    learner = SacLagrangian(OBS_DIM, ACT_DIM, config)
    rng = np.random.default_rng(0)
    window = learner.signal.recent_window  # recent transitions only for a signal measured on them

    def block() -> int:
        batch = buffer.sample(BATCH, rng)
        recent = buffer.sample_recent(BATCH, window, rng) if window is not None else None
        learner.update(batch, recent, episode_cost=0.0)
        return 1

    return block


def loop_rate(threads: int, seconds: float) -> dict[str, float]:
    """Env-steps/s of the training loop (tssac_core.train.train_role without epochs and validation)."""
    torch.set_num_threads(threads)
    defaults = TrainConfig()
    envs, mode = defaults.envs, ObservationMode(defaults.observation)
    scenario = load(DEFAULT_SCENARIO)
    torch.manual_seed(0)
    decisions = -(-scenario.episode_steps // defaults.action_repeat)  # the learner's episode, as train.sac_config
    config = SacConfig(hidden_sizes=HIDDEN, batch_size=BATCH, lr=LR, episode_steps=decisions)
    learner = SacLagrangian(mode.size, ACT_DIM, config)
    buffer = ReplayBuffer(mode.size, ACT_DIM, 100_000)
    task = RoleTask(scenario, Role.DECOY, envs, mode, teammates="none", seed=0)
    rng = np.random.default_rng(0)
    obs = task.reset()

    def env_step(action: np.ndarray) -> None:
        nonlocal obs
        step = task.step(action, repeat=defaults.action_repeat)
        # As train_role: only a hit ends the learner's future.
        buffer.add_batch(obs, action, step.reward, step.cost, step.final_obs, step.terminated & step.episode_success)
        obs = step.obs

    while len(buffer) < defaults.update_after:
        env_step(rng.uniform(-1.0, 1.0, (envs, ACT_DIM)))
    steps = updates = 0
    env_time = update_time = 0.0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        t0 = time.perf_counter()
        env_step(learner.act(obs, deterministic=False))
        steps += envs
        t1 = time.perf_counter()
        for _ in range(steps // defaults.update_every - updates):
            batch = buffer.sample(BATCH, rng)
            window = learner.signal.recent_window
            recent = buffer.sample_recent(BATCH, window, rng) if window is not None else None
            learner.update(batch, recent, episode_cost=0.0)
            updates += 1
        env_time += t1 - t0
        update_time += time.perf_counter() - t1
    total = time.perf_counter() - start
    return {
        "env_steps_per_s": steps / total,
        "updates_per_s": updates / total,
        "env_fraction": env_time / total,
        "update_fraction": update_time / total,
    }


# --- Stable-Baselines3 ----------------------------------------------------------------------------


def sb3_block() -> Callable[[], int] | None:
    """SB3's SAC.train, 10 gradient steps per call, after FILL random env steps; None without SB3."""
    try:
        from stable_baselines3 import SAC
    except ImportError:
        return None
    env = gym.make("tssac/Decoy-v0", teammates="none", observation="extended", action_repeat=1)
    model = SAC(
        "MlpPolicy",
        env,
        learning_rate=LR,
        buffer_size=100_000,
        learning_starts=FILL,  # learn() below only collects (random actions), never trains
        batch_size=BATCH,
        tau=0.005,
        gamma=0.99,
        train_freq=1,
        gradient_steps=1,
        policy_kwargs={"net_arch": list(HIDDEN)},
        device="cpu",
        seed=0,
    )
    model.learn(total_timesteps=FILL)
    steps = 10

    def block() -> int:
        model.train(gradient_steps=steps, batch_size=BATCH)
        return steps

    return block


# --- the machine bound ----------------------------------------------------------------------------


def layer_sizes(in_dim: int, out_dim: int) -> list[tuple[int, int]]:
    sizes = [in_dim, *HIDDEN, out_dim]
    return list(zip(sizes[:-1], sizes[1:]))


def forward(layers: Sequence[tuple[int, int]], members: int = 1) -> list[Matmul]:
    return [(BATCH, k, n) for k, n in layers for _ in range(members)]


def backward(
    layers: Sequence[tuple[int, int]], members: int = 1, weights: bool = True, first_input: bool = False
) -> list[Matmul]:
    """Weight gradients x^T g (k, B, n) and input gradients g W^T (B, n, k); the first layer's input
    gradient only when its input needs one (the actions, when the actor loss flows through a critic)."""
    out: list[Matmul] = []
    for i, (k, n) in enumerate(layers):
        for _ in range(members):
            if weights:
                out.append((k, BATCH, n))
            if i > 0 or first_input:
                out.append((BATCH, n, k))
    return out


def our_matmuls(recent: bool, cost_in_actor: bool) -> list[Matmul]:
    """One SacLagrangian.update: eq. 13's targets and critic step, eq. 12/16's actor step, eq. 15's Q^c."""
    actor, critic = layer_sizes(OBS_DIM, 2 * ACT_DIM), layer_sizes(OBS_DIM + ACT_DIM, 1)
    to_actor = 3 if cost_in_actor else 2
    return (
        forward(actor)
        + forward(critic, 3)  # targets: pi(s'), twin target critics, target cost critic
        + forward(critic, 3)
        + backward(critic, 3)  # critic step
        + forward(actor)
        + forward(critic, 3)  # actor step: pi(s) and the critics at its actions ...
        + backward(critic, to_actor, weights=False, first_input=True)
        + backward(actor)  # ... back to the actor
        + (forward(actor) + forward(critic, 1) if recent else [])  # Q^c on the recent batch
    )


def sb3_matmuls() -> list[Matmul]:
    """One step of SB3's SAC.train: its actor has two heads (mean, log-std) on a 256x256 trunk, and its
    actor loss's backward also computes the critics' weight gradients (zeroed before they are used)."""
    critic = layer_sizes(OBS_DIM + ACT_DIM, 1)
    trunk = layer_sizes(OBS_DIM, HIDDEN[-1])[:-1]
    actor = [*trunk, (HIDDEN[-1], ACT_DIM), (HIDDEN[-1], ACT_DIM)]
    return (
        forward(actor)
        + forward(actor)
        + forward(critic, 2)  # pi(s), then targets: pi(s'), target critics
        + forward(critic, 2)
        + backward(critic, 2)  # critic step
        + forward(critic, 2)
        + backward(critic, 2, weights=True, first_input=True)
        + backward(actor)  # actor step
    )


def flops(matmuls: Sequence[Matmul]) -> int:
    return sum(2 * m * k * n for m, k, n in matmuls)


def matmul_seconds(matmuls: Sequence[Matmul], threads: int, repeats: int = 5, calls: int = 20) -> float:
    """Time of all the matmuls with torch.mm into preallocated outputs (best of `repeats` per shape)."""
    torch.set_num_threads(threads)
    total = 0.0
    for (m, k, n), count in Counter(matmuls).items():
        a, b, out = torch.randn(m, k), torch.randn(k, n), torch.empty(m, n)
        for _ in range(3):
            torch.mm(a, b, out=out)
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(calls):
                torch.mm(a, b, out=out)
            best = min(best, (time.perf_counter() - t0) / calls)
        total += count * best
    return total


# --- main -----------------------------------------------------------------------------------------


def main() -> None:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    add_json_option(p, "train")
    p.add_argument("--seconds", type=float, default=3.0, help="per figure and thread count")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--threads", default="1,2")
    p.add_argument("--no-loop", action="store_true", help="skip the training-loop figure")
    args = p.parse_args()
    thread_counts = [int(t) for t in args.threads.split(",")]
    load_before = os.getloadavg()

    buffer = synthetic_buffer(FILL)
    blocks: dict[str, Callable[[], int]] = {
        "ours_tssac": our_update_block(Variant.TSSAC, buffer),
        "ours_sac": our_update_block(Variant.SAC, buffer),
    }
    sb3 = sb3_block()
    if sb3 is None:
        print("stable-baselines3 is not installed: SB3 skipped (pip install -e .[bench])")
    else:
        blocks["sb3_sac"] = sb3

    gflop = {
        "ours_tssac": flops(our_matmuls(recent=True, cost_in_actor=True)) / 1e9,
        "ours_sac": flops(our_matmuls(recent=False, cost_in_actor=False)) / 1e9,
        "sb3_sac": flops(sb3_matmuls()) / 1e9,
    }
    shapes = {
        "ours_tssac": our_matmuls(recent=True, cost_in_actor=True),
        "ours_sac": our_matmuls(recent=False, cost_in_actor=False),
        "sb3_sac": sb3_matmuls(),
    }
    figures: dict[str, Any] = {"gflop_per_update": gflop}
    per_threads: dict[str, dict[str, Any]] = {}
    for threads in thread_counts:
        rates = timed_rounds(blocks, threads, args.seconds, args.rounds)
        row: dict[str, Any] = {
            "updates_per_s": {k: v["per_s"] for k, v in rates.items()},
            "updates_per_cpu_s": {k: v["per_cpu_s"] for k, v in rates.items()},
        }
        mm_s = {name: matmul_seconds(s, threads) for name, s in shapes.items()}
        row["matmul_gflop_per_s"] = flops(shapes["ours_tssac"]) / mm_s["ours_tssac"] / 1e9
        row["bound_updates_per_s"] = {name: 1.0 / t for name, t in mm_s.items()}
        row["fraction_of_bound"] = {name: rates[name]["per_s"] * mm_s[name] for name in rates}
        row["achieved_gflop_per_s"] = {name: rates[name]["per_s"] * gflop[name] for name in rates}
        if "sb3_sac" in rates:
            row["ours_over_sb3"] = {
                name: rates[name]["per_s"] / rates["sb3_sac"]["per_s"] for name in ("ours_tssac", "ours_sac")
            }
        if not args.no_loop:
            row["loop"] = loop_rate(threads, args.seconds)
        per_threads[str(threads)] = row

        print(f"--- {threads} thread(s) ---")
        for name, rate in rates.items():
            print(
                f"{name:12s} {rate['per_s']:7.1f} updates/s ({rate['per_cpu_s']:6.1f} per CPU-s)  "
                f"{gflop[name]:.3f} GFLOP/update -> {rate['per_s'] * gflop[name]:5.1f} GFLOP/s, "
                f"{row['fraction_of_bound'][name]:.0%} of its bound {row['bound_updates_per_s'][name]:.0f}/s"
            )
        print(f"torch.mm on the update's shapes: {row['matmul_gflop_per_s']:.0f} GFLOP/s")
        for name, ratio in row.get("ours_over_sb3", {}).items():
            print(f"{name} / sb3_sac: {ratio:.2f}")
        if "loop" in row:
            loop = row["loop"]
            print(
                f"training loop: {loop['env_steps_per_s']:.0f} env-steps/s, {loop['updates_per_s']:.0f} updates/s "
                f"({loop['env_fraction']:.0%} env, {loop['update_fraction']:.0%} updates)"
            )

    figures["threads"] = per_threads
    figures["config"] = {
        "batch": BATCH,
        "hidden": list(HIDDEN),
        "obs_dim": OBS_DIM,
        "act_dim": ACT_DIM,
        "buffer_rows": FILL,
        "seconds": args.seconds,
        "rounds": args.rounds,
    }
    figures["machine"] = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "cpus": os.cpu_count(),
        "load_average_before": [round(x, 2) for x in load_before],
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", ""),
    }
    if sb3 is not None:
        import stable_baselines3

        figures["machine"]["stable_baselines3"] = stable_baselines3.__version__
    if load_before[0] > 0.5:
        print(f"note: load average {load_before[0]:.1f} before the run; other processes shared the machine")
    write_figures(args.json, figures)


if __name__ == "__main__":
    main()
