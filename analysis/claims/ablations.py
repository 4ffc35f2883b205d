"""The claims of the ablations and analyses: the action representation (section 5.1, F3), the t-SNE of latent
actions (F6), batch size and objective removal (F7), Table 2's other representation objectives, the horizon K (F8),
the action repeat (appendix B, F9), the latent action dimension (appendix E) and the timing of Tables 4-5. Only
vs_repr_objectives is simulated (Table 2 gives its means and stds); the others say why not."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from analysis import comparable, select
from analysis.cells import Cells, means_table, observed_cells, table2_cells
from analysis.claim_budget import frames_text
from analysis.claims.core import (
    REFUTED,
    SUPPORTED,
    ClaimSpec,
    Draws,
    Judgement,
    NotEnoughData,
    Simulation,
    apart,
    get,
    labelled,
    means,
    pct,
    present,
    require,
)
from analysis.claims.draws import Pair, judged, one_draw, universal
from analysis.context import Context
from analysis.paper import DMC9, PaperData
from analysis.speed import speed_measurements
from analysis.tsne import CLUSTER_THRESHOLD, tsne_for_context

REPR_TASKS = ("quadruped_run", "walker_run", "hopper_hop", "reacher_hard", "acrobot_swingup")

_FIGURE_ONLY = "the paper gives {} only as a figure ({}), with no numbers"
SPEED_TOLERANCE = 0.25  # speed: the FPS ratio within this fraction of the paper's "about 3.6x slower"


def action_repr_printed(paper: PaperData) -> tuple[str, str]:
    """What action_repr_gain's and no_action_repr_vs_drqv2's evidence quote: the prose's percentages
    (repro_data/paper/claim_numbers.csv)."""
    number = paper.claim_number
    return (f"(paper: +{number('action_repr_gain', 'gain_low_percent'):g}% quadruped_run ... "
            f"+{number('action_repr_gain', 'gain_high_percent'):g}% hopper_hop)",
            f"(paper: +{number('no_action_repr_vs_drqv2', 'quadruped_run_percent'):g}% quadruped_run, "
            f"+{number('no_action_repr_vs_drqv2', 'reacher_hard_percent'):g}% reacher_hard)")


def _action_repr_gain(ctx: Context) -> tuple[str, str]:
    cells = observed_cells(select.action_repr(ctx.scores, ctx.experiment_map), ["task", "label"])
    table = means_table(cells)
    tasks = sorted({k[0] for k in table if k[1] == "TACO w/o action repr"}
                   | {"quadruped_run", "hopper_hop", "reacher_hard"})
    pairs = [((t, "TACO"), (t, "TACO w/o action repr"), t) for t in tasks]
    verdict, ev = universal(one_draw(cells), pairs, ctx.min_seeds, ctx.budget_text()).first
    gains = [f"{t} {pct(present(ctx, table, t, 'TACO'), present(ctx, table, t, 'TACO w/o action repr'))}" for t in tasks
             if get(ctx, table, t, "TACO") and get(ctx, table, t, "TACO w/o action repr")]
    return verdict, f"gains {', '.join(gains)} {action_repr_printed(ctx.paper)[0]}. {ev}"


# no_action_repr_vs_drqv2's "comparable elsewhere": this project's reading, within this fraction of DrQ-v2's mean.
COMPARABLE_WITHIN = 0.2


def _no_repr_vs_drqv2(ctx: Context) -> tuple[str, str]:
    df = select.action_repr(ctx.scores, ctx.experiment_map)
    table = means(df, ["task", "label"])
    require(ctx, table, [(t, lab) for t in ("quadruped_run", "reacher_hard")
                         for lab in ("TACO w/o action repr", "DrQ-v2")])
    lines, ok = [], True
    for t in sorted({k[0] for k in table}):
        a, b = get(ctx, table, t, "TACO w/o action repr"), get(ctx, table, t, "DrQ-v2")
        if a is None or b is None:
            continue
        lines.append(f"{t} {pct(a, b)}")
        ok &= (a > b) if t in ("quadruped_run", "reacher_hard") else abs(a / b - 1) <= COMPARABLE_WITHIN
    return (SUPPORTED if ok else REFUTED), ("w/o action repr vs DrQ-v2: " + ", ".join(lines) + " "
                                            + action_repr_printed(ctx.paper)[1])


def _tsne(ctx: Context) -> tuple[str, str]:
    if not ctx.results.runs.empty and "tsne" not in ctx.cache:
        from analysis.tsne import find_tsne_run

        if find_tsne_run(ctx.results.runs) is None:
            raise NotEnoughData("no TACO run with distracting action dims and a checkpoint (experiment 'tsne')")
    elif ctx.results.runs.empty:
        raise NotEnoughData("no runs")
    res, info = tsne_for_context(ctx)
    if res.silhouette_latent_2d is None:
        raise NotEnoughData(info["reason"] or "no latent embedding")
    last = ctx.scores.loc[ctx.scores["run_id"] == info["run_id"], "last_frame"]
    if not ctx.below_budget and (last.empty or not comparable.reached(float(last.fillna(0).max()), ctx.budget)):
        got = frames_text(float(last.fillna(0).max())) if not last.empty else "no evaluation"
        raise NotEnoughData(f"the t-SNE run {info['run_id']} reaches {got}; the claim is about {ctx.budget_text()}")
    ok = res.silhouette_latent_2d >= CLUSTER_THRESHOLD and res.silhouette_raw_2d < CLUSTER_THRESHOLD
    return (SUPPORTED if ok else REFUTED), (
        f"silhouette raw {res.silhouette_raw_2d:.3f}, latent {res.silhouette_latent_2d:.3f} (t-SNE 2-D; original "
        f"spaces: raw {res.silhouette_raw:.3f}, latent {res.silhouette_latent:.3f}); run {info['run_id']}")


def _batch(ctx: Context) -> tuple[str, str]:
    df = select.batch_size(ctx.scores, ctx.experiment_map)
    table = means(df, ["method", "batch_size"])
    series = {}
    for m in ("TACO", "DrQ-v2"):
        pts = sorted((int(k[1]), present(ctx, table, *k)) for k in table
                     if k[0] == m and get(ctx, table, *k) is not None)
        if len(pts) < 2:
            raise NotEnoughData(f"need {m} at >= 2 batch sizes (have {len(pts)})")
        series[m] = pts
    t_vals = [v for _, v in series["TACO"]]
    d_vals = [v for _, v in series["DrQ-v2"]]
    grows = all(b >= a for a, b in zip(t_vals, t_vals[1:])) and t_vals[-1] >= 1.1 * t_vals[0]
    flat = (max(d_vals) - min(d_vals)) <= 0.15 * np.mean(d_vals)
    ev = "; ".join(f"{m}: " + ", ".join(f"B{b} {v:.0f}" for b, v in pts) for m, pts in series.items())
    return (SUPPORTED if grows and flat else REFUTED), ev + f" (TACO grows: {grows}; DrQ-v2 flat: {flat})"


def _objectives(ctx: Context) -> tuple[str, str]:
    table = means(select.objective_removal(ctx.scores, ctx.experiment_map), ["label"])
    require(ctx, table, [("full",), ("no TACO",), ("no CURL",), ("no reward",)])
    full = present(ctx, table, "full")
    drops = {k: full - present(ctx, table, k) for k in ("no TACO", "no CURL", "no reward")}
    ok = drops["no TACO"] > 0 and drops["no TACO"] > max(drops["no CURL"], drops["no reward"])
    shown = dict(zip(drops, apart(list(drops.values()), 0)))
    return (SUPPORTED if ok else REFUTED), (f"full {full:.0f}; drops: "
                                            + ", ".join(f"{k} {v}" for k, v in shown.items()))


def vs_repr_pairs(paper: PaperData) -> list[tuple[tuple, tuple, str]]:
    """vs_repr_objectives' comparisons: TACO against each other objective where the paper has its value."""
    return [((t, "TACO"), (t, m), f"{t} vs {m}") for t in REPR_TASKS for m in paper.repr_others
            if paper.repr_value(t, m) is not None]


