"""Tests of evio_lib.evaluation.plots_features: every figure renders to Agg with the expected panels; bad input is
refused with a message naming the expected form."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation.plots_features import (  # noqa: E402
    plot_binary_descriptors,
    plot_cell_correspondences,
    plot_cell_probabilities,
    plot_detections,
    plot_evaluation_schematic,
    plot_fast_circle,
    plot_feature_schematic,
    plot_heatmap_row,
    plot_homography_corners,
    plot_keypoints,
    plot_labelled_images,
    plot_match_grid,
    plot_matches,
    plot_oracle_corner_errors,
    plot_repeatability_bars,
    plot_repeatability_pair,
    plot_repeated_points,
    plot_scale_space,
    plot_structure_tensor_classes,
    plot_training_curve,
)

FAST_CIRCLE = np.array([(0, 3), (1, 3), (2, 2), (3, 1), (3, 0), (3, -1), (2, -2), (1, -3),
                        (0, -3), (-1, -3), (-2, -2), (-3, -1), (-3, 0), (-3, 1), (-2, 2), (-1, 3)])



@pytest.fixture
def image(rng: np.random.Generator) -> np.ndarray:
    return rng.random((40, 60)).astype(np.float32)


def _render(fig) -> np.ndarray:
    """Draw the figure on the Agg canvas and return its pixels (fails on any drawing error)."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())


def test_structure_tensor_classes_renders_three_panels(image: np.ndarray) -> None:
    classes = (image > 0.5).astype(int) + (image > 0.9)
    fig = plot_structure_tensor_classes(image, image - 0.5, classes, clip=0.05)
    assert len(fig.axes) == 4 and _render(fig).size > 0  # three panels and the colour bar of R
    assert fig.axes[1].images[0].get_clim() == pytest.approx((-0.05 * np.abs(image - 0.5).max(),
                                                               0.05 * np.abs(image - 0.5).max()))
    assert fig.axes[3].get_ylabel().startswith("R (colour scale clipped at ±5 %")
    with pytest.raises(ValueError, match="share one shape"):
        plot_structure_tensor_classes(image, image[:10], classes)


