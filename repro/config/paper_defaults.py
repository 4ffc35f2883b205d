"""Values the paper gives per task or per dataset, read by the config when a run leaves them unset.

Each table is one packaged CSV under ``repro/config/data/``, the only copy: the analysis reads the same file
through this module.
"""

from __future__ import annotations

import csv
from functools import lru_cache
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent / "data"
ALPHA_TABLE = DATA_DIR / "cql_alpha.csv"  # Table 6: CQL's alpha per task and dataset kind


def _dataset_key(dataset: str) -> str:
    return dataset.strip().lower().replace("-", "_")


@lru_cache(maxsize=1)
def _alpha_table() -> dict[tuple[str, str], float]:
    with ALPHA_TABLE.open(newline="") as f:
        return {(row["task"], _dataset_key(row["dataset"])): float(row["alpha_cql"]) for row in csv.DictReader(f)}


def cql_alpha(task: str, dataset: str) -> float:
    """The paper's Table 6 alpha for a task and dataset kind (``medium-replay`` and ``medium_replay`` alike).

    Unknown pairs raise a one-line ValueError naming the known tasks and kinds.
    """
    table = _alpha_table()
    key = (task, _dataset_key(dataset))
    if key not in table:
        tasks = sorted({t for t, _ in table})
        kinds = sorted({d.replace("_", "-") for _, d in table})
        raise ValueError(f"no Table 6 CQL alpha for task={task!r} dataset={dataset!r} (known tasks: "
                         f"{', '.join(tasks)}; datasets: {', '.join(kinds)}); set agent.cql.alpha")
    return table[key]
