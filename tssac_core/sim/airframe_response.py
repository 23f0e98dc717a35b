"""An airframe's measured response to the world's setpoints: the turn-rate lag and the achievable acceleration per
speed, fitted from JSBSim step responses (``python -m sim_vehicles.dynamics.response_fit``) and kept as data beside
the airframe's inner-loop gains (``sim_vehicles/dynamics/airframes/<name>.response.yaml``).

The point-mass model of eq. 5-6 turns at the commanded rate at once and accelerates at +-a_max. A fixed wing under
its inner loop does neither: it rolls in first, and its engine and drag set what it can gain or lose. The response
file describes the difference in the world's own terms (a heading-rate command held for a world step of ``dt_s``):

    omega_k+1 = omega_k + g (omega_cmd(k - d) - omega_k),   g = 1 - exp(-dt / tau)   (delay d steps, then first order)

the continuous first-order lag sampled at the steps; the heading turns over step k by its exact mean,
``omega_cmd(k - d) + (omega_k - omega_cmd(k - d)) h`` with ``h = tau g / dt``
(:func:`tssac_core.assurance.lagged_backups.lag_step_mean`). The time constant is ``turn_rollout_tau_s`` while the
rate rolls out (the command asks for less turn the same way, or none) and ``turn_tau_s`` otherwise (rolling in, or
reversing): a fixed wing rolls out of a turn faster than it rolls in
(:func:`tssac_core.assurance.lagged_backups.switched_lag_step`), in the monitor's model and in the training world's
varied airframes (:mod:`tssac_core.sim.varied_airframes`) alike.

with ``d = round(delay_s / dt_s)``, and the forward acceleration bounded by
``decel_max_m_s2(v) <= a <= accel_max_m_s2(v)``.
The lag is scheduled on speed: one time constant does not fit 150 and 300 m/s.
``turn_residual_m`` is the largest distance, per speed, between the airframe's path and this model's over a
maximum-rate turn held for two full circles, entered from straight flight and from a maximum-rate turn the other
way, and over a roll-out from a maximum-rate turn into straight flight: an error term that a bound built on the model
adds to its margin.

Between two tabled speeds the delay and time constants are interpolated linearly, and the worse neighbour's residual,
acceleration and deceleration count (the larger residual, the smaller magnitudes); outside the span the file is
refused (:meth:`AirframeResponse.at`). That the residual still bounds the airframe between the tabled speeds is
measured, not assumed: ``tests/test_lagged_backups.py`` flies the F-16 there.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from tssac_core.assurance.ground_loiter import LoiterBound, LoiterLaw
from tssac_core.assurance.lagged_backups import AirframeLag, lag_gains
from tssac_core.common.cli import UsageError
from tssac_core.common.errors import InputError
from tssac_core.common.files import sha256_file
from tssac_core.sim.yaml_file import read_yaml, typed_value

if TYPE_CHECKING:
    from tssac_core.sim.scenario import Scenario

RESPONSE_SCHEMA = 5
"""The file format's version; a newer one is refused (2 added ``turn_rollout_tau_s``; a version 1 file reads with the
roll-in's time constants for the roll-out; 3 added the ground loiter's fit, ``loiter_*``: a file without it promises
no loiter, so no wind; 4 added the loiter's turn-in and its own residuals, ``loiter_turn_in_s``,
``loiter_residual_m`` and ``loiter_heading_residual_deg``: a version 3 file's loiter starts where the lead ends, with
the turns' residuals; 5 added the held leads, ``held_after_s``, ``held_leads_s`` and ``held_residual_m``: an older file
offers none)."""


class ResponseFileError(InputError):
    """A response file that cannot be used: unreadable, malformed, for another airframe, or asked outside its span."""


@dataclass(frozen=True)
class ResponseAt:
    """The response at one speed (the worse of the two tabled neighbours)."""

    delay_s: float
    tau_s: float
    rollout_tau_s: float
    turn_residual_m: float
    accel_max_m_s2: float
    decel_max_m_s2: float
    loiter_excursion_m: float | None = None
    """How far beyond its radius the ground loiter may fly (m); None: no loiter fitted."""
    heading_residual_deg: float = 0.0
    """How far the airframe's course may lie from the model's heading (deg)."""
    held_residual_m: float | None = None
    """How far a held backup's path may lie from the prediction (m); None: no held leads fitted."""

    def delay_steps(self, dt_s: float) -> int:
        """The delay in whole world steps of ``dt_s``."""
        return round(self.delay_s / dt_s)

    def lag_gain(self, dt_s: float) -> float:
        """The first-order lag's share of the gap closed per world step: 1 - exp(-dt / tau)."""
        return float(lag_gains(np.array([self.tau_s]), dt_s)[0][0])


