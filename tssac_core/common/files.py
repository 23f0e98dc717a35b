"""Writing files so that a crash, a kill -9 or a power cut leaves the old file or the new one, never a torn one."""

from __future__ import annotations

import os
from pathlib import Path


def fsync_path(path: Path) -> None:
    """Flush a file's (or a directory's) data to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def replace_durably(tmp: Path, target: Path) -> None:
    """Move a completely written ``tmp`` onto ``target``: fsync the file, rename, fsync the directory (without
    the first, a crash can leave the renamed file empty; without the last, the rename itself can be lost)."""
    fsync_path(tmp)
    os.replace(tmp, target)
    fsync_path(target.parent)
