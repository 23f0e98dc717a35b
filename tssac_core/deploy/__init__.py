"""What flies a trained policy: its checkpoints, the exported actors and their manifest.

``policy`` (role checkpoints, torch) · ``numpy_actor`` (the exported actor, numpy only) · ``onnx_actor`` (an actor as
an ONNX file, onnxruntime: exported here or trained in any framework) · ``export`` (checkpoint -> ``<role>.npz``, a
models directory -> ``<role>.onnx``; ``python -m tssac_core.deploy.export``) · ``manifest`` (``SHA256SUMS``, the
models' integrity manifest; ``python -m tssac_core.deploy.manifest write|check DIR``). What the SITL and the bridge
share on the wire is in :mod:`tssac_core.wire`.
"""