@dataclass(frozen=True)
class AirframeResponse:
    """A response file, loaded (module docstring). Tuples are per entry of ``speeds_m_s``, ascending."""

    schema: int
    """The format's version (:data:`RESPONSE_SCHEMA`)."""
    aircraft: str
    """The airframe file's name (``f16``)."""
    airframe_sha256: str
    """SHA-256 of the airframe file the fit flew: the response belongs to those gains and limits only."""
    jsbsim_version: str
    """The JSBSim the fit flew."""
    command: str
    """The command that wrote the file."""
    altitude_m: float
    """Altitude of the fit (m)."""
    dt_s: float
    """The world step the model is written for (s)."""
    turn_rate_max_rad_s: float
    """The turn-rate step of the fit (rad/s): the scenarios' limit."""
    speeds_m_s: tuple[float, ...]
    turn_delay_s: tuple[float, ...]
    turn_tau_s: tuple[float, ...]
    """The lag's time constant rolling in or reversing, s."""
    turn_residual_m: tuple[float, ...]
    accel_max_m_s2: tuple[float, ...]
    """Mean acceleration over ``accel_window_s`` of full throttle from each speed (m/s^2, positive)."""
    decel_max_m_s2: tuple[float, ...]
    """Mean deceleration over ``accel_window_s`` at idle from each speed (m/s^2, negative)."""
    accel_window_s: float
    """The window of the acceleration figures (s)."""
    turn_rollout_tau_s: tuple[float, ...] = ()
    """The lag's time constant rolling out (toward a smaller turn the same way, or none), s; empty in a version 1 file
    (the roll-in's then count)."""
    turn_heading_residual_deg: tuple[float, ...] = ()
    """Per speed, the largest difference between the airframe's course and the model's heading over the same runs as
    ``turn_residual_m`` (deg): where a backup's loiter starts its centre lies R normal to the ground track, so a heading
    off by this moves the centre by R times it; empty in files before version 3 (none of their backups loiters)."""
    loiter_wind_max_m_s: float = 0.0
    """The steady wind the ground loiter's excursion was measured in, from every direction (m/s; the loiter's circle
    is sized for it: :func:`tssac_core.assurance.ground_loiter.loiter_radius_m`)."""
    loiter_authority: float = LoiterLaw.authority
    """The loiter law's gains the excursion was measured with
    (:class:`~tssac_core.assurance.ground_loiter.LoiterLaw`)."""
    loiter_lookahead_share: float = LoiterLaw.lookahead_share
    loiter_track_gain_1_s: float = LoiterLaw.track_gain_1_s
    loiter_excursion_m: tuple[float, ...] = ()
    """Per speed, the largest distance beyond the loiter's radius from its centre that the airframe (JSBSim) or its
    lag model flew (m), after a backup's lead and turn-in from straight flight and from maximum-rate turns either way,
    in calm air and in ``loiter_wind_max_m_s`` from every direction; empty: no loiter fitted (files before version
    3)."""
    loiter_turn_in_s: float = 0.0
    """How long a backup's maximum-rate turn flies between its lead and its loiter (s; 0 in a version 3 file: the
    loiter starts where the lead ends)."""
    loiter_residual_m: tuple[float, ...] = ()
    """Per speed, the largest distance between the airframe's path and the model's over the loiter fit's leads and
    turn-ins (m); empty (version 3): ``turn_residual_m``."""
    loiter_heading_residual_deg: tuple[float, ...] = ()
    """Per speed, the largest difference between the airframe's heading and the model's where the fit's loiters
    start (deg; the loiter's centre lies R normal to the ground track there); empty (version 3):
    ``turn_heading_residual_deg``."""
    held_after_s: float = 32.0
    """How long a held lead flies open loop before it holds its course (s): the longest open lead the turns' fit
    covers (:func:`tssac_core.assurance.lagged_backups.held_rollout`)."""
    held_leads_s: tuple[float, ...] = ()
    """The held leads the fit flew (s, each longer than ``held_after_s``): a monitor predicting with this file offers
    these in calm air beside its open ones; empty (files before version 5): none."""
    held_residual_m: tuple[float, ...] = ()
    """Per speed, how far a held backup's path may lie from the monitor's prediction (m), the largest over the fit's
    JSBSim and lag-model runs (:mod:`sim_vehicles.dynamics.held_fit`); empty when ``held_leads_s`` is."""

    def loiter_law(self) -> LoiterLaw:
        """The loiter law the excursion was measured with."""
        return LoiterLaw(self.loiter_authority, self.loiter_lookahead_share, self.loiter_track_gain_1_s)

    def loiter_bound(self) -> LoiterBound | None:
        """The ground loiter's fitted figures (None: none fitted, a file before version 3)."""
        if not self.loiter_excursion_m:
            return None
        degrees = self.loiter_heading_residual_deg or self.turn_heading_residual_deg
        headings = tuple(math.radians(d) for d in degrees) or (0.0,) * len(self.speeds_m_s)
        return LoiterBound(
            self.loiter_wind_max_m_s,
            self.loiter_law(),
            self.speeds_m_s,
            self.loiter_excursion_m,
            headings,
            self.loiter_residual_m or self.turn_residual_m,
            self.loiter_turn_in_s,
        )

    def rollout_taus(self) -> tuple[float, ...]:
        """``turn_rollout_tau_s``, or for a version 1 file the roll-in's time constants."""
        return self.turn_rollout_tau_s or self.turn_tau_s

    def __post_init__(self) -> None:
        n = len(self.speeds_m_s)
        tables = (
            self.turn_delay_s,
            self.turn_tau_s,
            self.rollout_taus(),
            self.turn_residual_m,
            self.accel_max_m_s2,
            self.decel_max_m_s2,
        )
        optional = (
            self.loiter_excursion_m,
            self.turn_heading_residual_deg,
            self.loiter_residual_m,
            self.loiter_heading_residual_deg,
            self.held_residual_m,
        )
        if bool(self.held_leads_s) != bool(self.held_residual_m) or any(
            t <= self.held_after_s for t in self.held_leads_s
        ):
            raise ValueError(
                f"response of {self.aircraft}: held leads need their residuals, each longer than held_after_s"
            )
        if n < 1 or any(len(t) != n for t in tables) or any(len(t) not in (0, n) for t in optional):
            raise ValueError(f"response of {self.aircraft}: every table needs one entry per speed ({n})")
        if any(b <= a for a, b in zip(self.speeds_m_s, self.speeds_m_s[1:])) or self.speeds_m_s[0] <= 0.0:
            raise ValueError(f"response of {self.aircraft}: speeds_m_s must be positive and ascending")
        if (
            min(self.turn_delay_s + self.turn_tau_s + self.rollout_taus() + self.turn_residual_m) < 0.0
            or min(self.loiter_excursion_m + self.loiter_residual_m + (self.loiter_wind_max_m_s,)) < 0.0
            or min(self.loiter_heading_residual_deg + (self.loiter_turn_in_s,)) < 0.0
        ):
            raise ValueError(
                f"response of {self.aircraft}: delays, time constants, residuals and excursions must be >= 0"
            )
        self.loiter_law()  # its gains checked
        if min(self.accel_max_m_s2) <= 0.0 or max(self.decel_max_m_s2) >= 0.0:
            raise ValueError(f"response of {self.aircraft}: accelerations must be > 0 and decelerations < 0")
        if not (self.dt_s > 0.0 and self.turn_rate_max_rad_s > 0.0 and self.accel_window_s > 0.0):
            raise ValueError(f"response of {self.aircraft}: dt_s, turn_rate_max_rad_s and accel_window_s must be > 0")

    def at(self, speed_m_s: float) -> ResponseAt:
        """The response at ``speed_m_s``: the delay and time constants interpolated linearly between its tabled
        neighbours (the lag's shape changes smoothly with speed: the worse neighbour's lag flown for 30 s leaves
        heading errors the residual does not cover), the worse neighbour's residual and accelerations."""
        lo, hi = self.speeds_m_s[0], self.speeds_m_s[-1]
        if not lo - 1e-9 <= speed_m_s <= hi + 1e-9:
            raise ResponseFileError(
                f"response of {self.aircraft}: speed {speed_m_s:g} m/s is outside the fitted span {lo:g}-{hi:g} m/s"
            )
        i = bisect.bisect_left(self.speeds_m_s, speed_m_s - 1e-9)
        j = i if abs(self.speeds_m_s[i] - speed_m_s) <= 1e-9 else i - 1
        share = 0.0 if i == j else (speed_m_s - self.speeds_m_s[j]) / (self.speeds_m_s[i] - self.speeds_m_s[j])

        def between(table: tuple[float, ...]) -> float:
            return table[j] + share * (table[i] - table[j])

        pair = (i, j)
        return ResponseAt(
            delay_s=between(self.turn_delay_s),
            tau_s=between(self.turn_tau_s),
            rollout_tau_s=between(self.rollout_taus()),
            turn_residual_m=max(self.turn_residual_m[k] for k in pair),
            accel_max_m_s2=min(self.accel_max_m_s2[k] for k in pair),
            decel_max_m_s2=max(self.decel_max_m_s2[k] for k in pair),
            loiter_excursion_m=max(self.loiter_excursion_m[k] for k in pair) if self.loiter_excursion_m else None,
            heading_residual_deg=max((self.turn_heading_residual_deg[k] for k in pair), default=0.0)
            if self.turn_heading_residual_deg
            else 0.0,
            held_residual_m=max(self.held_residual_m[k] for k in pair) if self.held_residual_m else None,
        )

    def worst(self, speed_min_m_s: float, speed_max_m_s: float) -> ResponseAt:
        """The worst response anywhere in [speed_min, speed_max] (a bound for a vehicle flying that envelope)."""
        inside = [self.at(speed_min_m_s), self.at(speed_max_m_s)]
        inside += [self.at(v) for v in self.speeds_m_s if speed_min_m_s < v < speed_max_m_s]
        return ResponseAt(
            delay_s=max(r.delay_s for r in inside),
            tau_s=max(r.tau_s for r in inside),
            rollout_tau_s=max(r.rollout_tau_s for r in inside),
            turn_residual_m=max(r.turn_residual_m for r in inside),
            accel_max_m_s2=min(r.accel_max_m_s2 for r in inside),
            decel_max_m_s2=max(r.decel_max_m_s2 for r in inside),
            loiter_excursion_m=max(
                (r.loiter_excursion_m for r in inside if r.loiter_excursion_m is not None), default=None
            ),
            heading_residual_deg=max(r.heading_residual_deg for r in inside),
            held_residual_m=max((r.held_residual_m for r in inside if r.held_residual_m is not None), default=None),
        )


