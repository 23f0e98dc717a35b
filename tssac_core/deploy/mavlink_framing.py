"""Finding the MAVLink frames in one UDP datagram: one scanner for both ends of our links.

The SITL vehicles (``sim_vehicles.mavlink_io``) and the companions (``mavlink_bridge.link``) split every
datagram with :func:`scan_frames` and only then verify (signing) and decode (pymavlink) each frame, so the
same bytes give the same frames on both sides. A candidate frame is a start byte (0xFD MAVLink 2, 0xFE
MAVLink 1) whose header gives a length that fits in the datagram, whose message id the dialect knows and
whose CRC (with the message's CRC_EXTRA) matches. Anything else is not a frame: the scan goes on from the
next byte, so a valid frame behind a garbage header in the same datagram is still found, and a frame of an
unknown message id is dropped (its CRC cannot be checked, so neither can its length: it may be garbage
claiming a long frame over the next real one). UDP keeps datagram boundaries: a frame cut off by the end of
its datagram is dropped, never joined to the next datagram.

Pure standard library: the caller passes the dialect (its CRC_EXTRA table and the CRC-16/MCRF4XX function),
so tssac_core imports no pymavlink.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

__all__ = ["Dialect", "Scan", "scan_frames"]

MAGIC_V1, MAGIC_V2 = 0xFE, 0xFD
HEADER_LEN_V1, HEADER_LEN_V2 = 6, 10
"""Bytes before the payload, start byte included."""
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
_START_BYTES = (bytes((MAGIC_V2,)), bytes((MAGIC_V1,)))


@dataclass(frozen=True)
class Dialect:
    """What framing needs from a MAVLink dialect."""

    crc_extras: Mapping[int, int]
    """Message id -> CRC_EXTRA, for every message the dialect knows."""
    crc16: Callable[[bytes], int]
    """CRC-16/MCRF4XX of a byte string (MAVLink's X.25 checksum)."""


@dataclass
class Scan:
    """The frames of one datagram, in order, and what was not a frame."""

    frames: list[bytes] = field(default_factory=list)
    garbage_bytes: int = 0
    """Bytes skipped outside any candidate frame (including impossible headers)."""
    truncated: int = 0
    """Candidate frames cut off by the end of the datagram."""
    unknown_id: int = 0
    """Candidate frames of a message id the dialect does not know."""
    bad_crc: int = 0


def scan_frames(data: bytes, dialect: Dialect) -> Scan:
    """Every frame in ``data`` whose header, message id and CRC check out (module docstring)."""
    out = Scan()
    i, n = 0, len(data)
    while i < n:
        if data[i] not in (MAGIC_V2, MAGIC_V1):
            j = _next_start(data, i + 1)
            out.garbage_bytes += j - i
            i = j
            continue
        size = frame_size(data, i)
        if size is None:  # impossible header: not a frame start
            out.garbage_bytes += 1
            i += 1
            continue
        if i + size > n:
            out.truncated += 1
            i += 1  # it may be garbage that happens to hold a start byte: rescan past it
            continue
        frame = data[i : i + size]
        crc_extra = dialect.crc_extras.get(message_id(frame))
        if crc_extra is None:
            out.unknown_id += 1
            i += 1
            continue
        if not _crc_ok(frame, crc_extra, dialect):
            out.bad_crc += 1
            i += 1
            continue
        out.frames.append(frame)
        i += size
    return out


def frame_size(data: bytes, i: int) -> int | None:
    """Total length of the frame starting at ``data[i]`` from its header, None if the header is impossible.

    A header cut off by the end of the datagram reports the minimum length, so it counts as truncated.
    """
    if data[i] == MAGIC_V2:
        if i + 3 > len(data):
            return HEADER_LEN_V2 + 2
        length, incompat = data[i + 1], data[i + 2]
        if incompat & ~IFLAG_SIGNED:
            return None
        return HEADER_LEN_V2 + length + 2 + (SIGNATURE_LEN if incompat & IFLAG_SIGNED else 0)
    if i + 2 > len(data):
        return HEADER_LEN_V1 + 2
    return HEADER_LEN_V1 + data[i + 1] + 2


def message_id(frame: bytes) -> int:
    """The message id in a frame's header."""
    return frame[7] | (frame[8] << 8) | (frame[9] << 16) if frame[0] == MAGIC_V2 else frame[5]


def source(frame: bytes) -> tuple[int, int]:
    """The sender's (system id, component id) in a frame's header."""
    return (frame[5], frame[6]) if frame[0] == MAGIC_V2 else (frame[3], frame[4])


def _crc_ok(frame: bytes, crc_extra: int, dialect: Dialect) -> bool:
    """The frame's checksum (header after the start byte, payload, CRC_EXTRA) matches."""
    signed = frame[0] == MAGIC_V2 and bool(frame[2] & IFLAG_SIGNED)
    end = len(frame) - (SIGNATURE_LEN if signed else 0)
    return dialect.crc16(bytes(frame[1 : end - 2]) + bytes((crc_extra,))) == struct.unpack_from("<H", frame, end - 2)[0]


def _next_start(data: bytes, start: int) -> int:
    """Index of the next MAVLink start byte at or after ``start`` (len(data) if none)."""
    found = [k for k in (data.find(b, start) for b in _START_BYTES) if k >= 0]
    return min(found) if found else len(data)
