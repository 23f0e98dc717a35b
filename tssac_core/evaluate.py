"""``python -m tssac_core.evaluate``: fly whole three-UAV missions in the batched world and score them.

Examples::

    python -m tssac_core.evaluate --controller guidance --scenario scenarios/random.yaml --episodes 50 --seed 7
    python -m tssac_core.evaluate --models models/tssac --scenario scenarios/random.yaml --episodes 50 --json out.json
    python -m tssac_core.evaluate --models models/tssac --seed 770001 --mission 417     # one mission again, alone
    python -m tssac_core.evaluate --models models/tssac --episodes 1000 --seed 9 --shield --json shielded.json
    python -m tssac_core.evaluate --controller at_radar --episodes 200 --seed 2100001 --shield  # an adversary
    python -m tssac_core.evaluate --models onnx-team --episodes 50   # export --format onnx --out onnx-team's actors
    python -m tssac_core.evaluate --policy decoy=sb3:ppo-decoy.zip --decision-interval-s 1 --models models/tssac

Prints the success rate (target hit) with its 95% Wilson interval, the mean hazard cost per UAV per episode with
its 95% bootstrap interval over missions, per-role figures with the tail (the fraction of UAV-missions within
the cost limit C, the worst cost, CVaR_0.95) and the costliest UAV-missions; ``--json`` writes them as an evaluation
record (:mod:`tssac_core.common.evaluation_record`: ``success_rate``, ``success_interval95``, ``mean_cost``,
``mean_cost_interval95``, ``episodes``, one entry per role name under ``roles``, ``worst_missions`` (mission index,
layout seed, role, cost), what flew where, and ``record_version``).
Mission ``k`` of seed ``S`` flies its own layout, drawn from seed ``S + k`` (tssac_core.sim.missions), so
``--seed S --mission k`` flies any one of them again alone. ``--shield`` flies every UAV through the
runtime-assurance monitor (:mod:`tssac_core.assurance.monitor`, ``docs/runtime_assurance.md``) and adds its counts
under ``shield``: interventions per UAV-mission and the fraction of flight time under the backup. Off by
default: the learned policy is measured alone.

``--policy [ROLE=]KIND:FILE`` flies a policy trained anywhere (:mod:`tssac_core.deploy.any_policy`): ``sb3:`` a
Stable-Baselines3 model file, ``onnx:`` an ONNX actor, ``torch:`` a whole ``torch.nn.Module`` saved with ``torch.save``
(CleanRL's and OmniSafe's actors); one per role (``decoy=...``), or one for every UAV; the other roles fly ``--models``
or ``--controller``. ``--observation`` and ``--decision-interval-s`` say what the env it was trained on gave it and
how often it decided (the file's own word where it has one; they must agree). The policy is checked against the env's
spaces before the first mission; a mismatch is one line and exit code 2. The JSON is the same, plus ``policies`` (per
role: the policy, its observation and decision interval). From Python, :func:`evaluate_policy` does the same and
returns the JSON's dict.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NotRequired, TypedDict

from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError, command_description, run, seed_arg, write_json
from tssac_core.common.evaluation_record import (
    BatchedRun,
    EvaluationRecord,
    EvaluationRecordJson,
    WorldMonitorFigures,
)
from tssac_core.common.shield_options import SHIELD_ADJUST_HELP, adjust_option, adjusted_text, held_text
from tssac_core.deploy.policy_spec import PolicyError, PolicySpec, check_policy
from tssac_core.reporting.progress import MissionBar, ShardsBar
from tssac_core.sim.adversaries import ADVERSARY_NAMES, Adversary, AdversaryPilot
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.observation import ObservationMode
from tssac_core.sim.pilots import GUIDANCE, PilotSpec
from tssac_core.sim.scenario import DEFAULT_SCENARIO, ROLES, Role, Scenario, load_for_batched_world
from tssac_core.sim.shield_tuning import add_tuning_options, tuning_option

POLICY_KINDS = ("sb3", "onnx", "torch")
"""``--policy KIND:FILE``: a Stable-Baselines3 model, an ONNX actor, a whole torch module."""


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line, its values checked (UsageError, one line) and its policies read as sources."""
    args = build_parser().parse_args(argv)
    check_args(args)
    args.policy_sources = policy_sources(args.policy or [])
    return args


