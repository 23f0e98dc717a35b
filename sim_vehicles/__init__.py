"""SITL vehicles: each UAV of a scenario as a MAVLink 2 autopilot on UDP, physics from tssac_core.sim.world.

``python -m sim_vehicles --scenario FILE`` starts them (see :mod:`sim_vehicles.__main__`); the
protocol is described in ``docs/mavlink.md``. Modules, one job each:

* :mod:`~sim_vehicles.config` — the run's configuration (frozen dataclass, enums);
* :mod:`~sim_vehicles.world_runner` — the loop: world steps, real time / speed-up / lockstep, events;
* :mod:`~sim_vehicles.clock` — the simulated, link-model, wall and Unix clocks the runner keeps;
* :mod:`~sim_vehicles.vehicle` — one vehicle's state and decisions (modes, setpoints, failsafes, its action);
* :mod:`~sim_vehicles.vehicle_link` — one vehicle's MAVLink side (link model both ways, telemetry, lockstep credit);
* :mod:`~sim_vehicles.commands` — what a vehicle does with its clients' messages (commands, parameters, ...);
* :mod:`~sim_vehicles.streams` — which telemetry a vehicle sends when, and each stream's messages;
* :mod:`~sim_vehicles.telemetry` — telemetry messages from a state (frames and units);
* :mod:`~sim_vehicles.setpoints` — setpoint messages -> what the vehicle flies;
* :mod:`~sim_vehicles.modes` / :mod:`~sim_vehicles.navigation` — flight modes and the autonomous modes' guidance;
* :mod:`~sim_vehicles.params` — the parameter table;
* :mod:`~sim_vehicles.mavlink_io` — the UDP endpoint around pymavlink (framing, signing checks, peers);
* :mod:`~sim_vehicles.signing` — signing keys and replay detection;
* :mod:`~sim_vehicles.link_model` — GPS and datalink models;
* :mod:`~sim_vehicles.events` — mission events and their NAMED_VALUE_INT names;
* :mod:`~sim_vehicles.truth_log` — the JSON Lines truth log;
* :mod:`~tssac_core.wire.geodetic` — frames and the flat-earth conversion.
"""

from sim_vehicles.config import ClockMode, LockstepStart, SitlConfig
from sim_vehicles.world_runner import Endpoint, RunResult, SitlError, WorldRunner

__all__ = ["ClockMode", "Endpoint", "LockstepStart", "RunResult", "SitlConfig", "SitlError", "WorldRunner"]
