"""What the runtime-assurance monitor costs a team on real-dynamics airframes, in the batched world: the fast measure
beside the SITL campaigns on JSBSim (issue 58, "with the monitor: success within 2 points of the unshielded team").

For each team (``--models``, repeatable) and each wind (``--wind-m-s``, repeatable; 0 is still air), ``--episodes``
fresh random.yaml missions on airframes drawn from the fitted response's spans (turn delay, roll-in and roll-out,
achievable acceleration and braking; ``--airframe-response``), in a steady wind of that speed from a direction drawn
per mission, flown twice on the same layouts and airframes: alone, and through the adjusted monitor predicting with
each airframe's lag (in wind its backups end in the ground loiter, bounded on the lag model at the spans' corners).
The monitor decides from the world's true state (no estimate error, no link): the SITL's companions add those, so
this is the monitor's own cost, an upper bound on what it can leave to a team. ``--decision-error POS HEADING SPEED``
makes it keep a companion's error bound off every decision's clearance (metres, degrees, m/s; the figures a companion
reports, e.g. 1.6 2.0 1.31 for a JSBSim F-16's steady flight): what the clearance the filter asks for costs the team,
apart from the filter's own noise and the link. Prints one row per (team, wind,
monitor): success and mean cost per UAV with their 95% intervals, interventions per UAV-mission, the flight time
under the backup; writes them as JSON.

    python benchmarks/bench_monitored_team.py --models models/tssac --models results/monitored/seed0 \
        --episodes 200 --seed 7700001 --wind-m-s 0 --wind-m-s 10 [--json OUT]

Every figure with the seed it was flown on: choose on one seed, report on another.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.output import add_json_option  # noqa: E402
from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError, UsageParser, command_description, run, write_json
from tssac_core.deploy.policy import load_team
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import DEFAULT_SCENARIO, Scenario, load
from tssac_core.sim.shield_tuning import add_tuning_options, tuning_option
from tssac_core.sim.varied_airframes import AirframeVariation
from tssac_core.sim.world_monitor import DecisionError

ROOT = Path(__file__).resolve().parents[1]
F16_RESPONSE = ROOT / "sim_vehicles" / "dynamics" / "airframes" / "f16.response.yaml"


def airframes_in(
    response_path: Path, wind_m_s: float, scenario: Scenario
) -> tuple[AirframeVariation, LoiterBound | None]:
    """The response's spans in a steady wind of ``wind_m_s`` (direction drawn per mission), and in wind the loiter's
    bound for them (None in still air: the backups end in a constant turn)."""
    response = load_response(response_path)
    variation = dataclasses.replace(AirframeVariation.from_response(response), wind_m_s=(wind_m_s, wind_m_s))
    if wind_m_s == 0:
        return variation, None
    return variation, variation.envelope_loiter_bound(response.loiter_law(), scenario)


def fly_row(
    models: Path,
    airframes: tuple[AirframeVariation, LoiterBound | None],
    shield: ShieldConfig | None,
    args: Any,
    scenario: Scenario,
) -> dict[str, Any]:
    """One row: the team of ``models`` on ``airframes`` (:func:`airframes_in`), through the monitor ``shield`` or
    alone (None)."""
    variation, loiter = airframes
    wind_m_s = variation.wind_m_s[1]
    t0 = time.monotonic()
    pilots = load_team(models)
    error = args.decision_error if shield is not None else None
    results = fly_missions(
        scenario,
        pilots,
        args.episodes,
        args.seed,
        shield=shield,
        airframes=variation,
        loiter=loiter,
        decision_error=error,
    )
    record = results.record(scenario.cost_limit)
    row: dict[str, Any] = {
        "models": str(models),
        "wind_m_s": wind_m_s,
        "monitor": shield is not None,
        "missions": record.episodes,
        "decision_error": None if error is None else dataclasses.asdict(error),
        "success_rate": record.success_rate,
        "success_interval95": record.success_interval95,
        "mean_cost": record.mean_cost,
        "mean_cost_interval95": record.mean_cost_interval95,
        "uav_missions_with_cost": int((results.cost > 0).sum()),
        "uavs_out": int(results.out_of_area.sum()),
    }
    if record.monitor is not None:
        row["interventions_per_uav_mission"] = record.monitor.interventions_per_uav_mission
        row["backup_time_fraction"] = record.monitor.backup_time_fraction
        row["unprotected_time_fraction"] = record.monitor.unprotected_time_fraction
    row["wall_time_s"] = round(time.monotonic() - t0, 1)
    return row


def describe(row: dict[str, Any]) -> str:
    lo, hi = row["success_interval95"]
    clo, chi = row["mean_cost_interval95"]
    text = (
        f"{row['models']:<28} wind {row['wind_m_s']:>4g} m/s  monitor {'on ' if row['monitor'] else 'off'}  "
        f"success {row['success_rate']:.1%} ({lo:.1%}-{hi:.1%})  cost {row['mean_cost']:.2f} ({clo:.2f}-{chi:.2f})  "
        f"costed {row['uav_missions_with_cost']}  out {row['uavs_out']}"
    )
    if row["monitor"]:
        text += (
            f"  interventions {row['interventions_per_uav_mission']:.2f}/UAV-mission"
            f"  backup {row['backup_time_fraction']:.1%}"
        )
    return text + f"  [{row['wall_time_s']:.0f} s]"


def main(argv: Sequence[str] | None = None) -> int:
    p = UsageParser(description=command_description(__doc__))
    p.add_argument("--models", type=Path, action="append", required=True, help="a team's directory (repeatable)")
    p.add_argument("--episodes", type=int, default=200)
    p.add_argument("--seed", type=int, required=True, help="the layouts' and airframes' seed")
    p.add_argument("--wind-m-s", type=float, action="append", help="a steady wind (m/s; repeatable; default 0 and 10)")
    p.add_argument("--airframe-response", type=Path, default=F16_RESPONSE)
    p.add_argument("--scenario", type=Path, default=DEFAULT_SCENARIO)
    p.add_argument("--margin-m", type=float, default=ShieldConfig.margin_m, help="the monitor's clearance (m)")
    p.add_argument(
        "--decision-error",
        type=float,
        nargs=3,
        metavar=("POS_M", "HEADING_DEG", "SPEED_M_S"),
        help="the monitor keeps this estimate error bound off every decision's clearance, as a companion would "
        "(default: none, the true state)",
    )
    add_tuning_options(p)
    add_json_option(p, "monitored_team")
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    winds = args.wind_m_s if args.wind_m_s is not None else [0.0, 10.0]
    if any(not (0.0 <= w < 75.0) for w in winds):
        raise UsageError(f"--wind-m-s must be in [0, 75), got {winds}")
    if args.decision_error is not None:
        pos, heading_deg, speed = args.decision_error
        try:
            args.decision_error = DecisionError(pos, math.radians(heading_deg), speed)
        except ValueError as e:
            raise UsageError(f"--decision-error: {e}") from None
    torch.set_num_threads(1)  # the team's forward passes are small: one core each, the other for whatever runs beside
    scenario = load(args.scenario)
    shield = tuning_option(args, True).config(adjust=True, margin_m=args.margin_m)
    rows: list[dict[str, Any]] = []
    out: dict[str, Any] = {"episodes": args.episodes, "seed": args.seed, "scenario": str(args.scenario), "rows": rows}
    airframes = {wind: airframes_in(args.airframe_response, wind, scenario) for wind in winds}  # a loiter fit each
    for models in args.models:
        for wind in winds:
            for monitor in (None, shield):
                rows.append(fly_row(models, airframes[wind], monitor, args, scenario))
                print(describe(rows[-1]), flush=True)
                args.json.parent.mkdir(parents=True, exist_ok=True)
                write_json(args.json, out)  # again after every row: a run stopped part-way keeps what it flew
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run(main))
