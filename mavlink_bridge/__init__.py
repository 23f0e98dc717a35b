"""Companion-computer side: MAVLink telemetry in, filtered state and policy setpoints out.

* :mod:`mavlink_bridge.link` — one MAVLink 2 link over UDP (commands with ACK checks, signing, tlog);
* :mod:`mavlink_bridge.state_filter` — the Kalman filter of a vehicle's horizontal state;
* :mod:`mavlink_bridge.companion` — one UAV's companion process (``python -m mavlink_bridge.companion``);
* :mod:`mavlink_bridge.fly` — whole missions: a SITL world and three companions (``python -m mavlink_bridge.fly``);
* :mod:`mavlink_bridge.frames`, :mod:`mavlink_bridge.processes`, :mod:`mavlink_bridge.mission_log` — helpers.

The bridge reaches vehicles only over MAVLink/UDP and never imports ``sim_vehicles``; see ``docs/bridge.md``.
"""
