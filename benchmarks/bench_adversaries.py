"""Every adversarial pilot (tssac_core/sim/adversaries.py) against the runtime-assurance monitor, at scale.

For each adversary: ``--episodes`` batched missions per batched scenario with the monitor off and on
(``tssac_core.sim.missions.fly_missions``, over ``--workers`` Ray workers), and ``--sitl-missions`` SITL missions
per SITL scenario with the monitor on in every companion (``python -m mavlink_bridge.fly --pilot NAME --shield
--workers N``, lockstep). Prints one row per (adversary, where, monitor): missions, the hazard cost summed over
UAV-missions, UAVs out of the area, the most steps one UAV spent inside a radar, the monitor's interventions and
the success rate; writes them as JSON.

    python benchmarks/bench_adversaries.py                     # the full size: 2,000 batched, 50 SITL each
    python benchmarks/bench_adversaries.py --batched --sitl random --sitl-dynamics jsbsim \
        --airframe-response sim_vehicles/dynamics/airframes/f16.response.yaml --json OUT --resume
                                                               # the SITL rows on JSBSim F-16s, the monitor
                                                               # predicting with the airframe's response
    python benchmarks/bench_adversaries.py --sitl --airframe-response FILE [--eq5-monitor] --workers 1 --json OUT
                                                               # the batched rows on airframes drawn from the
                                                               # response's spans; --eq5-monitor: the monitor
                                                               # predicts with eq. 5 (the negative control)
    python benchmarks/bench_adversaries.py --sitl --airframe-response FILE --wind-m-s 10 [--no-loiter] --workers 1 \
        --json OUT                                             # the same in a steady 10 m/s wind (its direction
                                                               # drawn per mission), the backups ending in the
                                                               # ground loiter; --no-loiter: in calm air's
                                                               # constant turn (the negative control)
    python benchmarks/bench_adversaries.py --episodes 200 --sitl-missions 2 --json benchmarks/results/adversaries.json

Any of these with ``--shield-adjust``: the monitors fly the passing action nearest a failing proposal before the
backup (``fly --shield-adjust``); the rows' places end in "adjusted".

Seeds: the adversaries' own range, used for nothing else. Mission k of a batched scenario flies seed
``--seed + offset + k`` (random.yaml offset 10,000, corner.yaml 20,000; SITL random.yaml 30,000, degraded.yaml
40,000), so each adversary flies the same layouts as the others, and any row's mission can be flown again alone
(``evaluate --controller NAME --seed S --mission K``, ``fly --pilot NAME --seed S --mission K``). The tests use
``--seed`` + 0..59.

A run below the default size is marked ``"smoke": true`` in the JSON. With ``--json`` the file is written again
after every row (``"complete": false`` until the last), and ``--resume`` keeps the rows of such a file that the same
settings wrote and flies only the rest, so a run stopped part-way (a session's end, Ctrl-C) loses at most one row.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

import tssac_core
from tssac_core.assurance.ground_loiter import LoiterBound
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError, UsageParser, command_description, run, write_json
from tssac_core.common.shield_options import SHIELD_ADJUST_HELP
from tssac_core.parallel.mission_shards import fly_missions_sharded
from tssac_core.parallel.ray_cluster import RayTarget, ray_session
from tssac_core.sim.adversaries import ADVERSARY_NAMES, Adversary, AdversaryPilot
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.scenario import Scenario, dump, load
from tssac_core.sim.shield_tuning import ShieldTuning, add_tuning_options, tuning_argv, tuning_option
from tssac_core.sim.varied_airframes import AirframeVariation

ROOT = Path(tssac_core.__file__).resolve().parents[1]
DEFAULT_EPISODES = 2000
DEFAULT_SITL_MISSIONS = 50
SEED = 2_100_001
BATCHED = ("random", "corner")
SITL = ("random", "degraded")
SEED_OFFSETS = {("batched", "random"): 10_000, ("batched", "corner"): 20_000}
SEED_OFFSETS |= {("sitl", "random"): 30_000, ("sitl", "degraded"): 40_000}
SMOKE_NOTE = (
    "a smoke run, below the default size (2,000 batched and 50 SITL missions per adversary and scenario): "
    "it shows that the benchmark works, not the issue's targets"
)


@dataclass(frozen=True)
class BenchConfig:
    adversaries: tuple[Adversary, ...]
    episodes: int
    """Batched missions per adversary and batched scenario."""
    sitl_missions: int
    """SITL missions per adversary and SITL scenario (0: none)."""
    workers: int
    seed: int
    episode_steps: int | None
    """Cap every mission at this many steps (None: the scenario's own, 4,000)."""
    batched: tuple[str, ...]
    sitl: tuple[str, ...]
    json_path: Path | None
    progress: bool
    resume: bool
    sitl_dynamics: str = "kinematic"
    """The SITL vehicles' physics (``fly --dynamics``)."""
    airframe_response: Path | None = None
    """The SITL monitors predict with this airframe response (``fly --airframe-response``), and the batched rows fly
    airframes drawn from its spans, their monitors predicting with each one's lag; None: eq. 5-6."""
    eq5_monitor: bool = False
    """With ``airframe_response``: the monitors predict with eq. 5 all the same (the negative control)."""
    wind_m_s: float = 0.0
    """With ``airframe_response``: the batched worlds fly in a steady wind of this speed, from a direction drawn per
    mission, and the monitors' backups end in the ground loiter sized for it."""
    no_loiter: bool = False
    """With ``wind_m_s``: the backups end in calm air's constant turn all the same (the negative control)."""
    shield_adjust: bool = False
    """The monitors fly the passing action nearest a failing proposal before the backup (``fly --shield-adjust``)."""
    shield_tuning: ShieldTuning = ShieldTuning()
    """The monitors' hand-back and what they ask the pilots to be shown (``fly --shield-release-m`` and the rest)."""

    @property
    def shield(self) -> ShieldConfig:
        """The monitor every row flies."""
        return self.shield_tuning.config(self.shield_adjust)

    def shield_settings(self) -> dict[str, Any]:
        """The monitor's settings as a row records them; what the pilots are shown only when set, so that files
        written before those settings existed still resume."""
        shield = dataclasses.asdict(self.shield)
        for name in ("route_edge_margin_m", "radar_view_margin_m"):
            if not shield[name]:
                del shield[name]
        return shield

    def settings(self) -> dict[str, Any]:
        """What a row depends on: rows written under other settings are never reused by ``--resume``."""
        settings: dict[str, Any] = {
            "episodes": self.episodes,
            "sitl_missions": self.sitl_missions,
            "seed": self.seed,
            "episode_steps": self.episode_steps,
            "shield": self.shield_settings(),
        }
        if self.sitl_dynamics != "kinematic":  # only when set: files written before these options still resume
            settings["sitl_dynamics"] = self.sitl_dynamics
        if self.airframe_response is not None:
            settings["airframe_response"] = self.airframe_response.name
        if self.eq5_monitor:
            settings["eq5_monitor"] = True
        if self.wind_m_s:
            settings["wind_m_s"] = self.wind_m_s
        if self.no_loiter:
            settings["no_loiter"] = True
        return json.loads(json.dumps(settings))  # as the file holds them (tuples as lists)

    @property
    def smoke(self) -> bool:
        return self.episodes < DEFAULT_EPISODES or (0 < self.sitl_missions < DEFAULT_SITL_MISSIONS)


def parse_args(argv: Sequence[str] | None) -> BenchConfig:
    p = UsageParser(prog="python benchmarks/bench_adversaries.py", description=command_description(__doc__))
    p.add_argument("--adversaries", default=",".join(ADVERSARY_NAMES), help="comma-separated (default: all)")
    p.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, help="batched missions per adversary/scenario")
    p.add_argument("--sitl-missions", type=int, default=DEFAULT_SITL_MISSIONS, help="SITL missions per ... (0: none)")
    p.add_argument("--workers", type=int, default=2, help="Ray workers (batched) and crews (SITL)")
    p.add_argument("--seed", type=int, default=SEED, help=f"start of the seed range (default {SEED:,})")
    p.add_argument("--episode-steps", type=int, help="cap every mission at N steps (default: the scenario's)")
    p.add_argument(
        "--batched",
        nargs="*",
        default=list(BATCHED),
        help="batched scenarios (default random corner; the flag alone: no batched rows)",
    )
    p.add_argument(
        "--sitl",
        nargs="*",
        default=list(SITL),
        help="SITL scenarios (default random degraded; the flag alone: no SITL rows)",
    )
    p.add_argument(
        "--sitl-dynamics", choices=["kinematic", "jsbsim"], default="kinematic", help="the SITL vehicles' physics"
    )
    p.add_argument(
        "--airframe-response",
        type=Path,
        metavar="FILE",
        help="the SITL monitors predict with this airframe's fitted response (with --sitl-dynamics jsbsim); the "
        "batched rows fly airframes drawn from its spans (on one worker)",
    )
    p.add_argument(
        "--eq5-monitor",
        action="store_true",
        help="with --airframe-response: the monitors predict with eq. 5 all the same (the negative control)",
    )
    p.add_argument(
        "--wind-m-s",
        type=float,
        default=0.0,
        help="with --airframe-response: the batched rows fly in a steady wind of this speed (m/s, its direction drawn "
        "per mission), the monitors' backups ending in the ground loiter",
    )
    p.add_argument(
        "--no-loiter",
        action="store_true",
        help="with --wind-m-s: the backups end in calm air's constant turn all the same (the negative control)",
    )
    p.add_argument("--shield-adjust", action="store_true", help=SHIELD_ADJUST_HELP)
    add_tuning_options(p)
    p.add_argument("--json", type=Path, help="write the rows here")
    p.add_argument("--resume", action="store_true", help="keep the rows --json holds from the same settings")
    p.add_argument("--no-progress", action="store_true")
    a = p.parse_args(argv)
    if a.resume and a.json is None:
        raise UsageError("--resume needs --json (the file whose rows it keeps)")
    names = [n.strip() for n in a.adversaries.split(",") if n.strip()]
    unknown = [n for n in names if n not in ADVERSARY_NAMES]
    if unknown or not names:
        raise UsageError(f"--adversaries: unknown {unknown or 'none given'} (known: {', '.join(ADVERSARY_NAMES)})")
    if a.episodes <= 0 or a.sitl_missions < 0 or a.workers <= 0:
        raise UsageError("--episodes and --workers must be positive, --sitl-missions >= 0")
    if a.episode_steps is not None and a.episode_steps <= 0:
        raise UsageError(f"--episode-steps must be positive, got {a.episode_steps}")
    sitl_rows = a.sitl_missions > 0 and bool(a.sitl)
    if a.airframe_response is not None and (
        not a.airframe_response.is_file() or (sitl_rows and a.sitl_dynamics != "jsbsim")
    ):
        raise UsageError("--airframe-response: an existing response file (SITL rows: with --sitl-dynamics jsbsim)")
    if a.eq5_monitor and a.airframe_response is None:
        raise UsageError("--eq5-monitor is the control of --airframe-response: give both")
    if not 0.0 <= a.wind_m_s < 100.0 or (a.wind_m_s and (a.airframe_response is None or sitl_rows)):
        raise UsageError("--wind-m-s: a speed in [0, 100) m/s, with --airframe-response, for batched rows (--sitl)")
    if a.no_loiter and not a.wind_m_s:
        raise UsageError("--no-loiter is the control of --wind-m-s: give both")
    for name in (*a.batched, *a.sitl):
        if not (ROOT / "scenarios" / f"{name}.yaml").is_file():
            raise UsageError(f"scenario '{name}': no scenarios/{name}.yaml")
    return BenchConfig(
        adversaries=tuple(Adversary(n) for n in names),
        episodes=a.episodes,
        sitl_missions=a.sitl_missions,
        workers=a.workers,
        seed=a.seed,
        episode_steps=a.episode_steps,
        batched=tuple(a.batched),
        sitl=tuple(a.sitl),
        json_path=a.json,
        progress=not a.no_progress,
        resume=a.resume,
        sitl_dynamics=a.sitl_dynamics,
        airframe_response=None if a.airframe_response is None else a.airframe_response.resolve(),
        eq5_monitor=a.eq5_monitor,
        wind_m_s=a.wind_m_s,
        no_loiter=a.no_loiter,
        shield_adjust=a.shield_adjust,
        shield_tuning=tuning_option(a, True),
    )


