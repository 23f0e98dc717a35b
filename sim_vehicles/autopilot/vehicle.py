"""One SITL vehicle: what it is, what it flies and how it decides its next action.

The vehicle's state is its setup, its parameters, arming, mode, the setpoint it flies, its failsafes and its true
state after the last world step. It never moves itself: the runner (:mod:`sim_vehicles.world_runner`) asks it for
its action (:meth:`Vehicle.action`), steps the world and hands it the new true state (:meth:`Vehicle.observe`).
Everything MAVLink (the socket, the link model, telemetry streams, incoming messages) is its
:class:`~sim_vehicles.protocol.vehicle_link.VehicleLink`; the vehicle speaks through it only to say something (a
STATUSTEXT, :class:`Radio`) and to tell the lockstep barrier that it has come under companion control.

What arrives from clients is handled by :class:`sim_vehicles.protocol.commands.CommandHandler`, which changes this state
only through the methods here (:meth:`Vehicle.set_mode`, :meth:`Vehicle.set_armed`, :meth:`Vehicle.fly_demand`,
...).

* Modes (:mod:`sim_vehicles.autopilot.modes`, ArduPlane's numbers): MANUAL holds heading and speed; GUIDED
  flies setpoints; LOITER, CIRCLE and RTL steer by themselves (:mod:`sim_vehicles.autopilot.navigation`) while
  armed. Disarmed, the vehicle holds heading and speed (it is airborne from the first step).
* Setpoints (:mod:`sim_vehicles.autopilot.setpoints`): the companion's acceleration + yaw rate, MAVSDK's
  forward speed + yaw rate, or SET_ATTITUDE_TARGET's thrust + yaw rate; obeyed only armed in
  GUIDED. The world's action is (omega / turn_rate_max, u / accel_max) in [-1, 1], omega = -yaw_rate
  (:mod:`tssac_core.wire.units`: the companion scales its setpoints with the same functions).
* Setpoint-timeout failsafe: armed in GUIDED with no setpoint for ``GUID_TIMEOUT`` simulated seconds,
  hold heading and speed (STATUSTEXT, ``system_status`` CRITICAL) until the next setpoint. ArduPlane's
  CHANGE_HEADING / CHANGE_SPEED targets have no such timeout (``mode_guided.cpp``): while they are in force the
  vehicle flies them on, however long the companion is silent. Under lockstep a silent companion still stops
  holding the world after ``GUID_TIMEOUT`` wall seconds (:mod:`sim_vehicles.world_runner`); with targets in force
  that release changes nothing of what is flown (STATUSTEXT "... flying its GUIDED targets").
* Datalink failsafe (ArduPlane's ``FS_GCS_ENABL``, ``FS_LONG_TIMEOUT``, ``FS_LONG_ACTN``): armed, with
  the failsafe enabled, and no valid message from any client for ``FS_LONG_TIMEOUT`` wall seconds
  after one was heard: RTL (from MANUAL always, from GUIDED when ``FS_LONG_ACTN`` is 1).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sim_vehicles.autopilot import guided_slew, navigation
from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.autopilot.events import EventKind, MissionEvent, WorldFlags
from sim_vehicles.autopilot.guided_slew import HeadingTarget, SpeedTarget
from sim_vehicles.autopilot.modes import AUTONOMOUS, FlightMode
from sim_vehicles.autopilot.params import ParamTable, vehicle_params
from sim_vehicles.autopilot.setpoints import Demand, Refusal, SetpointForm, accel_command
from sim_vehicles.autopilot.telemetry import VehicleTruth
from sim_vehicles.link.link_model import GpsReceiver
from tssac_core.sim.scenario import LinkModel, Origin
from tssac_core.wire import units
from tssac_core.wire.vehicle_limits import Achievable

_log = logging.getLogger(__name__)

M = mavlink2  # enums
COMPONENT_ID = 1
"""MAV_COMP_ID_AUTOPILOT1."""
EPS_S = 1e-6
"""Slack of the simulated-time comparisons (timeouts, stream schedules)."""
GOTO_UNDO_S = 5.0
"""A goto refused within this many wall seconds of the switch to GUIDED made for it undoes the switch."""
REFUSAL_INTERVAL_S = 1.0
"""A refused setpoint stream (20 Hz from MAVSDK) gets one STATUSTEXT per second."""


@dataclass(frozen=True)
class VehicleSetup:
    """What a vehicle needs to know about itself and its world."""

    index: int
    """Position in ROLES (0 decoy, 1 detect, 2 strike)."""
    role: str
    sysid: int
    turn_rate_max_rad_s: float
    accel_max_m_s2: float
    speed_min_m_s: float
    speed_max_m_s: float
    dt_s: float
    origin: Origin
    home_east_m: float
    home_north_m: float
    link: LinkModel
    setpoint_timeout_s: float
    achievable: Achievable | None = None
    """What the physics achieves of the limits (published as ACHV_*); None: the limits themselves."""
    bank_limit_deg: float | None = None
    """Its largest bank (published as ROLL_LIMIT_DEG); None: a coordinated turn's at the limits."""


