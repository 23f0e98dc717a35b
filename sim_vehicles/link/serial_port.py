"""A vehicle's telemetry port on a pseudo-terminal: a UART at a baud rate, between a pty and the vehicle's UDP endpoint.

``python -m sim_vehicles --serial BAUD`` gives every vehicle one :class:`PtySerialPort`: a pseudo-terminal whose
device (``/dev/pts/N``) a companion opens as it would a flight controller's TELEM port (``--connect
/dev/pts/N,57600``). The port is the vehicle's serial line, plugged into its UDP endpoint the way a serial-to-UDP
adapter is: what the companion writes is framed (:class:`tssac_core.wire.stream_framing.StreamFramer`) and handed
to the endpoint from one local address, the frames of each burst (what crossed the line before it fell quiet) in one
datagram, as such adapters packetise on the line's pauses (a lockstep grant goes with the setpoint it follows); and
what the endpoint sends that address goes onto the line.
So the vehicle itself (its clients, commands, telemetry, signing) is the one on UDP, and a ground station still
reaches it on its UDP port or ``--out`` beside the companion.

The line runs at its baud rate, each way (8N1: :data:`tssac_core.wire.uart.BITS_PER_BYTE` bits a byte, so 57,600
baud carries 5,760 bytes/s): bytes leave at that rate, never faster, whatever the pty itself could take. Towards
the companion the vehicle's frames wait in a transmit buffer of :data:`TX_BUFFER_BYTES`; a frame that does not fit
is not sent (counted in ``tx_overflow_frames``), as ArduPilot sends a message only when its port has room for all
of it (``HAVE_PAYLOAD_SPACE`` in GCS_MAVLink/GCS.h: it never blocks and never cuts one). Telemetry that fits the
line loses nothing; more than the line carries loses whole frames, which the companion sees as gaps in the
vehicle's sequence numbers. ``byte_loss`` drops single bytes on the line, each way, each with that probability
(a noisy line: the framers at both ends must resynchronise).

The pty's slave side is kept open here as well (never read), so the port outlives its companions: the next one
(``--serve``'s next mission) opens the same device, and bytes written while nobody listens wait in the pty
(a companion drops them when it opens the port).
"""

from __future__ import annotations

import collections
import errno
import os
import socket
import termios
import tty
from dataclasses import dataclass, field

import numpy as np

from sim_vehicles.link.mavlink_io import DIALECT, MAX_DATAGRAM
from tssac_core.wire.framing import scan_frames
from tssac_core.wire.stream_framing import StreamCounters, StreamFramer
from tssac_core.wire.uart import bytes_per_s, termios_speed

__all__ = ["PtySerialPort", "SerialCounters", "TX_BUFFER_BYTES"]

TX_BUFFER_BYTES = 4096
"""The vehicle's transmit buffer towards the companion: 0.7 s of the line at 57,600 baud."""
RX_QUEUE_BYTES = 65536
"""Bytes from the companion waiting for the line at most; beyond it they are dropped (counted)."""
LINE_BURST_BYTES = 300
"""Bytes the line may send at once after a pause: a silent line saves up no more than this. One whole frame (280
bytes at most), so the vehicle's frames go onto the line whole, never paused half-way, as a UART sends a frame from
its buffer."""
IDLE_FLUSH_S = 0.1
"""Wall seconds without bytes from the companion after which a frame still incomplete is cut."""


@dataclass
class SerialCounters:
    """What crossed one serial port, each way."""

    baud: int
    bytes_to_companion: int = 0
    frames_to_companion: int = 0
    tx_overflow_frames: int = 0
    """Frames the vehicle sent that did not fit the transmit buffer (telemetry beyond what the line carries)."""
    bytes_from_companion: int = 0
    rx_overflow_bytes: int = 0
    bytes_lost_on_line: int = 0
    """Bytes the line dropped (``byte_loss``), both ways."""
    pty_full_bytes: int = 0
    """Bytes the pty did not take (nobody reads the port, and its buffer is full)."""
    from_companion: StreamCounters = field(default_factory=StreamCounters)
    """The framing of the companion's bytes: frames, garbage, bad CRCs, cut frames."""


class _Line:
    """One direction of the line: a token bucket at the line's byte rate (wall clock)."""

    def __init__(self, rate_bytes_per_s: float, now_s: float) -> None:
        self.rate = rate_bytes_per_s
        self.tokens = float(LINE_BURST_BYTES)
        self.at_s = now_s

    def allowance(self, now_s: float) -> int:
        """Whole bytes the line can send now."""
        self.tokens = min(float(LINE_BURST_BYTES), self.tokens + (now_s - self.at_s) * self.rate)
        self.at_s = now_s
        return int(self.tokens)

    def spend(self, n: int) -> None:
        self.tokens -= n

    def wait_s(self, n: int) -> float:
        """Seconds until ``n`` bytes (at most a burst) may go."""
        need = min(n, LINE_BURST_BYTES) - self.tokens
        return max(0.0, need / self.rate)


