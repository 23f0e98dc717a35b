"""One SITL vehicle's state: an autopilot around one UAV of the world.

The vehicle owns its :class:`~sim_vehicles.mavlink_io.MavEndpoint` (socket, framing, signing), two
:class:`~sim_vehicles.link_model.LinkChannel` (datalink out and in) and a
:class:`~sim_vehicles.link_model.GpsReceiver`. It never moves itself: the runner
(:mod:`sim_vehicles.world_runner`) asks it for its action (:meth:`Vehicle.action`), steps the world,
hands it the new true state (:meth:`Vehicle.observe`) and lets it publish (:meth:`Vehicle.publish`).

What arrives from clients is handled by the :class:`MessageHandler` the runner attaches,
:class:`sim_vehicles.commands.CommandHandler` (commands, modes, setpoints, parameters, missions, FTP),
which imports this module and not the other way round; it changes this state only through the methods here
(:meth:`Vehicle.set_mode`, :meth:`Vehicle.set_armed`, :meth:`Vehicle.fly_demand`, ...).

* Modes (:mod:`sim_vehicles.modes`, ArduPlane's numbers): MANUAL holds heading and speed; GUIDED
  flies setpoints; LOITER, CIRCLE and RTL steer by themselves (:mod:`sim_vehicles.navigation`) while
  armed. Disarmed, the vehicle holds heading and speed (it is airborne from the first step).
* Setpoints (:mod:`sim_vehicles.setpoints`): the companion's acceleration + yaw rate, MAVSDK's
  forward speed + yaw rate, or SET_ATTITUDE_TARGET's thrust + yaw rate; obeyed only armed in
  GUIDED. The world's action is (omega / turn_rate_max, u / accel_max) in [-1, 1], omega = -yaw_rate.
* FlownSetpoint-timeout failsafe: armed in GUIDED with no setpoint for ``GUID_TIMEOUT`` simulated seconds,
  hold heading and speed (STATUSTEXT, ``system_status`` CRITICAL) until the next setpoint.
* Datalink failsafe (ArduPlane's ``FS_GCS_ENABL``, ``FS_LONG_TIMEOUT``, ``FS_LONG_ACTN``): armed, with
  the failsafe enabled, and no valid message from any client for ``FS_LONG_TIMEOUT`` wall seconds
  after one was heard: RTL (from MANUAL always, from GUIDED when ``FS_LONG_ACTN`` is 1).
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import BinaryIO, Protocol

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles import navigation, telemetry
from sim_vehicles.events import EventKind, MissionEvent, WorldFlags
from sim_vehicles.link_model import GpsFix, GpsReceiver, LinkChannel
from sim_vehicles.mavlink_io import Address, MavEndpoint, Parsed, Sender
from sim_vehicles.modes import AUTONOMOUS, FlightMode
from sim_vehicles.params import ParamTable, vehicle_params
from sim_vehicles.setpoints import Demand, Refusal, accel_command, parse_attitude_target, parse_position_target
from sim_vehicles.telemetry import VehicleTruth
from tssac_core.sim.scenario import LinkModel, Origin

_log = logging.getLogger(__name__)

COMPONENT_ID = 1
"""MAV_COMP_ID_AUTOPILOT1."""
FORCE_MAGIC = 21196
"""COMPONENT_ARM_DISARM param2 that forces arming / disarming."""

_EPS_S = 1e-6
COALESCE_BYTES = 1200
GOTO_UNDO_S = 5.0
"""A goto refused within this many wall seconds of the switch to GUIDED made for it undoes the switch."""
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
    M.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
}
"""Default stream intervals in simulated seconds (None = off); SET_MESSAGE_INTERVAL changes them."""
MAX_INTERVAL_US = 2**31 - 1
"""Longest stream interval SET_MESSAGE_INTERVAL accepts (~36 min): MESSAGE_INTERVAL.interval_us is an int32."""
GPS_GATED = frozenset({M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED})
"""Streams that carry a GPS fix: sent when due *and* a fix newer than the last one sent exists."""
REQUESTABLE = frozenset(DEFAULT_INTERVALS_S) | {M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN}
"""Message ids MAV_CMD_REQUEST_MESSAGE can ask for."""


@dataclass
class Clock:
    """Times the runner keeps and its vehicles read."""

    sim_s: float = 0.0
    """Simulated time (s since boot)."""
    link_s: float = 0.0
    """The link models' clock (see :mod:`sim_vehicles.link_model`)."""
    wall_s: float = 0.0
    """time.monotonic() of the current loop iteration."""
    unix_start_s: float = 0.0
    """Unix time of simulated time 0 (SYSTEM_TIME, tlog timestamps)."""
    lockstep: bool = False
    """The world runs in lockstep: every SYSTEM_TIME is a step tick, delayed by the link but never lost."""

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
class FlownSetpoint:
    """The setpoint being flown."""

    demand: Demand
    """What it asks for (limits are applied at each step, see :meth:`Vehicle.action`)."""
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
    datalink_failsafes: int = 0
    refusal_texts_suppressed: int = 0
    """Refusal STATUSTEXTs not sent because the same kind went out less than REFUSAL_INTERVAL_S ago."""
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


