"""The companion's MAVLink link: one typed pymavlink connection (commands with ACK checks, signing, tlog), the frame
conversions between MAVLink's messages and the world's frame, and the run's signing key.

* :mod:`mavlink_bridge.link.connection` — :class:`~mavlink_bridge.link.connection.MavLink`, connection strings;
* :mod:`mavlink_bridge.link.frames` — telemetry to the world's frame, actions to setpoints;
* :mod:`mavlink_bridge.link.signing_key` — reading the key a run signs with.

Imports nothing else of ``mavlink_bridge``.
"""
