"""Baseline calibration: the user's DrQ-v2 runs held against the DrQ-v2 authors' published learning curves.

The published curves (``repro_data/reference/drqv2_curves``, loaded by :func:`analysis.load.load_published`
into a Results of their own, ``source`` = ``published``) are never mixed with the user's runs. This is about the
baseline, not about a claim of the paper: it may be read at any budget.

* **Budget of a cell** (one task, experiment and variant of the user's DrQ-v2 runs): the runs' own budget, the
  last frame every run of the cell reached (their lowest last evaluation frame), capped at the end of the
  published curve. Each run and each published seed is read there by linear interpolation between its own
  evaluations (the published ones every 20K frames, 100K on humanoid); nothing is extrapolated.
* **Mean and 95% CI** of each side: mean over seeds; CI by rliable's stratified bootstrap of the mean
  (:func:`analysis.stats.mean_cis`).
* **Reading** (:func:`reading`): the 95% percentile bootstrap CI of the difference of means, user minus
  published, each side resampled over its own seeds (:func:`analysis.stats.difference_of_means`, fixed random
  state): "below" if the CI lies below 0, "above" if above 0, else "consistent". Fewer than
  :data:`MIN_SEEDS` seeds on either side: no reading ("not enough seeds"), and the row says which side.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.cache import lookup
from analysis.claim_budget import frames_text
from analysis.comparable import env_differences
from analysis.load import PUBLISHED_ACTION_REPEAT, SOURCE_PUBLISHED, SOURCE_RUNS, Results, load_published
from analysis.stats import DEFAULT_REPS, DEFAULT_SEED, difference_of_means, mean_cis
from analysis.tables import TableOutput, fmt_ci, fmt_num, write_table

MIN_SEEDS = 3
BELOW, CONSISTENT, ABOVE, NOT_ENOUGH, NO_CURVE = "below", "consistent", "above", "not enough seeds", \
    "no published curve"
OTHER_ENV = "not comparable"  # runs whose episodes or camera differ from the published setting (analysis.comparable)
SOURCE_TEXT = ("the DrQ-v2 authors' published learning curves (facebookresearch/drqv2, curves/, commit c0c650b, MIT; "
               "packaged in repro_data/reference/drqv2_curves)")
INTERP_TEXT = ("published values between their evaluations (every 20K frames, 100K on humanoid) are linearly "
               "interpolated per seed, never extrapolated")
ABOUT_TEXT = ("This is a calibration of the baseline, not a claim of the paper: it holds at any budget, long "
              "before a claim's own budget.")


@functools.cache
def packaged_published() -> Results:
    """The packaged published curves, loaded once per process (callers must not modify the tables), and kept in
    the command's cache (analysis/cache.py: they change only with the code version, which covers repro_data)."""
    return lookup("published", "packaged", load_published, process=False)


def values_at(results: Results, frame: float, task: str | None = None) -> pd.DataFrame:
    """Each run's ``episode_reward`` at ``frame`` by linear interpolation between its own evaluations: columns
    run_id, task, seed, value. A run whose evaluations do not span ``frame`` is left out (no extrapolation)."""
    curves = _packaged_curves(task) if results is packaged_published() else _run_curves(results, task)
    return _interpolate(curves, frame)


_Curve = tuple[object, object, object, np.ndarray, np.ndarray]  # run_id, task, seed, frames, values


@functools.cache
def _packaged_curves(task: str | None) -> list[_Curve]:
    """:func:`_run_curves` of the packaged published curves, once per task and process (they do not change)."""
    return _run_curves(packaged_published(), task)


def _run_curves(results: Results, task: str | None) -> list[_Curve]:
    """Each run's evaluations with a value (of ``task``, if given), sorted by frame, in the runs' order."""
    ev = results.eval
    if ev.empty:
        return []
    ev = ev[ev["frame"].notna()]
    if task is not None:
        ev = ev[ev["task"] == task]
    out = []
    for run_id, rows in ev.groupby("run_id", sort=False):
        rows = rows.sort_values("frame")
        vals = pd.to_numeric(rows["episode_reward"], errors="coerce").to_numpy(dtype=float)
        frames = rows["frame"].to_numpy(dtype=float)
        ok = ~np.isnan(vals)
        out.append((run_id, rows["task"].iloc[0], rows["seed"].iloc[0], frames[ok], vals[ok]))
    return out


