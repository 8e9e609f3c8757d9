"""Tests of evio_lib.evaluation.plots_epipolar: labelled axes and legends (issue 27), clipping of the lines."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from evio_lib.evaluation.plots_epipolar import line_segments_in_image, plot_cheirality, plot_epipolar_lines  # noqa: E402
from evio_lib.geometry.epipolar import decompose_essential, essential_from_pose  # noqa: E402


def test_epipolar_figure_labels_axes_and_explains_points_and_lines():
    F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # rectified pair: the line of a point is its row
    fig = plot_epipolar_lines([[50.0, 20.0], [10.0, 40.0]], [[30.0, 20.0], [5.0, 40.0]], F, 100, 60)
    assert [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes] == [("x [px]", "y [px]")] * 2
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts == ["point (one colour per correspondence)", "epipolar line of the same-colour point of the other view"]
    assert len(fig.axes[1].lines) == 2 and all(np.allclose(line.get_ydata(), y) for line, y in
                                               zip(fig.axes[1].lines, (20.0, 40.0)))
    fig.canvas.draw()


def test_cheirality_figure_has_metric_axes_and_a_legend():
    xy = np.array([[0.0, 0.0], [0.1, 0.05]])
    fig = plot_cheirality(decompose_essential(essential_from_pose(np.eye(3), [-1.0, 0, 0])), xy, xy - [0.2, 0])
    assert all(ax.get_xlabel() == "x in C1 [m]" and ax.get_ylabel() == "z in C1 [m]" for ax in fig.axes)
    assert "in front of both cameras" in [t.get_text() for t in fig.legends[0].get_texts()]
    fig.canvas.draw()


def test_line_segments_are_clipped_to_the_image():
    segments = line_segments_in_image([[0.0, 1.0, -20.0]], 100, 60)  # y = 20
    assert np.allclose(segments[0][:, 1], 20.0) and segments[0][:, 0].min() >= -0.5 and segments[0][:, 0].max() <= 99.5
