"""F6: do latent actions of a trained TACO action encoder cluster where raw actions do not?

Following the paper (Section 5.1): pick 4 centroid actions in the true action space, make ``n`` copies
of each with standard Gaussian noise in the distracting dimensions, embed raw actions and their latent
actions (the encoder's per-step MLP) with t-SNE, and score how well the 4 groups separate with the
silhouette coefficient (``sklearn.metrics.silhouette_score``, in [-1, 1]; higher = better separated),
on the 2-D t-SNE embeddings and on the original spaces.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from analysis.cache import lookup
from repro.config.errors import UserError
from repro.runs.runformat import read_done
from repro.train import action_tsne
from repro.train.action_tsne import N_CENTROIDS, TsneResult, make_actions, perplexity_for

__all__ = ["N_CENTROIDS", "TsneResult", "make_actions", "run_tsne", "tsne_2d", "tsne_for_context"]
CLUSTER_THRESHOLD = 0.5  # silhouette at or above this counts as "forms clusters" (claim tsne_clusters)
_PREFIXES = ("agent.action_encoder.step.", "action_encoder.step.", "step.")


class ActionEncoderNotFound(UserError, KeyError):
    """The checkpoint has no action-encoder state dict of the expected layout."""

    def __str__(self) -> str:
        return str(self.args[0])


def find_action_encoder_state(ckpt: Mapping[str, Any]) -> dict[str, Any]:
    """The per-step MLP parameters ``{"0.weight", "0.bias", "2.weight", "2.bias"}`` from a checkpoint.

    Accepted layouts: ``ckpt["agent"]["action_encoder"]`` or ``ckpt["agent"]["agent.action_encoder"]``
    (a module state dict with ``step.0.weight`` ...), ``ckpt["agent.action_encoder"]``, or flat keys
    ``[agent.]action_encoder.step.0.weight`` in ``ckpt["agent"]`` or ``ckpt``.
    """
    candidates: list[Mapping[str, Any]] = []
    agent = ckpt.get("agent") if isinstance(ckpt, Mapping) else None
    for holder in (agent, ckpt):
        if isinstance(holder, Mapping):
            for key in ("action_encoder", "agent.action_encoder"):
                if isinstance(holder.get(key), Mapping):
                    candidates.append(holder[key])
            candidates.append(holder)
    for sd in candidates:
        for prefix in _PREFIXES:
            keys = {f"{i}.{p}": f"{prefix}{i}.{p}" for i in (0, 2) for p in ("weight", "bias")}
            if all(k in sd for k in keys.values()):
                return {short: sd[full] for short, full in keys.items()}
    raise ActionEncoderNotFound("no action encoder (step.0.weight ... step.2.bias) in the checkpoint")


def build_step_mlp(state: Mapping[str, Any]):
    """The encoder's per-step MLP Linear(|A| -> hidden), Tanh, Linear(hidden -> d_u) with ``state`` loaded."""
    import torch
    from torch import nn

    w0, w2 = state["0.weight"], state["2.weight"]
    mlp = nn.Sequential(nn.Linear(w0.shape[1], w0.shape[0]), nn.Tanh(), nn.Linear(w2.shape[1], w2.shape[0]))
    mlp.load_state_dict({k: torch.as_tensor(v) for k, v in state.items()})
    return mlp.eval()


def load_step_mlp(checkpoint: Path):
    """Load ``checkpoint.pt`` (weights only) and build the action encoder's per-step MLP."""
    import torch

    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=True)
    return build_step_mlp(find_action_encoder_state(ckpt))


def tsne_2d(x: np.ndarray, seed: int = 0, max_iter: int = 1000) -> np.ndarray:
    """2-D t-SNE as a run makes it (:func:`repro.train.action_tsne.tsne_2d`); the same points, seed and iterations
    reuse the command's cache (analysis/cache.py: the embedding depends on no run but the checkpoint that encoded
    ``x``)."""
    x = np.ascontiguousarray(x)
    key = hashlib.sha1(f"{x.dtype}|{x.shape}|{seed}|{max_iter}|{perplexity_for(len(x))!r}".encode()
                       + x.tobytes()).hexdigest()
    return lookup("tsne", key, lambda: action_tsne.tsne_2d(x, seed, max_iter))


def run_tsne(true_dim: int, distracting_dims: int, mlp=None, n: int = 1000, seed: int = 0,
             max_iter: int = 1000) -> TsneResult:
    """Embed raw (and, with ``mlp``: the encoder's per-step MLP, latent) actions and score the clusters, as a run
    does (:func:`repro.train.action_tsne.embed`) with this command's cached t-SNE."""
    latent = None if mlp is None else action_tsne.encoder_latent(mlp)
    return action_tsne.embed(true_dim, distracting_dims, latent, n=n, seed=seed, max_iter=max_iter, embed_2d=tsne_2d)


