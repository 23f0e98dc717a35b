"""Bytes a second a companion's link needs, each way, against what a serial line carries.

A MAVLink 2 frame is a 10-byte header, its payload and a 2-byte CRC (:data:`FRAME_OVERHEAD_BYTES`), plus a 13-byte
signature when signed. The payload is counted at its full length (pymavlink's wire struct, extensions included):
MAVLink 2 cuts trailing zero bytes, so frames on the wire are never longer and the figures are upper bounds.

What the companion needs (:func:`companion_streams`): from the vehicle, the streams it asks for and reads —
LOCAL_POSITION_NED at the step rate (MAV_CMD_SET_MESSAGE_INTERVAL), SYSTEM_TIME (every step under lockstep, where
it is the step's tick; else once a second), HEARTBEAT and the mission flags (NAMED_VALUE_INT) once a second; to the
vehicle, one setpoint per step in its dialect (a SET_POSITION_TARGET_LOCAL_NED, or ArduPlane's GUIDED_CHANGE_HEADING
and GUIDED_CHANGE_SPEED as COMMAND_INT) and its HEARTBEAT. On a serial line it asks for no more than
:data:`LINE_SHARE` of the line either way (:func:`check_line`): the rest is the vehicle's other streams, command
acknowledgements and STATUSTEXTs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from mavlink_bridge.link.guided_commands import SetpointDialect
from tssac_core.wire.uart import bytes_per_s as line_bytes_per_s

__all__ = ["FRAME_OVERHEAD_BYTES", "LINE_SHARE", "LineBudget", "check_line", "companion_streams", "frame_bytes"]

M = mavlink2
FRAME_OVERHEAD_BYTES = 12
"""MAVLink 2: 10-byte header (start byte included) and 2-byte CRC."""
SIGNATURE_BYTES = 13
LINE_SHARE = 0.5
"""The most of a serial line, each way, the companion's own streams may take."""


def frame_bytes(name: str, signed: bool) -> int:
    """The longest frame of message ``name`` (``"LOCAL_POSITION_NED"``) on the wire."""
    cls = M.mavlink_map[getattr(M, f"MAVLINK_MSG_ID_{name}")]
    return FRAME_OVERHEAD_BYTES + int(cls.unpacker.size) + (SIGNATURE_BYTES if signed else 0)


def stream_bytes_per_s(rates_hz: Mapping[str, float], signed: bool) -> float:
    """Bytes a second of messages sent at these rates (message name -> Hz)."""
    return sum(rate * frame_bytes(name, signed) for name, rate in rates_hz.items())


@dataclass(frozen=True)
class CompanionStreams:
    """What a companion exchanges with its vehicle, message name -> Hz, each way."""

    from_vehicle: dict[str, float]
    to_vehicle: dict[str, float]


def companion_streams(dt_s: float, lockstep: bool, setpoints: SetpointDialect) -> CompanionStreams:
    """The streams a companion asks for and reads, and what it sends, at a step of ``dt_s`` (module docstring)."""
    step_hz = 1.0 / dt_s
    from_vehicle = {
        "LOCAL_POSITION_NED": step_hz,
        "SYSTEM_TIME": step_hz if lockstep else 1.0,
        "HEARTBEAT": 1.0,
        "NAMED_VALUE_INT": 1.0,
    }
    if setpoints is SetpointDialect.ARDUPLANE:
        to_vehicle = {"COMMAND_INT": 2.0 * step_hz, "HEARTBEAT": 1.0}
    else:
        to_vehicle = {"SET_POSITION_TARGET_LOCAL_NED": step_hz, "HEARTBEAT": 1.0}
    if lockstep:
        to_vehicle["NAMED_VALUE_INT"] = step_hz  # a grant may go with every setpoint
    return CompanionStreams(from_vehicle, to_vehicle)


@dataclass(frozen=True)
class LineBudget:
    """A companion's streams against a serial line, bytes a second."""

    baud: int
    line_bytes_per_s: float
    from_vehicle_bytes_per_s: float
    to_vehicle_bytes_per_s: float

    @property
    def share(self) -> float:
        """The larger of the two directions' share of the line."""
        return max(self.from_vehicle_bytes_per_s, self.to_vehicle_bytes_per_s) / self.line_bytes_per_s

    def describe(self) -> str:
        return (
            f"{self.baud} baud carries {self.line_bytes_per_s:.0f} bytes/s each way; the companion's streams need "
            f"{self.from_vehicle_bytes_per_s:.0f} from the vehicle and {self.to_vehicle_bytes_per_s:.0f} to it "
            f"({100.0 * self.share:.0f}% of the line)"
        )


def line_budget(baud: int, streams: CompanionStreams, signed: bool) -> LineBudget:
    return LineBudget(
        baud,
        line_bytes_per_s(baud),
        stream_bytes_per_s(streams.from_vehicle, signed),
        stream_bytes_per_s(streams.to_vehicle, signed),
    )


def check_line(budget: LineBudget) -> str | None:
    """Why the line is too slow for the companion (one line), None if its streams fit in :data:`LINE_SHARE` of it."""
    if budget.share <= LINE_SHARE:
        return None
    return f"{budget.describe()}: more than {100 * LINE_SHARE:.0f}%; use a faster line (57600 baud or more)"
