"""The paper's own numbers (a copy of ``shared/paper`` in ``repro_data/paper``), as printed.

``claim_numbers.csv`` beside them is this project's: the numbers the paper gives only in its prose (the "1.4x", the
"3.6 times slower", appendix G's "3 out of 6 seeds"), each with the words it is quoted from
(repro_data/README.md). Table 1 and Table 6, which the training code reads too, have their one packaged copy in
``repro/config/data/`` and are read from there (``repro.config.paper_defaults``)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pandas as pd

from repro.config.paper_defaults import ALPHA_TABLE, ONLINE_TABLE
from repro.config.schema import normalize_dataset
from repro_data import PAPER_DIR

# The nine DMC tasks of Table 1 in the paper's row order.
DMC9 = (
    "quadruped_run",
    "hopper_hop",
    "walker_run",
    "quadruped_walk",
    "cheetah_run",
    "finger_turn_hard",
    "acrobot_swingup",
    "reacher_hard",
    "reach_duplo",
)
METAWORLD6 = ("hammer", "assembly", "disassemble", "stick-pull", "pick-place-wall", "hand-insert")
OFFLINE_TASKS = ("hopper_hop", "cheetah_run", "walker_run", "quadruped_run")


@dataclass
class PaperData:
    """Read-only access to the paper's tables; ``root`` holds the CSVs and ``taco_paper.tex`` but Tables 1 and 6
    (repro/config/data/)."""

    root: Path = PAPER_DIR

    def _csv(self, name: str | Path) -> pd.DataFrame:
        return pd.read_csv(self.root / name)  # an absolute path (ONLINE_TABLE, ALPHA_TABLE) stays as it is

    @cached_property
    def online(self) -> pd.DataFrame:
        """Table 1: task, method, mean, std, frames, seeds, family."""
        return self._csv(ONLINE_TABLE)

    @cached_property
    def repr_objectives(self) -> pd.DataFrame:
        """Table 2: task, method, mean, std (DRIML empty where N/A)."""
        return self._csv("representation_objectives_table.csv")

    @property
    def repr_methods(self) -> tuple[str, ...]:
        """Table 2's methods in its column order (the order of each task's rows in its CSV)."""
        return tuple(dict.fromkeys(self.repr_objectives["method"]))

    @property
    def repr_others(self) -> tuple[str, ...]:
        """The representation objectives Table 2 sets against TACO (all but TACO and the DrQ-v2 baseline), in its
        order: read from the table, never listed in the code."""
        return tuple(m for m in self.repr_methods if m not in ("TACO", "DrQ-v2"))

    @cached_property
    def online_gain(self) -> float:
        """Table 1's TACO / DrQ-v2: the ratio of their means over the nine DMC tasks (the abstract's '1.4x')."""
        piv = self.online.pivot(index="task", columns="method", values="mean").loc[list(DMC9)]
        return float(piv["TACO"].mean() / piv["DrQ-v2"].mean())

    @cached_property
    def offline(self) -> pd.DataFrame:
        """Table 3: task, dataset, method, normalized_mean, normalized_std."""
        df = self._csv("offline_rl_table.csv")
        df["dataset"] = df["dataset"].map(normalize_dataset)
        return df

    @cached_property
    def offline_average(self) -> pd.DataFrame:
        """Table 3's average row as printed: method, average_normalized."""
        return self._csv("offline_average.csv")

    @cached_property
    def time_efficiency(self) -> pd.DataFrame:
        """Tables 4 and 5: method, batch_size, fps, hardware."""
        return self._csv("time_efficiency.csv")

    @cached_property
    def cql_alpha(self) -> pd.DataFrame:
        """Table 6: task, dataset, alpha_cql (dataset names normalised to Table 3's)."""
        df = self._csv(ALPHA_TABLE)
        df["dataset_as_printed"] = df["dataset"]
        df["dataset"] = df["dataset"].map(normalize_dataset)
        return df

    @cached_property
    def claims(self) -> pd.DataFrame:
        """claims.csv: id, where, claim, evidence."""
        return self._csv("claims.csv")

    @cached_property
    def claim_numbers(self) -> pd.DataFrame:
        """claim_numbers.csv: claim, name, value, written (the number as the quote writes it), quote (words of the
        claim's text in claims.csv), tex (the same statement's words in taco_paper.tex), where (in the paper)."""
        return self._csv("claim_numbers.csv")

    def claim_number(self, claim: str, name: str) -> float:
        """The number ``name`` the paper's prose gives for claim ``claim`` (claim_numbers.csv; KeyError if none)."""
        rows = self.claim_numbers[(self.claim_numbers["claim"] == claim) & (self.claim_numbers["name"] == name)]
        if rows.empty:
            raise KeyError(f"no number {name!r} of claim {claim!r} in {self.root / 'claim_numbers.csv'}")
        return float(rows["value"].iloc[0])

    def claim_integer(self, claim: str, name: str) -> int:
        """:meth:`claim_number` for a number the prose gives as a whole number (a count, a horizon K); ValueError
        if claim_numbers.csv gives it with a fraction."""
        value = self.claim_number(claim, name)
        if not value.is_integer():
            raise ValueError(f"number {name!r} of claim {claim!r} is {value:g}, not a whole number")
        return int(value)

    @cached_property
    def tex(self) -> str:
        """The paper's LaTeX source."""
        return (self.root / "taco_paper.tex").read_text(encoding="utf-8")

    def online_value(self, task: str, method: str) -> tuple[float, float] | None:
        """(mean, std) of Table 1 for ``task`` and ``method``, or None."""
        return _lookup(self.online, task=task, method=method)

    def repr_value(self, task: str, method: str) -> tuple[float, float] | None:
        """(mean, std) of Table 2, or None (also where the paper prints N/A)."""
        return _lookup(self.repr_objectives, task=task, method=method)

    def fps(self, method: str, batch_size: int) -> float:
        """Tables 4-5's FPS of ``method`` at ``batch_size`` (KeyError if the paper has no such entry)."""
        return float(self.time_efficiency.set_index(["method", "batch_size"]).loc[(method, batch_size), "fps"])


def _lookup(df: pd.DataFrame, **where: str) -> tuple[float, float] | None:
    mask = pd.Series(True, index=df.index)
    for col, val in where.items():
        mask &= df[col] == val
    rows = df[mask]
    if rows.empty or pd.isna(rows.iloc[0]["mean"]):
        return None
    return float(rows.iloc[0]["mean"]), float(rows.iloc[0]["std"])
