"""One vehicle's MAVLink 2 endpoint on UDP: socket, framing, signing checks, clients.

:class:`MavEndpoint` wraps a UDP socket bound like pymavlink's ``udpin:HOST:PORT`` and two pymavlink
MAVLink protocol objects (dialect ardupilotmega, wire protocol 2.0): one that packs (and signs) what the
vehicle sends, one without a key that only decodes frames already checked here. It does not use
``mavutil.mavudp`` because the vehicle needs what that class hides: the sender of every datagram
(clients are learned only from datagrams holding an accepted message, and forgotten after
:data:`PEER_TIMEOUT_S` of silence), per-datagram framing (UDP keeps datagram boundaries, so a truncated
frame must not swallow the next datagram), a bind that fails when the port is taken (``mavudp`` sets
SO_REUSEADDR), and socket errors counted rather than swallowed.

Every datagram is split into frames by :func:`tssac_core.wire.framing.scan_frames` (the companion's
link uses the same scanner); a frame is decoded only if its CRC (with the message's CRC_EXTRA) matches and,
with signing, its signature verifies
(:class:`tssac_core.wire.signing.SignatureVerifier`:
signature first, then the stream's timestamp — pymavlink's own check records the timestamp first).
Garbage bytes, truncated frames, bad CRCs, unknown message ids, unsigned, wrongly signed and replayed
messages are dropped and counted in :class:`RxCounters`; a header that does not check out (unknown id,
bad CRC, cut off) is rescanned from its next byte, so a valid frame behind it in the same datagram is
still found. Nothing that arrives on the socket can raise out of :meth:`MavEndpoint.parse`.

Who gets telemetry:

* **clients** (:attr:`MavEndpoint.peers`): senders of an accepted message — with signing, a correctly
  signed, fresh one; without signing, any valid one. At most :data:`MAX_PEERS` at once.
* **monitors** (:attr:`MavEndpoint.monitors`, only with signing and ``unsigned_monitors``): senders of an
  *unsigned* HEARTBEAT or RADIO_STATUS, the passive displays and radios PX4 lets in. At most
  :data:`MAX_MONITORS`, each with a telemetry budget of :data:`MONITOR_BYTES_PER_S` (what does not fit
  is not sent to it, counted). Off by default: with signing on and default settings, a client is made only
  by a correctly signed, fresh frame from the address its stream's newest frame came from (a replay, to this
  vehicle or another of the run, makes none: :class:`tssac_core.wire.signing.SignatureVerifier`). A wrongly
  signed frame is never a monitor's: it is refused.
"""

from __future__ import annotations

import enum
import errno
import logging
import socket
import time
from collections.abc import Hashable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.link import signing
from tssac_core.wire.framing import (
    Dialect,
    FrameDecoder,
    FramePacker,
    message_id,
    scan_frames,
    source,
)
from tssac_core.wire.signing import (
    COMPANION_LINK_BASE,
    SIGNATURE_BLOCK_LEN,
    SignatureVerifier,
    StreamKey,
    Verdict,
    companion_link_id,
    is_signed,
    refresh_outgoing_timestamp,
)

_log = logging.getLogger(__name__)

Address = tuple[str, int]
MAX_DATAGRAM = 65535
RCVBUF_BYTES = 1 << 20
PEER_TIMEOUT_S = 30.0
"""A client silent this long (wall clock) is forgotten; ground stations and companions send at 1 Hz or more."""
MAX_PEERS = 16
"""Clients served at once; a new one beyond this is refused (counted) until another falls silent."""
MAX_MONITORS = 4
"""Unsigned monitors served at once (signing on, ``unsigned_monitors`` set)."""
MONITOR_BYTES_PER_S = 2000
"""Telemetry budget of one unsigned monitor: 1 Hz heartbeat, status and a position, not the 10 Hz streams."""
DIALECT = Dialect.of_messages(mavlink2.mavlink_map)
"""ardupilotmega's message ids and CRC_EXTRAs, for :func:`tssac_core.wire.framing.scan_frames`."""


class Sender(enum.Enum):
    """What a datagram's accepted messages make of its sender."""

    CLIENT = "client"
    """A signed, fresh message (or, without signing, any valid one): full telemetry, commands obeyed."""
    MONITOR = "monitor"
    """Only unsigned HEARTBEAT / RADIO_STATUS under signing, monitors allowed: budgeted telemetry, nothing obeyed."""


