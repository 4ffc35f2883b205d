"""`repro verify`'s figure: each method's curve (mean and seeds' range) over the published DrQ-v2 band, one panel a
task (PNG + PDF)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from analysis.calibration import SOURCE_TEXT, packaged_published, values_at  # noqa: E402
from analysis.identity import task_display  # noqa: E402
from analysis.io import save_figure_files  # noqa: E402
from analysis.load import Results  # noqa: E402
from analysis.verify import BAND_SD, VerdictRow, band, published_frames, verify_cells  # noqa: E402
from paper_figures.common import palette, placeholder, setup_style  # noqa: E402

PUBLISHED_COLOR = "#7f7f7f"


def caption() -> str:
    return (f"repro verify: each method's mean evaluation return over its seeds (line) and the seeds' range (shaded) "
            f"on the verify runs; grey: the DrQ-v2 authors' published seeds ({SOURCE_TEXT}): their mean (dashed), "
            f"their range (shaded) and the band the verdict uses (dotted: the range ± {BAND_SD:g} sd of those seeds "
            "at each published frame). Error bars are ranges over seeds, not confidence intervals.")


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


def plot_verify(results: Results, rows: Sequence[VerdictRow], out_dir: Path, name: str = "verify") -> list[Path]:
    """Write ``{name}.png`` and ``{name}.pdf``; returns both paths."""
    setup_style()
    runs = verify_cells(results)
    tasks = sorted(set(runs["task"])) if not runs.empty else []
    fig, axes = plt.subplots(1, max(len(tasks), 1), figsize=(6.0 * max(len(tasks), 1), 4.2), squeeze=False)
    published = packaged_published()
    if not tasks:
        placeholder(axes[0, 0], "no verify runs under the results root: run `repro verify`")
    verdicts = {(r.task, r.method, r.variant): r.verdict for r in rows}
    for ax, task in zip(axes[0], tasks):
        cell = runs[runs["task"] == task]
        upto = float(np.nanmax(cell["last_frame"].to_numpy(dtype=float))) if cell["last_frame"].notna().any() else 0
        pub_frames = [0, *published_frames(task, max(upto, 20_000))]
        pub = np.stack([values_at(published, f, task)["value"].to_numpy(dtype=float) for f in pub_frames], axis=1)
        bands = np.array([band(pub[:, j]) for j in range(len(pub_frames))])
        ax.fill_between(pub_frames, pub.min(0), pub.max(0), color=PUBLISHED_COLOR, alpha=0.18, lw=0)
        ax.plot(pub_frames, pub.mean(0), color=PUBLISHED_COLOR, ls="--", lw=1.6,
                label=f"DrQ-v2 published (n={pub.shape[0]})")
        judged = pub_frames[1:]  # the verdict reads the frames after 0
        ax.plot(judged, bands[1:, 0], color=PUBLISHED_COLOR, ls=":", lw=1.0)
        ax.plot(judged, bands[1:, 1], color=PUBLISHED_COLOR, ls=":", lw=1.0, label="verdict band")
        groups = list(cell.groupby(["method", "variant"], sort=True))
        colors = palette([str(m) for (m, _), _ in groups])
        for (method, variant), group in groups:
            ev = results.eval[results.eval["run_id"].isin(group["run_id"])]
            frames = sorted(float(f) for f in ev["frame"].dropna().unique())
            vals = _curves(results, list(group["run_id"]), frames)
            color = colors[str(method)]
            label = f"{method}{'' if variant == 'base' else f' ({variant})'} (n={len(group)}): " \
                    f"{verdicts.get((task, method, variant), '')}"
            with np.errstate(all="ignore"):
                ax.plot(frames, np.nanmean(vals, 0), color=color, lw=2.0, label=label)
                ax.fill_between(frames, np.nanmin(vals, 0), np.nanmax(vals, 0), color=color, alpha=0.2, lw=0)
        ax.set_title(task_display(task))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}K" if x else "0"))
        ax.set_xlabel("frames")
        ax.set_ylabel("evaluation return")
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    paths = save_figure_files(fig, [out_dir / f"{name}.{ext}" for ext in ("png", "pdf")], bbox_inches="tight")
    plt.close(fig)
    return paths
