"""`repro verify`'s figure: each method's curve (mean and seeds' range) over the published DrQ-v2 band, one panel a
task (PNG + PDF)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from analysis.calibration import SOURCE_TEXT, packaged_published, values_at  # noqa: E402
from analysis.identity import task_display  # noqa: E402
from analysis.io import save_figure_files  # noqa: E402
from analysis.load import Results  # noqa: E402
from analysis.verify import BAND_SD, Judgement, VerdictRow, band, published_frames  # noqa: E402
from paper_figures.common import palette, placeholder, setup_style  # noqa: E402

PUBLISHED_COLOR = "#7f7f7f"


def caption() -> str:
    return (f"repro verify: each method's mean evaluation return over its seeds (line) and the seeds' range (shaded) "
            f"on the verify runs; grey: the DrQ-v2 authors' published seeds ({SOURCE_TEXT}): their mean (dashed), "
            f"their range (shaded) and, at each published frame the runs reach, the band the verdict uses (the range "
            f"± {BAND_SD:g} sd of those seeds; a dotted line joins the bands). The published curves are drawn up to "
            "the runs' last frame (interpolated between their evaluations); a panel's title names any setting of the "
            "runs that differs from the published curves'. Error bars are ranges over seeds, not confidence "
            "intervals.")


def _curves(results: Results, run_ids: Sequence[str], frames: Sequence[float]) -> np.ndarray:
    """(seeds, frames) returns of the runs ``run_ids`` at ``frames`` (NaN where a run does not reach a frame)."""
    ev = results.eval[results.eval["run_id"].isin(list(run_ids))]
    sub = Results(results.root, results.runs[results.runs["run_id"].isin(list(run_ids))], ev)
    out = np.full((len(run_ids), len(frames)), np.nan)
    index = {rid: i for i, rid in enumerate(run_ids)}
    for j, f in enumerate(frames):
        at = values_at(sub, f)
        for rid, value in zip(at["run_id"], at["value"]):
            out[index[rid], j] = value
    return out


def _frames_label(x: float, _pos: object = None) -> str:
    return f"{x / 1000:g}K" if abs(x) >= 1000 else f"{x:g}"


def _published(task: str, upto: float) -> tuple[list[float], np.ndarray]:
    """The published frames up to ``upto`` (0, every published evaluation, and ``upto`` itself interpolated between
    two evaluations when it is none) and the seeds' returns there: (frames, (seeds, frames))."""
    published = packaged_published()
    frames: list[float] = [0.0, *(float(f) for f in published_frames(task, upto))]
    cols = [values_at(published, f, task)["value"].to_numpy(dtype=float) for f in frames]
    if upto > frames[-1]:
        end = values_at(published, upto, task)["value"].to_numpy(dtype=float)
        if len(end) == len(cols[0]):  # within the published curves (they are never extrapolated)
            frames.append(float(upto))
            cols.append(end)
    return frames, np.stack(cols, axis=1)


def draw_panel(ax: plt.Axes, results: Results, cell: pd.DataFrame, task: str, rows: Sequence[VerdictRow]) -> None:
    """One task's panel: the published seeds and the verdict band up to the runs' last frame, each method's curve;
    the x axis ends at the runs' last frame, the legend lists only what is drawn, the title names a setting of the
    runs that differs from the published curves'."""
    last = pd.to_numeric(cell["last_frame"], errors="coerce")
    upto = float(last.max()) if last.notna().any() else 0.0
    pub_frames, pub = _published(task, upto)
    ax.fill_between(pub_frames, pub.min(0), pub.max(0), color=PUBLISHED_COLOR, alpha=0.18, lw=0,
                    label="DrQ-v2 published: seeds' range")
    ax.plot(pub_frames, pub.mean(0), color=PUBLISHED_COLOR, ls="--", lw=1.6, marker="o" if len(pub_frames) < 3
            else None, ms=3, label=f"DrQ-v2 published: mean (n={pub.shape[0]})")
    judged = published_frames(task, upto)  # the verdict reads the published frames after 0
    if judged:
        bands = np.array([band(pub[:, pub_frames.index(float(f))]) for f in judged])
        mid = bands.mean(axis=1)
        ax.errorbar(judged, mid, yerr=[mid - bands[:, 0], bands[:, 1] - mid], fmt="none", ecolor=PUBLISHED_COLOR,
                    elinewidth=1.2, capsize=5, label=f"verdict band (range ± {BAND_SD:g} sd)")
        if len(judged) > 1:
            ax.plot(judged, bands[:, 0], color=PUBLISHED_COLOR, ls=":", lw=1.0)
            ax.plot(judged, bands[:, 1], color=PUBLISHED_COLOR, ls=":", lw=1.0)
    verdicts = {(r.method, r.variant): r.verdict for r in rows if r.task == task}
    groups = list(cell.groupby(["method", "variant"], sort=True))
    colors = palette([str(m) for (m, _), _ in groups])
    for (method, variant), group in groups:
        ev = results.eval[results.eval["run_id"].isin(group["run_id"])]
        frames = sorted(float(f) for f in ev["frame"].dropna().unique())
        vals = _curves(results, list(group["run_id"]), frames)
        color = colors[str(method)]
        label = f"{method}{'' if variant == 'base' else f' ({variant})'} (n={len(group)}): " \
                f"{verdicts.get((str(method), str(variant)), '')}"
        with np.errstate(all="ignore"):
            ax.plot(frames, np.nanmean(vals, 0), color=color, lw=2.0, marker="o" if len(frames) < 3 else None, ms=4,
                    label=label)
            ax.fill_between(frames, np.nanmin(vals, 0), np.nanmax(vals, 0), color=color, alpha=0.2, lw=0)
    envs = sorted({r.environment for r in rows if r.task == task and r.environment})
    title = task_display(task) + "".join(f"\nruns: {e}" for e in envs) + ("\nnot comparable with the published "
                                                                            "curves" if envs else "")
    ax.set_title(title, fontsize=10 if envs else None)
    pad = 0.02 * upto
    ax.set_xlim(-pad, upto + pad if upto > 0 else 1.0)
    ax.xaxis.set_major_formatter(FuncFormatter(_frames_label))
    repeats = sorted({int(a) for a in pd.to_numeric(cell.get("action_repeat"), errors="coerce").dropna()}) \
        if "action_repeat" in cell else []
    ax.set_xlabel("environment frames (agent steps x action repeat"
                  + (f" {', '.join(map(str, repeats))}" if repeats else "") + ")")
    ax.set_ylabel("evaluation return")
    ax.legend(fontsize=7.5, loc="best")


def plot_verify(results: Results, judged: Judgement, out_dir: Path, name: str = "verify") -> list[Path]:
    """Write ``{name}.png`` and ``{name}.pdf`` of the runs ``judged`` holds (their curves read from ``results``),
    labelled with its verdicts; returns both paths."""
    setup_style()
    runs, rows = judged.cells, judged.rows
    tasks = sorted(set(runs["task"])) if not runs.empty else []
    fig, axes = plt.subplots(1, max(len(tasks), 1), figsize=(6.0 * max(len(tasks), 1), 4.2), squeeze=False)
    if not tasks:
        placeholder(axes[0, 0], "no verify runs under the results root: run `repro verify`")
    for ax, task in zip(axes[0], tasks):
        draw_panel(ax, results, runs[runs["task"] == task], task, rows)
    fig.tight_layout()
    paths = save_figure_files(fig, [out_dir / f"{name}.{ext}" for ext in ("png", "pdf")], bbox_inches="tight")
    plt.close(fig)
    return paths
