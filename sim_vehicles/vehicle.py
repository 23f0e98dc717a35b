"""One SITL vehicle: an autopilot's MAVLink behaviour around one UAV of the world.

The vehicle owns its :class:`~sim_vehicles.mavlink_io.MavEndpoint` (socket, framing, signing), two
:class:`~sim_vehicles.link.LinkChannel` (datalink out and in) and a
:class:`~sim_vehicles.link.GpsReceiver`. It never moves itself: the runner
(:mod:`sim_vehicles.world_runner`) asks it for its action (:meth:`Vehicle.action`), steps the world,
hands it the new true state (:meth:`Vehicle.observe`) and lets it publish (:meth:`Vehicle.publish`).

Modes (ArduPlane's numbers, only these two; any other mode is refused with MAV_RESULT_DENIED):

* MANUAL (0): our idle mode, hold heading and speed (action 0, 0). The vehicles are airborne from
  the first step, so this — not a runway — is where they start.
* GUIDED (15): fly the companion's setpoints, when armed.

Disarmed, the vehicle also holds heading and speed; arming is always accepted (``param2 = 21196``
forces it, as in ArduPilot, though nothing here needs forcing).

Setpoints: SET_POSITION_TARGET_LOCAL_NED, frame MAV_FRAME_BODY_FRD (12) or MAV_FRAME_BODY_NED (8),
``type_mask`` :data:`SETPOINT_TYPE_MASK` = 1087 (ignore x, y, z, vx, vy, vz and yaw; use afx and
yaw_rate; the afy / afz ignore bits 128 / 256 may be set too — their values are never used):

* ``afx``: forward (longitudinal) acceleration, m/s^2 = the world's u; clipped to the vehicle's
  ``accel_max_m_s2``;
* ``yaw_rate``: rad/s, NED, clockwise-positive (a right turn is positive); the world's omega is
  CCW-positive, so omega = -yaw_rate; clipped to ``turn_rate_max``.

The world's action is then (omega / turn_rate_max, u / accel_max) in [-1, 1]. The latest setpoint is
flown until replaced. Setpoints are obeyed only armed in GUIDED; otherwise they are ignored and
counted, with one STATUSTEXT per arming / mode state. Setpoints with another frame or mask, or with
non-finite values, are rejected and counted (one STATUSTEXT each kind).

Failsafe: armed in GUIDED with no setpoint for ``GUID_TIMEOUT`` seconds of simulated time (default
``--setpoint-timeout-s`` = 1.0): hold heading and speed, STATUSTEXT, ``system_status`` CRITICAL in
the HEARTBEAT, until the next setpoint arrives.
"""

from __future__ import annotations

import enum
import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sim_vehicles import telemetry
from sim_vehicles.events import EventKind, MissionEvent, MissionFlags
from sim_vehicles.link import GpsFix, GpsReceiver, LinkChannel
from sim_vehicles.mavlink_io import Address, MavEndpoint
from sim_vehicles.params import ParamTable, vehicle_params
from sim_vehicles.telemetry import VehicleTruth
from tssac_core.sim.scenario import LinkModel, Origin

_log = logging.getLogger(__name__)

COMPONENT_ID = 1
"""MAV_COMP_ID_AUTOPILOT1."""
FORCE_MAGIC = 21196
"""COMPONENT_ARM_DISARM param2 that forces arming / disarming."""

_TM = mavlink2
SETPOINT_TYPE_MASK = (
    _TM.POSITION_TARGET_TYPEMASK_X_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | _TM.POSITION_TARGET_TYPEMASK_YAW_IGNORE
)
"""1087: the bits that must be set (positions, velocities and yaw ignored)."""
_MASK_OPTIONAL = _TM.POSITION_TARGET_TYPEMASK_AY_IGNORE | _TM.POSITION_TARGET_TYPEMASK_AZ_IGNORE
SETPOINT_FRAMES = frozenset({_TM.MAV_FRAME_BODY_FRD, _TM.MAV_FRAME_BODY_NED})

_EPS_S = 1e-6
COALESCE_BYTES = 1200
"""Largest datagram :meth:`Vehicle.flush` builds from several frames (below any path MTU on a LAN)."""
M = mavlink2  # message ids and enums