def scenario_of(name: str, cfg: BenchConfig) -> Scenario:
    scenario = load(ROOT / "scenarios" / f"{name}.yaml")
    return scenario if cfg.episode_steps is None else dataclasses.replace(scenario, episode_steps=cfg.episode_steps)


def seed_of(kind: str, name: str, cfg: BenchConfig) -> int:
    return cfg.seed + SEED_OFFSETS.get((kind, name), 50_000)


def batched_row(adversary: Adversary, name: str, shield: bool, cfg: BenchConfig, bar: tqdm) -> dict[str, Any]:
    scenario, seed = scenario_of(name, cfg), seed_of("batched", name, cfg)
    pilots = [AdversaryPilot(adversary)] * 3
    monitor = cfg.shield if shield else None
    t0 = time.monotonic()
    results: MissionResults
    if cfg.airframe_response is not None:  # on airframes drawn from the response's spans: one process
        variation, loiter = varied_airframes(cfg, scenario)
        results = fly_missions(
            scenario, pilots, cfg.episodes, seed, progress=bar.update, shield=monitor, airframes=variation,
            monitor_sees_airframes=not cfg.eq5_monitor, loiter=loiter,
        )  # fmt: skip
    elif cfg.workers > 1:
        indices = list(range(cfg.episodes))
        target = RayTarget(None)
        results = fly_missions_sharded(
            scenario, pilots, indices, seed, cfg.workers, target, lambda report: bar.update(report.finished), monitor
        )
    else:
        results = fly_missions(scenario, pilots, cfg.episodes, seed, progress=bar.update, shield=monitor)
    counts = results.monitor
    return {
        "adversary": adversary.value,
        "where": batched_where(name, cfg),
        "monitor": shield,
        "seed": seed,
        "missions": len(results.success),
        "cost_total": float(results.cost.sum()),
        "uav_missions_with_cost": int((results.cost > 0).sum()),
        "uavs_out_of_area": int(results.out_of_area.sum()),
        "max_steps_inside": float(results.cost.max()),
        "interventions": None if counts is None else int(counts.interventions.sum()),
        "interventions_per_uav_mission": None if counts is None else float(counts.interventions.mean()),
        "backup_time_fraction": None
        if counts is None
        else float(counts.backup_steps.sum() / max(1, counts.flown_steps.sum())),
        "held_time_fraction": None
        if counts is None
        else float(counts.held_steps.sum() / max(1, counts.flown_steps.sum())),
        "unprotected_steps": None if counts is None else int(counts.unprotected_steps.sum()),
        "success_rate": float(results.success.mean()),
        "unsafe_missions": [int(k) for k in ((results.cost > 0) | results.out_of_area).any(axis=1).nonzero()[0]][:20],
        "wall_time_s": round(time.monotonic() - t0, 1),
    }