def test_keypoints_panels_titles_and_counts(image: np.ndarray, rng: np.random.Generator) -> None:
    sets = {"harris": rng.uniform(0, 40, (7, 2)), "fast": np.zeros((0, 2)), "sift": rng.uniform(0, 40, (3, 2))}
    fig = plot_keypoints(image, sets, ncols=2, ranked=True)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert titles == ["harris: 7", "fast: 0", "sift: 3"]
    assert len(fig.axes) == 5  # 2 x 2 grid, the last panel empty, and one colour bar for the rank
    assert fig.axes[4].get_ylabel() == "rank / count (0 = strongest, 1 = weakest)"
    np.testing.assert_allclose(fig.axes[0].collections[0].get_array(), np.arange(7) / 6)  # strongest first
    assert len(plot_keypoints(image, sets, ncols=2).axes) == 4  # one colour: no colour bar
    _render(fig)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        plot_keypoints(image, {"bad": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="2-D grayscale"):
        plot_keypoints(np.zeros((4, 4, 3)), {"a": np.zeros((1, 2))})


def test_fast_circle_colours_follow_the_segment_test() -> None:
    square = np.full((21, 21), 50, np.uint8)
    square[10:, 10:] = 200  # the centre (10, 10) is the corner of a bright square
    fig = plot_fast_circle(square, (10, 10), FAST_CIRCLE, 20.0, np.array([[10.0, 10.0]]))
    colours = fig.axes[0].collections[0].get_edgecolors()
    darker = np.sum(np.all(np.isclose(colours[:, :3], matplotlib.colors.to_rgb("tab:blue")), axis=1))
    d = square[10 + FAST_CIRCLE[:, 1], 10 + FAST_CIRCLE[:, 0]].astype(int) - 200
    assert darker == np.sum(d < -20) > 0  # the dark background pixels of the circle are drawn blue
    _render(fig)
    with pytest.raises(ValueError, match="at least 5 px inside"):
        plot_fast_circle(square, (2, 10), FAST_CIRCLE, 20.0)


def test_scale_space_binary_and_repeatability_figures(image: np.ndarray, rng: np.random.Generator) -> None:
    fig = plot_scale_space([image - 0.5, 2 * (0.5 - image)], [1.6, 2.0], image, rng.uniform(0, 40, (5, 2)))
    assert [ax.get_title() for ax in fig.axes] == ["DoG, sigma = 1.60", "DoG, sigma = 2.00", "SIFT: 5 keypoints", ""]
    lim = np.percentile(np.abs(np.concatenate([image - 0.5, 2 * (0.5 - image)])), 99.5)  # over both levels
    assert fig.axes[0].images[0].get_clim() == fig.axes[1].images[0].get_clim() == pytest.approx((-lim, lim))
    assert fig.axes[3].get_ylabel() == "D (image intensity units)"
    with pytest.raises(ValueError, match="equal length"):
        plot_scale_space([image], [1.6, 2.0], image, np.zeros((0, 2)))
    with pytest.raises(ValueError, match=r"clip_percentile must lie in \(0, 100\]"):
        plot_scale_space([image], [1.6], image, np.zeros((0, 2)), clip_percentile=0)

    bits = np.unpackbits(rng.integers(0, 256, (20, 32), dtype=np.uint8), axis=1)
    fig = plot_binary_descriptors(bits, 12, "ORB")
    assert fig.axes[0].images[0].get_array().shape == (12, 256)
    with pytest.raises(ValueError, match="zeros and ones"):
        plot_binary_descriptors(np.full((2, 8), 3))

    points = rng.uniform(0, 40, (6, 2))
    fig = plot_repeatability_pair(image, image, points, points, np.arange(6) % 2 == 0, points, 3)
    assert len(fig.axes) == 2 and "3 px" in fig.axes[0].get_title()
    with pytest.raises(ValueError, match="one row per point"):
        plot_repeatability_pair(image, image, points, points, [True], points, 3)

    table = {"harris": {"viewpoint": [0.5, 0.7, 0.8], "illumination": [0.6, 0.7, 0.9]},
             "sift": {"viewpoint": [0.4, 0.6, 0.7], "illumination": [0.5, 0.6, 0.8]}}
    fig = plot_repeatability_bars(table, (1, 3, 5))
    heights = sorted(round(p.get_height(), 3) for p in fig.axes[0].patches)
    assert heights == sorted([0.5, 0.7, 0.8, 0.4, 0.6, 0.7])  # one bar per detector and eps, at its value
    with pytest.raises(ValueError, match="one value per eps"):
        plot_repeatability_bars(table, (1, 3))


def test_training_curve_and_matches(image: np.ndarray) -> None:
    losses = np.linspace(4.0, 1.0, 40)
    fig = plot_training_curve(losses, [{"step": 20, "loss": 2.0}, {"step": 40, "loss": 1.5}],
                              reference=(np.log(65), "log 65"), log_scale=True)
    lines = fig.axes[0].lines
    assert len(lines) == 4 and fig.axes[0].get_yscale() == "log"
    np.testing.assert_allclose(lines[1].get_ydata(), np.convolve(losses, np.ones(2) / 2, mode="valid"))
    with pytest.raises(ValueError, match="non-empty 1-D"):
        plot_training_curve([], [])

    kp = np.array([[5.0, 5.0], [10.0, 20.0]])
    fig = plot_matches(image, image, {"untrained": (kp, kp, np.array([[0, 0], [1, 1]]), np.array([True, False])),
                                      "trained": (kp, kp, np.zeros((0, 2), int), np.zeros(0, bool))})
    assert [ax.get_title().split(":")[0] for ax in fig.axes] == ["untrained", "trained"]
    assert len(fig.axes[0].lines) == 2 and fig.axes[0].lines[0].get_xdata()[1] == 5.0 + image.shape[1]
    _render(fig)
    with pytest.raises(ValueError, match="one shape"):
        plot_matches(image, image[:10], {})


def test_detections_grid_rows_are_detectors(image: np.ndarray) -> None:
    labels = [np.array([[5.0, 5.0]]), np.zeros((0, 2))]
    found = {"untrained": [np.array([[1.0, 1.0]]), np.array([[2.0, 2.0], [3.0, 3.0]])],
             "trained": [np.array([[5.0, 5.0]]), np.zeros((0, 2))]}
    fig = plot_detections([image, image], labels, found, titles=["cube", "star"])
    titles = ["untrained: cube", "untrained: star", "trained: cube", "trained: star"]
    assert [ax.get_title() for ax in fig.axes] == titles
    red = fig.axes[1].collections[1].get_offsets()
    np.testing.assert_allclose(red, found["untrained"][1])  # the detections of that detector on that image
    _render(fig)
    with pytest.raises(ValueError, match="one \\(M, 2\\) array per image"):
        plot_detections([image, image], labels, {"a": [np.zeros((0, 2))]})


def test_heatmap_row_and_cell_correspondences(image: np.ndarray) -> None:
    fig = plot_heatmap_row([image, image * 2, image], ["image", "one view", "labels"], ["gray", "magma", "gray"],
                           points={2: np.array([[3.0, 4.0], [10.0, 12.0]])})
    assert [ax.get_title() for ax in fig.axes] == ["image", "one view", "labels", ""]  # a colour bar for the heatmap
    np.testing.assert_allclose(fig.axes[2].collections[0].get_offsets(), [[3.0, 4.0], [10.0, 12.0]])
    assert not fig.axes[1].collections  # no points on the other panels
    with pytest.raises(ValueError, match="panel indices"):
        plot_heatmap_row([image], ["a"], points={3: np.zeros((1, 2))})
    fig = plot_heatmap_row([image, image * 2, image * 3], ["a", "b", "c"], ["gray", "magma", "magma"],
                           colorbar_labels={0: "intensity", 2: "probability"}, shared=[(1, 2)])
    assert [ax.get_ylabel() for ax in fig.axes[3:]] == ["intensity", "", "probability"]
    assert fig.axes[1].images[0].get_clim() == fig.axes[2].images[0].get_clim() == (
        pytest.approx(2 * image.min()), pytest.approx(3 * image.max()))
    _render(fig)
    with pytest.raises(ValueError, match="groups of panel indices"):
        plot_heatmap_row([image, image], ["a", "b"], shared=[(0, 5)])

    centres = np.array([[3.5, 3.5], [11.5, 3.5], [19.5, 3.5]])
    S = np.array([[0, 1, 0], [0, 0, 1], [0, 0, 0]])
    fig = plot_cell_correspondences(image, image, centres, S)
    np.testing.assert_allclose(fig.axes[0].collections[0].get_offsets(), centres[[0, 1]])  # rows with a match
    np.testing.assert_allclose(fig.axes[1].collections[0].get_offsets(), centres[[1, 2]])  # their partners
    _render(fig)
    with pytest.raises(ValueError, match=r"shape \(N, N\)"):
        plot_cell_correspondences(image, image, centres, np.eye(2))


def test_labelled_images_grid_circles_each_images_keypoints(image: np.ndarray, rng: np.random.Generator) -> None:
    points = [rng.uniform(0, 40, (4, 2)), np.zeros((0, 2)), rng.uniform(0, 40, (2, 2))]
    fig = plot_labelled_images([image] * 3, points, ["cube", "ellipses", "star"], ncols=2)
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert len(fig.axes) == 4 and [ax.get_title() for ax in shown] == ["cube", "ellipses", "star"]  # 2 x 2, one hidden
    for ax, p in zip(shown, points):
        np.testing.assert_allclose(ax.collections[0].get_offsets().reshape(-1, 2), p)
    _render(fig)

    mask = np.zeros_like(image)
    mask[5:30, 10:50] = 1.0
    fig = plot_labelled_images([image, image], points[:2], ["a", "b"], masks=[mask, mask], ncols=4)
    assert len(fig.axes) == 2  # ncols shrinks to the number of images
    assert len(fig.axes[0].collections) == 2  # the mask's contour and the keypoints
    _render(fig)
    with pytest.raises(ValueError, match="equal length"):
        plot_labelled_images([image, image], points[:1], ["a", "b"])
    with pytest.raises(ValueError, match=r"masks\[0\] must have the shape of images\[0\]"):
        plot_labelled_images([image], points[:1], ["a"], masks=[mask[:10]])
    with pytest.raises(ValueError, match=r"keypoints\[0\] must have shape \(N, 2\)"):
        plot_labelled_images([image], [np.zeros((3, 3))], ["a"])


def test_cell_probabilities_shows_the_cell_and_cell_borders() -> None:
    probabilities = np.full(65, 0.5 / 64)
    probabilities[-1] = 0.5
    heatmap = np.zeros((16, 24))
    fig = plot_cell_probabilities(probabilities, heatmap, cell_name="(0, 1)")
    left, right, left_bar, right_bar = fig.axes
    assert (left_bar.get_ylabel(), right_bar.get_ylabel()) == ("probability", "keypoint probability")
    assert left.get_title() == "65 probabilities of cell (0, 1): 64 pixels + dustbin (last)"
    np.testing.assert_allclose(left.images[0].get_array(), probabilities[None])
    assert len(right.lines) == 3  # borders between the 2 x 3 cells: 2 vertical, then 1 horizontal
    assert [list(line.get_xdata()) for line in right.lines[:2]] == [[7.5, 7.5], [15.5, 15.5]]
    assert list(right.lines[2].get_ydata()) == [7.5, 7.5]
    fig = plot_cell_probabilities(np.full(17, 1 / 17), np.zeros((12, 8)), cell=4)
    assert len(fig.axes[1].lines) == 1 + 2  # 8 / 4 - 1 vertical, 12 / 4 - 1 horizontal
    _render(fig)
    with pytest.raises(ValueError, match=r"shape \(cell\^2 \+ 1,\) = \(65,\)"):
        plot_cell_probabilities(np.ones(64), heatmap)
    with pytest.raises(ValueError, match="multiples of cell = 8"):
        plot_cell_probabilities(probabilities, np.zeros((16, 20)))


def test_repeated_points_colours_follow_the_flags(image: np.ndarray, rng: np.random.Generator) -> None:
    warped, detected = rng.uniform(0, 40, (7, 2)), rng.uniform(0, 40, (5, 2))
    repeated = np.array([True, False, True, True, False, False, True])
    fig = plot_repeated_points(image, warped, detected, repeated, eps=3, title="SIFT")
    blue, green, red = fig.axes[0].collections
    np.testing.assert_allclose(blue.get_offsets(), detected)
    np.testing.assert_allclose(green.get_offsets(), warped[repeated])
    np.testing.assert_allclose(red.get_offsets(), warped[~repeated])
    assert fig.axes[0].get_legend().get_texts()[1].get_text() == "H x_i, repeated (eps = 3)"
    _render(fig)
    with pytest.raises(ValueError, match=r"repeated must be \(7,\) booleans"):
        plot_repeated_points(image, warped, detected, repeated[:3], eps=3)
    with pytest.raises(ValueError, match="booleans"):
        plot_repeated_points(image, warped, detected, repeated.astype(int), eps=3)


def test_homography_corners_draw_both_quadrilaterals_and_the_mean_error(image: np.ndarray) -> None:
    h, w = image.shape
    true = np.array([[-12.0, -8.0], [w + 10.0, -6.0], [-9.0, h + 7.0], [w + 12.0, h + 9.0]])  # a zoom
    estimated = true + np.array([[3.0, 4.0], [0.0, 0.0], [-6.0, 8.0], [0.0, 0.0]])  # errors 5, 0, 10, 0
    fig = plot_homography_corners(image, true, estimated)
    ax = fig.axes[0]
    assert ax.get_title() == "image 1's corners in image 2: mean error 3.75 px"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x in image 2 (px)", "y in image 2 (px)")
    x, y = ax.lines[0].get_data()
    np.testing.assert_allclose(np.column_stack([x, y]), true[[0, 1, 3, 2, 0]])  # a closed quadrilateral
    assert ax.get_xlim()[0] < true[:, 0].min() and ax.get_xlim()[1] > true[:, 0].max()  # corners outside the image
    assert ax.get_ylim()[0] > true[:, 1].max()  # image convention: y grows downwards
    _render(fig)
    with pytest.raises(ValueError, match=r"corners_estimated must have shape \(4, 2\)"):
        plot_homography_corners(image, true, estimated[:3])
    with pytest.raises(ValueError, match="corners_true must be finite"):
        plot_homography_corners(image, np.full((4, 2), np.inf), estimated)


def test_match_grid_rows_are_methods_columns_are_pairs(image: np.ndarray, rng: np.random.Generator) -> None:
    kp = rng.uniform(0, 40, (30, 2))
    matches = np.column_stack([np.arange(30), np.arange(30)])
    correct = np.arange(30) % 3 == 0  # 10 of 30
    none = (kp, kp, np.zeros((0, 2), int), np.zeros(0, bool))
    results = {"viewpoint": {"sift": (kp, kp, matches, correct), "orb": none},
               "illumination": {"sift": (kp, kp, matches[:4], correct[:4]), "orb": none}}
    fig = plot_match_grid({"viewpoint": (image, image[:30]), "illumination": (image, image)}, results, rng=0,
                          max_drawn=12, gap=10)
    axes = np.array(fig.axes).reshape(2, 2)
    assert axes[0, 0].get_title() == "VIEWPOINT — sift: 10 of 30 matches correct (33%)"
    assert axes[1, 0].get_title() == "orb: 0 of 0 matches correct"
    assert axes[0, 1].get_title() == "ILLUMINATION — sift: 2 of 4 matches correct (50%)"
    assert len(axes[0, 0].lines) == 12 and len(axes[0, 1].lines) == 4  # at most max_drawn lines
    assert axes[0, 0].images[0].get_array().shape == (40, 60 + 10 + 60)  # side by side with a gap
    for line in axes[0, 1].lines:  # every line joins a point to its partner, shifted by width + gap
        x, y = line.get_data()
        assert x[1] - x[0] == pytest.approx(70.0) and y[0] == pytest.approx(y[1])
    colours = {matplotlib.colors.to_hex(line.get_color()) for line in axes[0, 0].lines}
    assert colours <= {matplotlib.colors.to_hex("tab:green"), matplotlib.colors.to_hex("tab:red")}
    again = plot_match_grid({"viewpoint": (image, image[:30]), "illumination": (image, image)}, results, rng=0,
                            max_drawn=12)
    assert [line.get_xdata()[0] for line in again.axes[0].lines] == [line.get_xdata()[0] for line in axes[0, 0].lines]
    _render(fig)
    with pytest.raises(ValueError, match="same non-empty columns"):
        plot_match_grid({"viewpoint": (image, image)}, results)
    with pytest.raises(ValueError, match="same non-empty methods"):
        plot_match_grid({"a": (image, image), "b": (image, image)}, {"a": {"sift": none}, "b": {"orb": none}})
    with pytest.raises(ValueError, match="one boolean per match"):
        plot_match_grid({"a": (image, image)}, {"a": {"sift": (kp, kp, matches, correct[:5])}})


def test_oracle_corner_errors_scatter_clipped_for_log_axes() -> None:
    fig = plot_oracle_corner_errors({"sift": ([120, 40, 0], [0.01, 2.5, np.inf]), "net": ([8], [12.0])}, eps=3.0)
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    np.testing.assert_allclose(ax.collections[0].get_offsets(), [[120, 0.05], [40, 2.5], [1, 1000]])
    np.testing.assert_allclose(ax.collections[1].get_offsets(), [[8, 12.0]])
    assert list(ax.lines[0].get_ydata()) == [3.0, 3.0]
    _render(fig)
    with pytest.raises(ValueError, match="at least one detector"):
        plot_oracle_corner_errors({})
    with pytest.raises(ValueError, match=r"diagnoses\['sift'\] must be two \(P,\) arrays of equal length"):
        plot_oracle_corner_errors({"sift": ([1, 2], [1.0])})


def _arrow_styles(ax) -> list[str]:
    """The line style of every arrow annotation of ``ax``: '-' solid or ':' dotted."""
    return [a.arrow_patch.get_linestyle() for a in ax.texts if getattr(a, "arrow_patch", None) is not None]


def test_feature_schematic_draws_detector_descriptor_window_shifts_and_repeatability() -> None:
    fig = plot_feature_schematic(eps=3.0)
    titles = [ax.get_title() for ax in fig.axes]
    assert [t.split(":")[0] for t in titles] == ["detector", "one keypoint", "descriptor", "flat", "edge", "corner",
                                                 "repeatability"]
    flat, edge, corner = fig.axes[3:6]
    solid, dotted = "-", ":"
    assert set(_arrow_styles(flat)) == {dotted}  # no shift changes a flat window
    assert sorted(_arrow_styles(edge)).count(dotted) == 2  # up and down along the vertical edge
    assert set(_arrow_styles(corner)) == {solid}  # every shift changes a corner's window
    assert "λ2 = 0.00" in flat.texts[-1].get_text() and "λ2 = 0.00" in edge.texts[-1].get_text()
    assert "λ2 = 0.00" not in corner.texts[-1].get_text()
    bars = fig.axes[2].patches
    assert len(bars) == 32 and np.isclose(np.linalg.norm([b.get_height() for b in bars]), 1.0)  # unit length
    assert titles[-1].endswith("Rep = (6 + 6) / (7 + 7) = 0.86")  # one detection drawn 9 px off
    assert "Rep = (7 + 7)" in plot_feature_schematic(eps=10.0).axes[-1].get_title()
    _render(fig)
    with pytest.raises(ValueError, match="positive number of pixels"):
        plot_feature_schematic(eps=0.0)


def test_evaluation_schematic_draws_the_four_steps_with_computed_values() -> None:
    fig = plot_evaluation_schematic(eps=3.0)
    pair, repeat, match, homography = fig.axes
    assert "Rep = (6 + 6) / (7 + 7) = 0.86" in repeat.get_title()
    colours = [matplotlib.colors.to_hex(line.get_color()) for line in match.lines]
    assert colours.count(matplotlib.colors.to_hex("tab:green")) == 4  # 7 matches: 2 swapped, 1 detection off
    assert "(4 of 7)" in match.get_title()
    assert "not correct at ε = 3 px" in homography.get_title()
    assert "4.1 px" in homography.get_title()
    assert plot_evaluation_schematic(eps=5.0).axes[3].get_title().endswith("\ncorrect at ε = 5 px")
    assert (homography.get_xlabel(), homography.get_ylabel()) == ("x in image 2 (px)", "y in image 2 (px)")
    _render(fig)
    with pytest.raises(ValueError, match="positive number of pixels"):
        plot_evaluation_schematic(eps=float("nan"))
