"""The campaign's world fault profiles (issue 12): ``crowd`` and ``clutter`` on the sim,
their ground-truth sidecar, and profiles combined with ``+``."""

from __future__ import annotations

import pytest

from mmexec.config.yamlload import InputError
from mmexec.executive.campaign.faults import (
    BUILTIN_PROFILES,
    apply_fault_profile,
    load_fault_profile,
)

CONFIG = {"backend": "sim", "sim": {"world": "lab", "faults": {"kidnap": {"at": 3.0}}}}


@pytest.mark.parametrize("name", ["crowd", "clutter"])
def test_the_world_fault_profiles_switch_the_fault_on_and_write_the_truth(name: str) -> None:
    assert name in BUILTIN_PROFILES
    cfg = apply_fault_profile(CONFIG, load_fault_profile(name), randomize=True)
    assert cfg["sim"] == {"world": "lab", "faults": {name: {}}, "truth_log": "truth/{seed}.jsonl", "randomize": True}


def test_profiles_combine_with_a_plus() -> None:
    both = load_fault_profile("crowd+arm_fail_first")
    assert both.name == "crowd+arm_fail_first" and "people walk" in both.description
    cfg = apply_fault_profile(CONFIG, both, randomize=False)
    # every fault off once (the config's kidnap is gone), then both profiles' faults
    assert cfg["sim"]["faults"] == {"crowd": {}, "arm_fail_attempts": [1]}
    # the config's own faults kept, the crowd added
    cfg = apply_fault_profile(CONFIG, load_fault_profile("config+crowd"), randomize=False)
    assert cfg["sim"]["faults"] == {"kidnap": {"at": 3.0}, "crowd": {}}
    # only the backends all of them can run
    assert set(load_fault_profile("nominal+crowd").patches) == {"sim"}


def test_a_combination_without_a_common_backend_or_with_an_empty_name_is_refused() -> None:
    with pytest.raises(InputError, match="have no backend in common"):
        load_fault_profile("crowd+nav_blocked")
    with pytest.raises(InputError, match="an empty profile name"):
        load_fault_profile("crowd+")
    with pytest.raises(InputError, match="unknown fault profile 'crwod'"):
        load_fault_profile("crwod+arm_fail_first")
