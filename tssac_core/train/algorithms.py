"""The algorithms of the paper's comparison, in one typed table.

| Algo        | family     | constrained (given C) | transfers | ships by default      | figure 7 |
| ----------- | ---------- | --------------------- | --------- | --------------------- | -------- |
| tssac       | off-policy | yes (damped beta)     | yes       | best within the limit | yes      |
| sac_lag     | off-policy | yes (beta)            | no        | best within the limit | yes      |
| sac         | off-policy | no                    | no        | best success          | yes      |
| sac_penalty | off-policy | no (r + penalty * c)  | no        | best success          | no       |
| ppo         | on-policy  | no                    | no        | best success          | yes      |
| ppo_lag     | on-policy  | yes (lambda)          | no        | best within the limit | no       |
| cpo         | on-policy  | yes (trust region)    | no        | best within the limit | yes      |

A learner that is not given the cost limit is not judged by it either (tssac_core.train.validation).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from tssac_core.algos.onpolicy.config import OnPolicyAlgo
from tssac_core.algos.sac_config import Variant


class Family(enum.Enum):
    """Which learner trains the algorithm, and so which settings (``--set``) it takes."""

    OFF_POLICY = "sac"
    """SacLagrangian (SacConfig): replay buffer, one update per ``update_every`` decisions."""
    ON_POLICY = "onpolicy"
    """Ppo or Cpo (OnPolicyConfig): one rollout per epoch, then the update."""


class Algo(enum.StrEnum):
    """``--algo``: an algorithm of the comparison (a str, so it reads and compares as its name)."""

    SAC = "sac"
    SAC_PENALTY = "sac_penalty"
    SAC_LAG = "sac_lag"
    TSSAC = "tssac"
    PPO = "ppo"
    PPO_LAG = "ppo_lag"
    CPO = "cpo"


class Selection(enum.StrEnum):
    """``--selection``: which validated epoch a role ships (tssac_core.train.validation)."""

    WITHIN_LIMIT = "within_limit"
    """The best mission success among the epochs within the cost limit."""
    SUCCESS = "success"
    """The best mission success, whatever the cost."""
    TAIL = "tail"
    """Screen every epoch on the upper bound of its cost and its within-C fraction, then choose among the best
    three on more missions."""


@dataclass(frozen=True)
class Algorithm:
    name: Algo
    family: Family
    constrained: bool
    """Given the cost limit C (a multiplier or a trust region on the cost)."""
    transfers: bool
    """Each role starts from the previous role's networks (TSSAC's N_k -> N_k+1)."""
    variant: Variant | None = None
    """The SacLagrangian variant (off-policy family)."""
    onpolicy: OnPolicyAlgo | None = None
    """The on-policy algorithm (on-policy family)."""
    in_figure7: bool = True
    """One of the paper's five compared algorithms (figure 7, Table 4): not PPO-Lagrangian (ours), nor SAC with a
    penalty (the paper's experiment III, figure 12)."""

    @property
    def default_selection(self) -> Selection:
        return Selection.WITHIN_LIMIT if self.constrained else Selection.SUCCESS

    @property
    def off_policy(self) -> bool:
        return self.family is Family.OFF_POLICY


ALGORITHMS: dict[Algo, Algorithm] = {
    a.name: a
    for a in (
        Algorithm(Algo.SAC, Family.OFF_POLICY, constrained=False, transfers=False, variant=Variant.SAC),
        Algorithm(
            Algo.SAC_PENALTY,
            Family.OFF_POLICY,
            constrained=False,
            transfers=False,
            variant=Variant.SAC_PENALTY,
            in_figure7=False,
        ),
        Algorithm(Algo.SAC_LAG, Family.OFF_POLICY, constrained=True, transfers=False, variant=Variant.SAC_LAG),
        Algorithm(Algo.TSSAC, Family.OFF_POLICY, constrained=True, transfers=True, variant=Variant.TSSAC),
        Algorithm(Algo.PPO, Family.ON_POLICY, constrained=False, transfers=False, onpolicy=OnPolicyAlgo.PPO),
        Algorithm(
            Algo.PPO_LAG,
            Family.ON_POLICY,
            constrained=True,
            transfers=False,
            onpolicy=OnPolicyAlgo.PPO_LAG,
            in_figure7=False,
        ),
        Algorithm(Algo.CPO, Family.ON_POLICY, constrained=True, transfers=False, onpolicy=OnPolicyAlgo.CPO),
    )
}
"""Every algorithm by its name (``--algo``), in the order of the command's choices."""


def algorithm(name: str) -> Algorithm:
    """The table's row of ``name`` (ValueError naming the choices for another)."""
    try:
        return ALGORITHMS[Algo(name)]
    except ValueError:
        raise ValueError(f"unknown algorithm {name!r} (choose from {', '.join(ALGORITHMS)})") from None


def family_of(name: str) -> Family:
    return algorithm(name).family
