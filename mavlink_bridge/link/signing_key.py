"""MAVLink 2 signing keys as the command lines take them (the same file format as the SITL's)."""

from __future__ import annotations

from pathlib import Path

from tssac_core.common.cli import UsageError
from tssac_core.wire.signing import SigningKeyError, load_key


def read_signing_key(path: Path) -> bytes:
    """A key file in the wire's one format (:func:`tssac_core.wire.signing.load_key`); UsageError otherwise."""
    try:
        return load_key(path)
    except SigningKeyError as exc:
        raise UsageError(str(exc)) from None
