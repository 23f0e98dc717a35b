"""Files: writing them so that a crash, a kill -9 or a power cut leaves the old file or the new one, never a torn one;
and a file's digest."""

from __future__ import annotations

import errno
import hashlib
import os
import stat
import sys
import tempfile
from pathlib import Path


def sha256_file(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, hex (read in blocks, not whole into memory)."""
    with Path(path).open("rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


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


def _umask() -> int:
    """The process's umask, read without changing it (Linux: /proc; elsewhere the usual 022)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022


def _check_link_owner(path: Path) -> None:
    """A link the user did not make is not written through (PermissionError): in a directory others can write, a
    link planted under the name the user gave would have the user's write land on a file of the planter's choice.
    Links of the user's own and of root (``/dev/stdout``) are followed."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(st.st_mode) and st.st_uid not in (os.geteuid(), 0):
        raise PermissionError(errno.EPERM, f"a link of another user (uid {st.st_uid}): not written through", str(path))


def _descriptor(path: Path) -> tuple[int, int] | None:
    """(pid, fd) when ``path`` leads through ``/proc/PID/fd/N`` (``/dev/stdout``, ``/dev/fd/1``): an open descriptor of
    a process, whatever it is (a terminal, a pipe, the file a shell redirected to), not a name to replace."""
    current = os.path.abspath(path)
    for _ in range(40):
        current = os.path.join(os.path.realpath(os.path.dirname(current)), os.path.basename(current))
        parts = Path(current).parts
        if len(parts) == 5 and parts[1] == "proc" and parts[3] == "fd" and parts[2].isdigit() and parts[4].isdigit():
            return int(parts[2]), int(parts[4])
        if not os.path.islink(current):
            return None
        current = os.path.join(os.path.dirname(current), os.readlink(current))
    return None


def _write_to_own_descriptor(fd: int, text: str) -> None:
    """Write through one of this process's descriptors (``--json /dev/stdout``): after what Python has buffered for
    it, and at its own offset, so that the JSON lands where the command's other output goes, in order."""
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None and stream.fileno() == fd:
                stream.flush()
        except (OSError, ValueError):  # a stream replaced by one with no descriptor (a test's capture)
            pass
    data = text.encode("utf-8")
    while data:
        data = data[os.write(fd, data) :]


def write_text_safely(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` as a user means it: a named pipe, a character device or an open descriptor
    (``/dev/stdout``, even redirected to a file) is written in place, appended to what is there, and stays what it
    is; a regular file, or a name for a new one, is replaced atomically (a new file in the same directory, renamed
    over it: a crash leaves the old text or the new, never a torn one), through any links of the user's own to the
    file they name. A directory, a block device or a socket is refused (OSError), as is a link another user made."""
    _check_link_owner(path)
    try:
        st: os.stat_result | None = os.stat(path)
    except FileNotFoundError:
        st = None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, "is a directory", str(path))
    descriptor = _descriptor(path) if st is not None else None
    if descriptor is not None and descriptor[0] == os.getpid():
        _write_to_own_descriptor(descriptor[1], text)
        return
    special = st is not None and (stat.S_ISFIFO(st.st_mode) or stat.S_ISCHR(st.st_mode))
    if special or descriptor is not None:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(text)
        return
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OSError(errno.EINVAL, "not a regular file, a named pipe or a character device: not written", str(path))
    target = Path(os.path.realpath(path))
    target.parent.mkdir(parents=True, exist_ok=True)
    mode = stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~_umask()
    fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            os.fchmod(fh.fileno(), mode)
            fh.write(text)
        replace_durably(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def create_exclusively(path: Path, mode: int = 0o644) -> int:
    """A new, empty file at ``path`` open for writing (its descriptor), made by us with ``mode``: whatever was there
    (an old file, or a file or link someone planted) is removed, never followed, and a file that appears in between
    fails the creation (FileExistsError) instead of being written. Used for keys and logs in directories that other
    users may write (``fly --logs``, ``--tlog``): O_CREAT alone would keep a planted file's mode (a key readable by
    everyone) and follow a planted link (a file of the planter's choice overwritten)."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode)


def _writable_by_others(st: os.stat_result) -> bool:
    """Another user may add, remove or rename entries: group or others may write, and no sticky bit stops them."""
    return bool(st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)) and not st.st_mode & stat.S_ISVTX


def private_directory(path: Path, option: str) -> Path:
    """``path`` (given as ``option``) as a directory nobody else can plant files or links in, created (with its
    parents) if needed; returned with the user's own links resolved. It must be the user's (or root's) and not
    writable by others unless its sticky bit keeps them from touching entries they do not own: then the entries we
    make in it stay ours. PermissionError (one line) otherwise, and for a link another user made."""
    _check_link_owner(path)
    path.mkdir(parents=True, exist_ok=True)
    real = Path(os.path.realpath(path))
    st = os.lstat(real)
    if not stat.S_ISDIR(st.st_mode):
        raise NotADirectoryError(errno.ENOTDIR, f"{option}: not a directory", str(path))
    if st.st_uid not in (os.geteuid(), 0):
        raise PermissionError(
            errno.EPERM, f"{option}: a directory of another user (uid {st.st_uid}): not written in", str(path)
        )
    if _writable_by_others(st):
        raise PermissionError(
            errno.EPERM,
            f"{option}: other users can write in this directory and replace what is written there (give one only you "
            "can write, or one with the sticky bit, as /tmp)",
            str(path),
        )
    return real
