"""``python -m tssac_core.evaluate``: fly whole three-UAV missions in the batched world and score them.

Examples::

    python -m tssac_core.evaluate --controller guidance --scenario scenarios/random.yaml --episodes 50 --seed 7
    python -m tssac_core.evaluate --models models/tssac --scenario scenarios/random.yaml --episodes 50 --json out.json
    python -m tssac_core.evaluate --models models/tssac --seed 770001 --mission 417     # one mission again, alone
    python -m tssac_core.evaluate --models models/tssac --episodes 1000 --seed 9 --shield --json shielded.json
    python -m tssac_core.evaluate --controller at_radar --episodes 200 --seed 2100001 --shield  # an adversary
    python -m tssac_core.evaluate --models onnx-team --episodes 50   # export --format onnx --out onnx-team's actors

Prints the success rate (target hit) with its 95% Wilson interval, the mean hazard cost per UAV per episode with
its 95% bootstrap interval over missions, per-role figures with the tail (the fraction of UAV-missions within
the cost limit C, the worst cost, CVaR_0.95) and the costliest UAV-missions; ``--json`` writes them with the
keys ``success_rate``, ``success_interval95``, ``mean_cost``, ``mean_cost_interval95``, ``episodes``, one
entry per role name under ``roles`` and ``worst_missions`` (mission index, layout seed, role, cost).
Mission ``k`` of seed ``S`` flies its own layout, drawn from seed ``S + k`` (tssac_core.sim.missions), so
``--seed S --mission k`` flies any one of them again alone. ``--shield`` flies every UAV through the
runtime-assurance monitor (:mod:`tssac_core.assurance.monitor`, ``docs/runtime_assurance.md``) and adds its counts
under ``shield``: interventions per UAV-mission and the fraction of flight time under the backup. Off by
default: the learned policy is measured alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError, command_description, run, seed_arg, write_json
from tssac_core.reporting.progress import MissionBar, progress_bar
from tssac_core.sim.adversaries import ADVERSARY_NAMES, Adversary, AdversaryPilot
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.pilots import GUIDANCE, PilotSpec
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Scenario, load_for_batched_world


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m tssac_core.evaluate", description=command_description(__doc__))
    who = p.add_mutually_exclusive_group()
    who.add_argument(
        "--controller",
        choices=[GUIDANCE, *ADVERSARY_NAMES],
        help="fly every UAV with the rule-based guidance controller (default without --models), or with an "
        "adversary built to break the monitor (docs/runtime_assurance.md, 'Adversarial pilots')",
    )
    who.add_argument(
        "--models",
        type=Path,
        help="directory holding decoy.pt, detect.pt, strike.pt (made by tssac_core.train), or decoy.onnx, detect.onnx, "
        "strike.onnx (made by tssac_core.deploy.export --format onnx; flown with onnxruntime)",
    )
    p.add_argument(
        "--scenario", type=Path, default=DEFAULT_SCENARIO, help="scenario file (default: scenarios/random.yaml)"
    )
    p.add_argument("--episodes", type=int, default=50, help="missions to fly (default 50)")
    p.add_argument(
        "--seed",
        type=seed_arg,
        default=12345,
        help="mission k flies the layout of seed S + k (default 12345, never used in training)",
    )
    p.add_argument(
        "--mission", type=int, metavar="K", help="fly only mission K of --seed (e.g. one of the JSON's worst_missions)"
    )
    p.add_argument(
        "--shield", action="store_true", help="fly through the runtime-assurance monitor (docs/runtime_assurance.md)"
    )
    p.add_argument(
        "--shield-margin-m",
        type=float,
        default=ShieldConfig.margin_m,
        metavar="M",
        help=f"with --shield: clearance kept from every radar and edge (default {ShieldConfig.margin_m:g})",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        metavar="N",
        help="fly the missions in N shards on Ray workers (default 1: in one batch here, without Ray); same results",
    )
    p.add_argument(
        "--address",
        metavar="HOST:PORT",
        help="fly the shards on this existing Ray cluster (default with --workers: a Ray started inside the command)",
    )
    p.add_argument("--json", type=Path, help="write the results here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if args.episodes <= 0:
        raise UsageError("--episodes must be positive")
    if args.mission is not None and args.mission < 0:
        raise UsageError(f"--mission must be >= 0, got {args.mission}")
    if args.workers <= 0:
        raise UsageError(f"--workers must be positive, got {args.workers}")
    if not (math.isfinite(args.shield_margin_m) and args.shield_margin_m >= 0):
        raise UsageError(f"--shield-margin-m must be a finite number >= 0, got {args.shield_margin_m}")
    return args


def load_pilots(models: Path | None, controller: str = GUIDANCE) -> list[PilotSpec]:
    """The team's pilots: the actors in ``models`` (its ``<role>.pt``, or its ``<role>.onnx`` in a directory of ONNX
    actors), else the ``controller`` (guidance or an adversary) for every UAV."""
    if models is None:
        if controller in ADVERSARY_NAMES:
            return [AdversaryPilot(Adversary(controller))] * len(ROLES)
        return [GUIDANCE] * len(ROLES)
    from tssac_core.deploy.numpy_actor import holds_onnx, load_policy

    if holds_onnx(models):
        return [load_policy(models, role) for role in ROLES]
    from tssac_core.deploy.policy import load_team

    return list(load_team(models))


def compare_shield(
    models: Path | None, scenario: Scenario, episodes: int, seed: int, shield: ShieldConfig | None = None
) -> dict[str, dict[str, Any]]:
    """A team (a models directory, None = the guidance controller) on the same missions with the monitor off
    and on: ``{"off": summary, "on": summary}`` (the "with monitor" column of Table 4: success, cost, and the
    time under the backup, ``on["shield"]["backup_time_fraction"]``)."""
    pilots = load_pilots(models)
    cfg = shield or ShieldConfig()  # the starts of both runs admitted with the monitor's margins: the same layouts
    off = fly_missions(scenario, pilots, episodes, seed, start_check=cfg).summary(scenario.cost_limit)
    on = fly_missions(scenario, pilots, episodes, seed, shield=cfg).summary(scenario.cost_limit)
    return {"off": off, "on": on}


def console() -> int:
    """``tssac-evaluate`` and ``python -m tssac_core.evaluate``: :func:`main` with known errors as one line (exit 2)."""
    return run(main)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    scenario = load_for_batched_world(args.scenario)
    controller = args.controller or GUIDANCE
    pilots = load_pilots(args.models, controller)
    shield = ShieldConfig(margin_m=args.shield_margin_m) if args.shield else None
    indices = [args.mission] if args.mission is not None else list(range(args.episodes))
    if args.workers > 1 or args.address is not None:
        from tssac_core.parallel.mission_shards import fly_missions_sharded
        from tssac_core.parallel.ray_cluster import RayTarget

        with progress_bar(total=len(indices), desc="missions", unit="mission", disable=args.no_progress) as bar:
            results = fly_missions_sharded(
                scenario, pilots, indices, args.seed, args.workers, RayTarget(args.address), bar.update, shield=shield
            )
    else:
        with MissionBar(len(indices), scenario.episode_steps, disable=args.no_progress) as bar:
            results = fly_missions(
                scenario,
                pilots,
                len(indices),
                args.seed,
                indices=indices,
                shield=shield,
                on_step=bar.step,
            )
    summary = results.summary(scenario.cost_limit)
    summary.update(
        {
            "controller": str(args.models) if args.models else controller,
            "scenario": str(args.scenario),
            "seed": args.seed,
            "cost_limit": scenario.cost_limit,
        }
    )
    if shield is not None:
        summary["shield"]["config"] = dataclasses.asdict(shield)
    print_summary(summary, scenario.cost_limit)
    if args.json:
        write_json(args.json, summary)
        print(f"wrote {args.json}")
    return 0


def print_summary(summary: dict[str, Any], cost_limit: float) -> None:
    """The summary's figures, intervals and tails, and its worst missions, on stdout."""
    lo, hi = summary["success_interval95"]
    clo, chi = summary["mean_cost_interval95"]
    print(
        f"success rate {summary['success_rate']:.1%} (95% interval {lo:.1%}-{hi:.1%}) over {summary['episodes']} "
        f"missions, "
        f"mean hazard cost per UAV {summary['mean_cost']:.2f} (95% interval {clo:.2f}-{chi:.2f}; limit {cost_limit:g})"
    )
    for role, fig in summary["roles"].items():
        print(
            f"  {role:6s} task {fig['task_success_rate']:.1%}  cost mean {fig['mean_cost']:.2f} within C "
            f"{fig['within_cost_limit']:.1%} "
            f"CVaR95 {fig['cvar95_cost']:.1f} max {fig['max_cost']:.0f}  left the area {fig['left_area_rate']:.1%}  "
            f"return {fig['mean_return']:.1f}"
        )
    for row in summary["worst_missions"]:
        print(f"  worst: mission {row['mission']} (layout seed {row['seed']}) {row['role']} cost {row['cost']:.0f}")
    if "shield" in summary:
        sh = summary["shield"]
        print(
            f"shield: {sh['interventions_per_uav_mission']:.2f} interventions per UAV-mission (max "
            f"{sh['max_interventions_per_uav_mission']}), "
            f"{sh['backup_time_fraction']:.2%} of flight time under the backup, {sh['uav_missions_with_cost']} "
            f"UAV-missions with cost, "
            f"{sh['uavs_left_area']} UAVs left the area"
        )


if __name__ == "__main__":
    sys.exit(console())
