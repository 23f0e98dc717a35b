"""The networks of K learners stacked along a leading axis, each layer one `torch.baddbmm` for all K.

`StackedActor` holds K `SquashedGaussianActor`s, `StackedCritic` K `Critic`s of n_members each
(K x n_members members in one batched pass, the idea of `Critic` carried one axis further). Member k
computes exactly what the single network with its weights computes; `member_tensors` and
`load_member` convert member k's parameters (or any tensors shaped like them, e.g. Adam's moments)
to and from the single network's layout, in the single network's `parameters()` order, so that a
seed's state is saved in the format of `SacLagrangian.state_dict`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

from tssac_core.algos.networks import LOG_STD_MAX, LOG_STD_MIN, squashed_gaussian


def _stacked_layers(n: int, sizes: Sequence[int]) -> nn.ParameterList:
    """[w_0, b_0, w_1, b_1, ...], w_i (n, fan_in, fan_out), b_i (n, 1, fan_out), each member
    initialised like `nn.Linear`'s bias (uniform in +-1/sqrt(fan_in)); the learners load their own
    weights (`load_member`), this only makes a fresh stack valid."""
    params = nn.ParameterList()
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        bound = 1.0 / math.sqrt(fan_in)
        params.append(nn.Parameter(torch.empty(n, fan_in, fan_out).uniform_(-bound, bound)))
        params.append(nn.Parameter(torch.empty(n, 1, fan_out).uniform_(-bound, bound)))
    return params


def _stacked_mlp(params: nn.ParameterList, h: torch.Tensor) -> torch.Tensor:
    """(n, batch, in) -> (n, batch, out) through [w_0, b_0, ...], ReLU after all but the last."""
    tensors = list(params._parameters.values())  # no ParameterList indexing (see Critic.forward)
    last = len(tensors) // 2 - 1
    for i in range(last + 1):
        h = torch.baddbmm(tensors[2 * i + 1], h, tensors[2 * i])
        if i < last:
            h = h.relu_()  # in place: baddbmm's backward does not need its output
    return h


class StackedActor(nn.Module):
    """K squashed-Gaussian actors (see `SquashedGaussianActor`): obs (K, batch, obs_dim) ->
    actions (K, batch, act_dim) in [-1, 1] and log_pi (K, batch)."""

    def __init__(self, n_seeds: int, obs_dim: int, act_dim: int, hidden_sizes: Sequence[int]) -> None:
        super().__init__()
        self.n_seeds = n_seeds
        self.act_dim = act_dim
        self.layers = _stacked_layers(n_seeds, [obs_dim, *hidden_sizes, 2 * act_dim])

    def forward(
        self, obs: torch.Tensor, generators: Sequence[torch.Generator] | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """generators: one per seed, each drawing its seed's noise exactly as `torch.randn_like`
        draws a single actor's from the global generator; None: deterministic (a = tanh(mean))."""
        mean, log_std = _stacked_mlp(self.layers, obs).chunk(2, dim=-1)
        log_std = log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)
        eps = None
        if generators is not None:
            shape = mean.shape[1:]
            eps = torch.stack([torch.randn(shape, generator=g) for g in generators])
        return squashed_gaussian(mean, log_std, eps)

    def member_tensors(self, k: int, stacked: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Member k's slices of tensors shaped like self.parameters(), in `SquashedGaussianActor`'s
        layout (nn.Linear weight (out, in), bias (out,)) and order; copies."""
        out: list[torch.Tensor] = []
        for i, tensor in enumerate(stacked):
            member = tensor[k].transpose(0, 1) if i % 2 == 0 else tensor[k, 0]
            out.append(member.detach().clone().contiguous())
        return out

    def load_member(
        self, k: int, stacked: Sequence[torch.Tensor], member: Sequence[torch.Tensor]
    ) -> None:
        """Write member k's tensors (`SquashedGaussianActor` layout) into the stacked tensors."""
        with torch.no_grad():
            for i, (tensor, value) in enumerate(zip(stacked, member, strict=True)):
                (tensor[k] if i % 2 == 0 else tensor[k, 0]).copy_(value.T if i % 2 == 0 else value)


class StackedCritic(nn.Module):
    """K `Critic`s of n_members each, as K x n_members members of one batched pass:
    obs (K, batch, obs_dim), action (K, batch, act_dim) -> Q-values (K, n_members, batch)."""

    def __init__(
        self, n_seeds: int, obs_dim: int, act_dim: int, hidden_sizes: Sequence[int], n_members: int
    ) -> None:
        super().__init__()
        self.n_seeds = n_seeds
        self.n_members = n_members
        self.n_layers = len(hidden_sizes) + 1
        self.layers = _stacked_layers(n_seeds * n_members, [obs_dim + act_dim, *hidden_sizes, 1])

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, action], dim=-1)  # (K, batch, in)
        k, batch, width = x.shape
        h = x.unsqueeze(1).expand(k, self.n_members, batch, width).reshape(-1, batch, width)
        return _stacked_mlp(self.layers, h).view(k, self.n_members, batch)

    def _order(self) -> list[int]:
        """`Critic.parameters()` order (weights, then biases) as indices into [w_0, b_0, ...]."""
        return [2 * i for i in range(self.n_layers)] + [2 * i + 1 for i in range(self.n_layers)]

    def member_tensors(self, k: int, stacked: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Seed k's slices (its n_members members) of tensors shaped like self.parameters(), in
        `Critic`'s layout and order; copies."""
        rows = slice(k * self.n_members, (k + 1) * self.n_members)
        return [stacked[i][rows].detach().clone() for i in self._order()]

    def load_member(
        self, k: int, stacked: Sequence[torch.Tensor], member: Sequence[torch.Tensor]
    ) -> None:
        """Write seed k's tensors (`Critic` layout and order) into the stacked tensors."""
        rows = slice(k * self.n_members, (k + 1) * self.n_members)
        with torch.no_grad():
            for i, value in zip(self._order(), member, strict=True):
                stacked[i][rows].copy_(value)
