"""Figures of lesson 04 (events to frames): representations side by side, reconstructions against the truth, SSIM
against the window fraction n, one adaptive window. Plotting only; every number shown is computed by the caller."""
from __future__ import annotations

from typing import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["plot_representations", "plot_image_grid", "plot_ssim_vs_fraction", "plot_adaptive_window",
           "plot_training_history"]


def plot_representations(polarity: np.ndarray, surface: np.ndarray, voxels: np.ndarray, title: str = "") -> plt.Figure:
    """Return a figure: the polarity frame, the two time-surface channels and every voxel-grid bin, with colour bars.

    Args:
        polarity: (H, W) sum of polarities per pixel [events, ON minus OFF].
        surface: (2, H, W) time surface [ON, OFF], exp(-(t_ref - t_last) / tau) in [0, 1].
        voxels: (B, H, W) voxel grid (normalised: zero mean, unit variance over the non-zero voxels).
        title: figure title.
    """
    from matplotlib.patches import Patch

    n_bins = voxels.shape[0]
    columns = max(3, n_bins)
    fig, axes = plt.subplots(2, columns, figsize=(2.9 * columns, 5.2))
    for ax in axes.ravel():
        ax.set_axis_off()
    limit = max(1.0, float(np.percentile(np.abs(polarity), 99)))
    shown = axes[0, 0].imshow(polarity, cmap="bwr", vmin=-limit, vmax=limit)
    axes[0, 0].set_title("polarity frame")
    fig.colorbar(shown, ax=axes[0, 0], fraction=0.046, pad=0.03).set_label("ON - OFF events per pixel")
    axes[0, 0].legend(handles=[Patch(color="red", label="ON (p = +1): brighter"),
                               Patch(color="blue", label="OFF (p = -1): darker")],
                      loc="upper center", bbox_to_anchor=(0.5, 0.0), fontsize=7, ncol=1, frameon=False)
    for c, name in enumerate(("time surface ON", "time surface OFF")):
        shown = axes[0, 1 + c].imshow(surface[c], cmap="magma", vmin=0, vmax=1)
        axes[0, 1 + c].set_title(name)
        fig.colorbar(shown, ax=axes[0, 1 + c], fraction=0.046, pad=0.03).set_label("exp(-(t_ref - t_last) / tau)")
    v_lim = max(1e-6, float(np.percentile(np.abs(voxels), 99)))
    for b in range(n_bins):
        shown = axes[1, b].imshow(voxels[b], cmap="bwr", vmin=-v_lim, vmax=v_lim)
        axes[1, b].set_title(f"voxel bin {b}")
    fig.colorbar(shown, ax=axes[1, n_bins - 1], fraction=0.046, pad=0.03).set_label(
        "normalised voxel value (red: ON)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_image_grid(images: Mapping[str, np.ndarray], columns: int = 4, size: float = 3.0, title: str = "",
                    colorbar_label: str = "intensity (0 black, 1 white)") -> plt.Figure:
    """Return a figure of gray images in [0, 1] (uint8 images are shown as value / 255), one panel per entry, its key
    as the panel title, all on one colour range with one colour bar labelled ``colorbar_label`` (none if empty)."""
    names = list(images)
    rows = int(np.ceil(len(names) / columns))
    first = np.asarray(images[names[0]]) if names else np.zeros((3, 4))
    aspect = first.shape[0] / first.shape[1]                      # every panel's height over its width
    height = rows * (size * aspect + 0.4) + (0.4 if title else 0) + (0.7 if colorbar_label else 0)
    fig, axes = plt.subplots(rows, columns, figsize=(size * columns, height), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    shown = None
    for ax, name in zip(axes.ravel(), names):
        image = np.asarray(images[name])
        image = image / 255.0 if image.dtype == np.uint8 else image
        shown = ax.imshow(image, cmap="gray", vmin=0, vmax=1)
        ax.set_title(name, fontsize=9)
    fig.suptitle(title)
    fig.tight_layout()
    if colorbar_label and shown is not None:
        fig.colorbar(shown, ax=list(axes.ravel()), orientation="horizontal", fraction=0.04, pad=0.02,
                     aspect=40).set_label(colorbar_label, fontsize=8)
    return fig


def plot_ssim_vs_fraction(fractions: Sequence[float], ssim: Mapping[str, Sequence[float]],
                          marks: Mapping[str, float] | None = None) -> plt.Figure:
    """Return SSIM against the window fraction n (log axis), one line per sequence.

    ``marks`` draws the thesis's n per sequence as a dotted vertical line of the sequence's colour, named in the legend.
    """
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for name, values in ssim.items():
        line, = ax.plot(fractions, values, "o-", label=f"{name}: measured")
        if marks and name in marks:
            ax.axvline(marks[name], color=line.get_color(), ls=":", lw=1.5,
                       label=f"{name}: thesis's n = {marks[name]:g}")
    ax.set_xscale("log")
    ax.set_xticks(list(fractions), [f"{n:g}" for n in fractions])    # plain numbers at the measured n
    ax.minorticks_off()
    ax.set_xlabel("window fraction n  (N_e = n H W events; log scale)")
    ax.set_ylabel("SSIM against the sharp truth (1 = identical)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return fig


def plot_adaptive_window(count: np.ndarray, active: np.ndarray, ratio: float, n_min: int, stop: int) -> plt.Figure:
    """Return the events of one adaptive window against the pixels they lit, with the line that closes it.

    Args:
        count: (K,) events in the window so far, 1..K.
        active: (K,) distinct pixels that fired among those events.
        ratio: events per active pixel that close the window.
        n_min: smallest window [events].
        stop: the window's size as the rule chose it [events].
    """
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ax.plot(count, active, label="pixels that fired (active)")
    ax.plot(count, count / ratio, "--", label=f"events / {ratio:g}: the window closes once active is below")
    ax.axvline(n_min, color="gray", ls=":", label=f"smallest window: {n_min} events")
    ax.axvline(stop, color="k", lw=1, label=f"window closes at {stop} events")
    ax.set_xlabel("events in the window")
    ax.set_ylabel("pixels [px]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_training_history(history: Sequence[Mapping[str, float]]) -> plt.Figure:
    """Return the validation SSIM of a reconstructor training run against the step: raw, and after the benchmark's
    percentile stretch where the run recorded it (``val_ssim_stretched``).

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
        stretched = [(h["step"], h["val_ssim_stretched"]) for h in part if "val_ssim_stretched" in h]
        if stretched:
            b.plot(*zip(*stretched), "o-", color=f"C{stage - 1}", label=label)
    a.set_xlabel("training step (batches)")
    a.set_ylabel("validation SSIM (1 = identical)")
    b.set_xlabel("training step (batches)")
    b.set_ylabel("validation SSIM, both stretched")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        if len(stages) > 1 and ax.get_legend_handles_labels()[0]:
            ax.legend()
    fig.tight_layout()
    return fig


def plot_training_sequences(sequences: Sequence[Mapping[str, np.ndarray]], metas: Sequence[Mapping[str, float]],
                            windows: Sequence[int] = (0, 10, 39), size: float = 1.9) -> plt.Figure:
    """Return one row per training sequence: its sharp frames at ``windows`` and the polarity sum of the last one's
    voxel grid (red ON, blue OFF, one colour range for all rows), the row labelled with the sequence's contrast
    threshold, window rule, n and speed (view widths per second, "views/s").

    ``sequences`` and ``metas`` are what :func:`evio_lib.events.reconstruction.training_set.make_sequence` returns.
    """
    columns = len(windows) + 1
    fig, axes = plt.subplots(len(sequences), columns, figsize=(size * columns, size * len(sequences) + 0.8),
                             squeeze=False)
    lasts = [min(windows[-1], arrays["frames"].shape[0] - 1) for arrays in sequences]
    polarities = [arrays["voxels"][last].astype(np.float32).sum(axis=0) for arrays, last in zip(sequences, lasts)]
    lit = np.concatenate([np.abs(p[p != 0]) for p in polarities])
    limit = max(float(np.percentile(lit, 95)) if lit.size else 0.0, 1e-6)   # one range; hot pixels would set it
    for row, arrays, meta, last, polarity in zip(axes, sequences, metas, lasts, polarities):
        for ax, k in zip(row, windows):
            k = min(k, arrays["frames"].shape[0] - 1)
            frame_handle = ax.imshow(arrays["frames"][k].astype(np.float32), cmap="gray", vmin=0, vmax=1)
            ax.set_title(f"truth, window {k}", fontsize=8)
        event_handle = row[-1].imshow(polarity, cmap="bwr", vmin=-limit, vmax=limit)
        row[-1].set_title(f"events, window {last}", fontsize=8)
        rule = (f"n = {meta['fraction']:.2f}" if meta["rule"] == "count"
                else f"time windows (n ~ {meta['fraction']:.2f})")
        row[0].set_ylabel(f"C = {meta['contrast_pos']:.2f}\n{rule}\nspeed {meta['speed']:.1f} views/s", fontsize=8)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.colorbar(frame_handle, ax=list(axes[:, :-1].ravel()), orientation="horizontal", fraction=0.04, pad=0.03,
                 aspect=40).set_label("sharp intensity (0 black, 1 white)", fontsize=8)
    fig.colorbar(event_handle, ax=list(axes[:, -1]), orientation="horizontal", fraction=0.04, pad=0.03,
                 aspect=10).set_label("voxel sum (red: ON)", fontsize=8)
    return fig
