"""Companion-computer side: MAVLink telemetry in, filtered state and policy setpoints out. Five rooms, each importing
only the rooms above it in this list:

* :mod:`mavlink_bridge.link` — one MAVLink 2 link (commands with ACK checks, signing, tlog), frame conversions;
* :mod:`mavlink_bridge.estimation` — the Kalman filter of a vehicle's horizontal state and its motion model;
* :mod:`mavlink_bridge.processes` — child processes and the fork server that starts a crew's;
* :mod:`mavlink_bridge.companion` — one UAV's companion process (``python -m mavlink_bridge.companion``), with the
  runtime-assurance monitor's glue (:mod:`mavlink_bridge.companion.shield`);
* :mod:`mavlink_bridge.fly` — whole missions: a SITL world and three companions (``python -m mavlink_bridge.fly``),
  scored from their truth logs (:mod:`mavlink_bridge.fly.mission_log`).

The bridge reaches vehicles only over MAVLink and never imports ``sim_vehicles``; see ``docs/bridge.md``.
"""
