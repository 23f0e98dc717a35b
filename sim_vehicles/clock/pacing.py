"""The real-time schedule of a paced world (``--speedup``; a lockstep world with no vehicle in the loop; the linger
after a mission off lockstep): step ``k`` of simulated time is due ``k * dt / speedup`` wall seconds after the
schedule's anchor. A world that falls more than :data:`MAX_LAG_S` simulated seconds behind (a loaded machine) is
re-anchored rather than made to race through the backlog.
"""

from __future__ import annotations

import logging

MAX_LAG_S = 1.0
"""Simulated seconds behind schedule after which real-time pacing is re-anchored."""
EPS = 1e-9

_log = logging.getLogger(__name__)


class PacedSchedule:
    """When the next step of a paced world is due, in wall time."""

    def __init__(self, dt_s: float, speedup: float) -> None:
        self.dt_s = dt_s
        self.speedup = speedup
        self._wall0 = 0.0
        self._sim0 = 0.0

    def anchor(self, wall_s: float, sim_s: float) -> None:
        """Simulated time ``sim_s`` is now, ``wall_s``: the schedule counts from here."""
        self._wall0 = wall_s
        self._sim0 = sim_s

    def step_due(self, wall_s: float, sim_s: float) -> bool:
        """At wall time ``wall_s``, is the step after simulated time ``sim_s`` due? A world too far behind is
        re-anchored here (its next step is then due at once)."""
        target = self._sim0 + (wall_s - self._wall0) * self.speedup
        if target - sim_s > MAX_LAG_S + self.dt_s:
            _log.warning("simulation is %.2f s behind its clock; re-anchoring the schedule", target - sim_s)
            self.anchor(wall_s, sim_s)
            return True
        return sim_s + self.dt_s <= target + EPS

    def next_step_wall(self, sim_s: float) -> float:
        """The wall time at which the step after simulated time ``sim_s`` is due."""
        return self._wall0 + (sim_s + self.dt_s - self._sim0) / self.speedup
