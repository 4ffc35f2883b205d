"""Write tables as CSV (raw numbers), Markdown and LaTeX (formatted), and build comparison tables.

A comparison table puts, for each cell, the paper's value beside the reproduced mean +- std (ddof=1),
the number of seeds, the 95% bootstrap CI, the difference and whether the paper's value lies in the CI.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.comparable import Budget, comparable, not_comparable_text, units_note
from analysis.io import atomic_write_text
from analysis.stats import CellStats

EMPTY = "—"  # an empty cell: no data


def fmt_num(value: Any, digits: int = 1) -> str:
    """A number for display; NaN/None as the empty-cell mark."""
    if value is None:
        return EMPTY
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(v):
        return EMPTY
    return f"{v:.{digits}f}"


def fmt_pm(mean: Any, std: Any, digits: int = 1) -> str:
    """``mean ± std``, ``mean`` alone if std is undefined, the empty mark if mean is."""
    m = fmt_num(mean, digits)
    if m == EMPTY:
        return EMPTY
    s = fmt_num(std, digits)
    return m if s == EMPTY else f"{m} ± {s}"


def fmt_ci(lo: Any, hi: Any, digits: int = 1) -> str:
    a, b = fmt_num(lo, digits), fmt_num(hi, digits)
    return EMPTY if EMPTY in (a, b) else f"[{a}, {b}]"


def fmt_bool(value: bool | None, yes: str = "yes", no: str = "no") -> str:
    return EMPTY if value is None else (yes if value else no)


def to_markdown(df: pd.DataFrame) -> str:
    """A GitHub-flavoured Markdown pipe table of the (already formatted) frame."""

    def cell(v: Any) -> str:
        text = EMPTY if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
        return text.replace("|", "\\|").replace("\n", " ")

    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(cell(c) for c in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(cell(v) for v in row) + " |")
    return "\n".join(lines) + "\n"


_TEX_ESCAPE = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "±": r"$\pm$",
    "—": "--",
    "Δ": r"$\Delta$",
    "≤": r"$\le$",
    "≥": r"$\ge$",
    "×": r"$\times$",
}


def tex_escape(text: Any) -> str:
    return "".join(_TEX_ESCAPE.get(ch, ch) for ch in str(text))


def to_latex(df: pd.DataFrame, caption: str, label: str) -> str:
    """A booktabs ``table`` environment of the (already formatted) frame."""
    cols = list(df.columns)
    lines = [
        r"\begin{table}[ht]",
        r"\centering",
        rf"\caption{{{tex_escape(caption)}}}",
        rf"\label{{{label}}}",
        r"\begin{tabular}{" + "l" * len(cols) + "}",
        r"\toprule",
        " & ".join(tex_escape(c) for c in cols) + r" \\",
        r"\midrule",
    ]
    for row in df.itertuples(index=False):
        lines.append(" & ".join(tex_escape(EMPTY if v is None else v) for v in row) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}", ""]
    return "\n".join(lines)


@dataclass
class TableOutput:
    """A written table: its id, caption, notes, raw and display frames, and the files."""

    name: str
    caption: str
    data: pd.DataFrame
    display: pd.DataFrame
    notes: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    def markdown(self) -> str:
        notes = "".join(f"\n_{n}_\n" for n in self.notes)
        return f"**{self.name}.** {self.caption}\n\n{to_markdown(self.display)}{notes}"


def write_table(
    out_dir: Path,
    name: str,
    data: pd.DataFrame,
    caption: str,
    display: pd.DataFrame | None = None,
    notes: Sequence[str] = (),
) -> TableOutput:
    """Write ``{name}.csv`` (raw ``data``), ``{name}.md`` and ``{name}.tex`` (``display``) atomically."""
    out_dir = Path(out_dir)
    display = data if display is None else display
    table = TableOutput(name, caption, data, display, list(notes))
    table.files = [
        atomic_write_text(out_dir / f"{name}.csv", data.to_csv(index=False)),
        atomic_write_text(out_dir / f"{name}.md", table.markdown()),
        atomic_write_text(
            out_dir / f"{name}.tex",
            to_latex(display, caption + "".join(" " + n for n in notes), f"tab:repro_{name.lower()}"),
        ),
    ]
    return table


KEY_NAMES = {"label": "Method / variant", "ar": "Action repeat", "k": "K", "dim": "Latent action dim",
             "batch": "Batch size", "arm": "Arm"}


def key_name(key: str) -> str:
    """Display name of a key column: ``task`` -> ``Task``, ``ar`` -> ``Action repeat``."""
    return KEY_NAMES.get(key, key.replace("_", " ").capitalize() if key.islower() else key)


@dataclass
class Cell:
    """One cell of a comparison: its keys (e.g. task, method), the paper's value and the reproduced stats.

    ``budget``: the budget of the runs its stats come from (those that reached it; analysis.comparable.rows_budget),
    ``paper_budget`` the budget of the paper's value (None: a value without one, e.g. a timing); the cell is
    :attr:`comparable` by analysis.comparable's rule, and only then shows a Δ and a "Paper in CI".
    """

    keys: dict[str, Any]
    paper_mean: float | None
    paper_std: float | None
    stats: CellStats
    n_short: int = 0  # runs that stopped before the frame budget (not used in the stats)
    note: str = ""
    budget: Budget | None = None
    paper_budget: Budget | None = None
    short_at: str = ""  # where the runs counted in n_short stopped ('400 frames')

    @property
    def comparable(self) -> bool:
        """Whether its reproduced value may stand beside the paper's (analysis.comparable.comparable)."""
        return comparable(self.budget, self.paper_budget)


