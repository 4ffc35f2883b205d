"""F6's embedding made by the run (tsne.npz, repro/train/action_tsne.py) and read by the report (analysis/tsne.py).

A real tiny TACO run with distracting action dims writes its embedding at its final evaluation; the report uses it
at the same settings (and then computes no t-SNE), and embeds the checkpoint itself otherwise. The run's embedding
is the one the report computes from the run's checkpoint, to the bit (one process)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.context import Context
from analysis.load import load_results
from analysis.tsne import load_step_mlp, run_tsne, tsne_for_context
from helpers import TINY_TACO
from repro.runs import rundir
from repro.runs.runformat import CHECKPOINT, DONE, TSNE
from repro.train import action_tsne, api

N, ITER = 20, 250  # copies per centroid and t-SNE iterations of these tests (the paper's: 1000, 1000)
# 50-frame episodes, a checkpoint at every episode end (so the checkpoint holds the final encoder), 200 frames.
TINY = ["profile=tiny", "task=cheetah_run", "env.image_size=32", "agent.feature_dim=16", "agent.hidden_dim=16",
        "agent.action_hidden_dim=16", "train.save_frames=false", "runtime.threads=1", "env.max_episode_frames=50",
        "train.seed_frames=50", "train.eval_every_frames=100", "train.checkpoint_every_episodes=1",
        "train.frames=200", "experiment=tsne"]


@pytest.fixture(scope="module")
def distracted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny TACO run with 20 distracting action dims, its embedding at N copies and ITER iterations."""
    root = tmp_path_factory.mktemp("tsne_run")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(action_tsne, "PAPER_N", N)
        mp.setattr(action_tsne, "PAPER_ITER", ITER)
        return api.train([*TINY, "env.distracting_dims=20", f"runtime.results_root={root}"], echo=lambda s: None)


def _context(run: Path, out: Path, n: int = N) -> Context:
    root = run.parents[4]
    return Context(results=load_results(root), out_dir=out, tsne_n=n, tsne_iter=ITER, render_envs=False)


def test_the_run_writes_its_final_encoders_embedding(distracted: Path) -> None:
    saved = action_tsne.read_tsne(distracted)
    assert saved is not None and saved.made_with(N, action_tsne.PAPER_SEED, ITER)
    assert saved.frame == json.loads((distracted / DONE).read_text())["frame"] == 200
    res = saved.result
    assert (res.true_dim, res.distracting_dims) == (6, 20)
    assert res.raw_2d.shape == res.latent_2d.shape == (4 * N, 2)  # type: ignore[union-attr]
    # what the report computes from the checkpoint the run ended with: the run embedded its final encoder
    again = run_tsne(6, 20, load_step_mlp(distracted / CHECKPOINT), n=N, seed=action_tsne.PAPER_SEED, max_iter=ITER)
    assert np.array_equal(again.raw_2d, res.raw_2d) and np.array_equal(again.latent_2d, res.latent_2d)
    assert again.silhouette_latent_2d == res.silhouette_latent_2d and again.silhouette_raw == res.silhouette_raw


@pytest.mark.xdist_group(TINY_TACO)  # the session run: trained once, on that group's worker
def test_a_run_without_distracting_dims_writes_none(tiny_taco: Path) -> None:
    assert not (tiny_taco / TSNE).exists()


def test_the_report_reads_the_runs_embedding_and_computes_none(distracted: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    def no_tsne(*args: object, **kwargs: object) -> np.ndarray:
        raise AssertionError("t-SNE computed although the run's embedding was there")

    monkeypatch.setattr(action_tsne, "tsne_2d", no_tsne)
    res, info = tsne_for_context(_context(distracted, tmp_path))
    assert info["source"] == "run" and info["frame"] == 200 and info["run_id"].endswith("seed_1")
    assert np.array_equal(res.latent_2d, action_tsne.read_tsne(distracted).result.latent_2d)  # type: ignore[union-attr]


@pytest.mark.parametrize("change", ["other_n", "extended", "torn"])
def test_the_report_embeds_the_checkpoint_when_the_runs_embedding_does_not_fit(
        distracted: Path, tmp_path: Path, change: str) -> None:
    """Another --tsne-n, an embedding older than the run's end (DONE at another frame), an unreadable file: the
    report embeds the checkpoint itself."""
    run = tmp_path / "results" / distracted.relative_to(distracted.parents[4])
    run.mkdir(parents=True)
    for f in distracted.iterdir():
        if f.is_file():
            (run / f.name).write_bytes(f.read_bytes())
    n = N + 1 if change == "other_n" else N
    if change == "extended":
        rundir.write_done(run, {**json.loads((run / DONE).read_text()), "frame": 400}, 400)
    if change == "torn":
        (run / TSNE).write_bytes((run / TSNE).read_bytes()[:100])
    res, info = tsne_for_context(_context(run, tmp_path / "out", n))
    assert info["source"] == "report" and info["run_id"] is not None
    assert res.n_per_centroid == n and res.latent_2d is not None