def load_response(path: str | Path, airframe_path: str | Path | None = None) -> AirframeResponse:
    """Read a response file; with ``airframe_path``, refuse one fitted to another version of that airframe file.
    Every problem is one :class:`ResponseFileError` line."""

    def error(source: str, where: str, problem: str) -> ResponseFileError:
        return ResponseFileError(f"{source}: {where + ': ' if where else ''}{problem}")

    raw = read_yaml(path, error)
    if isinstance(raw, dict) and isinstance(raw.get("schema"), int) and raw["schema"] > RESPONSE_SCHEMA:
        raise error(str(path), "schema", f"version {raw['schema']} is newer than this program's ({RESPONSE_SCHEMA})")
    response = typed_value(AirframeResponse, raw, "", str(path), error)
    if airframe_path is not None:
        actual = sha256_file(airframe_path)
        if actual != response.airframe_sha256:
            raise ResponseFileError(
                f"{path}: fitted to another version of {airframe_path} (sha256 {response.airframe_sha256[:12]}..., "
                f"the file's is {actual[:12]}...): fit it again with python -m sim_vehicles.dynamics.response_fit"
            )
    return response


def dump_response(response: AirframeResponse) -> str:
    """The file's text (:func:`load_response` reads it back equal)."""
    header = (
        f"# The response of airframe {response.aircraft} to the world's setpoints "
        "(tssac_core/sim/airframe_response.py).\n"
        f"# Written by: {response.command}\n"
        "# Do not edit: fit again (a changed airframe file makes this one refused).\n"
    )
    data = asdict(response)
    for key, value in data.items():
        if isinstance(value, tuple):
            data[key] = list(value)
    return header + yaml.safe_dump(data, sort_keys=False, width=120)


