"""Errors the torch-free and the torch parts of TSSAC share (importing this module costs nothing)."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input a user can fix (a file, an argument, a setting): ``str()`` is the one line they see, and
    :func:`tssac_core.common.cli.run` turns it into that line and exit code 2."""


class CheckpointError(InputError):
    """A checkpoint (``<role>.pt``) or exported actor (``<role>.npz``) that is missing, corrupt or does
    not fit; ``str()`` is one line."""
