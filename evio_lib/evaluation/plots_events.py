"""Figures of lesson 04 (events to frames): representations side by side, reconstructions against the truth, SSIM
against the window fraction n. Plotting only; every number shown is computed by the caller."""
from __future__ import annotations

from typing import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["plot_representations", "plot_image_grid", "plot_ssim_vs_fraction", "plot_training_history"]


def plot_representations(polarity: np.ndarray, surface: np.ndarray, voxels: np.ndarray, title: str = "") -> plt.Figure:
    """Return a figure: the polarity frame, the two time-surface channels, and every voxel-grid bin.

    Args:
        polarity: (H, W) sum of polarities per pixel.
        surface: (2, H, W) time surface [ON, OFF].
        voxels: (B, H, W) voxel grid.
        title: figure title.
    """
    n_bins = voxels.shape[0]
    fig, axes = plt.subplots(2, max(3, n_bins), figsize=(2.6 * max(3, n_bins), 4.6))
    limit = max(1.0, float(np.percentile(np.abs(polarity), 99)))
    axes[0, 0].imshow(polarity, cmap="bwr", vmin=-limit, vmax=limit)
    axes[0, 0].set_title("polarity frame")
    for c, name in enumerate(("time surface ON", "time surface OFF")):
        axes[0, 1 + c].imshow(surface[c], cmap="magma", vmin=0, vmax=1)
        axes[0, 1 + c].set_title(name)
    v_lim = max(1e-6, float(np.percentile(np.abs(voxels), 99)))
    for b in range(n_bins):
        axes[1, b].imshow(voxels[b], cmap="bwr", vmin=-v_lim, vmax=v_lim)
        axes[1, b].set_title(f"voxel bin {b}")
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_image_grid(images: Mapping[str, np.ndarray], columns: int = 4, size: float = 3.0, title: str = "") -> plt.Figure:
    """Return a figure of gray images in [0, 1] (or uint8), one panel per entry, its key as the panel title."""
    names = list(images)
    rows = int(np.ceil(len(names) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(size * columns, 0.8 * size * rows), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, name in zip(axes.ravel(), names):
        image = np.asarray(images[name])
        ax.imshow(image, cmap="gray", vmin=0, vmax=255 if image.dtype == np.uint8 else 1)
        ax.set_title(name, fontsize=9)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_ssim_vs_fraction(fractions: Sequence[float], ssim: Mapping[str, Sequence[float]],
                          marks: Mapping[str, float] | None = None) -> plt.Figure:
    """Return SSIM against the window fraction n, one line per sequence; ``marks`` draws the thesis's n per sequence."""
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for name, values in ssim.items():
        line, = ax.plot(fractions, values, "o-", label=name)
        if marks and name in marks:
            ax.axvline(marks[name], color=line.get_color(), ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("window fraction n  (N_e = n H W events)")
    ax.set_ylabel("SSIM against the sharp truth")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_training_history(history: Sequence[Mapping[str, float]]) -> plt.Figure:
    """Return the validation SSIM and loss of a reconstructor training run against the step.

    Entries with a ``stage`` key (a fine-tuning stage on other data, with its own validation set) are drawn as one
    line per stage.
    """
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.2))
    stages = sorted({int(h.get("stage", 1)) for h in history})
    for stage in stages:
        part = [h for h in history if int(h.get("stage", 1)) == stage]
        steps = [h["step"] for h in part]
        label = f"stage {stage}" if len(stages) > 1 else None
        a.plot(steps, [h["val_ssim"] for h in part], "o-", color=f"C{stage - 1}", label=label)
        b.plot(steps, [h["val_loss"] for h in part], "o-", color=f"C{stage - 1}", label=label)
    a.set_xlabel("step")
    a.set_ylabel("validation SSIM")
    b.set_xlabel("step")
    b.set_ylabel("validation loss")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        if len(stages) > 1:
            ax.legend()
    fig.tight_layout()
    return fig
