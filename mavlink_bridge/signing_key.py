"""MAVLink 2 signing keys as the command lines take them (the same file format as the SITL's)."""

from __future__ import annotations

from pathlib import Path

from tssac_core.common.cli import UsageError


def read_signing_key(path: Path) -> bytes:
    """A key file: 32 raw bytes or 64 hex characters (the SITL's format); UsageError otherwise."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UsageError(f"signing key {path}: cannot read file ({exc.strerror or exc})") from None
    if len(data) == 32:
        return data
    text = data.strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise UsageError(f"signing key {path}: expected 32 raw bytes or 64 hex characters, got {len(data)} bytes")