@dataclass(frozen=True)
class FlownSetpoint:
    """The setpoint being flown."""

    demand: Demand
    """What it asks for (limits are applied at each step, see :meth:`Vehicle.action`)."""
    time_s: float
    """Simulated time it arrived."""


@dataclass
class VehicleCounters:
    """Protocol-level counts (link and framing counts live in the endpoint and channels)."""

    setpoints_accepted: int = 0
    setpoints_ignored: int = 0
    """Valid setpoints that arrived while not armed in GUIDED."""
    setpoints_rejected: int = 0
    """Setpoints with an unsupported frame or type_mask, or non-finite values."""
    commands: int = 0
    commands_unsupported: int = 0
    not_for_us: int = 0
    """Messages addressed to another system or component."""
    failsafes: int = 0
    datalink_failsafes: int = 0
    refusal_texts_suppressed: int = 0
    """Refusal STATUSTEXTs not sent because the same kind went out less than REFUSAL_INTERVAL_S ago."""
    handler_errors: int = 0
    """Messages whose handler raised (a bug: logged with its traceback)."""


@dataclass
class Orbit:
    """The circle an autonomous mode flies (world frame, metres)."""

    center: tuple[float, float] | None
    """None: CIRCLE's constant turn without a centre."""
    radius_m: float
    ccw: bool = False


@dataclass
class DatalinkWatch:
    """When a client was last heard (wall clock), for the datalink failsafe."""

    last_heard_wall_s: float | None = None
    """None until the first valid message from any client."""
    lost: bool = False


@dataclass
class RefusalLimiter:
    """A refusal STATUSTEXT of each kind at most every ``interval_s`` wall seconds (not once per kind)."""

    interval_s: float
    last_wall_s: dict[str, float] = field(default_factory=dict)

    def allow(self, kind: str, now_wall_s: float) -> bool:
        last = self.last_wall_s.get(kind)
        if last is not None and now_wall_s - last < self.interval_s:
            return False
        self.last_wall_s[kind] = now_wall_s
        return True

    def forget(self, kind: str) -> None:
        self.last_wall_s.pop(kind, None)


class Radio(Protocol):
    """What the vehicle says over its datalink (:class:`sim_vehicles.protocol.vehicle_link.VehicleLink`)."""

    def statustext(self, severity: int, text: str) -> None:
        """A STATUSTEXT to every client."""

    def took_control(self) -> None:
        """The companion has just taken control (armed in GUIDED): the lockstep barrier notes where its client
        stands."""


class _NoRadio:
    """The radio of a vehicle not yet connected to its link: says nothing."""

    def statustext(self, severity: int, text: str) -> None:
        pass

    def took_control(self) -> None:
        pass


EventSink = Callable[[str, str, int, str | None], None]
"""(role, event name, value, text or None) -> None: arming, mode, failsafe changes and relayed STATUSTEXTs for the
truth log."""


