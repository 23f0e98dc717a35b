"""One MAVLink 2 link to one vehicle over UDP or a serial line: a typed wrapper around pymavlink's protocol object.

:class:`MavLink` owns a UDP socket (or a serial device, :mod:`mavlink_bridge.link.serial_port`) and a pymavlink
``MAVLink`` object (dialect ardupilotmega, MAVLink 2). It does not use ``mavutil.mavudp`` because that class
swallows socket errors in ``write`` and keeps state in module globals (``mavutil.global_link_id`` for signing):
here socket errors are counted in :class:`LinkCounters` and logged (rate-limited), and every setting is an argument.

Connection strings follow pymavlink / MAVProxy:

* ``udpout:HOST:PORT`` — send to the vehicle at HOST:PORT from an OS-assigned local port (what the
  bundled SITL prints). The vehicle learns us from our first datagram, so we send HEARTBEATs
  while waiting for it (:meth:`MavLink.wait_heartbeat`).
* ``udpin:HOST:PORT`` (or ``udp:HOST:PORT``) — bind HOST:PORT and answer the vehicle (below).
* ``DEVICE[,BAUD]`` (a path: ``/dev/ttyUSB0,57600``, MAVProxy's form; 57,600 baud without one) — a serial line,
  the flight controller's telemetry port. Its bytes are framed by :class:`tssac_core.wire.stream_framing.StreamFramer`,
  which keeps a frame still arriving between reads and resynchronises after garbage or a dropped byte; a frame still
  incomplete when the line has been idle for :data:`SERIAL_IDLE_S` is cut. Everything heard on the line is the
  vehicle's.

Receiving keeps UDP's datagram boundaries: every datagram is split into frames on its own, by the scanner
the SITL vehicles use (:mod:`tssac_core.wire.framing`), so a truncated frame never swallows the
start of the next datagram, a valid frame behind a garbage header is still found, and frames of message ids
the dialect does not know are dropped. Only the vehicle is heard: with ``udpout`` a datagram
from any address but the vehicle's is dropped unread (counted in ``foreign_rx``); with ``udpin`` the
first sender of an accepted message is the vehicle (with signing, the sender of the latest correctly
signed one). With signing, every frame is verified by
:class:`tssac_core.wire.signing.SignatureVerifier` — signature first, then the stream's
timestamp — before it is believed; pymavlink only decodes (its own check records a forged frame's
timestamp before it compares the signature, and one far-future forgery would lock the vehicle's stream
out). So mission events (NAMED_VALUE_INT ``MSN_END``, ``HIT``) are as authenticated as everything else. Messages that
arrive while a command waits for its
COMMAND_ACK are kept and returned by later :meth:`MavLink.recv` calls, never dropped. Every
wait is bounded on ``time.monotonic()``; no wait uses the vehicle's clock (a silent vehicle has none).

:attr:`MavLink.last_rx_s` is the time (``time.monotonic()``) at which the datagram of the message
:meth:`MavLink.recv` returned last was read, for latency measurements.

Frames the vehicle sent that never arrived are counted from its sequence numbers (``frames_lost_rx``).

Optionally every message received and sent is appended to a ``.tlog`` (8-byte big-endian Unix time
in microseconds, then the raw frame: the format MAVProxy writes and pymavlink's ``mavlogdump.py``
reads).
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import select
import socket
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from mavlink_bridge.link.guided_commands import GuidedSlew
from mavlink_bridge.link.serial_port import SerialError, SerialPort, SerialSpec, is_serial, parse_serial
from tssac_core.common.files import create_exclusively
from tssac_core.wire import units
from tssac_core.wire.framing import Dialect, FrameDecoder, FramePacker, scan_frames, source
from tssac_core.wire.lockstep import GRANT_NAME
from tssac_core.wire.signing import SignatureVerifier, Verdict, now_10us, refresh_outgoing_timestamp
from tssac_core.wire.stream_framing import SequenceGaps, StreamFramer
from tssac_core.wire.uart import bytes_per_s

__all__ = [
    "CommandError",
    "ConnectionSpec",
    "LinkCounters",
    "LinkError",
    "MavLink",
    "Message",
    "parse_connection",
    "SETPOINT_TYPE_MASK",
    "SerialSpec",
]

_log = logging.getLogger(__name__)

Message: TypeAlias = mavlink2.MAVLink_message
M = mavlink2

MAX_DATAGRAM = 65535
SERIAL_IDLE_S = 0.5
"""A serial line silent this long (wall s) with a frame still incomplete has cut it: the bytes behind its start are
scanned again. Ten times what a whole frame (280 bytes) takes at 57,600 baud, and more than it takes at 9,600."""
_TLOG_FLUSH_S = 1.0
DIALECT = Dialect.of_messages(M.mavlink_map)
"""ardupilotmega's message ids and CRC_EXTRAs, for :func:`tssac_core.wire.framing.scan_frames`."""

