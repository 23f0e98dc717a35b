"""MAVLink 2 message signing checked in the right order: signature first, then the timestamp.

Both ends of our links (the SITL vehicles in ``sim_vehicles``, the companions in ``mavlink_bridge``)
verify incoming frames with :class:`SignatureVerifier` instead of pymavlink's
``MAVLink.check_signature``. pymavlink 2.4 records a stream's timestamp *before* it compares the
signature (``signing.stream_timestamps[stream_key] = timestamp`` precedes the SHA-256 check in the
generated ``check_signature``), and its ``allow_unsigned_callback`` then lets a wrongly signed
HEARTBEAT through: one forged frame with a far-future timestamp on a legitimate stream makes every
later genuine frame of that stream look like a replay. Here a frame's timestamp is believed only after
its signature verifies, so a frame without the key changes nothing.

The wire format (MAVLink 2 signing, https://mavlink.io/en/guide/message_signing.html): a signed frame
ends in a 13-byte block ``link_id (1) | timestamp (6, little-endian, 10 us units since 2015-01-01) |
signature (6)``, with ``signature = SHA-256(key + frame[:-6])[:6]``. A *stream* is (link id, system id,
component id); a frame is fresh if its timestamp is newer than the stream's last accepted one, or, for a
stream not seen yet, no more than one minute older than our clock (MAVLink's rule; pymavlink's
constant). This module uses the wall clock for that (``time.time()``), and the senders here keep their
outgoing timestamps at or above the wall clock (:func:`refresh_outgoing_timestamp`), so a stream that
has been sending for hours is still "new-stream fresh" for a client that joins late.

Receivers that share a key and a process (the three vehicles of one SITL) share one table (``shared``): per
stream, the newest timestamp any of them accepted and the address it came from. A frame is fresh at a receiver
only if it is not older than that, and a frame no newer than it must come from that same address: the sender's
own fan-out of one frame to several vehicles (one socket, one address) passes, while the same frame from anyone
else is a replay at every receiver, at once or later. A sender that comes back from a new address takes its stream
with its next, newer frame. What binds a companion's frames to its vehicle besides is its link id
(:func:`companion_link_id`), which the other vehicles refuse.

Pure standard library (hashlib, hmac, struct): tssac_core imports no pymavlink, and both sides, which
never import each other, share this one implementation.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct
import time
from collections.abc import Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

__all__ = [
    "COMPANION_LINK_BASE",
    "KEY_LEN",
    "NEW_STREAM_MAX_AGE_10US",
    "SIGNATURE_BLOCK_LEN",
    "SignatureVerifier",
    "SigningCounters",
    "StreamKey",
    "Verdict",
    "companion_link_id",
    "is_signed",
    "now_10us",
    "refresh_outgoing_timestamp",
    "signature_stream",
]

KEY_LEN = 32
SIGNATURE_BLOCK_LEN = 13
"""link id (1) + timestamp (6) + signature (6)."""
NEW_STREAM_MAX_AGE_10US = 6000 * 1000
"""A stream's first frame may be this far behind our clock: one minute (MAVLink's rule)."""
EPOCH_2015_UNIX_S = 1420070400
COMPANION_LINK_BASE = 200
"""Link ids from here on name a companion's vehicle: the companion of system N signs on link id 200 + N."""
_MAGIC_V2 = 0xFD
_IFLAG_SIGNED = 0x01
_HEADER_LEN_V2 = 10

StreamKey = tuple[int, int, int]
"""(link id, system id, component id)."""


class Verdict(enum.Enum):
    """What :meth:`SignatureVerifier.check` concluded about one frame."""

    OK = "ok"
    UNSIGNED = "unsigned"
    BAD_SIGNATURE = "bad_signature"
    REPLAYED = "replayed"
    """Correctly signed, but not newer than its stream's last frame (or too old for a new stream)."""


@dataclass
class SigningCounters:
    """Frames checked, by verdict."""

    ok: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0


class SigningKeyError(ValueError):
    """A key file that cannot be used; ``str()`` is one line."""