def vs_repr_rule(draws: Draws, pairs: Sequence[Pair], *, min_seeds: int, budget: str) -> Judgement:
    """vs_repr_objectives: TACO's mean > each other objective's of Table 2 (``pairs``: :func:`vs_repr_pairs`) on each
    of the 5 tasks (:func:`universal`)."""
    return universal(draws, pairs, min_seeds, budget)


def _judge_vs_repr(ctx: Context, draws: Draws) -> Judgement:
    return vs_repr_rule(draws, vs_repr_pairs(ctx.paper), min_seeds=ctx.min_seeds, budget=ctx.budget_text())


def _repr_cells(ctx: Context) -> Cells:
    return observed_cells(labelled(select.repr_objectives(ctx.scores, ctx.experiment_map)), ["task", "method"])


def _horizon(ctx: Context) -> tuple[str, str]:
    cells = observed_cells(select.horizon(ctx.scores, ctx.experiment_map), ["task", "label"])
    pairs = [((t, "K=3"), (t, "K=1"), f"{t} K3>K1")
             for t in ("hopper_hop", "quadruped_walk", "acrobot_swingup", "reacher_hard")]
    pairs += [((t, "K=1"), (t, "K=3"), f"{t} K1>K3") for t in ("quadruped_run", "walker_run")]
    pairs += [((t, k), (t, "DrQ-v2"), f"{t} {k}>DrQ-v2") for t in DMC9 for k in ("K=1", "K=3")]
    return universal(one_draw(cells), pairs, ctx.min_seeds, ctx.budget_text()).first


