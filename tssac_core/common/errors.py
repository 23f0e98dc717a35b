"""Errors the torch-free and the torch parts of TSSAC share (importing this module costs nothing)."""

from __future__ import annotations


class CheckpointError(ValueError):
    """A checkpoint (``<role>.pt``) or exported actor (``<role>.npz``) that is missing, corrupt or does
    not fit; ``str()`` is one line."""