class Vehicle:
    """One autopilot's state and decisions (see the module docstring)."""

    def __init__(
        self,
        setup: VehicleSetup,
        clock: Clock,
        flags: WorldFlags,
        gps_rng: np.random.Generator,
        on_event: EventSink | None = None,
    ) -> None:
        self.setup = setup
        self.index = setup.index
        self.role = setup.role
        self.sysid = setup.sysid
        self.compid = COMPONENT_ID
        self.clock = clock
        self.flags = flags
        self.gps = GpsReceiver(setup.link, gps_rng)
        self.params: ParamTable = vehicle_params(
            setup.sysid,
            setup.setpoint_timeout_s,
            setup.dt_s,
            math.degrees(setup.turn_rate_max_rad_s),
            setup.accel_max_m_s2,
            setup.speed_min_m_s,
            setup.speed_max_m_s,
            setup.achievable,
            setup.bank_limit_deg,
        )
        self.counters = VehicleCounters()
        self._on_event = on_event
        self.radio: Radio = _NoRadio()
        """Set by the vehicle's :class:`~sim_vehicles.protocol.vehicle_link.VehicleLink` when it is made."""
        self.armed = False
        self.mode = FlightMode.MANUAL
        self.failsafe = False
        self.fence_breached = False
        self.setpoint: FlownSetpoint | None = None
        self._guided_from: tuple[FlightMode, float] | None = None
        """(the mode before GUIDED, wall time of the switch) while in GUIDED: a refused goto undoes the switch."""
        self.last_setpoint_s = 0.0
        self.loop_since_wall_s = 0.0
        """Wall time the vehicle last came under companion control (for the lockstep barrier)."""
        self.last_action = (0.0, 0.0)
        self.truth = VehicleTruth(setup.home_east_m, setup.home_north_m, setup.speed_min_m_s, 0.0, 0.0, 0.0)
        self.orbit: Orbit | None = None
        self.datalink = DatalinkWatch()
        self.refusals = RefusalLimiter(REFUSAL_INTERVAL_S)

    # ------------------------------------------------------------------------------ properties

    @property
    def guided(self) -> bool:
        return self.mode is FlightMode.GUIDED

    @property
    def setpoint_timeout_s(self) -> float:
        p = self.params.get("GUID_TIMEOUT")
        assert p is not None
        return p.value

    @property
    def targets_in_force(self) -> bool:
        """Armed in GUIDED with ArduPlane's CHANGE_HEADING / CHANGE_SPEED targets in force (flown with no timeout)."""
        sp = self.setpoint
        return self.armed and self.guided and sp is not None and sp.demand.form is SetpointForm.GUIDED_SLEW

    @property
    def in_loop(self) -> bool:
        """Under companion control: armed in GUIDED and not in failsafe (the lockstep barrier waits for it)."""
        return self.armed and self.guided and not self.failsafe

    @property
    def system_status(self) -> int:
        """HEARTBEAT.system_status: POWEROFF once the mission has ended (the SITL exits after its linger: what a
        companion checks a mission end against), CRITICAL in a failsafe, else ACTIVE armed / STANDBY disarmed."""
        if self.flags.end is not None:
            return M.MAV_STATE_POWEROFF
        if self.failsafe or self.datalink.lost:
            return M.MAV_STATE_CRITICAL
        return M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY

    def param(self, name: str) -> float:
        p = self.params.get(name)
        assert p is not None, name
        return p.value

    # ------------------------------------------------------------------------------- physics

    def action(self) -> tuple[float, float]:
        """The world action [omega, u] in [-1, 1] for the next step (checks the failsafes first)."""
        now = self.clock.sim_s
        if self.in_loop and not self.targets_in_force and now - self.last_setpoint_s > self.setpoint_timeout_s + EPS_S:
            self.enter_failsafe(f"no setpoint for {self.setpoint_timeout_s:g} s")
        self.check_datalink()
        omega, accel = self._command_now()
        su = self.setup
        a = units.action_from_command(omega, accel, su.turn_rate_max_rad_s, su.accel_max_m_s2)
        self.last_action = a
        return a

    def _command_now(self) -> tuple[float, float]:
        """(omega CCW-positive rad/s, forward acceleration m/s^2) within the limits, for the current mode."""
        su, t = self.setup, self.truth
        sp = self.setpoint
        if self.targets_in_force and sp is not None:
            return self._slew_command(sp.demand)  # in a (lockstep) failsafe too: they have no timeout
        if self.in_loop and sp is not None:
            if sp.demand.course_rad is not None:
                omega = navigation.course_turn_rate(t.phi_rad, sp.demand.course_rad, su.turn_rate_max_rad_s)
            else:
                omega = units.omega_from_yaw_rate(sp.demand.yaw_rate_rad_s)
                omega = min(su.turn_rate_max_rad_s, max(-su.turn_rate_max_rad_s, omega))
            accel = accel_command(
                sp.demand, t.speed_m_s, su.accel_max_m_s2, su.speed_min_m_s, su.speed_max_m_s, su.dt_s
            )
            return omega, accel
        orbit = self.orbit
        if self.armed and self.mode in AUTONOMOUS and orbit is not None:
            if orbit.center is None:
                return navigation.circle_turn_rate(t.speed_m_s, orbit.radius_m, orbit.ccw, su.turn_rate_max_rad_s), 0.0
            omega = navigation.orbit_turn_rate(
                t.east_m,
                t.north_m,
                t.phi_rad,
                t.speed_m_s,
                orbit.center,
                orbit.radius_m,
                orbit.ccw,
                su.turn_rate_max_rad_s,
            )
            return omega, 0.0
        return 0.0, 0.0

    def _slew_command(self, demand: Demand) -> tuple[float, float]:
        """ArduPlane's GUIDED under CHANGE_HEADING / CHANGE_SPEED (:mod:`sim_vehicles.autopilot.guided_slew`): the
        turn toward the heading target, the speed toward the speed target, each at its commanded rate."""
        su, t = self.setup, self.truth
        air = t.air
        omega = 0.0
        heading = demand.heading_target
        if heading is not None:
            now = t.phi_rad if heading.over_ground or air is None else air.heading_rad
            omega = guided_slew.heading_turn_rate(heading, now, t.speed_m_s, su.turn_rate_max_rad_s)
        accel = 0.0
        if demand.speed_target is not None:
            airspeed = t.speed_m_s if air is None else air.airspeed_m_s
            accel = guided_slew.speed_accel(demand.speed_target, airspeed, su.accel_max_m_s2, su.dt_s)
        return omega, accel

    def fly_heading(self, target: HeadingTarget | None) -> bool:
        """A CHANGE_HEADING (None: back to GUIDED's own navigation, straight on here), beside the CHANGE_SPEED in
        force; flown if armed in GUIDED (True)."""
        return self.fly_demand(dataclasses.replace(self._slew_in_force(), heading_target=target))

    def fly_speed(self, target: SpeedTarget) -> bool:
        """A CHANGE_SPEED, beside the CHANGE_HEADING in force; flown if armed in GUIDED (True)."""
        return self.fly_demand(dataclasses.replace(self._slew_in_force(), speed_target=target))

    def _slew_in_force(self) -> Demand:
        sp = self.setpoint
        if sp is not None and sp.demand.form is SetpointForm.GUIDED_SLEW:
            return sp.demand
        return Demand(SetpointForm.GUIDED_SLEW, 0.0)

    def observe(self, truth: VehicleTruth) -> None:
        """The true state after a world step (or at reset)."""
        self.truth = truth

    def sample_gps(self) -> None:
        """Take a GPS fix of the true state if one is due (before the telemetry of a step is sent)."""
        t = self.truth
        self.gps.sample(self.clock.sim_s, t.east_m, t.north_m, t.vel_east_m_s, t.vel_north_m_s)

    def mission_event(self, event: MissionEvent) -> None:
        """A mission event of the world: a geofence breach of this vehicle shows in its SYS_STATUS from now on."""
        if event.kind is EventKind.GEOFENCE and event.vehicle == self.index:
            self.fence_breached = True

    # -------------------------------------------------------------------------- state changes

    def set_mode(self, mode: FlightMode, reason: str = "") -> None:
        """Enter ``mode`` (a no-op if already in it); autonomous modes pick their circle now."""
        if mode is self.mode:
            return
        was_in_loop = self.in_loop
        self._guided_from = (self.mode, self.clock.wall_s) if mode is FlightMode.GUIDED else None
        self.mode = mode
        self.setpoint = None
        self.failsafe = False
        self.refusals.forget("ignored")
        self.orbit = self._orbit_for(mode)
        self._enter_loop_if(was_in_loop)
        _log.info("%s: mode %s%s", self.role, mode.name, f" ({reason})" if reason else "")
        self.event("MODE", int(mode))

    def undo_guided_switch(self, reason: str) -> bool:
        """Go back to the mode before GUIDED if GUIDED was entered less than GOTO_UNDO_S wall seconds ago and no
        setpoint has come since (a refused goto's mode change, see CommandHandler); True if it did."""
        if self.mode is not FlightMode.GUIDED or self.setpoint is not None or self._guided_from is None:
            return False
        previous, since_wall_s = self._guided_from
        if self.clock.wall_s - since_wall_s > GOTO_UNDO_S:
            return False
        self.set_mode(previous, reason)
        return True

    def _orbit_for(self, mode: FlightMode) -> Orbit | None:
        t, su = self.truth, self.setup
        if mode not in AUTONOMOUS:
            return None
        radius = navigation.orbit_radius_m(self.param("WP_LOITER_RAD"), t.speed_m_s, su.turn_rate_max_rad_s)
        if mode is FlightMode.RTL:
            return Orbit((su.home_east_m, su.home_north_m), radius)
        if mode is FlightMode.LOITER:
            return Orbit(navigation.orbit_center(t.east_m, t.north_m, t.phi_rad, radius, ccw=False), radius)
        return Orbit(None, radius)  # CIRCLE

    def set_armed(self, armed: bool) -> None:
        if armed is self.armed:
            return
        was_in_loop = self.in_loop
        self.armed = armed
        self.setpoint = None
        self.failsafe = False
        self.refusals.forget("ignored")
        self._enter_loop_if(was_in_loop)
        _log.info("%s: %s", self.role, "armed" if armed else "disarmed")
        self.event("ARMED", int(armed))

    def _enter_loop_if(self, was_in_loop: bool) -> None:
        if self.in_loop and not was_in_loop:
            # The setpoint timeout runs from the moment the companion takes control.
            self.last_setpoint_s = self.clock.sim_s
            self.loop_since_wall_s = self.clock.wall_s
            self.radio.took_control()

    def fly_demand(self, demand: Demand) -> bool:
        """Fly a parsed setpoint if armed in GUIDED (True), else count it as ignored (False)."""
        if not (self.armed and self.guided):
            self.counters.setpoints_ignored += 1
            self.refuse("ignored", "SP ignored: arm and set GUIDED (15) first")
            return False
        now = self.clock.sim_s
        self.setpoint = FlownSetpoint(demand, now)
        self.last_setpoint_s = now
        self.counters.setpoints_accepted += 1
        if self.failsafe:
            self.clear_failsafe()
        return True

    def reject(self, refusal: Refusal) -> None:
        """A setpoint that cannot be flown: counted, and a STATUSTEXT that says what to send instead."""
        self.counters.setpoints_rejected += 1
        self.refuse(refusal.kind, refusal.text)

    def refuse(self, kind: str, text: str) -> None:
        """STATUSTEXT ``text`` to every client, at most once per REFUSAL_INTERVAL_S for each ``kind``."""
        if self.refusals.allow(kind, self.clock.wall_s):
            self.radio.statustext(M.MAV_SEVERITY_WARNING, text)
        else:
            self.counters.refusal_texts_suppressed += 1

    def event(self, name: str, value: int, text: str | None = None) -> None:
        """A change for the truth log (``text``: a client's STATUSTEXT relayed)."""
        if self._on_event is not None:
            self._on_event(self.role, name, value, text)

    # ------------------------------------------------------------------------------ failsafes

    def enter_failsafe(self, reason: str) -> None:
        """Hold heading and speed until the next setpoint (with targets in force: fly them on, module docstring);
        CRITICAL in the heartbeat."""
        if self.failsafe:
            return
        self.failsafe = True
        self.counters.failsafes += 1
        flies = "flying its GUIDED targets" if self.targets_in_force else "holding"
        _log.warning("%s: failsafe: %s, %s", self.role, reason, flies)
        self.radio.statustext(M.MAV_SEVERITY_WARNING, f"Failsafe: {reason}, {flies}")
        self.event("FAILSAFE", 1)

    def clear_failsafe(self) -> None:
        self.failsafe = False
        self.loop_since_wall_s = self.clock.wall_s
        self.radio.statustext(M.MAV_SEVERITY_INFO, "Failsafe cleared: setpoints resumed")
        self.event("FAILSAFE", 0)

    def heard_client(self) -> None:
        """A valid message from a client arrived (the datalink failsafe's clock restarts)."""
        self.datalink.last_heard_wall_s = self.clock.wall_s
        if self.datalink.lost:
            self.datalink.lost = False
            self.radio.statustext(M.MAV_SEVERITY_INFO, "Failsafe: datalink restored")
            self.event("DATALINK", 0)

    def check_datalink(self) -> None:
        """ArduPlane's long GCS failsafe: no client heard for FS_LONG_TIMEOUT wall seconds while armed."""
        d = self.datalink
        if d.lost or d.last_heard_wall_s is None or not self.armed or self.param("FS_GCS_ENABL") == 0:
            return
        timeout = self.param("FS_LONG_TIMEOUT")
        if self.clock.wall_s - d.last_heard_wall_s <= timeout:
            return
        d.lost = True
        self.counters.datalink_failsafes += 1
        # ArduPlane: from a pilot mode always RTL; from an auto mode RTL only with FS_LONG_ACTN = 1.
        rtl = self.mode is not FlightMode.RTL and (self.mode is FlightMode.MANUAL or self.param("FS_LONG_ACTN") == 1)
        action = "RTL" if rtl else f"staying in {self.mode.name}"
        _log.warning("%s: datalink lost for %g s: %s", self.role, timeout, action)
        self.radio.statustext(M.MAV_SEVERITY_CRITICAL, f"Failsafe: no link {timeout:g} s, {action}")
        self.event("DATALINK", 1)
        if rtl:
            self.set_mode(FlightMode.RTL, "datalink failsafe")
