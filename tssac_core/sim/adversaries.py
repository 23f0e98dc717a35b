"""Adversarial pilots: test pilots built to break the runtime-assurance monitor (``docs/runtime_assurance.md``).

Each one is a pure function of the UAV's state, the layout and the decision's index, vectorised over any
array shape of UAVs (the batched world's N worlds x 3 UAVs, or a companion's one), and decides every
:data:`DECISION_STEPS` world steps (1 s), as the shipped policies do. The same :func:`adversary_actions` flies
in the batched world (:class:`AdversaryPilot`, ``python -m tssac_core.evaluate --controller NAME``) and in a
companion computer (``python -m mavlink_bridge.companion --pilot NAME``, ``python -m mavlink_bridge.fly
--pilot NAME``).

======================  ==========================================================================================
name                    action [omega, u] at each decision
======================  ==========================================================================================
``full_speed``          [0, +1]: straight on, accelerating to v_max
``turn_left``           [+1, +1]: the maximum-rate turn to the left (counter-clockwise), at full speed
``turn_right``          [-1, +1]: the same to the right
``random``              uniform in [-1, 1]^2, a new draw each decision (seeded: see below)
``at_radar``            full speed, the maximum-rate turn towards the centre of the nearest radar (nearest disk)
``at_edge``             full speed, the maximum-rate turn towards the nearest edge of the area (its outward normal)
``chatter``             bang-bang: [+1, +1] at even decisions, [-1, -1] at odd ones
``nan``                 [NaN, NaN]: what a policy with NaN weights proposes
======================  ==========================================================================================

The steering pilots turn at the maximum rate until the heading error is less than one decision's turn
(omega_max x 1 s), then by the error, so they point at their aim instead of swinging across it.

``random`` draws from a counter-based generator (SplitMix64) keyed by the layout (the bits of its SAM, target
and radar positions and radii), the UAV's role and the decision's index: no state is carried, the same mission
draws the same actions wherever and however often it is flown, and a mission flown again alone (``--mission
K``) draws what it drew in the full run.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from tssac_core.sim.world import N_ROLES
from tssac_core.sim.world_state import WorldState

DECISION_STEPS = 10
"""World steps between two decisions of an adversary (the shipped policies' action_repeat)."""


class Adversary(enum.StrEnum):
    """The adversarial pilots (module docstring); the value is the name on the command lines."""

    FULL_SPEED = "full_speed"
    TURN_LEFT = "turn_left"
    TURN_RIGHT = "turn_right"
    RANDOM = "random"
    AT_RADAR = "at_radar"
    AT_EDGE = "at_edge"
    CHATTER = "chatter"
    NAN = "nan"


ADVERSARY_NAMES = tuple(a.value for a in Adversary)


@dataclass(frozen=True)
class Situation:
    """What an adversary decides on, for UAVs in arrays of one shape S ((N, 3) in the batched world)."""

    x_m: np.ndarray
    """East position, S."""
    y_m: np.ndarray
    """North position, S."""
    phi_rad: np.ndarray
    """Heading, counter-clockwise from east, S."""
    decision: np.ndarray
    """Index of this decision since the mission started (world step // DECISION_STEPS), S, int64."""
    key: np.ndarray
    """The UAV's random stream in its layout, S, uint64 (:func:`layout_keys`)."""
    radar_m: np.ndarray
    """Radar centres, S + (K, 2)."""
    radar_r_m: np.ndarray
    """Radar radii, S + (K,) (0: an unused slot)."""
    turn_per_decision_rad: np.ndarray
    """The largest heading change in one decision, omega_max x DECISION_STEPS x dt, S."""
    area_m: float
    """The area is [0, area_m]^2."""


def situation(state: WorldState, steps: np.ndarray | int | None = None) -> Situation:
    """Every UAV of ``state`` as an adversary sees it, shape (N, 3); ``steps``: the world step of each world (N,)
    (default ``state.steps``)."""
    n = state.n
    shape = (n, N_ROLES)
    step = state.steps if steps is None else np.broadcast_to(np.asarray(steps, dtype=np.int64), (n,))
    c = state.c
    return Situation(
        x_m=state.x_m.copy(),
        y_m=state.y_m.copy(),
        phi_rad=state.phi_rad.copy(),
        decision=np.broadcast_to((step // DECISION_STEPS)[:, None], shape),
        key=layout_keys(state),
        radar_m=np.broadcast_to(state.radar_m[:, None], (n, N_ROLES, *state.radar_m.shape[1:])),
        radar_r_m=np.broadcast_to(state.radar_r_m[:, None], (n, N_ROLES, state.radar_r_m.shape[1])),
        turn_per_decision_rad=np.broadcast_to(c.turn_rate_max_rad_s * c.dt_s * DECISION_STEPS, shape),
        area_m=c.area_m,
    )


def adversary_actions(adversary: Adversary, s: Situation) -> np.ndarray:
    """The adversary's actions [omega, u], shape S + (2,) (module docstring)."""
    shape = s.x_m.shape
    ones = np.ones(shape)
    if adversary is Adversary.FULL_SPEED:
        return np.stack([np.zeros(shape), ones], axis=-1)
    if adversary is Adversary.TURN_LEFT:
        return np.stack([ones, ones], axis=-1)
    if adversary is Adversary.TURN_RIGHT:
        return np.stack([-ones, ones], axis=-1)
    if adversary is Adversary.RANDOM:
        return np.stack([uniform(s.key, s.decision, 0), uniform(s.key, s.decision, 1)], axis=-1) * 2.0 - 1.0
    if adversary is Adversary.AT_RADAR:
        return np.stack([_steer(nearest_radar_bearing(s), s), ones], axis=-1)
    if adversary is Adversary.AT_EDGE:
        return np.stack([_steer(nearest_edge_bearing(s), s), ones], axis=-1)
    if adversary is Adversary.CHATTER:
        sign = np.where(s.decision % 2 == 0, 1.0, -1.0)
        return np.stack([sign, sign], axis=-1)
    if adversary is Adversary.NAN:
        return np.full((*shape, 2), np.nan)
    raise ValueError(f"unknown adversary {adversary!r}")


def _steer(bearing_rad: np.ndarray, s: Situation) -> np.ndarray:
    """The turn command towards ``bearing_rad``: the maximum rate until less than one decision's turn is left."""
    error = np.mod(bearing_rad - s.phi_rad + math.pi, 2 * math.pi) - math.pi
    return np.clip(error / s.turn_per_decision_rad, -1.0, 1.0)


def nearest_radar_bearing(s: Situation) -> np.ndarray:
    """Bearing of the centre of the radar whose disk is nearest, S (the heading itself when there is no radar)."""
    dx = s.radar_m[..., 0] - s.x_m[..., None]
    dy = s.radar_m[..., 1] - s.y_m[..., None]
    to_disk = np.where(s.radar_r_m > 0, np.hypot(dx, dy) - s.radar_r_m, np.inf)
    k = np.argmin(to_disk, axis=-1)[..., None]
    bearing = np.arctan2(np.take_along_axis(dy, k, -1), np.take_along_axis(dx, k, -1))[..., 0]
    return np.where(np.isfinite(to_disk.min(axis=-1, initial=np.inf)), bearing, s.phi_rad)


_EDGE_NORMALS_RAD = np.array([math.pi, 0.0, -math.pi / 2, math.pi / 2])
"""Outward normals of the west, east, south and north edges."""


def nearest_edge_bearing(s: Situation) -> np.ndarray:
    """The outward normal of the nearest edge of the area, S."""
    a = s.area_m
    gaps = np.stack([s.x_m, a - s.x_m, s.y_m, a - s.y_m], axis=-1)
    return _EDGE_NORMALS_RAD[np.argmin(gaps, axis=-1)]


# ----------------------------------------------------------------------------------------- randomness

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def _splitmix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's output function (Steele, Lea and Flood 2014) on uint64 arrays (wrapping arithmetic)."""
    with np.errstate(over="ignore"):
        z = np.asarray(z, dtype=np.uint64) + _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * _MIX1
        z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


def uniform(key: np.ndarray, counter: np.ndarray, stream: int) -> np.ndarray:
    """A uniform draw in [0, 1) per element: a hash of (key, counter, stream), the key's shape."""
    z = _splitmix(np.asarray(key, dtype=np.uint64) ^ _splitmix(np.asarray(counter, dtype=np.int64).astype(np.uint64)))
    z = _splitmix(z ^ np.uint64(stream))
    return (z >> np.uint64(11)).astype(np.float64) * 2.0**-53


def layout_keys(state: WorldState) -> np.ndarray:
    """Each UAV's random key, (N, 3) uint64: a hash of its world's layout (SAM, target, radars) and its role."""
    parts = [state.sam_m, state.target_m, state.radar_m.reshape(state.n, -1), state.radar_r_m]
    numbers = np.ascontiguousarray(np.concatenate(parts, axis=1), dtype=np.float64)
    h = np.zeros(state.n, dtype=np.uint64)
    for column in numbers.view(np.uint64).T:
        h = _splitmix(h ^ column)
    return _splitmix(h[:, None] ^ np.arange(1, N_ROLES + 1, dtype=np.uint64)[None, :])


@dataclass(frozen=True)
class AdversaryPilot:
    """An adversary as a :class:`~tssac_core.sim.pilots.Pilot` (of the batched world's Team or a companion): it reads
    the state, not an observation, and decides every ``action_repeat`` steps."""

    adversary: Adversary
    action_repeat: ClassVar[int] = DECISION_STEPS

    @property
    def name(self) -> str:
        return self.adversary.value

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        """The actions (N, 2) of vehicle ``role_index`` in every world."""
        return adversary_actions(self.adversary, situation(state))[:, role_index]
