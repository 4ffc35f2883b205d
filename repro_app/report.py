"""REPORT.md and REPORT.html: every table and figure, the claims, the audit and the provenance of the runs."""

from __future__ import annotations

import base64
import datetime as dt
import html
import importlib.metadata
import platform
import re
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

from analysis.audit import mismatches, published_frame, published_rows, published_summary, write_audit
from analysis.bootstrap import ESTIMATOR
from analysis.calibration import CalibrationRow, calibration_frames, calibration_notes, write_calibration
from analysis.claims import claims_frame, verdict_counts, write_claims
from analysis.context import Context
from analysis.io import atomic_write_text
from analysis.power import REPORT_MAX_SEEDS, REPORT_SIMS, next_runs_paragraph, write_power
from analysis.report_model import ReportModel, build_model
from analysis.tables import TableOutput, to_markdown
from analysis.verify import (
    ADVANTAGE_NOTE,
    VerdictRow,
    advantage_display,
    verdict_caption,
    verdict_display,
    verdict_notes,
    write_verdicts,
)
from paper_figures.catalog import resolve, sorted_ids
from paper_figures.report_figures import ReportFigures, draw_report
from paper_figures.verify_plot import caption as verify_caption

PACKAGES = ("numpy", "pandas", "scipy", "rliable", "arch", "scikit-learn", "matplotlib", "seaborn", "torch",
            "taco-repro")


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True, text=True,
                             timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


