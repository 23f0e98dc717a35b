"""Learners of the paper's comparison: SAC, SAC with a hazard penalty, SAC-Lagrangian and TSSAC.

Independent of the environment: observation and action sizes are constructor arguments.
`sac_lagrangian` holds the learner and `transfer`, `losses` the paper's eq. 12-17 as pure functions,
`lagrange` the (damped) multiplier, `networks` the actor and critics, `replay` the buffer.
"""

from tssac_core.algos.lagrange import DampedLagrangeMultiplier, qc_limit
from tssac_core.algos.networks import Critic, SquashedGaussianActor, mlp
from tssac_core.algos.replay import ReplayBuffer, ReplaySamples
from tssac_core.algos.sac_lagrangian import (
    TRANSFERRED_NETWORKS,
    SacConfig,
    SacLagrangian,
    UpdateStats,
    Variant,
    transfer,
)

__all__ = [
    "TRANSFERRED_NETWORKS",
    "Critic",
    "DampedLagrangeMultiplier",
    "ReplayBuffer",
    "ReplaySamples",
    "SacConfig",
    "SacLagrangian",
    "SquashedGaussianActor",
    "UpdateStats",
    "Variant",
    "mlp",
    "qc_limit",
    "transfer",
]
