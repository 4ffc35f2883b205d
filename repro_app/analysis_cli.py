"""``repro figures | claims | audit | calibrate | report``: commands added to the Typer app by :func:`register`.

Bad input (unknown artifact id, missing results root, bad option) prints one line and exits non-zero.
"""

from __future__ import annotations

import contextlib
import inspect
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

import typer

from analysis.defaults import DEFAULT_REPS, DEFAULT_SEED
from repro.runs.console import fail
from repro.runs.fsutil import writable_folder

if TYPE_CHECKING:
    from analysis.context import Context

DEFAULT_RESULTS = Path("runs")
RESULTS_OPT = typer.Option(DEFAULT_RESULTS, "--results", "-r", help="Results root holding the run directories.")
OUT_OPT = typer.Option(Path("results/report"), "--out", "-o", help="Folder for tables, figures and reports.")
FRAMES_OPT = typer.Option(1_000_000, "--frames", help="Frame budget of 'score at N frames' (the paper: 1M).")
REPS_OPT = typer.Option(DEFAULT_REPS, "--reps", help="Bootstrap repetitions (rliable's default 50,000).")
SEED_OPT = typer.Option(DEFAULT_SEED, "--seed", help="Random state of the bootstrap and t-SNE.")
MIN_SEEDS_OPT = typer.Option(2, "--min-seeds", help="Seeds a cell needs before a claim gets a verdict (raises, never "
                             "lowers, each claim's own minimum in analysis/claim_budgets.csv).")
INDICATIVE_OPT = typer.Option(False, "--indicative", help="For claims whose runs fall short of the claim's budget or "
                              "seed count, add a labelled indicative reading at the frames the runs reach (never "
                              "a supported/refuted verdict).")
MAP_OPT = typer.Option(
    None, "--experiment-map", "-x",
    help="Read a canonical experiment from other experiment names, e.g. -x main=tiny (repeatable).",
)
TSNE_OPT = typer.Option(1000, "--tsne-n", help="Noisy copies per centroid in F6 (the paper: 1000).")
RENDER_OPT = typer.Option(
    True, "--render-envs/--no-render-envs",
    help="F13: render random-action frames with make_env when no run saved frames.",
)
CACHE_OPT = typer.Option(True, "--cache/--no-cache",
                         help="Reuse what an earlier command computed from unchanged runs (OUT/.cache; "
                              "--no-cache recomputes everything and writes no cache).")
PUBLISHED_OPT = typer.Option(True, "--published/--no-published",
                             help="F4: draw the DrQ-v2 authors' published curve (mean, 95% CI band) beside the runs.")


