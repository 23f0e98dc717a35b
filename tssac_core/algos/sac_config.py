"""The settings of the SAC family's learner (`tssac_core.algos.sac_lagrangian`): which variant, and its
hyperparameters. Free of torch, so that a command reads its configuration (and answers ``--help``) without it."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from tssac_core.algos.budget import qc_limit


class Variant(enum.Enum):
    """Which algorithm of the paper's comparison the learner runs."""

    SAC = "sac"
    SAC_PENALTY = "sac_penalty"
    SAC_LAG = "sac_lag"
    TSSAC = "tssac"


MULTIPLIER_VARIANTS = (Variant.SAC_LAG, Variant.TSSAC)
"""The variants that learn the cost multiplier beta (eq. 15)."""


class MultiplierSignal(enum.StrEnum):
    """SacConfig.multiplier_signal: what eq. 15 and 17 compare with C (a str: it reads as its word)."""

    EPISODE_COST = "episode_cost"
    """The mean measured cost of the last `cost_window` training episodes, on Q^c's scale."""
    Q_C = "q_c"
    """The mean Q^c of the current policy on recent transitions (eq. 15 literally)."""


@dataclass(frozen=True)
class SacConfig:
    """Hyperparameters; defaults are the paper's Table 3 unless a field says otherwise."""

    variant: Variant = Variant.TSSAC
    """The algorithm (see the module docstring's table)."""

    hidden_sizes: tuple[int, ...] = (256, 256)
    """Hidden layer sizes of the actor and of every critic (Table 3: 256, 256, ReLU)."""

    lr: float = 1e-3
    """Adam learning rate eta of the actor, the critics and alpha (Table 3)."""

    gamma: float = 0.99
    """Discount factor gamma of rewards and costs (Table 3)."""

    polyak: float = 0.995
    """Target averaging: target <- polyak * target + (1 - polyak) * online (Table 3)."""

    batch_size: int = 256
    """Minibatch size; read by the training loop when it samples the replay buffer (Table 3)."""

    replay_size: int = 1_000_000
    """Replay capacity M; read by the training loop when it builds the buffer (Table 3)."""

    target_entropy: float = -1.0
    """Entropy target H0 of eq. 14, in nats, for the whole action (not per dimension) (Table 3)."""

    alpha_init: float = 0.0
    """Initial entropy coefficient (Table 3: 0). alpha is learned directly and projected onto
    >= 0 after each Adam step (like beta), so 0 is a valid start: alpha stays 0 until the policy's
    entropy falls below H0, then rises. A log-alpha parametrisation could not start at 0."""

    beta_init: float = 0.0
    """Initial cost multiplier beta (Table 3: 0)."""

    beta_lr: float = 1e-2
    """Adam learning rate of beta (not in the paper; 10 x lr, as DESIGN.md section 2 asks for a
    larger one). Adam moves beta by about beta_lr per update, so from 0 it can reach ~10 within
    ~1,000 updates (a quarter of a 4,000-step epoch) and fall back as fast once the constraint
    holds; at lr = 1e-3 that would take 2.5 of the paper's 50 epochs."""

    k_d: float = 10.0
    """Damping scale factor k_d of eq. 17 (Table 3); used by TSSAC only (SAC_LAG runs with 0)."""

    cost_limit: float = 3.0
    """Cost threshold C per episode, an undiscounted sum of eq. 11's costs (Table 3). Converted to
    the scale of Q^c with `qc_limit(cost_limit, gamma, episode_steps)`."""

    episode_steps: int = 4000
    """Episode length T used to convert cost_limit for Q^c (Table 3: max 4,000 steps)."""

    penalty: float = 0.0
    """SAC_PENALTY only: reward r + penalty * c, penalty <= 0 (paper's experiment: 0, -10, -15,
    -50). Must be 0 for the other variants."""

    multiplier_signal: MultiplierSignal = MultiplierSignal.EPISODE_COST
    """What eq. 15 and 17 compare with C (``lagrange.choose_signal`` turns it into the learner's signal; the
    training loop passes the measurements). "episode_cost": the mean measured cost of the last `cost_window`
    training episodes, converted to Q^c's scale (``lagrange.SignalRule.episode_scale``), as PID-Lagrangian
    (Stooke et al. 2020) and OmniSafe's SAC-Lag measure the constraint, and as our PPO-Lag and CPO do. "q_c":
    the mean Q^c of the current policy on recent transitions (`multiplier_window`), eq. 15's E[Q^c] literally.
    Deviation from the paper (docs/decisions.md; the side-by-side run: results/multiplier-signal/): a
    mean cost critic barely registers the rare long stays inside a radar that make up the tail of the
    episode cost (its mean over an epoch stayed under the limit in epochs whose training episodes
    averaged 5-10 x C), so with "q_c" beta sat near 0 while the role's cost was above C."""

    cost_window: int = 10
    """"episode_cost": the number of most recent finished training episodes averaged (about one
    4,000-decision epoch of 400-decision missions); before the first one ends, the measured cost is 0."""

    multiplier_window: int | None = 4000
    """"q_c": Q^c of eq. 15 and 17 is measured on transitions drawn from the last this many added to
    the replay buffer, i.e. on the current policy's state distribution rho_pi, as eq. 15's expectation
    says (None: on the update's own batch from the whole buffer, as WCSAC does). Deviation from
    common practice, not from the paper: the whole buffer keeps early exploration's states inside
    radars, whose cost-to-go no policy can bring under the limit, so beta would rise for ever."""

    multiplier_max: float = 10.0
    """Upper bound of beta and of the effective multiplier (not in the paper; OmniSafe bounds its
    Lagrange multiplier the same way). Q^c counts discounted hazard steps, the reward about 0.1 per
    step, so a multiplier of 10 already makes one hazard step outweigh ten steps of progress; see
    DampedLagrangeMultiplier."""

    clamp_effective: bool = True
    """Clamp the effective multiplier beta - xi of eq. 16 at >= 0 (see DampedLagrangeMultiplier)."""

    cost_cvar_level: float | None = None
    """None: the actor's cost term is the mean cost-to-go Q^c (eq. 12 / 16). A level in (0, 1): a worst-case cost
    critic as WCSAC's (Yang et al. 2021), layered on the same multiplier: a second network learns the variance
    V^c of the cost-to-go (``losses.cost_variance_target``, ``losses.variance_loss``), and the actor's cost term is
    CVaR_level of N(Q^c, V^c), the mean of the worst ``level`` share of outcomes (``losses.cost_cvar``), so a
    state from which the cost is rare but long weighs more than its mean. Not in the paper; the multiplier's
    signal (eq. 15, 17) is unchanged."""

    def __post_init__(self) -> None:
        checks = [
            (0.0 <= self.gamma < 1.0, f"gamma must be in [0, 1), got {self.gamma}"),
            (0.0 <= self.polyak <= 1.0, f"polyak must be in [0, 1], got {self.polyak}"),
            (self.lr > 0.0, f"lr must be > 0, got {self.lr}"),
            (self.beta_lr > 0.0, f"beta_lr must be > 0, got {self.beta_lr}"),
            (self.alpha_init >= 0.0, f"alpha_init must be >= 0, got {self.alpha_init}"),
            (self.beta_init >= 0.0, f"beta_init must be >= 0, got {self.beta_init}"),
            (self.k_d >= 0.0, f"k_d must be >= 0, got {self.k_d}"),
            (self.multiplier_max > 0.0, f"multiplier_max must be > 0, got {self.multiplier_max}"),
            (self.cost_limit >= 0.0, f"cost_limit must be >= 0, got {self.cost_limit}"),
            (self.episode_steps >= 1, f"episode_steps must be >= 1, got {self.episode_steps}"),
            (
                self.multiplier_signal in list(MultiplierSignal),
                f"multiplier_signal must be one of {', '.join(MultiplierSignal)}, got {self.multiplier_signal!r}",
            ),
            (self.cost_window >= 1, f"cost_window must be >= 1, got {self.cost_window}"),
            (
                self.cost_cvar_level is None or 0.0 < self.cost_cvar_level < 1.0,
                f"cost_cvar_level must be in (0, 1) or None, got {self.cost_cvar_level}",
            ),
            (self.batch_size >= 1, f"batch_size must be >= 1, got {self.batch_size}"),
            (self.replay_size >= 1, f"replay_size must be >= 1, got {self.replay_size}"),
            (len(self.hidden_sizes) >= 1, "hidden_sizes must not be empty"),
            (self.penalty <= 0.0, f"penalty must be <= 0 (r + penalty * c), got {self.penalty}"),
            (
                self.penalty == 0.0 or self.variant is Variant.SAC_PENALTY,
                f"penalty is used only by variant sac_penalty, got {self.penalty} with {self.variant.value}",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
        object.__setattr__(self, "multiplier_signal", MultiplierSignal(self.multiplier_signal))

    @property
    def qc_limit(self) -> float:
        """The cost limit C on the scale of Q^c (see `budget.qc_limit`)."""
        return qc_limit(self.cost_limit, self.gamma, self.episode_steps)
