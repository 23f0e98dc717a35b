"""What flies a trained policy: its checkpoints, the exported actors and their manifest.

``policy`` (role checkpoints, torch) · ``numpy_actor`` (the exported actor, numpy only) · ``onnx_actor`` (an actor as
an ONNX file, onnxruntime: exported here or trained in any framework) · ``export`` (checkpoint -> ``<role>.npz``, a
models directory -> ``<role>.onnx``; ``python -m tssac_core.deploy.export``) · ``manifest`` (``SHA256SUMS``, the
models' integrity manifest; ``python -m tssac_core.deploy.manifest write|check DIR``) · ``policy_spec`` (a policy with
what it was trained on stated, and its check against a role's env) · ``any_policy`` (its loaders: a callable, a torch
module, an ONNX graph) · ``sb3_policy`` (a Stable-Baselines3 model file as one) · ``mlp_graph`` (a policy's MLP layers
from torch, and their ONNX graph) · ``policy_export`` (a spec as an ONNX actor; a team directory for ``fly``). What the
SITL and the bridge share on the wire is in :mod:`tssac_core.wire`.
"""
