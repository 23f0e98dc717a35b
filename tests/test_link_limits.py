"""Link settings a scenario may give are the ones a companion can fly with (issue 61, item 3): the validator refuses a
link that loses (or, signed, reorders) more than 60% of its frames each way, and up to that a companion's commands
get through, their attempts sized to the link (mavlink_bridge.companion.config.command_attempts)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from sitl_helpers import GUIDED, STRIKE, scenario, sitl

from mavlink_bridge.companion.config import CompanionConfig, command_attempts
from mavlink_bridge.link.connection import MavLink
from tssac_core.sim.scenario import MAX_LINK_LOSS, LinkModel, Role, ScenarioError, load


@pytest.mark.parametrize(
    "link, flyable",
    [
        ({"packet_loss": 0.6}, True),
        ({"reordering": 0.6}, True),
        ({"packet_loss": 0.61}, False),
        ({"reordering": 1.0, "signing": True}, False),  # every frame held behind the next: a replay to signing
        ({"reordering": 1.0}, False),  # fly signs by default: the scenario's link is judged signed
        ({"packet_loss": 0.5, "reordering": 0.3}, False),  # 65% of the frames do not count
    ],
)
def test_the_validator_admits_only_links_a_companion_flies(link: dict[str, object], flyable: bool, tmp_path: Path):
    data = yaml.safe_load(STRIKE.read_text())
    data["link"].update(link)
    path = tmp_path / "link.yaml"
    path.write_text(yaml.safe_dump(data))
    if flyable:
        assert load(path).link.frame_loss <= MAX_LINK_LOSS
    else:
        with pytest.raises(ScenarioError, match=r"link: .* at most 60% may be lost"):
            load(path)


def test_command_attempts_grow_with_the_link_loss_and_stay_ten_on_the_shipped_links() -> None:
    assert command_attempts(LinkModel()) == 10  # random.yaml, strike.yaml
    assert command_attempts(LinkModel(packet_loss=0.1)) == 10  # degraded.yaml: unchanged
    assert command_attempts(LinkModel(packet_loss=0.6)) == 80
    assert command_attempts(LinkModel(reordering=0.6)) == 80
    # the chance that every attempt fails, at the validator's limit: below one in a million
    assert (1 - 0.4**2) ** command_attempts(LinkModel(packet_loss=0.6)) < 1e-6


@pytest.mark.timeout(60)
def test_commands_get_through_a_link_that_loses_sixty_percent_each_way() -> None:
    """A real vehicle (SITL, 60% loss each way on its link) and a companion's link: 40 mode changes with the
    attempts the companion takes for this link all acknowledged; some needed more than the 10 attempts a companion
    used to give up after (``fly`` over such a link ended its campaign with 'no COMMAND_ACK')."""
    lossy = dataclasses.replace(scenario(), link=dataclasses.replace(scenario().link, packet_loss=0.6))
    attempts = CompanionConfig("udpout:127.0.0.1:1", Role.DECOY, lossy).attempts
    with sitl(lossy, speedup=20.0, seed=61) as s, MavLink(f"udpout:127.0.0.1:{s.ports[0]}") as link:
        link.wait_heartbeat(30.0)
        retried = []
        for _ in range(40):
            before = link.counters.command_retries
            link.set_mode(GUIDED, timeout_s=0.03, retries=attempts)
            retried.append(link.counters.command_retries - before)
    assert max(retried) >= 10, retried
