"""Serial lines: the baud rates a UART runs at, and how many bytes a second a rate carries.

A UART sends 8N1 (start bit, 8 data bits, stop bit): :data:`BITS_PER_BYTE` = 10 bits on the line for each byte,
so 57,600 baud carries 5,760 bytes a second. The rates are those the operating system's serial driver can be set
to (``termios``'s ``B<rate>`` constants, from 1,200 baud up: slower lines carry too little for MAVLink); a rate
outside them (57,601, 100,000) is a typing error, not a line.
"""

from __future__ import annotations

import re
import termios

__all__ = ["BITS_PER_BYTE", "UART_BAUDS", "BaudError", "bytes_per_s", "check_baud", "termios_speed"]

BITS_PER_BYTE = 10
"""8N1: one start bit, eight data bits, one stop bit."""
MIN_BAUD = 1200
UART_BAUDS: tuple[int, ...] = tuple(
    sorted(rate for rate in (int(name[1:]) for name in dir(termios) if re.fullmatch(r"B\d+", name)) if rate >= MIN_BAUD)
)
"""Every rate the serial driver can be set to, from :data:`MIN_BAUD` (1200 ... 57600, 115200, ... 921600, ...)."""


class BaudError(ValueError):
    """A baud rate no UART runs at; ``str()`` is one line."""


def check_baud(baud: int, what: str = "baud rate") -> int:
    """``baud`` if a UART runs at it; BaudError (one line, naming the common rates) otherwise."""
    if baud not in UART_BAUDS:
        common = ", ".join(str(b) for b in (9600, 57600, 115200, 921600))
        raise BaudError(f"{what} {baud} is not a rate a UART runs at (e.g. {common})")
    return baud


def termios_speed(baud: int) -> int:
    """The ``termios`` constant of a rate (:func:`check_baud` first)."""
    return int(getattr(termios, f"B{check_baud(baud)}"))


def bytes_per_s(baud: int) -> float:
    """Bytes a second a line at ``baud`` carries, each way."""
    return baud / BITS_PER_BYTE