def airframe_lag(response: AirframeResponse, speeds_m_s: np.ndarray, dt_s: float) -> AirframeLag:
    """The monitor's model of each vehicle's airframe (:class:`tssac_core.assurance.lagged_backups.AirframeLag`): the
    response read at each vehicle's speed (the worse of the table's neighbours)."""
    at = [response.at(float(v)) for v in np.asarray(speeds_m_s, dtype=np.float64)]
    return AirframeLag(
        delay_steps=np.array([r.delay_steps(dt_s) for r in at], dtype=np.int64),
        tau_s=np.array([r.tau_s for r in at]),
        rollout_tau_s=np.array([r.rollout_tau_s for r in at]),
        accel_m_s2=np.array([r.accel_max_m_s2 for r in at]),
        decel_m_s2=np.array([r.decel_max_m_s2 for r in at]),
        residual_m=np.array([r.turn_residual_m for r in at]),
        held_residual_m=np.array([r.held_residual_m for r in at]) if response.held_leads_s else None,
        held_after_s=response.held_after_s,
    )


def response_option(path: Path | None, shield: bool, scenario: Scenario) -> Path | None:
    """A command's ``--airframe-response FILE``, checked before anything flies: it needs ``--shield`` (it is the
    monitor's model of the airframe), a file that reads, and a fit that covers the scenario's vehicles
    (:func:`check_covers`); each problem one :class:`UsageError` line."""
    if path is None:
        return None
    if not shield:
        raise UsageError("--airframe-response is the monitor's model of the airframe: it needs --shield")
    try:
        check_covers(load_response(path), scenario)
    except ResponseFileError as exc:
        raise UsageError(f"--airframe-response {exc}") from None
    return path.resolve()


