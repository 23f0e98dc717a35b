"""The companion's state machine: connect, engage, fly each tick of the vehicle's clock, end.

States (:class:`Phase`) and failsafes: :mod:`mavlink_bridge.companion`.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict

import numpy as np

from mavlink_bridge.companion.clock_rate import ClockRate
from mavlink_bridge.companion.config import (
    GUIDED_MODE,
    LOITER_MODE,
    MIN_POS_SIGMA_M,
    MIN_VEL_SIGMA_M_S,
    CompanionConfig,
)
from mavlink_bridge.companion.grants import GrantRule
from mavlink_bridge.companion.held_pilot import DecisionClock, HeldPilot, make_pilot
from mavlink_bridge.companion.mission_end import EndWatch
from mavlink_bridge.companion.shield import CompanionShield, Estimate
from mavlink_bridge.companion.status import CompanionCounters, CompanionResult, MissionFlags
from mavlink_bridge.estimation.state_filter import FilterNoise, VehicleStateFilter
from mavlink_bridge.link.connection import CommandError, LinkError, M, MavLink, Message
from mavlink_bridge.link.frames import (
    HOLD,
    Measurement,
    Setpoint,
    action_to_setpoint,
    from_global_position_int,
    from_local_position_ned,
    setpoint_to_action,
)
from mavlink_bridge.link.guided_commands import SLEW_COMMANDS, SetpointDialect, slew_from_setpoint
from tssac_core.common.cli import UsageError, write_json
from tssac_core.sim.airframe_response import load_response
from tssac_core.sim.world_state import WorldState, initial_state
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
TIMED_TYPES = frozenset({"ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "SYSTEM_TIME", "NAMED_VALUE_INT"})
"""Messages whose ``time_boot_ms`` is the vehicle's clock."""
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
        assert s.layout is not None
        self.role_index = config.role.index
        self.spec = s.vehicle(config.role)
        self.dt_ms = int(round(s.dt_s * 1000.0))
        self.pilot: HeldPilot = make_pilot(config)
        self.layout_state: WorldState = initial_state(s, s.layout)
        """The mission's start as the pilots see it; each tick the filter's estimate replaces this vehicle's state."""
        self.shield = (
            None
            if config.shield is None
            else CompanionShield(
                self.layout_state,
                config.role,
                s,
                config.shield,
                config.lockstep,
                None if config.airframe_response is None else load_response(config.airframe_response),
            )
        )
        self.pilot.action(lambda: self.layout_state, self.role_index, 0)  # warm up: the guidance plans its route
        self.pilot.reset()
        _log.info("%s: pilot %s", config.role.value, self.pilot.name)
        link_model = s.link
        self.noise = FilterNoise.from_sensor(
            max(link_model.gps_position_sigma_m, MIN_POS_SIGMA_M),
            max(link_model.gps_velocity_sigma_m_s, MIN_VEL_SIGMA_M_S),
            max_accel_m_s2=self.spec.accel_max_m_s2,
            max_turn_rate_rad_s=math.radians(self.spec.turn_rate_max_deg_s),
        )
        self._grant_rule = GrantRule.of(config)
        self.counters = CompanionCounters()
        self.latencies_s: list[float] = []
        self._first_control_wall_s: float | None = None
        self._last_control_wall_s: float | None = None
        self._first_control_cpu_s = 0.0
        self._last_control_cpu_s = 0.0
        self.phase = Phase.CONNECT
        self._stop_requested = False
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
        self.vt_ms: int | None = None  # newest vehicle time seen
        self.vt_rx_s = 0.0  # wall time it was first seen
        self.fix_ms: int | None = None  # time of the newest position fix
        self.fix_rx_s = 0.0
        self.local_ms: int | None = None  # newest LOCAL_POSITION_NED
        self.last_control_ms: int | None = None
        self._decisions = DecisionClock(self.pilot.repeat)  # the monitor's decision ticks
        self.fly_start_ms: int | None = None
        self.armed = False
        self.mode: int | None = None
        self._state_valid_after_s = 0.0  # heartbeats read before this wall time predate our last commands
        self._clock_rate = ClockRate()  # vehicle seconds per wall second
        self._holding: str | None = None  # why we hold, while we do
        self._gap_seen = False  # a gap happened since the last fix: re-engage a disarmed vehicle
        self._sent: Setpoint | None = None  # the setpoint sent last
        self._granted_ms: int | None = None  # the last tick it answers for (a lockstep grant), None: its own tick
        self.pilot.reset()

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
            msg = link.recv(self._wait_s())
            while msg is not None:
                if self.cfg.lockstep and self._tick_due() and getattr(msg, "time_boot_ms", -1) > (self.vt_ms or 0):
                    # A lockstep world sends ticks back to back through a grant and after the mission's end (its
                    # linger): each tick is controlled before anything of a later one is read, as if the world had
                    # waited for its answer, however fast the next ticks come.
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

    def _wait_s(self) -> float:
        """How long the next receive may block (wall seconds)."""
        wait = 0.1
        if self.phase is Phase.FLY and self.vt_ms is not None and self._tick_due():
            if self.fix_ms != self.vt_ms:
                wait = max(0.0, self.vt_rx_s + self._settle_s - time.monotonic())
            else:
                wait = 0.0
        elif self.phase is Phase.FLY and self._extrapolating() and self.rate:
            wait = min(wait, 0.5 * self.dt_ms / 1000.0 / self.rate)
        return wait

    # --------------------------------------------------------------------------- engage

    def _engage(self) -> None:
        """Arm and switch to GUIDED, checking both COMMAND_ACKs; stream the position at the step rate."""
        link, cfg = self._link, self.cfg
        assert link is not None
        role = cfg.role.value
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
        self.last_control_ms = None  # act at once on the newest tick
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
        # Under lockstep the step's tick (SYSTEM_TIME, sent after the rest of the step) says a step is there: a frame of
        # a step read before its tick may have come without the step's fix (the rest in a datagram not yet read).
        if mtype in TIMED_TYPES and (mtype == "SYSTEM_TIME" or not self.cfg.lockstep):
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
        if self.vt_ms is not None and t_ms < self.vt_ms - self.cfg.restart_jump_s * 1000.0:
            self._on_restart(t_ms)
        if self.vt_ms is None or t_ms > self.vt_ms:
            self.vt_ms = t_ms
            self.vt_rx_s = rx_s
            self._clock_rate.seen(rx_s, t_ms)

    @property
    def rate(self) -> float | None:
        """Vehicle seconds per wall second (:class:`ClockRate`), None until measured."""
        return self._clock_rate.rate

    def _on_restart(self, t_ms: int) -> None:
        role = self.cfg.role.value
        _log.warning(
            "%s: vehicle clock went back from %.1f s to %.1f s: the vehicle restarted; re-initialising",
            role,
            (self.vt_ms or 0) / 1000.0,
            t_ms / 1000.0,
        )
        self.counters.restarts += 1
        self._reset_vehicle_state()
        if self.shield is not None:
            self.shield.reset()
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
            self.last_control_ms = None
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
        if self.filter.update(m.t_s, (m.east_m, m.north_m), (m.vel_east_m_s, m.vel_north_m_s)):
            self.counters.fixes += 1
        else:
            self.counters.fixes_rejected += 1
        t_ms = int(round(m.t_s * 1000.0))
        if self.fix_ms is None or t_ms >= self.fix_ms:
            self.fix_ms = t_ms
            self.fix_rx_s = rx_s

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
        stamp = self.vt_ms or 0
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

    def _tick_due(self) -> bool:
        """A vehicle tick newer than the last control step is known."""
        if self.vt_ms is None:
            return False
        return self.last_control_ms is None or self.vt_ms >= self.last_control_ms + self.dt_ms - 1

    @property
    def _settle_s(self) -> float:
        """How long a known tick waits for its fix. Not at all under lockstep: the vehicle sends a step's
        telemetry in one datagram and then waits for us, so a fix that is not there was lost by the link."""
        return 0.0 if self.cfg.lockstep else self.cfg.settle_s

    def _extrapolating(self) -> bool:
        return not self.cfg.lockstep and self.rate is not None and self.rate > 0 and self.vt_ms is not None

    def _maybe_control(self, now: float) -> None:
        if self.phase is not Phase.FLY or self.vt_ms is None:
            return
        if self._tick_due():
            if self.fix_ms != self.vt_ms and now < self.vt_rx_s + self._settle_s:
                return  # the tick's fix is probably still on its way
            trigger = self.fix_rx_s if self.fix_ms == self.vt_ms else self.vt_rx_s
            self._control(self.vt_ms, trigger)
            return
        if self._extrapolating():
            assert self.rate is not None and self.last_control_ms is not None
            silent_s = now - self.last_rx_s
            if silent_s < 1.5 * self.dt_ms / 1000.0 / self.rate:
                return
            est_ms = self.vt_ms + (now - self.vt_rx_s) * self.rate * 1000.0
            tick_ms = int(est_ms // self.dt_ms) * self.dt_ms
            if tick_ms >= self.last_control_ms + self.dt_ms:
                self.counters.extrapolated_steps += 1
                self._control(tick_ms, None)

    def _control(self, t_ms: int, trigger_rx_s: float | None) -> None:
        """One control step at vehicle time t_ms."""
        link = self._link
        assert link is not None
        if self.last_control_ms is not None and t_ms > self.last_control_ms + self.dt_ms:
            self.counters.skipped_ticks += (t_ms - self.last_control_ms) // self.dt_ms - 1
        self.last_control_ms = t_ms
        if self.fly_start_ms is None:
            self.fly_start_ms = t_ms
        self.counters.control_steps += 1
        now = time.monotonic()
        if self._first_control_wall_s is None:
            self._first_control_wall_s = now
            self._first_control_cpu_s = time.process_time()
        self._last_control_wall_s = now
        self._last_control_cpu_s = time.process_time()
        setpoint, why = self._decide(t_ms)
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
        if self.shield is not None:
            self.shield.sent(setpoint_to_action(setpoint, self.spec), t_ms // self.dt_ms, not self.filter.initialised)
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
        step = t_ms // self.dt_ms
        next_step = self.pilot.next_decision_step(step)
        if self.shield is not None:
            next_step = min(next_step, max(step + 1, self._decisions.next_step))
            turn = self.shield.next_change_step  # a backup's turn after its lead, before the next decision
            if turn is not None:
                next_step = min(next_step, max(step + 1, turn))
        return self._grant_rule.through_ms(
            t_ms,
            next_step,
            lambda tick_ms: self._gap_s(tick_ms) > self.cfg.hold_after_s,
            self._duration_over if self.cfg.duration_s is not None else None,
        )

    def _gap_s(self, t_ms: int) -> float:
        """Vehicle seconds from the last position fix to tick ``t_ms``, if no fix came in between."""
        return t_ms / 1000.0 - self.filter.last_measurement_t_s

    def _duration_over(self, t_ms: int) -> bool:
        """``--duration-s`` of flight is over at tick ``t_ms``."""
        assert self.fly_start_ms is not None
        return self.cfg.duration_s is not None and (t_ms - self.fly_start_ms) / 1000.0 >= self.cfg.duration_s

    def _decide(self, t_ms: int) -> tuple[Setpoint, str | None]:
        """The setpoint for vehicle time t_ms, and what is amiss (None if nothing is).

        Without the monitor, what is amiss is flown as the hold setpoint. With it, every tick after the first fix
        goes through the monitor: a non-finite action, or no action at all in a telemetry gap, is a proposal that
        never passes, so the remembered backup flies (as in the batched world)."""
        step = int(t_ms // self.dt_ms)
        if not self.filter.initialised:
            if self.shield is None:
                return HOLD, "no position fix yet"
            # Nothing to propose from, but the start is known: the monitor flies its backup from where the vehicle
            # is (the start flown through what was sent), as the start check admitted it to.
            return self._shielded(np.full(2, np.nan), step, lambda: self._start_reckoned(step)), "no position fix yet"
        self.filter.predict_to(t_ms / 1000.0)
        gap_s = self._gap_s(t_ms)
        if gap_s > self.cfg.hold_after_s:
            self._gap_seen = True
            gap = f"telemetry gap {gap_s:.1f} s"
            if self.shield is None:
                return HOLD, gap
            return self._shielded(np.full(2, np.nan), step), gap
        action = self.pilot.action(lambda: self._estimated_state(step), self.role_index, step)
        why: str | None = None
        if action.shape != (2,) or not (math.isfinite(action[0]) and math.isfinite(action[1])):
            self.counters.nonfinite_actions += 1
            why = "non-finite action"
            if self.shield is None:
                self.pilot.reset()
                return HOLD, why
            action = np.full(2, np.nan)
        self._gap_seen = False
        if self.shield is not None:
            return self._shielded(action, step), why
        return action_to_setpoint((float(action[0]), float(action[1])), self.spec), None

    def _estimated_state(self, step: int) -> WorldState:
        """The mission as the pilot sees it at tick ``step``: the layout, this vehicle at the filter's estimate, the
        flags the datalink told."""
        f = self.filter
        x_m, y_m = f.pos_m
        return self.layout_state.with_vehicle(
            self.role_index,
            x_m,
            y_m,
            f.speed_m_s,
            f.heading_rad,
            bool(self.flags.get(EventName.RADAR_ON)),
            bool(self.flags.get(EventName.IDENT)),
            step,
        )

    def _start_reckoned(self, step: int) -> Estimate:
        """Before the first fix: the scenario's start of this vehicle flown to tick ``step`` (its sigmas zero)."""
        assert self.shield is not None
        s, j = self.layout_state, self.role_index
        start = (float(s.x_m[0, j]), float(s.y_m[0, j]), float(s.v_m_s[0, j]), float(s.phi_rad[0, j]))
        return self.shield.dead_reckoned(start, step)

    def _shielded(self, proposed: np.ndarray, step: int, estimate: Callable[[], Estimate] | None = None) -> Setpoint:
        """The monitor's choice at each decision tick (held between them); a STATUSTEXT at each hand-over.

        Decision ticks are the pilot's grid, ticks 0, k, 2k, ... of the vehicle's clock (k = the pilot's
        ``repeat``; a tick skipped by a slow companion moves the decision to the next tick seen), whether or not
        the pilot was asked this tick."""
        assert self.shield is not None
        decision = self._decisions.due(step)
        action, text = self.shield.action(
            decision, self.pilot.repeat, proposed, estimate or self._monitor_estimate, step
        )
        if text is not None:
            _log.info("%s at %.1f s", text, (self.last_control_ms or 0) / 1000.0)
            self._say(M.MAV_SEVERITY_NOTICE, text)
        return action_to_setpoint((float(action[0]), float(action[1])), self.spec)

    def _monitor_estimate(self) -> Estimate:
        """What the monitor decides on: the filter's (x, y, v, phi), its sigmas of position (major axis), heading
        and speed, and its turn rate with its sigma (a filter without one: 0, as uncertain as the limit allows)."""
        f = self.filter
        x_m, y_m = f.pos_m
        rate, rate_sigma = f.turn_rate_rad_s, f.turn_rate_sigma_rad_s
        unknown = (0.0, math.radians(self.spec.turn_rate_max_deg_s))
        turn = unknown if rate is None or rate_sigma is None else (rate, rate_sigma)
        sigmas = (f.position_sigma_major_m, *f.speed_heading_sigma[::-1])
        return (x_m, y_m, f.speed_m_s, f.heading_rad), sigmas, turn

    def _hold_reason(self, why: str) -> None:
        """Count and say (once per spell) what is amiss: the hold flies without the monitor, its backup with it."""
        self.counters.holds += 1
        kind = why.split(" ")[0]
        if self._holding is None or self._holding.split(" ")[0] != kind:
            self.counters.hold_episodes += 1
            flown = "sending the hold setpoint" if self.shield is None else "the monitor's backup flies"
            _log.warning("%s: %s: %s", self.cfg.role.value, why, flown)
            said = "holding" if self.shield is None else "backup"
            self._say(M.MAV_SEVERITY_WARNING, f"{self.cfg.role.value}: {why}, {said}")
        self._holding = why

    def _check_silence(self, now: float) -> None:
        silent_s = now - self.last_rx_s
        if silent_s > self.cfg.lost_after_s:
            raise _Stop("lost", f"no message from the vehicle for {silent_s:.1f} s")
        if self.phase is not Phase.FLY or self._extrapolating():
            return
        if silent_s > self.cfg.silence_hold_s and now - self._last_silence_hold_s >= 1.0:
            self._last_silence_hold_s = now
            self._gap_seen = True
            self._hold_reason(f"link silent {silent_s:.1f} s")
            link = self._link
            assert link is not None
            # With the monitor the vehicle is sent again the command the monitor chose for this tick (a new one
            # could start nowhere the monitor checked); without it, the hold.
            sp = HOLD if self.shield is None else action_to_setpoint(tuple(self.shield.held), self.spec)
            self._send_setpoint(self.vt_ms or 0, sp, None)

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
            vehicle_time_s=None if self.vt_ms is None else self.vt_ms / 1000.0,
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
            shield=None if self.shield is None else asdict(self.shield.counters),
            write_error=None if link is None else link.tlog_error,
        )
