"""Networks of SAC-Lagrangian (paper section 4.1, Table 3): MLP, squashed-Gaussian actor, critics.

Table 3 gives ReLU MLPs with hidden sizes (256, 256) for the actor (output 2 = action dimension) and
the critics (output 1). The actor here has one output layer of size 2 * act_dim (mean and log-std).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import torch
import torch.nn.functional as F
from torch import nn

LOG_STD_MIN = -20.0
LOG_STD_MAX = 2.0
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_LOG_2 = math.log(2.0)


def mlp(in_dim: int, hidden_sizes: Sequence[int], out_dim: int) -> nn.Sequential:
    """MLP in_dim -> hidden_sizes... -> out_dim, ReLU after every layer but the last.

    The ReLUs work in place: a Linear's backward does not need its output, so overwriting it saves
    one activation-sized allocation and memory pass per layer (no parameters, same state_dict).
    """
    layers: list[nn.Module] = []
    sizes = [in_dim, *hidden_sizes]
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(fan_in, fan_out), nn.ReLU(inplace=True)]
    layers.append(nn.Linear(sizes[-1], out_dim))
    return nn.Sequential(*layers)


def tanh_log_abs_det_jacobian(u: torch.Tensor) -> torch.Tensor:
    """log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)), elementwise; finite for any u.

    The naive log(1 - tanh(u)^2 + eps) (Tianshou's `correct_log_prob_gaussian_tanh`) is biased by
    eps and saturates at log(eps) once tanh(u) rounds to 1 (|u| > ~9 in float32); this identity is
    the one of torch's TanhTransform and Spinning Up's SAC.
    """
    return 2.0 * (_LOG_2 - u - F.softplus(-2.0 * u))


class SquashedGaussianActor(nn.Module):
    """pi(a|s): a = tanh(u), u ~ N(mean(s), exp(log_std(s))^2); actions in [-1, 1].

    log pi(a|s) = sum_i [log N(u_i; mean_i, std_i) - log(1 - tanh(u_i)^2)]  (change of variables).
    log_std is clamped to [LOG_STD_MIN, LOG_STD_MAX] = [-20, 2]. Deterministic mode: a = tanh(mean).
    """

    def __init__(self, obs_dim: int, act_dim: int, hidden_sizes: Sequence[int]) -> None:
        super().__init__()
        self.act_dim = act_dim
        # One output layer for mean and log-std together: one matmul instead of two.
        self.net = mlp(obs_dim, hidden_sizes, 2 * act_dim)

    def mean_log_std(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and clamped log-std of the pre-tanh Gaussian, each (batch, act_dim)."""
        mean, log_std = self.net(obs).chunk(2, dim=-1)
        return mean, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)

    def forward(self, obs: torch.Tensor, deterministic: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """Return (action in [-1, 1], log_pi) with shapes (batch, act_dim), (batch,).

        The stochastic action is reparametrised (u = mean + std * eps), so log_pi and the action are
        differentiable in the actor's parameters. In deterministic mode log_pi is the density at
        u = mean.
        """
        mean, log_std = self.mean_log_std(obs)
        return squashed_gaussian(mean, log_std, None if deterministic else torch.randn_like(mean))


def squashed_gaussian(
    mean: torch.Tensor, log_std: torch.Tensor, eps: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """(a = tanh(u), log pi(a|s)) for u = mean + exp(log_std) * eps, or u = mean if eps is None.

    Shapes (..., act_dim) -> (..., act_dim), (...); the change of variables of
    `SquashedGaussianActor`.
    """
    if eps is None:
        u = mean
        noise_sq = torch.zeros_like(mean)
    else:
        u = mean + log_std.exp() * eps
        noise_sq = eps.square()  # ((u - mean) / std)^2, without the division
    gaussian_log_prob = -0.5 * noise_sq - log_std - _HALF_LOG_2PI
    log_pi = (gaussian_log_prob - tanh_log_abs_det_jacobian(u)).sum(dim=-1)
    return torch.tanh(u), log_pi


class Critic(nn.Module):
    """n_members independent Q(s, a) networks in one batched pass; output (n_members, batch).

    Each member is a ReLU MLP (obs_dim + act_dim) -> hidden_sizes -> 1. The members' weights are
    stacked along a leading axis and applied with `torch.baddbmm`, so the twin reward critics cost
    one forward/backward pass instead of two. Each member is initialised like `nn.Linear`
    (uniform in +-1/sqrt(fan_in) for weights and biases).
    """

    def __init__(self, obs_dim: int, act_dim: int, hidden_sizes: Sequence[int], n_members: int = 1) -> None:
        super().__init__()
        self.n_members = n_members
        sizes = [obs_dim + act_dim, *hidden_sizes, 1]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
            bound = 1.0 / math.sqrt(fan_in)
            self.weights.append(nn.Parameter(torch.empty(n_members, fan_in, fan_out).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(n_members, 1, fan_out).uniform_(-bound, bound)))

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Q-values of all members, shape (n_members, batch)."""
        x = torch.cat([obs, action], dim=-1)
        h = x.expand(self.n_members, *x.shape)
        last = len(self.weights) - 1
        # The lists' own parameter dicts, in order: iterating a ParameterList indexes it item by
        # item through string keys, ~20 us per forward pass here.
        weights = cast("dict[str, torch.Tensor]", self.weights._parameters)
        biases = cast("dict[str, torch.Tensor]", self.biases._parameters)
        layers = zip(weights.values(), biases.values())
        for i, (w, b) in enumerate(layers):
            h = torch.baddbmm(b, h, w)
            if i < last:
                h = h.relu_()  # in place: baddbmm's backward does not need its output
        return h.squeeze(-1)