# the action-repeat sweep's grid (appendix B: action repeats 1, 2, 4; K from {1,3,5}), as the sweep runs it
ACTION_REPEATS = (1, 2, 4)


REPEAT_HORIZONS = (1, 3, 5)


def best_k_printed(paper: PaperData) -> dict[int, int]:
    """The action_repeat claim's best K at each action repeat, as the prose gives it (claim_numbers.csv)."""
    return {a: paper.claim_integer("action_repeat", f"best_k_at_repeat_{a}") for a in ACTION_REPEATS}


def _action_repeat_rule_text(paper: PaperData) -> str:
    (a1, k1), *rest = best_k_printed(paper).items()
    return (f"on hopper_hop the K in {{{','.join(map(str, REPEAT_HORIZONS))}}} with the highest mean is {k1} at "
            f"action repeat {a1}, " + " and ".join(f"{k} at {a}" for a, k in rest))


def _action_repeat(ctx: Context) -> tuple[str, str]:
    table = means(select.action_repeat(ctx.scores, ctx.experiment_map), ["label"])
    keys = [(f"AR={a}, K={k}",) for a in ACTION_REPEATS for k in REPEAT_HORIZONS]
    require(ctx, table, keys)
    best = {a: max(REPEAT_HORIZONS, key=lambda k: present(ctx, table, f"AR={a}, K={k}")) for a in ACTION_REPEATS}
    printed = best_k_printed(ctx.paper)
    ok = best == printed
    return (SUPPORTED if ok else REFUTED), ("best K: " + ", ".join(f"AR{a}: K={k}" for a, k in best.items())
                                            + " (paper: " + ", ".join(f"AR{a} K={k}" for a, k in printed.items())
                                            + ")")


def _action_dim(ctx: Context) -> tuple[str, str]:
    df = select.action_dim_runs(ctx.scores, ctx.experiment_map)
    table = means(df, ["dim"]) if not df.empty else {}
    have = sorted(k[0] for k in table if get(ctx, table, *k) is not None)
    mid = [d for d in have if 6 < d < 24]
    if 6 not in have or 24 not in have or not mid:
        raise NotEnoughData(f"need dims 6, 24 and one in between (have {have})")
    mids = [present(ctx, table, d) for d in mid]
    ok = (max(present(ctx, table, 6), present(ctx, table, 24)) < min(mids)
          and (max(mids) - min(mids)) <= 0.15 * np.mean(mids))
    return (SUPPORTED if ok else REFUTED), ", ".join(f"d={d} {get(ctx, table, d):.0f}" for d in have)


def paper_slowdown(paper: PaperData) -> float:
    """The speed claim's "about 3.6x slower" as the paper's prose gives it (repro_data/paper/claim_numbers.csv)."""
    return paper.claim_number("speed", "slowdown")


def _speed_rule_text(paper: PaperData) -> str:
    return (f"on one hardware, FPS(DrQ-v2 B256) / FPS(TACO B1024) within ±{SPEED_TOLERANCE:.0%} of "
            f"{paper_slowdown(paper):g}, and TACO's FPS decreases with batch size where measured (from `repro bench` "
            "files and runs of experiment 'speed'; other runs' FPS only in an indicative reading)")


def speed_printed(paper: PaperData) -> tuple[str, str]:
    """What the speed claim's evidence quotes from the packaged paper data: the prose's ratio with Tables 4-5's, and
    TACO's FPS per batch size."""
    taco = {b: paper.fps("TACO", b) for b in (256, 512, 1024)}
    drq = paper.fps("DrQ-v2", 256)
    return (f"(paper {paper_slowdown(paper):g}, from its table {drq:g}/{taco[1024]:g} = {drq / taco[1024]:.2f})",
            "(paper " + ", ".join(f"B{b} {v:g}" for b, v in taco.items()) + ")")


