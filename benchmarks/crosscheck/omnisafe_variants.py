"""Ablations of OmniSafe's algorithms for the cross-check, run in OmniSafe's own environment (omnisafe_side).

Two, for CPO, named in the custom_cfgs' ``crosscheck`` section (``--omnisafe-set crosscheck.cpo_constraint=
per_decision``, ``--omnisafe-set crosscheck.cpo_dual=ours``; omnisafe_side takes the section out before OmniSafe
checks the rest):

``cpo_constraint: per_decision``: OmniSafe 0.5.0's CPO compares the episode cost with the limit in episode units,
``c = EpCost - cost_limit`` (``CPO._update_actor``), against the gradient of a per-decision surrogate. Ours divides
the violation by the mean episode length, ``c = (J_C - C) / L`` (tssac_core/algos/onpolicy/cpo.py). The variant is
OmniSafe's CPO with only that changed: the c its case choice, its step and its line search receive is divided by
the mean episode length of the same window of episodes (``Metrics/EpLen``).

``cpo_dual: ours`` (with ``cpo_constraint: per_decision``): in cases 1 and 2 the step of our dual solution
(tssac_core.algos.onpolicy.cpo.dual_solution: nu = max(0, lam c + r) / s, the active set bounded at -r / c) in
place of OmniSafe's (nu = max(0, lam c - r) / s, bounded at r / c). With OmniSafe's g, the gradient of the reward to
raise, its step changes the cost surrogate by 2 r / lam - c to first order instead of -c.
"""

from __future__ import annotations

from typing import Any

import torch
from omnisafe.algorithms import registry
from omnisafe.algorithms.algo_wrapper import AlgoWrapper
from omnisafe.algorithms.on_policy.second_order.cpo import CPO

from tssac_core.algos.onpolicy.cpo import dual_solution

CONSTRAINT_UNITS = ("per_episode", "per_decision")
DUALS = ("omnisafe", "ours")


@registry.register
class CPOPerDecision(CPO):
    """OmniSafe's CPO with its constraint value per decision (module docstring)."""

    def _per_decision(self, c: Any) -> Any:
        return c / max(float(self._logger.get_stats("Metrics/EpLen")[0]), 1.0)

    def _determine_case(self, b_grads: Any, ep_costs: Any, q: Any, r: Any, s: Any) -> Any:
        return super()._determine_case(b_grads=b_grads, ep_costs=self._per_decision(ep_costs), q=q, r=r, s=s)

    def _step_direction(self, **kwargs: Any) -> Any:
        kwargs["ep_costs"] = self._per_decision(kwargs["ep_costs"])
        return super()._step_direction(**kwargs)

    def _cpo_search_step(self, **kwargs: Any) -> Any:
        kwargs["violation_c"] = self._per_decision(kwargs["violation_c"])
        return super()._cpo_search_step(**kwargs)


@registry.register
class CPOPerDecisionOurDual(CPOPerDecision):
    """:class:`CPOPerDecision` whose cases 1 and 2 take our dual solution (module docstring)."""

    def _step_direction(self, **kwargs: Any) -> Any:
        if kwargs["optim_case"] not in (1, 2):
            return super()._step_direction(**kwargs)
        q, r, s = (float(kwargs[k]) for k in ("q", "r", "s"))
        c = float(self._per_decision(kwargs["ep_costs"]))
        lam, nu = dual_solution(q, r, s, c, float(self._cfgs.algo_cfgs.target_kl))
        step = (kwargs["x"] - nu * kwargs["p"]) / lam
        return step, torch.as_tensor(lam), torch.as_tensor(nu)


class VariantAgent(AlgoWrapper):
    """``omnisafe.Agent`` for ``algo`` (its defaults and checks) that trains the class registered as ``variant``
    (``algo`` itself: exactly ``omnisafe.Agent``)."""

    def __init__(self, variant: str, algo: str, env_id: str, custom_cfgs: dict[str, Any]) -> None:
        self._variant = variant
        super().__init__(algo, env_id, custom_cfgs=custom_cfgs)

    def _init_algo(self) -> None:
        algo, self.algo = self.algo, self._variant
        try:
            super()._init_algo()
        finally:
            self.algo = algo


def variant_of(algo: str, section: dict[str, Any]) -> str | None:
    """The class to train for ``algo`` under the ``crosscheck`` section, None for OmniSafe's own; ValueError for a
    setting this module does not know."""
    unknown = set(section) - {"cpo_constraint", "cpo_dual"}
    if unknown:
        raise ValueError(f"unknown crosscheck settings: {', '.join(sorted(unknown))}")
    units = section.get("cpo_constraint", "per_episode")
    if units not in CONSTRAINT_UNITS:
        raise ValueError(f"crosscheck.cpo_constraint must be one of {', '.join(CONSTRAINT_UNITS)}, got {units!r}")
    dual = section.get("cpo_dual", "omnisafe")
    if dual not in DUALS:
        raise ValueError(f"crosscheck.cpo_dual must be one of {', '.join(DUALS)}, got {dual!r}")
    if dual == "ours" and units != "per_decision":
        raise ValueError("crosscheck.cpo_dual=ours needs crosscheck.cpo_constraint=per_decision (our c)")
    if units == "per_episode":
        return None
    if algo != "CPO":
        raise ValueError(f"crosscheck.cpo_constraint is for CPO, not {algo}")
    return (CPOPerDecisionOurDual if dual == "ours" else CPOPerDecision).__name__
