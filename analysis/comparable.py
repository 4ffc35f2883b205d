"""When a reproduced value may stand beside the paper's: the one rule every table and figure follows.

The paper gives its values at a budget: Table 1 and the figures drawn from it at 1M environment frames, Table 3 at
a number of gradient updates it does not state. A reproduced value is *comparable* with the paper's, and only then
gets a difference (Δ), a "Paper in CI" or a bar beside the paper's diamond without a mark, when it is computed at
the paper's budget, in the same unit, from runs that reached it (:func:`comparable`; a run reached a budget only by
evidence, an evaluation at or past it: :func:`reached`, which analysis.scores.final_scores' ``reached``, the claims,
the curves (F4) and `repro verify` all read). A value at another budget (``--frames 400``, a run of 20 updates) is
shown as what it is: its value, its budget and "not comparable".

Units: a frame budget counts **environment frames** (agent steps x action repeat; the paper and the DrQ-v2 authors'
curves use action repeat 2), an offline budget gradient updates. :class:`Budget` says both, the repeat beside the
frames.

A run whose environment differs from the paper's (episode length ``env.max_episode_frames``, action repeat, camera,
distracting action dimensions) is labelled with the difference wherever it is shown (:func:`env_differences`); the
paper's environment is the packaged config's ``env`` section (repro/conf/config.yaml), the paper's setting.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import pandas as pd
import yaml

from repro.config.compose import CONF_DIR

FRAMES, UPDATES = "frames", "updates"
DMC_EPISODE_FRAMES = 1000  # a DeepMind Control episode: 1000 environment frames (500 agent steps at repeat 2)
ENV_KEYS = ("action_repeat", "max_episode_frames", "camera", "distracting_dims", "image_size", "frame_stack")


@functools.cache
def _defaults() -> dict[str, Any]:
    """The packaged config's ``env`` and ``offline`` sections (the paper's setting and the project's defaults)."""
    data = yaml.safe_load((CONF_DIR / "config.yaml").read_text(encoding="utf-8"))
    return {"env": dict(data["env"]), "offline": dict(data["offline"])}


def paper_env() -> dict[str, Any]:
    """The paper's environment: the packaged config's env values of :data:`ENV_KEYS` (action repeat 2, the
    suite's own episodes, the task's camera, no distracting dims)."""
    env = _defaults()["env"]
    return {k: env[k] for k in ENV_KEYS}


def short_number(value: float) -> str:
    """400 -> '400'; 100000 -> '100K'; 1500000 -> '1.5M'."""
    if value >= 1e6:
        return f"{value / 1e6:g}M"
    if value >= 1e4:
        return f"{value / 1e3:g}K"
    return f"{value:,.0f}"


@dataclass(frozen=True)
class Budget:
    """A budget: ``value`` in ``unit`` (environment frames or gradient updates), the action repeats of the runs it
    is about (frames only), and ``at_least`` for the paper's offline budget, which the paper does not state: a run
    at or past it is compared."""

    value: float
    unit: str = FRAMES
    repeats: tuple[int, ...] = ()
    at_least: bool = False

    def short(self) -> str:
        """'1M frames', '400 frames', '20 updates', '≥ 100K updates'."""
        return ("≥ " if self.at_least else "") + f"{short_number(self.value)} {self.unit}"

    def header(self) -> str:
        """The budget in a column header: '1M env. frames, action repeat 2', '20 gradient updates'."""
        return self.text().replace(" (action repeat", ", action repeat").removesuffix(")") if self.repeats \
            else self.text()

    def text(self) -> str:
        """The budget with its unit in words: '1M env. frames (action repeat 2)', '20 gradient updates'."""
        if self.unit == UPDATES:
            return ("≥ " if self.at_least else "") + f"{short_number(self.value)} gradient updates"
        return f"{short_number(self.value)} env. frames{repeat_text(self.repeats)}"


def repeat_text(repeats: Iterable[Any]) -> str:
    """' (action repeat 2)', ' (action repeat 2, 4)', '' when unknown."""
    values = sorted({int(r) for r in repeats if r is not None and not pd.isna(r)})
    return f" (action repeat {', '.join(str(r) for r in values)})" if values else ""