def varied_airframes(cfg: BenchConfig, scenario: Scenario) -> tuple[AirframeVariation, LoiterBound | None]:
    """The batched rows' airframes (the response's spans, in ``--wind-m-s`` from a direction drawn per mission) and
    the loiter's bound for them (None in calm air or under ``--no-loiter``)."""
    assert cfg.airframe_response is not None
    response = load_response(cfg.airframe_response)
    variation = AirframeVariation.from_response(response, wind_max_m_s=cfg.wind_m_s)
    if not cfg.wind_m_s:
        return variation, None
    variation = dataclasses.replace(variation, wind_m_s=(cfg.wind_m_s, cfg.wind_m_s))
    if cfg.no_loiter:
        return variation, None
    return variation, variation.envelope_loiter_bound(response.loiter_law(), scenario)


def sitl_row(adversary: Adversary, name: str, cfg: BenchConfig, work: Path, bar: tqdm) -> dict[str, Any]:
    seed = seed_of("sitl", name, cfg)
    path, out = work / f"{name}.yaml", work / f"{adversary.value}-{name}.json"
    dump(scenario_of(name, cfg), path)
    argv = ["--scenario", str(path), "--pilot", adversary.value, "--shield", "--episodes", str(cfg.sitl_missions)]
    workers = min(cfg.workers, cfg.sitl_missions)  # one mission: flown here, without starting Ray
    argv += ["--seed", str(seed), "--json", str(out), "--workers", str(workers), "--no-progress"]
    argv += ["--dynamics", cfg.sitl_dynamics]
    if cfg.airframe_response is not None and not cfg.eq5_monitor:
        argv += ["--airframe-response", str(cfg.airframe_response)]
    if cfg.shield_adjust:
        argv += ["--shield-adjust"]
    argv += tuning_argv(cfg.shield_tuning)
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    bar.update(cfg.sitl_missions)
    if not out.is_file():
        raise RuntimeError(f"fly {' '.join(argv)} wrote no JSON (exit {proc.returncode}): {proc.stderr[-500:]}")
    summary = json.loads(out.read_text())
    missions = summary["missions"]
    costs = [c for m in missions for c in (m.get("cost") or {}).values()]
    shield = summary.get("shield") or {}
    uav_missions = shield.get("uav_missions") or 0
    per_uav = shield.get("interventions_per_uav_mission")
    return {
        "adversary": adversary.value,
        "where": sitl_where(name, cfg),
        "monitor": True,
        "seed": seed,
        "missions": len(missions),
        "cost_total": float(sum(costs)),
        "uav_missions_with_cost": int(sum(c > 0 for c in costs)),
        "uavs_out_of_area": int(sum(bool(v) for m in missions for v in (m.get("left_area") or {}).values())),
        "max_steps_inside": float(max(costs, default=0.0)),
        "interventions": None if per_uav is None else round(per_uav * uav_missions),
        "interventions_per_uav_mission": per_uav,
        "backup_time_fraction": shield.get("backup_time_fraction"),
        "held_time_fraction": shield.get("held_time_fraction"),
        "unprotected_steps": unprotected_steps(missions),
        "success_rate": summary.get("success_rate"),
        "unsafe_missions": [
            int(m["index"])
            for m in missions
            if any(c > 0 for c in (m.get("cost") or {}).values()) or any((m.get("left_area") or {}).values())
        ][:20],
        "fly_exit_code": proc.returncode,
        "fly_error": summary.get("error"),
        "wall_time_s": round(time.monotonic() - t0, 1),
    }


