"""Tests of evio_lib.evaluation.plots_epipolar: labelled axes and legends, clipped lines, the schematics' geometry."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

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


def test_pinhole_schematic_draws_the_projection_and_the_lens_shift():
    from evio_lib.evaluation.plots_epipolar import plot_pinhole_schematic
    from evio_lib.geometry.camera import PinholeRadtan

    cam = PinholeRadtan.davis240c()
    P = np.array([1.0, -0.9, 2.0])
    fig = plot_pinhole_schematic(cam, P)
    scene, sensor = fig.axes
    assert (scene.get_xlabel(), scene.get_ylabel(), scene.get_zlabel()) == ("x_C [m]", "z_C [m]", "−y_C (up) [m]")
    assert (sensor.get_xlabel(), sensor.get_ylabel()) == ("u [px]", "v [px]")
    lens_pixel = [line for line in sensor.lines if line.get_label() == "P's pixel through the real lens"][0]
    assert np.allclose(np.ravel(lens_pixel.get_xydata()), cam.project(P))
    ideal_pixel = [line for line in sensor.lines if line.get_label() == "K p: P's pixel with a perfect lens"][0]
    assert np.allclose(np.ravel(ideal_pixel.get_xydata()), (cam.K @ P)[:2] / P[2])
    fig.canvas.draw()
    with pytest.raises(ValueError, match="Z > 0"):
        plot_pinhole_schematic(cam, [0.0, 0.0, -1.0])


def test_epipolar_schematic_puts_the_ray_on_the_epipolar_line_through_the_epipole():
    from evio_lib.evaluation.plots_epipolar import plot_epipolar_schematic

    fig = plot_epipolar_schematic()
    scene, image2 = fig.axes
    assert (scene.get_xlabel(), scene.get_ylabel(), scene.get_zlabel()) == ("x [m]", "z [m]", "−y (up) [m]")
    assert "epipolar plane through C1, C2 and X" in [t.get_text() for t in scene.get_legend().get_texts()]
    lines = {line.get_label(): line.get_xydata() for line in image2.lines}
    (a, b), (c, d) = lines["epipolar line l2 = E x1"]
    direction = np.array([c - a, d - b]) / np.hypot(c - a, d - b)
    for label in ("epipole e2: C1's centre seen by camera 2", "points of C1's ray through x1, at depth Z1 in C1",
                  "x2: the image of X"):
        offsets = (lines[label] - [a, b]) @ [-direction[1], direction[0]]  # distance from the line
        assert np.abs(offsets).max() < 1e-9, label
    fig.canvas.draw()
    with pytest.raises(ValueError, match="toe_in_deg"):
        plot_epipolar_schematic(toe_in_deg=90.0)
