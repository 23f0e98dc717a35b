"""The cost multiplier of SAC-Lagrangian (eq. 15) and its damped form used by TSSAC (eq. 16-17), and what it
compares with the cost limit C: the one place that chooses that signal (:func:`choose_signal`)."""

from __future__ import annotations

import copy
import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

import torch
from torch.optim.optimizer import StateDict

from tssac_core.algos import losses
from tssac_core.algos.sac_config import MultiplierSignal


class CostSignal(enum.Enum):
    """What the multiplier compares with C in an update (eq. 15 and 17), on the multiplier's scale."""

    EPISODE_COST = "episode_cost"
    """The mean measured cost of the recent finished training episodes, converted to the multiplier's scale
    (:attr:`SignalRule.episode_scale`), as PID-Lagrangian (Stooke et al. 2020), OmniSafe's SAC-Lag and PPO-Lag
    measure the constraint."""
    Q_C_RECENT = "q_c_recent"
    """The mean Q^c of the current policy on the most recent transitions (:attr:`SignalRule.recent_window`): eq.
    15's E[Q^c] over the current policy's state distribution."""
    Q_C_BATCH = "q_c_batch"
    """The mean Q^c of the current policy on the update's batch from the whole buffer (WCSAC's); also the figure a
    learner without a multiplier reports."""


