"""Which trained teams meet issue 23's batched-world targets: how many seeds of a recipe give a safe team.

    python -m tssac_core.experiments.targets runs/kd2/seed0 runs/kd2/seed1 runs/kd2/seed2 --seed 1100001 [--json FILE]

Every team flies missions 0-999 of ``--seed`` on scenarios/random.yaml and missions 0-499 of ``--seed`` + 1,000
on scenarios/generalization.yaml (mission k of seed S flies the layout of seed S + k, as ``evaluate`` does, so
the two sets draw from disjoint seeds and any mission can be flown again alone). A team meets a target when
its figures reach every threshold of it (:data:`TARGETS`); the 95% intervals are printed beside them. Pick a
seed that no training, selection or earlier evaluation used: a figure from layouts a choice was made on is
not evidence.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

from tssac_core.common.cli import UsageError, command_description, run, seed_arg, write_json
from tssac_core.common.evaluation_record import EvaluationRecord, EvaluationRecordJson
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import ROLES, SCENARIOS_DIR, load


@dataclass(frozen=True)
class Target:
    """One row of issue 23's table for the batched world."""

    scenario: str
    """A file of scenarios/."""
    missions: int
    min_success: float
    max_mean_cost: float
    """Mean hazard cost per UAV and mission."""
    min_within_limit: float | None = None
    """Every role's fraction of UAV-missions with a cost within C (None: not a target here)."""

    def to_json(self) -> TargetJson:
        return {
            "scenario": self.scenario,
            "missions": self.missions,
            "min_success": self.min_success,
            "max_mean_cost": self.max_mean_cost,
            "min_within_limit": self.min_within_limit,
        }


TARGETS = (
    Target("random.yaml", 1000, min_success=0.95, max_mean_cost=1.0, min_within_limit=0.995),
    Target("generalization.yaml", 500, min_success=0.90, max_mean_cost=1.0),
)


def misses(target: Target, record: EvaluationRecord) -> list[str]:
    """What of ``target`` the evaluation ``record`` does not reach, in words (empty: met)."""
    assert record.success_rate is not None and record.mean_cost is not None, "the batched world knows both"
    missed = []
    if record.success_rate < target.min_success:
        missed.append(f"success {record.success_rate:.1%} < {target.min_success:.0%}")
    if record.mean_cost > target.max_mean_cost:
        missed.append(f"mean cost {record.mean_cost:.2f} > {target.max_mean_cost:g}")
    if target.min_within_limit is not None:
        for role in ROLES:
            within = record.roles[role.value].within_cost_limit
            assert within is not None, "the batched world knows each role's cost"
            if within < target.min_within_limit:
                missed.append(f"{role.value} within C {within:.1%} < {target.min_within_limit:.1%}")
    return missed


class TargetJson(TypedDict):
    scenario: str
    missions: int
    min_success: float
    max_mean_cost: float
    min_within_limit: float | None


class TargetRow(TypedDict):
    """One target flown by one team: the target, the first mission's seed, the record and what is missed."""

    target: TargetJson
    seed: int
    summary: EvaluationRecordJson
    misses: list[str]


class TeamCheck(TypedDict):
    """A team against every target (what ``--json`` holds per team)."""

    team: str
    meets_every_target: bool
    targets: list[TargetRow]


def check_team(team: Path, seed: int, scale: float = 1.0) -> TeamCheck:
    """Fly ``team`` on every target's missions (``scale`` times as many, at least 1); its summaries and misses."""
    from tssac_core.deploy.policy import load_team  # torch: after the arguments are parsed

    pilots = list(load_team(team))
    rows: list[TargetRow] = []
    first = seed
    for target in TARGETS:
        scenario = load(SCENARIOS_DIR / target.scenario)
        missions = max(1, round(target.missions * scale))
        record = fly_missions(scenario, pilots, missions, first).record(scenario.cost_limit)
        rows.append(
            {"target": target.to_json(), "seed": first, "summary": record.to_json(), "misses": misses(target, record)}
        )
        first += missions
    return {"team": str(team), "meets_every_target": not any(r["misses"] for r in rows), "targets": rows}


def line(row: TargetRow) -> str:
    """One target's figures with their intervals, and what is missed."""
    s = EvaluationRecord.from_json(row["summary"])
    assert s.success_interval95 is not None and s.mean_cost_interval95 is not None, "the batched world knows both"
    lo, hi = s.success_interval95
    clo, chi = s.mean_cost_interval95
    within = " / ".join(f"{s.roles[r.value].within_cost_limit:.1%}" for r in ROLES)
    verdict = "met" if not row["misses"] else "MISSED: " + "; ".join(row["misses"])
    return (
        f"  {row['target']['scenario']:<20} {s.episodes:>5} (seed {row['seed']}): success {s.success_rate:.1%} "
        f"({lo:.1%}-{hi:.1%}), mean cost {s.mean_cost:.2f} ({clo:.2f}-{chi:.2f}), within C {within}: {verdict}"
    )


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tssac_core.experiments.targets", description=command_description(__doc__)
    )
    p.add_argument("teams", nargs="+", type=Path, help="directories holding decoy.pt, detect.pt, strike.pt")
    p.add_argument("--seed", type=seed_arg, required=True, help="the first layout seed (use one nothing else used)")
    p.add_argument("--json", type=Path, help="write every team's figures here")
    p.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="fly this share of each target's missions (a quick look: not the targets)",
    )
    args = p.parse_args(argv)
    if not args.scale > 0:
        raise UsageError(f"--scale must be positive, got {args.scale}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    results = []
    for team in args.teams:
        result = check_team(team, args.seed, args.scale)
        results.append(result)
        print(f"{team}: {'meets every target' if result['meets_every_target'] else 'misses'}")
        for row in result["targets"]:
            print(line(row))
    met = sum(r["meets_every_target"] for r in results)
    print(
        f"{met} of {len(results)} teams meet every target" + ("" if args.scale == 1.0 else f" (scale {args.scale:g})")
    )
    if args.json:
        write_json(args.json, {"seed": args.seed, "scale": args.scale, "teams_meeting": met, "teams": results})
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run(main))
