"""The cross-check's OmniSafe side (benchmarks/crosscheck/omnisafe_side.py), in OmniSafe's own environment (README,
"OmniSafe"): the test command runs this file there (tests/test_omnisafe_side.py); by hand:

    PYTHONPATH=. $(python benchmarks/omnisafe_env.py) -m pytest -q -o addopts= tests/test_crosscheck_omnisafe.py

OmniSafe accepts every configuration the driver builds (no key it does not know, the cost limit where its algorithm
reads it), and the exported numpy actor is OmniSafe's deterministic actor behind its observation normaliser.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

omnisafe = pytest.importorskip("omnisafe")
torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import omnisafe.algorithms.algo_wrapper as wrapper  # noqa: E402
from gymnasium import spaces  # noqa: E402
from omnisafe.common.normalizer import Normalizer  # noqa: E402
from omnisafe.models.actor.actor_builder import ActorBuilder  # noqa: E402
from omnisafe.utils.config import Config, get_default_kwargs_yaml  # noqa: E402
from omnisafe.utils.tools import recursive_check_config  # noqa: E402

from benchmarks.crosscheck.actor_file import OmniSafeActor  # noqa: E402
from benchmarks.crosscheck.omnisafe_side import default_cfgs_with_env_section, export, last_checkpoint  # noqa: E402
from benchmarks.crosscheck.settings import ALGOS, Budget, Shared, omnisafe_cfgs  # noqa: E402
from tssac_core.sim.observation import ObservationMode, observation_bounds  # noqa: E402

SHARED = Shared(3.0, 1.0, 0.995, (128, 128), 10, 2, 1000)
TYPES = {"cpo": "on-policy", "ppo_lag": "on-policy", "sac_lag": "off-policy"}


@pytest.mark.parametrize("algo", list(ALGOS))
def test_omnisafe_accepts_every_configuration_and_reads_the_limit_there(algo, tmp_path):
    patched = default_cfgs_with_env_section(get_default_kwargs_yaml)
    defaults = patched(ALGOS[algo], "TssacDetect-v0", TYPES[algo])
    cfgs = omnisafe_cfgs(algo, Budget(50, 4000), 0, SHARED, tmp_path)
    recursive_check_config(cfgs, defaults)  # KeyError for a key OmniSafe does not have
    section = "algo_cfgs" if algo == "cpo" else "lagrange_cfgs"
    assert "cost_limit" in defaults[section]
    defaults.recurisve_update(cfgs)
    assert defaults[section]["cost_limit"] == 3.0 and defaults.train_cfgs.total_steps == 200_000


def test_unpatched_off_policy_defaults_refuse_env_cfgs():
    """Why omnisafe_side patches OmniSafe's defaults: its SACLag.yaml has no env_cfgs section."""
    defaults = get_default_kwargs_yaml("SACLag", "TssacDetect-v0", "off-policy")
    with pytest.raises(KeyError, match="env_cfgs"):
        recursive_check_config({"env_cfgs": {"teammates": "none"}}, defaults)
    assert wrapper.get_default_kwargs_yaml is not None


@pytest.mark.parametrize("actor_type, activation", [("gaussian_learning", "tanh"), ("gaussian_sac", "relu")])
def test_export_is_omnisafes_deterministic_actor(tmp_path, actor_type, activation):
    low, high = observation_bounds(ObservationMode.ROUTE)
    obs_space = spaces.Box(low, high, dtype=np.float32)
    act_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    actor = ActorBuilder(obs_space, act_space, [16, 16], activation, "kaiming_uniform").build_actor(actor_type)
    norm = Normalizer(obs_space.shape, clip=5)
    rng = np.random.default_rng(1)
    norm.normalize(torch.as_tensor(rng.normal(3.0, 2.0, size=(64, len(low))), dtype=torch.float32))
    save = tmp_path / "log" / "torch_save"
    save.mkdir(parents=True)
    params = {"pi": actor.state_dict(), "obs_normalizer": norm.state_dict()}
    torch.save(params, save / "epoch-2.pt")
    torch.save({"pi": {}}, save / "epoch-10.pt")
    assert last_checkpoint(tmp_path / "log").name == "epoch-10.pt"  # by number, not by name
    cfgs = Config.dict2config(
        {
            "algo": "X",
            "algo_cfgs": {"obs_normalize": True},
            "env_cfgs": {"action_repeat": 10},
            "model_cfgs": {
                "actor_type": actor_type,
                "weight_initialization_mode": "kaiming_uniform",
                "actor": {"hidden_sizes": [16, 16], "activation": activation},
            },
        }
    )
    checked = export(cfgs, save / "epoch-2.pt", tmp_path / "actor.npz")
    assert checked["export_max_abs_diff"] < 1e-5
    obs = rng.normal(3.0, 2.0, size=(5, len(low))).astype(np.float32)
    with torch.no_grad():
        x = torch.clamp((torch.as_tensor(obs) - norm._mean) / norm._std, -5, 5)
        ref = torch.clamp(actor.predict(x, deterministic=True), -1, 1).numpy()
    np.testing.assert_allclose(OmniSafeActor.load(tmp_path / "actor.npz")(obs), ref, atol=1e-5)