def build_parser() -> argparse.ArgumentParser:
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
        "--policy",
        action="append",
        metavar="[ROLE=]KIND:FILE",
        help="a policy trained anywhere, KIND sb3 (a Stable-Baselines3 model file), onnx (an ONNX actor) or torch (a "
        "torch.nn.Module saved whole); ROLE= for one role (repeat for others; the rest fly --models or --controller), "
        "without it for every UAV",
    )
    p.add_argument(
        "--observation",
        choices=[m.value for m in ObservationMode],
        help="with --policy: the observation of the env it was trained on (the env's default: route); an sb3 or "
        "TSSAC onnx file says its own",
    )
    p.add_argument(
        "--decision-interval-s",
        type=float,
        metavar="S",
        help="with --policy: seconds between its decisions in the env it was trained on (the env's default "
        "action_repeat=10 is 1.0); a TSSAC onnx file says its own",
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
    p.add_argument("--shield-adjust", action="store_true", help=SHIELD_ADJUST_HELP)
    add_tuning_options(p)
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
    return p


def check_args(args: argparse.Namespace) -> None:
    """The values no flag's type checks: counts, margins, and what goes with --policy."""
    if args.episodes <= 0:
        raise UsageError("--episodes must be positive")
    if args.mission is not None and args.mission < 0:
        raise UsageError(f"--mission must be >= 0, got {args.mission}")
    if args.workers <= 0:
        raise UsageError(f"--workers must be positive, got {args.workers}")
    if not (math.isfinite(args.shield_margin_m) and args.shield_margin_m >= 0):
        raise UsageError(f"--shield-margin-m must be a finite number >= 0, got {args.shield_margin_m}")
    if not args.policy and (args.observation is not None or args.decision_interval_s is not None):
        raise UsageError("--observation and --decision-interval-s describe a --policy: give one")
    if args.decision_interval_s is not None and not (
        math.isfinite(args.decision_interval_s) and args.decision_interval_s > 0
    ):
        raise UsageError(f"--decision-interval-s must be a positive number of seconds, got {args.decision_interval_s}")


def policy_sources(texts: Sequence[str]) -> dict[Role | None, tuple[str, Path]]:
    """``--policy`` values as {role (None: every UAV): (kind, file)}; UsageError for a malformed or repeated one."""
    found: dict[Role | None, tuple[str, Path]] = {}
    for text in texts:
        role_text, sep, source = text.partition("=")
        if not sep:
            role_text, source = "", text
        kind, sep, file = source.partition(":")
        if not sep or kind not in POLICY_KINDS or not file:
            raise UsageError(f"--policy {text!r}: expected [ROLE=]KIND:FILE with KIND one of {', '.join(POLICY_KINDS)}")
        try:
            role = Role(role_text) if role_text else None
        except ValueError:
            raise UsageError(f"--policy {text!r}: {role_text!r} is not decoy, detect or strike") from None
        if role in found or (found and (role is None or None in found)):
            raise UsageError(f"--policy {text!r}: one policy per role (ROLE=), or one for every UAV alone")
        found[role] = (kind, Path(file))
    return found


def load_policy_spec(
    kind: str, path: Path, role: Role | None, observation: str | None, decision_interval_s: float | None
) -> PolicySpec:
    """The spec of a ``--policy`` file (:mod:`tssac_core.deploy.any_policy`)."""
    from tssac_core.deploy import any_policy

    if kind == "sb3":
        from tssac_core.deploy.sb3_policy import from_sb3

        return from_sb3(path, observation, decision_interval_s, role=role)
    if kind == "onnx":
        return any_policy.from_onnx(path, observation, decision_interval_s, role=role)
    module = any_policy.load_torch_module(path)
    return any_policy.from_torch(module, observation, decision_interval_s, role=role, name=str(path))


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
) -> dict[str, EvaluationRecord]:
    """A team (a models directory, None = the guidance controller) on the same missions with the monitor off
    and on: ``{"off": record, "on": record}`` (the "with monitor" column of Table 4: success, cost, and the
    time under the backup, ``on.monitor.backup_time_fraction``)."""
    pilots = load_pilots(models)
    cfg = shield or ShieldConfig()  # the starts of both runs admitted with the monitor's margins: the same layouts
    off = fly_missions(scenario, pilots, episodes, seed, start_check=cfg).record(scenario.cost_limit)
    on = fly_missions(scenario, pilots, episodes, seed, shield=cfg).record(scenario.cost_limit)
    return {"off": off, "on": on}


class PolicyDescription(TypedDict):
    """One role's entry in the JSON's ``policies``: the policy's name, the observation it takes and its decision
    interval."""

    policy: str
    observation: str
    decision_interval_s: float