@dataclass
class Orbit:
    """The circle an autonomous mode flies (world frame, metres)."""

    center: tuple[float, float] | None
    """None: CIRCLE's constant turn without a centre."""
    radius_m: float
    ccw: bool = False


@dataclass
class DatalinkWatch:
    """When a client was last heard (wall clock), for the datalink failsafe."""

    last_heard_wall_s: float | None = None
    """None until the first valid message from any client."""
    lost: bool = False


@dataclass
class RefusalLimiter:
    """A refusal STATUSTEXT of each kind at most every ``interval_s`` wall seconds (not once per kind)."""

    interval_s: float
    last_wall_s: dict[str, float] = field(default_factory=dict)

    def allow(self, kind: str, now_wall_s: float) -> bool:
        last = self.last_wall_s.get(kind)
        if last is not None and now_wall_s - last < self.interval_s:
            return False
        self.last_wall_s[kind] = now_wall_s
        return True

    def forget(self, kind: str) -> None:
        self.last_wall_s.pop(kind, None)


REFUSAL_INTERVAL_S = 1.0
"""A refused setpoint stream (20 Hz from MAVSDK) gets one STATUSTEXT per second."""


class MessageHandler(Protocol):
    """The incoming side of a vehicle: reads a client's message, answers it, changes the vehicle's state."""

    def handle(self, msg: mavlink2.MAVLink_message, addr: Address) -> None: ...


EventSink = Callable[..., None]
"""(role, event name, value) -> None: arming, mode and failsafe changes for the truth log."""


