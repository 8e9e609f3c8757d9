"""Smoke tests of the lesson-04 figures: each helper returns a figure with the expected panels."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.evaluation.plots_events import (plot_adaptive_window, plot_image_grid,  # noqa: E402
                                              plot_representations, plot_ssim_vs_fraction, plot_training_history)


def test_figures_have_their_panels():
    rng = np.random.default_rng(0)
    fig = plot_representations(rng.normal(size=(6, 8)), rng.uniform(size=(2, 6, 8)), rng.normal(size=(5, 6, 8)))
    assert len(fig.axes) == 10 + 4          # 3 + 5 panels, 1 empty, and 4 colour bars (polarity, ON, OFF, voxels)
    colour_bars = [ax.get_ylabel() for ax in fig.axes[10:]]
    assert colour_bars[0] == "ON - OFF events per pixel" and all(colour_bars)
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["ON (p = +1): brighter",
                                                                            "OFF (p = -1): darker"]
    fig2 = plot_image_grid({"a": rng.uniform(size=(6, 8)), "b": np.full((6, 8), 255, np.uint8)}, columns=2)
    assert [ax.get_title() for ax in fig2.axes[:2]] == ["a", "b"]
    assert [ax.images[0].get_clim() for ax in fig2.axes[:2]] == [(0.0, 1.0)] * 2      # one colour range
    assert fig2.axes[1].images[0].get_array().max() == 1.0                            # uint8 shown as value / 255
    assert fig2.axes[2].get_xlabel() == "intensity (0 black, 1 white)"                # the shared colour bar
    assert len(plot_image_grid({"a": np.zeros((6, 8))}, colorbar_label="").axes) == 4  # no colour bar
    fig3 = plot_ssim_vs_fraction([0.1, 0.2], {"x": [0.3, 0.4]}, marks={"x": 0.2})
    assert fig3.axes[0].get_xscale() == "log"
    assert [t.get_text() for t in fig3.axes[0].get_legend().get_texts()] == ["x: measured", "x: thesis's n = 0.2"]
    assert fig3.axes[0].get_xlabel() and fig3.axes[0].get_ylabel()
    count = np.arange(1, 101)
    fig6 = plot_adaptive_window(count, np.minimum(count, 40), ratio=2.0, n_min=10, stop=80)
    assert fig6.axes[0].get_xlabel() == "events in the window" and fig6.axes[0].get_ylabel() == "pixels [px]"
    assert len(fig6.axes[0].get_legend().get_texts()) == 4
    fig4 = plot_training_history([{"step": 1, "val_ssim": 0.5, "val_loss": 0.9}, {"step": 2, "val_ssim": 0.6,
                                                                                  "val_loss": 0.8}])
    assert len(fig4.axes) == 2
    assert [ax.get_xlabel() for ax in fig4.axes] == ["training step (batches)"] * 2
    staged = [{"step": 1, "val_ssim": 0.5, "val_loss": 0.9, "stage": 1}, {"step": 2, "val_ssim": 0.6, "val_loss": 0.8,
                                                                         "stage": 2},
              {"step": 3, "val_ssim": 0.6, "val_ssim_stretched": 0.45, "stage": 3},
              {"step": 4, "val_ssim": 0.61, "val_ssim_stretched": 0.48, "stage": 3}]
    fig5 = plot_training_history(staged)
    assert [len(ax.lines) for ax in fig5.axes] == [3, 1]       # raw SSIM per stage; stretched where recorded
    assert [t.get_text() for t in fig5.axes[0].get_legend().get_texts()] == ["stage 1", "stage 2", "stage 3"]
    assert fig5.axes[1].lines[0].get_ydata().tolist() == [0.45, 0.48]
    plt.close("all")


def test_training_sequences_figure_labels_each_row_with_its_sensor():
    from evio_lib.evaluation.plots_events import plot_training_sequences

    rng = np.random.default_rng(0)
    arrays = {"frames": rng.uniform(0, 1, (40, 16, 16)).astype(np.float16),
              "voxels": rng.normal(0, 1, (40, 5, 16, 16)).astype(np.float16)}
    metas = [{"contrast_pos": 0.18, "rule": "count", "fraction": 0.3, "speed": 1.0},
             {"contrast_pos": 1.2, "rule": "time", "fraction": 0.05, "speed": 3.0}]
    arrays2 = dict(arrays, voxels=(3 * arrays["voxels"]).astype(np.float16))
    fig = plot_training_sequences([arrays, arrays2], metas)
    axes = np.array(fig.axes[:8]).reshape(2, 4)
    assert axes[0, 0].get_ylabel().startswith("C = 0.18") and "n = 0.30" in axes[0, 0].get_ylabel()
    assert "time windows" in axes[1, 0].get_ylabel() and axes[1, 3].get_title() == "events, window 39"
    assert axes[1, 0].get_ylabel().endswith("speed 3.0 views/s")                   # the speed with its unit
    assert axes[0, 3].images[0].get_clim() == axes[1, 3].images[0].get_clim()     # one range for every row's events
    assert [ax.get_xlabel() for ax in fig.axes[8:]] == ["sharp intensity (0 black, 1 white)", "voxel sum (red: ON)"]
    plt.close(fig)