def unprotected_steps(missions: list[dict[str, Any]]) -> int | None:
    """Control steps flown with no passing action and no clear backup, summed over the missions' companions (their
    status files' ``shield.unprotected_steps``); None if no companion reported its counts."""
    counts = [
        (c.get("shield") or {}).get("unprotected_steps") for m in missions for c in (m.get("companions") or {}).values()
    ]
    known = [int(n) for n in counts if n is not None]
    return sum(known) if known else None


def sitl_where(name: str, cfg: BenchConfig) -> str:
    """A SITL row's place: the scenario, and the physics and the monitor's model when they are not the default."""
    where = f"SITL {name}"
    if cfg.sitl_dynamics != "kinematic":
        where += f" {cfg.sitl_dynamics}"
    if cfg.airframe_response is not None:
        where += " eq5" if cfg.eq5_monitor else " response"
    return where + (" adjusted" if cfg.shield_adjust else "") + tuned_text(cfg.shield_tuning)


def tuned_text(tuning: ShieldTuning) -> str:
    """A row's place ends in "tuned" when the monitor's hand-back or the pilots' view is not the default."""
    return "" if tuning == ShieldTuning() else " tuned"


def batched_where(name: str, cfg: BenchConfig) -> str:
    """A batched row's place: the scenario, and on varied airframes the monitor's model."""
    adjusted = " adjusted" if cfg.shield_adjust else ""
    if cfg.airframe_response is None:
        return f"batched {name}{adjusted}"
    where = f"batched {name} airframes" + (" eq5" if cfg.eq5_monitor else "")
    if cfg.wind_m_s:
        where += f" wind {cfg.wind_m_s:g}" + (" turn" if cfg.no_loiter else " loiter")
    return where + adjusted + tuned_text(cfg.shield_tuning)


