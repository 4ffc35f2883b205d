"""Values the paper gives per task or per dataset: Table 6's CQL alpha (read by the config when a run leaves
it unset) and Table 1's online returns (the offline score's reference, repro/data/reference.py).

Each table is one packaged CSV under ``repro/config/data/``, the only copy: the analysis (analysis/paper.py)
reads the same files through this module's paths.
"""

from __future__ import annotations

import csv
from functools import lru_cache
from pathlib import Path

from omegaconf import DictConfig

from repro.config.schema import normalize_dataset

DATA_DIR = Path(__file__).resolve().parent / "data"
ALPHA_TABLE = DATA_DIR / "cql_alpha.csv"  # Table 6: CQL's alpha per task and dataset kind
ONLINE_TABLE = DATA_DIR / "online_rl_table.csv"  # Table 1: mean and std return at 1M frames per task and method


@lru_cache(maxsize=1)
def _alpha_table() -> dict[tuple[str, str | None], float]:
    with ALPHA_TABLE.open(newline="") as f:
        return {(row["task"], normalize_dataset(row["dataset"])): float(row["alpha_cql"]) for row in csv.DictReader(f)}


def cql_alpha(task: str, dataset: str) -> float:
    """The paper's Table 6 alpha for a task and dataset kind (``medium-replay`` and ``medium_replay`` alike).

    Unknown pairs raise a one-line ValueError naming the known tasks and kinds.
    """
    table = _alpha_table()
    key = (task, normalize_dataset(dataset))
    if key not in table:
        tasks = sorted({t for t, _ in table})
        kinds = sorted({str(d) for _, d in table})
        raise ValueError(f"no Table 6 CQL alpha for task={task!r} dataset={dataset!r} (known tasks: "
                         f"{', '.join(tasks)}; datasets: {', '.join(kinds)}); set agent.cql.alpha")
    return table[key]


def resolve_cql_alpha(cfg: DictConfig) -> None:
    """Learner ``cql``'s ``resolve`` hook (repro/config/schema.py): a null ``agent.cql.alpha`` takes Table 6's value
    for the run's task and dataset kind, before anything is written. ValueError (one line) for a dataset folder or
    a pair the table lacks: the run must set agent.cql.alpha."""
    dataset = cfg.offline.dataset
    if cfg.agent.cql.alpha is not None or dataset is None:
        return
    from repro.config.compose import is_folder_value

    dataset = str(dataset)
    if is_folder_value(dataset):
        raise ValueError(f"agent.cql.alpha: Table 6 gives alpha per task and dataset kind, not for the folder "
                         f"'{dataset}'; set agent.cql.alpha (one of 0.5, 1, 2, 4, 8 in the paper).")
    try:
        cfg.agent.cql.alpha = float(cql_alpha(str(cfg.task.name), dataset))
    except ValueError:
        raise ValueError(f"agent.cql.alpha: Table 6 has no value for task {cfg.task.name} and dataset {dataset}; "
                         "set agent.cql.alpha.") from None


def online_means(method: str) -> dict[str, float]:
    """Table 1's mean return at 1M frames of ``method`` (as printed, e.g. ``TACO``) per task, in the table's order."""
    with ONLINE_TABLE.open(newline="") as f:
        return {row["task"]: float(row["mean"]) for row in csv.DictReader(f) if row["method"] == method}
