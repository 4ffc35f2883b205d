"""F6's embedding (fig:tsne_act), made by the run whose action encoder it shows: ``tsne.npz``.

Following the paper (Section 5.1): 4 centroid actions uniform in the true action space, ``n`` copies of each with
standard Gaussian noise in the distracting dimensions; the raw actions and their latent actions (the action
encoder's per-step MLP) are embedded in 2-D with t-SNE (scikit-learn, PCA init) and scored with the silhouette
coefficient of the centroid labels, on the embeddings and on the original spaces.

An online run with an action encoder and ``env.distracting_dims > 0`` embeds its final encoder at its final
evaluation, at the paper's settings (:data:`PAPER_N` copies per centroid, random state :data:`PAPER_SEED`,
:data:`PAPER_ITER` iterations), and writes the result to ``tsne.npz`` (this module owns that file). About 25 s on
one CPU core, once at the end of a run of hours; the report then reads it instead of embedding 8,000 points
itself (``analysis/tsne.py``, which computes it the same way for any other settings or run).
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from repro.runs.fsutil import atomic_write
from repro.runs.runformat import TSNE

N_CENTROIDS = 4
PAPER_N = 1000  # noisy copies per centroid (the paper's 1000; the report's --tsne-n default)
PAPER_SEED = 0  # random state of the actions and of t-SNE (the report's default --seed)
PAPER_ITER = 1000  # t-SNE iterations (scikit-learn's default)
TSNE_FORMAT = 1  # the layout of tsne.npz below

__all__ = ["N_CENTROIDS", "PAPER_ITER", "PAPER_N", "PAPER_SEED", "SavedTsne", "TsneResult", "embed", "encoder_latent",
           "make_actions", "perplexity_for", "read_tsne", "save_final_tsne", "tsne_2d", "write_tsne"]


@dataclass
class TsneResult:
    """Embeddings and cluster scores; the ``latent`` fields are None when no encoder was given."""

    labels: np.ndarray
    raw_2d: np.ndarray
    latent_2d: np.ndarray | None
    silhouette_raw_2d: float
    silhouette_latent_2d: float | None
    silhouette_raw: float
    silhouette_latent: float | None
    n_per_centroid: int
    true_dim: int
    distracting_dims: int


def make_actions(true_dim: int, distracting_dims: int, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """4 centroids uniform in [-1, 1]^true_dim (zero in the distracting dims), n copies each with N(0, 1)
    noise added to the distracting dims. Returns (actions (4n x (true+distracting)), labels)."""
    rng = np.random.default_rng(seed)
    centroids = rng.uniform(-1.0, 1.0, size=(N_CENTROIDS, true_dim))
    blocks = []
    for c in centroids:
        noise = rng.standard_normal((n, distracting_dims))
        blocks.append(np.hstack([np.repeat(c[None, :], n, axis=0), noise]))
    labels = np.repeat(np.arange(N_CENTROIDS), n)
    return np.vstack(blocks).astype(np.float32), labels


def perplexity_for(points: int) -> float:
    """scikit-learn's default perplexity (30), or less for small inputs (it must stay below the points)."""
    return min(30.0, (points - 1) / 3.0)


def tsne_2d(x: np.ndarray, seed: int = 0, max_iter: int = 1000) -> np.ndarray:
    """2-D t-SNE of ``x`` (scikit-learn, PCA init, :func:`perplexity_for`)."""
    from sklearn.manifold import TSNE as SklearnTSNE

    x = np.ascontiguousarray(x)
    return SklearnTSNE(n_components=2, perplexity=perplexity_for(len(x)), init="pca", random_state=seed,
                       max_iter=max_iter).fit_transform(x)


def embed(true_dim: int, distracting_dims: int, latent: Callable[[np.ndarray], np.ndarray] | None = None,
          n: int = PAPER_N, seed: int = PAPER_SEED, max_iter: int = PAPER_ITER,
          embed_2d: Callable[[np.ndarray, int, int], np.ndarray] = tsne_2d) -> TsneResult:
    """Embed the raw actions (and, with ``latent``: actions -> latent actions, theirs) and score the clusters;
    ``embed_2d(points, seed, max_iter)`` is the t-SNE (the report passes its cached one)."""
    from sklearn.metrics import silhouette_score

    actions, labels = make_actions(true_dim, distracting_dims, n, seed)
    raw_2d = embed_2d(actions, seed, max_iter)
    codes = codes_2d = None
    if latent is not None:
        codes = np.asarray(latent(actions))
        codes_2d = embed_2d(codes, seed, max_iter)
    return TsneResult(
        labels=labels,
        raw_2d=raw_2d,
        latent_2d=codes_2d,
        silhouette_raw_2d=float(silhouette_score(raw_2d, labels)),
        silhouette_latent_2d=None if codes_2d is None else float(silhouette_score(codes_2d, labels)),
        silhouette_raw=float(silhouette_score(actions, labels)),
        silhouette_latent=None if codes is None else float(silhouette_score(codes, labels)),
        n_per_centroid=n,
        true_dim=true_dim,
        distracting_dims=distracting_dims,
    )


