"""Headless Chromium for the report's HTML tests (tests/test_report_html.py, tests/test_reproduce.py): which images a
page shows as Chromium loads it, and a screenshot of those images read back, so that a test sees what a reader sees.

Chromium is Debian's ``chromium-headless-shell`` (or ``chromium``; `make test` installs the former where it can, the
Makefile's ``browser`` target); a test that needs it is skipped where neither is installed.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

NAMES = ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--virtual-time-budget=10000")
IMG_SRC = re.compile(r'<img\b[^>]*?\bsrc="([^"]+)"')
CELL = (240, 180)  # one image's cell in the screenshot, pixels

# Appended to a copy of the page: once it has loaded, every <img> as Chromium holds it, in a <pre id="probe">.
PROBE = """<script>addEventListener("load", () => {
  const rows = [...document.images].map(i => {
    const r = i.getBoundingClientRect(), s = getComputedStyle(i);
    return {src: i.getAttribute("src").slice(0, 40), complete: i.complete, width: i.naturalWidth,
            height: i.naturalHeight, shown_width: r.width, shown_height: r.height,
            hidden: s.display === "none" || s.visibility === "hidden" || s.opacity === "0"};
  });
  const pre = document.createElement("pre"); pre.id = "probe"; pre.textContent = JSON.stringify(rows);
  document.body.appendChild(pre);
});</script>"""


def chromium() -> str:
    """The Chromium executable; skips the calling test when there is none."""
    for name in NAMES:
        found = shutil.which(name)
        if found:
            return found
    pytest.skip("no headless Chromium (apt-get install chromium-headless-shell; `make browser`)")


def _run(args: list[str]) -> str:
    out = subprocess.run([chromium(), *FLAGS, *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def image_sources(page: str) -> list[str]:
    """The ``src`` of every ``<img>`` of an HTML page, as written."""
    return [html.unescape(s) for s in IMG_SRC.findall(page)]


def loaded_images(page: Path, work: Path) -> list[dict]:
    """Every ``<img>`` of ``page`` once Chromium has loaded it (a copy with :data:`PROBE` in ``work``, so that only
    what the page itself holds can load): src (its start), complete, natural width and height, shown width and
    height, hidden."""
    probed = work / "probe.html"
    probed.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    dom = _run(["--dump-dom", probed.as_uri()])
    found = re.search(r'<pre id="probe">(.*?)</pre>', dom, re.S)
    assert found, dom[-2000:]
    return json.loads(html.unescape(found.group(1)))


def screenshot_images(sources: list[str], work: Path) -> list[np.ndarray]:
    """A screenshot (Chromium) of a page that shows each of ``sources`` in a cell of its own, read back: one RGB
    array per image, cut from the screenshot where Chromium drew it."""
    import matplotlib.image as mpimg

    cols = max(1, min(4, len(sources)))
    rows = -(-len(sources) // cols)
    w, h = CELL
    cells = "".join(f'<img src="{html.escape(src)}" style="position:absolute;left:{(i % cols) * w + 5}px;'
                    f'top:{(i // cols) * h + 5}px;width:{w - 10}px;height:{h - 10}px;object-fit:contain">'
                    for i, src in enumerate(sources))
    page = work / "grid.html"
    page.write_text(f"<!DOCTYPE html><html><body style=\"margin:0;background:#fff\">{cells}</body></html>",
                    encoding="utf-8")
    shot = work / "grid.png"
    _run([f"--screenshot={shot}", f"--window-size={cols * w},{rows * h}", page.as_uri()])
    pixels = mpimg.imread(shot)[:, :, :3]
    return [pixels[(i // cols) * h + 5:(i // cols + 1) * h - 5, (i % cols) * w + 5:(i % cols + 1) * w - 5]
            for i in range(len(sources))]


def drawn(cell: np.ndarray) -> bool:
    """Whether a cell of a screenshot shows a figure: enough pixels off the white page, in more than one shade."""
    off_white = (cell < 0.9).any(axis=2)
    return bool(off_white.mean() > 0.005 and cell.std() > 0.02)


def check_report_html(page: Path, work: Path) -> int:
    """The report's HTML opened alone: every figure embedded (a PNG data URI), loaded and shown by Chromium, and
    drawn in a screenshot read back. Returns the number of figures."""
    alone = work / "alone"
    alone.mkdir()
    copy = alone / page.name
    shutil.copy(page, copy)  # nothing beside it: what shows comes from the file itself
    sources = image_sources(copy.read_text(encoding="utf-8"))
    assert sources and all(s.startswith("data:image/png;base64,") for s in sources), \
        [s[:60] for s in sources if not s.startswith("data:")]
    images = loaded_images(copy, alone)
    assert len(images) == len(sources)
    bad = [i for i in images if not (i["complete"] and i["width"] > 0 and i["height"] > 0 and i["shown_width"] > 0
                                     and i["shown_height"] > 0 and not i["hidden"])]
    assert not bad, bad
    blank = [n for n, cell in enumerate(screenshot_images(sources, alone)) if not drawn(cell)]
    assert not blank, f"figures {blank} of {len(sources)} are blank in the screenshot"
    return len(sources)
