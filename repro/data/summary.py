"""What `repro dataset info` shows: size on disk, episode and transition counts, return statistics."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from repro.data.dataset import Manifest
from repro.runs.fsutil import atomic_write


def disk_bytes(directory: Path) -> int:
    return sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())


def summarize(manifest: Manifest, directory: Path) -> dict[str, Any]:
    """Counts and return statistics read from the manifest (not re-verified: `dataset check` does that)."""
    r = manifest.returns
    lengths = np.array([e.transitions for e in manifest.episodes])
    return {"task": manifest.task, "kind": manifest.kind, "action_dim": manifest.action_dim,
            "frame_shape": list(manifest.frame_shape), "bytes": disk_bytes(directory),
            "episodes": len(r), "transitions": manifest.transitions,
            "length_min": int(lengths.min()), "length_max": int(lengths.max()),
            "return_mean": float(r.mean()), "return_std": float(r.std()), "return_min": float(r.min()),
            "return_median": float(np.median(r)), "return_max": float(r.max()), "returns": r.tolist()}


def plot_returns(returns: np.ndarray, path: Path, title: str, bins: int = 20) -> None:
    """A histogram of per-episode returns, written atomically as PNG."""
    import matplotlib  # imported here: plotting is the only user, and `repro` should start fast

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(5, 3.2), dpi=120)
    ax.hist(returns, bins=bins, color="#4C72B0", edgecolor="white")
    ax.axvline(float(np.mean(returns)), color="black", lw=1, ls="--", label=f"mean {np.mean(returns):.1f}")
    ax.set_xlabel("episode return")
    ax.set_ylabel("episodes")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic_write(path, lambda f: f.write(buf.getvalue()))
