"""The learner seam must not change the online agent: a few fixed-seed updates equal the record written by the
code before the refactor (tests/data/online_updates.json, see make_seam_fixture.py), up to the last-bit noise
between CPUs (seam_reference.RTOL), and bit for bit when computed twice in one process."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from seam_reference import AGENTS, RTOL, deviation, record, written_by

# its module-scoped runs are made once: every test of this module on one pytest-xdist worker
pytestmark = pytest.mark.xdist_group("seam")

FIXTURE = Path(__file__).parent / "data" / "online_updates.json"


@pytest.fixture(scope="module")
def expected() -> dict:
    return json.loads(FIXTURE.read_text())


@pytest.fixture(scope="module")
def today() -> dict:
    return {name: json.loads(json.dumps(record(name))) for name in AGENTS}


def _where(expected: dict) -> str:
    return f" (record from {expected['written_by']}, here {written_by()})"


@pytest.mark.parametrize("name", AGENTS)
def test_online_updates_equal_the_pre_refactor_record(name: str, expected: dict, today: dict):
    worst = deviation(today[name], expected[name])
    over = {kind: w for kind, w in worst.items() if not w[0] <= 1.0}
    assert not over, f"beyond tolerance {RTOL}: {over}" + _where(expected)


def test_a_one_line_change_to_the_update_exceeds_the_tolerance_by_orders_of_magnitude(expected: dict):
    """Dropping the target-noise clip (stddev_clip 0.3 -> none) is a one-line change to the update."""
    worst = deviation(json.loads(json.dumps(record("drqv2", ["agent.stddev_clip=1000000"]))), expected["drqv2"])
    assert worst["metrics"][0] > 1000 and worst["actions"][0] > 1000, worst
    assert worst["parameters"][0] > 10 and worst["optimizer"][0] > 10, worst


def test_the_record_is_bit_identical_within_one_process(today: dict):
    assert json.loads(json.dumps(record("taco"))) == today["taco"]


def test_fixture_covers_every_module_and_optimizer(expected: dict):
    keys = expected["taco"]["state"]
    for part in ("modules.encoder.", "modules.actor.", "modules.critic.", "modules.critic_target.",
                 "modules.action_encoder.", "modules.objective.taco.", "optimizers.aux.", "optimizers.critic."):
        assert any(k.startswith(part) for k in keys), part
    assert len(expected["taco"]["metrics"]) >= 3 and "taco_loss" in expected["taco"]["metrics"][0]
    assert {"torch", "cpu_capability"} <= set(expected["written_by"])