def print_table(rows: list[dict[str, Any]]) -> None:
    head = f"{'adversary':11s} {'where':26s} {'monitor':7s} {'missions':>8s} {'cost total':>10s} {'UAVs out':>8s} "
    print(head + f"{'max steps in':>12s} {'interventions':>13s} {'success':>7s}")
    for r in rows:
        interventions = "-" if r["interventions"] is None else f"{r['interventions']:,}"
        print(
            f"{r['adversary']:11s} {r['where']:26s} {'on' if r['monitor'] else 'off':7s} {r['missions']:8,d} "
            f"{r['cost_total']:10,.0f} {r['uavs_out_of_area']:8d} {r['max_steps_inside']:12,.0f} {interventions:>13s} "
            f"{r['success_rate']:7.1%}"
        )


def row_key(row: dict[str, Any]) -> tuple[str, str, bool]:
    return (row["adversary"], row["where"], bool(row["monitor"]))


def kept_rows(cfg: BenchConfig) -> dict[tuple[str, str, bool], dict[str, Any]]:
    """The rows ``--resume`` keeps: those of ``--json`` written under the same settings (none without --resume)."""
    if not cfg.resume or cfg.json_path is None or not cfg.json_path.is_file():
        return {}
    try:
        old = json.loads(cfg.json_path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise UsageError(f"--resume: cannot read {cfg.json_path}: {exc}") from None
    if not isinstance(old, dict) or old.get("settings") != cfg.settings():
        raise UsageError(f"--resume: {cfg.json_path} was written with other settings; give another --json")
    return {row_key(r): r for r in old.get("rows", [])}


def write_rows(cfg: BenchConfig, argv: Sequence[str] | None, rows: list[dict[str, Any]], complete: bool) -> None:
    if cfg.json_path is None:
        return
    write_json(
        cfg.json_path,
        {
            "smoke": cfg.smoke,
            "note": SMOKE_NOTE if cfg.smoke else "",
            "complete": complete,
            "size": f"{cfg.episodes} batched missions per adversary and scenario (off and on), "
            f"{cfg.sitl_missions if cfg.sitl else 0} SITL missions per adversary and scenario (on)",
            "command": "python benchmarks/bench_adversaries.py " + " ".join(sys.argv[1:] if argv is None else argv),
            "settings": cfg.settings(),
            "episode_steps": cfg.episode_steps,
            "shield": cfg.shield_settings(),
            "rows": rows,
            "wall_time_s": round(sum(r["wall_time_s"] for r in rows), 1),
        },
    )


def main(argv: Sequence[str] | None = None) -> int:
    cfg = parse_args(argv)
    kept = kept_rows(cfg)
    rows: list[dict[str, Any]] = []

    def add(key: tuple[str, str, bool], fly: Callable[[], dict[str, Any]]) -> None:
        rows.append(kept[key] if key in kept else fly())
        write_rows(cfg, argv, rows, complete=False)

    batched = [(a, n, s) for a in cfg.adversaries for n in cfg.batched for s in (False, True)]
    todo = [b for b in batched if (b[0].value, batched_where(b[1], cfg), b[2]) not in kept]
    with (
        # one Ray for every row (none on varied airframes: they fly in this process)
        ray_session(RayTarget(None))
        if cfg.workers > 1 and todo and cfg.airframe_response is None
        else contextlib.nullcontext(),
        tqdm(total=len(todo) * cfg.episodes, desc="batched missions", disable=not cfg.progress) as bar,
    ):
        for adversary, name, shield in batched:
            add(
                (adversary.value, batched_where(name, cfg), shield),
                lambda: batched_row(adversary, name, shield, cfg, bar),  # noqa: B023 (called at once)
            )
    if cfg.sitl_missions:
        sitl = [(a, n) for a in cfg.adversaries for n in cfg.sitl]
        todo_sitl = [b for b in sitl if (b[0].value, sitl_where(b[1], cfg), True) not in kept]
        with (
            tempfile.TemporaryDirectory(prefix="bench-adversaries-") as tmp,
            tqdm(total=len(todo_sitl) * cfg.sitl_missions, desc="SITL missions", disable=not cfg.progress) as bar,
        ):
            for adversary, name in sitl:
                add(
                    (adversary.value, sitl_where(name, cfg), True),
                    lambda: sitl_row(adversary, name, cfg, Path(tmp), bar),  # noqa: B023 (called at once)
                )
    print_table(rows)
    write_rows(cfg, argv, rows, complete=True)
    if cfg.json_path is not None:
        print(f"wrote {cfg.json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
