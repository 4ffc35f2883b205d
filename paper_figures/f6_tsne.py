"""F6 (fig:tsne_act): t-SNE of raw vs latent actions with distracting dimensions, scored by silhouette."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd

from analysis.context import Context
from analysis.tables import fmt_num, write_table
from analysis.tsne import CLUSTER_THRESHOLD, tsne_for_context
from paper_figures.common import banner, placeholder, save_figure
from paper_figures.registry import ArtifactResult, register


@register("F6", "t-SNE of raw vs latent actions", "figure", "fig:tsne_act")
def render(ctx: Context) -> ArtifactResult:
    res, info = tsne_for_context(ctx)
    colors = plt.get_cmap("tab10").colors  # type: ignore[attr-defined]  # tab10 is a ListedColormap
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.6))
    for ax, emb, sil, name in ((a1, res.raw_2d, res.silhouette_raw_2d, "raw actions"),
                               (a2, res.latent_2d, res.silhouette_latent_2d, "latent actions")):
        if emb is None:
            placeholder(ax, f"latent actions: {info['reason']}")
            ax.set_title(name)
            continue
        for c in range(4):
            pts = emb[res.labels == c]
            ax.scatter(pts[:, 0], pts[:, 1], s=3, alpha=0.6, color=colors[c], label=f"centroid {c + 1}")
        ax.set_title(f"{name} (silhouette {sil:.2f})")
        ax.set_xlabel("t-SNE 1")
        ax.set_ylabel("t-SNE 2")
        ax.legend(fontsize=7, markerscale=3, loc="best")
    fig.tight_layout()
    if info["run_id"] is None:
        banner(fig, "no trained TACO action encoder found: raw actions only")
    png = save_figure(fig, ctx, "F6")
    src = f"the action encoder of run {info['run_id']}" if info["run_id"] else "no trained encoder (latent panel empty)"
    made = (f"embedded by the run at its final evaluation (frame {info['frame']:,}; its tsne.npz)"
            if info.get("source") == "run" else "embedded by this command")
    caption = (
        f"t-SNE (scikit-learn, PCA init, random state {ctx.seed}) of {4 * res.n_per_centroid} actions: 4 centroids "
        f"uniform in the true {res.true_dim}-D action space, {res.n_per_centroid} copies each with standard Gaussian "
        f"noise in the {res.distracting_dims} distracting dimensions; left raw actions, right their latent actions "
        f"from {src}, {made}. Colours: centroid. Cluster quality: silhouette coefficient of the centroid labels "
        f"(≥ {CLUSTER_THRESHOLD} counts as 'forms clusters')."
    )
    raw = pd.DataFrame(
        [
            {"space": "raw", "silhouette_tsne_2d": res.silhouette_raw_2d, "silhouette_original": res.silhouette_raw},
            {
                "space": "latent",
                "silhouette_tsne_2d": res.silhouette_latent_2d,
                "silhouette_original": res.silhouette_latent,
            },
        ]
    )
    disp = pd.DataFrame([
        {"Actions": "raw", "Silhouette (t-SNE 2-D)": fmt_num(res.silhouette_raw_2d, 3),
         "Silhouette (original space)": fmt_num(res.silhouette_raw, 3), "Paper": "no clusters (by eye)"},
        {"Actions": "latent", "Silhouette (t-SNE 2-D)": fmt_num(res.silhouette_latent_2d, 3),
         "Silhouette (original space)": fmt_num(res.silhouette_latent, 3), "Paper": "4 clusters (by eye)"},
    ])
    table = write_table(ctx.out_dir, "F6", raw, "Cluster quality of raw and latent actions (silhouette, higher is "
                        "better separated; the paper judges by eye).", disp)
    return ArtifactResult("F6", "t-SNE of actions", caption, figures=[png], tables=[table],
                          has_runs=info["run_id"] is not None, extra={"tsne": res, "tsne_info": info},
                          notes=[] if info["run_id"] else [info["reason"]])
