"""The companion's state machine: connect, engage, fly each tick of the vehicle's clock, end.

States (:class:`Phase`) and failsafes: :mod:`mavlink_bridge.companion`.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from dataclasses import asdict

import numpy as np

from mavlink_bridge.companion.config import (
    GUIDED_MODE,
    LOITER_MODE,
    MIN_POS_SIGMA_M,
    MIN_VEL_SIGMA_M_S,
    CompanionConfig,
)
from mavlink_bridge.companion.grants import GrantRule
from mavlink_bridge.companion.mission_end import EndWatch
from mavlink_bridge.companion.pilot_step import PilotStep
from mavlink_bridge.companion.status import CompanionCounters, CompanionResult, MissionFlags
from mavlink_bridge.companion.tick_clock import TickClock
from mavlink_bridge.companion.vehicle_limits import describe, read_achievable
from mavlink_bridge.estimation.state_filter import FilterNoise, VehicleStateFilter
from mavlink_bridge.link.connection import CommandError, LinkError, M, MavLink, Message
from mavlink_bridge.link.frames import (
    Measurement,
    Setpoint,
    from_global_position_int,
    from_local_position_ned,
)
from mavlink_bridge.link.guided_commands import SLEW_COMMANDS, SetpointDialect, slew_from_setpoint
from tssac_core.common.cli import UsageError, write_json
from tssac_core.wire.mission_events import (
    FLAGS,
    HIT_TEXT,
    IDENTIFIED_TEXT,
    MISSION_END_PREFIX,
    RADAR_TEXTS,
    EventName,
    MissionEnd,
    end_from_text,
)
from tssac_core.wire.signing import companion_link_id

_log = logging.getLogger("mavlink_bridge.companion")

LEAN_OFF = ("GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD")
"""The vehicle streams a companion with ``lean_telemetry`` (or on a serial line, a port of its own) switches off: those
at the step rate that it does not read. The once-a-second ones it does not read either (SYS_STATUS, GPS_RAW_INT,
HOME_POSITION, EXTENDED_SYS_STATE) stay on: switching them off saved no CPU measurably, and cost four more command
round trips at every engagement (0.4 s each over the degraded scenario's link)."""
_LOCAL_FRESH_S = 2.0
"""GLOBAL_POSITION_INT is used only when no LOCAL_POSITION_NED came for this long (vehicle time)."""


class Phase(enum.Enum):
    CONNECT = "connect"
    ENGAGE = "engage"
    FLY = "fly"
    PAUSED = "paused"
    END = "end"


class _Stop(Exception):
    """Internal: leave the loop."""


def open_link(cfg: CompanionConfig) -> MavLink:
    """The companion's link to its vehicle; a link that cannot open is bad input (UsageError, one line)."""
    try:
        return MavLink(
            cfg.connection,
            signing_key=cfg.signing_key,
            # Binds our signed frames to our vehicle (the SITL's sysid of the role): the others refuse them.
            signing_link_id=companion_link_id(cfg.role.index + 1),
            tlog_path=cfg.tlog,
            source_system=cfg.role.index + 1 if cfg.source_system is None else cfg.source_system,
        )
    except LinkError as exc:
        raise UsageError(str(exc)) from None


class Companion:
    """One UAV's companion process (see the module docstring)."""

    def __init__(self, config: CompanionConfig) -> None:
        self.cfg = config
        s = config.scenario
        self.spec = s.vehicle(config.role)
        self.dt_ms = int(round(s.dt_s * 1000.0))
        self.counters = CompanionCounters()
        self.pilot_step = PilotStep.of(config, self.counters)
        """The pilot and the monitor: what flies at each tick (:mod:`.pilot_step`)."""
        _log.info("%s: pilot %s", config.role.value, self.pilot_step.pilot.name)
        link_model = s.link
        self.noise = FilterNoise.from_sensor(
            max(link_model.gps_position_sigma_m, MIN_POS_SIGMA_M),
            max(link_model.gps_velocity_sigma_m_s, MIN_VEL_SIGMA_M_S),
            max_accel_m_s2=self.spec.accel_max_m_s2,
            max_turn_rate_rad_s=math.radians(self.spec.turn_rate_max_deg_s),
        )
        self._grant_rule = GrantRule.of(config)
        self.latencies_s: list[float] = []
        self._first_control_wall_s: float | None = None
        self._last_control_wall_s: float | None = None
        self._first_control_cpu_s = 0.0
        self._last_control_cpu_s = 0.0
        self.phase = Phase.CONNECT
        self._stop_requested = False
        self._limits_read = False
        """The vehicle's achievable limits were asked for in this run (a monitored flight asks once, before it arms)."""
        self._link: MavLink | None = None
        self._ends = EndWatch()
        self._reset_vehicle_state()
        self._status: tuple[str, str] | None = None

    # --------------------------------------------------------------------------- control

    def request_stop(self) -> None:
        """End the run at the next loop iteration (safe from a signal handler)."""
        self._stop_requested = True

    def _reset_vehicle_state(self) -> None:
        """Forget everything about the vehicle's flight (at start and after a restart)."""
        self.filter = VehicleStateFilter(self.noise, self.cfg.filter_model)
        self.flags = MissionFlags()
        self.ticks = TickClock(self.dt_ms, self.cfg.lockstep, self.cfg.settle_s)
        """The vehicle's clock as we follow it (:mod:`.tick_clock`)."""
        self.local_ms: int | None = None  # newest LOCAL_POSITION_NED
        self.fly_start_ms: int | None = None
        self.armed = False
        self.mode: int | None = None
        self._state_valid_after_s = 0.0  # heartbeats read before this wall time predate our last commands
        self._holding: str | None = None  # why we hold, while we do
        self._gap_seen = False  # a gap happened since the last fix: re-engage a disarmed vehicle
        self._sent: Setpoint | None = None  # the setpoint sent last
        self._granted_ms: int | None = None  # the last tick it answers for (a lockstep grant), None: its own tick
        self.pilot_step.reset()

    def run(self, link: MavLink | None = None) -> CompanionResult:
        """Connect, engage, fly until the mission ends, the vehicle is lost or a stop is requested.

        ``link``: the link of a companion that flies mission after mission (``--serve``); it is reset for this
        mission (:meth:`MavLink.new_mission`) and left open. Without one, the run opens its own and closes it."""
        cfg = self.cfg
        own_link = link is None
        if link is None:
            link = open_link(cfg)
        else:
            try:
                link.new_mission(cfg.tlog)
            except LinkError as exc:
                raise UsageError(str(exc)) from None
        self._link = link
        self._limits_read = False
        self.last_rx_s = time.monotonic()
        self._next_heartbeat_s = 0.0
        self._last_silence_hold_s = -math.inf
        try:
            try:
                hb = link.wait_heartbeat(cfg.connect_timeout_s, stop=lambda: self._stop_requested)
            except LinkError as exc:
                if self._stop_requested:
                    raise _Stop("stopped", "stopped before the vehicle answered") from None
                raise _Stop("no_vehicle", str(exc)) from None
            _log.info(
                "%s: vehicle sysid %d at %s (type %d, autopilot %d); we are %d:%d",
                cfg.role.value,
                hb.get_srcSystem(),
                link.spec,
                hb.type,
                hb.autopilot,
                cfg.source_system or hb.get_srcSystem(),
                link.mav.srcComponent,
            )
            if cfg.source_system is None:
                link.mav.srcSystem = link.target_system  # the vehicle's system, our own component (191)
            budget = cfg.line_budget
            if budget is not None:
                _log.info("%s: %s", cfg.role.value, budget.describe())
            self.last_rx_s = time.monotonic()
            self.phase = Phase.ENGAGE
            self._loop()
        except _Stop as stop:
            self._status = (stop.args[0], stop.args[1])
        finally:
            link.close_tlog()  # first: its last bytes are written now, and may be lost now
            result = self._result()
            if own_link:
                link.close()
            if cfg.status_json is not None:
                write_json(cfg.status_json, result.as_dict())
        return result

    # ------------------------------------------------------------------------------ loop

    def _loop(self) -> None:
        link = self._link
        assert link is not None
        while True:
            if self._stop_requested:
                raise _Stop("stopped", "stopped by a signal")
            if self.phase is Phase.ENGAGE:
                self._engage()
            msg = link.recv(self.ticks.wait_s(self.phase is Phase.FLY, time.monotonic()))
            while msg is not None:
                if self.ticks.later_tick_read(getattr(msg, "time_boot_ms", -1)):
                    self._maybe_control(time.monotonic())
                self._handle(msg)
                if self._end_believed():
                    break  # nothing after a signed end is flown (the world's linger arrives right behind it)
                msg = link.recv(0.0)
            now = time.monotonic()
            self._maybe_control(now)
            self._check_end(now)
            self._check_silence(now)
            if now >= self._next_heartbeat_s:
                link.send_heartbeat()
                self._next_heartbeat_s = now + 1.0

    # --------------------------------------------------------------------------- engage

    def _engage(self) -> None:
        """Arm and switch to GUIDED, checking both COMMAND_ACKs; stream the position at the step rate."""
        link, cfg = self._link, self.cfg
        assert link is not None
        role = cfg.role.value
        shield = self.pilot_step.shield
        if shield is not None and not self._limits_read:
            achievable = read_achievable(link, cfg.command_timeout_s, cfg.attempts)
            self._limits_read = True
            _log.info("%s: the vehicle %s", role, describe(achievable))
            refusal = shield.use_achievable(achievable)
            if refusal is not None:
                raise _Stop("refused", refusal)
        try:
            link.arm(cfg.command_timeout_s, cfg.attempts)
            _log.info("%s: armed", role)
            link.set_mode(GUIDED_MODE, cfg.command_timeout_s, cfg.attempts)
            _log.info("%s: GUIDED", role)
        except CommandError as exc:
            if self._stop_requested:
                raise _Stop("stopped", "stopped while engaging") from None
            raise _Stop("refused", str(exc)) from None
        self._state_valid_after_s = link.last_rx_s  # when the GUIDED ACK was read
        self.armed, self.mode = True, GUIDED_MODE
        intervals = {"LOCAL_POSITION_NED": self.cfg.scenario.dt_s}
        if cfg.lean_telemetry or link.baud is not None:  # a serial port is the companion's own: nobody else reads it
            intervals.update({name: -1.0 for name in LEAN_OFF})
        for name, interval_s in intervals.items():
            # Position at the step rate; an autopilot that cannot do it keeps its default (logged).
            try:
                link.set_message_interval(
                    getattr(M, f"MAVLINK_MSG_ID_{name}"), interval_s, cfg.command_timeout_s, cfg.attempts
                )
            except CommandError as exc:
                _log.warning("%s: %s (keeping the vehicle's default)", role, exc)
        self.counters.engagements += 1
        self.ticks.last_control_ms = None  # act at once on the newest tick
        self.phase = Phase.FLY

    # --------------------------------------------------------------------------- receive

    def _handle(self, msg: Message) -> None:
        link = self._link
        assert link is not None
        if not link.from_vehicle(msg):
            return
        rx_s = link.last_rx_s
        self.last_rx_s = max(self.last_rx_s, rx_s)
        mtype = msg.get_type()
        if self.ticks.stamps_time(mtype):
            self._vehicle_time(int(msg.time_boot_ms), rx_s)
        if mtype == "HEARTBEAT":
            self._on_heartbeat(msg, rx_s)
        elif mtype == "LOCAL_POSITION_NED":
            self.local_ms = int(msg.time_boot_ms)
            self._on_fix(from_local_position_ned(msg.time_boot_ms, msg.x, msg.y, msg.vx, msg.vy), rx_s)
        elif mtype == "GLOBAL_POSITION_INT":
            if self.local_ms is None or msg.time_boot_ms - self.local_ms > _LOCAL_FRESH_S * 1000:
                self._on_fix(
                    from_global_position_int(
                        self.cfg.scenario.origin, msg.time_boot_ms, msg.lat, msg.lon, msg.vx, msg.vy
                    ),
                    rx_s,
                )
        elif mtype == "NAMED_VALUE_INT":
            self._on_named_value(str(msg.name).rstrip("\x00"), int(msg.value), int(msg.time_boot_ms))
        elif mtype == "STATUSTEXT":
            self._on_statustext(str(msg.text).rstrip("\x00"))
        elif mtype == "COMMAND_ACK" and msg.command in SLEW_COMMANDS:
            self._on_slew_ack(int(msg.command), int(msg.result))
        elif mtype == "WIND" and self.pilot_step.shield is not None:
            # The wind the vehicle reports, blowing FROM ``direction`` (deg clockwise from north): the air's velocity.
            towards = math.radians(float(msg.direction)) + math.pi
            speed = float(msg.speed)
            self.pilot_step.shield.set_wind(speed * math.sin(towards), speed * math.cos(towards))

    def _on_slew_ack(self, command: int, result: int) -> None:
        """A GUIDED slew command's answer. Refused, the vehicle cannot be flown in this dialect: it is left in LOITER,
        as a failsafe would, and the companion ends with one line that says which command and why."""
        if result == M.MAV_RESULT_ACCEPTED:
            self.counters.slew_acks += 1
            return
        name = M.enums["MAV_CMD"][command].name
        why = M.enums["MAV_RESULT"][result].name if result in M.enums["MAV_RESULT"] else str(result)
        link = self._link
        assert link is not None
        try:
            link.set_mode(LOITER_MODE, self.cfg.command_timeout_s, self.cfg.attempts)
            left = "left in LOITER"
        except CommandError as exc:
            left = f"LOITER refused too ({exc})"
        said = f"the vehicle refused {name} ({why}): it cannot be flown with --setpoints arduplane; {left}"
        _log.error("%s: %s", self.cfg.role.value, said)
        raise _Stop("refused", said)

    def _vehicle_time(self, t_ms: int, rx_s: float) -> None:
        if self.ticks.went_back(t_ms, self.cfg.restart_jump_s):
            self._on_restart(t_ms)
        self.ticks.seen(t_ms, rx_s)

    def _on_restart(self, t_ms: int) -> None:
        role = self.cfg.role.value
        _log.warning(
            "%s: vehicle clock went back from %.1f s to %.1f s: the vehicle restarted; re-initialising",
            role,
            (self.ticks.vt_ms or 0) / 1000.0,
            t_ms / 1000.0,
        )
        self.counters.restarts += 1
        self._reset_vehicle_state()
        if self.pilot_step.shield is not None:
            self.pilot_step.shield.reset()
        if self.phase in (Phase.FLY, Phase.PAUSED):
            self.phase = Phase.ENGAGE
        self._say(M.MAV_SEVERITY_WARNING, f"{role}: vehicle restart seen, re-engaging")

    def _on_heartbeat(self, msg: Message, rx_s: float) -> None:
        if not self._link or not self._link.is_vehicle_heartbeat(msg):
            return
        self._check_claimed_end(int(msg.system_status), rx_s)
        if rx_s < self._state_valid_after_s:
            return
        self.armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        self.mode = int(msg.custom_mode)
        in_control = self.armed and self.mode == GUIDED_MODE
        role = self.cfg.role.value
        if self.phase is Phase.FLY and not in_control:
            if self._gap_seen:
                _log.warning(
                    "%s: after the link gap the vehicle is %s in mode %d: re-engaging",
                    role,
                    "armed" if self.armed else "disarmed",
                    self.mode,
                )
                self.phase = Phase.ENGAGE
            else:
                _log.warning(
                    "%s: the vehicle left GUIDED or was disarmed (mode %d, %s): pausing until it is back",
                    role,
                    self.mode,
                    "armed" if self.armed else "disarmed",
                )
                self.counters.pauses += 1
                self.phase = Phase.PAUSED
        elif self.phase is Phase.PAUSED and in_control:
            _log.info("%s: armed in GUIDED again: resuming", role)
            self.ticks.last_control_ms = None
            self.phase = Phase.FLY

    def _on_fix(self, m: Measurement, rx_s: float) -> None:
        if not (
            math.isfinite(m.east_m)
            and math.isfinite(m.north_m)
            and math.isfinite(m.vel_east_m_s)
            and math.isfinite(m.vel_north_m_s)
        ):
            self.counters.fixes_rejected += 1
            return
        pos, vel = (m.east_m, m.north_m), (m.vel_east_m_s, m.vel_north_m_s)
        prior = None if self.filter.initialised else self.pilot_step.start_turn_rate(int(round(m.t_s * 1000.0)))
        if prior is not None:  # the first fix of a flight whose turn rate is known: the filter starts from it
            self.filter.reset(m.t_s, pos, vel, prior)
            self.counters.fixes += 1
        elif self.filter.update(m.t_s, pos, vel):
            self.counters.fixes += 1
        else:
            self.counters.fixes_rejected += 1
        self.ticks.fix(int(round(m.t_s * 1000.0)), rx_s)

    def _on_named_value(self, name: str, value: int, stamp_ms: int) -> None:
        if name not in FLAGS:
            return
        if self.flags.set(name, value, stamp_ms):
            _log.info("%s: %s = %d at %.1f s", self.cfg.role.value, name, value, stamp_ms / 1000.0)
        if name == EventName.HIT and value == 1:
            self._claim_end("success", f"target hit at {stamp_ms / 1000.0:.1f} s")
        if name == EventName.MSN_END and value in set(MissionEnd):
            end = MissionEnd(value)
            self._claim_end(end.status, f"mission ended ({end.status}) at {stamp_ms / 1000.0:.1f} s")

    def _on_statustext(self, text: str) -> None:
        _log.info("%s: vehicle says: %s", self.cfg.role.value, text)
        # The flags normally come as NAMED_VALUE_INT; the texts are the human-readable fallback.
        stamp = self.ticks.vt_ms or 0
        if text in (RADAR_TEXTS[True], RADAR_TEXTS[False]):
            self.flags.set(EventName.RADAR_ON, int(text == RADAR_TEXTS[True]), stamp)
        elif text == IDENTIFIED_TEXT:
            self.flags.set(EventName.IDENT, 1, stamp)
        elif text == HIT_TEXT:
            self._claim_end("success", f"target hit (STATUSTEXT) at {stamp / 1000.0:.1f} s")
        elif text.startswith(MISSION_END_PREFIX):
            end = end_from_text(text)
            what = text[len(MISSION_END_PREFIX) :]
            status = end.status if end is not None else what.replace(" ", "_")
            self._claim_end(status, f"mission ended ({what}) at {stamp / 1000.0:.1f} s")

    # ----------------------------------------------------------------------- mission end

    def _claim_end(self, status: str, message: str) -> None:
        """A mission end from the vehicle's address: flown on until the vehicle confirms it (:mod:`.mission_end`)."""
        if self._ends.hear(status, message, time.monotonic()):
            _log.info("%s: %s: waiting for the vehicle to confirm it", self.cfg.role.value, message)

    def _check_claimed_end(self, system_status: int, rx_s: float) -> None:
        """A vehicle heartbeat read at ``rx_s`` confirms a claimed end (POWEROFF) or, after the grace, refutes it."""
        refuted = self._ends.heartbeat(system_status, rx_s)
        if refuted is not None:
            _log.warning(
                "%s: ignoring '%s': the vehicle still reports state %d, not a mission end",
                self.cfg.role.value,
                refuted.message,
                system_status,
            )
            self.counters.ends_refuted += 1

    def _end_believed(self) -> bool:
        """A mission end is claimed in a frame signed with the run's key: it came from the vehicle itself."""
        return self._ends.claim is not None and self._link is not None and self._link.signing

    def _check_end(self, now: float) -> None:
        """End the run once a claimed end is confirmed (:meth:`EndWatch.confirmed`)."""
        end = self._ends.confirmed(now, self.last_rx_s, self._end_believed())
        if end is not None:
            raise _Stop(end.status, end.message)

    # --------------------------------------------------------------------------- control

    def _maybe_control(self, now: float) -> None:
        """A control step if one is due (:meth:`TickClock.due`)."""
        if self.phase is not Phase.FLY:
            return
        due = self.ticks.due(now, self.last_rx_s)
        if due is None:
            return
        if due.extrapolated:
            self.counters.extrapolated_steps += 1
        self._control(due.t_ms, due.trigger_rx_s)

    def _control(self, t_ms: int, trigger_rx_s: float | None) -> None:
        """One control step at vehicle time t_ms."""
        link = self._link
        assert link is not None
        self.counters.skipped_ticks += self.ticks.controlled(t_ms)
        if self.fly_start_ms is None:
            self.fly_start_ms = t_ms
        self.counters.control_steps += 1
        now = time.monotonic()
        if self._first_control_wall_s is None:
            self._first_control_wall_s = now
            self._first_control_cpu_s = time.process_time()
        self._last_control_wall_s = now
        self._last_control_cpu_s = time.process_time()
        decision = self.pilot_step.decide(t_ms, self.filter, self.flags)
        if decision.gap_seen is not None:
            self._gap_seen = decision.gap_seen
        if decision.handover is not None:
            _log.info("%s at %.1f s", decision.handover, (self.ticks.last_control_ms or 0) / 1000.0)
            self._say(M.MAV_SEVERITY_NOTICE, decision.handover)
        setpoint, why = decision.setpoint, decision.why
        if why is None:
            if self._holding is not None:
                _log.info("%s: %s over, resuming", self.cfg.role.value, self._holding)
                self._say(M.MAV_SEVERITY_INFO, f"{self.cfg.role.value}: telemetry back, resuming")
                self._holding = None
        else:
            self._hold_reason(why)
        if self._granted_ms is not None and t_ms <= self._granted_ms and setpoint == self._sent:
            self.counters.ticks_granted += 1  # answered by the setpoint sent with the grant
        else:
            self._send_setpoint(t_ms, setpoint, None if why is not None else self._grant_ms(t_ms))
            if trigger_rx_s is not None:
                self.latencies_s.append(time.monotonic() - trigger_rx_s)
        self.pilot_step.sent(setpoint, t_ms, before_fix=not self.filter.initialised)
        if self._duration_over(t_ms):
            raise _Stop("duration", f"flew {self.cfg.duration_s:g} s of vehicle time")

    def _send_setpoint(self, t_ms: int, setpoint: Setpoint, granted_through_ms: int | None) -> None:
        link = self._link
        assert link is not None
        if self.cfg.setpoints is SetpointDialect.ARDUPLANE:
            f = self.filter
            course, speed = (f.heading_rad, f.speed_m_s) if f.initialised else (None, None)
            link.send_guided_slew(slew_from_setpoint(setpoint, course, speed, self.spec), t_ms, granted_through_ms)
        else:
            link.send_setpoint(t_ms, setpoint.yaw_rate_rad_s, setpoint.accel_m_s2, granted_through_ms)
        self.counters.setpoints_sent += 1
        self._sent = setpoint
        self._granted_ms = granted_through_ms

    def _grant_ms(self, t_ms: int) -> int | None:
        """The last tick a setpoint sent at tick ``t_ms`` answers for (None: only its own): up to the pilot's and
        the monitor's next decision (:class:`GrantRule`)."""
        if not self._grant_rule.enabled:
            return None
        return self._grant_rule.through_ms(
            t_ms,
            self.pilot_step.next_change_step(t_ms // self.dt_ms),
            lambda tick_ms: self.pilot_step.gap_s(self.filter, tick_ms) > self.cfg.hold_after_s,
            self._duration_over if self.cfg.duration_s is not None else None,
        )

    def _duration_over(self, t_ms: int) -> bool:
        """``--duration-s`` of flight is over at tick ``t_ms``."""
        assert self.fly_start_ms is not None
        return self.cfg.duration_s is not None and (t_ms - self.fly_start_ms) / 1000.0 >= self.cfg.duration_s

    def _hold_reason(self, why: str) -> None:
        """Count and say (once per spell) what is amiss: the hold flies without the monitor, its backup with it."""
        self.counters.holds += 1
        kind = why.split(" ")[0]
        if self._holding is None or self._holding.split(" ")[0] != kind:
            self.counters.hold_episodes += 1
            monitored = self.pilot_step.shield is not None
            flown = "the monitor's backup flies" if monitored else "sending the hold setpoint"
            _log.warning("%s: %s: %s", self.cfg.role.value, why, flown)
            said = "backup" if monitored else "holding"
            self._say(M.MAV_SEVERITY_WARNING, f"{self.cfg.role.value}: {why}, {said}")
        self._holding = why

    def _check_silence(self, now: float) -> None:
        silent_s = now - self.last_rx_s
        if silent_s > self.cfg.lost_after_s:
            raise _Stop("lost", f"no message from the vehicle for {silent_s:.1f} s")
        if self.phase is not Phase.FLY or self.ticks.extrapolating():
            return
        if silent_s > self.cfg.silence_hold_s and now - self._last_silence_hold_s >= 1.0:
            self._last_silence_hold_s = now
            self._gap_seen = True
            self._hold_reason(f"link silent {silent_s:.1f} s")
            link = self._link
            assert link is not None
            self._send_setpoint(self.ticks.vt_ms or 0, self.pilot_step.held_setpoint(), None)

    def _say(self, severity: int, text: str) -> None:
        if self._link is not None:
            self._link.send_statustext(severity, text)

    # ---------------------------------------------------------------------------- result

    def _result(self) -> CompanionResult:
        status, message = self._status if self._status is not None else ("stopped", "stopped")
        lat = np.asarray(self.latencies_s) * 1000.0
        latency = {}
        if lat.size:
            latency = {
                "n": float(lat.size),
                "p50": float(np.percentile(lat, 50)),
                "p99": float(np.percentile(lat, 99)),
                "max": float(lat.max()),
            }
        link = self._link
        return CompanionResult(
            status=status,
            role=self.cfg.role.value,
            message=message,
            vehicle_time_s=None if self.ticks.vt_ms is None else self.ticks.vt_ms / 1000.0,
            flight_wall_s=None
            if self._first_control_wall_s is None or self._last_control_wall_s is None
            else self._last_control_wall_s - self._first_control_wall_s,
            flight_cpu_s=None
            if self._first_control_wall_s is None
            else self._last_control_cpu_s - self._first_control_cpu_s,
            counters=self.counters,
            link=asdict(link.counters) if link is not None else {},
            latency_ms=latency,
            flags=dict(self.flags.values),
            latency_samples_ms=[round(float(x), 4) for x in lat],
            shield=None if self.pilot_step.shield is None else asdict(self.pilot_step.shield.counters),
            vehicle_limits=None
            if self.pilot_step.shield is None or self.pilot_step.shield.achievable is None
            else asdict(self.pilot_step.shield.achievable),
            write_error=None if link is None else link.tlog_error,
        )