def paper_frames() -> Budget:
    """The paper's budget of Table 1, Table 2 and the bar figures: 1M environment frames at its action repeat."""
    return Budget(1_000_000, FRAMES, (int(paper_env()["action_repeat"]),))


def paper_updates() -> Budget:
    """The paper's offline budget: it states no number of updates; a run is compared when it finished at least the
    project's default ``offline.updates`` (100K, docs/deviations.md)."""
    return Budget(float(_defaults()["offline"]["updates"]), UPDATES, at_least=True)


def reached(last: Any, budget: float) -> bool:
    """THE evidence that a run reached ``budget``: its last evaluation (online: the last evaluated environment frame;
    offline: the last evaluated gradient update) is at or past it. A run configured for more, or marked done, without
    an evaluation there did not reach it. ``last``: NaN or None when the run has no evaluation."""
    return last is not None and not pd.isna(last) and float(last) >= float(budget)


def comparable(at: Budget | None, paper: Budget | None) -> bool:
    """THE rule: may a reproduced value at budget ``at`` stand beside the paper's value at ``paper`` (with a Δ, a
    "Paper in CI", a bar beside its diamond)? Only at the paper's budget in the paper's unit (an offline run: at
    least it), from runs that reached it (``at`` is the budget of the runs that reached it; None: no such runs). A
    paper value without a budget (a timing) is compared as it is."""
    if paper is None:
        return True
    if at is None or at.unit != paper.unit or math.isnan(at.value):
        return False
    return at.value >= paper.value if paper.at_least else at.value == paper.value


def rows_budget(rows: pd.DataFrame) -> Budget | None:
    """The budget of ``rows`` (rows of analysis.scores.final_scores that reached it: column ``budget``, the frames
    asked for online, each run's offline.updates offline): the smallest; None without rows or the column."""
    if rows.empty or "budget" not in rows.columns:
        return None
    values = pd.to_numeric(rows["budget"], errors="coerce").dropna()
    if values.empty:
        return None
    offline = "dataset" in rows.columns and bool(rows["dataset"].notna().any())
    if offline:
        return Budget(float(values.min()), UPDATES)
    repeats = tuple(sorted({int(r) for r in rows.get("action_repeat", pd.Series(dtype=float)).dropna()}))
    return Budget(float(values.min()), FRAMES, repeats)


def stopped_text(rows: pd.DataFrame) -> str:
    """Where runs that did not reach a budget stopped: '400 frames', '200-400 frames', '10 updates' ('' unknown)."""
    if rows.empty:
        return ""
    offline = "dataset" in rows.columns and bool(rows["dataset"].notna().any())
    col, unit = ("last_update", UPDATES) if offline else ("last_frame", FRAMES)
    if col not in rows.columns:
        return ""
    last = pd.to_numeric(rows[col], errors="coerce").fillna(0.0)
    lo, hi = float(last.min()), float(last.max())
    return f"{short_number(lo)} {unit}" if lo == hi else f"{short_number(lo)}-{short_number(hi)} {unit}"


def not_comparable_text(ats: Sequence[Budget], paper: Budget) -> str:
    """The note under a table or figure with values at the budgets ``ats`` beside the paper's at ``paper``."""
    where = ", ".join(b.text() for b in ats) or "another budget"
    theirs = (f"an unstated number of updates (a run is compared from {short_number(paper.value)} updates on)"
              if paper.at_least else paper.text())
    return (f"Not comparable: reproduced values at {where}, the paper's at {theirs}; they are shown as what "
            "they are, with no Δ and no 'Paper in CI' (a value is compared only at the paper's budget, from runs "
            "that reached it).")


def units_note(paper: Budget | None, repeats: Iterable[Any] = ()) -> str:
    """What a budget's unit is, the repeats beside it: the paper's and those of ``repeats`` (the runs')."""
    if paper is not None and paper.unit == UPDATES:
        return (f"Budgets in gradient updates; the paper states none, so a run is compared with it when it finished "
                f"at least {short_number(paper.value)} updates (the default offline.updates, docs/deviations.md).")
    parts = []
    if paper is not None and paper.repeats:
        parts.append("the paper: " + repeat_text(paper.repeats).strip(" ()"))
    ours = repeat_text(repeats).strip(" ()")
    if ours:
        parts.append("these runs: " + ours)
    return ("Frames are environment frames = agent steps x action repeat"
            + (f" ({'; '.join(parts)})" if parts else "") + ".")


