"""Campaign requests drawn from a sim world's untagged objects (--draw item=@objects) and
the answers file passed to every trial (--answers), for the fetch_object mission."""

from __future__ import annotations

from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError
from mmexec.executive.campaign.requests import parse_draws
from mmexec.executive.campaign.run import Campaign, CampaignOptions, RequestPlan

REPO = Path(__file__).resolve().parents[2]


def test_at_objects_draws_the_worlds_untagged_objects() -> None:
    draws = parse_draws(["item=@objects"], {"backend": "sim", "sim": {"world": "lab_objects"}})
    assert draws == {"item": ("box_red", "cylinder_violet", "screwdriver", "pen", "pliers")}


@pytest.mark.parametrize(("cfg", "message"), [
    ({"backend": "sim", "sim": {"world": "lab"}}, "no untagged objects"),
    ({"backend": "mock", "mock": {}}, "@objects needs a sim config"),
])
def test_at_objects_without_objects_is_a_located_error(cfg: dict, message: str) -> None:
    with pytest.raises(InputError) as e:
        parse_draws(["item=@objects"], cfg)
    assert message in str(e.value) and "--draw" in str(e.value)


def test_the_answers_file_goes_to_every_trial(tmp_path: Path) -> None:
    answers = REPO / "config" / "answers" / "sim_click.yaml"
    opts = CampaignOptions(mission=REPO / "trees" / "fetch_object.yaml", config=REPO / "config" / "locobot_objects_sim.yaml",
                           trials=2, out=tmp_path / "c", requests=RequestPlan(draws={"item": ("pen",)}), answers=answers)
    camp = Campaign(opts)
    spec = camp._spec(0, 7, [{"item": "pen"}], str(REPO))
    i = spec.argv.index("--answers")
    assert spec.argv[i + 1] == str(answers)
    assert "--answers" in spec.command  # the reproduction answers the same way
