"""The OmniSafe adapter (tssac_core.train.omnisafe_env), in OmniSafe's own environment (gymnasium 0.28.1; README,
"OmniSafe"): the test command runs this file there (tests/test_omnisafe_side.py); by hand:

    PYTHONPATH=. $(python benchmarks/omnisafe_env.py) -m pytest -q -o addopts= tests/test_omnisafe_env.py
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

omnisafe = pytest.importorskip("omnisafe")
torch = pytest.importorskip("torch")

from omnisafe.envs.core import make, support_envs  # noqa: E402

from tssac_core.sim.observation import ObservationMode  # noqa: E402
from tssac_core.sim.scenario import Radar, Role, Start, dump, load  # noqa: E402
from tssac_core.train.omnisafe_env import TssacRoleEnv  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def test_registered_in_omnisafes_registry():
    assert {"TssacDecoy-v0", "TssacDetect-v0", "TssacStrike-v0"} <= set(support_envs())
    env = make("TssacDetect-v0", num_envs=3, teammates=str(ROOT / "models" / "tssac"))
    assert isinstance(env, TssacRoleEnv) and env.role is Role.DETECT
    assert type(env.task.pilots[0]).__name__ == "NumpyPolicy"  # the shipped decoy flies
    assert env.task.pilots[2] is None  # strike parked, as the curriculum trains detect
    assert env.observation_space.shape == (ObservationMode.ROUTE.size,) and env.max_episode_steps == 400


def test_step_sums_action_repeat_and_resets_finished_worlds():
    env = make("TssacDecoy-v0", num_envs=4, action_repeat=10)
    env.set_seed(7)
    obs, _ = env.reset()
    assert obs.shape == (4, ObservationMode.ROUTE.size) and obs.dtype == torch.float32
    ended = 0
    actions = torch.Generator().manual_seed(7)  # the same actions every run
    for _ in range(450):
        obs, reward, cost, terminated, truncated, info = env.step(torch.rand(4, 2, generator=actions) * 2 - 1)
        assert reward.shape == cost.shape == terminated.shape == (4,) and terminated.dtype == torch.bool
        assert torch.all(cost >= 0) and torch.all(cost <= 10)
        done = terminated | truncated
        if done.any():
            ended += int(done.sum())
            assert info["final_observation"].shape == obs.shape
    assert ended >= 1


def test_same_seed_same_layouts_and_one_world_is_unbatched():
    a, b = make("TssacStrike-v0", num_envs=1), make("TssacStrike-v0", num_envs=1)
    a.set_seed(3)
    b.set_seed(3)
    oa, _ = a.reset()
    ob, _ = b.reset()
    assert oa.shape == (ObservationMode.ROUTE.size,) and torch.equal(oa, ob)
    sa, sb = a.step(torch.zeros(2)), b.step(torch.zeros(2))
    assert all(torch.equal(x, y) for x, y in zip(sa[:5], sb[:5]))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="unknown env_cfgs"):
        make("TssacDecoy-v0", num_envs=1, colour="red")
    with pytest.raises(ValueError, match="cost_margin_km"):
        make("TssacDecoy-v0", num_envs=1, cost_margin_km=-1)
    with pytest.raises(ValueError, match="learning role"):
        make("TssacDetect-v0", num_envs=1, teammates=str(ROOT / "models" / "tssac"), teammate_roles=["detect"])


def test_cost_margin_is_the_tightened_cost_our_learners_constrain(tmp_path: Path) -> None:
    """cost_margin_km (the cross-check sets our TrainConfig's 1 km): the learner's cost counts the steps within 1 km
    of a radar too, so it is eq. 11's inside the radar and more on a path through the band. The detect UAV flies
    straight north at 250 m/s from 5 km south of a 5 km radar: the band from its 16th decision, the radar from its
    20th."""
    base = load(ROOT / "scenarios" / "strike.yaml")
    layout = dataclasses.replace(
        base.layout,
        radars=(*base.layout.radars, Radar((82.0, 30.0), 5.0)),
        starts={**base.layout.starts, "detect": Start((82.0, 20.0), 90.0)},
    )
    path = tmp_path / "radar-ahead.yaml"
    dump(dataclasses.replace(base, layout=layout), path)
    cfg = {"num_envs": 1, "teammates": "none", "scenario": str(path)}
    exact, margin = make("TssacDetect-v0", **cfg), make("TssacDetect-v0", cost_margin_km=1.0, **cfg)
    assert exact.task.cost_margin_m == 0.0 and margin.task.cost_margin_m == 1000.0
    costs: list[list[float]] = [[], []]
    for i, env in enumerate((exact, margin)):
        env.set_seed(5)
        env.reset()
        for _ in range(30):
            costs[i].append(float(env.step(torch.zeros(2))[2]))
    first = [next(k for k, c in enumerate(run) if c > 0) for run in costs]
    assert first[1] < first[0] and first[0] in (19, 20, 21)  # the band before the radar
    assert sum(costs[1]) > sum(costs[0]) > 0
    assert all(m >= e for m, e in zip(costs[1], costs[0]))  # never fewer than eq. 11's


def test_only_a_hit_terminates_unless_leaving_terminates():
    """Our learners bootstrap through leaving the area (docs/decisions.md); the adapter tells OmniSafe the same by
    default (leaving is ``truncated``), and ``leaving_terminates`` makes leaving ``terminated``, a zero future."""
    # Nobody strikes (teammates "none"), so no episode can end in a hit: every end is a leave or the cap.
    envs = [make("TssacDetect-v0", num_envs=4, teammates="none", leaving_terminates=flag) for flag in (False, True)]
    for env in envs:
        env.set_seed(11)
        env.reset()
    straight = torch.tensor([[0.0, 1.0]] * 4)  # hold the heading: every UAV flies out of the area
    leaves = 0
    for _ in range(400):
        (_, ra, ca, term_a, trunc_a, _), (_, rb, cb, term_b, trunc_b, _) = (env.step(straight) for env in envs)
        assert torch.equal(ra, rb) and torch.equal(ca, cb) and torch.equal(term_a | trunc_a, term_b | trunc_b)
        assert not (term_a & trunc_a).any()
        assert not term_a.any()  # no hit, so nothing terminates by default
        leaves += int((term_b & trunc_a).sum())
        assert torch.all(ra[term_b] < -19)  # the -20 for leaving is paid either way
    assert leaves >= 4
