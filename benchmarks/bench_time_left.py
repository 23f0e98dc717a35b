"""How true ``evaluate``'s time left is: the README's evaluation flown as ``evaluate`` flies it, every estimate the bar
would show recorded with its time, then compared with the time that was really left.

    python benchmarks/bench_time_left.py                      # the README's: 10,000 missions, 2 workers
    python benchmarks/bench_time_left.py --episodes 1000 --workers 1

Prints and writes (JSON) the ratio estimate / truth over every estimate shown, and over those shown after the first
10% of the run: its smallest and largest value and the share of estimates within 1.5x.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from benchmarks.output import add_json_option, write_figures  # noqa: E402
from tssac_core.common.cli import command_description  # noqa: E402
from tssac_core.evaluate import load_pilots  # noqa: E402
from tssac_core.reporting.progress import ShardsBar  # noqa: E402
from tssac_core.sim.missions import fly_missions  # noqa: E402
from tssac_core.sim.scenario import load  # noqa: E402
from tssac_core.sim.time_left import ShardProgress, TimeLeft  # noqa: E402

SHOWN_EVERY_S = 0.5
"""How often an estimate is recorded (the bars redraw about as often)."""


def estimates(
    episodes: int, seed: int, workers: int, models: Path, scenario: Path
) -> tuple[list[tuple[float, float]], float]:
    """(time since the start, estimate) for every estimate shown, and the run's wall time."""
    world = load(scenario)
    pilots = load_pilots(models)
    shown: list[tuple[float, float]] = []
    start = time.perf_counter()
    if workers > 1:
        from tssac_core.parallel.mission_shards import fly_missions_sharded, shard_count
        from tssac_core.parallel.ray_cluster import RayTarget

        indices = list(range(episodes))
        bar = ShardsBar(episodes, shard_count(episodes, workers), disable=True)

        def report(progress: ShardProgress) -> None:
            bar.update(progress)
            now = time.perf_counter()
            left = bar.seconds(now)
            if left is not None:
                shown.append((now - start, left))

        fly_missions_sharded(world, pilots, indices, seed, workers, RayTarget(None), report)
    else:
        left_now = TimeLeft(episodes, world.episode_steps, clock_s=start)
        last_shown = [start]

        def step(flying: int, still: int) -> None:
            left_now.tick(flying, still)
            now = left_now.clock_s
            if now - last_shown[0] >= SHOWN_EVERY_S and left_now.seconds is not None:
                last_shown[0] = now
                shown.append((now - start, left_now.seconds))

        fly_missions(world, pilots, episodes, seed, on_step=step)
    return shown, time.perf_counter() - start


def summary(shown: list[tuple[float, float]], total_s: float) -> dict[str, float | int]:
    def ratios(after_s: float) -> list[float]:
        return [est / (total_s - t) for t, est in shown if t >= after_s and total_s - t > 1.0]

    out: dict[str, float | int] = {"wall_s": round(total_s, 1), "estimates": len(shown)}
    for label, after in (("all", 0.0), ("after_10pct", 0.1 * total_s)):
        r = ratios(after)
        if r:
            out[f"{label}_min_ratio"] = round(min(r), 3)
            out[f"{label}_max_ratio"] = round(max(r), 3)
            out[f"{label}_share_within_1_5x"] = round(sum(1 / 1.5 <= x <= 1.5 for x in r) / len(r), 3)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/bench_time_left.py", description=command_description(__doc__))
    p.add_argument("--episodes", type=int, default=10_000)
    p.add_argument("--seed", type=int, default=2200001)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--models", type=Path, default=Path("models/tssac"))
    p.add_argument("--scenario", type=Path, default=Path("scenarios/random.yaml"))
    add_json_option(p, "time_left")
    args = p.parse_args(argv)
    shown, total = estimates(args.episodes, args.seed, args.workers, args.models, args.scenario)
    figures = {"episodes": args.episodes, "workers": args.workers, "seed": args.seed, **summary(shown, total)}
    for key, value in figures.items():
        print(f"{key}: {value}")
    write_figures(args.json, {**figures, "shown": [[round(t, 2), round(e, 2)] for t, e in shown]})
    return 0


if __name__ == "__main__":
    sys.exit(main())
