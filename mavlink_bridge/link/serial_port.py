"""The companion's end of a serial line: a flight controller's TELEM port on a UART, or the SITL's pseudo-terminal.

Connection strings as MAVProxy writes them (``--master=/dev/ttyUSB0,57600``): ``DEVICE[,BAUD]``, the baud
rate :data:`DEFAULT_BAUD` when it is left out (MAVProxy's default, and ArduPilot's on its telemetry ports). The
device is opened non-blocking and raw (no echo, no line editing, no flow control: 8N1 at the baud rate), and
taken for this process alone: an advisory lock (``flock``, as pyserial's ``exclusive=True``) and ``TIOCEXCL``,
so a second companion on the same port is refused with one line instead of both reading half of the stream. Bytes
waiting from before we opened it are dropped.

Writes never block: what the driver does not take at once waits in a small buffer (:data:`TX_PENDING_MAX`) and
goes with the next write or read; a frame that does not fit is dropped whole (counted), never cut, so the far
end's framer never sees half a frame from us.
"""

from __future__ import annotations

import errno
import fcntl
import os
import termios
import tty
from dataclasses import dataclass

from tssac_core.wire.uart import BaudError, check_baud, termios_speed

__all__ = ["DEFAULT_BAUD", "SerialError", "SerialPort", "SerialSpec", "is_serial", "parse_serial"]

DEFAULT_BAUD = 57600
"""The baud rate of ``DEVICE`` without ``,BAUD``: MAVProxy's default, ArduPilot's SERIAL1_BAUD / SERIAL2_BAUD."""
TX_PENDING_MAX = 4096
"""Bytes a write may leave waiting for the driver; a frame beyond it is dropped whole."""
_READ_CHUNK = 4096


class SerialError(OSError):
    """A serial device that cannot be opened or used; ``str()`` is one line."""

    def __str__(self) -> str:
        return str(self.strerror)


@dataclass(frozen=True)
class SerialSpec:
    """A parsed serial connection string."""

    device: str
    baud: int

    def __str__(self) -> str:
        return f"{self.device},{self.baud}"


def is_serial(text: str) -> bool:
    """A connection string that names a device (a path) rather than a network address."""
    return text.strip().startswith("/")


def parse_serial(text: str) -> SerialSpec:
    """``DEVICE[,BAUD]`` (DEVICE a path: ``/dev/ttyUSB0,57600``); ValueError with one line otherwise."""
    device, sep, baud_text = text.strip().partition(",")
    if not device.startswith("/"):
        raise ValueError(f"connection {text!r}: a serial device is a path, e.g. /dev/ttyUSB0,57600")
    if not sep:
        return SerialSpec(device, DEFAULT_BAUD)
    if not baud_text.isdigit():
        raise ValueError(f"connection {text!r}: baud rate {baud_text!r} is not a number")
    try:
        return SerialSpec(device, check_baud(int(baud_text)))
    except BaudError as exc:
        raise ValueError(f"connection {text!r}: {exc}") from None


class SerialPort:
    """One open serial device (see the module docstring)."""

    def __init__(self, spec: SerialSpec) -> None:
        self.spec = spec
        self.tx_dropped_frames = 0
        """Frames not written because the driver's buffer and ours were full."""
        self._pending = bytearray()
        self._closed = False
        self._fd = _open(spec)

    def fileno(self) -> int:
        return self._fd

    def read(self) -> bytes:
        """Every byte waiting (b"" if none); SerialError if the line is gone (unplugged, the far end closed)."""
        chunks = []
        while True:
            try:
                chunk = os.read(self._fd, _READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                raise SerialError(exc.errno or 0, f"{self.spec.device}: read failed ({exc.strerror or exc})") from None
            if not chunk:  # end of file: the far end of a pseudo-terminal closed
                break
            chunks.append(chunk)
            if len(chunk) < _READ_CHUNK:
                break
        self._write_pending()
        return b"".join(chunks)

    def write(self, frames: bytes) -> bool:
        """Send whole frames (waiting in our buffer for the driver if need be); False if they were dropped."""
        self._write_pending()
        if len(self._pending) + len(frames) > TX_PENDING_MAX:
            self.tx_dropped_frames += 1
            return False
        self._pending += frames
        self._write_pending()
        return True

    def _write_pending(self) -> None:
        if not self._pending or self._closed:
            return
        try:
            n = os.write(self._fd, self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            raise SerialError(exc.errno or 0, f"{self.spec.device}: write failed ({exc.strerror or exc})") from None
        del self._pending[:n]

    def discard_input(self) -> None:
        """Drop every byte waiting to be read (a new session on the same line)."""
        termios.tcflush(self._fd, termios.TCIFLUSH)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self._fd)


def _open(spec: SerialSpec) -> int:
    """The device opened raw at its baud rate, for us alone; SerialError (one line) if it cannot be."""
    device = spec.device
    try:
        fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise SerialError(exc.errno or 0, _open_failure(device, exc)) from None
    try:
        if not os.isatty(fd):
            raise SerialError(errno.ENOTTY, f"serial device {device} is not a serial line (not a terminal)")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise SerialError(errno.EBUSY, f"serial device {device} is busy: another process has it open") from None
        fcntl.ioctl(fd, termios.TIOCEXCL)  # further opens fail (but root's): the lock above covers them too
        tty.setraw(fd, termios.TCSANOW)
        attrs = termios.tcgetattr(fd)
        attrs[2] = (attrs[2] | termios.CLOCAL | termios.CREAD) & ~termios.CRTSCTS  # no modem lines, no flow control
        attrs[4] = attrs[5] = termios_speed(spec.baud)
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
        termios.tcflush(fd, termios.TCIOFLUSH)
    except SerialError:
        os.close(fd)
        raise
    except (OSError, termios.error) as exc:
        os.close(fd)
        raise SerialError(errno.EIO, f"serial device {device}: cannot set it up ({exc})") from None
    return fd


def _open_failure(device: str, exc: OSError) -> str:
    if exc.errno == errno.ENOENT:
        return f"serial device {device} does not exist"
    if exc.errno == errno.EBUSY:
        return f"serial device {device} is busy: another process has it open"
    if exc.errno == errno.EACCES:
        return f"serial device {device}: permission denied (is the user in the dialout group?)"
    return f"serial device {device} cannot be opened ({exc.strerror or exc})"
