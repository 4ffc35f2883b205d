"""Shared test setup: headless rendering, one torch thread, and the runs several test modules check, each
made once per test session (pytest-xdist: the tests that use one are kept on one worker by their
``xdist_group`` mark, so no run is trained twice).

* ``tiny_taco``: the tiny TACO cheetah_run run (seed 3, 400 frames), plain.
* ``tiny_taco_watched``: the same run recorded, with TensorBoard and videos (runtime keys): its logs must equal
  ``tiny_taco``'s (determinism, and neither recording nor watching changes a logged number).
* ``main_job``: `repro reproduce` (the README's main job: tiny online grid, its offline leg, the report).
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

import pytest  # noqa: E402
import torch  # noqa: E402

from helpers import RECORD, TINY, WATCH  # noqa: E402

torch.set_num_threads(1)


def _quiet(_: str) -> None:
    pass


@pytest.fixture(scope="session")
def tiny_taco(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro import api

    return api.train([*TINY, f"runtime.results_root={tmp_path_factory.mktemp('tiny_taco')}"], echo=_quiet)


@pytest.fixture(scope="session")
def tiny_taco_watched(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro import api

    root = tmp_path_factory.mktemp("tiny_taco_watched")
    return api.train([*TINY, *RECORD, *WATCH, f"runtime.results_root={root}"], echo=_quiet)


@dataclass(frozen=True)
class MainJob:
    """What `repro reproduce --results runs --out out` left: its folders and its output."""

    runs: Path
    out: Path
    stdout: str


@pytest.fixture(scope="session")
def main_job(tmp_path_factory: pytest.TempPathFactory) -> MainJob:
    root = tmp_path_factory.mktemp("main_job")
    runs, out = root / "runs", root / "out"
    proc = subprocess.run([sys.executable, "-m", "repro", "reproduce", "--results", str(runs), "--out", str(out),
                           "--max-parallel", "2"], capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return MainJob(runs, out, proc.stdout)
