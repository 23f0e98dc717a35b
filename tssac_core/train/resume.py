"""Resume states: ``resume/<role>.pt``, the last completed epoch of a role, from which ``--resume`` continues.

One format for every learner (`ResumeState`): the loop's counters, the worlds, the last observation, torch's
random state, the validation selector's, and the learner's own part (`RoleLearner.state`: networks and
optimisers, plus the replay buffer and exploration generator of the off-policy learners, or the
unfinished episodes' lengths and the recent episodes' costs of the on-policy ones).

Written atomically and durably: to a temporary file, fsynced, the previous state kept as
``resume/<role>.prev.pt``, renamed into place, the directory fsynced. Read with a check: a state that does
not load (truncated by a crash or a full disk) is passed over, with one line, for the previous one, so a
resume loses at most one more epoch and never stops with a traceback. When a role has resume states and
none of them loads, the resume stops with one line (:class:`ResumeStateError`, exit 2): it never trains
the role again from epoch 0 behind the user's back. Files written by earlier versions
(one format per learner family, no ``format`` key) are read too (`from_legacy`).
"""

from __future__ import annotations

import dataclasses
import io
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NotRequired, TypedDict, final

import numpy as np
import torch

from tssac_core.algos.onpolicy.ppo import CpoState, PpoState
from tssac_core.algos.replay import ReplayState
from tssac_core.algos.sac_lagrangian import SacState
from tssac_core.common.cli import UsageError
from tssac_core.deploy.policy import torch_save_atomic
from tssac_core.sim.scenario import Role
from tssac_core.train.validation import SelectorState

logger = logging.getLogger("tssac_core.train")

FORMAT = "tssac-resume"
FORMAT_VERSION = 2
"""Version 1 is the two formats of before (off-policy and on-policy), read by `from_legacy`."""


class ResumeStateError(UsageError):
    """A role has resume states but none loads; ``str()`` is one line."""


class Pcg64Words(TypedDict):
    state: int
    inc: int


class Pcg64State(TypedDict):
    """numpy's PCG64 generator state (``Generator.bit_generator.state``), key for key as numpy gives it."""

    bit_generator: str
    state: Pcg64Words
    has_uint32: int
    uinteger: int


def pcg64_state(rng: np.random.Generator) -> Pcg64State:
    """The state of ``rng`` (a PCG64 generator: ``np.random.default_rng``'s)."""
    s = rng.bit_generator.state
    return {
        "bit_generator": s["bit_generator"],
        "state": {"state": s["state"]["state"], "inc": s["state"]["inc"]},
        "has_uint32": s["has_uint32"],
        "uinteger": s["uinteger"],
    }


@final
class OffPolicyResume(TypedDict):
    """An off-policy learner's part of a resume state (:meth:`OffPolicyLearner.state`)."""

    learner: SacState
    buffer: ReplayState
    rng: Pcg64State
    transferred: bool
    recent_costs: NotRequired[list[float]]
    """Missing from resume states older than the multiplier's measured-cost signal."""


@final
class OnPolicyResume(TypedDict):
    """An on-policy learner's part of a resume state (:meth:`OnPolicyLearner.state`)."""

    algo: str
    learner: PpoState | CpoState
    ep_len: np.ndarray
    finished: list[tuple[float, int]]


LearnerResume = OffPolicyResume | OnPolicyResume


@dataclass(frozen=True)
class ResumeState:
    algo: str
    epoch: int
    """The last completed epoch."""
    env_steps: int
    updates: int
    task: bytes
    """The worlds (RoleTask.snapshot)."""
    obs: np.ndarray
    torch_rng: torch.Tensor
    selector: SelectorState
    learner: LearnerResume
    """The learner family's part (RoleLearner.state)."""


def state_path(out: Path, role: Role | str) -> Path:
    return out / "resume" / f"{Role(role).value}.pt"


def previous_path(out: Path, role: Role | str) -> Path:
    return out / "resume" / f"{Role(role).value}.prev.pt"


def write_resume_state(out: Path, role: Role, state: ResumeState) -> None:
    """Write the role's resume state durably, keeping the one before as ``<role>.prev.pt`` (module docstring)."""
    path = state_path(out, role)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_file():
        os.replace(path, previous_path(out, role))
    # Not dataclasses.asdict: it deep-copies every value, the replay buffer included.
    fields = {f.name: getattr(state, f.name) for f in dataclasses.fields(state)}
    torch_save_atomic({"format": FORMAT, "format_version": FORMAT_VERSION, **fields}, path)


def load_state_file(path: Path) -> ResumeState:
    """One resume state file (ValueError with a one-line reason when it does not load or is not one)."""
    try:
        data = torch.load(io.BytesIO(path.read_bytes()), map_location="cpu", weights_only=False)
    except Exception as exc:  # torch raises many kinds on a truncated or corrupt file
        raise ValueError(f"not readable ({type(exc).__name__})") from None
    if not isinstance(data, dict):
        raise ValueError("not a resume state")
    if "format" not in data:
        data = from_legacy(data)
    elif data.get("format") != FORMAT or data.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"resume format {data.get('format')!r} version {data.get('format_version')!r}, "
            f"this TSSAC reads {FORMAT!r} {FORMAT_VERSION}"
        )
    try:
        return ResumeState(**{f.name: data[f.name] for f in dataclasses.fields(ResumeState)})
    except KeyError as exc:
        raise ValueError(f"no {exc.args[0]!r} in it") from None


def read_resume_state(out: Path, role: Role | str, warn: bool = True) -> ResumeState | None:
    """The newest resume state of ``role`` that loads: ``<role>.pt``, else (one line, if ``warn``)
    ``<role>.prev.pt``; None if the role has neither (it starts from epoch 0). Raises ResumeStateError when
    there are states and none loads."""
    damaged: list[tuple[Path, str]] = []
    for path in (state_path(out, role), previous_path(out, role)):
        if not path.is_file():
            continue
        try:
            state = load_state_file(path)
        except ValueError as exc:
            damaged.append((path, str(exc)))
            continue
        for bad, reason in damaged if warn else []:
            logger.warning("%s: %s; resuming from %s", bad, reason, path.name)
        return state
    if damaged:
        name = Role(role).value
        reasons = "; ".join(f"{path.name} {reason}" for path, reason in damaged)
        raise ResumeStateError(
            f"--resume: no resume state of {name} loads ({reasons}): remove {state_path(out, role).parent}/{name}*.pt "
            f"to train {name} again from epoch 0"
        )
    return None


def from_legacy(data: dict[str, Any]) -> dict[str, Any]:
    """A resume state written before the one format (it has no ``format`` key): the off-policy loop's (with a
    replay ``buffer``) or the on-policy loop's (with ``ep_len``), as a version-2 dict."""
    common: dict[str, Any] = {
        k: data[k] for k in ("epoch", "env_steps", "updates", "task", "obs", "torch_rng", "selector") if k in data
    }
    if "buffer" in data:
        learner = {
            "learner": data["learner"],
            "buffer": data["buffer"],
            "rng": data["rng"],
            "transferred": data["transferred"],
            "recent_costs": data.get("recent_costs", []),
        }
        return {**common, "algo": data["learner"].get("variant", ""), "learner": learner}
    if "ep_len" in data:
        learner = {
            "algo": data.get("algo", ""),
            "learner": data["learner"],
            "ep_len": data["ep_len"],
            "finished": data["finished"],
        }
        return {**common, "algo": data.get("algo", ""), "learner": learner}
    raise ValueError("not a resume state of this TSSAC")
