"""Sweep definitions: load and validate a sweep YAML, expand its grid into runs, resolve run dirs.

A sweep file (``sweeps/NAME.yaml``, documented in docs/sweeps.md) declares tasks, agents, variants
(name -> config overrides), seeds, frame budget and evaluation schedule. ``expand`` turns it into one
``Run`` per (agent, variant, task, seed); ``plan`` composes each run's config with the packaged Hydra
config and finds its run directory and state.

One module per job: ``overrides`` (override strings), ``sweepfile`` (one file's fields and checks),
``catalog`` (the packaged sweep files), ``groups`` (the sweep against the config groups, with
repro.config.compose's checks), ``grid`` (expansion), ``plan`` (composition and run-directory state). This
package re-exports their public names, so callers use ``repro.launch.spec`` as one namespace.
"""

from __future__ import annotations

from repro.config.compose import close_matches, config_groups
from repro.launch.spec.catalog import ENV_SWEEPS_DIR, load, load_all, sweep_names, sweeps_dir
from repro.launch.spec.errors import SweepError
from repro.launch.spec.grid import Run, Selection, excluded, expand, selection
from repro.launch.spec.groups import check_sets, check_tasks, missing_options, unavailable_reason
from repro.launch.spec.overrides import hydra_quote, merge_overrides, override_key, override_value
from repro.launch.spec.plan import PlannedRun, compose_runs, plan, results_root_of, run_key
from repro.launch.spec.sweepfile import EXCLUDE_FIELDS, FIELDS, REQUIRED, Exclusion, SweepSpec, load_file

__all__ = [
    "ENV_SWEEPS_DIR", "EXCLUDE_FIELDS", "FIELDS", "REQUIRED", "Exclusion", "PlannedRun", "Run", "Selection",
    "SweepError", "SweepSpec", "check_sets", "check_tasks", "close_matches", "compose_runs", "config_groups",
    "excluded", "expand", "hydra_quote", "load", "load_all", "load_file", "merge_overrides", "missing_options",
    "override_key", "override_value", "plan", "results_root_of", "run_key", "selection", "sweep_names",
    "sweeps_dir", "unavailable_reason",
]