def test_the_cpo_ablation_divides_omnisafes_constraint_value_by_the_episode_length(tmp_path, monkeypatch):
    """``crosscheck.cpo_constraint=per_decision``: OmniSafe's CPO, built with CPO's defaults and checks, whose c is
    the episode cost over the limit divided by the mean episode length (as ours); anything else is refused."""
    import tssac_core.train.omnisafe_env  # noqa: F401  (registers TssacDetect-v0)
    from benchmarks.crosscheck.omnisafe_variants import CPOPerDecision, VariantAgent, variant_of

    assert variant_of("CPO", {}) is None and variant_of("CPO", {"cpo_constraint": "per_episode"}) is None
    assert variant_of("CPO", {"cpo_constraint": "per_decision"}) == "CPOPerDecision"
    for algo, section, says in [
        ("PPOLag", {"cpo_constraint": "per_decision"}, "for CPO"),
        ("CPO", {"cpo_constraint": "per_step"}, "must be one of"),
        ("CPO", {"colour": "red"}, "unknown crosscheck settings: colour"),
    ]:
        with pytest.raises(ValueError, match=says):
            variant_of(algo, section)
    cfgs = omnisafe_cfgs("cpo", Budget(1, 400), 0, SHARED, tmp_path / "omnisafe")
    cfgs["env_cfgs"]["teammates"] = "none"
    cfgs["env_cfgs"].pop("teammate_roles")
    monkeypatch.setattr(wrapper, "get_default_kwargs_yaml", default_cfgs_with_env_section(get_default_kwargs_yaml))
    from omnisafe.algorithms.on_policy.second_order.cpo import CPO

    assert type(VariantAgent("CPO", "CPO", "TssacDetect-v0", cfgs).agent) is CPO  # no variant: OmniSafe's own
    agent = VariantAgent("CPOPerDecision", "CPO", "TssacDetect-v0", cfgs)
    cpo = agent.agent
    assert type(cpo) is CPOPerDecision and agent.algo == "CPO" and cpo._cfgs.algo_cfgs.cost_limit == 3.0
    cpo._logger.store({"Metrics/EpCost": 43.0, "Metrics/EpLen": 200.0})
    assert cpo._per_decision(torch.tensor(40.0)).item() == pytest.approx(0.2)  # (43 - 3) / 200
    # The case choice sees c per decision: with c = 40 per episode no step could reach feasibility (case 0); with
    # 0.2 per decision a step within the trust region can (case 1), as OmniSafe's own CPO decides for c = 0.2.
    b, q, r, s = torch.tensor([0.3, 0.4]), torch.tensor(0.05), torch.tensor(0.01), torch.tensor(4.0)
    own = super(CPOPerDecision, cpo)._determine_case
    assert own(b_grads=b, ep_costs=torch.tensor(40.0), q=q, r=r, s=s)[0] == 0
    assert cpo._determine_case(b_grads=b, ep_costs=torch.tensor(40.0), q=q, r=r, s=s)[0] == 1
    assert own(b_grads=b, ep_costs=torch.tensor(0.2), q=q, r=r, s=s)[0] == 1


def test_the_cpo_dual_ablation_takes_our_step_whose_cost_change_is_minus_c(tmp_path, monkeypatch):
    """``crosscheck.cpo_dual=ours``: in case 1 our dual solution's step lowers the linearised cost by exactly c, where
    OmniSafe's (nu = max(0, lam c - r) / s) raises it when the reward and cost gradients agree (r > 0)."""
    import tssac_core.train.omnisafe_env  # noqa: F401  (registers TssacDetect-v0)
    from benchmarks.crosscheck.omnisafe_variants import CPOPerDecision, CPOPerDecisionOurDual, VariantAgent, variant_of

    section = {"cpo_constraint": "per_decision", "cpo_dual": "ours"}
    assert variant_of("CPO", section) == "CPOPerDecisionOurDual"
    with pytest.raises(ValueError, match="needs crosscheck.cpo_constraint=per_decision"):
        variant_of("CPO", {"cpo_dual": "ours"})
    cfgs = omnisafe_cfgs("cpo", Budget(1, 400), 0, SHARED, tmp_path / "omnisafe")
    cfgs["env_cfgs"]["teammates"] = "none"
    cfgs["env_cfgs"].pop("teammate_roles")
    monkeypatch.setattr(wrapper, "get_default_kwargs_yaml", default_cfgs_with_env_section(get_default_kwargs_yaml))
    cpo = VariantAgent("CPOPerDecisionOurDual", "CPO", "TssacDetect-v0", cfgs).agent
    cpo._logger.store({"Metrics/EpCost": 8.0, "Metrics/EpLen": 100.0})
    g, b = torch.tensor([1.0, 0.5]), torch.tensor([0.8, 0.1])  # H = I: x = g, p = b; r = g.b > 0
    q, r, s = g.dot(g), g.dot(b), b.dot(b)
    c_episode = torch.tensor(5.0)  # 8 - 3 per episode: c = 0.05 per decision
    c = 0.05
    A, B = q - r**2 / s, 2 * 0.01 - c**2 / s
    assert cpo._determine_case(b_grads=b, ep_costs=c_episode, q=q, r=r, s=s)[0] == 1
    step_args = dict(optim_case=1, xHx=q, x=g, A=A, B=B, q=q, p=b, r=r, s=s, ep_costs=c_episode)
    ours, lam, _ = cpo._step_direction(**step_args)
    assert b.dot(ours).item() == pytest.approx(-c, rel=1e-4)  # the linearised constraint holds with equality
    assert 0.5 * ours.dot(ours).item() <= 0.01 + 1e-6  # inside the trust region (H = I)
    theirs, lam_o, _ = super(CPOPerDecisionOurDual, cpo)._step_direction(**step_args)
    assert type(cpo).__mro__[1] is CPOPerDecision
    assert b.dot(theirs).item() > 0.0  # OmniSafe's step raises the linearised cost here
