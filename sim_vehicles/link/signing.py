"""MAVLink 2 message signing on the vehicle: the key file and the signing of what it sends.

Key file (``--signing-key FILE``, read by :func:`tssac_core.wire.signing.load_key`): either exactly 32 raw bytes, or
64 hexadecimal characters (surrounding whitespace and a trailing newline allowed). MAVProxy's ``signing setup
PASSPHRASE`` uses ``sha256(PASSPHRASE)`` as the key, so ``python -c "import hashlib;
print(hashlib.sha256(b'PASSPHRASE').hexdigest())" > key.hex`` makes a file that matches it.

With a key the vehicle signs everything it sends (:func:`enable_signing`: the same
:class:`MAVLinkSigning` fields ``mavfile.setup_signing`` sets, link id 0) and accepts only correctly
signed, fresh messages, checked by :class:`tssac_core.wire.signing.SignatureVerifier` in
:mod:`sim_vehicles.link.mavlink_io` (signature first, then the timestamp). Unsigned HEARTBEAT and
RADIO_STATUS (:data:`MONITOR_IDS`) are accepted only from passive monitors and only when the run allows
them (``--unsigned-monitors``); rejections are counted by kind in :class:`sim_vehicles.link.mavlink_io.RxCounters`.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from tssac_core.wire.signing import KEY_LEN, SigningKeyError, now_10us

MONITOR_IDS = frozenset({mavlink2.MAVLINK_MSG_ID_HEARTBEAT, mavlink2.MAVLINK_MSG_ID_RADIO_STATUS})
"""Message ids a passive monitor may send unsigned while signing is on (when the run allows monitors)."""


def enable_signing(mav: mavlink2.MAVLink, key: bytes, link_id: int = 0, now_unix_s: float | None = None) -> None:
    """Sign outgoing messages with ``key`` (what ``mavfile.setup_signing`` does for the sending side)."""
    if len(key) != KEY_LEN:
        raise SigningKeyError(f"signing key must be {KEY_LEN} bytes, got {len(key)}")
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.allow_unsigned_callback = None
    mav.signing.link_id = link_id
    mav.signing.timestamp = now_10us(now_unix_s)
