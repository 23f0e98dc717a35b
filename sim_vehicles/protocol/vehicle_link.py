"""One vehicle's MAVLink side: its endpoint behind the link model, its telemetry, the lockstep credit, the tlog.

A :class:`VehicleLink` owns the vehicle's :class:`~sim_vehicles.link.mavlink_io.MavEndpoint` (socket, framing,
signing, clients), two :class:`~sim_vehicles.link.link_model.LinkChannel` (datalink out and in) and the
:class:`~sim_vehicles.protocol.streams.StreamTable`; it reads the :class:`~sim_vehicles.autopilot.vehicle.Vehicle`'s
state to make telemetry and hands what clients send to its :class:`MessageHandler`
(:class:`sim_vehicles.protocol.commands.CommandHandler`, attached by the runner). The runner drives it: drain the socket
(:meth:`VehicleLink.poll_socket`), handle what the incoming channel delivers (:meth:`VehicleLink.process_incoming`),
after each step publish the due streams (:meth:`VehicleLink.publish`), and send what the outgoing channel delivers
(:meth:`VehicleLink.flush`).

Lockstep credit: a setpoint that reaches the socket credits the barrier with the step it answers (its
``time_boot_ms``); the newest step tick (SYSTEM_TIME) the outgoing channel has delivered is the step a client can
have seen. A vehicle in the loop holds the world once its client has answered a tick since it took control
(:attr:`VehicleLink.holds_world`), and the world steps when every such client has answered the newest tick
(:meth:`VehicleLink.answered`). A client may also grant the ticks up to a later one beside its setpoint
(:mod:`tssac_core.wire.lockstep`): they count as answered, and the setpoint is flown through them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import BinaryIO, Protocol

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.autopilot import guided_slew, telemetry
from sim_vehicles.autopilot.events import MissionEvent
from sim_vehicles.autopilot.setpoints import Demand, Refusal, parse_attitude_target, parse_position_target
from sim_vehicles.autopilot.vehicle import Vehicle
from sim_vehicles.link.link_model import LinkChannel
from sim_vehicles.link.mavlink_io import Address, MavEndpoint, Parsed, Sender
from sim_vehicles.protocol import streams
from tssac_core.wire import units
from tssac_core.wire.lockstep import GRANT_NAME

M = mavlink2  # message ids and enums
_SYSTEM_TIME_MS = mavlink2.MAVLink_system_time_message.fieldnames.index("time_boot_ms")
"""Where SYSTEM_TIME's fields hold the step (a tick's ``time_boot_ms``)."""
_SETPOINT_PARSERS: dict[int, Callable[[mavlink2.MAVLink_message], Demand | Refusal]] = {
    M.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: parse_position_target,
    M.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: parse_attitude_target,
}
"""The setpoints a vehicle flies (and that credit the lockstep barrier), by message id."""
_COMMANDS = frozenset({M.MAVLINK_MSG_ID_COMMAND_INT, M.MAVLINK_MSG_ID_COMMAND_LONG})
COALESCE_BYTES = 1200
"""Largest datagram :meth:`VehicleLink.flush` builds from several frames (below any path MTU on a LAN)."""


class MessageHandler(Protocol):
    """The incoming side of a vehicle: reads a client's message, answers it, changes the vehicle's state."""

    def handle(self, msg: mavlink2.MAVLink_message, addr: Address) -> None: ...


@dataclass
class LockstepCredit:
    """Where the vehicle's clients stand in the lockstep (time_boot_ms of steps; -1 none)."""

    answered_ms: int = -1
    """Newest step a client has answered with a setpoint (at the socket, before the link model)."""
    tick_seen_ms: int = -1
    """Newest step tick (SYSTEM_TIME) the datalink has delivered to the clients."""
    entry_ms: int = -1
    """``answered_ms`` when the vehicle last came under companion control (it holds the world once that grows)."""
    granted_ms: int = -1
    """Last tick a client's grant counts as answered (:mod:`tssac_core.wire.lockstep`); forgotten when the vehicle
    comes under control again."""


