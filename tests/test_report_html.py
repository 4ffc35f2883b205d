"""REPORT.html is one self-contained file (issue 52): every figure embedded as a PNG data URI, so that the page
shows them opened alone (mailed, attached), checked in headless Chromium with a screenshot read back
(tests/browser.py). A small report: two cheap artifacts and `repro verify`'s section, from synthetic runs."""

from __future__ import annotations

import base64
from pathlib import Path

import pytest

from analysis import verify as V
from analysis.context import Context
from analysis.load import load_results
from analysis_fixtures import write_run
from browser import check_report_html, image_sources
from paper_figures.catalog import resolve
from paper_figures.render import render_artifacts
from paper_figures.verify_plot import plot_verify
from repro_app.report import SELF_CONTAINED_NOTE, build_markdown, embed_images, markdown_to_html

ARTIFACTS = ("F3", "F7a")  # two figures that render in well under a second without runs


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """REPORT.md and REPORT.html as `repro report` writes them, of two artifacts and a verify section."""
    root = tmp_path_factory.mktemp("report")
    for agent, curve in (("drqv2", [350, 300, 800, 980]), ("taco", [350, 900, 990, 990])):
        write_run(root, experiment="verify", agent=agent, task="cartpole_balance", seed=1, final=0.0, frames=60_000,
                  eval_every=20_000, curve=curve, batch_size=256)
    ctx = Context(results=load_results(root), out_dir=root / "out", budget=60_000, reps=100)
    artifacts = render_artifacts(ctx, resolve(ARTIFACTS))
    judged = V.judgement(ctx.results, random_returns={"cartpole_balance": 300.0})
    V.write_verdicts(ctx.out_dir, judged.rows)
    plot_verify(ctx.results, judged, ctx.out_dir)
    md = build_markdown(ctx, artifacts, [], [], verify=judged.rows)
    (ctx.out_dir / "REPORT.md").write_text(md)
    page = ctx.out_dir / "REPORT.html"
    page.write_text(markdown_to_html(md, base=ctx.out_dir))
    return page


def test_every_figure_is_embedded_as_its_png(report):
    page = report.read_text()
    md = report.with_name("REPORT.md").read_text()
    sources = image_sources(page)
    names = [f"{a}.png" for a in ARTIFACTS] + ["verify.png"]
    assert all(f"]({n})" in md for n in names)  # the Markdown links them: it sits beside them
    assert len(sources) == len(names)
    prefix = "data:image/png;base64,"
    assert all(s.startswith(prefix) for s in sources)
    embedded = {base64.b64decode(s[len(prefix):]) for s in sources}
    assert embedded == {(report.parent / n).read_bytes() for n in names}  # each file's own bytes
    assert SELF_CONTAINED_NOTE in page


def test_embed_images_leaves_what_it_cannot_embed():
    page = ('<p><img src="missing.png" alt="a"><img src="https://example.org/x.png">'
            '<img src="data:image/png;base64,AA"></p>')
    assert embed_images(page, Path("/nonexistent")) == page


def test_report_html_opened_alone_shows_every_figure_in_chromium(report, tmp_path):
    """The page copied alone into an empty folder: Chromium loads and shows each image (its natural size read from
    the embedded PNG, laid out with a size, not hidden), and a screenshot of the images, read back, has each one
    drawn."""
    assert check_report_html(report, tmp_path) == len(ARTIFACTS) + 1
