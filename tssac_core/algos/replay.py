"""Replay memory M of Algorithm 1: a preallocated ring buffer of transitions with their costs."""

from __future__ import annotations

from typing import NamedTuple, TypedDict

import numpy as np
import torch


class ReplaySamples(NamedTuple):
    """A minibatch, float32 tensors; `terminated` is 1.0 where the episode ended by termination."""

    observations: torch.Tensor  # (batch, obs_dim)
    actions: torch.Tensor  # (batch, act_dim), in [-1, 1]
    rewards: torch.Tensor  # (batch,)
    costs: torch.Tensor  # (batch,), eq. 11
    next_observations: torch.Tensor  # (batch, obs_dim)
    terminated: torch.Tensor  # (batch,), 0.0 or 1.0; truncation is *not* termination


class ReplayState(TypedDict):
    """What :meth:`ReplayBuffer.state_dict` returns: each field's filled rows (float32, in storage order), then the
    ring's write position, fill and capacity."""

    observations: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    costs: torch.Tensor
    next_observations: torch.Tensor
    terminated: torch.Tensor
    ptr: int
    size: int
    capacity: int


_FIELDS = ReplaySamples._fields
_VECTORS = ("observations", "actions", "next_observations")


class ReplayBuffer:
    """Fixed-capacity FIFO of (obs, action, reward, cost, next_obs, terminated), stored as float32.

    Once full, the oldest transitions are overwritten. `add_batch` takes the transitions of a
    batched environment (one row per sub-environment) in one call.

    Storage is one (capacity, width) array, a transition per row, and each field a column slice
    of it: a minibatch is one gather of whole rows (a few cache lines each) instead of one per
    field.
    """

    def __init__(self, obs_dim: int, act_dim: int, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.capacity = capacity
        widths = dict(zip(_FIELDS, (obs_dim, act_dim, 1, 1, obs_dim, 1)))
        self._rows = np.zeros((capacity, sum(widths.values())), dtype=np.float32)
        self._columns: dict[str, slice | int] = {}
        start = 0
        for name, width in widths.items():
            # The per-transition scalars (rewards, costs, terminated) are single columns.
            self._columns[name] = slice(start, start + width) if name in _VECTORS else start
            start += width
        self._arrays: dict[str, np.ndarray] = {name: self._rows[:, column] for name, column in self._columns.items()}
        self._ptr = 0  # next row to write
        self._size = 0

    def __len__(self) -> int:
        return self._size

    def add_batch(
        self,
        observations: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        costs: np.ndarray,
        next_observations: np.ndarray,
        terminated: np.ndarray,
    ) -> None:
        """Append n transitions (leading axis n); if n > capacity, only the last `capacity`."""
        values = dict(
            zip(
                _FIELDS,
                (observations, actions, rewards, costs, next_observations, terminated),
            )
        )
        n = len(rewards)
        for name, value in values.items():
            if len(value) != n:
                raise ValueError(f"{name} has {len(value)} rows, rewards has {n}")
        if n > self.capacity:
            values = {name: value[n - self.capacity :] for name, value in values.items()}
            n = self.capacity
        # At most two contiguous slices: up to the end of the arrays, then from the start.
        first = min(n, self.capacity - self._ptr)
        for name, value in values.items():
            array = self._arrays[name]
            array[self._ptr : self._ptr + first] = value[:first]
            array[: n - first] = value[first:]
        self._ptr = (self._ptr + n) % self.capacity
        self._size = min(self._size + n, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator) -> ReplaySamples:
        """batch_size transitions drawn uniformly with replacement."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        return self._gather(rng.integers(0, self._size, size=batch_size))

    def sample_recent(self, batch_size: int, window: int, rng: np.random.Generator) -> ReplaySamples:
        """batch_size transitions drawn uniformly from the last ``window`` added (the current policy's data)."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        span = min(window, self._size)
        idx = (self._ptr - 1 - rng.integers(0, span, size=batch_size)) % self.capacity
        return self._gather(idx)

    def _gather(self, idx: np.ndarray) -> ReplaySamples:
        # One fancy-indexing copy of the rows; the fields are views of it (from_numpy shares it).
        rows = torch.from_numpy(self._rows[idx])
        return ReplaySamples(*(rows[:, self._columns[name]] for name in _FIELDS))

    def state_dict(self) -> ReplayState:
        """The filled rows (tensors, in storage order), the write position and the capacity."""

        def filled(name: str) -> torch.Tensor:
            return torch.from_numpy(self._arrays[name][: self._size].copy())

        return {
            "observations": filled("observations"),
            "actions": filled("actions"),
            "rewards": filled("rewards"),
            "costs": filled("costs"),
            "next_observations": filled("next_observations"),
            "terminated": filled("terminated"),
            "ptr": self._ptr,
            "size": self._size,
            "capacity": self.capacity,
        }

    def load_state_dict(self, state: ReplayState) -> None:
        """Restore what `state_dict` returned; the storage layout (and so sampling) is identical.

        A buffer that was full can only be loaded into one of the same capacity (its ring order
        would be lost otherwise); a partly filled one into any capacity >= its size.
        """
        size = int(state["size"])
        ptr = int(state["ptr"])
        saved_capacity = int(state["capacity"])
        if size > self.capacity:
            raise ValueError(f"saved buffer holds {size} transitions, capacity is {self.capacity}")
        if size == saved_capacity and saved_capacity != self.capacity:
            raise ValueError(f"saved buffer was full at capacity {saved_capacity}; this one has {self.capacity}")
        saved = ReplaySamples(
            state["observations"],
            state["actions"],
            state["rewards"],
            state["costs"],
            state["next_observations"],
            state["terminated"],
        )
        for name, tensor in zip(_FIELDS, saved, strict=True):
            array = self._arrays[name]
            rows = tensor.numpy()
            if rows.shape[1:] != array.shape[1:] or len(rows) != size:
                raise ValueError(f"{name}: saved {tuple(rows.shape)} does not fit {array.shape}")
            array[:size] = rows
        self._ptr = ptr % self.capacity
        self._size = size