def comparison_frames(cells: Sequence[Cell], digits: int = 1) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of a comparison table; empty cells are kept and marked. A cell whose reproduced value
    is not comparable with the paper's (:attr:`Cell.comparable`) shows its value with its budget and "not
    comparable", and has no Δ and no "Paper in CI" (raw: NaN and None, ``comparable`` False)."""
    raw_rows, disp_rows = [], []
    for c in cells:
        s = c.stats
        paper = math.nan if c.paper_mean is None else float(c.paper_mean)
        shown = c.comparable
        diff = s.mean - paper if shown and not (math.isnan(paper) or math.isnan(s.mean)) else math.nan
        inside = s.contains(None if math.isnan(paper) else paper) if shown else None
        raw_rows.append(
            {
                **c.keys,
                "paper_mean": paper,
                "paper_std": math.nan if c.paper_std is None else float(c.paper_std),
                "n": s.n,
                "n_short": c.n_short,
                "repro_mean": s.mean,
                "repro_std": s.std,
                "ci_low": s.ci_low,
                "ci_high": s.ci_high,
                "diff": diff,
                "paper_in_ci": inside,
                "budget": math.nan if c.budget is None else c.budget.value,
                "budget_unit": None if c.budget is None else c.budget.unit,
                "paper_budget": None if c.paper_budget is None else c.paper_budget.short(),
                "comparable": shown if s.n and not math.isnan(paper) else None,
                "note": c.note,
            }
        )
        against = s.n > 0 and not math.isnan(paper)  # a reproduced value beside a paper value
        n_text = str(s.n) + (f" (+{c.n_short} short" + (f", at {c.short_at})" if c.short_at else ")")
                             if c.n_short else "")
        value = fmt_pm(s.mean, s.std, digits) if s.n else "no runs"
        if against and not shown:
            value += f" ({c.budget.short()}, not comparable)" if c.budget is not None else " (not comparable)"
        disp_rows.append(
            {
                **{key_name(k): v for k, v in c.keys.items()},
                "Paper": fmt_pm(c.paper_mean, c.paper_std, digits) if c.paper_mean is not None else "n/a",
                "Reproduced": value,
                "n": n_text,
                "95% CI": fmt_ci(s.ci_low, s.ci_high, digits),
                "Δ": fmt_num(diff, digits) if shown or not against else NOT_COMPARED,
                "Paper in CI": (fmt_bool(inside) if shown else NOT_COMPARED) if against else EMPTY,
            }
        )
    display = pd.DataFrame(disp_rows)
    if any(c.note for c in cells):
        display["Note"] = [c.note for c in cells]
    return pd.DataFrame(raw_rows), display.rename(columns=_budget_headers(cells))


NOT_COMPARED = "n/a"  # Δ and "Paper in CI" of a value that is not comparable with the paper's


def _budget_headers(cells: Sequence[Cell]) -> dict[str, str]:
    """The Paper and Reproduced headers with their budget, its unit and action repeat, where every cell shares one:
    'Paper (1M env. frames, action repeat 2)'."""
    out = {}
    papers = {c.paper_budget for c in cells if c.paper_mean is not None}
    if len(papers) == 1:
        paper = next(iter(papers))
        if paper is not None and not paper.at_least:
            out["Paper"] = f"Paper ({paper.header()})"
    ours = {c.budget.header() for c in cells if c.stats.n and c.budget is not None}
    if len(ours) == 1:
        out["Reproduced"] = f"Reproduced ({next(iter(ours))})"
    return out


def budget_notes(cells: Sequence[Cell]) -> list[str]:
    """The notes of a comparison table on its budgets: what their unit is (the action repeats beside the frames)
    and, where some reproduced values are not comparable with the paper's, which budgets stand beside which."""
    papers = [c.paper_budget for c in cells if c.paper_budget is not None]
    if not papers:
        return []
    paper = papers[0]
    repeats = [r for c in cells if c.stats.n and c.budget is not None for r in c.budget.repeats]
    notes = [units_note(paper, repeats)]
    apart = [c for c in cells if c.stats.n and c.paper_mean is not None and not c.comparable]
    if apart:
        notes.append(not_comparable_text(sorted({c.budget for c in apart if c.budget is not None},
                                                key=lambda b: (b.value, b.repeats)), paper))
    return notes