SETPOINT_TYPE_MASK = (
    M.POSITION_TARGET_TYPEMASK_X_IGNORE
    | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | M.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | M.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | M.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | M.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | M.POSITION_TARGET_TYPEMASK_YAW_IGNORE
)
"""Use only afx (forward acceleration) and yaw_rate: 1471 (= 1087 + the AY/AZ ignore bits)."""
SETPOINT_FRAME = M.MAV_FRAME_BODY_FRD
"""afx along the body's forward axis; yaw_rate about the down axis (clockwise-positive)."""


class LinkError(Exception):
    """A link that cannot be opened or a vehicle that does not answer; ``str()`` is one line."""


class CommandError(LinkError):
    """A COMMAND_LONG that was not acknowledged, or acknowledged with a result other than ACCEPTED."""

    def __init__(self, command: int, result: int | None, message: str) -> None:
        self.command = command
        self.result = result
        super().__init__(message)


@dataclass(frozen=True)
class ConnectionSpec:
    """A parsed connection string."""

    kind: str
    """"udpout" (send to host:port) or "udpin" (bind host:port)."""
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.kind}:{self.host}:{self.port}"


def parse_connection(text: str) -> ConnectionSpec | SerialSpec:
    """``udpout:HOST:PORT``, ``udpin:HOST:PORT``, ``udp:HOST:PORT`` or a serial ``DEVICE[,BAUD]``; ValueError (one
    line) otherwise."""
    if is_serial(text):
        return parse_serial(text)
    parts = text.strip().split(":")
    if len(parts) != 3 or parts[0] not in ("udpout", "udpin", "udp"):
        raise ValueError(
            f"connection {text!r}: expected udpout:HOST:PORT, udpin:HOST:PORT or a serial device DEVICE,BAUD"
        )
    kind = "udpin" if parts[0] == "udp" else parts[0]
    host = parts[1]
    try:
        port = int(parts[2])
    except ValueError:
        raise ValueError(f"connection {text!r}: port {parts[2]!r} is not a number") from None
    if not host or not 0 <= port <= 65535 or (kind == "udpout" and port == 0):
        raise ValueError(f"connection {text!r}: bad host or port")
    return ConnectionSpec(kind, host, port)


@dataclass
class LinkCounters:
    """What went over the link, by outcome."""

    datagrams_rx: int = 0
    """UDP datagrams, or serial reads that returned bytes."""
    bytes_rx: int = 0
    messages_rx: int = 0
    bad_data_rx: int = 0
    """Candidate frames dropped: bad CRC, unknown message id, or not decodable."""
    garbage_bytes_rx: int = 0
    """Bytes outside any frame."""
    signature_rejected: int = 0
    """Unsigned, wrongly signed or replayed messages (signing on): the sum of the next three."""
    unsigned_rx: int = 0
    bad_signature_rx: int = 0
    replayed_rx: int = 0
    foreign_rx: int = 0
    """Datagrams from an address other than the vehicle's, dropped unread."""
    truncated_rx: int = 0
    """Candidate frames cut off by the end of their datagram (serial: by the line falling idle)."""
    frames_lost_rx: int = 0
    """Frames missing from the vehicle's sequence numbers (lost by the link, or dropped by its sender)."""
    socket_errors_rx: int = 0
    messages_tx: int = 0
    bytes_tx: int = 0
    socket_errors_tx: int = 0
    """Sends the socket refused; serial: frames dropped because the line's buffer was full."""
    command_retries: int = 0


