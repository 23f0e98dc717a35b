"""What a vehicle does with the messages its clients send: commands, modes, setpoints, parameters,
missions, FTP and time sync.

:class:`CommandHandler` reads messages and answers them over the vehicle's
:class:`~sim_vehicles.protocol.vehicle_link.VehicleLink`; it changes the vehicle's state only through
:class:`sim_vehicles.autopilot.vehicle.Vehicle`'s methods (``set_mode``, ``set_armed``, ``fly_demand``, ...).
Every COMMAND_LONG / COMMAND_INT is answered with a COMMAND_ACK to its sender. Messages addressed to
another system or component are ignored (counted) and never passed on: a ground station on ``--out``
sends each frame to every vehicle (pymavlink's ``udpin`` side writes to all the addresses it has heard),
so each vehicle acts on the frames for its own system id (or for all) and the others drop them.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Callable
from typing import TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.autopilot import guided_slew, modes, setpoints
from sim_vehicles.autopilot.modes import FlightMode
from sim_vehicles.autopilot.vehicle import Vehicle
from sim_vehicles.link.mavlink_io import Address
from sim_vehicles.protocol.vehicle_link import VehicleLink
from tssac_core.wire import units

_log = logging.getLogger(__name__)
M = mavlink2
Msg: TypeAlias = mavlink2.MAVLink_message
CommandResult: TypeAlias = tuple[int, list[Msg]]

FTP_OP_ACK, FTP_OP_NAK = 128, 129
FTP_TERMINATE_SESSION, FTP_RESET_SESSIONS, FTP_OPEN_FILE_RO = 1, 2, 4
FTP_ERR_UNKNOWN_COMMAND = 7
FTP_PAYLOAD_LEN = 251
FTP_PARAM_FILE = b"@PARAM/param.pck"
"""MAVLink FTP: every request is NAKed with UnknownCommand (session ends are ACKed), so clients that try FTP
first fall back to the parameter protocol instead of timing out. A request for ArduPilot's parameter file is
also answered through the parameter protocol at once (every PARAM_VALUE, as for PARAM_REQUEST_LIST):
MAVProxy, which asks for it on connect and otherwise retries only on its next 1 Hz check, lists the
parameters as soon as they arrive."""
MISSION_UPLOAD_REFUSAL = "Mission upload refused: no AUTO mode here"
GOTO_REFUSAL = "Goto refused: fly GUIDED setpoints"


class CommandHandler:
    """The incoming side of one vehicle (see the module docstring)."""

    def __init__(self, vehicle: Vehicle, link: VehicleLink) -> None:
        self.v = vehicle
        self.link = link
        self._home_upload_from: Address | None = None
        """The client uploading a one-item (home slot only) mission, until its item 0 arrives."""
        self._handlers: dict[str, Callable[[Msg, Address], None]] = {
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_MODE": self._on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "SET_ATTITUDE_TARGET": self._on_setpoint,
            "SET_POSITION_TARGET_GLOBAL_INT": self._on_global_target,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "MISSION_REQUEST_INT": self._on_mission_request_item,
            "MISSION_REQUEST": self._on_mission_request_item,
            "MISSION_COUNT": self._on_mission_upload,
            "MISSION_ITEM_INT": self._on_mission_item,
            "MISSION_ITEM": self._on_mission_item,
            "MISSION_CLEAR_ALL": self._on_mission_clear_all,
            "FILE_TRANSFER_PROTOCOL": self._on_ftp,
            "TIMESYNC": self._on_timesync,
            "STATUSTEXT": self._on_statustext,
            "HEARTBEAT": self._on_heartbeat,
        }
        self._commands: dict[int, Callable[[tuple[float, ...]], CommandResult]] = {
            M.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            M.MAV_CMD_DO_SET_MODE: self._cmd_do_set_mode,
            M.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._cmd_return_to_launch,
            M.MAV_CMD_NAV_LOITER_UNLIM: self._cmd_loiter_unlimited,
            M.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_capabilities,
            M.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
            M.MAV_CMD_DO_REPOSITION: self._cmd_reposition,
            M.MAV_CMD_GUIDED_CHANGE_HEADING: self._cmd_change_heading,
            M.MAV_CMD_GUIDED_CHANGE_SPEED: self._cmd_change_speed,
            M.MAV_CMD_GUIDED_CHANGE_ALTITUDE: self._cmd_change_altitude,
        }

    # ------------------------------------------------------------------------------ dispatch

    def _on_statustext(self, msg: Msg, addr: Address) -> None:
        text = (
            msg.text.rstrip("\x00")
            if isinstance(msg.text, str)
            else bytes(msg.text).rstrip(b"\x00").decode("ascii", "replace")
        )
        self.link.relay_statustext(int(msg.severity), text, addr)

    def _on_heartbeat(self, msg: Msg, addr: Address) -> None:
        """A component of this vehicle (its companion computer, on the vehicle's system id) is passed on to the other
        clients and ground stations as it came, as ArduPilot's MAVLink routing forwards it: a ground station sees the
        companion as component 191 of the vehicle. Others' heartbeats (a ground station's) stay here."""
        if msg.get_srcSystem() == self.v.sysid and msg.get_srcComponent() != self.v.compid:
            self.link.relay(msg, addr)

    def handle(self, msg: Msg, addr: Address) -> None:
        v = self.v
        target_system = getattr(msg, "target_system", 0)
        target_component = getattr(msg, "target_component", 0)
        if target_system not in (0, v.sysid) or target_component not in (0, v.compid):
            v.counters.not_for_us += 1
            return
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            return
        try:
            handler(msg, addr)
        except Exception:
            # A bug reached by some field value must not take the vehicle (and the world) down.
            v.counters.handler_errors += 1
            _log.exception("%s: handling %s failed", v.role, msg.get_type())

    def _reply_ack(self, command: int, result: int, msg: Msg, addr: Address) -> None:
        self.link.send(
            self.link.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), addr
        )

    # ------------------------------------------------------------------------------ commands

    def _on_command_long(self, msg: Msg, addr: Address) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(msg.command, params, msg, addr)

    def _on_command_int(self, msg: Msg, addr: Address) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(msg.command, params, msg, addr)

    def _command(self, command: int, params: tuple[float, ...], msg: Msg, addr: Address) -> None:
        """Run a command and answer it with a COMMAND_ACK (always), then any messages it produced."""
        v = self.v
        v.counters.commands += 1
        handler = self._commands.get(command)
        replies: list[Msg]
        if handler is None:
            v.counters.commands_unsupported += 1
            result, replies = M.MAV_RESULT_UNSUPPORTED, []
        else:
            result, replies = handler(params)
        self._reply_ack(command, result, msg, addr)
        for reply in replies:
            self.link.send(reply, addr)

    def _cmd_arm_disarm(self, p: tuple[float, ...]) -> CommandResult:
        if abs(p[0] - 1.0) < 1e-3:
            self.v.set_armed(True)
            return M.MAV_RESULT_ACCEPTED, []
        if abs(p[0]) < 1e-3:
            self.v.set_armed(False)
            return M.MAV_RESULT_ACCEPTED, []
        return M.MAV_RESULT_DENIED, []

    def _cmd_do_set_mode(self, p: tuple[float, ...]) -> CommandResult:
        if not (math.isfinite(p[0]) and math.isfinite(p[1])):
            return M.MAV_RESULT_DENIED, []
        return self._set_mode(int(round(p[0])), int(round(p[1]))), []

    def _cmd_return_to_launch(self, p: tuple[float, ...]) -> CommandResult:
        self.v.set_mode(FlightMode.RTL, "MAV_CMD_NAV_RETURN_TO_LAUNCH")
        return M.MAV_RESULT_ACCEPTED, []

    def _cmd_loiter_unlimited(self, p: tuple[float, ...]) -> CommandResult:
        self.v.set_mode(FlightMode.LOITER, "MAV_CMD_NAV_LOITER_UNLIM")
        return M.MAV_RESULT_ACCEPTED, []

    def _cmd_reposition(self, p: tuple[float, ...]) -> CommandResult:
        """A goto (MAVSDK's goto_location: GUIDED, then MAV_CMD_DO_REPOSITION) is not flown here: refused, and the
        switch to GUIDED made for it is undone, so the vehicle does not sit in GUIDED without a setpoint."""
        v = self.v
        self.link.statustext(M.MAV_SEVERITY_WARNING, GOTO_REFUSAL)
        v.undo_guided_switch("goto refused")
        return M.MAV_RESULT_UNSUPPORTED, []

    # ------------------------------------------------------------ ArduPlane's GUIDED slew commands

    def _cmd_change_heading(self, p: tuple[float, ...]) -> CommandResult:
        if not self.v.guided:
            return M.MAV_RESULT_FAILED, []
        parsed = guided_slew.parse_change_heading(p)
        if isinstance(parsed, guided_slew.SlewRefusal):
            return self._slew_refused(parsed)
        return self._slew_flown(self.v.fly_heading(parsed))

    def _cmd_change_speed(self, p: tuple[float, ...]) -> CommandResult:
        v = self.v
        if not v.guided:
            return M.MAV_RESULT_FAILED, []
        parsed = guided_slew.parse_change_speed(p, v.setup.speed_min_m_s, v.setup.speed_max_m_s)
        if isinstance(parsed, guided_slew.SlewRefusal):
            return self._slew_refused(parsed)
        return self._slew_flown(v.fly_speed(parsed))

    def _cmd_change_altitude(self, p: tuple[float, ...]) -> CommandResult:
        """The vehicles fly level at the flight altitude: a CHANGE_ALTITUDE to it is accepted (nothing to change), any
        other refused with a STATUSTEXT that says so."""
        v = self.v
        if not v.guided:
            return M.MAV_RESULT_FAILED, []
        flight_alt_m = v.setup.origin.alt_m
        if math.isfinite(p[6]) and abs(p[6] - flight_alt_m) <= guided_slew.LEVEL_TOLERANCE_M:
            return M.MAV_RESULT_ACCEPTED, []
        return self._slew_refused(
            guided_slew.SlewRefusal(M.MAV_RESULT_DENIED, f"Alt cmd: level flight at {flight_alt_m:.0f} m only")
        )

    def _slew_refused(self, refusal: guided_slew.SlewRefusal) -> CommandResult:
        self.v.refuse("slew", refusal.text)
        return refusal.result, []

    @staticmethod
    def _slew_flown(flown: bool) -> CommandResult:
        # Armed in GUIDED: flown. In GUIDED but disarmed, the vehicle said why (fly_demand's refusal).
        return (M.MAV_RESULT_ACCEPTED if flown else M.MAV_RESULT_FAILED), []

    def _on_set_mode(self, msg: Msg, addr: Address) -> None:
        # ArduPilot answers the SET_MODE message with a COMMAND_ACK whose command is the message id (11).
        self._reply_ack(M.MAVLINK_MSG_ID_SET_MODE, self._set_mode(msg.base_mode, msg.custom_mode), msg, addr)

    def _set_mode(self, base_mode: int, custom_mode: int) -> int:
        v = self.v
        if not base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.link.statustext(M.MAV_SEVERITY_WARNING, "Set mode: base_mode needs CUSTOM_MODE_ENABLED")
            return M.MAV_RESULT_DENIED
        try:
            mode = FlightMode(custom_mode)
        except ValueError:
            self.link.statustext(M.MAV_SEVERITY_WARNING, modes.refusal(custom_mode))
            return M.MAV_RESULT_DENIED
        v.set_mode(mode)
        return M.MAV_RESULT_ACCEPTED

    def _cmd_request_message(self, p: tuple[float, ...]) -> CommandResult:
        msgs = self.link.requested(int(p[0]) if math.isfinite(p[0]) else -1)
        if msgs is None:
            return M.MAV_RESULT_UNSUPPORTED, []
        return (M.MAV_RESULT_ACCEPTED, msgs) if msgs else (M.MAV_RESULT_FAILED, [])

    def _cmd_request_capabilities(self, p: tuple[float, ...]) -> CommandResult:
        return M.MAV_RESULT_ACCEPTED, self.link.build(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _cmd_set_message_interval(self, p: tuple[float, ...]) -> CommandResult:
        ok = self.link.set_stream_interval(int(p[0]) if math.isfinite(p[0]) else -1, p[1])
        return ok, []

    def _cmd_get_message_interval(self, p: tuple[float, ...]) -> CommandResult:
        mid = int(p[0]) if math.isfinite(p[0]) else -1
        interval_us = self.link.stream_interval_us(mid)
        if interval_us is None:
            return M.MAV_RESULT_UNSUPPORTED, []
        return M.MAV_RESULT_ACCEPTED, [self.link.mav.message_interval_encode(mid, interval_us)]

    # ----------------------------------------------------------------------------- setpoints

    def _on_setpoint(self, msg: Msg, addr: Address) -> None:
        self._setpoint(self.link.setpoint(msg))

    def _on_global_target(self, msg: Msg, addr: Address) -> None:
        self.v.reject(setpoints.GLOBAL_REFUSAL)

    def _setpoint(self, parsed: setpoints.Demand | setpoints.Refusal) -> None:
        # Its time_boot_ms stamp was read at the socket (Vehicle.poll_socket: the lockstep barrier).
        if isinstance(parsed, setpoints.Refusal):
            self.v.reject(parsed)
        else:
            self.v.fly_demand(parsed)

    # ---------------------------------------------------------------------------- parameters

    def _param_value(self, index: int) -> Msg:
        params = self.v.params
        p = params.at(index)
        assert p is not None
        return self.link.mav.param_value_encode(p.name.encode("ascii"), p.value, p.param_type, len(params), index)

    def _on_param_request_list(self, msg: Msg, addr: Address) -> None:
        for i in range(len(self.v.params)):
            self.link.send(self._param_value(i), addr)

    def _on_param_request_read(self, msg: Msg, addr: Address) -> None:
        params = self.v.params
        index = msg.param_index if msg.param_index >= 0 else params.index(msg.param_id)
        if index is None or params.at(index) is None:
            _log.info("%s: PARAM_REQUEST_READ of unknown parameter %r / %d", self.v.role, msg.param_id, msg.param_index)
            self._param_error(msg, addr, M.MAV_PARAM_ERROR_DOES_NOT_EXIST)
            return
        self.link.send(self._param_value(index), addr)

    def _on_param_set(self, msg: Msg, addr: Address) -> None:
        v = self.v
        index = v.params.index(msg.param_id)
        refused = v.params.set(msg.param_id, float(msg.param_value))
        if refused is None:
            assert index is not None
            self.link.send(self._param_value(index))  # a changed value goes to every client
            return
        # As ArduPilot 4.6: PARAM_ERROR first (MAVSDK ends the set with its code), then why, then the old value.
        self._param_error(msg, addr, refused.error)
        if index is None:
            _log.info("%s: PARAM_SET of unknown parameter %r", v.role, msg.param_id)
            return
        self.link.statustext(M.MAV_SEVERITY_WARNING, refused.text, addr)
        self.link.send(self._param_value(index), addr)

    def _param_error(self, msg: Msg, addr: Address, error: int) -> None:
        param_id = msg.param_id.encode("ascii", "replace") if isinstance(msg.param_id, str) else bytes(msg.param_id)
        index = getattr(msg, "param_index", -1)
        self.link.send(
            self.link.mav.param_error_encode(msg.get_srcSystem(), msg.get_srcComponent(), param_id, index, error), addr
        )

    # ---------------------------------------------------------------- missions, FTP, time

    def _on_mission_request_list(self, msg: Msg, addr: Address) -> None:
        # No mission, fence or rally items: ground stations ask on connect and wait for an answer.
        self.link.send(
            self.link.mav.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type), addr
        )

    def _on_mission_request_item(self, msg: Msg, addr: Address) -> None:
        # There are no items to send.
        ack = self.link.mav.mission_ack_encode(
            msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_INVALID_SEQUENCE, msg.mission_type
        )
        self.link.send(ack, addr)

    def _on_mission_upload(self, msg: Msg, addr: Address) -> None:
        """MISSION_COUNT: an empty upload clears (0 items, or the home slot alone: MAVSDK's clear_mission() for
        ArduPilot uploads one empty item), as ArduPilot answers it; a mission with waypoints is refused."""
        if msg.count == 0:
            self._mission_ack(msg, addr, M.MAV_MISSION_ACCEPTED)
        elif msg.count == 1 and msg.mission_type == M.MAV_MISSION_TYPE_MISSION:
            self._home_upload_from = addr
            self.link.send(
                self.link.mav.mission_request_int_encode(
                    msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
                ),
                addr,
            )
        else:
            self.link.statustext(M.MAV_SEVERITY_WARNING, MISSION_UPLOAD_REFUSAL, addr)
            self._mission_ack(msg, addr, M.MAV_MISSION_UNSUPPORTED)

    def _on_mission_item(self, msg: Msg, addr: Address) -> None:
        """Item 0 of a one-item upload (the home slot): accepted, and there is still no mission to fly."""
        if addr != self._home_upload_from or msg.seq != 0 or msg.mission_type != M.MAV_MISSION_TYPE_MISSION:
            return
        self._home_upload_from = None
        self._mission_ack(msg, addr, M.MAV_MISSION_ACCEPTED)

    def _mission_ack(self, msg: Msg, addr: Address, result: int) -> None:
        ack = self.link.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), result, msg.mission_type)
        self.link.send(ack, addr)

    def _on_mission_clear_all(self, msg: Msg, addr: Address) -> None:
        self._mission_ack(msg, addr, M.MAV_MISSION_ACCEPTED)

    def _on_ftp(self, msg: Msg, addr: Address) -> None:
        payload = bytes(msg.payload)
        if len(payload) < 12:
            return
        seq, session, opcode = struct.unpack_from("<HBB", payload)
        if opcode in (FTP_OP_ACK, FTP_OP_NAK):
            return  # a reply, not a request
        if opcode in (FTP_TERMINATE_SESSION, FTP_RESET_SESSIONS):
            reply, data = FTP_OP_ACK, b""
        else:
            reply, data = FTP_OP_NAK, bytes((FTP_ERR_UNKNOWN_COMMAND,))
        # seq + 1, session, opcode, size, req_opcode, burst_complete, padding, offset, data
        header = struct.pack("<HBBBBBBI", (seq + 1) % 65536, session, reply, len(data), opcode, 0, 0, 0)
        body = (header + data).ljust(FTP_PAYLOAD_LEN, b"\0")
        self.link.send(
            self.link.mav.file_transfer_protocol_encode(0, msg.get_srcSystem(), msg.get_srcComponent(), list(body)),
            addr,
        )
        size = payload[4]
        if opcode == FTP_OPEN_FILE_RO and payload[12 : 12 + size].startswith(FTP_PARAM_FILE):
            self._on_param_request_list(msg, addr)

    def _on_timesync(self, msg: Msg, addr: Address) -> None:
        if msg.tc1 == 0:  # a request; answer with our (simulated) clock in ns
            self.link.send(self.link.mav.timesync_encode(units.ns_from_s(self.v.clock.sim_s), msg.ts1), addr)