def find_tsne_run(runs) -> Any:
    """The TACO run with distracting action dims and a checkpoint to embed: experiment 'tsne' and
    cheetah_run preferred, then the most distracting dims; None if there is none."""
    import pandas as pd

    if runs.empty:
        return None
    cand = runs[(runs["agent"] == "taco") & (pd.to_numeric(runs["distracting_dims"], errors="coerce").fillna(0) > 0)]
    if cand.empty:
        return None
    cand = cand.assign(
        _exp=(cand["experiment"] != "tsne").astype(int),
        _task=(cand["task"] != "cheetah_run").astype(int),
        _done=(cand["status"] != "done").astype(int),
    ).sort_values(["_exp", "_task", "_done", "distracting_dims", "seed"], ascending=[True, True, True, False, True])
    return cand.iloc[0]


def tsne_for_context(ctx) -> tuple[TsneResult, dict[str, Any]]:
    """The F6 t-SNE for a :class:`analysis.context.Context` (cached in ``ctx.cache``). The run's own embedding
    (``tsne.npz``, written at its final evaluation: :mod:`repro.train.action_tsne`) when it was made at this
    command's settings from the encoder the run ended with (its frame is the one in DONE); otherwise embedded here
    from the checkpoint, kept in the command's cache under the checkpoint's path, size and modification time and
    the settings (an unchanged checkpoint is neither loaded nor scored again).

    Returns the result and info: ``run_id`` (None if no trained run), ``reason`` when the latent panel
    is missing, ``source``: ``"run"`` (the run's tsne.npz, ``frame`` its encoder's frame) or ``"report"``.
    """
    if "tsne" in ctx.cache:
        return ctx.cache["tsne"]
    run = find_tsne_run(ctx.results.runs)
    settings = (ctx.tsne_n, ctx.seed, ctx.tsne_iter)
    saved = None if run is None else saved_tsne(ctx.results.root / run["run_id"], run, settings)
    if saved is not None:
        value: tuple[TsneResult, dict[str, Any]] = (
            saved.result, {"run_id": run["run_id"], "reason": None, "source": "run", "frame": saved.frame})
    elif run is None:
        value = _tsne_of(None, None, settings)
    else:
        ckpt = ctx.results.root / run["run_id"] / "checkpoint.pt"
        try:
            st = ckpt.stat()
            signature: tuple[int, int] | None = (st.st_size, st.st_mtime_ns)
        except OSError:
            signature = None
        key = (str(ckpt.resolve()), signature, str(run["run_id"]), str(run["task"]), int(run["distracting_dims"]),
               settings)
        value = lookup("tsne_result", key, lambda: _tsne_of(run, ckpt, settings))
    ctx.cache["tsne"] = value
    return value


def saved_tsne(run_dir: Path, run: Any, settings: tuple[int, int, int]) -> action_tsne.SavedTsne | None:
    """The run's tsne.npz when it holds both panels at ``settings`` (n, seed, iterations) for the run's
    distracting dims and was made at the frame the run finished at (DONE); None otherwise (an extended run's older
    embedding, another --tsne-n or --seed, a run that is not done)."""
    saved = action_tsne.read_tsne(run_dir)
    if saved is None or saved.result.latent_2d is None or not saved.made_with(*settings):
        return None
    if saved.result.distracting_dims != int(run["distracting_dims"]):
        return None
    done = read_done(run_dir)
    if not done or done.get("frame") != saved.frame:
        return None
    return saved


def _tsne_of(run: Any, ckpt: Path | None, settings: tuple[int, int, int]) -> tuple[TsneResult, dict[str, Any]]:
    """Embed and score for ``run`` (None: the raw panel only, the paper's cheetah_run with 20 distracting dims)."""
    from analysis.identity import action_dim

    n, seed, max_iter = settings
    info: dict[str, Any] = {"run_id": None, "reason": None, "source": "report"}
    mlp, true_dim, distract = None, 6, 20  # the paper's cheetah_run (|A| = 6) + 20 distracting dims
    if run is None or ckpt is None:
        info["reason"] = ("no trained TACO run with distracting action dims (experiment 'tsne': cheetah_run, "
                          "env.distracting_dims=20) found")
    else:
        info["run_id"] = run["run_id"]
        try:
            mlp = load_step_mlp(ckpt)
        except (OSError, RuntimeError, ValueError, KeyError) as exc:
            info["reason"] = f"cannot use {ckpt}: {exc}"
            info["run_id"] = None
        if mlp is not None:
            in_dim = mlp[0].in_features
            distract = int(run["distracting_dims"])
            true_dim = action_dim(run["task"]) or in_dim - distract
            if true_dim + distract != in_dim:
                true_dim = in_dim - distract
    return run_tsne(true_dim, distract, mlp, n=n, seed=seed, max_iter=max_iter), info
