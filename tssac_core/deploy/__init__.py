"""What flies a trained policy, and what the SITL vehicles and the MAVLink bridge share.

``policy`` (role checkpoints, torch) · ``numpy_actor`` (the exported actor, numpy only) · ``export``
(checkpoint -> ``<role>.npz``; ``python -m tssac_core.deploy.export``) · ``manifest`` (``SHA256SUMS``, the
models' integrity manifest; ``python -m tssac_core.deploy.manifest write|check DIR``) · ``geodetic`` (the
flat-earth frame between the world's metres and MAVLink's degrees) · ``truth_log_schema`` (the SITL world's truth log) ·
``mavlink_signing`` (MAVLink 2 signatures verified before their timestamps count; standard library only).
"""