@dataclass
class RxCounters:
    """Incoming traffic of one endpoint, by outcome."""

    datagrams: int = 0
    messages: int = 0
    """Frames decoded and handed on."""
    garbage_bytes: int = 0
    """Bytes outside any frame."""
    truncated: int = 0
    """Frames cut off by the end of their datagram."""
    bad_crc: int = 0
    unknown_id: int = 0
    """Frames of message ids the dialect does not know (their CRC cannot be checked)."""
    from_vehicles: int = 0
    """Frames whose header names the autopilot of one of this run's vehicles (system N, component 1: this
    one's own telemetry reflected back, another vehicle's): a vehicle takes nothing from an autopilot. A
    companion on the vehicle's system id with its own component id (191) is a client as any other."""
    wrong_link: int = 0
    """Signed frames on the link id of another vehicle's companion (``companion_link_id``)."""
    unsigned_rejected: int = 0
    bad_signature: int = 0
    replayed: int = 0
    """Signed frames whose timestamp is not newer than their stream's (or too old for a new stream)."""
    monitor_frames: int = 0
    """Unsigned HEARTBEAT / RADIO_STATUS accepted from monitors."""
    decode_errors: int = 0
    socket_errors: int = 0
    peers_refused: int = 0
    """Datagrams from a would-be client or monitor while the table was full."""

    @property
    def rejected(self) -> int:
        """Frames dropped for any reason (for SYS_STATUS.errors_comm)."""
        return (
            self.truncated
            + self.bad_crc
            + self.unknown_id
            + self.from_vehicles
            + self.wrong_link
            + self.unsigned_rejected
            + self.bad_signature
            + self.replayed
            + self.decode_errors
        )


@dataclass
class TxCounters:
    """Outgoing traffic of one endpoint."""

    packets: int = 0
    """Datagrams handed to the socket (one per peer)."""
    bytes: int = 0
    socket_errors: int = 0
    monitor_throttled: int = 0
    """Datagrams not sent to a monitor because its budget was spent."""


@dataclass
class Parsed:
    """The accepted messages of one datagram and what they make of its sender (None: nothing accepted)."""

    messages: list[mavlink2.MAVLink_message] = field(default_factory=list)
    sender: Sender | None = None


@dataclass
class _Monitor:
    last_seen_s: float
    tokens: float = float(MONITOR_BYTES_PER_S)
    refilled_s: float = 0.0


class EndpointError(OSError):
    """The endpoint could not be opened (e.g. the port is in use); ``str()`` is one line."""


