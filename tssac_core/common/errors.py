"""Errors the torch-free and the torch parts of TSSAC share (importing this module costs nothing)."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input a user can fix (a file, an argument, a setting): ``str()`` is the one line they see, and
    :func:`tssac_core.common.cli.run` turns it into that line and exit code 2."""


class CheckpointError(InputError):
    """A checkpoint (``<role>.pt``) or exported actor (``<role>.npz``) that is missing, corrupt or does
    not fit; ``str()`` is one line."""


MAX_ACTION_REPEAT = 10_000
"""The longest decision interval a policy may have, in world steps (1,000 s at 0.1 s: longer than any mission). The
monitor protects every interval (its backups do not depend on it); a checkpoint that says less than 1 or more than
this is damaged, not a policy."""


def check_action_repeat(value: int, where: str) -> int:
    """``value`` as a policy's ``action_repeat``; CheckpointError (one line naming ``where``) outside 1..MAX."""
    if not 1 <= value <= MAX_ACTION_REPEAT:
        raise CheckpointError(f"{where}: action_repeat {value} is not a decision interval (1 to {MAX_ACTION_REPEAT})")
    return value
