"""Which runs feed which artifact cell: a data-driven mapping from run identity to a labelled cell.

Each selection names the experiments (as the sweeps name them) it reads, in order of preference, and
labels runs from their config (K, batch size, objectives, ...), never from the path. When several of
the listed experiments hold runs for the same cell (e.g. DrQ-v2 on a task in both ``horizon`` and
``main``), the first listed experiment with runs for that cell is used and the others are ignored for
that cell, so one cell never mixes runs of different sweeps.

``experiment_map`` lets a user point a canonical experiment at other names, e.g.
``{"main": ["main", "tiny"]}``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import pandas as pd

from analysis.paper import DMC9

ExperimentMap = Mapping[str, Sequence[str]]
FULL_OBJECTIVES = ("curl", "reward", "taco")
_OBJECTIVE_LABELS = {"taco": "TACO", "curl": "CURL", "reward": "reward"}


def expand_experiments(experiments: Sequence[str], experiment_map: ExperimentMap | None) -> list[str]:
    """The actual experiment names read for canonical ``experiments`` under ``experiment_map``, in order."""
    return _expand(experiments, experiment_map)


def _expand(experiments: Sequence[str], experiment_map: ExperimentMap | None) -> list[str]:
    out: list[str] = []
    for name in experiments:
        for actual in (experiment_map or {}).get(name, [name]):
            if actual not in out:
                out.append(actual)
    return out


def _match(series: pd.Series, cond: Any) -> pd.Series:
    if callable(cond):
        return series.map(lambda v: bool(cond(v)))
    if isinstance(cond, (set, frozenset, list, tuple)):
        return series.isin(list(cond))
    return series == cond


def pick(
    scores: pd.DataFrame,
    experiments: Sequence[str],
    label: Callable[[pd.Series], str | None],
    keys: Sequence[str] = ("task", "label"),
    experiment_map: ExperimentMap | None = None,
    **where: Any,
) -> pd.DataFrame:
    """Rows of ``scores`` from ``experiments`` matching ``where``, with a ``label`` column.

    ``label`` returns None for rows that belong to no cell. For each ``keys`` group only the rows of
    the first experiment (in the given order) that has any are kept.
    """
    exps = _expand(experiments, experiment_map)
    if scores.empty:
        return scores.assign(label=pd.Series(dtype=object))
    df = scores[scores["experiment"].isin(exps)]
    for col, cond in where.items():
        df = df[_match(df[col], cond).to_numpy(dtype=bool)]
    if df.empty:
        return df.assign(label=pd.Series(dtype=object))
    df = df.assign(label=df.apply(label, axis=1))
    df = df[df["label"].notna()]
    if df.empty:
        return df
    rank = df["experiment"].map({e: i for i, e in enumerate(exps)})
    best = rank.groupby([df[k] for k in keys]).transform("min")
    return df[rank == best].copy()


def by_method(row: pd.Series) -> str:
    """A row's label: its ``method`` column, the paper's method name (runs of several variants of one method
    share the cell; the tables list the variants that contributed, see analysis.compare.build_cells)."""
    return str(row["method"])


def online_main(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """Table 1 / F1 / F4 / F11: online runs of the main comparison on the paper's nine DMC tasks (reach_duplo's
    suite is ``manipulation``), labelled by method."""
    return pick(scores, ["main"], by_method, experiment_map=experiment_map, task=set(DMC9),
                dataset=lambda d: pd.isna(d))


def repr_objectives(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """Table 2: TACO, SPR, ATC, DRIML, DrQ-v2 on the DrQ-v2 backbone."""
    return pick(
        scores,
        ["repr_objectives", "main"],
        by_method,
        experiment_map=experiment_map,
        agent={"taco", "spr", "atc", "driml", "drqv2"},
        dataset=lambda d: pd.isna(d),
    )


def action_repr(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F3: TACO with and without the action encoder, and DrQ-v2."""

    def label(row: pd.Series) -> str | None:
        if row["agent"] == "drqv2":
            return "DrQ-v2"
        if row["agent"] == "taco":
            enc = row["action_encoder"]
            off = enc is not None and not pd.isna(enc) and not bool(enc)
            return "TACO w/o action repr" if off else "TACO"
        return None

    return pick(scores, ["action_repr", "main"], label, experiment_map=experiment_map, dataset=lambda d: pd.isna(d))