def encoder_latent(encoder: Any) -> Callable[[np.ndarray], np.ndarray]:
    """actions -> latent actions through an action encoder's per-step MLP (a torch module taking (N, |A|)), on its
    device, in float32, without autocast."""
    import torch

    device = next(encoder.parameters()).device

    def latent(actions: np.ndarray) -> np.ndarray:
        with torch.no_grad(), torch.autocast(device.type, enabled=False):
            return encoder(torch.as_tensor(actions, device=device)).float().cpu().numpy()

    return latent


_SCORES = ("silhouette_raw_2d", "silhouette_latent_2d", "silhouette_raw", "silhouette_latent")


def write_tsne(run_dir: Path, result: TsneResult, frame: int, seed: int, max_iter: int) -> Path:
    """``{run_dir}/tsne.npz`` (atomic): the embeddings, labels and scores of ``result``, the settings that made them
    and ``frame``, the training frame of the encoder."""
    import sklearn

    arrays: dict[str, Any] = {
        "format": np.int64(TSNE_FORMAT), "frame": np.int64(frame), "n_per_centroid": np.int64(result.n_per_centroid),
        "seed": np.int64(seed), "max_iter": np.int64(max_iter), "true_dim": np.int64(result.true_dim),
        "distracting_dims": np.int64(result.distracting_dims), "sklearn": np.str_(sklearn.__version__),
        "labels": result.labels, "raw_2d": result.raw_2d,
        **{k: np.float64(np.nan if getattr(result, k) is None else getattr(result, k)) for k in _SCORES},
    }
    if result.latent_2d is not None:
        arrays["latent_2d"] = result.latent_2d
    path = Path(run_dir) / TSNE
    atomic_write(path, lambda fh: np.savez(fh, **arrays))
    return path


@dataclass(frozen=True)
class SavedTsne:
    """What ``tsne.npz`` holds: the result, the encoder's training frame and the settings that made it."""

    result: TsneResult
    frame: int
    seed: int
    max_iter: int
    sklearn: str

    def made_with(self, n: int, seed: int, max_iter: int) -> bool:
        return (self.result.n_per_centroid, self.seed, self.max_iter) == (n, seed, max_iter)


def read_tsne(run_dir: Path) -> SavedTsne | None:
    """``{run_dir}/tsne.npz`` as written by :func:`write_tsne`; None when there is none or it cannot be read (a
    torn, foreign or older file: the report then embeds the checkpoint itself)."""
    path = Path(run_dir) / TSNE
    try:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format"]) != TSNE_FORMAT:
                return None
            scores = {k: float(z[k]) for k in _SCORES}
            latent_2d = np.array(z["latent_2d"]) if "latent_2d" in z.files else None
            result = TsneResult(
                labels=np.array(z["labels"]), raw_2d=np.array(z["raw_2d"]), latent_2d=latent_2d,
                **{k: (None if np.isnan(v) else v) for k, v in scores.items()},  # type: ignore[arg-type]
                n_per_centroid=int(z["n_per_centroid"]), true_dim=int(z["true_dim"]),
                distracting_dims=int(z["distracting_dims"]))
            return SavedTsne(result, int(z["frame"]), int(z["seed"]), int(z["max_iter"]), str(z["sklearn"]))
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile):
        return None


def save_final_tsne(run_dir: Path, encoder: Any, action_dim: int, distracting_dims: int, frame: int) -> Path:
    """The run's own F6 embedding at the paper's settings: its encoder's latent actions of ``action_dim -
    distracting_dims`` true and ``distracting_dims`` distracting dimensions, written to tsne.npz."""
    result = embed(action_dim - distracting_dims, distracting_dims, encoder_latent(encoder), n=PAPER_N, seed=PAPER_SEED,
                   max_iter=PAPER_ITER)
    return write_tsne(run_dir, result, frame, PAPER_SEED, PAPER_ITER)
