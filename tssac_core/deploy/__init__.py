"""What flies a trained policy: its checkpoints, the exported actor and their manifest.

``policy`` (role checkpoints, torch) · ``numpy_actor`` (the exported actor, numpy only) · ``export``
(checkpoint -> ``<role>.npz``; ``python -m tssac_core.deploy.export``) · ``manifest`` (``SHA256SUMS``, the
models' integrity manifest; ``python -m tssac_core.deploy.manifest write|check DIR``). What the SITL and the bridge
share on the wire is in :mod:`tssac_core.wire`.
"""