def horizon(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F8: TACO at each K, and DrQ-v2, on the nine DMC tasks."""

    def label(row: pd.Series) -> str | None:
        if row["agent"] == "drqv2":
            return "DrQ-v2"
        if row["agent"] == "taco" and not pd.isna(row["K"]):
            return f"K={int(row['K'])}"
        return None

    return pick(
        scores,
        ["horizon", "main"],
        label,
        experiment_map=experiment_map,
        task=set(DMC9),
        action_repeat=lambda a: pd.isna(a) or int(a) == 2,
        dataset=lambda d: pd.isna(d),
    )


def action_repeat(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F9: TACO on hopper_hop for each (action repeat, K); label ``AR=a, K=k``."""

    def label(row: pd.Series) -> str | None:
        if pd.isna(row["K"]) or pd.isna(row["action_repeat"]):
            return None
        return f"AR={int(row['action_repeat'])}, K={int(row['K'])}"

    return pick(
        scores,
        ["action_repeat", "horizon", "main"],
        label,
        experiment_map=experiment_map,
        task="hopper_hop",
        agent="taco",
    )


def batch_size(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F7a: TACO and DrQ-v2 on quadruped_run for each batch size; label ``METHOD B``."""

    def label(row: pd.Series) -> str | None:
        if pd.isna(row["batch_size"]):
            return None
        return f"{row['method']} B{int(row['batch_size'])}"

    return pick(
        scores,
        ["batch_size", "main"],
        label,
        experiment_map=experiment_map,
        task="quadruped_run",
        agent={"taco", "drqv2"},
    )


def objective_label(objectives: str) -> str:
    """``full`` when TACO, CURL and reward are all on; ``no X`` when exactly X is off."""
    on = set(filter(None, str(objectives).split("+")))
    missing = [o for o in FULL_OBJECTIVES if o not in on]
    if not missing:
        return "full"
    if len(missing) == 1:
        return f"no {_OBJECTIVE_LABELS[missing[0]]}"
    return "only " + ("+".join(_OBJECTIVE_LABELS.get(o, o) for o in sorted(on)) or "RL loss")


def objective_removal(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F7b: TACO on quadruped_run with one objective removed at a time."""
    return pick(
        scores,
        ["objective_removal", "main"],
        lambda r: objective_label(r["objectives"]),
        experiment_map=experiment_map,
        task="quadruped_run",
        agent="taco",
    )


def dim_value(row: pd.Series) -> int | None:
    """The latent action dimension a run used (its recorded resolved value; None when unknown)."""
    return None if pd.isna(row["latent_action_dim"]) else int(row["latent_action_dim"])


def action_dim_runs(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F10: TACO on quadruped_run for each latent action dimension; label ``d=..``."""

    def label(row: pd.Series) -> str | None:
        dim = dim_value(row)
        return None if dim is None else f"d={dim}"

    df = pick(
        scores,
        ["action_dim", "main"],
        label,
        experiment_map=experiment_map,
        task="quadruped_run",
        agent="taco",
    )
    if not df.empty:
        df["dim"] = df.apply(dim_value, axis=1)
    return df


def metaworld(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F5: Meta-world runs labelled by method."""
    return pick(scores, ["metaworld", "main"], by_method, experiment_map=experiment_map, suite="metaworld")


def manipulator(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """F12: manipulator bring_ball runs labelled by method."""
    return pick(
        scores,
        ["manipulator", "main"],
        by_method,
        experiment_map=experiment_map,
        task=lambda t: str(t).startswith("manipulator"),
    )


def offline(scores: pd.DataFrame, experiment_map: ExperimentMap | None = None) -> pd.DataFrame:
    """T3: offline runs (a dataset in the config) labelled by method (``CQL+TACO``...)."""
    return pick(
        scores,
        ["offline"],
        by_method,
        keys=("task", "dataset", "label"),
        experiment_map=experiment_map,
        dataset=lambda d: not pd.isna(d),
    )
