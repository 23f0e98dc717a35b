"""SITL vehicles: each UAV of a scenario as a MAVLink 2 autopilot on UDP, physics from tssac_core.sim.world.

``python -m sim_vehicles --scenario FILE`` starts them (see :mod:`sim_vehicles.__main__`); the
protocol is described in ``docs/mavlink.md``. Rooms, each importing only those listed after it:

* the run: :mod:`~sim_vehicles.world_runner` (the loop: world steps, events, as the mode's clock policy says),
  :mod:`~sim_vehicles.truth_log` (the JSON Lines truth log), the command lines (``__main__`` from flags,
  ``from_config`` from the typed configuration fly gives it); the configuration itself,
  :class:`~tssac_core.sim.sitl_config.SitlConfig`, lives in :mod:`tssac_core.sim.sitl_config`, where fly builds it too;
* :mod:`sim_vehicles.protocol`: how a vehicle speaks MAVLink: its link both ways with telemetry and lockstep credit
  (``vehicle_link``), which streams when (``streams``), what clients send it (``commands``);
* :mod:`sim_vehicles.dynamics`: the physics behind the seam (the kinematic eq. 5-6, JSBSim airframes);
* :mod:`sim_vehicles.clock`: one clock policy per mode (``paced``: real time x speed-up; ``lockstep``), what they share
  (``policy``) and the real-time schedule (``pacing``): when a step is due, how long the loop waits, the linger;
* :mod:`sim_vehicles.autopilot`: one vehicle's state and decisions (``vehicle``: modes, setpoints, failsafes, its
  action), flight modes and the autonomous modes' guidance (``modes``, ``navigation``), setpoint messages and GUIDED's
  slews (``setpoints``, ``guided_slew``), parameters (``params``), clocks (``clock``), mission events (``events``),
  telemetry from a state (``telemetry``);
* :mod:`sim_vehicles.link`: the UDP endpoint (``mavlink_io``), serial lines (``serial_port``), signing keys and
  replay detection (``signing``), GPS and datalink models (``link_model``);
* below all: :mod:`tssac_core.wire` (framing, units, frames and the flat-earth conversion).
"""

from sim_vehicles.world_runner import Endpoint, RunResult, SitlError, WorldRunner
from tssac_core.sim.sitl_config import ClockMode, LockstepStart, SitlConfig

__all__ = ["ClockMode", "Endpoint", "LockstepStart", "RunResult", "SitlConfig", "SitlError", "WorldRunner"]
