"""One vehicle's MAVLink 2 endpoint on UDP: socket, framing, signing checks, peers.

:class:`MavEndpoint` wraps a UDP socket bound like pymavlink's ``udpin:HOST:PORT`` and pymavlink's
MAVLink protocol object (dialect ardupilotmega, wire protocol 2.0). It does not use
``mavutil.mavudp`` because the vehicle needs what that class hides: the sender of every datagram
(peers are learned only from datagrams holding a valid message, and forgotten after
:data:`PEER_TIMEOUT_S` of silence), per-datagram framing (UDP keeps
datagram boundaries, so a truncated frame must not swallow the next datagram), a bind that fails
when the port is taken (``mavudp`` sets SO_REUSEADDR), and socket errors counted rather than
swallowed.

Every datagram is split into frames here; a frame is decoded only if its CRC (with the message's
CRC_EXTRA) matches. Garbage bytes, truncated frames, bad CRCs, unknown message ids, unsigned,
wrongly signed and replayed messages are dropped and counted in :class:`RxCounters`; nothing that
arrives on the socket can raise out of :meth:`MavEndpoint.parse`.
"""

from __future__ import annotations

import errno
import logging
import socket
import struct
import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles import signing

_log = logging.getLogger(__name__)

Address = tuple[str, int]
MAX_DATAGRAM = 65535
RCVBUF_BYTES = 1 << 20
PEER_TIMEOUT_S = 30.0
"""A client silent this long (wall clock) is forgotten; ground stations and companions send at 1 Hz or more."""
_V1, _V2 = mavlink2.PROTOCOL_MARKER_V1, mavlink2.PROTOCOL_MARKER_V2
_SIG_LEN = mavlink2.MAVLINK_SIGNATURE_BLOCK_LEN
_IFLAG_SIGNED = mavlink2.MAVLINK_IFLAG_SIGNED


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
    unsigned_rejected: int = 0
    bad_signature: int = 0
    replayed: int = 0
    """Signed frames whose timestamp is not newer than their stream's (or too old for a new stream)."""
    decode_errors: int = 0
    socket_errors: int = 0

    @property
    def rejected(self) -> int:
        """Frames dropped for any reason (for SYS_STATUS.errors_comm)."""
        return self.truncated + self.bad_crc + self.unknown_id + self.unsigned_rejected + self.bad_signature + self.replayed + self.decode_errors


@dataclass
class TxCounters:
    """Outgoing traffic of one endpoint."""

    packets: int = 0
    """Datagrams handed to the socket (one per peer)."""
    bytes: int = 0
    socket_errors: int = 0


class EndpointError(OSError):
    """The endpoint could not be opened (e.g. the port is in use); ``str()`` is one line."""


