"""The config schema's name tables (repro/config/schema.py) and the registries that must agree with them."""

from __future__ import annotations

import importlib

import pytest

from repro.config import schema
from repro.config.schema import LearnerName, ObjectiveName, check_registry, is_offline


def test_check_registry_names_what_is_missing_and_what_is_extra():
    check_registry("learner", {n.value: None for n in LearnerName}, LearnerName)  # equal keys pass
    with pytest.raises(ValueError, match=r"missing: iql; not in the schema: -") as err:
        check_registry("learner", {n.value: None for n in LearnerName if n != LearnerName.iql}, LearnerName)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r"missing: -; not in the schema: sac"):
        check_registry("learner", [*LearnerName.values(), "sac"], LearnerName)


def _one_more(enum: type[schema.Choice], extra: str) -> type[schema.Choice]:
    return schema.Choice(enum.__name__, {**{v: v for v in enum.values()}, extra: extra})  # type: ignore[return-value]


@pytest.mark.parametrize("module, attribute, what", [("repro.learners.registry", "LearnerName", "learner"),
                                                     ("repro.agent.objectives", "ObjectiveName", "objective")])
def test_a_registry_that_lacks_a_schema_name_fails_at_import(monkeypatch, module: str, attribute: str, what: str):
    """Re-running the registry module's import against a schema with one name more (so the registry lacks it)."""
    mod = importlib.import_module(module)
    monkeypatch.setattr(schema, attribute, _one_more(getattr(schema, attribute), "newname"))
    try:
        with pytest.raises(ValueError, match=f"the {what} registry .* missing: newname"):
            importlib.reload(mod)
    finally:
        monkeypatch.undo()
        importlib.reload(mod)


def test_the_offline_flag_is_schema_data():
    assert not is_offline(LearnerName.actor_critic) and not is_offline("actor_critic")
    assert all(is_offline(n) for n in ("bc", "td3bc", "cql", "iql", "dt"))
    from repro.learners import is_offline as learners_is_offline

    assert learners_is_offline is is_offline  # the learners layer offers the schema's function, not its own table


def test_every_choice_member_is_named_by_its_value():
    """OmegaConf reads and writes an Enum field by member name: a name other than the value would change the
    YAML a run writes and the overrides it accepts."""
    fields = schema.choice_fields()
    assert fields["agent.learner"] is LearnerName
    for enum in {*fields.values(), ObjectiveName}:
        assert all(m.name == m.value for m in enum), enum
        assert all(str(m) == f"{m}" == m.value for m in enum), enum
