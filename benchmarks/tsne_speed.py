"""F6's t-SNE on one core: what a first ``repro report`` pays for the figure of the paper's Section 5.1 at its settings
(4 centroids x 1000 noisy copies of a 6 + 20 dimensional action, scikit-learn's Barnes-Hut t-SNE with its default
1000 iterations, PCA initialisation, perplexity 30), and what other settings or another library would change.

Each case embeds the raw actions and their latent actions (the encoder of the test fixture's checkpoint:
tests/analysis_fixtures.write_encoder_checkpoint, 6 + 20 -> 64 -> 8, blind to the distracting dims, as a trained
TACO encoder is meant to be), with the wall time of each embedding and the silhouette of each 2-D embedding (what the
claim ``tsne_clusters`` reads; analysis/tsne.py). The cases:

- ``sklearn``: the report's own path (analysis.tsne.tsne_2d), at the paper's n and fewer (``--tsne-n``), and at 500
  iterations (a setting the report does not offer);
- ``openTSNE bh`` and ``openTSNE fft``: the openTSNE library (not a dependency of this project), when importable.

    OMP_NUM_THREADS=1 python benchmarks/tsne_speed.py --json /tmp/tsne.json

Not a test: the numbers go to docs/performance.md. Run it on a quiet machine; it sets one thread for the whole
process (threadpoolctl) and names the CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from analysis.tsne import load_step_mlp, make_actions  # noqa: E402
from repro.runs.rundir import cpu_model  # noqa: E402

TRUE_DIM, DISTRACTING = 6, 20  # the paper's cheetah_run (|A| = 6) with 20 distracting dims (sweeps/tsne.yaml)


def _sklearn(max_iter: int) -> Callable[[np.ndarray], np.ndarray]:
    def embed(x: np.ndarray) -> np.ndarray:
        from analysis.tsne import tsne_2d

        return tsne_2d(x, seed=0, max_iter=max_iter)

    return embed


def _opentsne(method: str) -> Callable[[np.ndarray], np.ndarray]:
    def embed(x: np.ndarray) -> np.ndarray:
        import openTSNE

        return np.asarray(openTSNE.TSNE(perplexity=min(30.0, (len(x) - 1) / 3.0), initialization="pca",
                                        random_state=0, n_jobs=1, negative_gradient_method=method).fit(x))

    return embed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="write the rows here too")
    parser.add_argument("--ns", type=int, nargs="+", default=[1000, 500, 250], help="copies per centroid to time")
    args = parser.parse_args()

    import torch
    from sklearn.metrics import silhouette_score
    from threadpoolctl import threadpool_limits

    from analysis_fixtures import write_encoder_checkpoint

    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        write_encoder_checkpoint(Path(tmp), TRUE_DIM, DISTRACTING)
        mlp = load_step_mlp(Path(tmp) / "checkpoint.pt")

    cases: list[tuple[str, int, Callable[[np.ndarray], np.ndarray]]] = [
        (f"sklearn, {n} per centroid, 1000 iterations" + (" (the report's)" if n == 1000 else ""), n, _sklearn(1000))
        for n in args.ns]
    cases.append(("sklearn, 1000 per centroid, 500 iterations", 1000, _sklearn(500)))
    try:
        import openTSNE

        version = openTSNE.__version__
        cases += [(f"openTSNE {version} {m}, 1000 per centroid", 1000, _opentsne(m)) for m in ("bh", "fft")]
    except ImportError:
        print("openTSNE is not installed: its cases are left out")

    rows = []
    with threadpool_limits(limits=1):
        for name, n, embed in cases:
            actions, labels = make_actions(TRUE_DIM, DISTRACTING, n, seed=0)
            with torch.no_grad():
                latent = mlp(torch.as_tensor(actions)).numpy()
            row: dict = {"case": name, "points": len(actions)}
            for kind, x in (("raw", actions), ("latent", latent)):
                t0 = time.perf_counter()
                y = embed(x)
                row[f"{kind}_s"] = round(time.perf_counter() - t0, 2)
                row[f"{kind}_silhouette"] = round(float(silhouette_score(y, labels)), 3)
            rows.append(row)
            print(f"{name:55s} raw {row['raw_s']:6.2f} s (silhouette {row['raw_silhouette']:.3f})   "
                  f"latent {row['latent_s']:6.2f} s (silhouette {row['latent_silhouette']:.3f})", flush=True)
    out = {"cpu": cpu_model(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "load": os.getloadavg()[0],
           "rows": rows}
    print(f"CPU: {out['cpu']}; one thread; load {out['load']:.2f}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