@dataclass(frozen=True)
class SignalRule:
    """A learner's cost signal (:func:`choose_signal`) and how to measure it."""

    signal: CostSignal
    episode_scale: float = 1.0
    """EPISODE_COST: the measured cost per episode times this is the signal (1: the multiplier's limit is C itself;
    the SAC family's is C on Q^c's scale, ``budget.qc_limit``, so its scale is ``qc_limit(1, gamma, T)``: the
    conversion is linear, and comparing the result with that limit is comparing the episode cost with C)."""
    recent_window: int | None = None
    """Q_C_RECENT: the recent transitions are drawn from the last this many added to the replay buffer; None for
    the other signals (the learner then draws none)."""

    def measured(
        self,
        episode_cost: float | None = None,
        q_c_recent: Callable[[], torch.Tensor] | None = None,
        q_c_batch: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The signal's value, a 0-d tensor, from the learner's measurements: ``episode_cost`` (the recent
        episodes' mean cost, the scale of C), ``q_c_recent`` (computes the mean Q^c on the recent transitions, called
        only if that is the signal) and ``q_c_batch`` (the mean Q^c on the batch). ValueError if the signal's own
        measurement is missing."""
        if self.signal is CostSignal.EPISODE_COST:
            if episode_cost is None:
                raise ValueError("the multiplier's signal is the episode cost: pass episode_cost")
            return torch.as_tensor(episode_cost, dtype=torch.float32) * self.episode_scale
        if self.signal is CostSignal.Q_C_RECENT:
            if q_c_recent is None:
                raise ValueError("the multiplier's signal is Q^c on the recent transitions: pass them")
            return q_c_recent()
        if q_c_batch is None:
            raise ValueError("the multiplier's signal is Q^c on the batch: pass it")
        return q_c_batch


def choose_signal(
    setting: MultiplierSignal, learns_multiplier: bool, recent_window: int | None = None, episode_scale: float = 1.0
) -> SignalRule:
    """The signal a learner's multiplier compares with C, from its configuration: ``setting``
    (``SacConfig.multiplier_signal``; PPO-Lag: always the episode cost), ``recent_window``
    (``SacConfig.multiplier_window``) and ``episode_scale`` (:attr:`SignalRule.episode_scale`).

    - a learner without a multiplier (SAC, SAC with a penalty, PPO): Q_C_BATCH, which it only reports;
    - "episode_cost": EPISODE_COST;
    - "q_c": Q_C_RECENT on the last ``recent_window`` transitions, or Q_C_BATCH without a window.
    """
    if not learns_multiplier:
        return SignalRule(CostSignal.Q_C_BATCH)
    if setting is MultiplierSignal.EPISODE_COST:
        return SignalRule(CostSignal.EPISODE_COST, episode_scale=episode_scale)
    if recent_window:
        return SignalRule(CostSignal.Q_C_RECENT, recent_window=recent_window)
    return SignalRule(CostSignal.Q_C_BATCH)


class MultiplierState(TypedDict):
    """What :meth:`DampedLagrangeMultiplier.state_dict` returns."""

    beta: torch.Tensor
    optim: StateDict
    """Adam's state, as torch's ``Optimizer.state_dict`` gives it."""


class DampedLagrangeMultiplier:
    """beta >= 0 learned by projected Adam on eq. 15, plus the damping term xi of eq. 17.

    One call of `update(qc_mean)`, where qc_mean is the signal the caller measured (`SignalRule.measured`: a
    mean Q^c, or the recent episodes' cost on its scale; a constant here) and C = cost_limit on the same scale
    (the SAC family: C on the scale of Q^c, `budget.qc_limit`):

        J(beta) = beta * (C - qc_mean)                 eq. 15, `losses.multiplier_loss`
        beta    <- Adam step on J(beta)                gradient dJ/dbeta = C - qc_mean
        beta    <- min(upper, max(0, beta))            projection

    so beta rises while qc_mean > C and falls, down to 0, while qc_mean < C: an integral term on the
    constraint error. Adam normalises the step, so beta moves by about `lr` per update.

    `effective(qc_mean)` is the multiplier of Q^c in the actor loss (eq. 16):

        xi        = k_d * (C - qc_mean)                eq. 17, `losses.damping`
        effective = min(upper, max(0, beta - xi))      if clamp_effective (default)
        effective = beta - xi                          otherwise

    -xi = k_d (qc_mean - C) is a proportional term on the same error, which damps the oscillation of
    the plain multiplier (Stooke et al. 2020, "Responsive Safety in Reinforcement Learning by PID
    Lagrangian Methods"). k_d = 0 gives plain SAC-Lagrangian (eq. 12).

    Decision, clamp_effective = True: while the constraint is satisfied with margin and beta is
    near 0, beta - xi is negative, and a negative multiplier of Q^c would *reward* the policy for
    seeking hazards. The paper does not say; like the PID Lagrangian, which projects its summed
    multiplier (K_P error + K_I integral + K_D derivative) onto >= 0 (Stooke et al. 2020), we
    clamp it. clamp_effective = False keeps the paper's formula literally.

    Decision, upper (default infinity; the learner passes SacConfig.multiplier_max): OmniSafe's
    Lagrange class projects onto [0, upper] too. With Q^c in units of discounted hazard steps, a
    young policy's cost estimate can exceed the limit a hundredfold, and k_d = 10 then asks for a
    multiplier in the hundreds, which makes the reward irrelevant and saturates the actor; the
    bound keeps the transient finite while leaving the steady state (multiplier of a few) alone.
    """

    def __init__(
        self,
        cost_limit: float,
        k_d: float,
        beta_init: float = 0.0,
        lr: float = 1e-2,
        clamp_effective: bool = True,
        upper: float = math.inf,
    ) -> None:
        if beta_init < 0.0:
            raise ValueError(f"beta_init must be >= 0, got {beta_init}")
        if k_d < 0.0:
            raise ValueError(f"k_d must be >= 0, got {k_d}")
        self.cost_limit = cost_limit
        self.k_d = k_d
        self.beta_init = beta_init
        self.lr = lr
        self.clamp_effective = clamp_effective
        self.upper = upper
        self._beta = torch.tensor(float(beta_init), requires_grad=True)
        self._optim = torch.optim.Adam([self._beta], lr=lr)

    @property
    def beta(self) -> torch.Tensor:
        """The current beta, a 0-d tensor (a copy: later updates do not change it)."""
        return self._beta.detach().clone()

    def damping(self, qc_mean: torch.Tensor | float) -> torch.Tensor:
        """xi = k_d (C - qc_mean), eq. 17."""
        return losses.damping(torch.as_tensor(qc_mean), self.cost_limit, self.k_d)

    def effective(self, qc_mean: torch.Tensor | float) -> torch.Tensor:
        """The multiplier of Q^c in eq. 16: beta - xi, clamped to [0, upper] if clamp_effective."""
        multiplier = self.beta - self.damping(qc_mean)
        return multiplier.clamp(0.0, self.upper) if self.clamp_effective else multiplier

    def update(self, qc_mean: torch.Tensor | float) -> torch.Tensor:
        """One projected Adam step on J(beta) = beta (C - qc_mean), eq. 15; returns J (pre-step)."""
        loss = losses.multiplier_loss(self._beta, torch.as_tensor(qc_mean), self.cost_limit)
        self._optim.zero_grad()
        loss.backward()
        self._optim.step()
        with torch.no_grad():
            self._beta.clamp_(0.0, self.upper)
        return loss.detach()

    def reset(self) -> None:
        """beta back to beta_init and a fresh optimiser state."""
        with torch.no_grad():
            self._beta.fill_(self.beta_init)
        self._optim = torch.optim.Adam([self._beta], lr=self.lr)

    def state_dict(self) -> MultiplierState:
        """beta and the optimiser state."""
        return {"beta": self.beta.clone(), "optim": self._optim.state_dict()}

    def load_state_dict(self, state: MultiplierState) -> None:
        """Restore what `state_dict` returned."""
        with torch.no_grad():
            self._beta.copy_(state["beta"])
        self._optim.load_state_dict(copy.deepcopy(state["optim"]))  # never share Adam moments