DEFAULT_INTERVALS_S: dict[int, float | None] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.1,
    M.MAVLINK_MSG_ID_ATTITUDE: 0.1,
    M.MAVLINK_MSG_ID_VFR_HUD: 0.1,
    M.MAVLINK_MSG_ID_NAMED_VALUE_INT: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: None,
}
"""Default stream intervals in simulated seconds (None = off); SET_MESSAGE_INTERVAL changes them."""
GPS_GATED = frozenset({M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED})
"""Streams that carry a GPS fix: sent when due *and* a fix newer than the last one sent exists."""
REQUESTABLE = frozenset(DEFAULT_INTERVALS_S) | {M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN}
"""Message ids MAV_CMD_REQUEST_MESSAGE can ask for."""


class FlightMode(enum.IntEnum):
    """custom_mode values (ArduPlane's numbering)."""

    MANUAL = 0
    GUIDED = 15


@dataclass
class Clock:
    """Times the runner keeps and its vehicles read."""

    sim_s: float = 0.0
    """Simulated time (s since boot)."""
    link_s: float = 0.0
    """The link models' clock (see :mod:`sim_vehicles.link`)."""
    wall_s: float = 0.0
    """time.monotonic() of the current loop iteration."""
    unix_start_s: float = 0.0
    """Unix time of simulated time 0 (SYSTEM_TIME, tlog timestamps)."""

    @property
    def time_boot_ms(self) -> int:
        return int(round(self.sim_s * 1000.0))


@dataclass(frozen=True)
class VehicleSetup:
    """What a vehicle needs to know about itself and its world."""

    index: int
    """Position in ROLES (0 decoy, 1 detect, 2 strike)."""
    role: str
    sysid: int
    turn_rate_max_rad_s: float
    accel_max_m_s2: float
    speed_min_m_s: float
    speed_max_m_s: float
    dt_s: float
    origin: Origin
    home_east_m: float
    home_north_m: float
    link: LinkModel
    setpoint_timeout_s: float


@dataclass(frozen=True)
class Setpoint:
    """The setpoint being flown (already clipped to the limits)."""

    yaw_rate_rad_s: float
    """NED, clockwise-positive."""
    accel_m_s2: float
    """Forward."""
    time_s: float
    """Simulated time it arrived."""


@dataclass
class VehicleCounters:
    """Protocol-level counts (link and framing counts live in the endpoint and channels)."""

    setpoints_accepted: int = 0
    setpoints_ignored: int = 0
    """Valid setpoints that arrived while not armed in GUIDED."""
    setpoints_rejected: int = 0
    """Setpoints with an unsupported frame or type_mask, or non-finite values."""
    commands: int = 0
    commands_unsupported: int = 0
    not_for_us: int = 0
    """Messages addressed to another system or component."""
    failsafes: int = 0
    handler_errors: int = 0
    """Messages whose handler raised (a bug: logged with its traceback)."""


@dataclass
class _Stream:
    interval_s: float | None
    next_due_s: float = 0.0
    last_fix_s: float = -math.inf


@dataclass
class VehicleRngs:
    """The vehicle's random streams (seeded by the runner)."""

    tx: np.random.Generator
    rx: np.random.Generator
    gps: np.random.Generator


EventSink = Callable[[str, str, int], None]
"""(role, event name, value) -> None: arming, mode and failsafe changes for the truth log."""


