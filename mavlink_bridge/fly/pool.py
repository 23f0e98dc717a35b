"""``python -m mavlink_bridge.fly.pool A.json B.json ... [--json OUT]``: the figures of several ``fly`` campaigns
of one team on one scenario as one campaign (a campaign that spanned sittings, or one added to an earlier one).

Every mission is one layout of its own seed, so campaigns on disjoint layout seeds pool exactly: success with its
Wilson interval, the mean cost per UAV with the bootstrap interval over missions, and the tail per role, the same
figures (``tssac_core.common.stats.mission_statistics``) as one ``fly`` run of all the missions would give. Campaigns of
different teams, scenarios, cost limits or clocks, or that share a layout seed, are refused in one line.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from tssac_core.common.cli import write_json
from tssac_core.common.stats import mission_statistics
from tssac_core.sim.scenario import ROLES

SAME = ("pilot", "cost_limit", "clock")
"""What every pooled campaign must agree on (the scenario is compared by its file name)."""


class PoolError(Exception):
    """A set of campaigns that cannot be pooled, or a file that is not a campaign."""


def read_campaign(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PoolError(f"{path}: not a fly results file ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("missions"), list):
        raise PoolError(f"{path}: not a fly results file (no missions)")
    if any(not m.get("cost") for m in data["missions"]):
        raise PoolError(f"{path}: a mission without its cost (a crashed mission): pool only complete campaigns")
    return data


def pool(campaigns: Sequence[dict[str, Any]], names: Sequence[str]) -> dict[str, Any]:
    """The pooled figures of ``campaigns`` (fly results JSON, in order)."""
    first = campaigns[0]
    for data, name in zip(campaigns[1:], names[1:], strict=True):
        for key in SAME:
            if data.get(key) != first.get(key):
                raise PoolError(f"{name}: {key} {data.get(key)!r} differs from {names[0]}'s {first.get(key)!r}")
        if Path(str(data.get("scenario"))).name != Path(str(first.get("scenario"))).name:
            raise PoolError(
                f"{name}: scenario {data.get('scenario')} differs from {names[0]}'s {first.get('scenario')}"
            )
    missions = [m for data in campaigns for m in data["missions"]]
    seeds = [int(m["seed"]) for m in missions]
    if len(set(seeds)) != len(seeds):
        raise PoolError("the campaigns share layout seeds: pool campaigns of disjoint seeds only")
    success = np.array([bool(m["success"]) for m in missions])
    cost = np.array([[m["cost"][r.value] for r in ROLES] for m in missions], dtype=np.float64)
    roles = [r.value for r in ROLES]
    stats = mission_statistics(success, cost, float(first["cost_limit"]), roles, seeds)
    return {
        "success_rate": float(success.mean()),
        "success_interval95": stats["success_interval95"],
        "mean_cost": float(cost.mean()),
        "mean_cost_interval95": stats["mean_cost_interval95"],
        "episodes": len(missions),
        "roles": stats["roles_tail"],
        "worst_missions": stats["worst_missions"],
        "campaigns": [
            {"file": n, "seed": d.get("seed"), "episodes": len(d["missions"])} for n, d in zip(names, campaigns)
        ],
        **{key: first.get(key) for key in SAME},
        "scenario": Path(str(first.get("scenario"))).name,
    }


def _fail(message: str) -> NoReturn:
    print(f"python -m mavlink_bridge.fly.pool: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mavlink_bridge.fly.pool", description=__doc__.split("\n\n")[0])
    parser.add_argument("campaigns", nargs="+", type=Path, help="fly --json results of one team on one scenario")
    parser.add_argument("--json", type=Path, help="write the pooled figures here")
    args = parser.parse_args(argv)
    try:
        pooled = pool([read_campaign(p) for p in args.campaigns], [str(p) for p in args.campaigns])
    except PoolError as exc:
        _fail(str(exc))
    lo, hi = pooled["success_interval95"]
    clo, chi = pooled["mean_cost_interval95"]
    print(
        f"success rate {pooled['success_rate']:.1%} (95% interval {lo:.1%}-{hi:.1%}) over {pooled['episodes']} "
        f"missions, mean hazard cost per UAV {pooled['mean_cost']:.2f} (95% interval {clo:.2f}-{chi:.2f})"
    )
    for role, tail in pooled["roles"].items():
        print(f"  {role:6s} within C {tail['within_cost_limit']:.1%}  worst {tail['max_cost']:.0f}")
    if args.json is not None:
        write_json(args.json, pooled)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
