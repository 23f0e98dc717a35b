"""Which telemetry a vehicle sends, and when: the stream table and the messages of each stream for a state.

Every stream has an interval in simulated seconds (:data:`DEFAULT_INTERVALS_S`; MAV_CMD_SET_MESSAGE_INTERVAL
changes it, MAV_CMD_GET_MESSAGE_INTERVAL reads it). The position streams (:data:`GPS_GATED`) carry a GPS fix:
they are sent when due *and* a fix newer than the last one sent exists. :func:`build` makes the message(s) of
one id from a vehicle's state with the builders of :mod:`sim_vehicles.autopilot.telemetry`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.autopilot import telemetry
from sim_vehicles.autopilot.vehicle import EPS_S, Vehicle
from sim_vehicles.link.link_model import GpsFix
from tssac_core.wire import units

M = mavlink2  # message ids and enums

DEFAULT_INTERVALS_S: dict[int, float | None] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.1,
    M.MAVLINK_MSG_ID_ATTITUDE: 0.1,
    M.MAVLINK_MSG_ID_VFR_HUD: 0.1,
    M.MAVLINK_MSG_ID_NAMED_VALUE_INT: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    M.MAVLINK_MSG_ID_WIND: 1.0,
}
"""Default stream intervals in simulated seconds (None = off); SET_MESSAGE_INTERVAL changes them."""
MAX_INTERVAL_US = 2**31 - 1
"""Longest stream interval SET_MESSAGE_INTERVAL accepts (~36 min): MESSAGE_INTERVAL.interval_us is an int32."""
GPS_GATED = frozenset({M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED})
"""Streams that carry a GPS fix: sent when due *and* a fix newer than the last one sent exists."""
REQUESTABLE = frozenset(DEFAULT_INTERVALS_S) | {M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN}
"""Message ids MAV_CMD_REQUEST_MESSAGE can ask for."""
SNAPSHOT = (
    M.MAVLINK_MSG_ID_HEARTBEAT,
    M.MAVLINK_MSG_ID_SYS_STATUS,
    M.MAVLINK_MSG_ID_SYSTEM_TIME,
    M.MAVLINK_MSG_ID_NAMED_VALUE_INT,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    M.MAVLINK_MSG_ID_ATTITUDE,
    M.MAVLINK_MSG_ID_VFR_HUD,
)
"""The current state at once (a new peer; a lockstep world holding still): heartbeat, status, flags, position."""


@dataclass
class Stream:
    interval_s: float | None
    next_due_s: float = 0.0
    last_fix_s: float = -math.inf


class StreamTable:
    """The schedule of one vehicle's telemetry streams."""

    def __init__(self) -> None:
        self.streams = {mid: Stream(iv) for mid, iv in DEFAULT_INTERVALS_S.items()}

    def take_due(self, now_s: float, fix: GpsFix | None) -> list[int]:
        """The ids of the streams due at ``now_s`` (in table order), each scheduled for its next time; a GPS-gated
        stream is due only with a fix newer than the last it carried (it stays due until one arrives)."""
        due = []
        for mid, stream in self.streams.items():
            if stream.interval_s is None or now_s + EPS_S < stream.next_due_s:
                continue
            if mid in GPS_GATED:
                if fix is None or fix.time_s <= stream.last_fix_s:
                    continue  # stays due until a fresh fix arrives
                stream.last_fix_s = fix.time_s
            due.append(mid)
            nxt = stream.next_due_s + stream.interval_s
            stream.next_due_s = nxt if nxt > now_s + EPS_S else now_s + stream.interval_s
        return due

    def set_interval(self, mid: int, interval_us: float, now_s: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (-1 off, 0 default, > 0 microseconds); returns the MAV_RESULT."""
        stream = self.streams.get(mid)
        if stream is None:
            return M.MAV_RESULT_UNSUPPORTED
        if interval_us == -1:
            stream.interval_s = None
        elif interval_us == 0:
            stream.interval_s = DEFAULT_INTERVALS_S[mid]
        elif 0 < interval_us <= MAX_INTERVAL_US:  # also false for NaN
            stream.interval_s = units.s_from_us(interval_us)
        else:
            return M.MAV_RESULT_DENIED
        stream.next_due_s = now_s
        return M.MAV_RESULT_ACCEPTED

    def interval_us(self, mid: int) -> int | None:
        """MAV_CMD_GET_MESSAGE_INTERVAL: -1 off, else microseconds; None for an unknown stream."""
        stream = self.streams.get(mid)
        if stream is None:
            return None
        return -1 if stream.interval_s is None else min(MAX_INTERVAL_US, units.us_from_s(stream.interval_s))


Fields: TypeAlias = tuple[Any, ...]
"""A message's field values in its class's constructor order."""


def _local_position_ned(v: Vehicle) -> Fields | None:
    fix = v.gps.last_fix
    return None if fix is None else telemetry.local_position_ned_fields(fix)


def system_time_fields(v: Vehicle) -> Fields:
    """SYSTEM_TIME's fields now (the lockstep's step tick)."""
    return telemetry.system_time_fields(v.clock.unix_start_s, v.clock.sim_s)


FIELD_BUILDERS: dict[int, Callable[[Vehicle], Fields | None]] = {
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: _local_position_ned,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: system_time_fields,
}
"""The streams a lockstep vehicle sends at every step, as their message's fields for the vehicle's current state (the
arguments of pymavlink's ``<message>_encode``; None: nothing to say yet), so that they can be packed without building
message objects (:meth:`sim_vehicles.link.mavlink_io.MavEndpoint.encode_fields`). :func:`build` makes their messages
from the same fields."""


def build(mid: int, v: Vehicle, mav: mavlink2.MAVLink, errors_comm: int) -> list[mavlink2.MAVLink_message]:
    """The message(s) of one id for the vehicle's current state ([] if there is nothing to say, e.g. no fix yet);
    ``errors_comm``: SYS_STATUS's count of rejected frames."""
    build_fields = FIELD_BUILDERS.get(mid)
    if build_fields is not None:
        fields = build_fields(v)
        return [] if fields is None else [mavlink2.mavlink_map[mid](*fields)]
    now, t, o = v.clock.sim_s, v.truth, v.setup.origin
    ms = v.clock.time_boot_ms
    fix: GpsFix | None = v.gps.last_fix
    if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
        return [telemetry.heartbeat(mav, v.armed, int(v.mode), v.guided, v.system_status)]
    if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
        return [telemetry.sys_status(mav, v.gps.has_fix(now), not v.fence_breached, errors_comm)]
    if mid == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
        return [telemetry.extended_sys_state(mav)]
    if mid == M.MAVLINK_MSG_ID_GPS_RAW_INT:
        lk = v.setup.link
        return [
            telemetry.gps_raw_int(
                mav, o, fix, v.gps.has_fix(now), ms, lk.gps_position_sigma_m, lk.gps_velocity_sigma_m_s
            )
        ]
    if mid == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
        return [] if fix is None else [telemetry.global_position_int(mav, o, fix, t)]
    if mid == M.MAVLINK_MSG_ID_ATTITUDE:
        return [telemetry.attitude(mav, t, ms)]
    if mid == M.MAVLINK_MSG_ID_VFR_HUD:
        return [telemetry.vfr_hud(mav, t, o.alt_m, v.last_action[1])]
    if mid == M.MAVLINK_MSG_ID_WIND:
        msg = telemetry.wind(mav, t)
        return [] if msg is None else [msg]
    if mid == M.MAVLINK_MSG_ID_NAMED_VALUE_INT:
        return [telemetry.named_value_int(mav, ms, name, value) for name, value in v.flags.named_values()]
    if mid == M.MAVLINK_MSG_ID_HOME_POSITION:
        return [telemetry.home_position(mav, o, v.setup.home_east_m, v.setup.home_north_m, now)]
    if mid == M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
        return [telemetry.gps_global_origin(mav, o, now)]
    if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
        return [telemetry.autopilot_version(mav, v.sysid)]
    return []
