"""MAVLink frames out of a byte stream (a serial line), and the frames a stream lost.

A UDP datagram holds whole frames (:func:`tssac_core.wire.framing.scan_frames`); a serial line is a stream of
bytes that arrive in whatever pieces the driver hands over, and a noisy line drops or changes some of them.
:class:`StreamFramer` keeps the bytes of a frame still arriving between reads and runs the same scanner over the
stream (``scan_frames(..., stream=True)``): a frame is taken only when its header, message id and CRC check out,
and anything else is skipped one byte at a time until the next candidate that does, so the stream resynchronises
by itself after garbage, a dropped byte (the frame it was in fails its CRC; the next one is found behind it) or a
changed one. A candidate whose claimed length runs past what has arrived waits for more bytes; if the line then
falls idle (:meth:`StreamFramer.flush`: nothing more is coming), it is a cut frame, and the bytes behind its start
are scanned again as in a datagram.

:class:`SequenceGaps` counts the frames a link lost by the senders' sequence numbers (each sender numbers its
frames on a link 0-255 in turn; MAVLink's own loss count, as ``mavutil`` keeps it).

Pure standard library, as :mod:`tssac_core.wire.framing`.
"""

from __future__ import annotations

from dataclasses import dataclass

from tssac_core.wire.framing import Dialect, scan_frames, source

__all__ = ["SequenceGaps", "StreamCounters", "StreamFramer"]

_SEQ_REORDER = 128
"""A sequence number this far or further behind the expected one is a late or repeated frame, not a gap."""


@dataclass
class StreamCounters:
    """What a stream carried, by outcome."""

    bytes_in: int = 0
    frames: int = 0
    garbage_bytes: int = 0
    """Bytes skipped outside any candidate frame (noise, the rest of a frame whose CRC failed or that was cut)."""
    bad_crc: int = 0
    """Candidate frames whose CRC failed (a byte dropped or changed inside them)."""
    unknown_id: int = 0
    cut: int = 0
    """Candidate frames still incomplete when the line fell idle."""


class StreamFramer:
    """Whole, checked frames out of the pieces of a byte stream (see the module docstring)."""

    def __init__(self, dialect: Dialect) -> None:
        self._dialect = dialect
        self._buf = bytearray()
        self.counters = StreamCounters()

    @property
    def pending(self) -> int:
        """Bytes held back: the start of a frame still arriving."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes]:
        """The frames completed by ``data`` (the next bytes of the stream), in order."""
        self.counters.bytes_in += len(data)
        if self._buf:
            self._buf += data
            data = bytes(self._buf)
        scan = scan_frames(data, self._dialect, stream=True)
        self._count(scan.frames, scan.garbage_bytes, scan.bad_crc, scan.unknown_id)
        self._buf = bytearray(data[scan.consumed :])
        return scan.frames

    def flush(self) -> list[bytes]:
        """The line is idle: a frame still waiting for bytes is cut. The bytes held back are scanned as a datagram
        (a whole frame behind a cut one's start is still found); the frames found are returned, the rest dropped."""
        if not self._buf:
            return []
        data, self._buf = bytes(self._buf), bytearray()
        scan = scan_frames(data, self._dialect)
        self.counters.cut += scan.truncated
        self._count(scan.frames, scan.garbage_bytes, scan.bad_crc, scan.unknown_id)
        return scan.frames

    def _count(self, frames: list[bytes], garbage: int, bad_crc: int, unknown_id: int) -> None:
        c = self.counters
        c.frames += len(frames)
        c.garbage_bytes += garbage
        c.bad_crc += bad_crc
        c.unknown_id += unknown_id


class SequenceGaps:
    """Frames lost on a link, from the sequence numbers of each sender (system, component) on it."""

    def __init__(self) -> None:
        self._next: dict[tuple[int, int], int] = {}
        self.lost = 0
        """Frames missing between frames received (never counts the frames after the last one received)."""

    def observe(self, frame: bytes) -> int:
        """Count the frames missing before ``frame`` from its sender; returns how many."""
        sender = source(frame)
        seq = frame[4] if frame[0] == 0xFD else frame[2]
        expected = self._next.get(sender)
        self._next[sender] = (seq + 1) % 256
        if expected is None:
            return 0
        gap = (seq - expected) % 256
        if gap >= _SEQ_REORDER:  # late, repeated or a restarted sender: not a loss
            return 0
        self.lost += gap
        return gap

    def reset(self) -> None:
        """Forget every sender (a new session on the link)."""
        self._next.clear()
        self.lost = 0
