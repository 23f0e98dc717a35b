"""TSSAC: transfer-safe soft actor-critic for a team of cooperating UAVs.

Importing the package registers the gymnasium environments ``tssac/Decoy-v0``, ``tssac/Detect-v0``
and ``tssac/Strike-v0`` (keyword arguments: ``scenario=``, ``observation=``, ``teammates=``).
"""

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

for _role in ("decoy", "detect", "strike"):
    _id = f"tssac/{_role.capitalize()}-v0"
    if _id not in registry:
        register(id=_id, entry_point="tssac_core.env:UavRoleEnv", kwargs={"role": _role})