class MavLink:
    """A MAVLink 2 link to one vehicle over UDP or a serial line (see the module docstring).

    ``source_system`` / ``source_component`` identify us (default 255 / 191, an onboard computer);
    ``target_system`` / ``target_component`` are learned from the vehicle's first autopilot heartbeat
    (or given). ``signing_key`` (32 bytes) turns on MAVLink 2 signing: everything we send is signed,
    and unsigned, wrongly signed or replayed messages from the vehicle are dropped and counted.
    """

    def __init__(
        self,
        connection: str,
        *,
        source_system: int = 255,
        source_component: int = M.MAV_COMP_ID_ONBOARD_COMPUTER,
        target_system: int = 0,
        target_component: int = M.MAV_COMP_ID_AUTOPILOT1,
        signing_key: bytes | None = None,
        signing_link_id: int = 1,
        tlog_path: Path | None = None,
    ) -> None:
        try:
            self.spec = parse_connection(connection)
        except ValueError as exc:
            raise LinkError(str(exc)) from None
        self.counters = LinkCounters()
        self.target_system = target_system
        self.target_component = target_component
        self._targets = (target_system, target_component)
        self._backlog: collections.deque[tuple[Message, float]] = collections.deque()
        self.last_rx_s = 0.0
        """When the datagram of the message :meth:`recv` returned last was read (time.monotonic())."""
        self._peer: tuple[str, int] | None = None
        self._tlog: BinaryIO | None = None
        self._tlog_path: Path | None = None
        self._tlog_flushed = time.monotonic()
        self.tlog_error: str | None = None
        """Why the tlog is incomplete (a write or its close failed: a full disk), None while every byte went in."""
        self._closed = False
        self._seq_gaps = SequenceGaps()
        self._serial: SerialPort | None = None
        self._framer = StreamFramer(DIALECT)
        """Frames out of a serial line's bytes (unused on UDP)."""
        self._serial_rx_s = 0.0
        """When the serial line last delivered bytes (time.monotonic())."""
        self._serial_dead = False
        """The serial line failed (unplugged, the far end closed): it is read no more."""
        self._open_transport()
        self.mav = mavlink2.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
        """Builds what we send and holds our identity, sequence and signing state."""
        self._setpoint = self.mav.set_position_target_local_ned_encode(
            0, 0, 0, SETPOINT_FRAME, SETPOINT_TYPE_MASK, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        )
        """The one SET_POSITION_TARGET_LOCAL_NED :meth:`send_setpoint` fills in and packs (no object per step); the
        fields it does not set stay as made here: frame, type mask, and 0.0 for what the mask ignores."""
        self._grant = self.mav.named_value_int_encode(0, GRANT_NAME.encode(), 0)
        """The one lockstep grant :meth:`send_setpoint` fills in and sends beside a setpoint."""
        self._packer = FramePacker(DIALECT.crc16)
        """Packs (and signs) what we send: pymavlink's bytes, fewer objects per frame (tests/test_bridge.py)."""
        self._rx = FrameDecoder(M.mavlink_map, M.MAVLink_header)
        """Decodes the frames we accept (already checked): pymavlink's objects, without a second CRC."""
        self._verifier: SignatureVerifier | None = None
        if signing_key is not None:
            self.setup_signing(signing_key, signing_link_id)
        if tlog_path is not None:
            try:
                self._open_tlog(Path(tlog_path))
            except LinkError:
                self._close_transport()
                raise

    # ----------------------------------------------------------------------------- set-up

    def _open_transport(self) -> None:
        """The UDP socket (bound, or aimed at the vehicle) or the serial port of ``self.spec``, polled for input;
        LinkError (one line) if it cannot be opened."""
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._kind = "serial" if isinstance(self.spec, SerialSpec) else self.spec.kind
        try:
            if isinstance(self.spec, SerialSpec):
                self._serial = SerialPort(self.spec)
            elif self.spec.kind == "udpin":
                self._sock.bind((self.spec.host, self.spec.port))
            else:
                self._peer = (socket.gethostbyname(self.spec.host), self.spec.port)
                # A loopback vehicle is answered from a loopback address; anything else from any interface.
                self._sock.bind(("127.0.0.1" if self._peer[0].startswith("127.") else "0.0.0.0", 0))
        except SerialError as exc:
            self._sock.close()
            raise LinkError(f"connection {self.spec}: {exc}") from None
        except OSError as exc:
            self._sock.close()
            raise LinkError(f"connection {self.spec}: cannot open UDP socket ({exc.strerror or exc})") from None
        if self._serial is not None:
            self._sock.close()  # a serial link has no socket
        else:
            self._sock.setblocking(False)
        self._poll = select.poll()
        """Tells whether a datagram (or serial bytes) waits: cheaper than ``select.select`` and than a read that
        fails."""
        self._poll.register(self.fileno(), select.POLLIN)
        self.local_address: tuple[str, int] = ("", 0) if self._serial is not None else self._sock.getsockname()[:2]

    def setup_signing(self, key: bytes, link_id: int = 1) -> None:
        """Sign what we send with ``key`` and accept only correctly signed, fresh messages.

        The same fields as pymavlink's ``mavfile.setup_signing``, without its global link-id counter.
        """
        if len(key) != 32:
            raise LinkError(f"signing key must be 32 bytes, got {len(key)}")
        if not 0 <= link_id <= 255:
            raise LinkError(f"signing link id must be in 0..255, got {link_id}")
        signing = self.mav.signing
        signing.secret_key = key
        signing.sign_outgoing = True
        signing.allow_unsigned_callback = None
        signing.link_id = link_id
        signing.timestamp = now_10us()
        self._verifier = SignatureVerifier(key)

    @property
    def signing(self) -> bool:
        return self.mav.signing.secret_key is not None

    @property
    def baud(self) -> int | None:
        """The serial line's baud rate; None on UDP."""
        return self.spec.baud if isinstance(self.spec, SerialSpec) else None

    @property
    def line_bytes_per_s(self) -> float | None:
        """Bytes a second the serial line carries each way (8N1); None on UDP."""
        return None if self.baud is None else bytes_per_s(self.baud)

    def new_mission(self, tlog_path: Path | None) -> None:
        """Start afresh on the same socket after a mission reset (:mod:`tssac_core.wire.mission_reset`): drop
        what is queued or waiting in the socket (all of it from the previous mission: a reset vehicle is silent
        until it hears from us), learn the vehicle again from its next heartbeat, count from 0, and write the
        mission's own tlog. The signing state is kept: our timestamps only grow."""
        self._backlog.clear()
        if self._serial is not None:
            try:
                self._serial.discard_input()
            except OSError as exc:
                raise LinkError(f"connection {self.spec}: {exc}") from None
            self._framer = StreamFramer(DIALECT)
        else:
            while True:
                try:
                    self._sock.recvfrom(MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    continue
        self.target_system, self.target_component = self._targets
        self.counters = LinkCounters()
        self._seq_gaps.reset()
        self._close_tlog()
        self.tlog_error = None
        if tlog_path is not None:
            self._open_tlog(Path(tlog_path))

    def _open_tlog(self, path: Path) -> None:
        """Start a new tlog at ``path``, made by us (never a file or link planted under its name)."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._tlog = open(create_exclusively(path), "wb")
        except OSError as exc:
            raise LinkError(f"cannot write tlog {path}: {exc.strerror or exc}") from None
        self._tlog_path = path

    def close_tlog(self) -> None:
        """Close the tlog, keeping the socket (the end of a mission of a persistent companion)."""
        self._close_tlog()

    def fileno(self) -> int:
        return self._serial.fileno() if self._serial is not None else self._sock.fileno()

    # ---------------------------------------------------------------------------- receive

    def recv(self, timeout_s: float = 0.0) -> Message | None:
        """The next message, waiting up to ``timeout_s`` (wall clock) for one; None if none came."""
        if self._backlog:
            return self._pop()
        remaining = max(0.0, timeout_s)
        deadline = time.monotonic() + remaining
        while not self._closed:
            # poll first (it returns at once if a datagram waits): an empty socket costs no failed recvfrom.
            try:
                readable = self._poll.poll(remaining * units.MS_PER_S)  # milliseconds, rounded up
            except InterruptedError:  # a signal: let the caller look at its stop flag
                return None
            if readable or (self._serial is not None and self._framer.pending):
                self._pump()  # serial: also a frame cut by a line fallen idle
                if self._backlog:
                    return self._pop()
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return None
        return None

    def _pop(self) -> Message:
        msg, self.last_rx_s = self._backlog.popleft()
        return msg

    def _push_back(self, items: list[tuple[Message, float]]) -> None:
        """Return messages taken during a wait to the front of the queue, in their order."""
        self._backlog.extendleft(reversed(items))

    def pending(self) -> bool:
        """Messages are waiting (already parsed, or datagrams in the socket)."""
        if self._backlog:
            return True
        self._pump()
        return bool(self._backlog)

    def _pump(self, max_datagrams: int = 256) -> None:
        """Read and parse every waiting datagram (non-blocking)."""
        if self._closed:
            return
        if self._serial is not None:
            self._pump_serial()
            return
        for n in range(max_datagrams):
            if n and not self._poll.poll(0):  # the socket is empty: no recvfrom to fail
                return
            try:
                data, addr = self._sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:
                # ICMP port unreachable for an earlier send: the vehicle is not (yet) there.
                self.counters.socket_errors_rx += 1
                continue
            except OSError as exc:
                self.counters.socket_errors_rx += 1
                self._warn_rate_limited("recvfrom", self.counters.socket_errors_rx, exc)
                return
            now = time.monotonic()
            sender: tuple[str, int] = addr  # (host, port): an AF_INET socket's address
            if self._kind == "udpout" and sender != self._peer:
                self.counters.foreign_rx += 1
                continue
            self.counters.datagrams_rx += 1
            self.counters.bytes_rx += len(data)
            msgs = self._parse_datagram(data)
            if self._kind == "udpin" and sender != self._peer:
                # udpin: the first sender of an accepted message is the vehicle; with signing, a vehicle
                # that moved is followed to the address its correctly signed frames now come from.
                if not msgs or (self._peer is not None and self._verifier is None):
                    self.counters.foreign_rx += 1
                    continue
                self._peer = sender
            self._queue(msgs, now)

    def _queue(self, msgs: list[Message], now: float) -> None:
        """Accepted messages, read at ``now``, into the backlog (and the tlog)."""
        for msg in msgs:
            self.counters.messages_rx += 1
            if self._tlog is not None:
                self._log_frame(bytes(msg.get_msgbuf()))
            self._backlog.append((msg, now))

    def _pump_serial(self) -> None:
        """Read what the serial line holds and frame it (a frame still arriving waits for its next bytes)."""
        assert self._serial is not None
        if self._serial_dead:
            return
        try:
            data = self._serial.read()
        except SerialError as exc:  # unplugged, or the far end closed: nothing more comes
            self.counters.socket_errors_rx += 1
            _log.error("%s; the vehicle is silent from now on", exc)
            self._poll.unregister(self._serial.fileno())  # a dead line polls readable for ever: waits sleep instead
            self._serial_dead = True
            return
        now = time.monotonic()
        framer = self._framer
        before = dataclasses.replace(framer.counters)
        if data:
            self._serial_rx_s = now
            self.counters.datagrams_rx += 1
            self.counters.bytes_rx += len(data)
            frames = framer.feed(data)
        elif framer.pending and now - self._serial_rx_s > SERIAL_IDLE_S:
            frames = framer.flush()
        else:
            return
        after = framer.counters
        self.counters.garbage_bytes_rx += after.garbage_bytes - before.garbage_bytes
        self.counters.truncated_rx += after.cut - before.cut
        self.counters.bad_data_rx += after.bad_crc - before.bad_crc + after.unknown_id - before.unknown_id
        self._queue(self._accept(frames), now)

    def _parse_datagram(self, data: bytes) -> list[Message]:
        """The accepted messages of one datagram (with signing: correctly signed and fresh).

        Framed by the SITL's scanner (:func:`tssac_core.wire.framing.scan_frames`): a valid frame
        behind a garbage header is found, frames of unknown message ids are dropped (never handed on as
        pymavlink's ``UNKNOWN_*``), a frame cut off by the end of the datagram is dropped.
        """
        scan = scan_frames(data, DIALECT)
        self.counters.garbage_bytes_rx += scan.garbage_bytes
        self.counters.truncated_rx += scan.truncated
        self.counters.bad_data_rx += scan.bad_crc + scan.unknown_id
        return self._accept(scan.frames)

    def _accept(self, frames: list[bytes]) -> list[Message]:
        """The frames (CRC-checked) that pass signing, decoded; the vehicle's sequence gaps counted."""
        accepted: list[Message] = []
        verifier, decode = self._verifier, self._rx.decode
        for frame in frames:
            if verifier is not None and (verdict := verifier.check(frame)) is not Verdict.OK:
                self._count_refused(verdict)
                continue
            try:
                msg = decode(frame)
            except Exception as exc:  # a pymavlink bug on hostile input must not take the companion down
                self.counters.bad_data_rx += 1
                _log.debug("pymavlink failed on a frame: %r", exc)
                continue
            accepted.append(msg)
            if self.target_system == 0 or source(frame) == (self.target_system, self.target_component):
                self.counters.frames_lost_rx += self._seq_gaps.observe(frame)
        return accepted

    def _count_refused(self, verdict: Verdict) -> None:
        """Count a frame the verifier refused, by its verdict."""
        self.counters.signature_rejected += 1
        if verdict is Verdict.UNSIGNED:
            self.counters.unsigned_rx += 1
        elif verdict is Verdict.BAD_SIGNATURE:
            self.counters.bad_signature_rx += 1
        else:
            self.counters.replayed_rx += 1

    # ------------------------------------------------------------------------------- send

    def send(self, msg: Message) -> bool:
        """Pack (and sign) one message and send it; False if the socket refused it (counted, logged)."""
        if self._closed:
            return False
        return self._send_frames(self._pack(msg))

    def _pack(self, msg: Message) -> bytes:
        """One frame of ``msg``, packed (and signed) with our next sequence number, into the tlog if we keep one."""
        mav = self.mav
        if self._verifier is not None:
            refresh_outgoing_timestamp(mav.signing)
        buf = self._packer.pack(msg, mav.seq, mav.srcSystem, mav.srcComponent, mav.signing)
        mav.seq = (mav.seq + 1) % 256
        self._log_frame(buf)
        return buf

    def _send_frames(self, buf: bytes, frames: int = 1) -> bool:
        """Send ``frames`` packed frames in one datagram; False if the socket refused it (counted, logged)."""
        if self._serial is not None:
            try:
                sent = self._serial.write(buf)
            except SerialError as exc:
                sent = False
                self._warn_rate_limited("serial write", self.counters.socket_errors_tx + 1, exc)
            if not sent:
                self.counters.socket_errors_tx += 1
                return False
            self.counters.messages_tx += frames
            self.counters.bytes_tx += len(buf)
            return True
        if self._peer is None:  # udpin before anyone has spoken to us
            return False
        try:
            self._sock.sendto(buf, self._peer)
        except OSError as exc:
            self.counters.socket_errors_tx += 1
            self._warn_rate_limited("sendto", self.counters.socket_errors_tx, exc)
            return False
        self.counters.messages_tx += frames
        self.counters.bytes_tx += len(buf)
        return True

    def send_heartbeat(self) -> bool:
        """Our HEARTBEAT (an onboard controller, no autopilot)."""
        return self.send(
            self.mav.heartbeat_encode(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)
        )

    def send_statustext(self, severity: int, text: str) -> bool:
        """STATUSTEXT (cut to one 50-character chunk)."""
        return self.send(self.mav.statustext_encode(severity, text[:50].encode("ascii", "replace")))

    def send_setpoint(
        self, time_boot_ms: int, yaw_rate_rad_s: float, accel_m_s2: float, granted_through_ms: int | None = None
    ) -> bool:
        """SET_POSITION_TARGET_LOCAL_NED: forward acceleration ``afx`` (m/s^2) and ``yaw_rate`` (rad/s,
        clockwise-positive, NED), frame BODY_FRD, type mask :data:`SETPOINT_TYPE_MASK`.

        ``time_boot_ms`` echoes the newest vehicle time we acted on (a lockstep vehicle steps once
        every vehicle in the loop has a setpoint stamped for the current step). ``granted_through_ms``: a lockstep
        grant (:mod:`tssac_core.wire.lockstep`) in the same datagram, the ticks up to it answered by this setpoint.
        """
        if self._closed:
            return False
        msg = self._setpoint
        msg.time_boot_ms = stamp = int(time_boot_ms) & 0xFFFFFFFF
        msg.target_system = self.target_system
        msg.target_component = self.target_component
        msg.afx = float(accel_m_s2)
        msg.yaw_rate = float(yaw_rate_rad_s)
        buf = self._pack(msg)
        if granted_through_ms is None:
            return self._send_frames(buf)
        grant = self._grant
        grant.time_boot_ms = stamp
        grant.value = int(granted_through_ms)
        return self._send_frames(buf + self._pack(grant), frames=2)

    def send_guided_slew(self, slew: GuidedSlew, answered_ms: int, granted_through_ms: int | None = None) -> bool:
        """ArduPlane's dialect (:mod:`mavlink_bridge.link.guided_commands`): COMMAND_INT GUIDED_CHANGE_HEADING (course
        over ground, or back to the autopilot without a course estimate) and GUIDED_CHANGE_SPEED (airspeed), in one
        datagram; their COMMAND_ACKs arrive with the telemetry (the caller checks them, without waiting).

        Under lockstep they answer the tick the vehicle last sent (``answered_ms``; commands carry no stamp); a grant
        after them (``granted_through_ms``) answers the ticks up to it, as beside a setpoint."""
        if self._closed:
            return False
        heading_type = M.HEADING_TYPE_DEFAULT if slew.heading_deg is None else M.HEADING_TYPE_COURSE_OVER_GROUND
        frames = [
            self._command_int(
                M.MAV_CMD_GUIDED_CHANGE_HEADING, heading_type, slew.heading_deg or 0.0, slew.centripetal_m_s2
            )
        ]
        if slew.speed_m_s is not None:
            frames.append(
                self._command_int(M.MAV_CMD_GUIDED_CHANGE_SPEED, M.SPEED_TYPE_AIRSPEED, slew.speed_m_s, slew.slew_m_s2)
            )
        if granted_through_ms is not None:
            grant = self._grant
            grant.time_boot_ms = int(answered_ms) & 0xFFFFFFFF
            grant.value = int(granted_through_ms)
            frames.append(self._pack(grant))
        return self._send_frames(b"".join(frames), frames=len(frames))

    def _command_int(self, command: int, param1: float, param2: float, param3: float) -> bytes:
        msg = self.mav.command_int_encode(
            self.target_system,
            self.target_component,
            M.MAV_FRAME_GLOBAL,
            command,
            0,
            0,
            param1,
            param2,
            param3,
            0.0,
            0,
            0,
            0.0,
        )
        return self._pack(msg)

    # ------------------------------------------------------------------------------ waits

    def wait_heartbeat(
        self, timeout_s: float, heartbeat_interval_s: float = 1.0, stop: Callable[[], bool] | None = None
    ) -> Message:
        """Wait for an autopilot HEARTBEAT (learning the target system), sending ours meanwhile.

        Other messages received meanwhile stay queued for :meth:`recv`. Raises LinkError on timeout.
        """
        deadline = time.monotonic() + timeout_s
        next_hb = time.monotonic()
        skipped: list[tuple[Message, float]] = []
        try:
            while True:
                now = time.monotonic()
                if now >= next_hb:
                    self.send_heartbeat()
                    next_hb = now + heartbeat_interval_s
                if stop is not None and stop():
                    raise LinkError("stopped while waiting for the vehicle's heartbeat")
                remaining = deadline - now
                if remaining <= 0.0:
                    raise LinkError(f"no heartbeat from the vehicle at {self.spec} within {timeout_s:g} s")
                msg = self.recv(min(remaining, next_hb - now, 0.1))
                if msg is None:
                    continue
                skipped.append((msg, self.last_rx_s))
                if self.is_vehicle_heartbeat(msg):
                    self.target_system = msg.get_srcSystem()
                    self.target_component = msg.get_srcComponent()
                    return msg
        finally:
            self._push_back(skipped)

    def is_vehicle_heartbeat(self, msg: Message) -> bool:
        """An autopilot's HEARTBEAT (of our target system, once that is known)."""
        if msg.get_type() != "HEARTBEAT":
            return False
        if msg.type in (M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_TYPE_GIMBAL, M.MAV_TYPE_ADSB):
            return False
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID:
            return False
        return self.target_system == 0 or msg.get_srcSystem() == self.target_system

    def from_vehicle(self, msg: Message) -> bool:
        """Sent by our target autopilot (system and component)."""
        return msg.get_srcSystem() == self.target_system and msg.get_srcComponent() == self.target_component

    def command_long(
        self, command: int, params: tuple[float, ...] = (), timeout_s: float = 1.0, retries: int = 3
    ) -> Message:
        """Send COMMAND_LONG until its COMMAND_ACK arrives (``retries`` attempts, ``timeout_s`` each).

        Returns the ACK (whatever its result); raises CommandError if none came. Other messages
        received meanwhile stay queued for :meth:`recv`. ``confirmation`` counts the attempts, as the
        MAVLink command protocol asks.
        """
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        if len(p) != 7:
            raise ValueError(f"COMMAND_LONG takes at most 7 parameters, got {len(params)}")
        skipped: list[tuple[Message, float]] = []
        try:
            for attempt in range(max(1, retries)):
                if attempt:
                    self.counters.command_retries += 1
                    _log.info("command %s: no COMMAND_ACK, retry %d", _command_name(command), attempt)
                self.send(self.mav.command_long_encode(self.target_system, self.target_component, command, attempt, *p))
                deadline = time.monotonic() + timeout_s
                while (remaining := deadline - time.monotonic()) > 0.0:
                    msg = self.recv(remaining)
                    if msg is None:
                        continue
                    if msg.get_type() == "COMMAND_ACK" and msg.command == command and self._ack_for_us(msg):
                        if msg.result == M.MAV_RESULT_IN_PROGRESS:
                            deadline = time.monotonic() + timeout_s
                            continue
                        return msg
                    skipped.append((msg, self.last_rx_s))
        finally:
            ack_rx_s = self.last_rx_s
            self._push_back(skipped)
            self.last_rx_s = ack_rx_s  # the ACK's (or, on failure, the last message's) receive time
        raise CommandError(
            command,
            None,
            f"{_command_name(command)}: no COMMAND_ACK from the vehicle after {max(1, retries)} attempts of "
            f"{timeout_s:g} s",
        )

    def command_checked(
        self, command: int, params: tuple[float, ...] = (), timeout_s: float = 1.0, retries: int = 3
    ) -> Message:
        """:meth:`command_long`, raising CommandError unless the result is MAV_RESULT_ACCEPTED."""
        ack = self.command_long(command, params, timeout_s, retries)
        if ack.result != M.MAV_RESULT_ACCEPTED:
            raise CommandError(
                command, ack.result, f"{_command_name(command)} refused by the vehicle: {_result_name(ack.result)}"
            )
        return ack

    def arm(self, timeout_s: float = 1.0, retries: int = 3) -> Message:
        """MAV_CMD_COMPONENT_ARM_DISARM(1), checked."""
        return self.command_checked(M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), timeout_s, retries)

    def set_mode(self, custom_mode: int, timeout_s: float = 1.0, retries: int = 3) -> Message:
        """MAV_CMD_DO_SET_MODE with CUSTOM_MODE_ENABLED and the autopilot's mode number, checked."""
        return self.command_checked(
            M.MAV_CMD_DO_SET_MODE, (float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(custom_mode)), timeout_s, retries
        )

    def set_message_interval(
        self, message_id: int, interval_s: float, timeout_s: float = 1.0, retries: int = 3
    ) -> Message:
        """MAV_CMD_SET_MESSAGE_INTERVAL, checked: ``interval_s`` > 0, or -1 to stop the stream."""
        interval_us = -1.0 if interval_s < 0 else interval_s * units.US_PER_S  # a float parameter: not rounded
        return self.command_checked(
            M.MAV_CMD_SET_MESSAGE_INTERVAL, (float(message_id), interval_us), timeout_s, retries
        )

    def read_params(self, names: Sequence[str], timeout_s: float = 1.0, retries: int = 3) -> dict[str, float]:
        """The vehicle's values of the parameters ``names`` (PARAM_REQUEST_READ by name, PARAM_VALUE back), asking
        again for those still unanswered ``retries`` times, ``timeout_s`` each. A name the vehicle says it does not
        have (PARAM_ERROR) or never answers is left out of the result. Other messages received meanwhile stay
        queued for :meth:`recv`."""
        values: dict[str, float] = {}
        refused: set[str] = set()
        skipped: list[tuple[Message, float]] = []
        try:
            for _ in range(max(1, retries)):
                asked = [n for n in names if n not in values and n not in refused]
                if not asked:
                    break
                for name in asked:
                    self.send(
                        self.mav.param_request_read_encode(
                            self.target_system, self.target_component, name.encode("ascii"), -1
                        )
                    )
                deadline = time.monotonic() + timeout_s
                while any(n not in values and n not in refused for n in asked) and (
                    (remaining := deadline - time.monotonic()) > 0.0
                ):
                    msg = self.recv(remaining)
                    if msg is None:
                        continue
                    kind = msg.get_type() if self.from_vehicle(msg) else None
                    if kind == "PARAM_VALUE" and msg.param_id in asked:
                        values[msg.param_id] = float(msg.param_value)
                    elif kind == "PARAM_ERROR" and msg.param_id in asked:
                        refused.add(msg.param_id)
                    else:
                        skipped.append((msg, self.last_rx_s))
        finally:
            self._push_back(skipped)
        return values

    def _ack_for_us(self, ack: Message) -> bool:
        # MAVLink 2 COMMAND_ACK carries target fields; an autopilot that leaves them 0 addresses everyone.
        ts = getattr(ack, "target_system", 0)
        tc = getattr(ack, "target_component", 0)
        return ts in (0, self.mav.srcSystem) and tc in (0, self.mav.srcComponent)

    # ------------------------------------------------------------------------------ misc

    def _log_frame(self, frame: bytes) -> None:
        if self._tlog is None:
            return
        stamp_us = int(time.time() * units.US_PER_S) & ~3
        try:
            self._tlog.write(struct.pack(">Q", stamp_us) + frame)
            now = time.monotonic()
            if now - self._tlog_flushed > _TLOG_FLUSH_S:
                self._tlog.flush()
                self._tlog_flushed = now
        except OSError as exc:
            self._tlog_failed(exc)
            self._close_tlog()

    def _close_tlog(self) -> None:
        if self._tlog is not None:
            tlog, self._tlog = self._tlog, None
            try:
                tlog.close()  # writes what is buffered: it fails too on a full disk
            except OSError as exc:
                self._tlog_failed(exc)

    def _tlog_failed(self, exc: OSError) -> None:
        """The tlog lost data: logged, and kept in :attr:`tlog_error` for the run's status (the flight goes on)."""
        if self.tlog_error is None:
            self.tlog_error = f"tlog {self._tlog_path} cut: {exc.strerror or exc}"
            _log.error("%s; not written any more", self.tlog_error)

    @staticmethod
    def _warn_rate_limited(what: str, count: int, exc: OSError) -> None:
        if count in (1, 10, 100, 1000) or count % 10000 == 0:
            _log.warning("%s failed (%d so far): %s", what, count, exc)

    def close(self) -> None:
        """Close the socket and the tlog (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._close_transport()
        self._close_tlog()

    def _close_transport(self) -> None:
        if self._serial is not None:
            self._serial.close()
        else:
            self._sock.close()

    def __enter__(self) -> MavLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _command_name(command: int) -> str:
    entry = M.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"command {command}"


def _result_name(result: int) -> str:
    entry = M.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else str(result)