class _StepOccurrences:
    """How many times each message id has come up at the current step time (``time_boot_ms``): the occurrence part
    of a frame's link-model key, which names the frame instead of counting the traffic before it."""

    def __init__(self) -> None:
        self._step_ms = -1
        self._counts: dict[int, int] = {}

    def occurrence(self, now_ms: int, mid: int) -> int:
        """Count one more message ``mid`` at ``now_ms`` and return its occurrence (1 for the first of the step)."""
        if now_ms != self._step_ms:
            self._step_ms, self._counts = now_ms, {}
        n = self._counts[mid] = self._counts.get(mid, 0) + 1
        return n


class VehicleLink:
    """The MAVLink side of one vehicle (see the module docstring)."""

    def __init__(
        self,
        vehicle: Vehicle,
        endpoint: MavEndpoint,
        tx_rng: np.random.Generator,
        rx_rng: np.random.Generator,
        tlog: BinaryIO | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.endpoint = endpoint
        self.clock = vehicle.clock
        link = vehicle.setup.link
        self.tx: LinkChannel[tuple[bytes, Address, int]] = LinkChannel(link, tx_rng)
        """Frames out: (frame, destination or None for every client, the tick's time_boot_ms or -1)."""
        self.rx: LinkChannel[tuple[Parsed, Address]] = LinkChannel(link, rx_rng)
        """Datagrams in, already checked and decoded at the socket (see :meth:`poll_socket`)."""
        self.streams = streams.StreamTable()
        self.outputs: tuple[Address, ...] = ()
        """Ground-station addresses (``--out``) that get the stream from the start and are never forgotten."""
        self.credit = LockstepCredit()
        self.handler: MessageHandler | None = None
        """What handles incoming messages (:class:`sim_vehicles.protocol.commands.CommandHandler`, attached by the
        runner)."""
        self._tlog = tlog
        self._sent_in_step = _StepOccurrences()
        """Frames sent per message id at the current step time: the occurrence part of their link-model key."""
        self._rx_setpoints: dict[int, int] = {}
        """Datagrams holding a setpoint, per stamp: the occurrence part of their link-model key."""
        self._rx_in_step = _StepOccurrences()
        """Other messages received per message id at the current step time: the occurrence part of their datagram's
        key."""
        self._keeps_order_when_batched = link.reordering == 0
        """Frames released later leave in the order they would have left one by one (no reordering holds)."""
        self._last_setpoint: tuple[mavlink2.MAVLink_message, Demand | Refusal] | None = None
        """The setpoint message parsed last, and what it asks for (:meth:`setpoint`)."""
        vehicle.radio = self

    @property
    def mav(self) -> mavlink2.MAVLink:
        return self.endpoint.mav

    # ------------------------------------------------------------------------- lockstep credit

    def took_control(self) -> None:
        """The vehicle has come under companion control (:class:`sim_vehicles.autopilot.vehicle.Radio`)."""
        self.credit.entry_ms = self.credit.answered_ms
        self.credit.granted_ms = -1

    @property
    def holds_world(self) -> bool:
        """Lockstep barrier member: in the loop, and its client has answered a tick since it took control.

        Until that first answer the world does not wait for it: the client may still be waiting for the
        COMMAND_ACK of the mode change, which a lossy, slow link delivers only as simulated time runs.
        """
        return self.vehicle.in_loop and self.credit.answered_ms > self.credit.entry_ms

    def answered(self) -> bool:
        """Lockstep: a client has answered the newest step tick the datalink delivered (see :meth:`poll_socket`)."""
        c = self.credit
        return max(c.answered_ms, c.granted_ms) >= c.tick_seen_ms

    def granted(self, tick_ms: int) -> bool:
        """Lockstep: the client's grant answers the tick at ``tick_ms`` (the world will not wait for it there), so the
        tick's telemetry may leave with the telemetry of the tick the world waits at (see :meth:`flush`)."""
        return self.credit.granted_ms >= tick_ms and self.clock.lockstep and self._keeps_order_when_batched

    def _grant(self, msg: mavlink2.MAVLink_message, stamp_ms: int) -> None:
        """A client's lockstep grant beside a setpoint stamped ``stamp_ms`` in the same datagram: the ticks after the
        stamp up to the grant's ``value`` count as answered."""
        if msg.get_msgId() != M.MAVLINK_MSG_ID_NAMED_VALUE_INT or msg.name != GRANT_NAME:
            return
        if int(msg.time_boot_ms) != stamp_ms or msg.value <= stamp_ms:
            return
        c = self.credit
        c.granted_ms = max(c.granted_ms, int(msg.value))

    def _credit(self, msg: mavlink2.MAVLink_message) -> int | None:
        """A flyable setpoint for us credits the lockstep barrier with the step it answers (its stamp; 0 = now), and
        so does a flyable GUIDED slew command (ArduPlane's dialect: no stamp, so the step the datalink delivered);
        returns the answer's stamp (a grant beside it must carry it), None if nothing was credited."""
        v = self.vehicle
        mid = msg.get_msgId()
        if mid in _SETPOINT_PARSERS:
            if isinstance(self.setpoint(msg), Refusal):
                return None
            stamp = int(msg.time_boot_ms)
        elif mid in _COMMANDS and msg.command in guided_slew.SLEW_COMMANDS:
            if not self._flyable_slew(msg):
                return None
            stamp = 0
        else:
            return None
        if msg.target_system not in (0, v.sysid) or msg.target_component not in (0, v.compid):
            return None
        c = self.credit
        c.answered_ms = max(c.answered_ms, c.tick_seen_ms if stamp == 0 else min(stamp, self.clock.time_boot_ms))
        return stamp if mid in _SETPOINT_PARSERS else c.tick_seen_ms

    def _flyable_slew(self, msg: mavlink2.MAVLink_message) -> bool:
        """A CHANGE_HEADING or CHANGE_SPEED the vehicle would accept (judged again when it is handled)."""
        su = self.vehicle.setup
        params = (msg.param1, msg.param2, msg.param3)
        if msg.command == M.MAV_CMD_GUIDED_CHANGE_HEADING:
            parsed: object = guided_slew.parse_change_heading(params)
        else:
            parsed = guided_slew.parse_change_speed(params, su.speed_min_m_s, su.speed_max_m_s)
        return not isinstance(parsed, guided_slew.SlewRefusal)

    def setpoint(self, msg: mavlink2.MAVLink_message) -> Demand | Refusal:
        """What a SET_POSITION_TARGET_LOCAL_NED or SET_ATTITUDE_TARGET asks for: parsed once when it reaches the socket
        (:meth:`_credit`) and read again when the handler flies it."""
        last = self._last_setpoint
        if last is not None and last[0] is msg:
            return last[1]
        parsed = _SETPOINT_PARSERS[msg.get_msgId()](msg)
        self._last_setpoint = (msg, parsed)
        return parsed

    # ------------------------------------------------------------------------------- incoming

    def add_outputs(self, outputs: tuple[Address, ...]) -> None:
        """Ground stations (``--out``) that get every stream from the start and whose commands are taken."""
        self.outputs = tuple(outputs)
        for out in self.outputs:
            self.endpoint.peers.setdefault(out, self.clock.wall_s)

    def poll_socket(self, receive: bool = True) -> None:
        """Check and decode waiting datagrams and move them into the incoming link channel (``receive`` False: the
        socket is known to be empty, only the peer table is brought up to date).

        Checking (signatures, replays) happens here, at the socket, so that the link model acts on
        messages: a setpoint the link then loses or delays still tells the lockstep barrier that its
        client has answered the step (:meth:`answered`). The vehicle flies the previous command until
        the setpoint arrives, or through the step if it never does, as a real vehicle would.
        """
        for out in self.outputs:  # --out ground stations are never forgotten
            self.endpoint.peers[out] = self.clock.wall_s
        self.endpoint.expire_peers(self.clock.wall_s)
        if not receive:
            return
        for data, addr in self.endpoint.receive():
            parsed = self.endpoint.parse(data, addr)
            if parsed.sender is None:
                continue  # nothing accepted: it never reaches the vehicle, and its sender is nobody
            key = None
            credited: int | None = None  # the stamp of a setpoint that credited a tick: a grant beside it may follow
            for msg in parsed.messages:
                if credited is not None and parsed.sender is Sender.CLIENT:
                    self._grant(msg, credited)
                stamp = self._credit(msg)
                if stamp is not None:
                    credited = stamp
                    if self.rx.ideal:
                        continue
                    if len(self._rx_setpoints) > 256:  # only recent stamps matter; clients may send any
                        self._rx_setpoints.clear()
                    n = self._rx_setpoints[stamp] = self._rx_setpoints.get(stamp, -1) + 1
                    key = hash((msg.get_msgId(), stamp, n))
            if key is None and not self.rx.ideal:
                key = self._rx_key(parsed)
            self.rx.push(self.clock.link_s, (parsed, addr), key)  # an ideal channel draws nothing: no key

    def _rx_key(self, parsed: Parsed) -> int:
        """The link model's key of a datagram without a setpoint: the step, and its messages' ids with their
        occurrence in this step (as outgoing frames are keyed), so that whether a command is lost does not depend on
        how many heartbeats the wall clock let through before it."""
        now_ms = self.clock.time_boot_ms
        seen = [(mid, self._rx_in_step.occurrence(now_ms, mid)) for mid in (msg.get_msgId() for msg in parsed.messages)]
        return hash((now_ms, *seen))

    def process_incoming(self) -> None:
        """Handle the datagrams the incoming channel delivers now."""
        for parsed, addr in self.rx.pop_due(self.clock.link_s):
            if parsed.sender is Sender.CLIENT:  # an unsigned monitor keeps no datalink alive
                self.vehicle.heard_client()
            assert parsed.sender is not None
            if self.endpoint.admit(addr, parsed.sender):
                self.send_snapshot(addr)
            for msg in parsed.messages:
                if self._tlog is not None:
                    self._write_tlog(bytes(msg.get_msgbuf()))
                assert self.handler is not None, "no message handler attached"
                self.handler.handle(msg, addr)

    # ------------------------------------------------------------------------------- outgoing

    def send(self, msg: mavlink2.MAVLink_message, dest: Address | None = None) -> None:
        """Queue one message for ``dest`` (None: every client and monitor) on the outgoing link.

        Each destination is a link of its own with its own sequence numbers (:meth:`MavEndpoint.encode`), taken
        in the order the frames are queued: a client never sees a gap for a frame that went to another one."""
        mid = msg.get_msgId()
        tick_ms = int(msg.time_boot_ms) if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME else -1
        endpoint = self.endpoint
        self._queue(mid, tick_ms, dest, lambda to: endpoint.encode(msg, to))

    def send_fields(self, mid: int, fields: streams.Fields, dest: Address | None = None) -> None:
        """:meth:`send` of message ``mid`` given by its fields
        (:data:`sim_vehicles.protocol.streams.FIELD_BUILDERS`), packed without building the message object."""
        cls = mavlink2.mavlink_map[mid]
        tick_ms = int(fields[_SYSTEM_TIME_MS]) if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME else -1
        endpoint = self.endpoint
        self._queue(mid, tick_ms, dest, lambda to: endpoint.encode_fields(cls, fields, to))

    def _queue(self, mid: int, tick_ms: int, dest: Address | None, encode: Callable[[Address], bytes]) -> None:
        """Encode message ``mid`` (``tick_ms``: a SYSTEM_TIME's step, else -1) for each destination and push the frames
        into the outgoing channel, the first into the tlog."""
        dests = (dest,) if dest is not None else self.endpoint.destinations()
        if not dests:
            return
        # The link model's key names the frame (id, step, occurrence): its fate does not depend on other traffic.
        clock = self.clock
        key = None  # an ideal channel draws nothing: no key
        if not self.tx.ideal:
            now_ms = clock.time_boot_ms
            key = hash((mid, now_ms, self._sent_in_step.occurrence(now_ms, mid)))
        lossless = clock.lockstep and tick_ms >= 0
        for i, to in enumerate(dests):
            buf = encode(to)
            if i == 0 and self._tlog is not None:
                self._write_tlog(buf)  # one copy per message, as the vehicle sent it
            self.tx.push(clock.link_s, (buf, to, tick_ms), key, lossless)

    def flush(self) -> None:
        """Send the frames the outgoing channel delivers now, packed into datagrams per destination.

        Frames released together for the same destination share one datagram (in order, up to
        COALESCE_BYTES), as a flight controller's UDP output does: one system call per destination and
        step instead of one per message. Loss, duplication and latency still act on every frame.
        """
        due = self.tx.pop_due(self.clock.link_s)
        if not due:
            return
        credit = self.credit
        batches: dict[Address, list[bytes]] = {}
        for data, dest, tick_ms in due:
            if tick_ms > credit.tick_seen_ms:
                credit.tick_seen_ms = tick_ms
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

    def _write_tlog(self, frame: bytes) -> None:
        assert self._tlog is not None
        stamp_us = units.us_from_s(self.clock.unix_start_s + self.clock.sim_s)
        self._tlog.write(struct.pack(">Q", stamp_us) + frame)

    # ------------------------------------------------------------------------------ telemetry

    def build(self, mid: int) -> list[mavlink2.MAVLink_message]:
        """The message(s) of one id for the vehicle's current state ([] if there is nothing to say yet)."""
        return streams.build(mid, self.vehicle, self.mav, self.endpoint.rx.rejected)

    def publish(self, tick: bool = False) -> None:
        """After a step: take a GPS fix if one is due and send every stream that is due.

        ``tick`` (lockstep): also send SYSTEM_TIME, the step's tick, so clients see every step; it leaves last, after
        the step's other telemetry, so a client that answers the tick has read everything of its step whichever
        datagram each frame went in (a client that decided on a tick before the step's fix had arrived would fly
        the wall clock's choice, not the mission's).
        """
        v = self.vehicle
        v.sample_gps()
        due = self.streams.take_due(self.clock.sim_s, v.gps.last_fix)
        if self.endpoint.has_clients:
            for mid in due:
                if tick and mid == M.MAVLINK_MSG_ID_SYSTEM_TIME:
                    continue
                build_fields = streams.FIELD_BUILDERS.get(mid)
                if build_fields is None:
                    for msg in self.build(mid):
                        self.send(msg)
                else:
                    fields = build_fields(v)
                    if fields is not None:
                        self.send_fields(mid, fields)
        if tick:
            self.send_fields(M.MAVLINK_MSG_ID_SYSTEM_TIME, streams.system_time_fields(v))

    def send_snapshot(self, dest: Address | None = None) -> None:
        """The current state at once (a new peer; a lockstep world holding still): heartbeat, status, flags,
        position."""
        for mid in streams.SNAPSHOT:
            for msg in self.build(mid):
                self.send(msg, dest)

    def announce(self, event: MissionEvent) -> None:
        """A mission event as STATUSTEXT + NAMED_VALUE_INT to every peer."""
        severity, text = event.statustext()
        self.send(telemetry.statustext(self.mav, severity, text))
        self.send(
            telemetry.named_value_int(self.mav, units.ms_from_s(event.time_s), event.kind.value_name, event.value)
        )

    def statustext(self, severity: int, text: str, dest: Address | None = None) -> None:
        self.send(telemetry.statustext(self.mav, severity, text), dest)

    def relay(self, msg: mavlink2.MAVLink_message, source: Address) -> None:
        """A client's frame passed on as it came (its ids, sequence number and signature) to every other client and
        ground station (:meth:`sim_vehicles.protocol.commands.CommandHandler._on_heartbeat`); nothing when there is
        no other."""
        frame = bytes(msg.get_msgbuf())
        for peer in set(self.endpoint.peers) | set(self.outputs):
            if peer != source:
                self._queue(msg.get_msgId(), -1, peer, lambda _to: frame)

    def relay_statustext(self, severity: int, text: str, source: Address) -> None:
        """A client's STATUSTEXT (a companion's note) to every other client, into the tlog as sent, and into the
        truth log as a STATUSTEXT event with its text, as an autopilot forwards it to its ground stations."""
        for peer in set(self.endpoint.peers) | set(self.outputs):
            if peer != source:
                self.statustext(severity, text, peer)
        self.vehicle.event("STATUSTEXT", severity, text)

    def requested(self, mid: int) -> list[mavlink2.MAVLink_message] | None:
        """MAV_CMD_REQUEST_MESSAGE: the message(s) of ``mid`` now ([] if there is nothing yet), None if unknown."""
        return self.build(mid) if mid in streams.REQUESTABLE else None

    def set_stream_interval(self, mid: int, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (-1 off, 0 default, > 0 microseconds); returns the MAV_RESULT."""
        return self.streams.set_interval(mid, interval_us, self.clock.sim_s)

    def stream_interval_us(self, mid: int) -> int | None:
        """MAV_CMD_GET_MESSAGE_INTERVAL: -1 off, else microseconds; None for an unknown stream."""
        return self.streams.interval_us(mid)
