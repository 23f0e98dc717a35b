"""``python -m mavlink_bridge.fly.pool A.json B.json ... [--json OUT]``: the figures of several ``fly`` campaigns
of one team on one scenario as one campaign (a campaign that spanned sittings, or one added to an earlier one).

Every mission is one layout of its own seed, so campaigns on disjoint layout seeds pool exactly: success with its
Wilson interval, the mean cost per UAV with the bootstrap interval over missions, and the tail per role, the same
figures (``tssac_core.common.stats.pooled_record``) as one ``fly`` run of all the missions would give.

Every file is checked before anything is pooled, and what cannot be pooled is refused in one line (exit 2): a file
that is not a fly results file (unreadable, not UTF-8, not JSON, not an object, no missions); a mission whose fields
are not what fly writes (``success`` a JSON boolean, the cost of each role a finite number of steps >= 0, ``index``
and ``seed`` whole numbers with ``seed`` = the campaign's seed + ``index``); campaigns of different teams, scenarios,
cost limits, clocks, physics, wind or monitor settings, or that share a layout seed. A campaign that did not fly
every mission it was asked for (interrupted, stopped by an error) is refused too unless ``--partial`` is given: its
finished missions are then pooled, with one line on stderr saying so, provided no mission is missing before its last
finished one (a missing one may be the long mission that stopped it) unless another campaign flew it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn, TypedDict, TypeGuard

import numpy as np

from tssac_core.common.cli import bad_input_line, command_description, write_json
from tssac_core.common.evaluation_record import EvaluationRecord, EvaluationRecordJson
from tssac_core.common.stats import pooled_record
from tssac_core.sim.scenario import ROLES

PROG = "python -m mavlink_bridge.fly.pool"
SAME = ("pilot", "cost_limit", "clock")
"""What every pooled campaign must agree on as written (the scenario is compared by its file name; the physics, wind
and monitor by :func:`_flight_settings`)."""
MAX_FILE_BYTES = 512 * 1024 * 1024
"""The largest results file read (fly writes about 2 kB per mission): a device or a pipe that never ends is refused
instead of filling the memory."""


class PoolError(Exception):
    """A set of campaigns that cannot be pooled, or a file that is not a campaign; ``str()`` is one line."""


@dataclass(frozen=True)
class Mission:
    """What pooling reads of one mission row."""

    index: int
    seed: int
    success: bool
    cost: tuple[float, ...]
    """Steps inside a radar per role, in :data:`ROLES` order."""
    sim_time_s: float | None = None
    """The mission's simulated time, where its row gives one."""


@dataclass(frozen=True)
class Campaign:
    """One checked fly results file."""

    name: str
    data: dict[str, Any]
    missions: list[Mission]
    stopped: str | None
    """Why it did not fly every mission it was asked for (None: it did)."""


def _read_text(path: Path) -> str:
    """The file's text, at most :data:`MAX_FILE_BYTES`."""
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise PoolError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise PoolError(f"{path}: not a fly results file (more than {MAX_FILE_BYTES:,} bytes)")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise PoolError(f"{path}: not a fly results file (not UTF-8 text)") from None


