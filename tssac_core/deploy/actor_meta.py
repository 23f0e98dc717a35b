"""What a role checkpoint and an exported actor say about themselves beside the weights, as JSON values (the
standard library only: both the torch side, :mod:`tssac_core.deploy.policy`, and the numpy side,
:mod:`tssac_core.deploy.numpy_actor`, read and write it)."""

from __future__ import annotations

from typing import TypedDict


class CheckpointFields(TypedDict):
    """What a role checkpoint (and so an exported actor) stores about itself beside the weights, as plain JSON values
    (``tssac_core.deploy.policy.CheckpointInfo.fields``)."""

    role: str
    algo: str
    observation_mode: str
    obs_dim: int
    act_dim: int
    hidden_sizes: list[int]
    scenario_digest: str
    versions: dict[str, str]
    metrics: dict[str, float]
    action_repeat: int


class ActorMeta(CheckpointFields):
    """An exported actor's metadata (``<role>.npz``'s ``meta``, the ONNX file's properties): the format, the
    checkpoint's fields, and the file it was made from."""

    format: str
    format_version: int
    source: str
    source_sha256: str
