"""What ``fly`` shows: the printed summary and the figure-9 style plot of a mission."""

from __future__ import annotations

import threading
from pathlib import Path

from mavlink_bridge.companion.vehicle_limits import describe
from mavlink_bridge.fly.config import FlyConfig
from mavlink_bridge.fly.mission_log import MissionRecord
from mavlink_bridge.fly.scoring import CampaignResults
from tssac_core.common.evaluation_record import SitlMonitorFigures
from tssac_core.common.shield_options import adjusted_text, held_text
from tssac_core.sim.scenario import Dynamics, DynamicsModel, Layout, Scenario
from tssac_core.wire.vehicle_limits import Achievable


def print_report(results: CampaignResults, cfg: FlyConfig) -> None:
    r = results.record
    if not r.episodes:
        return
    assert r.success_rate is not None and r.success_interval95 is not None, "known for a campaign that flew"
    lo, hi = r.success_interval95
    cost = "unknown"
    if r.mean_cost is not None and r.mean_cost_interval95 is not None:
        clo, chi = r.mean_cost_interval95
        cost = f"{r.mean_cost:.2f} (95% interval {clo:.2f}-{chi:.2f})"
    print(
        f"success rate {r.success_rate:.1%} (95% interval {lo:.1%}-{hi:.1%}) over {r.episodes} missions, mean hazard "
        f"cost per UAV {cost} (limit {cfg.scenario.cost_limit:g}), mean mission time {r.mean_mission_time_s or 0:.1f} s"
    )
    for role, fig in r.roles.items():
        parts = [f"  {role:6s}"]
        if fig.mean_cost is not None:
            parts.append(
                f"task {fig.task_success_rate:.0%}  cost mean {fig.mean_cost:.2f} within C {fig.within_cost_limit:.1%} "
                f"CVaR95 {fig.cvar95_cost:.1f} max {fig.max_cost:.0f}"
            )
        if fig.latency_p50_ms is not None:
            parts.append(f"latency p50 {fig.latency_p50_ms:.2f} ms p99 {fig.latency_p99_ms:.2f} ms")
        print("  ".join(parts))
    if cfg.connect is None:
        print(f"dynamics: {physics_text(cfg.scenario)}")
    sh = r.monitor
    assert sh is None or isinstance(sh, SitlMonitorFigures), "fly's monitor is its companions'"
    if sh is not None:
        print_monitor(sh)
    for w in r.worst_missions:
        print(
            f"  worst: mission {w.mission} (seed {w.seed}) {w.role} cost {w.cost:.0f}: fly again with --seed "
            f"{cfg.seed} --mission {w.mission} --plot FILE"
        )
    for m in results.missions:
        speed = f", {m['speed_x']:.0f}x real time in flight" if m.get("speed_x") else ""
        print(
            f"  mission {m['index']}: {'success' if m.get('success') else m.get('end')}, "
            f"{m.get('sim_time_s') or 0:.1f} s simulated, {m['wall_time_s']:.1f} s wall{speed}"
        )
    for m in results.missions:
        for what, drawn in (("plot", m.get("plot")), ("animation", m.get("animation"))):
            if drawn:
                print(f"wrote {what} of mission {m['index']}: {drawn}")
    if cfg.json_path is not None:
        print(f"wrote {cfg.json_path}")


def mission_file(cfg: FlyConfig, path: Path, index: int, default_suffix: str) -> Path:
    """FILE for one mission, FILE-NNN.ext per mission when there are several."""
    if cfg.episodes > 1:
        path = path.with_name(f"{path.stem}-{index:03d}{path.suffix or default_suffix}")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def physics_text(scenario: Scenario) -> str:
    """Which dynamics flew, in which air: "kinematic, still air", "jsbsim f16, wind 10 m/s from 270 deg"."""
    d, w = scenario.dynamics or Dynamics(), scenario.wind
    physics = d.model.value if d.model is DynamicsModel.KINEMATIC else f"{d.model.value} {d.aircraft}"
    return f"{physics}, " + ("still air" if w is None else f"wind {w.speed_m_s:g} m/s from {w.from_deg:g} deg")


