"""The learner seam must not change the online agent: a few fixed-seed updates are bit-identical to the
record written by the code before the refactor (tests/data/online_updates.json, see make_seam_fixture.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from seam_reference import AGENTS, record  # noqa: E402

FIXTURE = Path(__file__).parent / "data" / "online_updates.json"


@pytest.fixture(scope="module")
def expected() -> dict:
    return json.loads(FIXTURE.read_text())


@pytest.mark.parametrize("name", AGENTS)
def test_online_updates_bit_identical_to_pre_refactor_record(name: str, expected: dict):
    want = expected[name]
    got = json.loads(json.dumps(record(name)))  # same float repr as the fixture
    hint = "" if got["torch"] == want["torch"] else f" (fixture from torch {want['torch']}, now {got['torch']})"
    assert got["parameter_counts"] == want["parameter_counts"]
    assert got["metric_names"] == want["metric_names"]
    assert got["metrics"] == want["metrics"], "update metrics differ" + hint
    assert got["actions"] == want["actions"], "actions differ" + hint
    assert sorted(got["state"]) == sorted(want["state"]), "state dict keys differ"
    changed = [k for k in want["state"] if got["state"][k] != want["state"][k]]
    assert not changed, f"{len(changed)} tensors differ, e.g. {changed[:3]}" + hint


def test_fixture_covers_every_module_and_optimizer(expected: dict):
    keys = expected["taco"]["state"]
    for part in ("modules.encoder.", "modules.actor.", "modules.critic.", "modules.critic_target.",
                 "modules.action_encoder.", "modules.objective.taco.", "optimizers.aux.", "optimizers.critic."):
        assert any(k.startswith(part) for k in keys), part
    assert len(expected["taco"]["metrics"]) >= 3 and "taco_loss" in expected["taco"]["metrics"][0]
    # the record is CPU- and torch-version-specific: a failure names both versions (see the hint above)