class MavEndpoint:
    """A MAVLink system's UDP endpoint: bind, receive, frame + check + decode, encode, send to clients."""

    def __init__(
        self,
        host: str,
        port: int,
        sysid: int,
        compid: int,
        signing_key: bytes | None = None,
        unsigned_monitors: bool = False,
        run_sysids: frozenset[int] = frozenset(),
        shared_streams: dict[StreamKey, tuple[int, Hashable]] | None = None,
    ) -> None:
        """``run_sysids``: the system ids of every vehicle of the run (this one's included); ``shared_streams``:
        one dict for all of them, the signing streams' newest accepted timestamps (see :class:`SignatureVerifier`)."""
        self.sysid = sysid
        self.run_sysids = run_sysids | {sysid}
        self.foreign_links = frozenset(
            companion_link_id(s) for s in self.run_sysids - {sysid} if s <= 255 - COMPANION_LINK_BASE
        )
        """Link ids of the other vehicles' companions: refused here."""
        self.compid = compid
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            what = "is in use" if exc.errno == errno.EADDRINUSE else f"cannot be bound ({exc.strerror or exc})"
            raise EndpointError(exc.errno or 0, f"UDP port {host}:{port} {what}") from None
        self._sock.setblocking(False)
        # Room for bursts (several clients, a ground station's parameter requests); the kernel caps it.
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        self.host, self.port = self._sock.getsockname()[:2]
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        """Holds the sending side's identity, sequence and signing state (what pymavlink's ``pack`` reads); never
        decodes."""
        self._packer = FramePacker(DIALECT.crc16)
        """Packs (and signs) what this system sends: pymavlink's bytes (tests/test_bridge.py), fewer objects."""
        self._decoder = FrameDecoder(mavlink2.mavlink_map, mavlink2.MAVLink_header)
        """Decodes frames this endpoint has already checked: pymavlink's objects (tests/test_bridge.py)."""
        self.verifier: SignatureVerifier | None = None
        if signing_key is not None:
            signing.enable_signing(self.mav, signing_key)
            self.verifier = SignatureVerifier(signing_key, shared_streams)
        self.signing = signing_key is not None
        self.unsigned_monitors = unsigned_monitors and self.signing
        self.peers: dict[Address, float] = {}
        """Clients, by address: time.monotonic() of their last accepted message."""
        self.monitors: dict[Address, _Monitor] = {}
        """Unsigned monitors (signing on, ``unsigned_monitors``), by address."""
        self.rx = RxCounters()
        self.tx = TxCounters()
        self._tx_seq: dict[Address, int] = {}
        """The next sequence number of each destination's link."""
        self._closed = False

    # ------------------------------------------------------------------------------------ socket

    def fileno(self) -> int:
        return self._sock.fileno()

    @property
    def has_clients(self) -> bool:
        """Anyone to send telemetry to (clients or monitors)."""
        return bool(self.peers) or bool(self.monitors)

    def receive(self, max_datagrams: int = 256) -> list[tuple[bytes, Address]]:
        """Drain up to ``max_datagrams`` waiting datagrams (non-blocking)."""
        out: list[tuple[bytes, Address]] = []
        for _ in range(max_datagrams):
            try:
                data, addr = self._sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                # e.g. ECONNREFUSED reported for an earlier sendto to a client that went away
                self.rx.socket_errors += 1
                _log.debug("sysid %d: recvfrom failed: %s", self.sysid, exc)
                continue
            out.append((data, (str(addr[0]), int(addr[1]))))
        return out

    def sendto(self, data: bytes, dest: Address | None = None) -> None:
        """Send one datagram to ``dest``, or to every client and monitor if None (monitors within budget)."""
        targets = self.destinations() if dest is None else [dest]
        for addr in targets:
            monitor = self.monitors.get(addr) if addr not in self.peers else None
            if monitor is not None and not self._spend(monitor, len(data)):
                self.tx.monitor_throttled += 1
                continue
            try:
                self._sock.sendto(data, addr)
            except OSError as exc:
                self.tx.socket_errors += 1
                if self.tx.socket_errors in (1, 10, 100, 1000) or self.tx.socket_errors % 10000 == 0:
                    _log.warning(
                        "sysid %d: sendto %s failed (%d so far): %s", self.sysid, addr, self.tx.socket_errors, exc
                    )
                continue
            self.tx.packets += 1
            self.tx.bytes += len(data)

    @staticmethod
    def _spend(monitor: _Monitor, size: int) -> bool:
        """Token bucket: MONITOR_BYTES_PER_S, at most one second's worth saved up."""
        now = time.monotonic()
        monitor.tokens = min(
            float(MONITOR_BYTES_PER_S), monitor.tokens + (now - monitor.refilled_s) * MONITOR_BYTES_PER_S
        )
        monitor.refilled_s = now
        if size > monitor.tokens:
            return False
        monitor.tokens -= size
        return True

    def admit(self, addr: Address, sender: Sender) -> bool:
        """Record a datagram's sender as a client or monitor; True if it is a new one (it gets a snapshot)."""
        now = time.monotonic()
        if sender is Sender.CLIENT or addr in self.peers:
            if addr in self.peers:
                self.peers[addr] = now
                return False
            if len(self.peers) >= MAX_PEERS:
                self._refuse(addr, "clients")
                return False
            self.peers[addr] = now
            self.monitors.pop(addr, None)
            _log.info("sysid %d: new client %s:%d", self.sysid, addr[0], addr[1])
            return True
        monitor = self.monitors.get(addr)
        if monitor is not None:
            monitor.last_seen_s = now
            return False
        if len(self.monitors) >= MAX_MONITORS:
            self._refuse(addr, "monitors")
            return False
        self.monitors[addr] = _Monitor(last_seen_s=now, refilled_s=now)
        _log.info("sysid %d: new unsigned monitor %s:%d", self.sysid, addr[0], addr[1])
        return True

    def _refuse(self, addr: Address, table: str) -> None:
        self.rx.peers_refused += 1
        if self.rx.peers_refused in (1, 10, 100, 1000) or self.rx.peers_refused % 10000 == 0:
            _log.warning(
                "sysid %d: %s table full, %s:%d refused (%d so far)",
                self.sysid,
                table,
                addr[0],
                addr[1],
                self.rx.peers_refused,
            )

    def expire_peers(self, now_wall_s: float, timeout_s: float = PEER_TIMEOUT_S) -> None:
        """Forget clients and monitors that sent nothing accepted for ``timeout_s`` wall seconds."""
        if self.peers and now_wall_s - min(self.peers.values()) > timeout_s:
            self._expire_clients(now_wall_s, timeout_s)
        if self.monitors:
            for addr, monitor in list(self.monitors.items()):
                if now_wall_s - monitor.last_seen_s > timeout_s:
                    del self.monitors[addr]
        if not self._tx_seq.keys() <= self.peers.keys():  # a link of a client or monitor that is gone
            for addr in [a for a in self._tx_seq if a not in self.peers and a not in self.monitors]:
                del self._tx_seq[addr]

    def _expire_clients(self, now_wall_s: float, timeout_s: float) -> None:
        for addr, last in list(self.peers.items()):
            if now_wall_s - last > timeout_s:
                del self.peers[addr]
                _log.info(
                    "sysid %d: client %s:%d silent for %.0f s, forgotten",
                    self.sysid,
                    addr[0],
                    addr[1],
                    now_wall_s - last,
                )

    def new_session(self) -> None:
        """After a mission reset (a reboot): drop what the socket holds, forget every client and monitor, number
        each link from 0 again and count from 0. The signing streams' timestamps are kept, so that nothing signed
        before the reset can be replayed after it."""
        while self.receive():
            pass
        self.peers.clear()
        self.monitors.clear()
        self._tx_seq.clear()
        self.rx = RxCounters()
        self.tx = TxCounters()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._sock.close()

    # ---------------------------------------------------------------------------------- encoding

    def encode(self, msg: mavlink2.MAVLink_message, dest: Address) -> bytes:
        """Pack (and sign, if signing is on) one message from this system for ``dest``.

        Every destination is a link with its own sequence numbers, one after the other in the order its frames
        are packed (ArduPilot numbers per channel): a client that gets only its own replies and the telemetry
        sees no gap for the replies that went to another client, so a lossless link shows no loss."""
        mav = self.mav
        buf = self._packer.pack(msg, self._next_seq(dest), mav.srcSystem, mav.srcComponent, mav.signing)
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return buf

    def encode_fields(self, cls: type[mavlink2.MAVLink_message], fields: Sequence[Any], dest: Address) -> bytes:
        """:meth:`encode` of ``cls(*fields)`` without the message object (a class without strings and arrays)."""
        mav = self.mav
        buf = self._packer.pack_fields(cls, fields, self._next_seq(dest), mav.srcSystem, mav.srcComponent, mav.signing)
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(buf)
        return buf

    def _next_seq(self, dest: Address) -> int:
        """Take ``dest``'s next sequence number (pymavlink's ``seq`` follows it) and, signing, bring the signing
        timestamp up to the wall clock: what comes before packing a frame."""
        if self.signing:
            refresh_outgoing_timestamp(self.mav.signing)
        seq = self._tx_seq.get(dest, 0)
        self.mav.seq = seq
        self._tx_seq[dest] = (seq + 1) % 256
        return seq

    def destinations(self) -> list[Address]:
        """Everyone telemetry goes to: the clients, then the monitors that are not clients."""
        if not self.monitors:
            return list(self.peers)
        return list(self.peers) + [a for a in self.monitors if a not in self.peers]

    def parse(self, data: bytes, addr: Address) -> Parsed:
        """Check and decode every frame of one datagram (clients are recorded by :meth:`admit`)."""
        self.rx.datagrams += 1
        out = Parsed()
        scan = scan_frames(data, DIALECT)
        self.rx.garbage_bytes += scan.garbage_bytes
        self.rx.truncated += scan.truncated
        self.rx.unknown_id += scan.unknown_id
        self.rx.bad_crc += scan.bad_crc
        for frame in scan.frames:
            verdict = self._check_signing(frame, addr)
            if verdict is None:
                continue
            msg = self._decode(frame)
            if msg is None:
                continue
            out.messages.append(msg)
            if out.sender is not Sender.CLIENT:
                out.sender = verdict
        self.rx.messages += len(out.messages)
        return out

    def _check_signing(self, frame: bytes, addr: Address) -> Sender | None:
        """Whether a whole, CRC-checked frame vouches for a client or a monitor; None: refused (counted)."""
        sysid, compid = source(frame)
        if sysid in self.run_sysids and compid == self.compid:
            self.rx.from_vehicles += 1
            return None
        if self.verifier is None:
            return Sender.CLIENT
        if is_signed(frame) and frame[-SIGNATURE_BLOCK_LEN] in self.foreign_links:
            self.rx.wrong_link += 1
            return None
        verdict = self.verifier.check(frame, sender=addr)
        if verdict is Verdict.OK:
            return Sender.CLIENT
        if verdict is Verdict.UNSIGNED:
            if self.unsigned_monitors and message_id(frame) in signing.MONITOR_IDS:
                self.rx.monitor_frames += 1
                return Sender.MONITOR
            self.rx.unsigned_rejected += 1
        elif verdict is Verdict.BAD_SIGNATURE:
            self.rx.bad_signature += 1
        else:
            self.rx.replayed += 1
        return None

    def _decode(self, frame: bytes) -> mavlink2.MAVLink_message | None:
        try:
            return self._decoder.decode(frame)
        except mavlink2.MAVError:
            self.rx.decode_errors += 1
            return None
        except Exception as exc:  # a pymavlink bug on hostile input must not take the vehicle down
            self.rx.decode_errors += 1
            _log.warning("sysid %d: pymavlink failed to decode a frame: %r", self.sysid, exc)
            return None
