"""MAVLink 2 message signing: the key file, the vehicle's signing state and replay detection.

Key file (``--signing-key FILE``): either exactly 32 raw bytes, or 64 hexadecimal characters (surrounding
whitespace and a trailing newline allowed). MAVProxy's ``signing setup PASSPHRASE`` uses
``sha256(PASSPHRASE)`` as the key, so ``python -c "import hashlib;print(hashlib.sha256(b'PASSPHRASE').hexdigest())" > key.hex``
makes a file that matches it.

With a key the vehicle signs everything it sends and accepts only correctly signed, fresh messages;
HEARTBEAT and RADIO_STATUS may arrive unsigned (as PX4 allows, so radios and passive monitors
still work). Rejections are counted by kind in :class:`sim_vehicles.mavlink_io.RxCounters`.

The vehicle does not use a ``mavutil`` connection (see :mod:`sim_vehicles.mavlink_io`), so
:func:`enable_signing` sets the same :class:`MAVLinkSigning` fields that ``mavfile.setup_signing``
sets: key, sign_outgoing, allow_unsigned_callback, link_id and the initial timestamp (10 us units
since 2015-01-01).
"""

from __future__ import annotations

import struct
import time
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

KEY_LEN = 32
ALLOWED_UNSIGNED_IDS = frozenset({mavlink2.MAVLINK_MSG_ID_HEARTBEAT, mavlink2.MAVLINK_MSG_ID_RADIO_STATUS})
"""Message ids accepted without a signature while signing is on."""
_EPOCH_2015_S = 1420070400
NEW_STREAM_MAX_AGE_10US = 6000 * 1000
"""pymavlink accepts a new stream's first timestamp if it is at most one minute behind ours."""


class SigningKeyError(ValueError):
    """A key file that cannot be used; ``str()`` is one line."""


def load_key(path: str | Path) -> bytes:
    """Read a signing key file: 32 raw bytes or 64 hex characters."""
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


def allow_unsigned(_mav: mavlink2.MAVLink, msg_id: int) -> bool:
    """pymavlink's allow_unsigned_callback: only HEARTBEAT and RADIO_STATUS pass unsigned."""
    return msg_id in ALLOWED_UNSIGNED_IDS


def enable_signing(mav: mavlink2.MAVLink, key: bytes, link_id: int = 0, now_unix_s: float | None = None) -> None:
    """Sign outgoing messages with ``key`` and check incoming ones (what ``mavfile.setup_signing`` does)."""
    if len(key) != KEY_LEN:
        raise SigningKeyError(f"signing key must be {KEY_LEN} bytes, got {len(key)}")
    now = time.time() if now_unix_s is None else now_unix_s
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.allow_unsigned_callback = allow_unsigned
    mav.signing.link_id = link_id
    mav.signing.timestamp = int((max(now, _EPOCH_2015_S) - _EPOCH_2015_S) * 100 * 1000)


def signature_stream(frame: bytes | bytearray) -> tuple[tuple[int, int, int], int]:
    """(stream key (link_id, sysid, compid), timestamp in 10 us units) of a signed MAVLink 2 frame."""
    sysid, compid = frame[5], frame[6]
    link_id = frame[-13]
    lo, hi = struct.unpack("<IH", bytes(frame[-12:-6]))
    return (link_id, sysid, compid), lo + (hi << 32)


def is_replay(mav: mavlink2.MAVLink, frame: bytes | bytearray) -> bool:
    """True if a signed frame's timestamp is not newer than its stream's last one (or too old for a new stream)."""
    key, stamp = signature_stream(frame)
    last = mav.signing.stream_timestamps.get(key)
    if last is not None:
        return stamp <= last
    return stamp + NEW_STREAM_MAX_AGE_10US < mav.signing.timestamp
