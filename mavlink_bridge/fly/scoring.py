"""A mission's outcome (from the world's truth log, or from the companions) and the results JSON."""

from __future__ import annotations

from typing import Any

import numpy as np

from mavlink_bridge.fly.config import FlyConfig, monitor_scope
from mavlink_bridge.fly.mission_log import MissionRecord
from tssac_core.common.stats import (
    bootstrap_mean_interval,
    cvar,
    wilson_interval,
    worst_missions,
)
from tssac_core.sim.scenario import ROLES, Dynamics

WORST_MISSIONS = 10
"""How many of the costliest UAV-missions the JSON lists (as tssac_core.evaluate's)."""


def outcome(record: MissionRecord, cost_limit: float) -> dict[str, Any]:
    tasks = record.task_done()
    return {
        "success": record.success,
        "end": record.end,
        "steps": record.steps,
        "sim_time_s": round(record.sim_time_s, 3),
        "cost": record.cost,
        "within_cost_limit": {k: v <= cost_limit for k, v in record.cost.items()},
        "task_done": tasks,
        "failsafe_steps": record.failsafe_steps,
        "left_area": record.event_count("FENCE"),
        "world_flight_cpu_s": record.summary.get("flight_cpu_s") if record.summary is not None else None,
    }


def outcome_from_companions(statuses: dict[str, dict[str, Any]]) -> dict[str, Any]:
    ends = [s.get("status") for s in statuses.values()]
    success = "success" in ends
    end = "success" if success else next((e for e in ends if e in ("geofence", "episode_cap")), "unknown")
    times = [s["vehicle_time_s"] for s in statuses.values() if s.get("vehicle_time_s") is not None]
    return {"success": success, "end": end, "sim_time_s": max(times) if times else None, "cost": None}


def shield_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The monitor's figures over the missions, from the companions' counts: interventions per UAV-mission, the
    fraction of control steps under the backup, the largest margin used; and what the guarantee is about (UAV-missions
    with any cost, UAVs that left the area)."""
    counts = [s["shield"] for r in rows for s in r.get("companions", {}).values() if s.get("shield")]
    steps = sum(c["decisions"] for c in counts)
    control = [s.get("control_steps") or 0 for r in rows for s in r.get("companions", {}).values() if s.get("shield")]
    costed = [r for r in rows if r.get("cost")]
    return {
        "uav_missions": len(counts),
        "interventions_per_uav_mission": float(np.mean([c["interventions"] for c in counts])) if counts else None,
        "max_interventions_per_uav_mission": max((c["interventions"] for c in counts), default=None),
        "backup_time_fraction": sum(c["backup_steps"] for c in counts) / max(1, sum(control)) if counts else None,
        "unprotected_time_fraction": sum(c["unprotected_steps"] for c in counts) / max(1, sum(control))
        if counts
        else None,
        "decisions": steps,
        "resets": sum(c["resets"] for c in counts),
        "max_margin_m": max((c["max_margin_m"] for c in counts), default=None),
        "uav_missions_with_cost": int(sum(v > 0 for r in costed for v in r["cost"].values())) if costed else None,
        "uavs_left_area": int(sum(sum(r.get("left_area", {}).values()) for r in costed)) if costed else None,
    }


def role_figures(
    rows: list[dict[str, Any]], costed: list[dict[str, Any]], name: str, cost_limit: float
) -> dict[str, Any]:
    """One role's figures: its cost tail and task success over the missions whose cost is known (``costed``), its
    companions' control latency over all."""
    fig: dict[str, Any] = {}
    if costed:
        costs = np.array([r["cost"][name] for r in costed])
        fig.update(
            {
                "mean_cost": float(costs.mean()),
                "max_cost": float(costs.max()),
                "within_cost_limit": float((costs <= cost_limit).mean()),
                "cvar95_cost": cvar(costs),
            }
        )
        fig["task_success_rate"] = float(np.mean([bool(r.get("task_done", {}).get(name)) for r in costed]))
    p50 = [
        r["companions"][name]["latency_p50_ms"]
        for r in rows
        if r.get("companions", {}).get(name, {}).get("latency_p50_ms") is not None
    ]
    p99 = [
        r["companions"][name]["latency_p99_ms"]
        for r in rows
        if r.get("companions", {}).get(name, {}).get("latency_p99_ms") is not None
    ]
    if p50:
        fig["latency_p50_ms"] = float(np.median(p50))
        fig["latency_p99_ms"] = float(np.max(p99))
    return fig


def summarise(rows: list[dict[str, Any]], cfg: FlyConfig) -> dict[str, Any]:
    """The results JSON: success_rate and mean_cost with their 95% intervals, episodes, per-role figures with the
    tail (within C, worst, CVaR_0.95), the costliest UAV-missions and the missions: the keys of
    ``tssac_core.evaluate``'s JSON (tssac_core.common.stats), with the cost figures None when the cost is unknown."""
    n = len(rows)
    wins = int(sum(bool(r.get("success")) for r in rows))
    out: dict[str, Any] = {
        "success_rate": wins / n if n else None,
        "success_interval95": [wilson_interval(wins, n).low, wilson_interval(wins, n).high] if n else None,
        "mean_cost": None,
        "mean_cost_interval95": None,
        "episodes": n,
        "episodes_requested": cfg.episodes,
        "mean_mission_time_s": None,
        "roles": {},
    }
    times = [r["sim_time_s"] for r in rows if r.get("sim_time_s") is not None]
    if times:
        out["mean_mission_time_s"] = float(np.mean(times))
    costed = [r for r in rows if r.get("cost")]
    out["worst_missions"] = []
    if costed:
        cost = np.array([[r["cost"][role.value] for role in ROLES] for r in costed], dtype=np.float64)
        interval = bootstrap_mean_interval(cost)
        out["mean_cost"] = float(cost.mean())
        out["mean_cost_interval95"] = [interval.low, interval.high]
        worst = worst_missions(cost, [r["seed"] for r in costed], [role.value for role in ROLES], WORST_MISSIONS)
        for w in worst:
            w["mission"] = costed[w["mission"]]["index"]
        out["worst_missions"] = worst
    for role in ROLES:
        out["roles"][role.value] = role_figures(rows, costed, role.value, cfg.scenario.cost_limit)
    if cfg.shield:
        out["shield"] = shield_summary(rows)
        scope = monitor_scope(cfg.scenario)
        out["shield"]["guarantee"] = scope is None
        out["shield"]["scope"] = scope
    dynamics = cfg.scenario.dynamics or Dynamics()
    wind = cfg.scenario.wind
    out.update(
        {
            "pilot": str(cfg.models) if cfg.models is not None else cfg.pilot,
            "setpoints": cfg.setpoints.value,
            "scenario": str(cfg.scenario_path),
            # The vehicles of --connect fly whatever physics they fly: unknown here.
            "dynamics": None
            if cfg.connect is not None
            else {"model": dynamics.model.value, "aircraft": dynamics.aircraft},
            "wind": None
            if wind is None
            else {"speed_m_s": wind.speed_m_s, "from_deg": wind.from_deg, "turbulence": wind.turbulence.value},
            "seed": cfg.seed,
            "clock": ("connected, lockstep" if cfg.lockstep else "connected")
            if cfg.connect is not None
            else ("lockstep" if cfg.lockstep else f"speedup {cfg.speedup:g}"),
            "cost_limit": cfg.scenario.cost_limit,
            "signing": cfg.signing_key_path is not None,
            "missions": rows,
        }
    )
    return out
