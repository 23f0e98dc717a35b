"""The kinematic backend: eq. 5-6, the training world's own integration (:meth:`tssac_core.sim.world.World.integrate`).

In calm air a vehicle's truth is what it has always been: the path's speed and heading, the commanded turn rate
(the model flies it at once) and the speed change over the step; the telemetry derives the rest (coordinated-turn
bank, airspeed = ground speed). In a scenario's wind the world moves each vehicle with the air mass as well: the
truth is then the ground speed and course, and the air data (airspeed, the nose's heading, wind) are reported
apart. Turbulence is JSBSim's alone: here the wind is its mean.
"""

from __future__ import annotations

import math

import numpy as np

from sim_vehicles.autopilot.telemetry import GRAVITY_M_S2, AirData, VehicleTruth
from tssac_core.sim.world import World
from tssac_core.wire import units
from tssac_core.wire.vehicle_limits import Achievable, coordinated_bank_deg


def _clip_unit(x: float) -> float:
    """``np.clip(x, -1, 1)`` for one float (NaN stays NaN), without numpy's per-call overhead."""
    return -1.0 if x < -1.0 else 1.0 if x > 1.0 else x


class KinematicDynamics:
    """World 0's three vehicles under eq. 5-6 (and the scenario's wind drift)."""

    name = "kinematic"

    def __init__(self, world: World) -> None:
        self.world = world
        c = world.c
        self._dt_s = c.dt_s
        self._turn_rate_max_rad_s: list[float] = c.turn_rate_max_rad_s.tolist()
        wind = world.scenario.wind
        self._wind_m_s = None if wind is None or wind.speed_m_s == 0.0 else wind.velocity_m_s()
        self._alt_m = world.scenario.origin.alt_m
        self._truths: list[VehicleTruth] = []
        self._truths = self._measure([0.0] * len(self._turn_rate_max_rad_s), [0.0, 0.0, 0.0], None)
        self.achievable = [
            Achievable.point_mass(math.degrees(turn), accel)
            for turn, accel in zip(self._turn_rate_max_rad_s, c.accel_max_m_s2.tolist(), strict=True)
        ]
        """Each vehicle's achievable limits: eq. 6's, exactly (it flies the command at once, both ways)."""
        self.bank_limits_deg = [
            coordinated_bank_deg(math.degrees(turn), v_max)
            for v_max, turn in zip(c.speed_max_m_s.tolist(), self._turn_rate_max_rad_s, strict=True)
        ]
        """The bank of a coordinated turn at the turn-rate limit at the top speed: the most it reports banking."""

    def truths(self) -> list[VehicleTruth]:
        """The vehicles' true states now (after the last step, or at the start)."""
        return self._truths

    def advance(self, actions: np.ndarray) -> list[VehicleTruth]:
        """Move the vehicles through one step under ``actions`` (1, 3, 2) in [-1, 1]; return their truths."""
        w = self.world
        v_before = w.v_m_s[0].tolist()
        w.integrate(actions)
        self._truths = self._measure(actions[0, :, 0].tolist(), actions[0, :, 1].tolist(), v_before)
        return self._truths

    def close(self) -> None:
        """Nothing to release."""

    def _measure(self, turn: list[float], accel: list[float], v_before: list[float] | None) -> list[VehicleTruth]:
        w = self.world
        x, y = w.x_m[0].tolist(), w.y_m[0].tolist()
        v, phi, active = w.v_m_s[0].tolist(), w.phi_rad[0].tolist(), w.active[0].tolist()
        truths = []
        for i, turn_max in enumerate(self._turn_rate_max_rad_s):
            omega = _clip_unit(turn[i]) * turn_max if active[i] else 0.0
            if self._wind_m_s is None:
                accel_m_s2 = 0.0 if v_before is None else (v[i] - v_before[i]) / self._dt_s
                truths.append(VehicleTruth(x[i], y[i], v[i], phi[i], omega, accel_m_s2))
            else:
                truths.append(self._in_wind(i, x[i], y[i], v[i], phi[i], omega, accel[i]))
        return truths

    def _in_wind(self, i: int, x: float, y: float, v: float, phi: float, omega: float, accel: float) -> VehicleTruth:
        """A vehicle's truth in the wind: ground speed and course from the air velocity plus the wind; the course's
        turn rate and the ground speed's change measured against the last step's."""
        assert self._wind_m_s is not None
        we, wn = self._wind_m_s
        ve, vn = v * math.cos(phi) + we, v * math.sin(phi) + wn
        ground, course = math.hypot(ve, vn), math.atan2(vn, ve)
        if not self._truths:  # the start
            turn_rate, accel_m_s2 = 0.0, 0.0
        else:
            before = self._truths[i]
            turn_rate = math.remainder(course - before.phi_rad, 2 * math.pi) / self._dt_s
            accel_m_s2 = (ground - before.speed_m_s) / self._dt_s
        yaw_rate = units.yaw_rate_from_omega(omega)
        air = AirData(
            airspeed_m_s=v,
            heading_rad=phi,
            roll_rad=math.atan(v * yaw_rate / GRAVITY_M_S2),
            pitch_rad=0.0,
            roll_rate_rad_s=0.0,
            pitch_rate_rad_s=0.0,
            yaw_rate_rad_s=yaw_rate,
            alt_m=self._alt_m,
            climb_m_s=0.0,
            wind_east_m_s=we,
            wind_north_m_s=wn,
            throttle=0.5 + 0.5 * max(-1.0, min(1.0, accel)),
        )
        return VehicleTruth(x, y, ground, course, turn_rate, accel_m_s2, air)