def _interpolate(curves: Sequence[_Curve], frame: float) -> pd.DataFrame:
    out = [{"run_id": run_id, "task": task, "seed": seed, "value": float(np.interp(frame, frames, vals))}
           for run_id, task, seed, frames, vals in curves if len(frames) and frames[0] <= frame <= frames[-1]]
    return pd.DataFrame(out, columns=["run_id", "task", "seed", "value"])


def published_end(published: Results, task: str) -> float | None:
    """The last frame every published seed of ``task`` reaches, or None if the task has no published curve."""
    runs = published.runs
    rows = runs[runs["task"] == task] if not runs.empty else runs
    return None if rows.empty else float(rows["last_frame"].min())


def published_values(published: Results, task: str, frame: float) -> np.ndarray:
    """The published seeds' values of ``task`` at ``frame`` (interpolated; empty past the curve's end)."""
    return values_at(published, frame, task)["value"].to_numpy(dtype=float)


def reading(user: np.ndarray, pub: np.ndarray, reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED,
            min_seeds: int = MIN_SEEDS) -> tuple[str, float, float, float, str]:
    """(reading, difference of means, its 95% CI low, high, why no reading) of user vs published values."""
    diff = float(np.mean(user) - np.mean(pub)) if len(user) and len(pub) else math.nan
    short = [f"{name} has {len(v)} seed{'s' if len(v) != 1 else ''}" for name, v in (("user", user),
                                                                                        ("published", pub))
             if len(v) < min_seeds]
    if short:
        return NOT_ENOUGH, diff, math.nan, math.nan, f"{' and '.join(short)}; a reading needs >= {min_seeds} each"
    d, lo, hi = difference_of_means(user, pub, reps, seed)
    return (BELOW if hi < 0 else ABOVE if lo > 0 else CONSISTENT), d, lo, hi, ""


@dataclass
class CalibrationRow:
    """One cell: the user's DrQ-v2 runs of one task/experiment/variant against the published curve."""

    task: str
    experiment: str
    variant: str
    frame: float
    user_n: int
    user_mean: float
    user_ci_low: float
    user_ci_high: float
    published_n: int
    published_mean: float
    published_ci_low: float
    published_ci_high: float
    diff: float
    diff_ci_low: float
    diff_ci_high: float
    reading: str
    note: str = ""


def user_drqv2_runs(results: Results) -> tuple[pd.DataFrame, int]:
    """(the user's online DrQ-v2 runs in the published setting — action repeat 2, no distracting action dims —,
    the number of other DrQ-v2 runs left out)."""
    runs = results.runs
    if runs.empty:
        return runs, 0
    if "source" in runs.columns and (runs["source"] != SOURCE_RUNS).any():
        raise ValueError("calibration reads the user's runs only; published curves are passed separately")
    drq = runs[(runs["method"] == "DrQ-v2") & runs["dataset"].isna()]
    ar = pd.to_numeric(drq["action_repeat"], errors="coerce")
    same = (ar.isna() | (ar == 2)) & (pd.to_numeric(drq["distracting_dims"], errors="coerce").fillna(0) == 0)
    return drq[same], int((~same).sum())


