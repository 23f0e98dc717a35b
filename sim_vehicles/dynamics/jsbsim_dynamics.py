"""The JSBSim backend: one JSBSim airframe per vehicle in the world's process, stepped in lockstep with the world.

Each vehicle's setpoint (the world action, [omega, u] in [-1, 1] scaled to the scenario's limits) goes to its
airframe's inner loop (:mod:`sim_vehicles.dynamics.jsbsim_airframe`), which flies it for one world step at the
physics rate. The airframe's ground position, ground speed and course then become the world's vehicle state
(:meth:`tssac_core.sim.world.World.set_states`), so the mission logic and the eq. 11 cost judge the path the
airframe flew. The truth the vehicles report is the airframe's: the measured turn rate and acceleration, attitude,
airspeed, altitude, climb and the wind at the airframe.
"""

from __future__ import annotations

import math

import numpy as np

from sim_vehicles.autopilot.telemetry import AirData, VehicleTruth
from sim_vehicles.dynamics.jsbsim_airframe import (
    AirframeError,
    AirframeSpec,
    AirframeState,
    JsbsimAirframe,
    StartState,
    Wind,
)
from tssac_core.sim.scenario import ROLES, Scenario
from tssac_core.sim.world import World
from tssac_core.wire.vehicle_limits import Achievable, bank_limited_turn_deg_s


def _clip_unit(x: float) -> float:
    """``np.clip(x, -1, 1)`` for one float; NaN (a garbage setpoint that passed) flies as 0."""
    return -1.0 if x < -1.0 else 1.0 if x > 1.0 else x if x == x else 0.0


def airframe_wind(scenario: Scenario) -> Wind:
    """The scenario's wind as the airframe's atmosphere takes it (calm without a ``wind:`` section)."""
    w = scenario.wind
    return Wind() if w is None else Wind(speed_m_s=w.speed_m_s, from_deg=w.from_deg, turbulence=w.turbulence)


def airframe_achievable(
    spec: AirframeSpec, turn_rate_max_rad_s: float, accel_max_m_s2: float, speed_max_m_s: float
) -> Achievable:
    """What a vehicle of airframe ``spec`` achieves with the scenario's limits: the scenario's turn rate, if a level
    coordinated turn at the bank limit gives it at the top speed (omega = g tan(bank) / v, the slowest turn of the
    envelope; else :class:`AirframeError`, one line: the scenario asks for a turn the airframe cannot fly), and the
    scenario's acceleration both ways, held to what the airframe file declares for its envelope."""
    turn_max = math.radians(bank_limited_turn_deg_s(spec.limits.bank_limit_deg, speed_max_m_s))
    if turn_max < turn_rate_max_rad_s:
        raise AirframeError(
            f"{spec.name}: turns at most {math.degrees(turn_max):.2f} deg/s at {speed_max_m_s:g} m/s (bank limit "
            f"{spec.limits.bank_limit_deg:g} deg); the scenario asks {math.degrees(turn_rate_max_rad_s):g} deg/s"
        )
    return Achievable(
        math.degrees(turn_rate_max_rad_s),
        min(accel_max_m_s2, spec.limits.max_accel_m_s2),
        min(accel_max_m_s2, -spec.limits.max_decel_m_s2),
    )


def truth_of(s: AirframeState) -> VehicleTruth:
    """A vehicle's truth from its airframe's state (the world's frame; attitude as MAVLink's)."""
    air = AirData(
        airspeed_m_s=s.airspeed_m_s,
        heading_rad=math.remainder(math.pi / 2 - s.yaw_rad, 2 * math.pi),
        roll_rad=s.roll_rad,
        pitch_rad=s.pitch_rad,
        roll_rate_rad_s=s.roll_rate_rad_s,
        pitch_rate_rad_s=s.pitch_rate_rad_s,
        yaw_rate_rad_s=s.yaw_rate_rad_s,
        alt_m=s.alt_m,
        climb_m_s=s.climb_m_s,
        wind_east_m_s=s.wind_east_m_s,
        wind_north_m_s=s.wind_north_m_s,
        throttle=s.throttle,
    )
    return VehicleTruth(s.east_m, s.north_m, s.groundspeed_m_s, s.course_rad, s.turn_rate_rad_s, s.accel_m_s2, air)


class JsbsimDynamics:
    """World 0's three vehicles, each a JSBSim airframe (created and settled at the scenario's starts)."""

    def __init__(self, world: World, spec: AirframeSpec, seed: int) -> None:
        self.world = world
        self.spec = spec
        self.name = f"jsbsim {spec.name}"
        c = world.c
        self._dt_s = c.dt_s
        self._turn_rate_max_rad_s: list[float] = c.turn_rate_max_rad_s.tolist()
        self._accel_max_m_s2: list[float] = c.accel_max_m_s2.tolist()
        self.achievable = [
            airframe_achievable(spec, turn, accel, v_max)
            for turn, accel, v_max in zip(
                self._turn_rate_max_rad_s, self._accel_max_m_s2, c.speed_max_m_s.tolist(), strict=True
            )
        ]
        """Each vehicle's achievable limits (:func:`airframe_achievable`)."""
        self.bank_limits_deg = [spec.limits.bank_limit_deg] * len(ROLES)
        wind = airframe_wind(world.scenario)
        alt_m = world.scenario.origin.alt_m
        seeds = np.random.SeedSequence(seed).generate_state(len(ROLES)).tolist()
        self.airframes: list[JsbsimAirframe] = []
        try:
            for i in range(len(ROLES)):
                start = StartState(
                    east_m=float(world.x_m[0, i]),
                    north_m=float(world.y_m[0, i]),
                    alt_m=alt_m,
                    speed_m_s=float(world.v_m_s[0, i]),
                    heading_rad=float(world.phi_rad[0, i]),
                )
                self.airframes.append(
                    JsbsimAirframe(
                        spec, start, wind, float(c.speed_min_m_s[i]), float(c.speed_max_m_s[i]), seed=int(seeds[i])
                    )
                )
        except BaseException:
            self.close()
            raise
        self._truths = [truth_of(a.state) for a in self.airframes]
        self._place()

    def truths(self) -> list[VehicleTruth]:
        """The vehicles' true states now (after the last step, or at the start)."""
        return self._truths

    def advance(self, actions: np.ndarray) -> list[VehicleTruth]:
        """Fly each moving vehicle's airframe through one step under its action; park the others."""
        w = self.world
        moving = (w.active[0] & w.running[0]).tolist()
        truths = list(self._truths)
        for i, airframe in enumerate(self.airframes):
            if not moving[i]:
                continue
            omega = _clip_unit(float(actions[0, i, 0])) * self._turn_rate_max_rad_s[i]
            accel = _clip_unit(float(actions[0, i, 1])) * self._accel_max_m_s2[i]
            truths[i] = truth_of(airframe.step(omega, accel, self._dt_s))
        self._truths = truths
        self._place()
        return truths

    def _place(self) -> None:
        t = self._truths
        self.world.set_states(
            np.array([[v.east_m for v in t]]),
            np.array([[v.north_m for v in t]]),
            np.array([[v.speed_m_s for v in t]]),
            np.array([[v.phi_rad for v in t]]),
        )

    def close(self) -> None:
        """Release the JSBSim instances (idempotent)."""
        for airframe in self.airframes:
            airframe.close()
        self.airframes = []
