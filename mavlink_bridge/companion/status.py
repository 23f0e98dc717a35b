"""What a companion counts, the mission flags it hears, and the result it reports."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from mavlink_bridge.companion.config import EXIT_OK, EXIT_VEHICLE, EXIT_WRITE_FAILED


@dataclass
class CompanionCounters:
    control_steps: int = 0
    setpoints_sent: int = 0
    ticks_granted: int = 0
    """Lockstep ticks answered by a grant sent with an earlier setpoint (no setpoint of their own)."""
    extrapolated_steps: int = 0
    """Control steps on an extrapolated vehicle clock (no telemetry)."""
    holds: int = 0
    """Hold setpoints sent."""
    hold_episodes: int = 0
    """Times the companion went into hold (gap, silence, non-finite action)."""
    nonfinite_actions: int = 0
    fixes: int = 0
    fixes_rejected: int = 0
    restarts: int = 0
    engagements: int = 0
    pauses: int = 0
    skipped_ticks: int = 0
    """Vehicle ticks that passed without a control step (the companion fell behind)."""
    ends_refuted: int = 0
    """Mission ends (HIT, MSN_END, their texts) that the vehicle's own heartbeats contradicted: ignored."""
    slew_acks: int = 0
    """GUIDED_CHANGE_HEADING / _SPEED commands the vehicle accepted (``--setpoints arduplane``)."""


@dataclass
class MissionFlags:
    """The flags the vehicles announce (NAMED_VALUE_INT), each with the vehicle time it was stamped."""

    values: dict[str, int] = field(default_factory=dict)
    stamps_ms: dict[str, int] = field(default_factory=dict)

    def set(self, name: str, value: int, stamp_ms: int) -> bool:
        """Take a value unless an older message overtook a newer one; True if it changed."""
        if stamp_ms < self.stamps_ms.get(name, -1):
            return False
        self.stamps_ms[name] = stamp_ms
        changed = self.values.get(name) != value
        self.values[name] = value
        return changed

    def get(self, name: str) -> int:
        return self.values.get(name, 0)


@dataclass
class CompanionResult:
    status: str
    role: str
    message: str
    vehicle_time_s: float | None
    flight_wall_s: float | None
    """Wall seconds between the first and the last control step."""
    flight_cpu_s: float | None
    """This process's CPU seconds between the first and the last control step."""
    counters: CompanionCounters
    link: dict[str, int]
    latency_ms: dict[str, float]
    """Telemetry received -> setpoint sent, wall clock: n, p50, p99, max."""
    flags: dict[str, int]
    latency_samples_ms: list[float] = field(default_factory=list)
    """Every control step's latency (for benchmarks that pool several companions)."""
    shield: dict[str, float] | None = None
    """The runtime-assurance monitor's counts (``ShieldCounters`` of the companion's shield), when it flew."""
    vehicle_limits: dict[str, object] | None = None
    """What the vehicle said it achieves (:class:`~tssac_core.wire.vehicle_limits.Achievable`), when the monitor flew
    and the vehicle said it."""
    write_error: str | None = None
    """What the run failed to write (its tlog cut by a full disk); None: nothing was lost. Not in the dict when None."""

    @property
    def exit_code(self) -> int:
        if self.status in ("lost", "no_vehicle", "refused"):
            return EXIT_VEHICLE
        return EXIT_WRITE_FAILED if self.write_error is not None else EXIT_OK

    def as_dict(self) -> dict[str, object]:
        d = asdict(self)
        if self.write_error is None:
            del d["write_error"]
        d["exit_code"] = self.exit_code
        return d