class Vehicle:
    """One autopilot (see the module docstring)."""

    def __init__(
        self,
        setup: VehicleSetup,
        endpoint: MavEndpoint,
        clock: Clock,
        flags: WorldFlags,
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
        self.tx: LinkChannel[tuple[bytes, Address, int]] = LinkChannel(setup.link, rngs.tx)
        """Frames out: (frame, destination or None for every client, the tick's time_boot_ms or -1)."""
        self.rx: LinkChannel[tuple[Parsed, Address]] = LinkChannel(setup.link, rngs.rx)
        """Datagrams in, already checked and decoded at the socket (see :meth:`poll_socket`)."""
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
        self.outputs: tuple[Address, ...] = ()
        """Ground-station addresses (``--out``) that get the stream from the start and are never forgotten."""
        self.counters = VehicleCounters()
        self._tlog = tlog
        self._on_event = on_event
        self.armed = False
        self.mode = FlightMode.MANUAL
        self.failsafe = False
        self.fence_breached = False
        self.setpoint: FlownSetpoint | None = None
        self._guided_from: tuple[FlightMode, float] | None = None
        """(the mode before GUIDED, wall time of the switch) while in GUIDED: a refused goto undoes the switch."""
        self.last_setpoint_s = 0.0
        self.loop_since_wall_s = 0.0
        """Wall time the vehicle last came under companion control (for the lockstep barrier)."""
        self._credit_ms = -1
        """Newest step a client has answered with a setpoint (at the socket, before the link model)."""
        self.tick_seen_ms = -1
        """Newest step tick (SYSTEM_TIME) the datalink has delivered to the clients."""
        self._entry_credit_ms = -1
        """The credit when the vehicle last came under companion control (it holds the world once it grows)."""
        self._sent_step_ms = -1
        self._sent_in_step: dict[int, int] = {}
        """Frames sent per message id at time _sent_step_ms: the occurrence part of their link-model key."""
        self._rx_setpoints: dict[int, int] = {}
        """Datagrams holding a setpoint, per stamp: the occurrence part of their link-model key."""
        self.last_action = (0.0, 0.0)
        self.truth = VehicleTruth(setup.home_east_m, setup.home_north_m, setup.speed_min_m_s, 0.0, 0.0, 0.0)
        self._streams = {mid: _Stream(iv) for mid, iv in DEFAULT_INTERVALS_S.items()}
        self.orbit: Orbit | None = None
        self.datalink = DatalinkWatch()
        self.refusals = RefusalLimiter(REFUSAL_INTERVAL_S)
        self.handler: MessageHandler | None = None
        """What handles incoming messages (:class:`sim_vehicles.commands.CommandHandler`, attached by the runner)."""

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

    @property
    def holds_world(self) -> bool:
        """Lockstep barrier member: in the loop, and its client has answered a tick since it took control.

        Until that first answer the world does not wait for it: the client may still be waiting for the
        COMMAND_ACK of the mode change, which a lossy, slow link delivers only as simulated time runs.
        """
        return self.in_loop and self._credit_ms > self._entry_credit_ms

    def answered(self) -> bool:
        """Lockstep: a client has answered the newest step tick the datalink delivered (see :meth:`poll_socket`)."""
        return self._credit_ms >= self.tick_seen_ms

    @property
    def system_status(self) -> int:
        """HEARTBEAT.system_status: POWEROFF once the mission has ended (the SITL exits after its linger: what a
        companion checks a mission end against), CRITICAL in a failsafe, else ACTIVE armed / STANDBY disarmed."""
        if self.flags.end is not None:
            return M.MAV_STATE_POWEROFF
        if self.failsafe or self.datalink.lost:
            return M.MAV_STATE_CRITICAL
        return M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY

    # ------------------------------------------------------------------------------- datalink

    def add_outputs(self, outputs: tuple[Address, ...]) -> None:
        """Ground stations (``--out``) that get every stream from the start and whose commands are taken."""
        self.outputs = tuple(outputs)
        for out in self.outputs:
            self.endpoint.peers.setdefault(out, self.clock.wall_s)

    def poll_socket(self) -> None:
        """Check and decode waiting datagrams and move them into the incoming link channel.

        Checking (signatures, replays) happens here, at the socket, so that the link model acts on
        messages: a setpoint the link then loses or delays still tells the lockstep barrier that its
        client has answered the step (:meth:`answered`). The vehicle flies the previous command until
        the setpoint arrives, or through the step if it never does, as a real vehicle would.
        """
        for out in self.outputs:  # --out ground stations are never forgotten
            self.endpoint.peers[out] = self.clock.wall_s
        self.endpoint.expire_peers(self.clock.wall_s)
        for data, addr in self.endpoint.receive():
            parsed = self.endpoint.parse(data, addr)
            if parsed.sender is None:
                continue  # nothing accepted: it never reaches the vehicle, and its sender is nobody
            key = None
            for msg in parsed.messages:
                if self._credit(msg):
                    stamp = int(msg.time_boot_ms)
                    if len(self._rx_setpoints) > 256:  # only recent stamps matter; clients may send any
                        self._rx_setpoints.clear()
                    n = self._rx_setpoints[stamp] = self._rx_setpoints.get(stamp, -1) + 1
                    key = hash((msg.get_msgId(), stamp, n))
            self.rx.push(self.clock.link_s, (parsed, addr), key)

    def process_incoming(self) -> None:
        """Handle the datagrams the incoming channel delivers now."""
        for parsed, addr in self.rx.pop_due(self.clock.link_s):
            if parsed.sender is Sender.CLIENT:  # an unsigned monitor keeps no datalink alive
                self._heard_client()
            assert parsed.sender is not None
            if self.endpoint.admit(addr, parsed.sender):
                self.send_snapshot(addr)
            for msg in parsed.messages:
                if self._tlog is not None:
                    self._write_tlog(bytes(msg.get_msgbuf()))
                assert self.handler is not None, "no message handler attached"
                self.handler.handle(msg, addr)

    def _credit(self, msg: mavlink2.MAVLink_message) -> bool:
        """A flyable setpoint for us credits the lockstep barrier with the step it answers (its stamp; 0 = now)."""
        mtype = msg.get_type()
        if mtype == "SET_POSITION_TARGET_LOCAL_NED":
            parsed = parse_position_target(msg)
        elif mtype == "SET_ATTITUDE_TARGET":
            parsed = parse_attitude_target(msg)
        else:
            return False
        if isinstance(parsed, Refusal):
            return False
        if msg.target_system not in (0, self.sysid) or msg.target_component not in (0, self.compid):
            return False
        stamp = int(msg.time_boot_ms)
        self._credit_ms = max(self._credit_ms, self.tick_seen_ms if stamp == 0 else min(stamp, self.clock.time_boot_ms))
        return True

    def flush(self) -> None:
        """Send the frames the outgoing channel delivers now, packed into datagrams per destination.

        Frames released together for the same destination share one datagram (in order, up to
        COALESCE_BYTES), as a flight controller's UDP output does: one system call per destination and
        step instead of one per message. Loss, duplication and latency still act on every frame.
        """
        batches: dict[Address, list[bytes]] = {}
        for data, dest, tick_ms in self.tx.pop_due(self.clock.link_s):
            self.tick_seen_ms = max(self.tick_seen_ms, tick_ms)
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

    def send(self, msg: mavlink2.MAVLink_message, dest: Address | None = None) -> None:
        """Queue one message for ``dest`` (None: every client and monitor) on the outgoing link.

        Each destination is a link of its own with its own sequence numbers (:meth:`MavEndpoint.encode`), taken
        in the order the frames are queued: a client never sees a gap for a frame that went to another one."""
        dests = [dest] if dest is not None else self.endpoint.destinations()
        if not dests:
            return
        # The link model's key names the frame (id, step, occurrence): its fate does not depend on other traffic.
        mid, now_ms = msg.get_msgId(), self.clock.time_boot_ms
        tick_ms = int(msg.time_boot_ms) if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME else -1
        if now_ms != self._sent_step_ms:
            self._sent_step_ms, self._sent_in_step = now_ms, {}
        n = self._sent_in_step[mid] = self._sent_in_step.get(mid, 0) + 1
        lossless = self.clock.lockstep and tick_ms >= 0
        for i, to in enumerate(dests):
            buf = self.endpoint.encode(msg, to)
            if i == 0 and self._tlog is not None:
                self._write_tlog(buf)  # one copy per message, as the vehicle sent it
            self.tx.push(self.clock.link_s, (buf, to, tick_ms), hash((mid, now_ms, n)), lossless)

    def _write_tlog(self, frame: bytes) -> None:
        assert self._tlog is not None
        stamp_us = int(round((self.clock.unix_start_s + self.clock.sim_s) * 1e6))
        self._tlog.write(struct.pack(">Q", stamp_us) + frame)

    # ------------------------------------------------------------------------------- physics

    def action(self) -> tuple[float, float]:
        """The world action [omega, u] in [-1, 1] for the next step (checks the failsafes first)."""
        now = self.clock.sim_s
        if self.in_loop and now - self.last_setpoint_s > self.setpoint_timeout_s + _EPS_S:
            self.enter_failsafe(f"no setpoint for {self.setpoint_timeout_s:g} s")
        self._check_datalink()
        omega, accel = self._command_now()
        su = self.setup
        a = (omega / su.turn_rate_max_rad_s, accel / su.accel_max_m_s2)
        self.last_action = a
        return a

    def _command_now(self) -> tuple[float, float]:
        """(omega CCW-positive rad/s, forward acceleration m/s^2) within the limits, for the current mode."""
        su, t = self.setup, self.truth
        sp = self.setpoint
        if self.in_loop and sp is not None:
            if sp.demand.course_rad is not None:
                omega = navigation.course_turn_rate(t.phi_rad, sp.demand.course_rad, su.turn_rate_max_rad_s)
            else:
                omega = min(su.turn_rate_max_rad_s, max(-su.turn_rate_max_rad_s, -sp.demand.yaw_rate_rad_s))
            accel = accel_command(
                sp.demand, t.speed_m_s, su.accel_max_m_s2, su.speed_min_m_s, su.speed_max_m_s, su.dt_s
            )
            return omega, accel
        orbit = self.orbit
        if self.armed and self.mode in AUTONOMOUS and orbit is not None:
            if orbit.center is None:
                return navigation.circle_turn_rate(t.speed_m_s, orbit.radius_m, orbit.ccw, su.turn_rate_max_rad_s), 0.0
            omega = navigation.orbit_turn_rate(
                t.east_m,
                t.north_m,
                t.phi_rad,
                t.speed_m_s,
                orbit.center,
                orbit.radius_m,
                orbit.ccw,
                su.turn_rate_max_rad_s,
            )
            return omega, 0.0
        return 0.0, 0.0

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
        self.statustext(M.MAV_SEVERITY_WARNING, f"Failsafe: {reason}, holding")
        self.event("FAILSAFE", 1)

    def clear_failsafe(self) -> None:
        self.failsafe = False
        self.loop_since_wall_s = self.clock.wall_s
        self.statustext(M.MAV_SEVERITY_INFO, "Failsafe cleared: setpoints resumed")
        self.event("FAILSAFE", 0)

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
            if self.endpoint.has_clients:
                for msg in self.build(mid):
                    self.send(msg)
            nxt = stream.next_due_s + stream.interval_s
            stream.next_due_s = nxt if nxt > now + _EPS_S else now + stream.interval_s
            time_sent = time_sent or mid == M.MAVLINK_MSG_ID_SYSTEM_TIME
        if tick and not time_sent:
            self.send(telemetry.system_time(self.mav, self.clock.unix_start_s, now))

    def send_snapshot(self, dest: Address | None = None) -> None:
        """The current state at once (a new peer; a lockstep world holding still): heartbeat, status, flags,
        position."""
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
            for msg in self.build(mid):
                self.send(msg, dest)

    def announce(self, event: MissionEvent) -> None:
        """A mission event as STATUSTEXT + NAMED_VALUE_INT to every peer."""
        if event.kind is EventKind.GEOFENCE and event.vehicle == self.index:
            self.fence_breached = True
        severity, text = event.statustext()
        self.send(telemetry.statustext(self.mav, severity, text))
        self.send(
            telemetry.named_value_int(self.mav, int(round(event.time_s * 1000.0)), event.kind.value_name, event.value)
        )

    def build(self, mid: int) -> list[mavlink2.MAVLink_message]:
        """The message(s) of one id for the current state ([] if there is nothing to say, e.g. no fix yet)."""
        mav, now, t, o = self.mav, self.clock.sim_s, self.truth, self.setup.origin
        ms = self.clock.time_boot_ms
        fix: GpsFix | None = self.gps.last_fix
        if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            return [telemetry.heartbeat(mav, self.armed, int(self.mode), self.guided, self.system_status)]
        if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
            return [
                telemetry.sys_status(mav, self.gps.has_fix(now), not self.fence_breached, self.endpoint.rx.rejected)
            ]
        if mid == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return [telemetry.extended_sys_state(mav)]
        if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return [telemetry.system_time(mav, self.clock.unix_start_s, now)]
        if mid == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            lk = self.setup.link
            return [
                telemetry.gps_raw_int(
                    mav, o, fix, self.gps.has_fix(now), ms, lk.gps_position_sigma_m, lk.gps_velocity_sigma_m_s
                )
            ]
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

    def statustext(self, severity: int, text: str, dest: Address | None = None) -> None:
        self.send(telemetry.statustext(self.mav, severity, text), dest)

    def event(self, name: str, value: int) -> None:
        if self._on_event is not None:
            self._on_event(self.role, name, value)

    def relay_statustext(self, severity: int, text: str, source: Address) -> None:
        """A client's STATUSTEXT (a companion's note) to every other client, into the tlog as sent, and into the
        truth log as a STATUSTEXT event with its text, as an autopilot forwards it to its ground stations."""
        for peer in set(self.endpoint.peers) | set(self.outputs):
            if peer != source:
                self.statustext(severity, text, peer)
        if self._on_event is not None:
            self._on_event(self.role, "STATUSTEXT", severity, text)

    def requested(self, mid: int) -> list[mavlink2.MAVLink_message] | None:
        """MAV_CMD_REQUEST_MESSAGE: the message(s) of ``mid`` now ([] if there is nothing yet), None if unknown."""
        return self.build(mid) if mid in REQUESTABLE else None

    def set_stream_interval(self, mid: int, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (-1 off, 0 default, > 0 microseconds); returns the MAV_RESULT."""
        stream = self._streams.get(mid)
        if stream is None:
            return M.MAV_RESULT_UNSUPPORTED
        if interval_us == -1:
            stream.interval_s = None
        elif interval_us == 0:
            stream.interval_s = DEFAULT_INTERVALS_S[mid]
        elif 0 < interval_us <= MAX_INTERVAL_US:  # also false for NaN
            stream.interval_s = interval_us / 1e6
        else:
            return M.MAV_RESULT_DENIED
        stream.next_due_s = self.clock.sim_s
        return M.MAV_RESULT_ACCEPTED

    def stream_interval_us(self, mid: int) -> int | None:
        """MAV_CMD_GET_MESSAGE_INTERVAL: -1 off, else microseconds; None for an unknown stream."""
        stream = self._streams.get(mid)
        if stream is None:
            return None
        return -1 if stream.interval_s is None else min(MAX_INTERVAL_US, int(round(stream.interval_s * 1e6)))

    # -------------------------------------------------------------------------- state changes

    def set_mode(self, mode: FlightMode, reason: str = "") -> None:
        """Enter ``mode`` (a no-op if already in it); autonomous modes pick their circle now."""
        if mode is self.mode:
            return
        was_in_loop = self.in_loop
        self._guided_from = (self.mode, self.clock.wall_s) if mode is FlightMode.GUIDED else None
        self.mode = mode
        self.setpoint = None
        self.failsafe = False
        self.refusals.forget("ignored")
        self.orbit = self._orbit_for(mode)
        self._enter_loop_if(was_in_loop)
        _log.info("%s: mode %s%s", self.role, mode.name, f" ({reason})" if reason else "")
        self.event("MODE", int(mode))

    def undo_guided_switch(self, reason: str) -> bool:
        """Go back to the mode before GUIDED if GUIDED was entered less than GOTO_UNDO_S wall seconds ago and no
        setpoint has come since (a refused goto's mode change, see CommandHandler); True if it did."""
        if self.mode is not FlightMode.GUIDED or self.setpoint is not None or self._guided_from is None:
            return False
        previous, since_wall_s = self._guided_from
        if self.clock.wall_s - since_wall_s > GOTO_UNDO_S:
            return False
        self.set_mode(previous, reason)
        return True

    def _orbit_for(self, mode: FlightMode) -> Orbit | None:
        t, su = self.truth, self.setup
        if mode not in AUTONOMOUS:
            return None
        radius = navigation.orbit_radius_m(self.param("WP_LOITER_RAD"), t.speed_m_s, su.turn_rate_max_rad_s)
        if mode is FlightMode.RTL:
            return Orbit((su.home_east_m, su.home_north_m), radius)
        if mode is FlightMode.LOITER:
            return Orbit(navigation.orbit_center(t.east_m, t.north_m, t.phi_rad, radius, ccw=False), radius)
        return Orbit(None, radius)  # CIRCLE

    def set_armed(self, armed: bool) -> None:
        if armed is self.armed:
            return
        was_in_loop = self.in_loop
        self.armed = armed
        self.setpoint = None
        self.failsafe = False
        self.refusals.forget("ignored")
        self._enter_loop_if(was_in_loop)
        _log.info("%s: %s", self.role, "armed" if armed else "disarmed")
        self.event("ARMED", int(armed))

    def _enter_loop_if(self, was_in_loop: bool) -> None:
        if self.in_loop and not was_in_loop:
            # The setpoint timeout runs from the moment the companion takes control.
            self.last_setpoint_s = self.clock.sim_s
            self.loop_since_wall_s = self.clock.wall_s
            self._entry_credit_ms = self._credit_ms

    def fly_demand(self, demand: Demand) -> bool:
        """Fly a parsed setpoint if armed in GUIDED (True), else count it as ignored (False)."""
        if not (self.armed and self.guided):
            self.counters.setpoints_ignored += 1
            self.refuse("ignored", "SP ignored: arm and set GUIDED (15) first")
            return False
        now = self.clock.sim_s
        self.setpoint = FlownSetpoint(demand, now)
        self.last_setpoint_s = now
        self.counters.setpoints_accepted += 1
        if self.failsafe:
            self.clear_failsafe()
        return True

    def reject(self, refusal: Refusal) -> None:
        """A setpoint that cannot be flown: counted, and a STATUSTEXT that says what to send instead."""
        self.counters.setpoints_rejected += 1
        self.refuse(refusal.kind, refusal.text)

    def refuse(self, kind: str, text: str) -> None:
        """STATUSTEXT ``text`` to every client, at most once per REFUSAL_INTERVAL_S for each ``kind``."""
        if self.refusals.allow(kind, self.clock.wall_s):
            self.statustext(M.MAV_SEVERITY_WARNING, text)
        else:
            self.counters.refusal_texts_suppressed += 1

    def param(self, name: str) -> float:
        p = self.params.get(name)
        assert p is not None, name
        return p.value

    # ----------------------------------------------------------------------- datalink failsafe

    def _heard_client(self) -> None:
        self.datalink.last_heard_wall_s = self.clock.wall_s
        if self.datalink.lost:
            self.datalink.lost = False
            self.statustext(M.MAV_SEVERITY_INFO, "Failsafe: datalink restored")
            self.event("DATALINK", 0)

    def _check_datalink(self) -> None:
        """ArduPlane's long GCS failsafe: no client heard for FS_LONG_TIMEOUT wall seconds while armed."""
        d = self.datalink
        if d.lost or d.last_heard_wall_s is None or not self.armed or self.param("FS_GCS_ENABL") == 0:
            return
        timeout = self.param("FS_LONG_TIMEOUT")
        if self.clock.wall_s - d.last_heard_wall_s <= timeout:
            return
        d.lost = True
        self.counters.datalink_failsafes += 1
        # ArduPlane: from a pilot mode always RTL; from an auto mode RTL only with FS_LONG_ACTN = 1.
        rtl = self.mode is not FlightMode.RTL and (self.mode is FlightMode.MANUAL or self.param("FS_LONG_ACTN") == 1)
        action = "RTL" if rtl else f"staying in {self.mode.name}"
        _log.warning("%s: datalink lost for %g s: %s", self.role, timeout, action)
        self.statustext(M.MAV_SEVERITY_CRITICAL, f"Failsafe: no link {timeout:g} s, {action}")
        self.event("DATALINK", 1)
        if rtl:
            self.set_mode(FlightMode.RTL, "datalink failsafe")