def calibrate(results: Results, published: Results | None = None, reps: int = DEFAULT_REPS,
              seed: int = DEFAULT_SEED, min_seeds: int = MIN_SEEDS,
              at: float | None = None) -> tuple[list[CalibrationRow], list[str]]:
    """One :class:`CalibrationRow` per task, experiment and variant of the user's DrQ-v2 runs, and notes.

    ``at``: read every cell at this frame instead of its own budget (a cell whose runs do not all reach it is
    read at its own budget, and its note says so)."""
    published = packaged_published() if published is None else published
    if not published.runs.empty and (published.runs["source"] != SOURCE_PUBLISHED).any():
        raise ValueError("the published curves must come from analysis.load.load_published")
    drq, left_out = user_drqv2_runs(results)
    notes = []
    if left_out:
        notes.append(f"{left_out} DrQ-v2 run(s) with an action repeat other than 2 or distracting action dims left "
                     "out (the published curves use action repeat 2 and no extra dims).")
    rows: list[CalibrationRow] = []
    if drq.empty:
        return rows, notes
    user_eval = results.eval[results.eval["run_id"].isin(drq["run_id"])]
    for (task, experiment, variant), cell in drq.groupby(["task", "experiment", "variant"], sort=True):
        last = pd.to_numeric(cell["last_frame"], errors="coerce").dropna()
        end = published_end(published, task)
        base = dict(task=task, experiment=experiment, variant=variant)
        if last.empty:
            notes.append(f"{task} ({experiment}/{variant}): no evaluations yet")
            continue
        frame = float(last.min())
        note = ""
        if at is not None and at <= frame:
            frame = float(at)
        elif at is not None:
            note = f"asked for {frames_text(at)}; runs reach {frames_text(frame)}, read there"
        if end is None:
            rows.append(_row(base, frame, np.array([]), np.array([]), NO_CURVE, math.nan, math.nan, math.nan,
                             "the published curves have no such task", reps, seed))
            continue
        if frame > end:
            note = f"{note}; " if note else ""
            note += f"runs reach {frames_text(frame)}; the published curve ends at {frames_text(end)}, read there"
            frame = end
        cell_eval = user_eval[user_eval["run_id"].isin(cell["run_id"])]
        user_vals = values_at(Results(results.root, cell, cell_eval), frame)["value"].to_numpy(dtype=float)
        pub_vals = published_values(published, task, frame)
        verdict, d, lo, hi, why = reading(user_vals, pub_vals, reps, seed, min_seeds)
        other = env_differences(cell)  # action repeat and distracting dims are left out above: episodes, camera
        if other:  # returns of other episodes: shown, with no difference and no reading
            verdict, d, lo, hi = OTHER_ENV, math.nan, math.nan, math.nan
            why = f"environment differs from the published one: {other}"
        rows.append(_row(base, frame, user_vals, pub_vals, verdict, d, lo, hi, "; ".join(x for x in (note, why) if x),
                         reps, seed))
    return rows, notes


def _row(base: dict, frame: float, user: np.ndarray, pub: np.ndarray, verdict: str, d: float, lo: float, hi: float,
         note: str, reps: int, seed: int) -> CalibrationRow:
    (ul, uh), (pl, ph) = mean_cis([user, pub], reps=reps, seed=seed)
    return CalibrationRow(**base, frame=frame, user_n=len(user),
                          user_mean=float(np.mean(user)) if len(user) else math.nan, user_ci_low=ul, user_ci_high=uh,
                          published_n=len(pub), published_mean=float(np.mean(pub)) if len(pub) else math.nan,
                          published_ci_low=pl, published_ci_high=ph, diff=d, diff_ci_low=lo, diff_ci_high=hi,
                          reading=verdict, note=note)


def _mean_ci(n: int, mean: float, lo: float, hi: float) -> str:
    if n == 0:
        return "no values"
    ci = fmt_ci(lo, hi)
    return f"{fmt_num(mean)} {ci}" if ci != "—" else fmt_num(mean)