def _version(pkg: str) -> str:
    try:
        return importlib.metadata.version(pkg)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def tool_provenance() -> dict[str, str]:
    """Git sha (and dirty flag) of this checkout, Python, platform and package versions."""
    info = {"analysis git sha": _git("rev-parse", "HEAD") or "unknown"}
    status = _git("status", "--porcelain")
    info["analysis git dirty"] = "unknown" if status is None else str(bool(status))
    info["python"] = platform.python_version()
    info["platform"] = platform.platform()
    for pkg in PACKAGES:
        try:
            info[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            info[pkg] = "not installed"
    return info


def runs_provenance(ctx: Context) -> pd.DataFrame:
    """Runs grouped by experiment, git sha, dirty flag, device and host, with counts."""
    runs = ctx.results.runs
    if runs.empty:
        return pd.DataFrame()
    cols = ["experiment", "git_sha", "git_dirty", "device", "cpu", "host", "versions"]
    present = [c for c in cols if c in runs.columns]
    g = runs.fillna({c: "unknown" for c in present}).astype({c: str for c in present})
    g = g.groupby(present).agg(runs=("run_id", "count"), done=("status", lambda s: int((s == "done").sum())))
    return g.reset_index()


def _section(title: str, body: str) -> str:
    return f"\n## {title}\n\n{body.strip()}\n"


def build_markdown(ctx: Context, artifacts, verdicts, findings,
                   calibration: tuple[list[CalibrationRow], list[str]] | None = None,
                   power: tuple[TableOutput, str] | None = None, verify: Sequence[VerdictRow] = ()) -> str:
    """REPORT.md: the header, the claims, the claims' power and what to run next, the audit, the calibration,
    `repro verify`'s verdicts (when verify runs exist), every artifact and the provenance."""
    lines = _header(ctx, verdicts, findings)
    lines.append(_claims_section(ctx, verdicts))
    if power is not None:
        table, next_runs = power
        lines.append(_section("Statistical power of the claims and what to run next",
                              f"{next_runs}\n\n{table.markdown()}\nFiles: "
                              + ", ".join(f"[{p.suffix[1:]}]({p.name})" for p in table.files)
                              + "; the truth assumed per cell: [plan_power_cells.md](plan_power_cells.md). "
                              "`repro plan --claims` adds what the seeds for 80% cost on your hardware."))
    lines += _audit_sections(findings)
    if calibration is not None:
        lines.append(_calibration_section(ctx, *calibration))
    if verify:
        lines.append(_verify_section(verify))
    lines += [_artifact_section(art) for art in artifacts]
    lines.append(_provenance_section(ctx))
    return "\n".join(lines) + "\n"


def _budget_words(ctx: Context) -> str:
    """The tables' budget with its unit and the action repeats of the online runs beside it: '1M env. frames (action
    repeat 2)' (issue 52: a budget never without its unit)."""
    if ctx.budget_label is not None or ctx.results.runs.empty:
        return ctx.budget_text()
    runs = ctx.results.runs
    return ctx.frames_budget(runs[runs["dataset"].isna()]).text()


def _header(ctx: Context, verdicts, findings) -> list[str]:
    """The title, what the scores are, what was loaded, and the claim and audit counts."""
    res = ctx.results
    lines = ["# TACO reproduction report", "",
             f"Generated {dt.datetime.now().astimezone().isoformat(timespec='seconds')} from `{res.root}`; "
             f"scores at {_budget_words(ctx)}; bootstrap: {ctx.reps:,} repetitions, random state {ctx.seed}; "
             "std over seeds with ddof=1.",
             "", f"Interval estimator: {ESTIMATOR} (rliable {_version('rliable')})."]
    if res.empty:
        lines.append("\n**No runs were found under the results root: every table and figure shows the paper's "
                     "reported numbers only, and every claim is 'not enough data'.**")
    else:
        lines.append(f"\n{len(res.runs)} runs loaded ({int((res.runs['status'] == 'done').sum())} done); "
                     f"{len(res.problems)} problem files (listed under Provenance).")
    n_bad = len(mismatches(findings))
    lines.append(f"\n**Claims:** {verdict_counts(verdicts)}. **Audit of the paper's own numbers:** {n_bad} "
                 "mismatches.")
    return lines


def _claims_section(ctx: Context, verdicts) -> str:
    claims_note = ("Each claim is judged at its own budget (column Budget, from analysis/claim_budgets.csv, not "
                   f"from the runs; the tables below use {_budget_words(ctx)}) and only from cells with at least the "
                   "seeds in column Seeds that reached it; otherwise the verdict is 'not enough data' with the "
                   "reason.")
    if any(v.indicative for v in verdicts):
        claims_note += (" Entries marked 'indicative' are readings below a claim's budget or seed count, asked for "
                        "with --indicative: they are not verdicts.")
    return _section("Claims", claims_note + "\n\n" + to_markdown(claims_frame(verdicts)))


def _audit_sections(findings) -> list[str]:
    """The paper's derived numbers that do not recompute, and its DrQ-v2 baseline against the published curves."""
    bad = [f for f in findings if f.kind == "check" and not f.match]
    audit_md = to_markdown(
        pd.DataFrame(
            {
                "Where": [f.where for f in bad],
                "What": [f.description for f in bad],
                "Paper prints": [f.printed for f in bad],
                "Recomputed": [f.recomputed for f in bad],
            }
        )
    )
    sections = [
        _section(
            "Audit: mismatches in the paper's derived numbers",
            audit_md + f"\nAll {len(findings)} checks, including those that agree: [audit.md](audit.md).",
        )
    ]
    if published_rows(findings):
        sections.append(_section("Audit: the paper's DrQ-v2 baseline against the published curves",
                                 published_summary(findings) + "\n\n" + to_markdown(published_frame(findings))))
    return sections


def _calibration_section(ctx: Context, rows: list[CalibrationRow], notes: list[str]) -> str:
    cal = (to_markdown(calibration_frames(rows)[1]) if rows else
           "No DrQ-v2 runs under the results root: nothing to calibrate (run DrQ-v2 at any budget, e.g. "
           "100K frames, to see whether it sits where the published curve sits).\n")
    cal += "".join(f"\n_{n}_\n" for n in calibration_notes(ctx.reps, ctx.seed, notes))
    return _section("Baseline calibration: your DrQ-v2 against the DrQ-v2 authors' published curves",
                    cal + "\nFiles: [csv](calibration.csv), [md](calibration.md), [tex](calibration.tex)")


def _verify_section(rows: Sequence[VerdictRow]) -> str:
    body = f"{verdict_caption(rows)}\n\n" + to_markdown(verdict_display(rows))
    body += "".join(f"\n_{n}_\n" for n in verdict_notes())
    adv = advantage_display(rows)
    if not adv.empty:
        body += ("\nEarly advantage against the published DrQ-v2 seeds (an observation at a small budget, not a "
                 "verdict):\n\n" + to_markdown(adv) + f"\n_{ADVANTAGE_NOTE}_\n")
    return _section("repro verify: does this installation learn as the DrQ-v2 authors' code did?",
                    body + f"\n_{verify_caption()}_\n\n![verify](verify.png)  \n[PDF](verify.pdf); tables: "
                    "[verify.md](verify.md), [verify_frames.md](verify_frames.md), "
                    "[verify_advantage.md](verify_advantage.md)")


def _artifact_section(art) -> str:
    """One table or figure: caption, images with their PDF, tables with their files, and its other notes."""
    body = [f"_{art.caption}_", ""] if art.figures else []
    for png in art.figures:
        body.append(f"![{art.id}]({png.name})  \n[PDF]({png.with_suffix('.pdf').name})")
    for table in art.tables:
        body.append(table.markdown())
        body.append(f"Files: {', '.join(f'[{p.suffix[1:]}]({p.name})' for p in table.files)}")
    extra = [n for n in art.notes if all(n not in t.notes for t in art.tables)]
    body += [f"_{n}_" for n in extra]
    return _section(f"{art.id}: {art.title}", "\n\n".join(body))


def _provenance_section(ctx: Context) -> str:
    """This analysis' versions, the runs' provenance (meta.json) and every problem file."""
    res = ctx.results
    prov = tool_provenance()
    prov_md = to_markdown(pd.DataFrame({"Item": list(prov), "Value": list(prov.values())}))
    runs_md = to_markdown(runs_provenance(ctx)) if not res.empty else "No runs.\n"
    probs = "\n".join(f"- `{p.path}`: {p.level}: {p.message}" for p in res.problems) or "None."
    return _section("Provenance", f"### This analysis\n\n{prov_md}\n### Runs (from meta.json)\n\n{runs_md}\n"
                                  f"### Problem files (skipped or used with a caveat)\n\n{probs}\n")


_CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}th,td{border:1px solid #ccc;padding:3px 6px}
th{background:#f2f2f2}img{max-width:100%}code{background:#f5f5f5}"""


_IMAGE_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".svg": "image/svg+xml",
                ".gif": "image/gif"}
_IMG_SRC = re.compile(r'(<img\b[^>]*?\bsrc=")([^"]+)(")')
SELF_CONTAINED_NOTE = ("One self-contained file: every figure is embedded in it (PNG, base64); the links to the "
                       "CSV, LaTeX and PDF files work where it sits beside them, in the folder `repro report` wrote.")


def embed_images(page: str, base: Path) -> str:
    """``page`` with every ``<img src>`` that names a file under ``base`` replaced by that file as a data URI (the
    file's bytes, base64): the page shows its figures wherever it is opened. An image ``base`` lacks keeps its
    link (tests/test_report_html.py fails on it)."""

    def data_uri(match: re.Match[str]) -> str:
        src = html.unescape(match.group(2))
        if src.startswith("data:") or "://" in src:
            return match.group(0)
        path = base / src
        mime = _IMAGE_TYPES.get(path.suffix.lower())
        if mime is None or not path.is_file():
            return match.group(0)
        encoded = base64.b64encode(path.read_bytes()).decode("ascii")
        return f"{match.group(1)}data:{mime};base64,{encoded}{match.group(3)}"

    return _IMG_SRC.sub(data_uri, page)


def markdown_to_html(md: str, title: str = "TACO reproduction report", base: Path | None = None) -> str:
    """Render the report's Markdown (GFM tables) to a standalone HTML page; with ``base`` (the folder the Markdown's
    images are in) every figure is embedded as a data URI (:func:`embed_images`), so the page is one file."""
    from markdown_it import MarkdownIt

    body = MarkdownIt("commonmark", {"html": False}).enable("table").render(md)
    if base is not None:  # the note under the title
        note = f"<p><em>{html.escape(SELF_CONTAINED_NOTE)}</em></p>\n"
        body = embed_images(body, Path(base))
        body = body.replace("</h1>\n", "</h1>\n" + note, 1) if "</h1>\n" in body else note + body
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body>\n{body}</body></html>\n")


def build_report(ctx: Context, progress: Callable[[str], None] | None = None) -> tuple[Path, Path]:
    """The report of ``ctx`` in ``ctx.out_dir``: its model built once (analysis/report_model.py), every artifact and
    the verify figure drawn from it (paper_figures), then its sections' files and REPORT.md/.html written."""
    model = build_model(ctx, REPORT_SIMS, REPORT_MAX_SEEDS)
    figures = draw_report(ctx, model, resolve(sorted_ids()), progress)
    return write_report(ctx, model, figures)


def write_report(ctx: Context, model: ReportModel, figures: ReportFigures) -> tuple[Path, Path]:
    """Write ``model``'s sections into ``ctx.out_dir`` (claims, audit, calibration, verify's tables, power) and
    REPORT.md/.html with ``figures``; returns the two report paths."""
    write_claims(ctx, model.verdicts)
    write_audit(ctx.out_dir, list(model.findings))
    write_calibration(ctx.out_dir, model.calibration, model.calibration_notes, ctx.reps, ctx.seed)
    if model.verify.rows:
        write_verdicts(ctx.out_dir, model.verify.rows)
    power_table, _ = write_power(ctx.out_dir, model.power, model.sims, ctx.seed, model.max_seeds,
                                 conditioned=model.conditioned)
    md = build_markdown(ctx, figures.artifacts, model.verdicts, model.findings,
                        (list(model.calibration), list(model.calibration_notes)),
                        (power_table, next_runs_paragraph(model.power, model.max_seeds)), model.verify.rows)
    md_path = atomic_write_text(ctx.out_dir / "REPORT.md", md)
    html_path = atomic_write_text(ctx.out_dir / "REPORT.html", markdown_to_html(md, base=ctx.out_dir))
    return md_path, html_path
