"""F13 (fig:task_vis_metaworld, sfig:manipulator_vis): image strips of trajectories per task.

Frame sources, in order: frames a run saved (``frames/*.png`` or ``frames.npz`` with a ``frames``
array of shape (T, H, W, 3) in the run directory; a trained agent's trajectory), else frames rendered
now with ``repro.envs.make_env`` and uniformly random actions (labelled as such, not an expert), else a
placeholder naming the runs that are needed.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from analysis.cache import current
from analysis.context import Context
from analysis.identity import task_display
from analysis.paper import METAWORLD6
from paper_figures.common import banner, save_figure
from paper_figures.registry import ArtifactResult, register

TASKS = [*METAWORLD6, "manipulator_bring_ball"]
N_FRAMES = 6
RANDOM_STEPS = 20  # random-action frames are a fallback: keep the software rendering short


def saved_frames(run_dir: Path) -> np.ndarray | None:
    """Frames a run saved, as uint8 (T, H, W, 3), or None."""
    npz = run_dir / "frames.npz"
    if npz.exists():
        with np.load(npz) as data:
            if "frames" in data:
                return np.asarray(data["frames"], dtype=np.uint8)
    pngs = sorted((run_dir / "frames").glob("*.png"))
    if pngs:
        return np.stack([(plt.imread(p)[..., :3] * 255).astype(np.uint8) for p in pngs])
    return None


def random_action_frames(tasks: list[str], timeout: float = 600.0) -> tuple[dict[str, np.ndarray], str]:
    """Random-action frames per task from one subprocess (:mod:`analysis.rollout`), so a simulator or
    OpenGL crash cannot take the caller down. Returns the tasks rendered and the error line, if any."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
           "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")}
    frames: dict[str, np.ndarray] = {}
    error = ""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "analysis.rollout", tmp, str(RANDOM_STEPS), *tasks]
        try:
            proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout,
                                  cwd=Path(__file__).resolve().parents[1])
            if proc.returncode != 0:
                error = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        except subprocess.TimeoutExpired:
            error = f"rendering timed out after {timeout:g}s"
        for task in tasks:
            path = Path(tmp) / f"{task}.npz"
            if path.exists():
                with np.load(path) as data:
                    frames[task] = np.asarray(data["frames"], dtype=np.uint8)
    return frames, error


def trained_frames(ctx: Context, task: str) -> tuple[np.ndarray | None, str]:
    """Frames saved by a TACO run of ``task`` (done runs first)."""
    runs = ctx.results.runs
    if not runs.empty:
        cand = runs[(runs["task"] == task) & (runs["agent"] == "taco")].sort_values("status")
        for run_id in cand["run_id"]:
            frames = saved_frames(ctx.results.root / run_id)
            if frames is not None and len(frames):
                return frames, f"trained TACO agent, run {run_id}"
    return None, ""


def all_frames(ctx: Context) -> dict[str, tuple[np.ndarray | None, str]]:
    """Per task: (frames or None, where they come from / why there are none)."""
    out = {task: trained_frames(ctx, task) for task in TASKS}
    missing = [t for t, (f, _) in out.items() if f is None]
    if missing and ctx.render_envs:
        # random-action frames depend on no run: the report's cache keeps them (analysis/cache.py), and the tasks
        # it lacks render in one subprocess together
        cache = current()
        rendered = {t: f for t in missing if (f := cache.peek("frames", (t, RANDOM_STEPS))) is not None}
        error = ""
        if len(rendered) < len(missing):
            new, error = random_action_frames([t for t in missing if t not in rendered])
            for task, frames in new.items():
                cache.put("frames", (task, RANDOM_STEPS), frames)
            rendered.update(new)
        for task in missing:
            if task in rendered:
                out[task] = (rendered[task], "random actions (no trained agent's frames found)")
            else:
                out[task] = (None, f"could not render random-action frames ({error[:90] or 'unknown error'})")
    elif missing:
        for task in missing:
            out[task] = (None, "no frames (no trained run saved any; environment rendering disabled)")
    return out


@register("F13", "Trajectory frames (Meta-world, manipulator)", "figure", "fig:task_vis_metaworld")
def render(ctx: Context) -> ArtifactResult:
    fig, axes = plt.subplots(len(TASKS), N_FRAMES, figsize=(1.6 * N_FRAMES, 1.75 * len(TASKS)), squeeze=False)
    sources, any_trained, any_frames = [], False, False
    found = all_frames(ctx)
    for row, task in zip(axes, TASKS):
        frames, source = found[task]
        any_trained |= source.startswith("trained")
        any_frames |= frames is not None
        sources.append(f"{task}: {source}")
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
        if frames is None:
            for ax in row:
                ax.axis("off")
            row[0].text(0.0, 0.5, f"{task_display(task)}: {source}", transform=row[0].transAxes, fontsize=8,
                        va="center", clip_on=False, bbox={"facecolor": "#eeeeee", "edgecolor": "none"})
            continue
        idx = np.linspace(0, len(frames) - 1, N_FRAMES).round().astype(int)
        for ax, i in zip(row, idx):
            ax.imshow(frames[i])
        row[0].set_ylabel(task_display(task), fontsize=8, rotation=0, ha="right", va="center")
        row[-1].text(1.05, 0.5, "trained" if source.startswith("trained") else "random", fontsize=7,
                     transform=row[-1].transAxes, va="center")
    fig.subplots_adjust(left=0.15, right=0.92, top=0.97, bottom=0.02, wspace=0.05, hspace=0.1)
    if not any_frames:
        banner(fig, "no frames: no run saved any and no environment could be rendered (placeholders only)")
    elif not any_trained:
        banner(
            fig, "no trained agent's frames: rows show random-action rollouts or placeholders, not expert trajectories"
        )
    png = save_figure(fig, ctx, "F13")
    caption = (
        "Frames along one trajectory per task, left to right. The paper shows expert (trained-agent) "
        "trajectories; a row labelled 'random' shows uniformly random actions from make_env(task, seed=0) "
        "because no run saved frames (frames.npz or frames/*.png in a TACO run directory of the task). "
        "Sources: " + "; ".join(sources) + "."
    )
    return ArtifactResult(
        "F13",
        "Trajectory frames",
        caption,
        figures=[png],
        has_runs=any_trained,
        notes=[] if any_trained else ["Needs trained TACO runs that save frames for: " + ", ".join(TASKS)],
    )