def calibration_frames(rows: Sequence[CalibrationRow]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of the calibration table."""
    raw = pd.DataFrame([r.__dict__ for r in rows], columns=list(CalibrationRow.__dataclass_fields__))
    display = pd.DataFrame({
        "Task": [r.task for r in rows],
        "Runs": [f"{r.experiment}/{r.variant}" for r in rows],
        f"Env. frames (action repeat {PUBLISHED_ACTION_REPEAT})": [frames_text(r.frame) for r in rows],
        "Your DrQ-v2 (n)": [f"{_mean_ci(r.user_n, r.user_mean, r.user_ci_low, r.user_ci_high)} (n={r.user_n})"
                            for r in rows],
        "Published DrQ-v2 (n)": [f"{_mean_ci(r.published_n, r.published_mean, r.published_ci_low, r.published_ci_high)}"
                                 f" (n={r.published_n})" for r in rows],
        "Δ [95% CI]": ["n/a" if r.reading == OTHER_ENV else
                       f"{fmt_num(r.diff)} {fmt_ci(r.diff_ci_low, r.diff_ci_high)}".strip() for r in rows],
        "Reading": [r.reading for r in rows],
        "Note": [r.note for r in rows],
    })
    return raw, display


def calibration_notes(reps: int, seed: int, extra: Sequence[str] = ()) -> list[str]:
    """The notes under the calibration table: source, budget, interpolation, statistics, test."""
    return [
        ABOUT_TEXT,
        f"Published: {SOURCE_TEXT}. Frames: each cell's own budget, the last frame all its runs reach (capped at the "
        f"published curve's end); {INTERP_TEXT}.",
        f"Mean [95% CI] over seeds; CI: stratified bootstrap of the mean (rliable, {reps:,} repetitions, random state "
        f"{seed}). Δ = yours − published, with the 95% percentile bootstrap CI of the difference of means (each side "
        f"resampled over its own seeds, rliable, random state {seed}). Reading: 'below' if that CI lies below 0, "
        f"'above' if above 0, else 'consistent'; no reading with fewer than {MIN_SEEDS} seeds on either side, and "
        f"'{OTHER_ENV}' (no Δ) for runs whose episodes or camera differ from the published setting.",
        *extra,
    ]


def write_calibration(out_dir: Path, rows: Sequence[CalibrationRow], notes: Sequence[str] = (),
                      reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED) -> TableOutput:
    """Write ``calibration.csv/.md/.tex``."""
    raw, display = calibration_frames(rows)
    counts = {k: sum(r.reading == k for r in rows) for k in (CONSISTENT, BELOW, ABOVE)}
    caption = ("Baseline calibration: your DrQ-v2 runs against the DrQ-v2 authors' published curves at your runs' "
               "own budget (" + (", ".join(f"{v} {k}" for k, v in counts.items()) if rows
                                 else "no DrQ-v2 runs") + ").")
    return write_table(out_dir, "calibration", raw, caption, display, calibration_notes(reps, seed, notes))


def published_band(published: Results, task: str, upto: float, reps: int, seed: int) -> pd.DataFrame:
    """The published mean and 95% CI (rliable stratified bootstrap of the mean over seeds) of ``task`` at each
    published evaluation frame <= ``upto``, plus ``upto`` itself (interpolated): columns frame, n, mean,
    ci_low, ci_high. Empty if the task has no published curve."""
    end = published_end(published, task)
    if end is None:
        return pd.DataFrame(columns=["frame", "n", "mean", "ci_low", "ci_high"])
    upto = min(float(upto), end)
    ev = published.eval[published.eval["task"] == task]
    frames = sorted({float(f) for f in ev["frame"] if f <= upto} | {upto})
    curves = _run_curves(published, task)  # once per task, not once per frame (459 frames on F4)
    cols = [_interpolate(curves, f)["value"].to_numpy(dtype=float) for f in frames]
    cis = mean_cis(cols, reps=reps, seed=seed)
    return pd.DataFrame({"frame": frames, "n": [len(c) for c in cols],
                         "mean": [float(np.mean(c)) if len(c) else math.nan for c in cols],
                         "ci_low": [c[0] for c in cis], "ci_high": [c[1] for c in cis]})


def band_caption(reps: int, seed: int) -> str:
    """What a published band on a figure is and where it comes from."""
    return (f"Grey dashed line and band: DrQ-v2 as published by its authors, not your runs (source: {SOURCE_TEXT}; "
            f"8-10 seeds per task): mean and 95% stratified-bootstrap CI of the mean over their seeds (rliable, "
            f"{reps:,} repetitions, random state {seed}) at their evaluations, up to the frames of your runs (1M "
            f"frames on an F4 panel without runs); {INTERP_TEXT}.")
