"""A sweep against the packaged config groups: options it names that do not exist, bad tasks and --set groups.

The group options, the check of one option and the close-match hints are repro.config.compose's.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from repro.config.compose import check_option, config_groups
from repro.launch.spec.errors import SweepError
from repro.launch.spec.overrides import override_key, override_value
from repro.launch.spec.sweepfile import SweepSpec


def missing_options(spec: SweepSpec) -> dict[str, list[str]]:
    """Group -> options the sweep selects that the packaged config does not have (e.g. an agent
    nobody has written yet). Empty when the sweep can run."""
    groups = config_groups()
    wanted: list[tuple[str, str]] = [("agent", a) for a in spec.agents]
    for ov in itertools.chain(spec.common, *spec.variants.values()):
        key = override_key(ov)
        if key in groups and not ov.startswith("~"):
            wanted.append((key, override_value(ov)))
    missing: dict[str, list[str]] = {}
    for group, option in wanted:
        if option not in groups.get(group, []) and option not in missing.get(group, []):
            missing.setdefault(group, []).append(option)
    return missing


def unavailable_reason(spec: SweepSpec) -> str | None:
    """One line saying why the sweep cannot run yet, or None."""
    missing = missing_options(spec)
    if not missing:
        return None
    parts = [f"{group} {', '.join(opts)}" for group, opts in missing.items()]
    return (f"sweep '{spec.name}' cannot run yet: {'; '.join(parts)} not in the packaged config "
            f"(repro/conf/{'|'.join(missing)}/); it is declared for {', '.join(spec.artifacts)}.")


def check_tasks(tasks: Sequence[str]) -> None:
    """ConfigError naming the first task the packaged config does not have."""
    for task in tasks:
        check_option("task", task)


def check_sets(sets: Sequence[str]) -> None:
    """SweepError for a ``--set`` that is not key=value, ConfigError for one that selects an unknown option of a
    config group."""
    groups = config_groups()
    for ov in sets:
        if "=" not in ov:
            raise SweepError(f"--set '{ov}' is not key=value.")
        key = override_key(ov)
        if key in groups:
            check_option(key, override_value(ov), where=f" in --set {ov}")