def _is_whole(value: object) -> TypeGuard[int]:
    """A JSON integer (a JSON boolean is not one, though Python's bool is an int)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _mission(row: object, k: int, campaign_seed: int, where: str) -> Mission:
    """Mission row ``k`` checked field by field (PoolError naming the row and the field)."""
    at = f"{where}: mission row {k}"
    if not isinstance(row, dict):
        raise PoolError(f"{at} is not a JSON object")
    for key in ("index", "seed", "success", "cost"):
        if key not in row:
            hint = " (a crashed mission): pool only complete missions" if key == "cost" else ""
            raise PoolError(f"{at} has no {key!r}{hint}")
    index, seed, success, cost = row["index"], row["seed"], row["success"], row["cost"]
    if not _is_whole(index) or index < 0:
        raise PoolError(f"{at}: 'index' must be a whole number >= 0, got {index!r}")
    if not _is_whole(seed):
        raise PoolError(f"{at}: 'seed' must be a whole number, got {seed!r}")
    if seed != campaign_seed + index:
        raise PoolError(f"{at}: seed {seed} is not the campaign's seed {campaign_seed} + index {index}")
    if not isinstance(success, bool):
        raise PoolError(f"{at}: 'success' must be true or false, got {success!r}")
    if not isinstance(cost, dict):
        hint = " (a crashed mission): pool only complete missions" if cost is None else ""
        raise PoolError(f"{at}: 'cost' must be an object of the roles' costs, got {cost!r}{hint}")
    names = [r.value for r in ROLES]
    if sorted(cost) != sorted(names):
        raise PoolError(f"{at}: 'cost' must give exactly the roles {', '.join(names)}, got {', '.join(map(str, cost))}")
    for name in names:
        value = cost[name]
        if not (_is_number(value) and math.isfinite(value) and value >= 0):
            raise PoolError(f"{at}: the {name}'s cost must be a finite number of steps >= 0, got {value!r}")
    time_s = row.get("sim_time_s")
    sim_time_s = float(time_s) if _is_number(time_s) and math.isfinite(time_s) and time_s >= 0 else None
    return Mission(index, seed, success, tuple(float(cost[n]) for n in names), sim_time_s)


def _stopped(data: dict[str, Any], flown: int) -> str | None:
    """Why a campaign flew fewer missions than asked (None: it flew them all)."""
    requested = data.get("episodes_requested", flown)
    if not _is_whole(requested) or requested < 1:
        raise PoolError(f"'episodes_requested' must be a whole number >= 1, got {requested!r}")
    if data.get("interrupted") is True:
        return f"interrupted after {flown} of {requested} missions"
    if data.get("error") is not None:
        return f"stopped by an error after {flown} of {requested} missions"
    if flown < requested:
        return f"{flown} of {requested} missions"
    return None


def check_campaign(data: object, name: str) -> Campaign:
    """A parsed results file checked for pooling (the module docstring lists what is refused)."""
    if not isinstance(data, dict):
        raise PoolError(f"{name}: not a fly results file (a JSON object expected)")
    missions = data.get("missions")
    if not isinstance(missions, list):
        raise PoolError(f"{name}: not a fly results file (no list of missions)")
    if not missions:
        raise PoolError(f"{name}: no missions to pool")
    for key in ("pilot", "scenario", "clock"):
        if not isinstance(data.get(key), str):
            raise PoolError(f"{name}: {key!r} must be a string, got {data.get(key)!r}")
    limit = data.get("cost_limit")
    if not (_is_number(limit) and math.isfinite(limit) and limit >= 0):
        raise PoolError(f"{name}: 'cost_limit' must be a finite number >= 0, got {limit!r}")
    seed = data.get("seed")
    if not _is_whole(seed):
        raise PoolError(f"{name}: 'seed' must be a whole number, got {seed!r}")
    rows = [_mission(row, k, seed, name) for k, row in enumerate(missions)]
    if "episodes" in data and data["episodes"] != len(rows):
        raise PoolError(f"{name}: 'episodes' says {data['episodes']!r} but the file has {len(rows)} missions")
    try:
        stopped = _stopped(data, len(rows))
    except PoolError as exc:
        raise PoolError(f"{name}: {exc}") from None
    return Campaign(name, data, rows, stopped)


def read_results(path: Path) -> dict[str, Any]:
    """A results file parsed, a JSON object holding a list of missions, its rows not yet checked (PoolError: one line
    naming the file)."""
    text = _read_text(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PoolError(f"{path}: not a fly results file (not JSON: {exc})") from None
    except RecursionError:
        raise PoolError(f"{path}: not a fly results file (nested too deeply)") from None
    if not isinstance(data, dict):
        raise PoolError(f"{path}: not a fly results file (a JSON object expected)")
    if not isinstance(data.get("missions"), list):
        raise PoolError(f"{path}: not a fly results file (no list of missions)")
    return data


def read_campaign(path: Path) -> Campaign:
    """A results file read and checked (PoolError: one line naming the file)."""
    return check_campaign(read_results(path), str(path))


def _flight_settings(data: dict[str, Any]) -> tuple[object, object, object]:
    """The physics, wind and monitor a campaign flew with (files of before the physics seam were kinematic, in still
    air): the monitor by whether it flew and what its bound rests on (its ``scope``: eq. 5 or an airframe's response;
    None where its proof holds)."""
    dynamics = data.get("dynamics")
    model = dynamics.get("model") if isinstance(dynamics, dict) else "kinematic"
    aircraft = dynamics.get("aircraft") if isinstance(dynamics, dict) and model != "kinematic" else None
    shield = data.get("shield")
    monitor = (True, shield.get("scope")) if isinstance(shield, dict) else ("shield" in data, None)
    return (model, aircraft), data.get("wind"), monitor


def _check_together(campaigns: Sequence[Campaign], partial: bool) -> None:
    """The campaigns are of one team on one scenario, disjoint, and complete (or ``partial`` without a gap)."""
    first = campaigns[0]
    for c in campaigns[1:]:
        for key in SAME:
            if c.data.get(key) != first.data.get(key):
                raise PoolError(
                    f"{c.name}: {key} {c.data.get(key)!r} differs from {first.name}'s {first.data.get(key)!r}"
                )
        if Path(c.data["scenario"]).name != Path(first.data["scenario"]).name:
            raise PoolError(
                f"{c.name}: scenario {c.data['scenario']} differs from {first.name}'s {first.data['scenario']}"
            )
        for what, mine, theirs in zip(
            ("physics", "wind", "monitor (--shield)"),
            _flight_settings(c.data),
            _flight_settings(first.data),
            strict=True,
        ):
            if mine != theirs:
                raise PoolError(f"{c.name}: {what} {mine!r} differs from {first.name}'s {theirs!r}")
    seeds = [m.seed for c in campaigns for m in c.missions]
    if len(set(seeds)) != len(seeds):
        raise PoolError("the campaigns share layout seeds: pool campaigns of disjoint seeds only")
    flown = set(seeds)
    for c in campaigns:
        if c.stopped is None:
            continue
        if not partial:
            raise PoolError(f"{c.name}: {c.stopped}: pool only complete campaigns (--partial pools its finished ones)")
        last = max(m.index for m in c.missions)
        gap = [i for i in range(last) if c.data["seed"] + i not in flown]
        if gap:
            raise PoolError(
                f"{c.name}: {c.stopped}, and mission {gap[0]} (seed {c.data['seed'] + gap[0]}) before its last "
                f"finished one was not flown ({len(gap)} such): fly it (--seed {c.data['seed']} --mission {gap[0]}) "
                "and pool it too"
            )


class PooledCampaign(TypedDict):
    file: str
    seed: int
    episodes: int
    complete: bool


class PooledJson(EvaluationRecordJson):
    """What ``fly.pool --json`` writes: the pooled record, the campaigns, and what they all flew (:data:`SAME`, the
    scenario's file name)."""

    campaigns: list[PooledCampaign]


@dataclass(frozen=True)
class Pooled:
    """The pooled figures of campaigns, and which campaigns."""

    record: EvaluationRecord
    campaigns: list[Campaign]

    def to_json(self) -> PooledJson:
        first = self.campaigns[0].data
        return {
            **self.record.to_json(),
            "campaigns": [
                {"file": c.name, "seed": c.data["seed"], "episodes": len(c.missions), "complete": c.stopped is None}
                for c in self.campaigns
            ],
            # SAME's keys, which every campaign has (check_campaign) and shares (_check_together).
            "pilot": first["pilot"],
            "cost_limit": first["cost_limit"],
            "clock": first["clock"],
            "scenario": Path(first["scenario"]).name,
        }


def pool(campaigns: Sequence[Campaign], partial: bool = False) -> Pooled:
    """The pooled figures of checked ``campaigns`` (in order)."""
    _check_together(campaigns, partial)
    missions = [m for c in campaigns for m in c.missions]
    success = np.array([m.success for m in missions])
    cost = np.array([m.cost for m in missions], dtype=np.float64)
    limit = float(campaigns[0].data["cost_limit"])
    times = [m.sim_time_s for m in missions if m.sim_time_s is not None]
    record = pooled_record(
        success,
        cost,
        limit,
        [r.value for r in ROLES],
        [m.seed for m in missions],
        time_s=times if len(times) == len(missions) else None,
    )
    return Pooled(record, list(campaigns))


def _fail(message: str) -> NoReturn:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=command_description(__doc__))
    parser.add_argument("campaigns", nargs="+", type=Path, help="fly --json results of one team on one scenario")
    parser.add_argument("--json", type=Path, help="write the pooled figures here")
    parser.add_argument(
        "--partial",
        action="store_true",
        help="pool the finished missions of a campaign that did not fly them all (interrupted or stopped by an "
        "error), if none is missing before its last finished one",
    )
    args = parser.parse_args(argv)
    try:
        campaigns = [read_campaign(p) for p in args.campaigns]
        pooled = pool(campaigns, args.partial)
    except PoolError as exc:
        _fail(str(exc))
    for c in campaigns:
        if c.stopped is not None:
            print(
                f"{PROG}: note: {c.name}: {c.stopped}: pooling its {len(c.missions)} finished missions", file=sys.stderr
            )
    r = pooled.record
    assert r.success_interval95 is not None and r.mean_cost_interval95 is not None, "every pooled mission has a cost"
    lo, hi = r.success_interval95
    clo, chi = r.mean_cost_interval95
    print(
        f"success rate {r.success_rate:.1%} (95% interval {lo:.1%}-{hi:.1%}) over {r.episodes} "
        f"missions, mean hazard cost per UAV {r.mean_cost:.2f} (95% interval {clo:.2f}-{chi:.2f})"
    )
    for role, tail in r.roles.items():
        print(f"  {role:6s} within C {tail.within_cost_limit:.1%}  worst {tail.max_cost:.0f}")
    if args.json is not None:
        try:
            write_json(args.json, pooled.to_json())
        except OSError as exc:
            _fail(bad_input_line(exc))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
