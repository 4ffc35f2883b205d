"""docs/extending.md documents every member of what an objective receives (repro/agent/objectives/base.py): a field
added to ObjectiveContext, a method added to AuxBatch or a class attribute an objective declares that the section
does not name fails here."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext

ROOT = Path(__file__).resolve().parents[1]


def test_extending_documents_what_an_objective_receives():
    text = (ROOT / "docs" / "extending.md").read_text()
    assert "## What an objective receives" in text
    section = text.split("## What an objective receives", 1)[1].split("\n## ", 1)[0]
    fields = [f.name for f in dataclasses.fields(ObjectiveContext) if not f.name.startswith("_")]
    missing = [f for f in fields if f"`{f}`" not in section]
    missing += [] if "`shared()`" in section else ["shared()"]
    methods = [n for n, _ in inspect.getmembers(AuxBatch, inspect.isfunction) if not n.startswith("_")]
    missing += [f"aux.{m}" for m in methods if f"`aux.{m}(" not in section]
    declared = ["needs_future_seq", "extra_metrics", "metric_keys()", "after_update()", "forward(aux)"]
    missing += [d for d in declared if f"`{d}" not in section]
    assert hasattr(Objective, "needs_future_seq") and hasattr(Objective, "extra_metrics")
    assert not missing, f"docs/extending.md does not document: {missing}"