class EvaluationJson(EvaluationRecordJson):
    """What ``--json`` writes: the evaluation record, and with ``--policy`` the policies flown."""

    policies: NotRequired[dict[str, PolicyDescription]]


def fly_pilots(
    policies: Mapping[Role | str, PolicySpec] | PolicySpec,
    scenario: Scenario,
    models: Path | None,
    controller: str = GUIDANCE,
) -> tuple[list[PilotSpec], dict[str, PolicyDescription]]:
    """The team's pilots with ``policies`` in their roles (one spec: every role), each checked against its role's env
    before any mission (PolicyError, one line); the other roles fly ``models``' actors or ``controller``. Also the
    JSON's ``policies`` entry: per role its name, observation and decision interval."""
    given = {role: policies for role in ROLES} if isinstance(policies, PolicySpec) else dict(policies)
    specs = {}
    for role, spec in given.items():
        try:
            specs[Role(role)] = spec
        except ValueError:
            raise PolicyError(f"role {role!r} is not decoy, detect or strike") from None
        if not isinstance(spec, PolicySpec):
            raise PolicyError(
                f"the {Role(role).value} policy is a {type(spec).__name__}, not a PolicySpec (from_callable, from_sb3, "
                "from_onnx, from_torch)"
            )
    if not specs:
        raise PolicyError("no policy given")
    checked = {role: check_policy(spec, role, scenario.dt_s) for role, spec in specs.items()}
    pilots: list[PilotSpec] = [None] * len(ROLES)
    if len(checked) < len(ROLES):
        pilots = load_pilots(models, controller)
    for j, role in enumerate(ROLES):
        if role in checked:
            pilots[j] = checked[role]
    described: dict[str, PolicyDescription] = {
        role.value: {
            "policy": spec.name,
            "observation": spec.observation_mode.value,
            "decision_interval_s": spec.decision_interval_s,
        }
        for role, spec in specs.items()
    }
    return pilots, described


def fly_team(
    scenario: Scenario,
    pilots: Sequence[PilotSpec],
    indices: Sequence[int],
    seed: int,
    shield: ShieldConfig | None,
    workers: int = 1,
    address: str | None = None,
    progress: bool = True,
) -> MissionResults:
    """Missions ``indices`` of seed ``seed`` flown by ``pilots``: in one batch here, or in shards on Ray workers."""
    if workers > 1 or address is not None:
        from tssac_core.parallel.mission_shards import fly_missions_sharded, shard_count
        from tssac_core.parallel.ray_cluster import RayTarget

        with ShardsBar(len(indices), shard_count(len(indices), workers), disable=not progress) as bar:
            return fly_missions_sharded(
                scenario, pilots, list(indices), seed, workers, RayTarget(address), bar.update, shield=shield
            )
    with MissionBar(len(indices), scenario.episode_steps, disable=not progress) as bar:
        return fly_missions(scenario, pilots, len(indices), seed, indices=indices, shield=shield, on_step=bar.step)


def summarize(
    results: MissionResults,
    scenario: Scenario,
    scenario_path: Path,
    controller: str,
    seed: int,
    shield: ShieldConfig | None,
) -> EvaluationRecord:
    """The results' record (:meth:`MissionResults.record`) with what flew them, where, with which seed, and the
    monitor's settings when it flew."""
    record = dataclasses.replace(
        results.record(scenario.cost_limit),
        run=BatchedRun(controller=controller, scenario=str(scenario_path), seed=seed, cost_limit=scenario.cost_limit),
    )
    return record if shield is None else record.with_monitor_config(dataclasses.asdict(shield))


def evaluate_policy(
    policies: Mapping[Role | str, PolicySpec] | PolicySpec,
    scenario: str | Path = DEFAULT_SCENARIO,
    episodes: int = 50,
    seed: int = 12345,
    *,
    team: str | Path | None = None,
    controller: str = GUIDANCE,
    shield: bool | ShieldConfig = False,
    mission: int | None = None,
    json: str | Path | None = None,
    progress: bool = True,
) -> EvaluationJson:
    """Evaluate a policy trained anywhere as ``python -m tssac_core.evaluate --policy`` does, and return the JSON's
    dict (the same figures, intervals and keys as for the shipped team, plus ``policies``).

    ``policies``: a :class:`~tssac_core.deploy.any_policy.PolicySpec` for every UAV, or role -> spec (``from_sb3``,
    ``from_onnx``, ``from_torch``, ``from_callable``: what it was trained on stated); the other roles fly the actors of
    the models directory ``team`` (e.g. ``"models/tssac"``), else ``controller``. Each spec is checked against its
    role's env before the first mission (PolicyError, one line). ``shield``: fly through the runtime-assurance monitor
    (True: its default margins). ``json``: also write the dict there."""
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes <= 0:
        raise PolicyError(f"episodes must be a positive whole number, got {episodes!r}")
    path = Path(scenario)
    world = load_for_batched_world(path)
    pilots, described = fly_pilots(policies, world, None if team is None else Path(team), controller)
    config = ShieldConfig() if shield is True else (shield or None)
    indices = [mission] if mission is not None else list(range(episodes))
    results = fly_team(world, pilots, indices, seed, config, progress=progress)
    record = summarize(results, world, path, policies_label(described, team, controller), seed, config)
    summary: EvaluationJson = {**record.to_json(), "policies": described}
    if json is not None:
        write_json(json, summary)
    return summary