def _experiment_map(items: Optional[list[str]]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for item in items or []:
        if "=" not in item:
            fail(f"--experiment-map expects CANONICAL=ACTUAL[,ACTUAL...], got {item!r}")
        key, value = item.split("=", 1)
        out.setdefault(key.strip(), []).extend(v.strip() for v in value.split(",") if v.strip())
    return out


def _load_results(results: Path):
    """The runs under the results root, or one line and exit 2."""
    from analysis.load import ResultsRootError, load_results

    try:
        return load_results(results)
    except ResultsRootError as exc:
        fail(f"{exc} (pass --results ROOT)")


def make_context(results: Path, out: Path, frames: int, reps: int, seed: int, min_seeds: int = 2,
                 experiment_map: Optional[list[str]] = None, tsne_n: int = 1000, render_envs: bool = True,
                 published: bool = True):
    """Load the results root into a Context, or fail with one line."""
    from analysis.context import Context

    if frames <= 0 or reps <= 0 or tsne_n <= 1 or min_seeds < 1:
        fail("--frames and --reps must be positive, --tsne-n > 1 and --min-seeds >= 1")
    if results == DEFAULT_RESULTS and not results.exists():
        # A fresh checkout before any training: show the paper-only view rather than an error.
        results.mkdir(parents=True, exist_ok=True)
    loaded = _load_results(results)
    return Context(results=loaded, out_dir=out, budget=frames, reps=reps, seed=seed, min_seeds=min_seeds,
                   experiment_map=_experiment_map(experiment_map), tsne_n=tsne_n, render_envs=render_envs,
                   published_band=published)


def summarize_load(ctx) -> None:
    """One line on what was loaded, and every problem file."""
    res = ctx.results
    if res.empty:
        typer.echo(f"No runs found under {res.root}: rendering the paper-only view (the paper's reported numbers).")
    else:
        done = int((res.runs["status"] == "done").sum())
        typer.echo(f"Loaded {len(res.runs)} runs ({done} done) from {res.root}; budget {ctx.budget_text()}.")
        from analysis.claim_budget import unread_hints

        for hint in unread_hints(ctx.scores, ctx.experiment_map):
            typer.echo(f"  Hint: {hint[0].upper()}{hint[1:]} (no claim reads these experiment names).")
    for problem in res.problems:
        typer.echo(f"  {problem}", err=True)


@dataclass(frozen=True)
class ContextOptions:
    """The options ``figures``, ``claims`` and ``report`` share (each names its own subset, see
    :func:`_context_options`; an option a command lacks takes its default from :data:`CONTEXT_OPTIONS`)."""

    results: Path
    out: Path
    frames: int
    reps: int
    seed: int
    min_seeds: int
    experiment_map: Optional[list[str]]
    tsne_n: int
    render_envs: bool
    indicative: bool
    published: bool
    cache: bool

    @contextlib.contextmanager
    def opened_cache(self, prune: bool = False) -> Iterator[None]:
        """The command's cache (analysis/cache.py) of ``--out``, or an in-memory one with ``--no-cache``; a line
        on what it reused. ``prune``: the command uses all a report needs, so what it did not use is dropped. A
        ``--out`` it cannot write is one line, exit 2, before anything is written."""
        from analysis.cache import opened

        writable_folder(self.out, "--out")
        with opened(self.out if self.cache else None, prune) as cache:
            yield
        if self.cache:
            typer.echo(f"Cache ({self.out / '.cache'}): {cache.summary() or 'nothing computed'}")

    def load(self) -> Context:
        """The results root loaded into a Context (or one line and exit 2), and a line on what was loaded."""
        ctx = make_context(self.results, self.out, self.frames, self.reps, self.seed, self.min_seeds,
                           self.experiment_map, self.tsne_n, self.render_envs, self.published)
        ctx.indicative = self.indicative
        summarize_load(ctx)
        return ctx


# Each shared option once: its parameter name (a field of ContextOptions), type and typer definition, in the
# order the commands list them.
CONTEXT_OPTIONS: dict[str, tuple[Any, Any]] = {
    "results": (Path, RESULTS_OPT),
    "out": (Path, OUT_OPT),
    "frames": (int, FRAMES_OPT),
    "reps": (int, REPS_OPT),
    "seed": (int, SEED_OPT),
    "min_seeds": (int, MIN_SEEDS_OPT),
    "experiment_map": (Optional[list[str]], MAP_OPT),
    "tsne_n": (int, TSNE_OPT),
    "render_envs": (bool, RENDER_OPT),
    "indicative": (bool, INDICATIVE_OPT),
    "published": (bool, PUBLISHED_OPT),
    "cache": (bool, CACHE_OPT),
}


def _context_options(*names: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """A command body ``f(<own parameters>, opts: ContextOptions)`` as a Typer command whose options are its own
    parameters followed by the shared options ``names`` (in :data:`CONTEXT_OPTIONS` order), gathered into
    ``opts``."""
    unknown = set(names) - set(CONTEXT_OPTIONS)
    assert not unknown, f"not shared options: {unknown}"
    shared = [n for n in CONTEXT_OPTIONS if n in names]

    def wrap(body: Callable[..., None]) -> Callable[..., None]:
        *own, last = inspect.signature(body, eval_str=True).parameters.values()
        assert last.name == "opts", f"{body.__name__}: the last parameter takes the ContextOptions"

        def command(**kwargs: Any) -> None:
            values = {n: kwargs[n] if n in shared else option.default for n, (_, option) in CONTEXT_OPTIONS.items()}
            body(**{p.name: kwargs[p.name] for p in own}, opts=ContextOptions(**values))

        command.__name__, command.__qualname__, command.__doc__ = body.__name__, body.__qualname__, body.__doc__
        command.__signature__ = inspect.Signature(  # type: ignore[attr-defined]  # read by typer via inspect
            [*own, *(inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=CONTEXT_OPTIONS[n][1],
                                       annotation=CONTEXT_OPTIONS[n][0]) for n in shared)],
            return_annotation=None)
        return command

    return wrap


@_context_options("results", "out", "frames", "reps", "seed", "experiment_map", "tsne_n", "render_envs", "published",
                  "cache")
def figures_cmd(
    ids: Optional[list[str]] = typer.Argument(None, help="Artifact ids, e.g. F8 T1 (F7 = F7a F7b)."),
    all_: bool = typer.Option(False, "--all", help="Render every table and figure."),
    list_: bool = typer.Option(False, "--list", help="List the artifact ids and exit."),
    *,
    opts: ContextOptions,
) -> None:
    """Render the paper's tables (CSV, Markdown, LaTeX) and figures (PNG, PDF) from the runs."""
    from paper_figures.render import render_artifacts

    if list_:
        _list_artifacts()
        return
    arts = _artifacts(ids, all_)
    with opts.opened_cache():
        ctx = opts.load()
        done = render_artifacts(ctx, arts, progress=lambda aid: typer.echo(f"  rendering {aid}"))
    for r in done:
        files = [p.name for p in r.figures] + [t.files[0].stem + ".{csv,md,tex}" for t in r.tables]
        flag = "" if r.has_runs else " (no run data used)"
        typer.echo(f"{r.id}: {', '.join(files)}{flag}")
    typer.echo(f"Wrote {len(done)} artifacts to {opts.out}")


def _list_artifacts() -> None:
    """``figures --list``: one line per artifact id."""
    from paper_figures.catalog import sorted_ids
    from paper_figures.registry import REGISTRY

    for aid in sorted_ids():
        a = REGISTRY[aid]
        typer.echo(f"{aid:<4} {a.kind:<6} {a.paper_label:<32} {a.title}")


def _artifacts(ids: Optional[list[str]], all_: bool) -> list:
    """The artifacts ``figures`` is asked for (every one with --all), or one line and exit 2."""
    from paper_figures.catalog import resolve, sorted_ids

    if not all_ and not ids:
        fail("name artifact ids (e.g. 'repro figures F8 T1'), or pass --all or --list")
    return resolve(sorted_ids() if all_ else (ids or []))  # ids is set unless --all


@_context_options("results", "out", "frames", "reps", "seed", "min_seeds", "experiment_map", "tsne_n", "indicative",
                  "cache")
def claims_cmd(*, opts: ContextOptions) -> None:
    """A verdict (supported / refuted / not enough data) on each claim of the paper, with its numbers."""
    from analysis.claims import evaluate_claims, write_claims

    with opts.opened_cache():
        ctx = opts.load()
        verdicts = evaluate_claims(ctx)
    for v in verdicts:
        typer.echo(f"{v.id:<26} {v.shown:<16} {v.evidence}")
    table = write_claims(ctx, verdicts)
    typer.echo(f"Wrote {', '.join(str(p) for p in table.files)}")


def audit_cmd(
    out: Path = OUT_OPT,
    show_all: bool = typer.Option(False, "--all", help="Also list the checks that agree."),
) -> None:
    """Recompute the paper's derived numbers from its own tables and list every mismatch."""
    from analysis.audit import mismatches, published_rows, published_summary, run_audit, write_audit

    writable_folder(out, "--out")
    findings = run_audit()
    bad = mismatches(findings)
    for f in findings if show_all else bad:
        if f.kind == "published":
            continue
        status = "MISMATCH" if f in bad else ("ok" if f.kind == "check" else "info")
        typer.echo(f"{status:<8} [{f.where}] {f.description}: paper {f.printed} | recomputed {f.recomputed}")
    typer.echo("The paper's DrQ-v2 baseline against the DrQ-v2 authors' published curves (1M frames):")
    for f in published_rows(findings):
        status = "inside" if f.match else "OUTSIDE"
        typer.echo(f"{status:<8} {f.description.split(':')[0]}: paper {f.printed} | {f.recomputed}")
    table = write_audit(out, findings)
    typer.echo(
        f"{len(bad)} mismatches in {sum(f.kind == 'check' for f in findings)} checks; "
        f"{published_summary(findings)} Wrote {table.files[1]}"
    )


def calibrate_cmd(
    results: Path = RESULTS_OPT,
    out: Path = OUT_OPT,
    reps: int = REPS_OPT,
    seed: int = SEED_OPT,
    at: Optional[int] = typer.Option(None, "--frames", help="Read every cell at this frame (default: each "
                                     "cell's own budget, the last frame all its runs reach)."),
) -> None:
    """Your DrQ-v2 runs against the DrQ-v2 authors' published curves at your runs' own budget (any budget)."""
    from analysis.calibration import ABOUT_TEXT, INTERP_TEXT, calibrate, write_calibration

    if reps <= 0 or (at is not None and at < 0):
        fail("--reps must be positive and --frames >= 0")
    writable_folder(out, "--out")
    loaded = _load_results(results)
    for problem in loaded.problems:
        typer.echo(f"  {problem}", err=True)
    rows, notes = calibrate(loaded, reps=reps, seed=seed, at=at)
    typer.echo(ABOUT_TEXT)
    if not rows:
        typer.echo(f"No DrQ-v2 runs under {results}: nothing to calibrate.")
    for r in rows:
        typer.echo(f"{r.task:<18} {r.experiment}/{r.variant} at {r.frame:,.0f} frames: yours {r.user_mean:.1f} "
                   f"(n={r.user_n}) vs published {r.published_mean:.1f} (n={r.published_n}): {r.reading}"
                   + (f" ({r.note})" if r.note else ""))
    for note in notes:
        typer.echo(f"  {note}")
    table = write_calibration(out, rows, notes, reps, seed)
    typer.echo(f"Reading: 95% bootstrap CI of the difference of means (yours − published) below 0, above 0, or "
               f"across it; {INTERP_TEXT}. Wrote {', '.join(str(p) for p in table.files)}")


@_context_options("results", "out", "frames", "reps", "seed", "min_seeds", "experiment_map", "tsne_n", "render_envs",
                  "indicative", "published", "cache")
def report_cmd(*, opts: ContextOptions) -> None:
    """Render everything and write REPORT.md and REPORT.html (tables, figures, claims, audit, provenance)."""
    from repro_app.report import build_report

    with opts.opened_cache(prune=True):
        ctx = opts.load()
        md, html = build_report(ctx, progress=lambda aid: typer.echo(f"  rendering {aid}"))
    typer.echo(f"Wrote {md} and {html}")


def register(app: typer.Typer) -> None:
    """Add ``figures``, ``claims``, ``audit``, ``calibrate`` and ``report`` to ``app``."""
    for name, command in (("figures", figures_cmd), ("claims", claims_cmd), ("audit", audit_cmd),
                          ("calibrate", calibrate_cmd), ("report", report_cmd)):
        app.command(name)(command)
