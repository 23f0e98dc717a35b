"""Which epoch a role ships (tssac_core.train.validation): the constrained learners within the cost limit, the others
by success."""

from __future__ import annotations

import dataclasses
import json

import pytest

from tssac_core.common.cli import UsageError
from tssac_core.train.algorithms import ALGORITHMS
from tssac_core.train.arguments import parse_cli
from tssac_core.train.config import TrainConfig, default_selection, selects_within_limit, with_recorded_defaults
from tssac_core.train.jobs.runner import config_difference
from tssac_core.train.legacy import config_from_saved
from tssac_core.train.validation import Score


def score(epoch: int, success: float, cost: float) -> Score:
    return Score(epoch, success, success, cost, cost_limit=3.0)


# Plain SAC's decoy, seed 0 of the grid: only its first epoch was within C.
EPOCHS = [score(1, 0.44, 0.0), score(5, 0.92, 7.0), score(12, 0.96, 98.0), score(13, 0.96, 174.0), score(20, 0.90, 2.0)]


def best(scores: list[Score], limit_first: bool) -> Score:
    return max(scores, key=lambda s: s.key(limit_first))


def test_within_the_limit_the_best_success_among_epochs_at_or_under_c_ships():
    assert best(EPOCHS, True).epoch == 20  # 0.90 at cost 2 beats 0.96 at cost 98
    assert best(EPOCHS[:4], True).epoch == 1  # the one epoch within C, however poor
    assert best([score(3, 0.9, 40.0), score(4, 1.0, 9.0)], True).epoch == 4  # none within: the lowest cost
    assert best([score(7, 0.9, 3.0), score(8, 0.9, 3.0)], True).epoch == 7  # at C is within; a tie: the earlier


def test_by_success_the_cost_only_breaks_ties():
    assert best(EPOCHS, False).epoch == 12  # 0.96 twice: the lower cost
    assert best([score(7, 0.9, 0.0), score(8, 0.9, 0.0)], False).epoch == 7


def tail(epoch: int, success: float, high: float, within: float) -> Score:
    return Score(epoch, success, success, high / 2, 3.0, cost_high=high, within_limit_fraction=within)


def test_the_tail_selection_puts_the_upper_bound_of_the_cost_first():
    # Grid seed 0's strike role: 0.90 validated on 50 missions at cost 0, and 2.65 on 500 unseen layouts.
    lucky = tail(20, 0.97, 4.0, 0.995)  # one crossing of a radar among 200 missions: its upper bound is over C
    clean = tail(12, 0.93, 0.0, 1.0)
    assert max([lucky, clean], key=Score.tail_key).epoch == 12
    assert max([clean, tail(15, 0.95, 2.9, 0.995)], key=Score.tail_key).epoch == 15  # feasible: success decides
    # None feasible: the most UAV-missions within C, then the lower bound; success does not count.
    assert max([tail(3, 0.99, 9.0, 0.98), tail(4, 0.50, 30.0, 0.99)], key=Score.tail_key).epoch == 4
    # Within C on average, but one UAV-mission in a hundred over it: not feasible beside a clean epoch.
    assert max([tail(9, 0.99, 2.0, 0.99), tail(10, 0.95, 2.0, 0.995)], key=Score.tail_key).epoch == 10
    assert max([tail(7, 0.9, 1.0, 1.0), tail(8, 0.9, 1.0, 1.0)], key=Score.tail_key).epoch == 8  # a tie: the later


def test_only_the_learners_given_the_limit_are_selected_within_it():
    assert {a: default_selection(a) for a in ALGORITHMS} == {
        "tssac": "within_limit",
        "sac_lag": "within_limit",
        "ppo_lag": "within_limit",
        "cpo": "within_limit",
        "sac": "success",
        "sac_penalty": "success",
        "ppo": "success",
    }
    cfg, *_ = parse_cli(["--algo", "sac", "--out", "r"])
    assert cfg.selection is None and not selects_within_limit(cfg)
    assert with_recorded_defaults(cfg).selection == "success"  # what config.json records
    cfg, *_ = parse_cli(["--algo", "sac", "--selection", "within_limit", "--out", "r"])
    assert selects_within_limit(cfg) and with_recorded_defaults(cfg).selection == "within_limit"


def saved(cfg: TrainConfig, **changes) -> dict:
    return json.loads(json.dumps({**dataclasses.asdict(with_recorded_defaults(cfg)), **changes}))


def test_a_run_from_before_the_setting_shipped_within_the_limit():
    """Every algorithm's epochs were selected within C before: an old SAC run is not the grid's SAC run now, a TSSAC
    one is."""
    for algo, same in (("sac", False), ("ppo", False), ("tssac", True), ("cpo", True)):
        cfg, *_ = parse_cli(["--algo", algo, "--out", "r"])
        old = saved(cfg)
        del old["selection"]
        assert config_from_saved(old).selection == "within_limit"
        difference = config_difference(old, cfg)
        assert (difference == "") is same, difference
        if not same:
            assert "selection: 'within_limit' in its config.json, 'success' in the grid" in difference
    with pytest.raises(UsageError, match="selection: expected one of within_limit, success, tail, got 'best'"):
        config_from_saved(saved(cfg, selection="best"))


def test_the_tail_selection_keeps_the_three_best_epochs_checkpoints_and_resumes_with_them(tmp_path, strike_path):
    from tssac_core.deploy.policy import FORMAT, FORMAT_VERSION, read_checkpoint, torch_save_atomic
    from tssac_core.sim.observation import ObservationMode
    from tssac_core.sim.scenario import Role, load
    from tssac_core.train.validation import EpochSelector

    HEADER = {"format": FORMAT, "format_version": FORMAT_VERSION}  # noqa: N806  (a checkpoint's header, no weights)
    selector = EpochSelector(load(strike_path), Role.DETECT, tmp_path, 0, 0, {}, ObservationMode.ROUTE, tail=True)
    selector.candidate.parent.mkdir(parents=True)
    scores = [
        tail(1, 0.5, 0.0, 1.0),
        tail(2, 0.9, 9.0, 0.98),
        tail(3, 0.8, 1.0, 1.0),
        tail(4, 0.7, 2.0, 0.995),
        tail(5, 0.95, 2.5, 0.995),
    ]
    for s in scores:
        torch_save_atomic({**HEADER, "epoch": s.epoch}, selector.candidate)  # what write_checkpoint left for this epoch
        selector._keep_candidate(s)
    assert [s.epoch for s in selector.top] == [5, 3, 4]  # feasible by success; 2 is over C, 1 the least successful
    kept = sorted(p.name for p in (tmp_path / "resume").glob("detect-e*.pt"))
    assert kept == ["detect-e3.pt", "detect-e4.pt", "detect-e5.pt"]
    assert read_checkpoint(tmp_path / "resume" / "detect-e5.pt")["epoch"] == 5
    again = EpochSelector(load(strike_path), Role.DETECT, tmp_path, 0, 0, {}, ObservationMode.ROUTE, tail=True)
    again.load_state_dict(selector.state_dict())
    assert again.top == selector.top