class MavEndpoint:
    """A MAVLink system's UDP endpoint: bind, receive, frame + decode, encode, send to peers."""

    def __init__(self, host: str, port: int, sysid: int, compid: int, signing_key: bytes | None = None) -> None:
        self.sysid = sysid
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
        self.signing = signing_key is not None
        if signing_key is not None:
            signing.enable_signing(self.mav, signing_key)
        self.peers: dict[Address, float] = {}
        """Clients, by address: time.monotonic() of their last valid message."""
        self.rx = RxCounters()
        self.tx = TxCounters()
        self._closed = False

    # ------------------------------------------------------------------------------------ socket

    def fileno(self) -> int:
        return self._sock.fileno()

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
        """Send one datagram to ``dest``, or to every known peer if None."""
        targets = list(self.peers) if dest is None else [dest]
        for addr in targets:
            try:
                self._sock.sendto(data, addr)
            except OSError as exc:
                self.tx.socket_errors += 1
                if self.tx.socket_errors in (1, 10, 100, 1000) or self.tx.socket_errors % 10000 == 0:
                    _log.warning("sysid %d: sendto %s failed (%d so far): %s", self.sysid, addr, self.tx.socket_errors, exc)
                continue
            self.tx.packets += 1
            self.tx.bytes += len(data)

    def expire_peers(self, now_wall_s: float, timeout_s: float = PEER_TIMEOUT_S) -> None:
        """Forget clients that sent nothing valid for ``timeout_s`` wall seconds (they stop getting telemetry)."""
        for addr, last in list(self.peers.items()):
            if now_wall_s - last > timeout_s:
                del self.peers[addr]
                _log.info("sysid %d: peer %s:%d silent for %.0f s, forgotten", self.sysid, addr[0], addr[1], now_wall_s - last)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._sock.close()

    # ---------------------------------------------------------------------------------- encoding

    def encode(self, msg: mavlink2.MAVLink_message) -> bytes:
        """Pack (and sign, if signing is on) one message from this system."""
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.mav.total_packets_sent += 1
        self.mav.total_bytes_sent += len(buf)
        return buf

    def parse(self, data: bytes, addr: Address) -> list[mavlink2.MAVLink_message]:
        """Decode every valid frame of one datagram; learn ``addr`` as a peer if any was valid."""
        self.rx.datagrams += 1
        msgs: list[mavlink2.MAVLink_message] = []
        i, n = 0, len(data)
        while i < n:
            magic = data[i]
            if magic != _V2 and magic != _V1:
                j = _next_magic(data, i + 1)
                self.rx.garbage_bytes += j - i
                i = j
                continue
            size = _frame_size(data, i)
            if size is None:  # impossible header: not a frame start
                self.rx.garbage_bytes += 1
                i += 1
                continue
            if i + size > n:
                self.rx.truncated += 1
                i += 1  # it may be garbage that happens to hold a magic byte: rescan past it
                continue
            frame = data[i : i + size]
            verdict = self._check_frame(frame)
            if verdict == "bad_crc":
                self.rx.bad_crc += 1
                i += 1
                continue
            i += size
            if verdict != "ok":
                continue
            msg = self._decode(frame)
            if msg is not None:
                msgs.append(msg)
        if msgs:
            if addr not in self.peers:
                _log.info("sysid %d: new peer %s:%d", self.sysid, addr[0], addr[1])
            self.peers[addr] = time.monotonic()
        self.rx.messages += len(msgs)
        return msgs

    def _check_frame(self, frame: bytes) -> str:
        """'ok', 'bad_crc', or the name of the counter already incremented for a rejected frame."""
        signed = frame[0] == _V2 and bool(frame[2] & _IFLAG_SIGNED)
        msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16) if frame[0] == _V2 else frame[5]
        msg_type = mavlink2.mavlink_map.get(msg_id)
        if msg_type is None:
            self.rx.unknown_id += 1
            return "unknown_id"
        end = len(frame) - (_SIG_LEN if signed else 0)
        crc = mavlink2.x25crc(bytes(frame[1 : end - 2]))
        crc.accumulate(bytes((msg_type.crc_extra,)))
        if crc.crc != struct.unpack_from("<H", frame, end - 2)[0]:
            return "bad_crc"
        if self.signing:
            if not signed:
                if not signing.allow_unsigned(self.mav, msg_id):
                    self.rx.unsigned_rejected += 1
                    return "unsigned_rejected"
            elif signing.is_replay(self.mav, frame):
                self.rx.replayed += 1
                return "replayed"
        return "ok"

    def _decode(self, frame: bytes) -> mavlink2.MAVLink_message | None:
        signed = frame[0] == _V2 and bool(frame[2] & _IFLAG_SIGNED)
        stream_key = signing.signature_stream(frame)[0] if (signed and self.signing) else None
        saved = self.mav.signing.stream_timestamps.get(stream_key) if stream_key is not None else None
        try:
            return self.mav.decode(bytearray(frame))
        except mavlink2.MAVError:
            if stream_key is not None:
                self.rx.bad_signature += 1
                # pymavlink records a stream's timestamp before it checks the signature; undo that, so a
                # forged frame with a far-future timestamp cannot lock the real sender out.
                if saved is None:
                    self.mav.signing.stream_timestamps.pop(stream_key, None)
                else:
                    self.mav.signing.stream_timestamps[stream_key] = saved
            else:
                self.rx.decode_errors += 1
            return None
        except Exception as exc:  # a pymavlink bug on hostile input must not take the vehicle down
            self.rx.decode_errors += 1
            _log.warning("sysid %d: pymavlink failed to decode a frame: %r", self.sysid, exc)
            return None


def _next_magic(data: bytes, start: int) -> int:
    """Index of the next MAVLink start byte at or after ``start`` (len(data) if none)."""
    a, b = data.find(bytes((_V2,)), start), data.find(bytes((_V1,)), start)
    if a < 0:
        return b if b >= 0 else len(data)
    return a if b < 0 else min(a, b)


def _frame_size(data: bytes, i: int) -> int | None:
    """Total length of the frame starting at ``data[i]`` from its header, None if the header is invalid.

    A header cut off by the end of the datagram reports the minimum length, so it counts as truncated.
    """
    if data[i] == _V2:
        if i + 3 > len(data):
            return mavlink2.HEADER_LEN_V2 + 2
        length, incompat = data[i + 1], data[i + 2]
        if incompat & ~_IFLAG_SIGNED:
            return None
        return mavlink2.HEADER_LEN_V2 + length + 2 + (_SIG_LEN if incompat & _IFLAG_SIGNED else 0)
    if i + 2 > len(data):
        return mavlink2.HEADER_LEN_V1 + 2
    return mavlink2.HEADER_LEN_V1 + data[i + 1] + 2