class PtySerialPort:
    """One vehicle's serial port on a pseudo-terminal (see the module docstring)."""

    def __init__(
        self, vehicle: tuple[str, int], baud: int, byte_loss: float, rng: np.random.Generator, now_s: float
    ) -> None:
        self.vehicle = ("127.0.0.1" if vehicle[0] in ("0.0.0.0", "") else vehicle[0], vehicle[1])
        self.baud = baud
        self.counters = SerialCounters(baud)
        self._byte_loss = byte_loss
        self._rng = rng
        self._master, self._slave = os.openpty()
        try:
            for fd in (self._master, self._slave):
                tty.setraw(fd, termios.TCSANOW)  # no echo: the vehicle's bytes must not come back to it
                attrs = termios.tcgetattr(fd)
                attrs[4] = attrs[5] = termios_speed(baud)
                termios.tcsetattr(fd, termios.TCSANOW, attrs)
            os.set_blocking(self._master, False)
            self.device = os.ttyname(self._slave)
            self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._udp.bind(("127.0.0.1", 0))
            self._udp.setblocking(False)
        except BaseException:
            os.close(self._master)
            os.close(self._slave)
            raise
        rate = bytes_per_s(baud)
        self._out = _Line(rate, now_s)
        self._in = _Line(rate, now_s)
        self._tx: collections.deque[bytes] = collections.deque()
        """The vehicle's frames waiting for the line."""
        self._tx_bytes = 0
        self._rx = bytearray()
        """The companion's bytes waiting for the line."""
        self._framer = StreamFramer(DIALECT)
        self._frames_in: list[bytes] = []
        """The companion's frames of the burst still crossing the line (they reach the vehicle together)."""
        self._rx_last_s = now_s
        self._closed = False

    @property
    def connection_string(self) -> str:
        """What a companion passes to ``--connect``: ``DEVICE,BAUD`` (MAVProxy's form)."""
        return f"{self.device},{self.baud}"

    def fds(self) -> list[int]:
        """What to wait on: the pty (the companion wrote) and the socket (the vehicle sent)."""
        return [self._master, self._udp.fileno()]

    def new_session(self) -> None:
        """A mission reset: what waits on the line, either way, belongs to the last mission."""
        self._tx.clear()
        self._tx_bytes = 0
        self._rx.clear()
        self._frames_in = []
        self._framer = StreamFramer(DIALECT)
        while True:
            try:
                self._udp.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                continue
        self.counters = SerialCounters(self.baud)

    # ------------------------------------------------------------------------------------------------ pumping

    def pump(self, now_s: float) -> None:
        """Move what the line carries by ``now_s``: the companion's bytes to the vehicle, the vehicle's to the pty."""
        if self._closed:
            return
        self._read_pty()
        self._to_vehicle(now_s)
        self._read_vehicle()
        self._to_companion(now_s)

    def next_due_s(self, now_s: float) -> float | None:
        """Wall seconds until the line can move bytes that wait (None: nothing waits)."""
        waits = []
        if self._tx:
            waits.append(self._out.wait_s(len(self._tx[0])))
        if self._rx:
            waits.append(self._in.wait_s(len(self._rx)))
        elif self._framer.pending:
            waits.append(max(0.0, self._rx_last_s + IDLE_FLUSH_S - now_s))
        return min(waits) if waits else None

    def _read_pty(self) -> None:
        while True:
            try:
                data = os.read(self._master, 4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if exc.errno == errno.EIO:  # no companion has the device open: nothing to read
                    return
                raise
            if not data:
                return
            room = RX_QUEUE_BYTES - len(self._rx)
            if len(data) > room:
                self.counters.rx_overflow_bytes += len(data) - room
                data = data[:room]
            self._rx += data

    def _to_vehicle(self, now_s: float) -> None:
        """The companion's bytes the line has carried by now, framed; whole frames to the vehicle in one datagram."""
        n = min(len(self._rx), self._in.allowance(now_s))
        if n > 0:
            chunk = bytes(self._rx[:n])
            del self._rx[:n]
            self._in.spend(n)
            self.counters.bytes_from_companion += n
            self._rx_last_s = now_s
            frames = self._framer.feed(self._lossy(chunk))
        elif self._framer.pending and not self._rx and now_s - self._rx_last_s > IDLE_FLUSH_S:
            frames = self._framer.flush()
        else:
            return
        self.counters.from_companion = self._framer.counters
        self._frames_in += frames
        if self._frames_in and not self._rx:  # the line has carried all the companion wrote: one datagram of it
            datagram, self._frames_in = b"".join(self._frames_in), []
            try:
                self._udp.sendto(datagram, self.vehicle)
            except OSError:
                pass  # the vehicle's endpoint is closing with the world

    def _read_vehicle(self) -> None:
        """The vehicle's datagrams: their whole frames into the transmit buffer, as far as it has room."""
        while True:
            try:
                data, _ = self._udp.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue
            for frame in scan_frames(data, DIALECT).frames:
                if self._tx_bytes + len(frame) > TX_BUFFER_BYTES:
                    self.counters.tx_overflow_frames += 1
                    continue
                self._tx.append(frame)
                self._tx_bytes += len(frame)
                self.counters.frames_to_companion += 1

    def _to_companion(self, now_s: float) -> None:
        """The vehicle's frames onto the line, each whole once the line has time for all of it."""
        allowance = self._out.allowance(now_s)
        while self._tx and len(self._tx[0]) <= allowance:
            frame = self._tx[0]
            chunk = self._lossy(frame)
            try:
                written = os.write(self._master, chunk) if chunk else 0
            except (BlockingIOError, InterruptedError):
                return  # the pty is full (nobody reads it): the line waits
            except OSError:
                return
            if written < len(chunk):  # the pty took part of it: the rest is lost with the pty full
                self.counters.pty_full_bytes += len(chunk) - written
            self._tx.popleft()
            self._tx_bytes -= len(frame)
            self._out.spend(len(frame))
            allowance -= len(frame)
            self.counters.bytes_to_companion += len(frame)

    def _lossy(self, chunk: bytes) -> bytes:
        """The bytes the line delivers of ``chunk``: each dropped with probability ``byte_loss``."""
        if self._byte_loss <= 0.0 or not chunk:
            return chunk
        keep = self._rng.random(len(chunk)) >= self._byte_loss
        self.counters.bytes_lost_on_line += int(len(chunk) - keep.sum())
        return np.frombuffer(chunk, dtype=np.uint8)[keep].tobytes()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._udp.close()
            os.close(self._master)
            os.close(self._slave)