class Vehicle:
    """One autopilot (see the module docstring)."""

    def __init__(
        self,
        setup: VehicleSetup,
        endpoint: MavEndpoint,
        clock: Clock,
        flags: MissionFlags,
        rngs: VehicleRngs,
        tlog: BinaryIO | None = None,
        on_event: EventSink | None = None,
    ) -> None:
        self.setup = setup
        self.index = setup.index
        self.role = setup.role
        self.sysid = setup.sysid
        self.compid = COMPONENT_ID
        self.endpoint = endpoint
        self.clock = clock
        self.flags = flags
        self.tx: LinkChannel[tuple[bytes, Address | None]] = LinkChannel(setup.link, rngs.tx)
        self.rx: LinkChannel[tuple[bytes, Address]] = LinkChannel(setup.link, rngs.rx)
        self.gps = GpsReceiver(setup.link, rngs.gps)
        self.params: ParamTable = vehicle_params(
            setup.sysid,
            setup.setpoint_timeout_s,
            setup.dt_s,
            math.degrees(setup.turn_rate_max_rad_s),
            setup.accel_max_m_s2,
            setup.speed_min_m_s,
            setup.speed_max_m_s,
        )
        self.counters = VehicleCounters()
        self._tlog = tlog
        self._on_event = on_event
        self.armed = False
        self.mode = FlightMode.MANUAL
        self.failsafe = False
        self.fence_breached = False
        self.setpoint: Setpoint | None = None
        self.last_setpoint_s = 0.0
        self.loop_since_wall_s = 0.0
        """Wall time the vehicle last came under companion control (for the lockstep barrier)."""
        self._credit_ms = -1
        self.last_action = (0.0, 0.0)
        self.truth = VehicleTruth(setup.home_east_m, setup.home_north_m, setup.speed_min_m_s, 0.0, 0.0, 0.0)
        self._streams = {mid: _Stream(iv) for mid, iv in DEFAULT_INTERVALS_S.items()}
        self._warned_ignored = False
        self._warned_rejected: set[str] = set()
        self._handlers: dict[str, Callable[[mavlink2.MAVLink_message, Address], None]] = {
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_MODE": self._on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "MISSION_COUNT": self._on_mission_upload,
            "MISSION_CLEAR_ALL": self._on_mission_clear_all,
            "TIMESYNC": self._on_timesync,
        }
        self._commands: dict[int, Callable[[tuple[float, ...]], tuple[int, list[mavlink2.MAVLink_message]]]] = {
            M.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            M.MAV_CMD_DO_SET_MODE: self._cmd_do_set_mode,
            M.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_capabilities,
            M.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
        }

    # ------------------------------------------------------------------------------ properties

    @property
    def mav(self) -> mavlink2.MAVLink:
        return self.endpoint.mav

    @property
    def guided(self) -> bool:
        return self.mode is FlightMode.GUIDED

    @property
    def setpoint_timeout_s(self) -> float:
        p = self.params.get("GUID_TIMEOUT")
        assert p is not None
        return p.value

    @property
    def in_loop(self) -> bool:
        """Under companion control: armed in GUIDED and not in failsafe (the lockstep barrier waits for it)."""
        return self.armed and self.guided and not self.failsafe

    def ready_for(self, time_boot_ms: int) -> bool:
        """A setpoint stamped for (or unstamped and received at) the step at ``time_boot_ms`` has arrived."""
        return self._credit_ms >= time_boot_ms

    @property
    def system_status(self) -> int:
        if self.failsafe:
            return M.MAV_STATE_CRITICAL
        return M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY

    # ------------------------------------------------------------------------------- datalink

    def poll_socket(self) -> None:
        """Move waiting datagrams from the socket into the incoming link channel."""
        self.endpoint.expire_peers(self.clock.wall_s)
        for data, addr in self.endpoint.receive():
            self.rx.push(self.clock.link_s, (data, addr))

    def process_incoming(self) -> None:
        """Parse and handle the datagrams the incoming channel delivers now."""
        for data, addr in self.rx.pop_due(self.clock.link_s):
            new_peer = addr not in self.endpoint.peers
            msgs = self.endpoint.parse(data, addr)
            if msgs and new_peer:
                self.send_snapshot(addr)
            for msg in msgs:
                if self._tlog is not None:
                    self._write_tlog(bytes(msg.get_msgbuf()))
                self._handle(msg, addr)

    def flush(self) -> None:
        """Send the frames the outgoing channel delivers now, packed into datagrams per destination.

        Frames released together for the same destination share one datagram (in order, up to
        COALESCE_BYTES), as a flight controller's UDP output does: one system call per destination and
        step instead of one per message. Loss, duplication and latency still act on every frame.
        """
        batches: dict[Address | None, list[bytes]] = {}
        for data, dest in self.tx.pop_due(self.clock.link_s):
            frames = batches.setdefault(dest, [])
            if frames and len(frames[-1]) + len(data) <= COALESCE_BYTES:
                frames[-1] += data
            else:
                frames.append(bytes(data))
        for dest, frames in batches.items():
            for datagram in frames:
                self.endpoint.sendto(datagram, dest)

    def next_link_due_s(self) -> float | None:
        """Link time at which a channel next has something to deliver."""
        times = [t for t in (self.tx.next_due_s(), self.rx.next_due_s()) if t is not None]
        return min(times) if times else None

    def _send(self, msg: mavlink2.MAVLink_message, dest: Address | None = None) -> None:
        if dest is None and not self.endpoint.peers:
            return
        buf = self.endpoint.encode(msg)
        if self._tlog is not None:
            self._write_tlog(buf)
        self.tx.push(self.clock.link_s, (buf, dest))

    def _write_tlog(self, frame: bytes) -> None:
        assert self._tlog is not None
        stamp_us = int(round((self.clock.unix_start_s + self.clock.sim_s) * 1e6))
        self._tlog.write(struct.pack(">Q", stamp_us) + frame)

    # ------------------------------------------------------------------------------- physics

    def action(self) -> tuple[float, float]:
        """The world action [omega, u] in [-1, 1] for the next step (checks the setpoint timeout first)."""
        now = self.clock.sim_s
        if self.in_loop and now - self.last_setpoint_s > self.setpoint_timeout_s + _EPS_S:
            self.enter_failsafe(f"no setpoint for {self.setpoint_timeout_s:g} s")
        sp = self.setpoint
        if self.in_loop and sp is not None:
            a = (-sp.yaw_rate_rad_s / self.setup.turn_rate_max_rad_s, sp.accel_m_s2 / self.setup.accel_max_m_s2)
        else:
            a = (0.0, 0.0)
        self.last_action = a
        return a

    def observe(self, truth: VehicleTruth) -> None:
        """The true state after a world step (or at reset)."""
        self.truth = truth

    def enter_failsafe(self, reason: str) -> None:
        """Hold heading and speed until the next setpoint; CRITICAL in the heartbeat."""
        if self.failsafe:
            return
        self.failsafe = True
        self.counters.failsafes += 1
        _log.warning("%s: failsafe: %s", self.role, reason)
        self._statustext(M.MAV_SEVERITY_WARNING, f"Failsafe: {reason}, holding")
        self._event("FAILSAFE", 1)

    def _clear_failsafe(self) -> None:
        self.failsafe = False
        self.loop_since_wall_s = self.clock.wall_s
        self._statustext(M.MAV_SEVERITY_INFO, "Failsafe cleared: setpoints resumed")
        self._event("FAILSAFE", 0)

    # ----------------------------------------------------------------------------- telemetry

    def publish(self, tick: bool = False) -> None:
        """After a step: take a GPS fix if one is due and send every stream that is due.

        ``tick`` (lockstep): also send SYSTEM_TIME now if its stream did not, so clients see every step.
        """
        now = self.clock.sim_s
        t = self.truth
        self.gps.sample(now, t.east_m, t.north_m, t.vel_east_m_s, t.vel_north_m_s)
        time_sent = False
        for mid, stream in self._streams.items():
            if stream.interval_s is None or now + _EPS_S < stream.next_due_s:
                continue
            if mid in GPS_GATED:
                fix = self.gps.last_fix
                if fix is None or fix.time_s <= stream.last_fix_s:
                    continue  # stays due until a fresh fix arrives
                stream.last_fix_s = fix.time_s
            if self.endpoint.peers:
                for msg in self._build(mid):
                    self._send(msg)
            nxt = stream.next_due_s + stream.interval_s
            stream.next_due_s = nxt if nxt > now + _EPS_S else now + stream.interval_s
            time_sent = time_sent or mid == M.MAVLINK_MSG_ID_SYSTEM_TIME
        if tick and not time_sent:
            self._send(telemetry.system_time(self.mav, self.clock.unix_start_s, now))

    def send_snapshot(self, dest: Address | None = None) -> None:
        """The current state at once (a new peer; a lockstep world holding still): heartbeat, status, flags, position."""
        for mid in (
            M.MAVLINK_MSG_ID_HEARTBEAT,
            M.MAVLINK_MSG_ID_SYS_STATUS,
            M.MAVLINK_MSG_ID_SYSTEM_TIME,
            M.MAVLINK_MSG_ID_NAMED_VALUE_INT,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
            M.MAVLINK_MSG_ID_ATTITUDE,
            M.MAVLINK_MSG_ID_VFR_HUD,
        ):
            for msg in self._build(mid):
                self._send(msg, dest)

    def announce(self, event: MissionEvent) -> None:
        """A mission event as STATUSTEXT + NAMED_VALUE_INT to every peer."""
        if event.kind is EventKind.GEOFENCE and event.vehicle == self.index:
            self.fence_breached = True
        severity, text = event.statustext()
        self._send(telemetry.statustext(self.mav, severity, text))
        self._send(telemetry.named_value_int(self.mav, int(round(event.time_s * 1000.0)), event.kind.value_name, event.value))

    def _build(self, mid: int) -> list[mavlink2.MAVLink_message]:
        """The message(s) of one id for the current state ([] if there is nothing to say, e.g. no fix yet)."""
        mav, now, t, o = self.mav, self.clock.sim_s, self.truth, self.setup.origin
        ms = self.clock.time_boot_ms
        fix: GpsFix | None = self.gps.last_fix
        if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            return [telemetry.heartbeat(mav, self.armed, int(self.mode), self.guided, self.system_status)]
        if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
            return [telemetry.sys_status(mav, self.gps.has_fix(now), not self.fence_breached, self.endpoint.rx.rejected)]
        if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return [telemetry.system_time(mav, self.clock.unix_start_s, now)]
        if mid == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            lk = self.setup.link
            return [telemetry.gps_raw_int(mav, o, fix, self.gps.has_fix(now), ms, lk.gps_position_sigma_m, lk.gps_velocity_sigma_m_s)]
        if mid == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return [] if fix is None else [telemetry.global_position_int(mav, o, fix, t.phi_rad)]
        if mid == M.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return [] if fix is None else [telemetry.local_position_ned(mav, fix)]
        if mid == M.MAVLINK_MSG_ID_ATTITUDE:
            return [telemetry.attitude(mav, t, ms)]
        if mid == M.MAVLINK_MSG_ID_VFR_HUD:
            return [telemetry.vfr_hud(mav, t, o.alt_m, self.last_action[1])]
        if mid == M.MAVLINK_MSG_ID_NAMED_VALUE_INT:
            return [telemetry.named_value_int(mav, ms, name, value) for name, value in self.flags.named_values()]
        if mid == M.MAVLINK_MSG_ID_HOME_POSITION:
            return [telemetry.home_position(mav, o, self.setup.home_east_m, self.setup.home_north_m, now)]
        if mid == M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
            return [telemetry.gps_global_origin(mav, o, now)]
        if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return [telemetry.autopilot_version(mav, self.sysid)]
        return []

    def _statustext(self, severity: int, text: str, dest: Address | None = None) -> None:
        self._send(telemetry.statustext(self.mav, severity, text), dest)

    def _event(self, name: str, value: int) -> None:
        if self._on_event is not None:
            self._on_event(self.role, name, value)

    # ------------------------------------------------------------------------------ incoming

    def _handle(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        target_system = getattr(msg, "target_system", 0)
        target_component = getattr(msg, "target_component", 0)
        if target_system not in (0, self.sysid) or target_component not in (0, self.compid):
            self.counters.not_for_us += 1
            return
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            return
        try:
            handler(msg, addr)
        except Exception:
            # A bug reached by some field value must not take the vehicle (and the world) down.
            self.counters.handler_errors += 1
            _log.exception("%s: handling %s failed", self.role, msg.get_type())

    def _on_command_long(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(msg.command, params, msg, addr)

    def _on_command_int(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(msg.command, params, msg, addr)

    def _command(self, command: int, params: tuple[float, ...], msg: mavlink2.MAVLink_message, addr: Address) -> None:
        """Run a command and answer it with a COMMAND_ACK (always), then any messages it produced."""
        self.counters.commands += 1
        handler = self._commands.get(command)
        if handler is None:
            self.counters.commands_unsupported += 1
            result, replies = M.MAV_RESULT_UNSUPPORTED, []
        else:
            result, replies = handler(params)
        ack = self.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        self._send(ack, addr)
        for reply in replies:
            self._send(reply, addr)

    def _cmd_arm_disarm(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        if abs(p[0] - 1.0) < 1e-3:
            if not self.armed:
                self._set_armed(True)
            return M.MAV_RESULT_ACCEPTED, []
        if abs(p[0]) < 1e-3:
            if self.armed:
                self._set_armed(False)
            return M.MAV_RESULT_ACCEPTED, []
        return M.MAV_RESULT_DENIED, []

    def _cmd_do_set_mode(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        if not (math.isfinite(p[0]) and math.isfinite(p[1])):
            return M.MAV_RESULT_DENIED, []
        return self._set_mode(int(round(p[0])), int(round(p[1]))), []

    def _on_set_mode(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        # ArduPilot answers the SET_MODE message with a COMMAND_ACK whose command is the message id (11).
        result = self._set_mode(msg.base_mode, msg.custom_mode)
        self._send(self.mav.command_ack_encode(M.MAVLINK_MSG_ID_SET_MODE, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), addr)

    def _set_mode(self, base_mode: int, custom_mode: int) -> int:
        if not base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self._statustext(M.MAV_SEVERITY_WARNING, "Set mode: base_mode needs CUSTOM_MODE_ENABLED")
            return M.MAV_RESULT_DENIED
        try:
            mode = FlightMode(custom_mode)
        except ValueError:
            self._statustext(M.MAV_SEVERITY_WARNING, f"Mode {custom_mode} unsupported: MANUAL=0 GUIDED=15")
            return M.MAV_RESULT_DENIED
        if mode is not self.mode:
            was_in_loop = self.in_loop
            self.mode = mode
            self.setpoint = None
            self.failsafe = False
            self._warned_ignored = False
            self._enter_loop_if(was_in_loop)
            _log.info("%s: mode %s", self.role, mode.name)
            self._event("MODE", int(mode))
        return M.MAV_RESULT_ACCEPTED

    def _set_armed(self, armed: bool) -> None:
        was_in_loop = self.in_loop
        self.armed = armed
        self.setpoint = None
        self.failsafe = False
        self._warned_ignored = False
        self._enter_loop_if(was_in_loop)
        _log.info("%s: %s", self.role, "armed" if armed else "disarmed")
        self._event("ARMED", int(armed))

    def _enter_loop_if(self, was_in_loop: bool) -> None:
        if self.in_loop and not was_in_loop:
            # The setpoint timeout runs from the moment the companion takes control.
            self.last_setpoint_s = self.clock.sim_s
            self.loop_since_wall_s = self.clock.wall_s

    def _cmd_request_message(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        mid = int(p[0]) if math.isfinite(p[0]) else -1
        if mid not in REQUESTABLE:
            return M.MAV_RESULT_UNSUPPORTED, []
        msgs = self._build(mid)
        return (M.MAV_RESULT_ACCEPTED, msgs) if msgs else (M.MAV_RESULT_FAILED, [])

    def _cmd_request_capabilities(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        return M.MAV_RESULT_ACCEPTED, self._build(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _cmd_set_message_interval(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        mid = int(p[0]) if math.isfinite(p[0]) else -1
        stream = self._streams.get(mid)
        if stream is None:
            return M.MAV_RESULT_UNSUPPORTED, []
        interval_us = p[1]
        if interval_us == -1:
            stream.interval_s = None
        elif interval_us == 0:
            stream.interval_s = DEFAULT_INTERVALS_S[mid]
        elif interval_us > 0 and math.isfinite(interval_us):
            stream.interval_s = interval_us / 1e6
        else:
            return M.MAV_RESULT_DENIED, []
        stream.next_due_s = self.clock.sim_s
        return M.MAV_RESULT_ACCEPTED, []

    def _cmd_get_message_interval(self, p: tuple[float, ...]) -> tuple[int, list[mavlink2.MAVLink_message]]:
        mid = int(p[0]) if math.isfinite(p[0]) else -1
        stream = self._streams.get(mid)
        if stream is None:
            return M.MAV_RESULT_UNSUPPORTED, []
        interval_us = -1 if stream.interval_s is None else int(round(stream.interval_s * 1e6))
        return M.MAV_RESULT_ACCEPTED, [self.mav.message_interval_encode(mid, interval_us)]

    def _on_setpoint(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        problem = None
        if msg.coordinate_frame not in SETPOINT_FRAMES:
            problem = f"frame {msg.coordinate_frame} unsupported: use 12 (BODY_FRD)"
        elif (msg.type_mask & ~_MASK_OPTIONAL) != SETPOINT_TYPE_MASK:
            problem = f"type_mask {msg.type_mask} unsupported: use {SETPOINT_TYPE_MASK}"
        elif not (math.isfinite(msg.afx) and math.isfinite(msg.yaw_rate)):
            problem = "afx / yaw_rate not finite"
        if problem is not None:
            self.counters.setpoints_rejected += 1
            kind = problem.split(" ", 1)[0]
            if kind not in self._warned_rejected:
                self._warned_rejected.add(kind)
                self._statustext(M.MAV_SEVERITY_WARNING, f"Setpoint rejected: {problem}")
            return
        if not (self.armed and self.guided):
            self.counters.setpoints_ignored += 1
            if not self._warned_ignored:
                self._warned_ignored = True
                self._statustext(M.MAV_SEVERITY_WARNING, "Setpoint ignored: not armed in GUIDED")
            return
        limit_w, limit_a = self.setup.turn_rate_max_rad_s, self.setup.accel_max_m_s2
        now = self.clock.sim_s
        self.setpoint = Setpoint(
            yaw_rate_rad_s=min(limit_w, max(-limit_w, float(msg.yaw_rate))),
            accel_m_s2=min(limit_a, max(-limit_a, float(msg.afx))),
            time_s=now,
        )
        self.last_setpoint_s = now
        self.counters.setpoints_accepted += 1
        current_ms = self.clock.time_boot_ms
        stamp = msg.time_boot_ms
        self._credit_ms = max(self._credit_ms, current_ms if stamp == 0 else min(stamp, current_ms))
        if self.failsafe:
            self._clear_failsafe()

    # ---------------------------------------------------------------------------- parameters

    def _param_value(self, index: int) -> mavlink2.MAVLink_message:
        p = self.params.at(index)
        assert p is not None
        return self.mav.param_value_encode(p.name.encode("ascii"), p.value, p.param_type, len(self.params), index)

    def _on_param_request_list(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        for i in range(len(self.params)):
            self._send(self._param_value(i), addr)

    def _on_param_request_read(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        index = msg.param_index if msg.param_index >= 0 else self.params.index(msg.param_id)
        if index is None or self.params.at(index) is None:
            _log.info("%s: PARAM_REQUEST_READ of unknown parameter %r / %d", self.role, msg.param_id, msg.param_index)
            return
        self._send(self._param_value(index), addr)

    def _on_param_set(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        index = self.params.index(msg.param_id)
        if index is None:
            _log.info("%s: PARAM_SET of unknown parameter %r", self.role, msg.param_id)
            return
        refused = self.params.set(msg.param_id, float(msg.param_value))
        if refused is not None:
            self._statustext(M.MAV_SEVERITY_WARNING, f"Param refused: {refused}", addr)
            self._send(self._param_value(index), addr)
            return
        self._send(self._param_value(index))  # a changed value goes to every client

    # ------------------------------------------------------------------------ mission, time

    def _on_mission_request_list(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        # No mission, fence or rally items: ground stations ask on connect and wait for an answer.
        self._send(self.mav.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type), addr)

    def _on_mission_upload(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        self._send(self.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_UNSUPPORTED, msg.mission_type), addr)

    def _on_mission_clear_all(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        self._send(self.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED, msg.mission_type), addr)

    def _on_timesync(self, msg: mavlink2.MAVLink_message, addr: Address) -> None:
        if msg.tc1 == 0:  # a request; answer with our (simulated) clock in ns
            self._send(self.mav.timesync_encode(int(round(self.clock.sim_s * 1e9)), msg.ts1), addr)