def frames_axis_label(repeats: Iterable[Any] = ()) -> str:
    """A frame axis: 'environment frames (action repeat 2)'."""
    return "environment frames" + repeat_text(repeats)


# ---------------------------------------------------------------- environments that differ from the paper's
def env_difference(row: Any, varied: Sequence[str] = (), against: str = "paper") -> list[str]:
    """How one run's environment differs from the paper's, in words (empty: as the paper's), leaving out the
    dimensions in ``varied`` (an artifact's own variable, e.g. F9's action repeat). ``row``: a mapping or a row of
    the runs / scores tables (columns action_repeat, max_episode_frames, camera, distracting_dims, image_size,
    frame_stack, suite, task; a missing one is taken as the paper's). ``against`` names the reference in the words
    ("paper", or "published" for the DrQ-v2 authors' curves, whose DMC settings are the paper's): the one rule of
    "another environment" for the tables, the figures and `repro verify`."""
    paper = paper_env()
    out = []

    def value(key: str) -> Any:
        v = row.get(key) if hasattr(row, "get") else None
        return None if v is None or (not isinstance(v, str) and pd.isna(v)) else v

    def differs(key: str) -> Any:
        v = value(key)
        return None if key in varied or v is None or paper[key] is None or int(v) == int(paper[key]) else int(v)

    episode = value("max_episode_frames")
    if "max_episode_frames" not in varied and episode is not None and episode != paper["max_episode_frames"]:
        if value("suite") in (None, "dmc"):
            if int(episode) < DMC_EPISODE_FRAMES:
                out.append(f"{int(episode):,}-frame episodes ({against}: {DMC_EPISODE_FRAMES:,})")
        else:
            out.append(f"episodes cut at {int(episode):,} frames ({against}: the suite's own)")
    if (repeat := differs("action_repeat")) is not None:
        out.append(f"action repeat {repeat} ({against}: {paper['action_repeat']})")
    camera, task = value("camera"), value("task")
    if "camera" not in varied and camera is not None and camera != paper["camera"]:
        own = _task_camera(str(task)) if task is not None else None
        if own is None or str(camera) != str(own):
            reference = "the task's own" if own is None else own
            out.append(f"camera {camera} ({against}: {reference})")
    if (dims := differs("distracting_dims")) is not None:
        out.append(f"{dims} distracting action dims ({against}: {paper['distracting_dims']})")
    if (size := differs("image_size")) is not None:
        out.append(f"{size}x{size} pixels ({against}: {paper['image_size']})")
    if (stack := differs("frame_stack")) is not None:
        out.append(f"{stack} stacked frames ({against}: {paper['frame_stack']})")
    return out


def _task_camera(task: str) -> Any:
    """The task's own camera (its upstream one), None for a task this installation does not know."""
    from repro.envs.registry import UnknownTaskError, get_task

    try:
        return get_task(task).camera
    except UnknownTaskError:
        return None


def env_differences(rows: pd.DataFrame, varied: Sequence[str] = ()) -> str:
    """Every difference from the paper's environment among ``rows`` (one per run), each once, '; '-joined, with
    the number of runs when only some differ: '100-frame episodes (paper: 1,000)'."""
    if rows is None or rows.empty:
        return ""
    counts: dict[str, int] = {}
    for row in rows.to_dict("records"):
        for text in env_difference(row, varied):
            counts[text] = counts.get(text, 0) + 1
    return "; ".join(text if n == len(rows) else f"{text} ({n} of {len(rows)} runs)" for text, n in counts.items())


def env_label(rows: pd.DataFrame, varied: Sequence[str] = ()) -> str:
    """``env_differences`` as a label: 'environment differs from the paper's: ...' ('' when it does not)."""
    text = env_differences(rows, varied)
    return f"environment differs from the paper's: {text}" if text else ""
