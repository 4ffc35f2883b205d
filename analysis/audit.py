"""Recompute every number the paper derives from other numbers and list each mismatch with both values.

Inputs are only the paper's own files (``repro_data/paper``): the CSV transcriptions of its tables, claims.csv, the
numbers of its prose (claim_numbers.csv) and the LaTeX source (read by analysis/paper_tex.py). Checks: printed
averages vs the mean of their column, relative gains (the 1.4x / 40% claim, the 3.6x speed ratio, the
action-representation percentages), entries repeated across tables (Table 1 vs Table 2, Table 4 vs Table 5),
bold/shaded "best" marks, textual statements that follow from a table, and the CSV transcription against the LaTeX
tables; plus the paper's DrQ-v2 baseline against the published curves (analysis/published_audit.py).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable

import pandas as pd

from analysis.calibration import SOURCE_TEXT
from analysis.findings import (
    PRECISION_NOTE,
    Finding,
    agree,
    half_unit,
    places,
    pm_text,
    printed_within,
    ratio_range,
    result_text,
    rounding_text,
)
from analysis.paper import DMC9, PaperData
from analysis.paper_tex import (
    T1_COLUMNS,
    header,
    parse_cql_table,
    parse_offline_table,
    parse_row_table,
    parse_single_row,
)
from analysis.published_audit import (
    PUBLISHED_REPS,
    check_published_baseline,
    published_baseline,
    published_frame,
    published_rows,
    published_summary,
)
from analysis.stats import DEFAULT_SEED
from analysis.tables import write_table

# the published-baseline part, for the report and calibration (analysis/published_audit.py)
__all__ = ["CHECK_FUNCS", "Finding", "mismatches", "published_baseline", "published_frame", "published_rows",
           "published_summary", "run_audit", "write_audit"]

MODEL_FREE = ["TACO", "DrQ-v2", "A-LIX", "DrQ", "CURL"]


# ---------------------------------------------------------------- checks
def check_offline_average(p: PaperData) -> Iterable[Finding]:
    """Table 3's average row against the mean of each method's 12 cells, at the printed precision: each cell within
    its printed rounding, the mean within as much, the printed average within its own."""
    recomputed = p.offline.groupby("method")["normalized_mean"].mean()
    printed = dict(zip(p.offline_average["method"], p.offline_average["average_normalized"]))
    h = half_unit(places(p.offline["normalized_mean"]))
    digits = places(p.offline_average["average_normalized"])
    for method, value in printed.items():
        r = float(recomputed[method])
        ok = printed_within(value, digits, r - h, r + h)
        desc = f"Table 3 average row, {method}: printed vs mean of its 12 cells (at the printed precision)"
        if not ok:
            twins = [m for m, v in recomputed.items() if m != method and printed_within(value, digits, v - h, v + h)]
            if twins:
                desc += f" (the printed value is the recomputed average of {', '.join(twins)}: swapped?)"
        yield Finding("offline_average_row", "T3", desc, f"{value:.{digits}f}",
                      f"{r:.3f} (→ {r:.{digits}f}); " + rounding_text(r - h, r + h, f"each cell within ±{h:g}",
                                                                    digits, value, r), ok)


def check_claim_text_numbers(p: PaperData) -> Iterable[Finding]:
    text = p.claims.set_index("id").loc["offline_average", "claim"]
    printed = dict(zip(p.offline_average["method"], p.offline_average["average_normalized"]))
    for method in ("TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL"):
        m = re.search(re.escape(method) + r"\s+(\d+(?:\.\d+)?)", text)
        val = float(m.group(1)) if m else None
        yield Finding("claim_offline_average", "claims.csv vs T3", f"claim offline_average quotes {method}",
                      f"{val:g}" if val is not None else "absent", f"{printed[method]:.1f} (offline_average.csv)",
                      val is not None and agree(val, printed[method]))
    speed = p.claims.set_index("id").loc["speed", "claim"]
    te = p.time_efficiency.set_index(["method", "batch_size"])["fps"]
    quoted = {("TACO", 1024): r"(\d+) vs", ("DrQ-v2", 256): r"vs (\d+) FPS", ("TACO", 512): r"(\d+) FPS at 512",
              ("TACO", 256): r"(\d+) FPS at 256"}
    for key, pattern in quoted.items():
        m = re.search(pattern, speed)
        val = float(m.group(1)) if m else None
        yield Finding(
            "claim_speed_fps",
            "claims.csv vs T4/T5",
            f"claim speed quotes {key[0]} B{key[1]} FPS",
            f"{val:g}" if val is not None else "absent",
            f"{te[key]:g}",
            val is not None and agree(val, te[key]),
        )


def check_online_gain(p: PaperData) -> Iterable[Finding]:
    """The prose's gain ("1.4x", "40% boost"; claim_numbers.csv) against Table 1's ratios of TACO to DrQ-v2."""
    gain, boost = p.claim_number("online_avg_gain", "gain"), p.claim_number("online_avg_gain", "boost_percent")
    piv = p.online.pivot(index="task", columns="method", values="mean")
    r = piv["TACO"].mean() / piv["DrQ-v2"].mean()
    h = half_unit(places(p.online["mean"]))
    low, high = ratio_range(piv["TACO"].mean(), piv["DrQ-v2"].mean(), h, h)
    digits = places([gain])
    yield Finding("online_gain_ratio", "abstract, §1, §5.1 vs T1",
                  f"TACO vs DrQ-v2: '{gain:g}x' / '{boost:g}% boost' vs ratio of the 9-task means of Table 1 (at the "
                  "printed precision)",
                  f"{gain:g}x ({boost:g}%)", f"{r:.3f}x ({100 * (r - 1):.1f}%); "
                  + rounding_text(low, high, f"each mean within ±{h:g}", digits, gain, r),
                  printed_within(gain, digits, low, high))
    per_task = (piv["TACO"] / piv["DrQ-v2"]).mean()
    yield Finding("online_gain_ratio_alt", "T1", "alternative reading: mean of the 9 per-task ratios TACO/DrQ-v2",
                  f"{gain:g}x", f"{per_task:.3f}x", abs(round(per_task, 1) - gain) < 1e-9, kind="info")
    best_mf = piv[[m for m in MODEL_FREE if m != "TACO"]].max(axis=1)
    r2 = piv["TACO"].mean() / best_mf.mean()
    yield Finding(
        "online_gain_vs_best_prior",
        "§1 contribution 4 vs T1",
        f"'outperforms prior state-of-the-art model-free RL by {gain:g}x': TACO vs the best prior model-free per task",
        f"{gain:g}x",
        f"{r2:.3f}x",
        abs(round(r2, 1) - gain) < 1e-9,
        kind="info",
    )


def check_model_based(p: PaperData) -> Iterable[Finding]:
    piv = p.online.pivot(index="task", columns="method", values="mean")
    wins = int((piv["TACO"] > piv[["DreamerV3", "TD-MPC"]].max(axis=1)).sum())
    yield Finding("beats_model_based", "§5.1 vs T1", "tasks where TACO beats both DreamerV3 and TD-MPC", "6 of 9",
                  f"{wins} of 9", wins == 6)
    losses = [t for t in DMC9 if not piv.loc[t, "TACO"] > piv.loc[t, "DrQ-v2"]]
    yield Finding("beats_drqv2_all", "§5.1 vs T1", "tasks where TACO beats DrQ-v2", "9 of 9",
                  f"{9 - len(losses)} of 9", not losses)


def check_t1_vs_t2(p: PaperData) -> Iterable[Finding]:
    t1 = p.online.set_index(["task", "method"])
    for r in p.repr_objectives.itertuples(index=False):
        if r.method not in ("TACO", "DrQ-v2"):
            continue
        a = t1.loc[(r.task, r.method)]
        ok = agree(a["mean"], r.mean) and agree(a["std"], r.std)
        desc = f"{r.task} {r.method}: Table 2 repeats Table 1's entry"
        if not ok:
            same = t1.loc[r.task]
            twins = [m for m in same.index
                     if agree(same.loc[m, "mean"], r.mean) and agree(same.loc[m, "std"], r.std)]
            if twins:
                desc += f" (Table 2's value is Table 1's {', '.join(twins)} entry)"
        yield Finding("t1_vs_t2", "T1 vs T2", desc, f"T2: {pm_text(r.mean, r.std)}",
                      f"T1: {pm_text(a['mean'], a['std'])}", ok)


def check_t4_vs_t5(p: PaperData) -> Iterable[Finding]:
    tex = p.tex
    t4 = parse_single_row(tex, "tab:time_efficiency")
    t5 = parse_single_row(tex, "tab:time_efficiency_taco")
    yield Finding(
        "t4_vs_t5", "T4 vs T5", "TACO B1024 FPS in both tables", f"T5: {t5[0]:g}", f"T4: {t4[0]:g}", agree(t4[0], t5[0])
    )
    te = p.time_efficiency.set_index(["method", "batch_size"])["fps"]
    ratio = te[("DrQ-v2", 256)] / te[("TACO", 1024)]
    slowdown = p.claim_number("speed", "slowdown")  # the prose's "about 3.6 times slower" (claim_numbers.csv)
    h, digits = half_unit(places(te)), places([slowdown])
    low, high = ratio_range(te[("DrQ-v2", 256)], te[("TACO", 1024)], h, h)
    yield Finding(
        "speed_ratio",
        "App. C vs T4",
        f"'about {slowdown:g} times slower than DrQ-v2': FPS(DrQ-v2 B256) / FPS(TACO B1024) (at the printed "
        "precision)",
        f"{slowdown:g}",
        f"{ratio:.3f} (→ {ratio:.{digits}f}) from the printed {te[('DrQ-v2', 256)]:g} / {te[('TACO', 1024)]:g}; "
        + rounding_text(low, high, f"each FPS within ±{h:g}", digits, slowdown, ratio),
        printed_within(slowdown, digits, low, high),
    )
    yield Finding("speed_vs_drq", "App. C vs T4", "'similar time efficiency as DrQ': TACO B1024 vs DrQ B512 FPS",
                  "similar", f"{te[('TACO', 1024)]:g} vs {te[('DrQ', 512)]:g}", True, kind="info")


# this project's tolerance for two readings of one bar of F3 from the prose's rounded percentages
IMPLIED_WITHIN = 0.02


def check_action_repr_text(p: PaperData) -> Iterable[Finding]:
    """§5.1's percentages for TACO without action representation (claim_numbers.csv) against Table 1: "18%" over
    DrQ-v2 and TACO "12.2%" above it on quadruped_run imply the same score; "51%" over DrQ-v2 on reacher_hard implies
    a TACO gain inside the stated 12.2%-70.4%."""
    on = p.online.set_index(["task", "method"])["mean"]
    low_pct, high_pct = (p.claim_number("action_repr_gain", n) for n in ("gain_low_percent", "gain_high_percent"))
    low, high = low_pct / 100, high_pct / 100
    over_quadruped = p.claim_number("no_action_repr_vs_drqv2", "quadruped_run_percent") / 100
    over_reacher = p.claim_number("no_action_repr_vs_drqv2", "reacher_hard_percent") / 100
    from_taco = on[("quadruped_run", "TACO")] / (1 + low)
    from_drq = on[("quadruped_run", "DrQ-v2")] * (1 + over_quadruped)
    yield Finding("action_repr_quadruped", "§5.1 (F3) vs T1",
                  f"quadruped_run TACO w/o action repr implied two ways: TACO/{1 + low:g} and DrQ-v2 x "
                  f"{1 + over_quadruped:g} (within {IMPLIED_WITHIN:.0%})",
                  f"{from_taco:.1f}", f"{from_drq:.1f}", abs(from_taco / from_drq - 1) <= IMPLIED_WITHIN)
    no_repr_reacher = on[("reacher_hard", "DrQ-v2")] * (1 + over_reacher)
    gain = on[("reacher_hard", "TACO")] / no_repr_reacher - 1
    yield Finding(
        "action_repr_reacher",
        "§5.1 (F3) vs T1",
        f"reacher_hard: w/o action repr = DrQ-v2 x {1 + over_reacher:g} implies a TACO gain that should lie in the "
        f"stated {low_pct:g}%-{high_pct:g}% range",
        f"{low_pct:g}% to {high_pct:g}%",
        f"{100 * gain:.1f}% (w/o = {no_repr_reacher:.0f}, TACO = {on[('reacher_hard', 'TACO')]:g})",
        low - 1e-9 <= gain <= high + 1e-9,
    )


def check_t2_text(p: PaperData) -> Iterable[Finding]:
    t2 = p.repr_objectives.pivot(index="task", columns="method", values="mean")
    below = [
        f"{m} on {t} ({t2.loc[t, m]:g} < {t2.loc[t, 'DrQ-v2']:g})"
        for t in t2.index
        for m in p.repr_others
        if not math.isnan(t2.loc[t, m]) and t2.loc[t, m] < t2.loc[t, "DrQ-v2"]
    ]
    yield Finding("t2_objectives_beat_drqv2", "§5.1 text vs T2",
                  "'previous representation learning objectives ... surpass the DrQ-v2 baseline'", "all above DrQ-v2",
                  "below DrQ-v2: " + ("; ".join(below) if below else "none"), not below)
    losses = [f"{m} on {t}" for t in t2.index for m in p.repr_others
              if not math.isnan(t2.loc[t, m]) and not t2.loc[t, "TACO"] > t2.loc[t, m]]
    yield Finding("t2_taco_best", "claim vs_repr_objectives vs T2",
                  f"TACO above {', '.join(p.repr_others)} on all five tasks", "all five",
                  "exceptions: " + (", ".join(losses) if losses else "none"), not losses)


def check_offline_gain(p: PaperData) -> Iterable[Finding]:
    o = p.offline.set_index(["task", "dataset", "method"])["normalized_mean"]
    fails = []
    for (task, dataset), _ in p.offline.groupby(["task", "dataset"]):
        for base in ("TD3+BC", "CQL"):
            if not o[(task, dataset, f"{base}+TACO")] > o[(task, dataset, base)]:
                fails.append(f"{task}/{dataset} {base}")
    yield Finding(
        "offline_gain",
        "claim offline_gain vs T3",
        "X+TACO above X on all 12 pairs for TD3+BC and CQL",
        "24 of 24",
        f"{24 - len(fails)} of 24" + (f" (fails: {', '.join(fails)})" if fails else ""),
        not fails,
    )


def check_bold_marks(p: PaperData) -> Iterable[Finding]:
    tex = p.tex
    t1 = parse_row_table(tex, "tab:online_table", T1_COLUMNS)
    for task, rows in t1.groupby("task", sort=False):
        best = rows.loc[rows["mean"].idxmax(), "method"]
        bold = list(rows.loc[rows["bold"], "method"])
        yield Finding("t1_bold", "T1 (LaTeX)", f"{task}: bold = best of all methods", ", ".join(bold) or "none", best,
                      bold == [best])
        mf = rows[rows["method"].isin(MODEL_FREE)]
        best_mf = mf.loc[mf["mean"].idxmax(), "method"]
        yield Finding("t1_shading", "T1 (LaTeX)", f"{task}: the shaded TACO column = best model-free", "TACO", best_mf,
                      best_mf == "TACO")
    t2 = parse_row_table(tex, "tab:spr_table", p.repr_methods)
    for task, rows in t2.groupby("task", sort=False):
        best = rows.loc[rows["mean"].astype(float).idxmax(), "method"]
        bold = list(rows.loc[rows["bold"] & rows["mean"].notna(), "method"])  # a bold "N/A" is not a best mark
        yield Finding("t2_bold", "T2 (LaTeX)", f"{task}: bold = best", ", ".join(bold) or "none", best, bold == [best])
    t3, _ = parse_offline_table(tex)
    for (task, dataset), rows in t3.groupby(["task", "dataset"], sort=False):
        r = rows.set_index("method")
        for base in ("TD3+BC", "CQL"):
            bold_taco = bool(r.loc[f"{base}+TACO", "bold"])
            better = r.loc[f"{base}+TACO", "mean"] > r.loc[base, "mean"]
            if bold_taco != better:
                yield Finding("t3_bold", "T3 (LaTeX)", f"{task}/{dataset}: {base}+TACO bold iff above {base}",
                              "bold" if bold_taco else "plain", "above" if better else "not above", False)


def check_transcription(p: PaperData) -> Iterable[Finding]:
    """The CSV files against the LaTeX tables, cell by cell (one summary row per table if all agree); Table 2's
    columns, which its CSV names (the parser reads the LaTeX columns in the CSV's order), against the LaTeX header."""
    tex = p.tex
    t2_header = header(tex, "tab:spr_table")
    yield Finding("csv_vs_tex", "T2 CSV vs LaTeX", "method columns in order", ", ".join(p.repr_methods),
                  ", ".join(t2_header), t2_header == list(p.repr_methods))
    pairs = [
        ("T1", parse_row_table(tex, "tab:online_table", T1_COLUMNS), p.online, ["task", "method"], "mean", "std"),
        ("T2", parse_row_table(tex, "tab:spr_table", p.repr_methods), p.repr_objectives, ["task", "method"], "mean",
         "std"),
        (
            "T3",
            parse_offline_table(tex)[0],
            p.offline.rename(columns={"normalized_mean": "mean", "normalized_std": "std"}),
            ["task", "dataset", "method"],
            "mean",
            "std",
        ),
    ]
    for name, parsed, csv, keys, mcol, scol in pairs:
        merged = parsed.merge(csv, on=keys, how="outer", suffixes=("_tex", "_csv"), indicator=True)
        bad = 0
        for d in merged.to_dict("records"):
            ok = (
                d["_merge"] == "both"
                and agree(d[f"{mcol}_tex"], d[f"{mcol}_csv"])
                and agree(d[f"{scol}_tex"], d[f"{scol}_csv"])
            )
            if not ok:
                bad += 1
                yield Finding("csv_vs_tex", f"{name} CSV vs LaTeX", " ".join(str(d[k]) for k in keys),
                              pm_text(d[f"{mcol}_csv"], d[f"{scol}_csv"]), pm_text(d[f"{mcol}_tex"], d[f"{scol}_tex"]),
                              False)
        if not bad:
            yield Finding("csv_vs_tex", f"{name} CSV vs LaTeX", f"all {len(merged)} cells", "CSV", "LaTeX", True)
    _, avg_tex = parse_offline_table(tex)
    for m, v in avg_tex.items():
        csv_v = float(p.offline_average.set_index("method").loc[m, "average_normalized"])
        if not agree(v, csv_v):
            yield Finding("csv_vs_tex", "T3 average CSV vs LaTeX", m, f"{csv_v:g}", f"{v:g}", False)
    t4 = parse_single_row(tex, "tab:time_efficiency")
    t4_csv = [
        float(p.time_efficiency.set_index(["method", "batch_size"]).loc[k, "fps"])
        for k in [("TACO", 1024), ("DrQ-v2", 256), ("A-LIX", 256), ("DrQ", 512), ("CURL", 512), ("DreamerV3", 256),
                  ("TD-MPC", 256)]
    ]
    yield Finding("csv_vs_tex", "T4 CSV vs LaTeX", "FPS row", str(t4_csv), str(t4), t4 == t4_csv)
    cql = parse_cql_table(tex).merge(p.cql_alpha, on=["task", "dataset"], how="outer")
    ok = bool((cql["alpha"] == cql["alpha_cql"]).all())
    yield Finding("csv_vs_tex", "T6 CSV vs LaTeX", f"all {len(cql)} alpha values", "CSV", "LaTeX", ok)


def check_cql_alpha(p: PaperData) -> Iterable[Finding]:
    allowed = {0.5, 1.0, 2.0, 4.0, 8.0}
    used = sorted(set(p.cql_alpha["alpha_cql"].astype(float)))
    yield Finding(
        "cql_alpha_grid",
        "App. D text vs T6",
        "every alpha_CQL of Table 6 is in the stated grid {0.5, 1, 2, 4, 8}",
        "{0.5, 1, 2, 4, 8}",
        str(used),
        set(used) <= allowed,
    )
    printed = sorted(set(p.cql_alpha["dataset_as_printed"]))
    yield Finding(
        "dataset_names",
        "T3 vs T6",
        "Table 6 calls the full-replay dataset 'Replay' (cql_alpha.csv: full_replay)",
        "Full-replay (T3)",
        ", ".join(printed),
        True,
        kind="info",
    )


CHECK_FUNCS = (
    check_offline_average,
    check_claim_text_numbers,
    check_online_gain,
    check_model_based,
    check_t1_vs_t2,
    check_t4_vs_t5,
    check_action_repr_text,
    check_t2_text,
    check_offline_gain,
    check_bold_marks,
    check_transcription,
    check_cql_alpha,
    check_published_baseline,
)


def run_audit(paper: PaperData | None = None) -> list[Finding]:
    """Every finding of every check, in a fixed order."""
    paper = paper or PaperData()
    return [f for fn in CHECK_FUNCS for f in fn(paper)]


def mismatches(findings: Iterable[Finding]) -> list[Finding]:
    return [f for f in findings if f.kind == "check" and not f.match]


def write_audit(out_dir, findings: list[Finding]):
    """Write ``audit.csv/.md/.tex``: mismatches first, then the checks that agree, then context rows."""
    kinds = {"check": 0, "published": 1}
    order = sorted(findings, key=lambda f: (kinds.get(f.kind, 2), f.match))
    raw = pd.DataFrame([f.__dict__ for f in order])
    disp = pd.DataFrame(
        {
            "Result": [result_text(f) for f in order],
            "Where": [f.where for f in order],
            "What": [f.description for f in order],
            "Paper prints": [f.printed for f in order],
            "Recomputed": [f.recomputed for f in order],
        }
    )
    n_bad = len(mismatches(findings))
    caption = (f"Audit of the paper's derived numbers from its own tables: {n_bad} mismatches in "
               f"{sum(f.kind == 'check' for f in findings)} checks.")
    notes = [PRECISION_NOTE]
    notes += [f"Rows 'outside/inside published CI': the paper's DrQ-v2 baseline against {SOURCE_TEXT}, at 1M frames "
             f"(every DMC9 curve has an evaluation there); CIs: stratified bootstrap over the published seeds "
             f"(rliable, {PUBLISHED_REPS:,} repetitions, random state {DEFAULT_SEED}). "
             + published_summary(findings) + " The CI is the published mean's alone (the paper's own seed spread is "
             "not part of it)."] if published_rows(findings) else []
    return write_table(out_dir, "audit", raw, caption, disp, notes)
