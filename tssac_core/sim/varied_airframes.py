"""Training worlds whose vehicles fly like a real airframe, varied per episode (off unless asked for).

The point-mass model of eq. 5-6 turns at the commanded rate at once and accelerates at +-a_max in still air. A fixed
wing under its inner loop (the SITL's JSBSim backend, or a real ArduPlane) does not: it rolls in first, its engine
and drag set what it gains or loses, and the wind carries it. :class:`VariedAirframes` puts those effects into the
batched world as a filter on the actions, so a team trained with it has met them; the world's own arithmetic is
untouched (off, the world is eq. 5-6 exactly, bit for bit).

Per world and vehicle, drawn at each reset from :class:`AirframeVariation`'s ranges (uniform):

* turn lag: the heading rate flown follows the command after ``d`` world steps through a first-order lag
  (``tssac_core/sim/airframe_response.py``'s model): ``omega_k+1 = omega_k + (1 - exp(-dt/tau)) (omega_cmd(k-d) -
  omega_k)``, the heading turning over each step by the lag's exact mean rate, with its own time constant rolling
  out of a turn (:func:`tssac_core.assurance.lagged_backups.switched_lag_step`, the runtime-assurance monitor's
  model);
* achievable acceleration: the forward acceleration is clipped to ``[decel, accel]`` (below the scenario's +-a_max);
* turbulence: a zero-mean normal heading-rate disturbance per step (``turn_noise_deg_s``, its standard deviation);

and per world a constant wind (speed uniform in the range, direction uniform), carried by the world's own wind drift
(:meth:`tssac_core.sim.world.World.set_wind`). Vehicles start each episode in straight flight (omega 0). A share of
the worlds (``nominal_fraction``, drawn per world and episode) flies eq. 5-6 exactly instead: no lag, the scenario's
+-a_max, no wind, no turbulence, so that a team trained on the mix keeps what it flies on the model it is judged on.

:meth:`AirframeVariation.from_response` reads the ranges from an airframe's fitted response
(``python -m sim_vehicles.dynamics.response_fit``): the spans of its table over the speeds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.ground_loiter import LoiterBound, LoiterLaw, model_excursion_m, settled_turn_in_s
from tssac_core.assurance.lagged_backups import AirframeLag, LagState, lag_gains, switched_lag_step
from tssac_core.sim.airframe_response import AirframeResponse
from tssac_core.sim.scenario import Scenario
from tssac_core.sim.world import World

Range = tuple[float, float]


@dataclass(frozen=True)
class AirframeVariation:
    """The ranges per-episode airframes are drawn from (each [low, high]; low == high: fixed)."""

    turn_delay_s: Range = (0.0, 0.0)
    turn_tau_s: Range = (0.0, 0.0)
    """Rolling in (or reversing)."""
    turn_rollout_tau_s: Range | None = None
    """Rolling out of a turn; None: the roll-in's time constant both ways."""
    accel_max_m_s2: Range | None = None
    """Achievable forward acceleration (positive); None: the scenario's a_max."""
    decel_max_m_s2: Range | None = None
    """Achievable forward deceleration (negative); None: the scenario's -a_max."""
    wind_m_s: Range = (0.0, 0.0)
    """Wind speed per world (m/s), from a direction drawn uniformly."""
    turn_noise_deg_s: float = 0.0
    """Standard deviation of the heading-rate disturbance per step (deg/s)."""
    held_leads_s: tuple[float, ...] = ()
    """The backups' leads that hold their course after ``held_after_s`` (s; the airframe's fitted ones): the world's
    monitor offers them in calm air (:func:`tssac_core.assurance.lagged_backups.held_rollout`); empty: none."""
    held_after_s: float = 32.0
    nominal_fraction: float = 0.0
    """The share of worlds that fly eq. 5-6 exactly in an episode (drawn per world at each reset; 0: none)."""

    def __post_init__(self) -> None:
        ranges = {"turn_delay_s": self.turn_delay_s, "turn_tau_s": self.turn_tau_s, "wind_m_s": self.wind_m_s}
        ranges |= {"turn_rollout_tau_s": self.turn_rollout_tau_s or (0.0, 0.0)}
        ranges |= {"accel_max_m_s2": self.accel_max_m_s2 or (1.0, 1.0)}
        decel = self.decel_max_m_s2 or (-1.0, -1.0)
        ranges |= {"decel_max_m_s2": (-decel[1], -decel[0])}  # magnitudes, low to high
        for name, (low, high) in ranges.items():
            if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
                raise ValueError(f"airframe variation {name}: expected 0 <= low <= high, got {getattr(self, name)}")
        if self.accel_max_m_s2 is not None and self.accel_max_m_s2[0] <= 0.0:
            raise ValueError(f"airframe variation accel_max_m_s2 must be > 0, got {self.accel_max_m_s2}")
        if self.decel_max_m_s2 is not None and self.decel_max_m_s2[1] >= 0.0:
            raise ValueError(f"airframe variation decel_max_m_s2 must be < 0, got {self.decel_max_m_s2}")
        if self.turn_delay_s[1] > 10.0:
            raise ValueError(f"airframe variation turn_delay_s: at most 10 s, got {self.turn_delay_s}")
        if not (math.isfinite(self.turn_noise_deg_s) and 0.0 <= self.turn_noise_deg_s <= 90.0):
            raise ValueError(f"airframe variation turn_noise_deg_s must be in [0, 90], got {self.turn_noise_deg_s}")
        if not (math.isfinite(self.nominal_fraction) and 0.0 <= self.nominal_fraction <= 1.0):
            raise ValueError(f"airframe variation nominal_fraction must be in [0, 1], got {self.nominal_fraction}")
        if any(not (math.isfinite(t) and t > self.held_after_s) for t in self.held_leads_s):
            raise ValueError(f"airframe variation held_leads_s must be longer than held_after_s, got {self}")

    @classmethod
    def from_response(
        cls,
        response: AirframeResponse,
        wind_max_m_s: float = 0.0,
        turn_noise_deg_s: float = 0.0,
        nominal_fraction: float = 0.0,
    ) -> AirframeVariation:
        """The spans of a fitted response's tables, a wind up to ``wind_max_m_s`` and the given turbulence, in all
        but ``nominal_fraction`` of the worlds."""
        return cls(
            turn_delay_s=(min(response.turn_delay_s), max(response.turn_delay_s)),
            turn_tau_s=(min(response.turn_tau_s), max(response.turn_tau_s)),
            turn_rollout_tau_s=(min(response.rollout_taus()), max(response.rollout_taus())),
            accel_max_m_s2=(min(response.accel_max_m_s2), max(response.accel_max_m_s2)),
            decel_max_m_s2=(min(response.decel_max_m_s2), max(response.decel_max_m_s2)),
            wind_m_s=(0.0, wind_max_m_s),
            turn_noise_deg_s=turn_noise_deg_s,
            held_leads_s=response.held_leads_s,
            held_after_s=response.held_after_s,
            nominal_fraction=nominal_fraction,
        )

    def corners(self, turn_rate_max_rad_s: float, dt_s: float) -> AirframeLag:
        """The airframes at the corners of the lag's ranges (delay, roll-in and roll-out time constants: 8, (K,))."""
        delays = sorted({round(d / dt_s) for d in self.turn_delay_s})
        outs = self.turn_rollout_tau_s or self.turn_tau_s
        rows = [(d, t, o) for d in delays for t in sorted(set(self.turn_tau_s)) for o in sorted(set(outs))]
        k = len(rows)
        return AirframeLag(
            np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[1] for r in rows]),
            np.array([r[2] for r in rows]),
            np.full(k, 1.0),
            np.full(k, -1.0),
            np.zeros(k),
        )

    def loiter_bound(
        self, law: LoiterLaw, speeds_m_s: tuple[float, ...], turn_rate_max_rad_s: float, dt_s: float
    ) -> LoiterBound:
        """The ground loiter's bound for airframes drawn from these ranges in winds up to the range's top: the loiter
        flown on the lag model at the ranges' corners (:func:`tssac_core.assurance.ground_loiter.model_excursion_m`)
        at ``speeds_m_s`` (the vehicles' envelope; between two of them the worse neighbour counts)."""
        wind, corners = self.wind_m_s[1], self.corners(turn_rate_max_rad_s, dt_s)
        turn_in = settled_turn_in_s(corners.delay_steps.max() * dt_s, corners.longest_tau_s().max())
        excursion = model_excursion_m(corners, speeds_m_s, wind, law, turn_rate_max_rad_s, dt_s, turn_in_s=turn_in)
        return LoiterBound(wind, law, speeds_m_s, excursion, turn_in_s=turn_in)

    def envelope_loiter_bound(self, law: LoiterLaw, scenario: Scenario) -> LoiterBound:
        """:meth:`loiter_bound` over the scenario's speed envelope every 25 m/s, at its turn-rate limit (the first
        vehicle's: the scenarios give the three the same)."""
        spec = next(iter(scenario.vehicles.values()))
        speeds = tuple(float(v) for v in np.arange(spec.speed_min_m_s, spec.speed_max_m_s + 1.0, 25.0))
        return self.loiter_bound(law, speeds, math.radians(spec.turn_rate_max_deg_s), scenario.dt_s)


