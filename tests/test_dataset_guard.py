"""Datasets verified wherever they are read, each import format at its documented frame size, files readable
by others, and one line instead of a traceback for every bad input (issue 17)."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from offline_fixtures import make_episode, write_dataset
from repro.config.compose import compose, typed  # noqa: E402
from repro.data import dataset as dataset_mod  # noqa: E402
from repro.data.formats import vd4rl64, vd4rl84  # noqa: E402
from repro.data.offline_replay import DatasetError  # noqa: E402
from repro.runs.fsutil import atomic_write_text  # noqa: E402
from repro.train import build  # noqa: E402
from repro_app.cli import app  # noqa: E402

TINY = ["agent=bc", "task=cheetah_run", "profile=tiny", "seed=2", "runtime.threads=1", "offline.dataset=medium",
        "offline.updates=10", "offline.eval_every_updates=10", "offline.checkpoint_every_updates=5",
        "offline.eval_episodes=0"]


@pytest.fixture(autouse=True)
def _private_cache(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def _root(tmp_path: Path) -> tuple[Path, Path]:
    d = write_dataset(tmp_path / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6)
    return tmp_path, d


def _manifest(d: Path) -> dict:
    return json.loads((d / "manifest.json").read_text())


def _save(d: Path, m: dict) -> None:
    (d / "manifest.json").write_text(json.dumps(m))


def _one_line(out) -> str:
    lines = [ln for ln in out.output.strip().splitlines() if ln]
    assert out.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:"), out.output
    return lines[0]


def _load(root: Path, agent: str = "bc") -> None:
    build.load_dataset(typed(compose([*TINY, f"agent={agent}", f"runtime.results_root={root}"])))


# ----------------------------------------------------------------------------- point 2: train checks what check checks
def test_an_edited_manifest_return_is_refused_by_training(tmp_path: Path):
    root, d = _root(tmp_path)
    m = _manifest(d)
    m["episodes"][1]["return"] = 1000.0
    _save(d, m)
    for agent in ("bc", "dt"):  # replay loading and episode loading (the DT conditions on the best return)
        with pytest.raises(DatasetError, match="return"):
            _load(root, agent)
    line = _one_line(CliRunner().invoke(app, ["train", *TINY, "agent=dt", f"runtime.results_root={root}"]))
    assert "the manifest says 1000" in line
    assert not (root / "default").exists()


def test_an_unlisted_episode_or_an_entry_outside_the_folder_is_refused_by_training(tmp_path: Path):
    root, d = _root(tmp_path)
    extra = d / "episodes" / "ep_0000003.npz"
    extra.write_bytes((d / "episodes" / "ep_0000002.npz").read_bytes())
    with pytest.raises(DatasetError, match="not listed"):
        _load(root)
    extra.unlink()
    m = _manifest(d)
    outside = tmp_path / "outside.npz"
    outside.write_bytes((d / m["episodes"][2]["file"]).read_bytes())
    m["episodes"][2]["file"] = "../../../../outside.npz"
    _save(d, m)
    with pytest.raises(DatasetError, match="expected episodes/ep_0000002.npz"):
        _load(root)


def test_hashes_are_checked_once_then_again_only_for_a_changed_file(tmp_path: Path, monkeypatch):
    root, d = _root(tmp_path)
    hashed: list[str] = []
    real = dataset_mod.read_episode_file

    def spy(path: Path, sha256: str | None = None):
        if sha256 is not None:
            hashed.append(path.name)
        return real(path, sha256)

    monkeypatch.setattr(dataset_mod, "read_episode_file", spy)
    _load(root)
    assert hashed == ["ep_0000000.npz", "ep_0000001.npz", "ep_0000002.npz"]
    hashed.clear()
    _load(root)
    assert hashed == []  # cached by size and mtime
    f = d / "episodes" / "ep_0000001.npz"
    os.utime(f, ns=(f.stat().st_atime_ns, f.stat().st_mtime_ns + 10**9))
    _load(root)
    assert hashed == ["ep_0000001.npz"]


# ----------------------------------------------------------------------------- point 3: documented sizes only
def _episodes(size: int, n: int = 2) -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(0)
    return [make_episode(i, 6, (3, size, size), 6, rng) for i in range(n)]


def _import(src: Path, fmt: str, out: Path, *extra: str):
    return CliRunner().invoke(app, ["dataset", "import", str(src), "--format", fmt, "--task", "cheetah_run",
                                    "--out", str(out), *extra])


def test_the_84_importer_refuses_64px_frames_unless_asked_to_resize(tmp_path: Path):
    src = tmp_path / "h5"
    src.mkdir()
    vd4rl84.write(_episodes(64), src)
    line = _one_line(_import(src, "vd4rl-84", tmp_path / "out" / "a"))
    assert "64x64" in line and "--resize" in line
    assert not (tmp_path / "out" / "a").exists()
    ok = _import(src, "vd4rl-84", tmp_path / "out" / "b", "--resize", "84")
    assert ok.exit_code == 0, ok.output
    m = _manifest(tmp_path / "out" / "b")
    assert m["frame_shape"] == [3, 84, 84] and m["source"]["resized_to"] == 84
    assert m["source"]["image_size"] == [64, 64]


@pytest.mark.parametrize("size", [8, 84])
def test_the_64_importer_takes_64px_frames_only(tmp_path: Path, size: int):
    src = tmp_path / "npz"
    src.mkdir()
    vd4rl64.write(_episodes(32), src, image_size=size)
    line = _one_line(_import(src, "vd4rl-64", tmp_path / "out"))
    assert f"{size}x{size}" in line and not (tmp_path / "out").exists()


@pytest.mark.parametrize("fields, needle", [({"task": "no_such_task"}, "unknown task"),
                                            ({"action_dim": 2}, "action dim 2"),
                                            ({"frame_shape": (3, 8, 8)}, "frame shape [3, 8, 8]")])
def test_check_refuses_what_no_run_could_use(tmp_path: Path, fields: dict, needle: str):
    kw = {"task": "cheetah_run", "action_dim": 6, "frame_shape": (3, 32, 32), **fields}
    d = write_dataset(tmp_path / "d", **kw)
    out = CliRunner().invoke(app, ["dataset", "check", str(d)])
    assert out.exit_code == 2 and needle in out.output, out.output


# ----------------------------------------------------------------------------- point 5: one line, nothing behind
@pytest.mark.parametrize("extra, needle", [(["--seed", "-1"], "--seed must be >= 0"),
                                           (["--device", "tpu"], "unknown device")])
def test_make_bad_seed_or_device_is_one_line(tmp_path: Path, extra: list[str], needle: str):
    out = CliRunner().invoke(app, ["dataset", "make", "--source", str(tmp_path / "run"), "--kind", "medium",
                                   "--out", str(tmp_path / "ds"), *extra])
    assert needle in _one_line(out)
    assert not any(tmp_path.iterdir())


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_cuda_on_a_machine_without_it_is_one_line_and_leaves_nothing(tmp_path: Path):
    out = CliRunner().invoke(app, ["dataset", "make", "--source", str(tmp_path / "run"), "--kind", "medium",
                                   "--device", "cuda"])
    assert "no CUDA device" in _one_line(out)
    for extra in (["runtime.device=cuda"], ["replay.device=cuda"]):
        out = CliRunner().invoke(app, ["train", "task=cheetah_run", "profile=tiny", *extra,
                                       f"runtime.results_root={tmp_path}", "--no-progress"])
        assert "no CUDA device" in _one_line(out)
    assert not any(tmp_path.iterdir())


def test_a_negative_training_seed_is_one_line(tmp_path: Path):
    out = CliRunner().invoke(app, ["train", "task=cheetah_run", "seed=-1", f"runtime.results_root={tmp_path}"])
    assert "seed must be >= 0" in _one_line(out)
    assert not any(tmp_path.iterdir())


# ----------------------------------------------------------------------------- point 6: modes, read-only datasets
def test_files_get_the_umask_mode_not_0600(tmp_path: Path):
    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        d = write_dataset(tmp_path / "d")
        os.umask(0o002)
        atomic_write_text(tmp_path / "b.txt", "x")
    finally:
        os.umask(old)
    mode = lambda p: stat.S_IMODE(p.stat().st_mode)  # noqa: E731
    assert mode(tmp_path / "a.txt") == 0o644 and mode(tmp_path / "b.txt") == 0o664
    assert mode(d / "manifest.json") == 0o644 and mode(d / "episodes" / "ep_0000000.npz") == 0o644


def test_info_prints_the_statistics_when_its_plot_cannot_be_written(tmp_path: Path):
    d = write_dataset(tmp_path / "d")
    (d / "returns.png").mkdir()  # the default plot path cannot be replaced (as in a read-only dataset folder)
    out = CliRunner().invoke(app, ["dataset", "info", str(d)])
    assert out.exit_code == 0, out.output
    assert "episodes     3" in out.output and "histogram    not written" in out.output
