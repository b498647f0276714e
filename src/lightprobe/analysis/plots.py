"""Figures (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["plot_envmap_pdf"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_envmap_pdf(env, output: str | os.PathLike, *, compensated: bool = False) -> Path:
    """Write a PNG: the tone-mapped map above its sampling PDF per steradian (log10 colour scale)."""
    from ..images import linear_to_srgb

    plt = _pyplot()
    image = env.to_array()
    exposure = 0.5 / max(float(np.percentile(image.mean(axis=2), 90)), 1e-12)
    pdf = env.pdf_image(compensated=compensated)
    fig, axes = plt.subplots(2, 1, figsize=(8, 8.4), constrained_layout=True)
    axes[0].imshow(linear_to_srgb(image * exposure), extent=(0, 1, 1, 0), aspect=0.5)
    axes[0].set_title(f"{Path(env.source).name}: radiance (exposure x{exposure:.3g})")
    positive = pdf[pdf > 0]
    floor = positive.min() if positive.size else 1e-12
    shown = axes[1].imshow(np.log10(np.maximum(pdf, floor)), extent=(0, 1, 1, 0), aspect=0.5, cmap="magma")
    kind = "MIS-compensated " if compensated else ""
    axes[1].set_title(f"{kind}sampling pdf ({env.pdf_mode}), log10 per steradian; zero shown at the minimum")
    for ax in axes:
        ax.set_xlabel("u")
        ax.set_ylabel("v")
    fig.colorbar(shown, ax=axes[1], shrink=0.8)
    out = Path(output)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
