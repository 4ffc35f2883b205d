"""Every repository path that code or docs name (``docs/...``, ``tests/data/.../README.md``) exists.

A path is checked when its first component is a folder of the repository (:data:`REPO_DIRS`) or it is
``README.md``; URLs, paths outside the repository (``../shared/...``), absolute paths, glob patterns and
placeholders (``{name}.md``, ``<run>/...``) are not. A bare file name with no folder (``REPORT.md``,
``T1.md``) names an output the code writes, not a file of the repository, and is not checked either.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The tracked top-level folders: a path that starts with one of them points into the repository.
REPO_DIRS = ("docs", "repro", "repro_data", "analysis", "paper_figures", "repro_app", "benchmarks", "tests", "scripts",
             "sweeps")
SCANNED_DIRS = ("repro", "repro_data", "analysis", "paper_figures", "repro_app", "benchmarks", "tests", "sweeps")
SCANNED_SUFFIXES = (".py", ".yaml", ".yml", ".md", ".txt", ".toml", ".sh")
SKIPPED_DIRS = frozenset({"__pycache__", ".pytest_cache", ".mypy_cache", ".ruff_cache"})
# A run of path characters (placeholders and glob characters included, so that a pattern is seen whole).
_TOKEN = re.compile(r"[\w.~/{}*?<>\[\]-]+")
_PATTERN_CHARS = set("{}*?<>[]~")


def _candidate(token: str, before: str) -> str | None:
    """The repository path ``token`` names, or None when it names none (or one this test does not check)."""
    path = token.rstrip(".")  # a path that ends a sentence
    if before == ":" or path.startswith(("/", "../", "./../")):  # URL, absolute, outside the repository
        return None
    path = path.removeprefix("./")
    if _PATTERN_CHARS & set(path) or not path:
        return None
    first = path.split("/", 1)[0]
    if path == "README.md" or (first in REPO_DIRS and "/" in path and (first == "docs" or path.endswith(".md"))):
        return path
    return None


def named_paths(text: str) -> list[str]:
    """The ``docs/...`` and ``*.md`` repository paths named in ``text``, in order of appearance."""
    out = []
    for match in _TOKEN.finditer(text):
        start = match.start()
        before = text[start - 1] if start else ""
        path = _candidate(match.group(), before)
        if path is not None:
            out.append(path)
    return out


def missing_paths(text: str, root: Path = ROOT) -> list[str]:
    """The paths named in ``text`` that do not exist under ``root``."""
    return [p for p in named_paths(text) if not (root / p).exists()]


def _scanned_files() -> list[Path]:
    """README.md, docs/*.md and the text files of :data:`SCANNED_DIRS`, less this file (its examples name
    missing paths on purpose)."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for folder in SCANNED_DIRS:
        for path in sorted((ROOT / folder).rglob("*")):
            if (path.is_file() and path.suffix in SCANNED_SUFFIXES
                    and not SKIPPED_DIRS.intersection(path.relative_to(ROOT).parts)
                    and path != Path(__file__).resolve()):
                files.append(path)
    return files


def test_named_paths_finds_and_skips():
    text = ("see docs/layers.md, and docs/offline.md. Also `tests/data/v1_runs/README.md` and README.md;\n"
            "not https://github.com/x/y/blob/main/docs/z.md, ../shared/docs/layout.md, docs/*.md,\n"
            "docs/{name}.md, results/tiny/REPORT.md, REPORT.md or /abs/docs/a.md")
    assert named_paths(text) == ["docs/layers.md", "docs/offline.md", "tests/data/v1_runs/README.md", "README.md"]


def test_missing_paths_reports_a_bad_path(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "here.md").write_text("x", encoding="utf-8")
    text = "Read docs/here.md first, then docs/gone.md (and repro/nothere.md)."
    assert missing_paths(text, root=tmp_path) == ["docs/gone.md", "repro/nothere.md"]
    assert missing_paths("docs/here.md", root=tmp_path) == []


def test_repo_dirs_exist():
    assert all((ROOT / d).is_dir() for d in REPO_DIRS)


def test_every_named_path_exists():
    files = _scanned_files()
    assert len(files) > 100  # the scan saw the code, not an empty folder
    bad = []
    for path in files:
        for missing in missing_paths(path.read_text(encoding="utf-8", errors="replace")):
            bad.append(f"{path.relative_to(ROOT)}: {missing}")
    assert not bad, "paths named but not in the repository:\n" + "\n".join(bad)