class VariedAirframes:
    """The per-episode airframes of N worlds and their turn-lag state (module docstring)."""

    _nominal: np.ndarray | None = None
    """Per world, whether it flies eq. 5-6 exactly this episode (None: every world varied). A class default, so that
    a resume state pickled before the mix restores with none."""

    def __init__(self, variation: AirframeVariation, world: World) -> None:
        self.variation = variation
        self.world = world
        n = world.n
        dt = world.c.dt_s
        self._dt = dt
        self._max_delay = round(variation.turn_delay_s[1] / dt)
        self._delay = np.zeros((n, 3), dtype=np.int64)
        self._gain = np.ones((n, 3))
        """g of :func:`tssac_core.assurance.lagged_backups.lag_gains` per vehicle (1: no lag)."""
        self._hold = np.zeros((n, 3))
        """h of the same (0: no lag)."""
        self._tau = np.zeros((n, 3))
        """The drawn time constants rolling in and rolling out (s)."""
        self._out_tau = np.zeros((n, 3))
        self._out_gain = np.ones((n, 3))
        """g rolling out of a turn."""
        self._out_hold = np.zeros((n, 3))
        """h rolling out of a turn."""
        self._low = np.full((n, 3), -1.0)
        """Normalised action bounds of the forward acceleration (decel / a_max), (N, 3)."""
        self._high = np.ones((n, 3))
        self._omega = np.zeros((n, 3))
        """The heading rate flown now, as a fraction of each vehicle's maximum, (N, 3)."""
        self._history = np.zeros((self._max_delay + 1, n, 3))
        """Normalised heading-rate commands of the last ``max_delay + 1`` steps (row k: k steps ago... after a
        roll, row 0 is the newest)."""
        self._wind = np.zeros((2, n))

    def reset(self, index: np.ndarray, rng: np.random.Generator) -> None:
        """Draw airframes for worlds ``index`` (after the world's own reset), straight flight, and their winds."""
        v = self.variation
        k = len(index)
        idx = np.asarray(index, dtype=np.int64)
        dt = self._dt
        self._delay[idx] = np.rint(rng.uniform(*v.turn_delay_s, size=(k, 3)) / dt).astype(np.int64)
        self._tau[idx] = rng.uniform(*v.turn_tau_s, size=(k, 3))
        self._gain[idx], self._hold[idx] = lag_gains(self._tau[idx], dt)
        if v.turn_rollout_tau_s is None:
            self._out_tau[idx] = self._tau[idx]
        else:
            self._out_tau[idx] = rng.uniform(*v.turn_rollout_tau_s, size=(k, 3))
        self._out_gain[idx], self._out_hold[idx] = lag_gains(self._out_tau[idx], dt)
        a_max = self.world.c.accel_max_m_s2[None, :]
        if v.accel_max_m_s2 is not None:
            self._high[idx] = np.minimum(rng.uniform(*v.accel_max_m_s2, size=(k, 3)) / a_max, 1.0)
        if v.decel_max_m_s2 is not None:
            self._low[idx] = np.maximum(rng.uniform(*v.decel_max_m_s2, size=(k, 3)) / a_max, -1.0)
        self._omega[idx] = 0.0
        self._history[:, idx] = 0.0
        speed = rng.uniform(*v.wind_m_s, size=k)
        towards = rng.uniform(0.0, 2.0 * math.pi, size=k)
        self._wind[:, idx] = speed * np.stack([np.cos(towards), np.sin(towards)])
        if v.nominal_fraction > 0.0:  # drawn last: without the mix, a run's draws are what they were
            self._draw_nominal(idx, rng.random(k) < v.nominal_fraction)
        self.world.set_wind(self._wind if v.wind_m_s[1] > 0.0 else None)

    def _draw_nominal(self, idx: np.ndarray, nominal: np.ndarray) -> None:
        """Worlds ``idx[nominal]`` fly eq. 5-6 this episode: no delay, no lag either way, +-a_max, no wind."""
        if self._nominal is None:
            self._nominal = np.zeros(self.world.n, dtype=bool)
        self._nominal[idx] = nominal
        eq5 = idx[nominal]
        self._delay[eq5] = 0
        self._tau[eq5] = self._out_tau[eq5] = 0.0
        self._gain[eq5], self._hold[eq5] = lag_gains(self._tau[eq5], self._dt)  # tau 0: g = 1, h = 0, no lag
        self._out_gain[eq5], self._out_hold[eq5] = self._gain[eq5], self._hold[eq5]
        self._high[eq5], self._low[eq5] = 1.0, -1.0
        self._wind[:, eq5] = 0.0

    def shape(self, action: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The actions (N, 3, 2) in [-1, 1] the airframes fly when commanded ``action``: the heading rate delayed,
        lagged and disturbed, the acceleration clipped to what each achieves."""
        out = np.clip(action, -1.0, 1.0)
        self._history = np.roll(self._history, 1, axis=0)
        self._history[0] = out[..., 0]
        delayed = np.take_along_axis(self._history, self._delay[None], axis=0)[0]
        gains_in, gains_out = (self._gain, self._hold), (self._out_gain, self._out_hold)
        flown, self._omega = switched_lag_step(self._omega, delayed, gains_in, gains_out)
        if self.variation.turn_noise_deg_s > 0.0:
            noise = rng.normal(0.0, math.radians(self.variation.turn_noise_deg_s), size=flown.shape)
            if self._nominal is not None:
                noise[self._nominal] = 0.0
            flown = flown + noise / self.world.c.turn_rate_max_rad_s[None, :]
        out[..., 0] = np.clip(flown, -1.0, 1.0)
        out[..., 1] = np.clip(out[..., 1], self._low, self._high)
        return out

    @property
    def held_leads_s(self) -> tuple[float, ...]:
        """The held leads the monitor offers: the variation's, in calm air only (none when a wind blows)."""
        return self.variation.held_leads_s if self.variation.wind_m_s[1] == 0.0 else ()

    def held_from_steps(self, dt_s: float) -> int | None:
        """The world step from which a held lead holds its course (None: no held leads offered), as
        :meth:`AirframeLag.held_from_steps` of :meth:`airframe` says, without building one."""
        return round(self.variation.held_after_s / dt_s) if self.held_leads_s else None

    def airframe(self, flat: np.ndarray) -> AirframeLag:
        """The airframes drawn for vehicles ``flat`` (indices into the (N, 3) vehicles, row-major) as the runtime-
        assurance monitor's model of them: exactly what they fly without turbulence (so no residual; a held lead,
        flown by the line law on the model itself, is its prediction: no residual either)."""
        n = self.world.n
        a_max = np.broadcast_to(self.world.c.accel_max_m_s2, (n, 3)).reshape(-1)[flat]
        return AirframeLag(
            delay_steps=self._delay.reshape(-1)[flat],
            tau_s=self._tau.reshape(-1)[flat],
            rollout_tau_s=self._out_tau.reshape(-1)[flat],
            accel_m_s2=self._high.reshape(-1)[flat] * a_max,
            decel_m_s2=self._low.reshape(-1)[flat] * a_max,
            residual_m=np.zeros(len(flat)),
            held_residual_m=np.zeros(len(flat)) if self.held_leads_s else None,
            held_after_s=self.variation.held_after_s,
        )

    def lag_state(self, flat: np.ndarray) -> LagState:
        """The lag's state of vehicles ``flat`` before this step's commands: the rate flown, and the last
        ``max_delay`` commands (oldest first; a vehicle of delay d follows the last d of them next)."""
        n, width = self.world.n, self._max_delay
        w = np.broadcast_to(self.world.c.turn_rate_max_rad_s, (n, 3)).reshape(-1)[flat]
        pending = self._history[:width][::-1].reshape(width, -1)[:, flat].T * w[:, None]
        return LagState(self._omega.reshape(-1)[flat] * w, pending)
