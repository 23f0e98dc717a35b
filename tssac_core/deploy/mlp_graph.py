"""A policy network as MLP layers, read from torch, and the ONNX graph of those layers.

:class:`Layer` is one step of a feed-forward policy: a Linear layer (weight (out, in), bias (out,), float32, as torch
keeps them) or an activation (Tanh, ReLU). :func:`torch_layers` reads them from an ``nn.Sequential`` (Identity and
Flatten of a batch of vectors are skipped: they change nothing); :func:`mlp_model` writes the graph
observation (n, d) -> Gemm / Tanh / Relu ... -> Clip to [-1, 1] -> action (n, 2), opset 17 as
:func:`tssac_core.deploy.export.actor_model` writes the team's actors, with the ``metadata_props`` given.
The final Clip is what the world does to every action (a tanh-squashed action passes unchanged). torch and onnx are
imported by the functions that need them.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


class LayerKind(enum.StrEnum):
    LINEAR = "linear"
    TANH = "tanh"
    RELU = "relu"


@dataclass(frozen=True, eq=False)
class Layer:
    """One step of an MLP: a Linear layer (with its weight (out, in) and bias (out,)), or an activation."""

    kind: LayerKind
    weight: np.ndarray | None = None
    bias: np.ndarray | None = None


def linear(weight: Any, bias: Any) -> Layer:
    """A Linear layer from torch's tensors (or arrays)."""
    w = np.asarray(weight.detach().cpu().numpy() if hasattr(weight, "detach") else weight, dtype=np.float32)
    b = np.asarray(bias.detach().cpu().numpy() if hasattr(bias, "detach") else bias, dtype=np.float32)
    return Layer(LayerKind.LINEAR, w, b)


def torch_layers(module: Any) -> tuple[Layer, ...] | None:
    """The layers of an ``nn.Sequential`` (nested ones too) of Linear, Tanh, ReLU, Identity and Flatten modules; None
    for anything else (its forward may do more than run its children in order)."""
    from torch import nn

    if isinstance(module, nn.Linear):
        if module.bias is None:
            return (linear(module.weight, np.zeros(module.out_features, np.float32)),)
        return (linear(module.weight, module.bias),)
    if isinstance(module, nn.Tanh):
        return (Layer(LayerKind.TANH),)
    if isinstance(module, nn.ReLU):
        return (Layer(LayerKind.RELU),)
    if isinstance(module, nn.Identity | nn.Flatten):
        return ()
    if type(module) is nn.Sequential:
        layers: list[Layer] = []
        for child in module:
            inner = torch_layers(child)
            if inner is None:
                return None
            layers += inner
        return tuple(layers)
    return None


def forward(layers: Sequence[Layer], obs: np.ndarray) -> np.ndarray:
    """The layers on a batch (n, d), in float32, then clipped to [-1, 1]: what :func:`mlp_model`'s graph computes."""
    h = np.asarray(obs, dtype=np.float32)
    for layer in layers:
        if layer.kind is LayerKind.LINEAR:
            assert layer.weight is not None and layer.bias is not None
            h = h @ layer.weight.T + layer.bias
        elif layer.kind is LayerKind.TANH:
            h = np.tanh(h)
        else:
            h = np.maximum(h, 0.0)
    return np.clip(h, -1.0, 1.0)


def sizes(layers: Sequence[Layer]) -> tuple[int, int]:
    """(input width, output width) of the layers (ValueError without a Linear layer, or with mismatched ones)."""
    shapes = [layer.weight.shape for layer in layers if layer.weight is not None]
    if not shapes:
        raise ValueError("no Linear layer")
    for (out_a, _), (_, in_b) in zip(shapes[:-1], shapes[1:]):
        if out_a != in_b:
            raise ValueError(f"a Linear layer of {out_a} outputs feeds one of {in_b} inputs")
    return int(shapes[0][1]), int(shapes[-1][0])


def mlp_model(layers: Sequence[Layer], props: Mapping[str, str], name: str) -> Any:
    """The ONNX model (``onnx.ModelProto``) of ``layers`` (module docstring), its ``metadata_props`` ``props``; checked
    by ``onnx.checker``."""
    from onnx import helper, numpy_helper

    from tssac_core.deploy.export import checked_model

    obs_dim, act_dim = sizes(layers)
    nodes, weights = [], []
    x = "obs"
    for i, layer in enumerate(layers):
        if layer.kind is LayerKind.LINEAR:
            assert layer.weight is not None and layer.bias is not None
            weights += [numpy_helper.from_array(layer.weight, f"w{i}"), numpy_helper.from_array(layer.bias, f"b{i}")]
            nodes.append(helper.make_node("Gemm", [x, f"w{i}", f"b{i}"], [f"z{i}"], transB=1))  # x @ w.T + b
        else:
            op = "Tanh" if layer.kind is LayerKind.TANH else "Relu"
            nodes.append(helper.make_node(op, [x], [f"z{i}"]))
        x = f"z{i}"
    weights += [
        numpy_helper.from_array(np.array(-1.0, dtype=np.float32), "action_min"),
        numpy_helper.from_array(np.array(1.0, dtype=np.float32), "action_max"),
    ]
    nodes.append(helper.make_node("Clip", [x, "action_min", "action_max"], ["action"]))  # as the world clips
    doc = f"{name}: observation -> action in [-1, 1] (tssac_core.deploy.mlp_graph)"
    return checked_model(nodes, weights, name, (obs_dim, act_dim), doc, props)