def _speed(ctx: Context) -> tuple[str, str]:
    meas = speed_measurements(ctx.results, fallback=ctx.below_budget)
    meas = meas[meas["speedup"] == "plain"]
    if meas.empty:
        raise NotEnoughData("no FPS measurements (bench/*.json or runs of experiment 'speed')")
    for hw, rows in meas.groupby("hardware"):
        fps = rows.groupby(["method", "batch_size"])["fps"].mean()
        if ("TACO", 1024) in fps.index and ("DrQ-v2", 256) in fps.index:
            ratio = fps[("DrQ-v2", 256)] / fps[("TACO", 1024)]
            taco = [(b, fps[("TACO", b)]) for b in (256, 512, 1024) if ("TACO", b) in fps.index]
            decreasing = all(a[1] > b[1] for a, b in zip(taco, taco[1:]))
            slowdown = paper_slowdown(ctx.paper)
            ok = (1 - SPEED_TOLERANCE) * slowdown <= ratio <= (1 + SPEED_TOLERANCE) * slowdown and decreasing
            printed_ratio, printed_fps = speed_printed(ctx.paper)
            ev = (f"on {hw}: ratio {ratio:.2f} {printed_ratio}; TACO FPS "
                  + ", ".join(f"B{b} {v}" for (b, _), v in zip(taco, apart([v for _, v in taco], 1)))
                  + f" {printed_fps}")
            return (SUPPORTED if ok else REFUTED), ev
    raise NotEnoughData("need TACO B1024 and DrQ-v2 B256 FPS measured on the same hardware")


SPECS: tuple[ClaimSpec, ...] = (
    ClaimSpec("action_repr_gain", _action_repr_gain,
              "TACO mean > TACO w/o action repr mean on every task of the action_repr sweep (named: "
              "quadruped_run, hopper_hop, reacher_hard)",
              not_simulated="the paper gives the gains as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("no_action_repr_vs_drqv2", _no_repr_vs_drqv2,
              "TACO w/o action repr beats DrQ-v2 on quadruped_run and reacher_hard, and is within "
              f"±{COMPARABLE_WITHIN:.0%} of DrQ-v2 on the other tasks of the sweep",
              not_simulated="the paper gives these as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("tsne_clusters", _tsne,
              f"silhouette of the 4 centroid labels on the t-SNE embedding: latent >= {CLUSTER_THRESHOLD} "
              f"and raw < {CLUSTER_THRESHOLD}",
              not_simulated="one trained agent and a t-SNE embedding: not a statistic over seeds"),
    ClaimSpec("batch_size", _batch,
              "on quadruped_run TACO's mean is non-decreasing in batch size and >= 10% higher at the largest "
              "than at the smallest; DrQ-v2's range is <= 15% of its mean",
              not_simulated=_FIGURE_ONLY.format("the batch-size results", "F7a")),
    ClaimSpec("objective_removal", _objectives,
              "on quadruped_run the drop full - no TACO is positive and larger than the drops of no "
              "CURL and no reward",
              not_simulated="the paper gives the ablation only as a figure (F7b), with no numbers"),
    ClaimSpec("vs_repr_objectives", judged(_repr_cells, _judge_vs_repr),
              "TACO mean > each other objective of Table 2 (each of its methods but TACO and DrQ-v2; where the "
              "paper has its value) on each of the 5 tasks",
              Simulation(lambda ctx, budget: table2_cells(ctx, REPR_TASKS), _judge_vs_repr, _repr_cells, REPR_TASKS)),
    ClaimSpec("horizon_choice", _horizon,
              "K=3 > K=1 on hopper_hop, quadruped_walk, acrobot_swingup, reacher_hard; K=1 > K=3 on "
              "quadruped_run, walker_run; K=1 and K=3 > DrQ-v2 on all 9 tasks",
              not_simulated=_FIGURE_ONLY.format("K=1 and K=3", "F8")),
    ClaimSpec("action_repeat", _action_repeat, _action_repeat_rule_text,
              not_simulated=_FIGURE_ONLY.format("the action-repeat results", "F9")),
    ClaimSpec("action_dim", _action_dim,
              "on quadruped_run the means at dims 6 and 24 are below every intermediate dim's, and the "
              "intermediate dims' range is <= 15% of their mean",
              not_simulated=_FIGURE_ONLY.format("the latent-dimension results", "appendix E")),
    ClaimSpec("speed", _speed, _speed_rule_text,
              not_simulated="a timing on your hardware (`repro bench`), not a statistic over seeds"),
)
