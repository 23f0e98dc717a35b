"""The runtime-assurance monitor in a companion computer: :func:`tssac_core.assurance.monitor.decide`
for one vehicle, fed with the Kalman filter's estimate, its covariance and the commands still on the link.

At each of the pilot's decisions (every ``action_repeat`` ticks; every tick for the guidance controller) the
proposed action goes through :class:`tssac_core.sim.world_monitor.VehicleMonitor` with

* the filter's estimate (x, y, v, phi) at the tick;
* the margin :func:`tssac_core.assurance.monitor.estimate_margin_m`: the base, ``sigma_k`` times the position's largest
  standard deviation (sqrt of the largest eigenvalue of the filter's position covariance), and v_max times
  the timing slack off lockstep or over a lossy link (``link.packet_loss`` > 0: a lost setpoint leaves the
  vehicle on the previous command, in lockstep too);
* the commands sent in the last round trip (``pending``): the vehicle flies the setpoint stamped for tick t
  about 2 x ``link.latency_ms`` after t, off lockstep (the SITL's link clock is simulated time at a
  speed-up, as a real link's latency is real time in flight) and in lockstep alike (there the link runs on
  simulated time: the telemetry of tick t arrives ``latency_ms`` later, and the answer as long again).
  Over a link without latency nothing is pending.

Between decisions the chosen action is held. A hold setpoint (telemetry gap, non-finite action) breaks the
chain of predictions the guarantee rests on, so the monitor forgets its backup then and starts afresh.
Each hand-over is said to the vehicle in a STATUSTEXT (``"<role>: shield on, backup <turn>"`` /
``"<role>: shield off, policy flies"``), which the SITL vehicle relays to its other clients and logs.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.monitor import N_TURNS, ShieldConfig, estimate_margin_m
from tssac_core.sim.scenario import Role, Scenario
from tssac_core.sim.world import World
from tssac_core.sim.world_monitor import VehicleMonitor

ENGAGED_TEXT = "shield on"
RELEASED_TEXT = "shield off"
_TURN_NAMES = ("left", "right", "left braking", "right braking")


@dataclass
class ShieldCounters:
    """The monitor's counts over a companion's flight (in its status JSON)."""

    decisions: int = 0
    interventions: int = 0
    """Times the backup took over."""
    releases: int = 0
    """Times control went back to the policy."""
    backup_steps: int = 0
    """Control steps flown under the backup."""
    unprotected_steps: int = 0
    """Control steps with no passing action and no clear backup."""
    resets: int = 0
    """Times a hold setpoint made the monitor start afresh."""
    max_margin_m: float = 0.0
    """The largest margin used (base + covariance + timing)."""


class CompanionShield:
    """One vehicle's monitor with its held action, its queue of sent commands and its counts."""

    def __init__(self, world: World, role: Role, scenario: Scenario, cfg: ShieldConfig, lockstep: bool) -> None:
        self.cfg = cfg
        self.role = role
        self.monitor = VehicleMonitor(world, role.index, cfg)
        self.dt_s = scenario.dt_s
        self.latency_s = scenario.link.latency_ms / 1000.0
        self.slack = not lockstep or scenario.link.packet_loss > 0
        self.speed_max_m_s = scenario.vehicle(role).speed_max_m_s
        self.counters = ShieldCounters()
        self.engaged = False
        self._unprotected = False
        self._held = np.zeros(2)
        self._sent: deque[np.ndarray] = deque(maxlen=2000)

    def reset(self) -> None:
        """Forget the backup and the queue (after a hold, a restart)."""
        self.monitor.reset()
        self.engaged = False
        self._unprotected = False
        self._sent.clear()
        self.counters.resets += 1

    def pending_ticks(self) -> int:
        """Setpoints still on their way to the vehicle or not yet flown: a round trip of the link in ticks."""
        if self.latency_s <= 0:
            return 0
        return round(2.0 * self.latency_s / self.dt_s)

    def action(
        self,
        decision: bool,
        steps: int,
        proposed: np.ndarray,
        state: tuple[float, float, float, float],
        sigma_major_m: float,
    ) -> tuple[np.ndarray, str | None]:
        """The action to send this tick and a STATUSTEXT to say (a hand-over), or None.

        ``decision``: the pilot decided this tick (its action holds for ``steps`` ticks); otherwise the
        monitor's last choice is held."""
        text = None
        if decision:
            margin = estimate_margin_m(self.cfg, sigma_major_m, self.speed_max_m_s, slack=self.slack)
            n = min(self.pending_ticks(), len(self._sent))
            pending = np.array(list(self._sent)[len(self._sent) - n :]) if n else None
            d = self.monitor.decide(*state, proposed=proposed, steps=steps, margin_m=margin, pending=pending)
            self._held = d.action[0].copy()
            self.counters.decisions += 1
            self.counters.max_margin_m = max(self.counters.max_margin_m, margin)
            if d.engaged_now[0]:
                self.counters.interventions += 1
                turn = _TURN_NAMES[int(d.memory.backup[0]) % N_TURNS]
                text = f"{self.role.value}: {ENGAGED_TEXT}, backup {turn}"
            elif d.released_now[0]:
                self.counters.releases += 1
                text = f"{self.role.value}: {RELEASED_TEXT}, policy flies"
            self.engaged = bool(d.engaged[0])
            self._unprotected = bool(d.unprotected[0])
        if self.engaged:
            self.counters.backup_steps += 1
            if self._unprotected:
                self.counters.unprotected_steps += 1
        return self._held, text

    def sent(self, action: np.ndarray) -> None:
        """Record the command sent this tick (the queue that ``pending`` is taken from)."""
        self._sent.append(np.asarray(action, dtype=np.float64).copy())
