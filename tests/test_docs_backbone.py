"""A backbone variant is the DrQ-v2 backbone given its parts (issue 51): docs/extending.md's worked example runs as
written, and A-LIX is the online agent on the backbone with A-LIX's parts (no backbone of its own, no copied
builder)."""

from __future__ import annotations

import ast
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

import alix_reference as ref
from repro.agent import alix
from repro.agent.agent import Agent
from repro.agent.backbone import DRQV2, DrQV2Backbone, twin_critic_loss
from repro.config.compose import compose, typed
from repro.config.schema import learner_section

ROOT = Path(__file__).resolve().parents[1]


def _section_code(title: str) -> str:
    text = (ROOT / "docs" / "extending.md").read_text()
    section = text.split(f"## {title}", 1)[1].split("\n## ", 1)[0]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


def _batch(seed: int) -> dict[str, torch.Tensor]:
    b = ref.batches()[seed % 2]
    return {k: torch.as_tensor(v[:8]) for k, v in b.items()}


def _built(factory: Callable[..., Any], overrides: list[str], **kwargs: Any) -> Any:
    cfg = typed(compose([*overrides, "profile=tiny"])).agent
    torch.manual_seed(0)
    return factory(cfg, ref.OBS_SHAPE, ref.ACTION_DIM, "cpu", **kwargs)


def test_the_backbone_variant_of_docs_extending_runs_as_written():
    namespace: dict = {}
    exec(compile(_section_code("A backbone variant"), "docs/extending.md", "exec"), namespace)
    huber, drqv2 = _built(namespace["HuberDrQV2"], ["agent=drqv2"]), _built(Agent, ["agent=drqv2"])
    assert type(huber.backbone) is DrQV2Backbone and huber.backbone.parts.critic_loss is namespace["huber_critic_loss"]
    assert drqv2.backbone.parts is DRQV2 and DRQV2.critic_loss is twin_critic_loss
    # the same networks, drawn the same way, under the same names (a checkpoint's keys)
    before = huber.state_dict()["modules"]
    assert before.keys() == drqv2.state_dict()["modules"].keys()
    assert all(torch.equal(v, drqv2.state_dict()["modules"]["critic"][k]) for k, v in before["critic"].items())
    torch.manual_seed(1)
    out = huber.update(_batch(0), 1000)
    torch.manual_seed(1)
    plain = drqv2.update(_batch(0), 1000)
    assert list(out) == huber.metric_names() == list(plain)
    assert out["critic_target_q"] == plain["critic_target_q"] and out["critic_loss"] != plain["critic_loss"]


def test_alix_is_the_online_agent_given_alix_parts():
    overrides = ["agent=alix", "agent.action_encoder=true", "+agent.objectives.curl=1.0"]
    learner = _built(alix.ALIX, overrides)
    parts = learner.backbone.parts
    assert type(learner.backbone) is DrQV2Backbone and isinstance(learner, Agent)
    assert parts.encoder.func is alix.ALIXEncoder and parts.critic.func is alix.ParallelCritic
    assert parts.critic_loss is alix.parallel_critic_loss and parts.encoder_groups.func is alix.strength_apart
    # the same learner as Agent given A-LIX's parts, but for the strength's column
    cfg = typed(compose([*overrides, "profile=tiny"])).agent
    agent = _built(Agent, overrides, parts=alix.alix_parts(learner_section(cfg, alix.ALIXConfig)))
    torch.manual_seed(1)
    out = learner.update(_batch(0), 1000)
    torch.manual_seed(1)
    plain = agent.update(_batch(0), 1000)
    assert {k: v for k, v in out.items() if k != alix.STRENGTH_METRIC} == plain
    for (name, a), b in zip(learner.state_dict()["modules"].items(), agent.state_dict()["modules"].values()):
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), name


def test_alix_imports_no_private_name_and_ignores_no_type():
    source = (ROOT / "repro" / "agent" / "alix.py").read_text()
    private = [f"{node.module}.{a.name}" for node in ast.walk(ast.parse(source))
               if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("repro")
               for a in node.names if a.name.startswith("_")]
    assert not private and "type: ignore" not in source
