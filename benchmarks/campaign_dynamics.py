"""The dynamics campaign: the same fresh layouts flown by ``fly`` over the kinematic backend, JSBSim F-16s in still air
and JSBSim F-16s in a 10 m/s wind, each without and with ``--shield``, by the shipped team and by the guidance
controller. It measures the gap between the world the team trained in and a real airframe (issue "Real flight
dynamics"), as measured, whatever the figures are. Two more campaigns fly the shipped team over the kinematic backend in
ArduPlane's GUIDED dialect (``--setpoints arduplane``, names ending ``-arduplane``) on the same layouts, to set beside
the body-rate campaigns.

Each campaign is one ``fly --resume`` command writing its JSON into ``--out``; a campaign whose JSON is already there,
whole, is not flown again, and one that ``fly`` stopped part-way (``interrupted``, or fewer missions than asked for)
flies on from its JSON, only the missions it lacks (:mod:`mavlink_bridge.fly.resume`): run the same command again. A
part written by a ``fly`` too old to name its settings (no ``resume_key``) is set aside as ``NAME.partial.json`` and
that campaign is flown from its first mission, on the same layouts. At the end the script
prints the table (success and mean cost with their 95% intervals) and writes it as ``summary.json`` beside the
campaigns.

    python benchmarks/campaign_dynamics.py --out results/dynamics --episodes 200 --seed 5700001 --workers 2
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.common.cli import command_description

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Campaign:
    pilot: str
    """"team" (the shipped models) or "guidance"."""
    dynamics: str
    """"kinematic", "jsbsim" or "jsbsim-wind"."""
    shield: bool
    setpoints: str = "body-rates"
    """The companion's command dialect: "body-rates" or "arduplane"."""

    @property
    def name(self) -> str:
        name = f"{self.pilot}-{self.dynamics}-{'shield' if self.shield else 'alone'}"
        return name if self.setpoints == "body-rates" else f"{name}-{self.setpoints}"

    def argv(self, args: argparse.Namespace, out: Path) -> list[str]:
        scenario = ROOT / "scenarios" / ("random-wind.yaml" if self.dynamics == "jsbsim-wind" else "random.yaml")
        argv = [sys.executable, "-m", "mavlink_bridge.fly", "--scenario", str(scenario)]
        argv += ["--models", str(args.models)] if self.pilot == "team" else ["--pilot", "guidance"]
        argv += ["--dynamics", "kinematic" if self.dynamics == "kinematic" else "jsbsim"]
        argv += ["--episodes", str(args.episodes), "--seed", str(args.seed), "--workers", str(args.workers)]
        argv += ["--setpoints", self.setpoints, "--no-progress", "--json", str(out), "--resume"]
        return argv + (["--shield"] if self.shield else [])


CAMPAIGNS = [
    Campaign(pilot, dynamics, shield)
    for pilot in ("team", "guidance")
    for dynamics in ("kinematic", "jsbsim", "jsbsim-wind")
    for shield in (False, True)
] + [Campaign("team", "kinematic", shield, "arduplane") for shield in (False, True)]


def row(campaign: Campaign, result: dict[str, Any]) -> dict[str, Any]:
    """A campaign's line of the table."""
    shield = result.get("shield") or {}
    return {
        "campaign": campaign.name,
        "pilot": campaign.pilot,
        "dynamics": campaign.dynamics,
        "shield": campaign.shield,
        "setpoints": campaign.setpoints,
        "episodes": result["episodes"],
        "success_rate": result["success_rate"],
        "success_interval95": result["success_interval95"],
        "mean_cost": result["mean_cost"],
        "mean_cost_interval95": result["mean_cost_interval95"],
        "uav_missions_with_cost": shield.get("uav_missions_with_cost"),
        "uavs_left_area": shield.get("uavs_left_area"),
        "guarantee": shield.get("guarantee"),
        "wall_time_s": result.get("wall_time_s"),
        "error": result.get("error"),
    }


def complete(out: Path, episodes: int) -> bool:
    """Whether ``out`` holds a whole campaign of ``episodes`` missions; a part of one without a resume key is moved
    aside (module docstring)."""
    if not out.is_file():
        return False
    result = json.loads(out.read_text())
    if not result.get("interrupted") and result.get("episodes") == episodes and not result.get("error"):
        return True
    if "resume_key" not in result:
        out.replace(out.with_suffix(".partial.json"))
    return False


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=command_description(__doc__))
    p.add_argument("--out", type=Path, required=True, help="directory for the campaigns' JSON (resumes from it)")
    p.add_argument("--episodes", type=int, default=200)
    p.add_argument("--seed", type=int, default=5700001)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--models", type=Path, default=ROOT / "models" / "tssac")
    p.add_argument("--only", action="append", default=[], help="fly only campaigns whose name contains this")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for campaign in CAMPAIGNS:
        if args.only and not any(text in campaign.name for text in args.only):
            continue
        out = args.out / f"{campaign.name}.json"
        if not complete(out, args.episodes):
            t0 = time.monotonic()
            proc = subprocess.run(campaign.argv(args, out), cwd=ROOT, capture_output=True, text=True)
            print(f"{campaign.name}: exit {proc.returncode} in {time.monotonic() - t0:.0f} s", flush=True)
            if proc.returncode != 0 or not out.is_file():
                print(proc.stderr[-2000:], file=sys.stderr)
                return 1
        rows.append(row(campaign, json.loads(out.read_text())))
    summary = {
        "command": " ".join(["python", "benchmarks/campaign_dynamics.py", *(argv or sys.argv[1:])]),
        "episodes": args.episodes,
        "seed": args.seed,
        "campaigns": rows,
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print("| pilot | dynamics | setpoints | monitor | success (95%) | mean cost (95%) | UAV-missions with cost |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        lo, hi = r["success_interval95"]
        clo, chi = r["mean_cost_interval95"]
        costed = "" if r["uav_missions_with_cost"] is None else str(r["uav_missions_with_cost"])
        print(
            f"| {r['pilot']} | {r['dynamics']} | {r['setpoints']} | {'on' if r['shield'] else 'off'} | "
            f"{r['success_rate']:.1%} ({lo:.1%}-{hi:.1%}) | {r['mean_cost']:.2f} ({clo:.2f}-{chi:.2f}) | {costed} |"
        )
    print(f"wrote {args.out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
