"""``python -m tssac_core.evaluate``: fly whole three-UAV missions in the batched world and score them.

Examples::

    python -m tssac_core.evaluate --controller guidance --scenario scenarios/random.yaml --episodes 50 --seed 7
    python -m tssac_core.evaluate --models models/tssac --scenario scenarios/random.yaml --episodes 50 --json out.json

Prints the success rate (target hit), the mean hazard cost per UAV per episode and per-role figures;
``--json`` writes them with the keys ``success_rate``, ``mean_cost``, ``episodes`` and one entry per
role name.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from tqdm import tqdm

from tssac_core.cli import UsageError, run, write_json
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import ROLES, load
from tssac_core.sim.team import GUIDANCE, Pilot

DEFAULT_SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "random.yaml"


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m tssac_core.evaluate", description=__doc__.split("\n")[0])
    who = p.add_mutually_exclusive_group()
    who.add_argument("--controller", choices=[GUIDANCE], help="fly every UAV with the rule-based guidance controller (default without --models)")
    who.add_argument("--models", type=Path, help="directory holding decoy.pt, detect.pt, strike.pt (made by tssac_core.train)")
    p.add_argument("--scenario", type=Path, default=DEFAULT_SCENARIO, help="scenario file (default: scenarios/random.yaml)")
    p.add_argument("--episodes", type=int, default=50, help="missions to fly (default 50)")
    p.add_argument("--seed", type=int, default=12345, help="seed of the layouts (default 12345, never used in training)")
    p.add_argument("--json", type=Path, help="write the results here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if args.episodes <= 0:
        raise UsageError("--episodes must be positive")
    return args


def load_pilots(models: Path | None) -> list[Pilot]:
    if models is None:
        return [GUIDANCE] * len(ROLES)
    from tssac_core.deploy.policy import load_team

    return list(load_team(models))


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    scenario = load(args.scenario)
    pilots = load_pilots(args.models)
    with tqdm(total=args.episodes, desc="missions", unit="mission", disable=args.no_progress, file=sys.stderr) as bar:
        results = fly_missions(scenario, pilots, args.episodes, args.seed, progress=bar.update)
    summary = results.summary(scenario.cost_limit)
    summary.update(
        {
            "controller": str(args.models) if args.models else GUIDANCE,
            "scenario": str(args.scenario),
            "seed": args.seed,
            "cost_limit": scenario.cost_limit,
        }
    )
    print(f"success rate {summary['success_rate']:.1%} over {summary['episodes']} missions, mean hazard cost per UAV {summary['mean_cost']:.2f} (limit {scenario.cost_limit:g})")
    for role, fig in summary["roles"].items():
        print(f"  {role:6s} task {fig['task_success_rate']:.1%}  cost mean {fig['mean_cost']:.2f} max {fig['max_cost']:.0f}  "
              f"left the area {fig['left_area_rate']:.1%}  return {fig['mean_return']:.1f}")
    if args.json:
        write_json(args.json, summary)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