def mission_title(cfg: FlyConfig, index: int, record: MissionRecord) -> str:
    verdict = "success" if record.success else record.end
    cost = ", ".join(f"{k} {v:g}" for k, v in record.cost.items())
    return (
        f"{cfg.scenario.name} #{index} (SITL, {physics_text(cfg.scenario)}): {verdict}, {record.sim_time_s:.0f} s, "
        f"cost {cost}"
    )


PYPLOT_LOCK = threading.Lock()
"""pyplot keeps its figures in global state: crews side by side (threads of one fly process) draw one at a time."""


def plot_mission_record(cfg: FlyConfig, index: int, layout: Layout, record: MissionRecord) -> Path:
    """Draw one mission's trajectories and events (``--plot``: FILE, or FILE-NNN.ext when there are several);
    returns the file written."""
    from tssac_core.reporting.plots import plot_mission  # matplotlib only when a plot is asked for

    assert cfg.plot_path is not None
    path = mission_file(cfg, cfg.plot_path, index, ".png")
    r = cfg.scenario.ranges
    with PYPLOT_LOCK:
        plot_mission(
            path,
            layout,
            record.tracks_km(),
            (r.strike_launch_km, r.detect_km, r.sam_launch_km, r.sam_detect_km),
            record.event_markers_km(),
            title=mission_title(cfg, index, record),
            area_km=cfg.scenario.area_km,
            backup_km=record.backup_segments_km(),
        )
    return path


def animate_mission_record(cfg: FlyConfig, index: int, layout: Layout, record: MissionRecord) -> Path:
    """``--animate``: one mission as a GIF or MP4 (:mod:`tssac_core.reporting.mission_animation`); returns the file
    written."""
    from tssac_core.reporting.mission_animation import MissionFilm, write_film  # matplotlib only when asked for

    assert cfg.animate_path is not None
    r = cfg.scenario.ranges
    film = MissionFilm(
        layout=layout,
        tracks_km=record.tracks_km(),
        ranges_km=(r.strike_launch_km, r.detect_km, r.sam_launch_km, r.sam_detect_km),
        dt_s=cfg.scenario.dt_s,
        area_km=cfg.scenario.area_km,
        events=record.timed_event_markers_km(),
        backup_steps={
            role: [(max(a - 1, 0), b) for a, b in spans] for role, spans in record.backup_step_ranges().items()
        },
        title=mission_title(cfg, index, record),
    )
    with PYPLOT_LOCK:
        return write_film(film, mission_file(cfg, cfg.animate_path, index, cfg.animate_path.suffix), cfg.progress)


def print_monitor(sh: SitlMonitorFigures) -> None:
    """The monitor's lines of the report: its scope, what the vehicles said they achieve, its counts."""
    if sh.scope:
        print(f"shield: {sh.scope}")
    if sh.vehicle_limits:
        print(f"shield: {achieved_text(sh.vehicle_limits)}")
    if sh.uav_missions:
        print(
            f"shield: {sh.interventions_per_uav_mission:.2f} interventions per UAV-mission "
            f"(max {sh.max_interventions_per_uav_mission}), {sh.backup_time_fraction:.2%} of control steps under the "
            f"backup{adjusted_text(sh.adjusted_time_fraction)}{held_text(sh.held_time_fraction)}, "
            f"margin up to {sh.max_margin_m:.0f} m, "
            f"{sh.uav_missions_with_cost} UAV-missions with cost, "
            f"{sh.uavs_left_area} UAVs left the area"
        )


def achieved_text(limits: dict[str, dict[str, object] | None]) -> str:
    """What the vehicles said they achieve (:attr:`SitlMonitorFigures.vehicle_limits`), one line."""
    said = {role: describe(None if v is None else Achievable.from_dict(v)) for role, v in limits.items()}
    if len(set(said.values())) == 1:
        return f"every vehicle {next(iter(said.values()))}"
    return "; ".join(f"the {role} vehicle {text}" for role, text in said.items())