def check_covers(response: AirframeResponse, scenario: Scenario) -> None:
    """Refuse (one :class:`ResponseFileError` line) a response that does not describe how the scenario's vehicles fly:
    a world step or a turn-rate limit other than the fit's, a speed range outside its fitted span (a model read
    outside the speeds it was fitted at is no bound), or a wind stronger than the one its ground loiter was measured
    in (the backups' bound in wind)."""
    lo, hi = response.speeds_m_s[0], response.speeds_m_s[-1]
    where = f"response of {response.aircraft}"
    if abs(scenario.dt_s - response.dt_s) > 1e-9:
        raise ResponseFileError(
            f"{where}: fitted for steps of {response.dt_s:g} s, the scenario steps {scenario.dt_s:g} s"
        )
    for role, spec in scenario.vehicles.items():
        if abs(math.radians(spec.turn_rate_max_deg_s) - response.turn_rate_max_rad_s) > 1e-9:
            raise ResponseFileError(
                f"{where}: fitted at a turn-rate limit of {math.degrees(response.turn_rate_max_rad_s):g} deg/s, the "
                f"scenario's {role} turns at {spec.turn_rate_max_deg_s:g} deg/s"
            )
        if spec.speed_min_m_s < lo - 1e-9 or spec.speed_max_m_s > hi + 1e-9:
            raise ResponseFileError(
                f"{where}: fitted at {lo:g}-{hi:g} m/s, the scenario's {role} flies "
                f"{spec.speed_min_m_s:g}-{spec.speed_max_m_s:g} m/s"
            )
    wind = scenario.wind
    if wind is not None and wind.promised_max_m_s > 0.0:
        if not response.loiter_excursion_m:
            raise ResponseFileError(
                f"{where}: fitted in calm air only (no ground loiter), the scenario promises winds up to "
                f"{wind.promised_max_m_s:g} m/s: fit it with python -m sim_vehicles.dynamics.response_fit "
                "--wind-max-m-s W"
            )
        if wind.promised_max_m_s > response.loiter_wind_max_m_s + 1e-9:
            raise ResponseFileError(
                f"{where}: its ground loiter was measured in winds up to {response.loiter_wind_max_m_s:g} m/s, the "
                f"scenario promises {wind.promised_max_m_s:g} m/s: fit it with --wind-max-m-s "
                f"{wind.promised_max_m_s:g} or more"
            )