def load_key(path: str | Path) -> bytes:
    """Read a signing key file, the one format of the SITL and the companion: exactly 32 raw bytes, or 64 hexadecimal
    characters (surrounding whitespace and a trailing newline allowed)."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise SigningKeyError(f"signing key {path}: cannot read file ({exc.strerror or exc})") from None
    if len(data) == KEY_LEN:
        return data
    text = data.strip()
    if len(text) == 2 * KEY_LEN:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise SigningKeyError(f"signing key {path}: expected 32 raw bytes or 64 hex characters, got {len(data)} bytes")


def now_10us(now_unix_s: float | None = None) -> int:
    """The signing clock: 10 us units since 2015-01-01 (0 before that)."""
    t = time.time() if now_unix_s is None else now_unix_s
    return int((max(t, EPOCH_2015_UNIX_S) - EPOCH_2015_UNIX_S) * 100_000)


class _SigningState(Protocol):
    timestamp: int


def companion_link_id(vehicle_sysid: int) -> int:
    """The link id the companion of vehicle ``vehicle_sysid`` (1..55) signs on; every other vehicle refuses it."""
    if not 1 <= vehicle_sysid <= 255 - COMPANION_LINK_BASE:
        raise ValueError(f"companion link ids exist for vehicle system ids 1..{255 - COMPANION_LINK_BASE}")
    return COMPANION_LINK_BASE + vehicle_sysid


def refresh_outgoing_timestamp(signing: _SigningState) -> None:
    """Keep a pymavlink ``MAVLinkSigning.timestamp`` at or above the wall clock before packing a frame.

    pymavlink only adds 1 (10 us) per frame it signs, so after a minute of sending fewer than 100,000
    frames per second a sender's stream falls more than a minute behind real time, and a receiver
    that joins then refuses it as a stale new stream.
    """
    now = now_10us()
    if signing.timestamp < now:
        signing.timestamp = now


def is_signed(frame: bytes | bytearray) -> bool:
    """A MAVLink 2 frame with the SIGNED incompatibility flag."""
    return len(frame) >= 3 and frame[0] == _MAGIC_V2 and bool(frame[2] & _IFLAG_SIGNED)


def signature_stream(frame: bytes | bytearray) -> tuple[StreamKey, int]:
    """(stream key, timestamp in 10 us units) of a signed MAVLink 2 frame."""
    link_id = frame[-SIGNATURE_BLOCK_LEN]
    lo, hi = struct.unpack_from("<IH", frame, len(frame) - 12)
    return (link_id, frame[5], frame[6]), lo | (hi << 32)


class SignatureVerifier:
    """Checks signed MAVLink 2 frames against one key; remembers each stream's newest verified timestamp.

    Streams enter the table only with a verified signature, so only holders of the key can grow it
    (at most 256 link ids x 255 x 255 ids, each an int: no bound is needed against outsiders).
    """

    def __init__(self, key: bytes, shared: dict[StreamKey, tuple[int, Hashable]] | None = None) -> None:
        if len(key) != KEY_LEN:
            raise ValueError(f"signing key must be {KEY_LEN} bytes, got {len(key)}")
        self._key = bytes(key)
        self._keyed = hashlib.sha256(self._key)
        """SHA-256 with the key already absorbed (copied for every frame)."""
        self.streams: dict[StreamKey, int] = {}
        """Newest verified timestamp per stream."""
        self.shared = shared
        """Per stream, the newest timestamp accepted by any verifier given the same dict and the address it came from
        (module docstring)."""
        self.counters = SigningCounters()

    def signature_ok(self, frame: bytes | bytearray) -> bool:
        """The frame is signed and its signature is this key's (no state is read or changed)."""
        return is_signed(frame) and self._signed_by_key(frame)

    def _signed_by_key(self, frame: bytes | bytearray) -> bool:
        """A frame flagged as signed carries this key's signature, ``SHA-256(key + frame[:-6])[:6]``."""
        if len(frame) < _HEADER_LEN_V2 + 2 + SIGNATURE_BLOCK_LEN:
            return False
        h = self._keyed.copy()
        h.update(frame[:-6])
        return hmac.compare_digest(h.digest()[:6], frame[-6:])

    def check(self, frame: bytes | bytearray, now_unix_s: float | None = None, sender: Hashable = None) -> Verdict:
        """Verify one whole frame (CRC already checked) that came from ``sender`` (its address; with a shared table,
        a frame no newer than the stream's newest must come from where that did); on OK the stream moves forward."""
        if not is_signed(frame):
            self.counters.unsigned += 1
            return Verdict.UNSIGNED
        if not self._signed_by_key(frame):  # one is_signed per frame: signature_ok would ask again
            self.counters.bad_signature += 1
            return Verdict.BAD_SIGNATURE
        # Only now, with the signature verified, is the timestamp worth anything.
        stream, stamp = signature_stream(frame)
        if not (self._fresh(stream, stamp, now_unix_s) and self._from_its_sender(stream, stamp, sender)):
            self.counters.replayed += 1
            return Verdict.REPLAYED
        self.streams[stream] = stamp
        if self.shared is not None and stamp > self.shared.get(stream, (-1, None))[0]:
            self.shared[stream] = (stamp, sender)
        self.counters.ok += 1
        return Verdict.OK

    def _fresh(self, stream: StreamKey, stamp: int, now_unix_s: float | None) -> bool:
        """Newer than the stream's last frame here; for a stream new here, at most a minute old and not older
        than the newest frame of the stream that a verifier sharing the table has accepted."""
        last = self.streams.get(stream)
        if last is not None:
            return stamp > last
        if self.shared is not None and stamp < self.shared.get(stream, (0, None))[0]:
            return False
        return stamp + NEW_STREAM_MAX_AGE_10US >= now_10us(now_unix_s)

    def _from_its_sender(self, stream: StreamKey, stamp: int, sender: Hashable) -> bool:
        """A frame no newer than the newest of its stream in the shared table comes from the address that one came
        from: the same frame delivered by anyone else (captured on its way to one vehicle, sent to another) is a
        replay, however soon."""
        if self.shared is None or stream not in self.shared:
            return True
        newest, owner = self.shared[stream]
        return stamp > newest or sender == owner
