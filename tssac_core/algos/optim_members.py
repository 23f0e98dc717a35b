"""One member's slice of an Adam optimiser over stacked parameters, in a single learner's format.

Adam is elementwise: one optimiser over K stacked copies of a network is K optimisers over the
copies, provided all K take every step (they share the step count). `member_state` cuts member k's
moments out as the `state_dict` of an optimiser over the single network's parameters;
`load_member_state` writes such a `state_dict` back into member k's slice.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from typing import Any

import torch

ToMember = Callable[[int, Sequence[torch.Tensor]], list[torch.Tensor]]
"""(k, tensors shaped like the stacked parameters) -> member k's tensors, single layout and order."""
LoadMember = Callable[[int, Sequence[torch.Tensor], Sequence[torch.Tensor]], None]
"""(k, stacked tensors, member k's tensors in single layout and order): write them in place."""


def member_state(
    optim: torch.optim.Optimizer, params: Sequence[torch.Tensor], k: int, to_member: ToMember
) -> dict[str, Any]:
    """Member k's `state_dict` of an optimiser with one param group over the single parameters."""
    (group,) = copy.deepcopy(optim.state_dict()["param_groups"])
    # The single learner's parameters are numbered 0, 1, ... in its order (the stack may hold them
    # in more or fewer tensors).
    group["params"] = list(range(len(to_member(k, params))))
    groups = [group]
    states = [optim.state.get(p, {}) for p in params]
    if not states[0]:
        return {"state": {}, "param_groups": groups}
    moments = {
        key: to_member(k, [s[key] for s in states]) for key in ("exp_avg", "exp_avg_sq")
    }
    step = states[0]["step"]
    state = {
        i: {"step": step.detach().clone(), "exp_avg": m, "exp_avg_sq": v}
        for i, (m, v) in enumerate(zip(moments["exp_avg"], moments["exp_avg_sq"]))
    }
    return {"state": state, "param_groups": groups}


def load_member_state(
    optim: torch.optim.Optimizer,
    params: Sequence[torch.Tensor],
    k: int,
    state: dict[str, Any],
    load_member: LoadMember,
) -> None:
    """Write member k's moments from `state` (see `member_state`); hyperparameters are kept.

    All members share the step count: an empty `state` (a fresh optimiser) fits only a stack whose
    optimiser is fresh too, and a saved step must equal the stack's (ValueError otherwise).
    """
    entries = state["state"]
    current = [optim.state.get(p, {}) for p in params]
    if not entries:
        if current[0]:
            raise ValueError(f"member {k}: a fresh optimiser state cannot join a stack at a later step")
        return
    saved = [entries[i] for i in sorted(entries)]
    step = saved[0]["step"]
    if not current[0]:
        for p in params:
            optim.state[p] = {
                "step": step.detach().clone(),
                "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format),
            }
        current = [optim.state[p] for p in params]
    elif float(current[0]["step"]) != float(step):
        raise ValueError(
            f"member {k}: optimiser at step {float(step):.0f}, the stack at {float(current[0]['step']):.0f}"
        )
    for key in ("exp_avg", "exp_avg_sq"):
        load_member(k, [s[key] for s in current], [s[key] for s in saved])
