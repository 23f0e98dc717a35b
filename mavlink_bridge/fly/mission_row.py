"""A mission's row in fly's results JSON (``missions``): what :meth:`MissionRunner.fly` returns, what the crews,
the Ray workers and the progress bar hand on, and what :func:`mavlink_bridge.fly.scoring.summarise` scores.

The companions' part comes from their status files (:mod:`mavlink_bridge.companion`), read as they wrote them: a
key a companion did not write is absent, or None where the runner fills every key in.
"""

from __future__ import annotations

from typing import NotRequired, TypedDict


class ShieldCounts(TypedDict):
    """A companion's runtime-assurance counts (its status file's ``shield``:
    :class:`mavlink_bridge.companion.shield.ShieldCounters`)."""

    decisions: int
    interventions: int
    releases: int
    backup_steps: int
    adjusted_steps: NotRequired[int]
    held_steps: NotRequired[int]
    unprotected_steps: int
    resets: int
    max_margin_m: float
    nonfinite_proposals: int


class CompanionStatus(TypedDict):
    """One companion at the end of a mission: its exit code and, if its status file was read, the rest (``status``
    is "unknown" when it was not)."""

    exit_code: int | None
    status: str | None
    vehicle_time_s: NotRequired[float | None]
    flight_wall_s: NotRequired[float | None]
    flight_cpu_s: NotRequired[float | None]
    control_steps: NotRequired[int | None]
    setpoints_sent: NotRequired[int | None]
    ticks_granted: NotRequired[int | None]
    holds: NotRequired[int | None]
    restarts: NotRequired[int | None]
    latency_p50_ms: NotRequired[float | None]
    latency_p99_ms: NotRequired[float | None]
    shield: NotRequired[ShieldCounts | None]
    vehicle_limits: NotRequired[dict[str, object]]
    """What the vehicle said it achieves, when the monitor flew and it said it (``ACHV_*``)."""
    write_error: NotRequired[str]
    """Set when the companion lost a write (its tlog is cut)."""


class Outcome(TypedDict):
    """How a mission ended: from the world's truth log, or (the vehicles of ``--connect``) from the companions,
    where only the first four keys are known and ``cost`` is None."""

    success: bool
    end: str
    sim_time_s: float | None
    cost: dict[str, float] | None
    """Per role, the mission's hazard cost (eq. 11, steps inside a radar)."""
    steps: NotRequired[int]
    within_cost_limit: NotRequired[dict[str, bool]]
    task_done: NotRequired[dict[str, bool]]
    failsafe_steps: NotRequired[dict[str, int]]
    left_area: NotRequired[dict[str, int]]
    """Per role, the times it left the area (FENCE events)."""
    world_flight_cpu_s: NotRequired[float | None]


class MissionRow(Outcome):
    """One mission's row, in the order its keys are written: the mission, its processes, the companions, the
    :class:`Outcome`, then what was drawn and measured."""

    index: int
    seed: int
    pids: dict[str, int]
    wall_time_s: float
    cpu_s: float | None
    companions: dict[str, CompanionStatus]
    plot: NotRequired[str]
    animation: NotRequired[str]
    flight_wall_s: NotRequired[float]
    speed_x: NotRequired[float]
    flight_cpu_s: NotRequired[float]
