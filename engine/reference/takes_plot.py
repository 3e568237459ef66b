"""Seed 002 fig. 5 for a reference built from takes: what the synchronisation did."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.io.figures import save_figure
from engine.reference.action_model import ActionModel


def plot_takes(model: ActionModel, path: Path) -> None:
    """Seed 002 fig. 5: aSpace dimensions 1-3 of every take before and after synchronisation,
    and the mean performance +- 3 sd (the takes dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from engine.reference.synchronisation import warp

    n_dims = min(3, model.space.dims)
    kept = np.flatnonzero(model.kept)
    xs = model.x
    fig, axes = plt.subplots(3, n_dims, figsize=(4.2 * n_dims, 8), squeeze=False,
                             constrained_layout=True)  # fmt: skip
    P = len(model.mean_x)
    for d in range(n_dims):
        for i in kept:
            axes[0, d].plot(xs[i][:, d], lw=1, label=model.names[i])
            axes[1, d].plot(warp(xs[i], model.syncs[i])[:, d], lw=1)
            axes[2, d].plot(warp(xs[i], model.syncs[i])[:, d], "b--", lw=0.6)
        m, sd = model.mean_x[:, d], model.sd_x[:, d]
        axes[2, d].plot(m, "r-", lw=1.5)
        axes[2, d].plot(m + 3 * sd, "k-", lw=0.8)
        axes[2, d].plot(m - 3 * sd, "k-", lw=0.8)
        axes[0, d].set_title(f"aSpace dimension {d + 1}")
        axes[2, d].set_xlabel(f"frame of the median take ({P} frames)")
    axes[0, 0].set_ylabel("takes as recorded")
    axes[1, 0].set_ylabel("synchronised to the median")
    axes[2, 0].set_ylabel("mean +- 3 sd")
    axes[0, 0].legend(fontsize=7)
    save_figure(fig, path, dpi=90)