def policies_label(described: Mapping[str, PolicyDescription], models: Path | str | None, controller: str) -> str:
    """The JSON's ``controller`` for a policy run: ``decoy=ppo.zip, others=models/tssac``."""
    mine = ", ".join(f"{role}={d['policy']}" for role, d in described.items())
    if len(described) == len(ROLES):
        return mine
    return f"{mine}, others={models if models is not None else controller}"


def console() -> int:
    """``tssac-evaluate`` and ``python -m tssac_core.evaluate``: :func:`main` with known errors as one line (exit 2)."""
    return run(main)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    scenario = load_for_batched_world(args.scenario)
    controller = args.controller or GUIDANCE
    who = str(args.models) if args.models else controller
    described: dict[str, PolicyDescription] = {}
    if args.policy_sources:
        specs = {
            role: load_policy_spec(kind, path, role, args.observation, args.decision_interval_s)
            for role, (kind, path) in args.policy_sources.items()
        }
        given = specs[None] if None in specs else {role: spec for role, spec in specs.items() if role is not None}
        pilots, described = fly_pilots(given, scenario, args.models, controller)
        who = policies_label(described, args.models, controller)
    else:
        pilots = load_pilots(args.models, controller)
    adjust = adjust_option(args.shield_adjust, args.shield)
    tuning = tuning_option(args, args.shield)
    shield = tuning.config(adjust, args.shield_margin_m) if args.shield else None
    indices = [args.mission] if args.mission is not None else list(range(args.episodes))
    results = fly_team(scenario, pilots, indices, args.seed, shield, args.workers, args.address, not args.no_progress)
    record = summarize(results, scenario, args.scenario, who, args.seed, shield)
    print_summary(record, scenario.cost_limit)
    if args.json:
        summary: EvaluationJson = {**record.to_json()}
        if described:
            summary["policies"] = described
        write_json(args.json, summary)
        print(f"wrote {args.json}")
    return 0


def print_summary(record: EvaluationRecord, cost_limit: float) -> None:
    """The record's figures, intervals and tails, and its worst missions, on stdout."""
    assert record.success_interval95 is not None and record.mean_cost_interval95 is not None, "the batched world's"
    lo, hi = record.success_interval95
    clo, chi = record.mean_cost_interval95
    print(
        f"success rate {record.success_rate:.1%} (95% interval {lo:.1%}-{hi:.1%}) over {record.episodes} missions, "
        f"mean hazard cost per UAV {record.mean_cost:.2f} (95% interval {clo:.2f}-{chi:.2f}; limit {cost_limit:g})"
    )
    for role, fig in record.roles.items():
        print(
            f"  {role:6s} task {fig.task_success_rate:.1%}  cost mean {fig.mean_cost:.2f} within C "
            f"{fig.within_cost_limit:.1%} CVaR95 {fig.cvar95_cost:.1f} max {fig.max_cost:.0f}  left the area "
            f"{fig.left_area_rate:.1%}  return {fig.mean_return:.1f}"
        )
    for row in record.worst_missions:
        print(f"  worst: mission {row.mission} (layout seed {row.seed}) {row.role} cost {row.cost:.0f}")
    sh = record.monitor
    if isinstance(sh, WorldMonitorFigures):
        print(
            f"shield: {sh.interventions_per_uav_mission:.2f} interventions per UAV-mission (max "
            f"{sh.max_interventions_per_uav_mission}), {sh.backup_time_fraction:.2%} of flight time under the backup"
            f"{adjusted_text(sh.adjusted_time_fraction)}{held_text(sh.held_time_fraction)}, "
            f"{sh.uav_missions_with_cost} UAV-missions with cost, {sh.uavs_left_area} UAVs left the area"
        )


if __name__ == "__main__":
    sys.exit(console())
