"""The paper's LaTeX tables read from its source (``repro_data/paper/taco_paper.tex``): Tables 1 and 2 (a row per
task), Table 3 with its printed average row, the one-row Tables 4 and 5 and Table 6 (CQL's alpha). Used by the audit
(analysis/audit.py) to check the CSV transcription and the tables' marks against the source.

Table 2's columns are its CSV's methods in their order (``PaperData.repr_methods``); :func:`header` reads the
LaTeX table's own header so that the audit checks the two agree."""

from __future__ import annotations

import re
from collections.abc import Sequence

import pandas as pd

from analysis.paper import DMC9
from repro.config.schema import normalize_dataset

T1_COLUMNS = ["TACO", "DrQ-v2", "A-LIX", "DrQ", "CURL", "DreamerV3", "TD-MPC"]
T3_COLUMNS = ["TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL", "DT", "IQL", "BC"]
_PM = re.compile(r"(-?\d+(?:\.\d+)?)\s*\\pm\s*(-?\d+(?:\.\d+)?)")
_NUM = re.compile(r"-?\d+(?:\.\d+)?")


def _tabular(tex: str, label: str) -> str:
    """The tabular body of the table environment holding ``\\label{label}``."""
    pos = tex.index(f"\\label{{{label}}}")
    start = tex.rfind("\\begin{table}", 0, pos)
    body_start = tex.index("\\begin{tabular}", start)
    return tex[body_start: tex.index("\\end{tabular}", body_start)]


def _rows(body: str) -> list[list[str]]:
    rows = []
    for raw in body.split("\\\\"):
        lines = [ln for ln in raw.splitlines() if not ln.strip().startswith("%")]
        text = " ".join(lines)
        text = re.sub(r"\\(toprule|midrule|bottomrule)", "", text).strip()
        if "&" not in text:
            continue
        rows.append([c.strip() for c in text.split("&")])
    return rows


def _cell(text: str) -> tuple[float | None, float | None, bool]:
    """(mean, std, bold) of a LaTeX cell like ``$\\mathbf{{541\\pm 38}}$``; (None, None, False) for N/A."""
    bold = "\\mathbf" in text or "\\textbf" in text
    m = _PM.search(text)
    if m:
        return float(m.group(1)), float(m.group(2)), bold
    if "N/A" in text:
        return None, None, bold
    nums = _NUM.findall(re.sub(r"\\[a-zA-Z]+\{?\*?\}?|\{\d\}", " ", text))
    return (float(nums[-1]) if nums else None), None, bold


def _task_key(text: str) -> str:
    name = re.sub(r"\\multirow\{\d+\}\{\*\}\{([^}]*)\}", r"\1", text)
    name = re.sub(r"[${}]|\\textbf|\\mathbf", "", name).strip()
    return name.lower().replace(" ", "_")


def header(tex: str, label: str) -> list[str]:
    """The column names of a task-per-row LaTeX table (the row above its first task), the task column's left out,
    each as printed without its formatting and with the paper's own macros expanded: "\\textbf{\\ours}" -> "TACO"."""
    macros = dict(re.findall(r"\\newcommand\{(\\[a-zA-Z]+)\}\{(.*)\}", tex))
    rows = _rows(_tabular(tex, label))
    first = next(i for i, cells in enumerate(rows) if _task_key(cells[0]) in DMC9)
    names = []
    for cell in rows[first - 1][1:]:
        for macro, body in macros.items():
            cell = re.sub(re.escape(macro) + r"(?![a-zA-Z])", body.replace("\\", "\\\\"), cell)
        names.append(re.sub(r"\\[a-zA-Z]+|[{}]", "", cell).strip())
    return names


def parse_row_table(tex: str, label: str, columns: Sequence[str]) -> pd.DataFrame:
    """A task-per-row LaTeX table (Tables 1 and 2) as rows: task, method, mean, std, bold; ``columns`` names its
    method columns in their order."""
    out = []
    for cells in _rows(_tabular(tex, label)):
        task = _task_key(cells[0])
        if task not in DMC9 or len(cells) != len(columns) + 1:
            continue
        for method, text in zip(columns, cells[1:]):
            mean, std, bold = _cell(text)
            out.append({"task": task, "method": method, "mean": mean, "std": std, "bold": bold})
    return pd.DataFrame(out)


def parse_offline_table(tex: str) -> tuple[pd.DataFrame, dict[str, float | None]]:
    """Table 3 as rows (task, dataset, method, mean, std, bold) and its printed average row."""
    out, average, task = [], {}, None
    for cells in _rows(_tabular(tex, "tab:offline_table")):
        if "Average" in cells[0]:
            average = {m: _cell(c)[0] for m, c in zip(T3_COLUMNS, cells[1:])}
            continue
        if len(cells) != len(T3_COLUMNS) + 2 or not cells[1] or "Dataset" in cells[0]:
            continue
        task = _task_key(cells[0]) or task
        dataset = normalize_dataset(cells[1])
        for method, text in zip(T3_COLUMNS, cells[2:]):
            mean, std, bold = _cell(text)
            out.append({"task": task, "dataset": dataset, "method": method, "mean": mean, "std": std, "bold": bold})
    return pd.DataFrame(out), average


def parse_single_row(tex: str, label: str) -> list[float]:
    """The numbers of a one-row table (Tables 4 and 5)."""
    rows = _rows(_tabular(tex, label))
    return [float(_NUM.findall(c)[0]) for c in rows[-1]]


def parse_cql_table(tex: str) -> pd.DataFrame:
    out, task = [], None
    for cells in _rows(_tabular(tex, "tab:cql_hyper")):
        if len(cells) != 3 or "Dataset" in cells[0] or "alpha" in cells[2]:
            continue
        task = _task_key(cells[0]) or task
        out.append({"task": task, "dataset": normalize_dataset(cells[1]), "alpha": _cell(cells[2])[0]})
    return pd.DataFrame(out)
