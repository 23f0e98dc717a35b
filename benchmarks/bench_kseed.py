"""K seeds in one batched learner against one seed, and against K single learners run in turn.

    python benchmarks/bench_kseed.py [--k 3] [--seconds 60] [--rounds 10] [--hidden 256,256] [--threads 1] \
        [--json benchmarks/results/kseed.json]

Table 3's sizes (batch 256, 256x256 ReLU networks, twin reward critics + cost critic + actor),
``--threads`` torch threads (default one), replay sampling included as the training loop does it (one buffer per seed, TSSAC's
recent batch for the multiplier). Three blocks alternate within every round, so that a change in the
machine's load hits all three; each figure is the median over the rounds:

* **1 seed**: `SacLagrangian.update`, one update;
* **K batched**: `KSeedSacLagrangian.update`, one update of all K seeds (K seed-updates);
* **K sequential**: K `SacLagrangian` learners, one update each, one after another.

The headline is the time of one K-seed update over the time of one single-seed update
(wall clock, and per CPU second of this process, which discounts time lost to other processes).
Batching saves per-call overhead, not arithmetic: K seeds are K times the matmuls. The floor of the
ratio is therefore printed too: the matmuls of K seeds' updates (the shapes of `bench_train`'s
machine bound, timed with `torch.mm` at hot caches) over the measured time of one whole update.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_train import ACT_DIM, BATCH, HIDDEN, LR, OBS_DIM, matmul_seconds, our_matmuls, synthetic_buffer, timed_rounds  # noqa: E402
from tssac_core.algos.kseed import KSeedSacLagrangian  # noqa: E402
from tssac_core.algos.replay import ReplayBuffer  # noqa: E402
from tssac_core.algos.sac_lagrangian import SacConfig, SacLagrangian, Variant  # noqa: E402

FILL = 4000
"""Transitions per seed's buffer (one of Table 3's epochs)."""


def table3_config(variant: Variant, hidden: tuple[int, ...] = HIDDEN) -> SacConfig:
    return SacConfig(variant=variant, hidden_sizes=hidden, batch_size=BATCH, lr=LR)


def single_block(config: SacConfig, buffers: Sequence[ReplayBuffer]) -> Callable[[], int]:
    """One update of each of len(buffers) single learners, one after another."""
    learners = []
    for k in range(len(buffers)):
        torch.manual_seed(k)
        learners.append(SacLagrangian(OBS_DIM, ACT_DIM, config))
    rng = np.random.default_rng(0)
    window = config.multiplier_window if learners[0].uses_multiplier else None

    def block() -> int:
        for learner, buffer in zip(learners, buffers):
            batch = buffer.sample(BATCH, rng)
            recent = buffer.sample_recent(BATCH, window, rng) if window else None
            learner.update(batch, recent)
        return 1

    return block


def batched_block(config: SacConfig, buffers: Sequence[ReplayBuffer]) -> Callable[[], int]:
    """One update of a KSeedSacLagrangian over len(buffers) seeds."""
    learner = KSeedSacLagrangian.from_seeds(OBS_DIM, ACT_DIM, config, range(len(buffers)))
    rng = np.random.default_rng(0)
    window = config.multiplier_window if learner.uses_multiplier else None

    def block() -> int:
        batches = [buffer.sample(BATCH, rng) for buffer in buffers]
        recents = [buffer.sample_recent(BATCH, window, rng) for buffer in buffers] if window else None
        learner.update(batches, recents)
        return 1

    return block


def measure(variant: Variant, k: int, seconds: float, rounds: int, hidden: tuple[int, ...] = HIDDEN, threads: int = 1) -> dict[str, float]:
    config = table3_config(variant, hidden)
    buffers = [synthetic_buffer(FILL, seed) for seed in range(k)]
    blocks = {
        "one": single_block(config, buffers[:1]),
        "batched": batched_block(config, buffers),
        "sequential": single_block(config, buffers),
    }
    rates = timed_rounds(blocks, threads=threads, seconds=seconds, rounds=rounds)
    one, batched, sequential = (rates[name] for name in ("one", "batched", "sequential"))
    floor: dict[str, float] = {}
    if hidden == HIDDEN:  # bench_train's matmul list is for Table 3's sizes
        matmuls = our_matmuls(recent=variant in (Variant.SAC_LAG, Variant.TSSAC), cost_in_actor=variant in (Variant.SAC_LAG, Variant.TSSAC))
        seconds_per_update = matmul_seconds(matmuls, threads=threads, repeats=15)  # best of 15: the load varies
        floor = {
            "matmul_ms_per_seed_update": 1e3 * seconds_per_update,
            # K seeds' matmuls alone, at torch.mm's hot-cache speed, over one whole single-seed update (CPU time).
            "floor_ratio_matmuls_only": k * seconds_per_update * one["per_cpu_s"],
        }
    return {
        "updates_per_s_1_seed": one["per_s"],
        "seed_updates_per_s_batched": k * batched["per_s"],
        "seed_updates_per_s_sequential": k * sequential["per_s"],
        "ratio_batched_over_1": one["per_s"] / batched["per_s"],
        "ratio_sequential_over_1": one["per_s"] / sequential["per_s"],
        "ratio_batched_over_1_cpu": one["per_cpu_s"] / batched["per_cpu_s"],
        "ratio_sequential_over_1_cpu": one["per_cpu_s"] / sequential["per_cpu_s"],
        "speedup_batched_vs_sequential": batched["per_s"] / sequential["per_s"],
        **floor,
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--k", type=int, default=3, help="seeds in the batched learner (default 3)")
    p.add_argument("--variants", default="tssac,sac", help="comma-separated (default tssac,sac)")
    p.add_argument("--seconds", type=float, default=60.0, help="measured seconds per block and variant")
    p.add_argument("--rounds", type=int, default=10, help="alternating rounds (medians over them)")
    p.add_argument("--hidden", default="256,256", help="hidden layer sizes (default Table 3's 256,256)")
    p.add_argument("--threads", type=int, default=1, help="torch threads for every block (default 1; this machine has 2 cores)")
    p.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "kseed.json")
    a = p.parse_args(argv)
    hidden = tuple(int(x) for x in a.hidden.split(","))
    torch.set_num_threads(a.threads)
    results: dict[str, object] = {
        "k": a.k,
        "threads": a.threads,
        "batch": BATCH,
        "hidden": list(hidden),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "load_average_before": list(os.getloadavg()),
    }
    for name in a.variants.split(","):
        figures = measure(Variant(name), a.k, a.seconds, a.rounds, hidden, a.threads)
        results[name] = figures
        print(
            f"{name}: 1 seed {figures['updates_per_s_1_seed']:.1f} updates/s; "
            f"{a.k} batched {figures['seed_updates_per_s_batched']:.1f} seed-updates/s; "
            f"{a.k} sequential {figures['seed_updates_per_s_sequential']:.1f} seed-updates/s"
        )
        print(
            f"{name}: time for {a.k} seeds batched / time for 1 seed = {figures['ratio_batched_over_1']:.2f} "
            f"(CPU time {figures['ratio_batched_over_1_cpu']:.2f}); {a.k} sequential / 1 = "
            f"{figures['ratio_sequential_over_1']:.2f}; batched is {figures['speedup_batched_vs_sequential']:.2f}x "
            f"sequential"
        )
        if "floor_ratio_matmuls_only" in figures:
            print(
                f"{name}: the matmuls of one seed's update take {figures['matmul_ms_per_seed_update']:.1f} ms at torch.mm's "
                f"hot-cache speed; {a.k} seeds' matmuls alone are {figures['floor_ratio_matmuls_only']:.2f} x one whole "
                f"single-seed update (the floor of the ratio above)"
            )
    results["load_average_after"] = list(os.getloadavg())
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
