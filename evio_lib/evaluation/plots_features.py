"""Figures for the feature lessons (notebooks 05-08): keypoints on images, the FAST circle, scale space, binary
descriptors, labelled Synthetic Shapes, SuperPoint's cell softmax, repeatability, homography corners, training
curves, descriptor matches and the match diagnosis; and two schematics drawn on a made-up scene, the ideas of a
feature front end (:func:`plot_feature_schematic`, notebook 05) and the benchmark's protocol
(:func:`plot_evaluation_schematic`, notebook 08).

Plotting only; the detectors live in :mod:`evio_lib.features`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "plot_structure_tensor_classes",
    "plot_keypoints",
    "plot_fast_circle",
    "plot_scale_space",
    "plot_binary_descriptors",
    "plot_repeatability_pair",
    "plot_repeatability_bars",
    "plot_training_curve",
    "plot_matches",
    "plot_detections",
    "plot_heatmap_row",
    "plot_cell_correspondences",
    "plot_labelled_images",
    "plot_cell_probabilities",
    "plot_repeated_points",
    "plot_homography_corners",
    "plot_match_grid",
    "plot_oracle_corner_errors",
    "plot_feature_schematic",
    "plot_evaluation_schematic",
]


def _image(image: ArrayLike, name: str = "image") -> NDArray:
    """Return ``image`` as a 2-D array or raise ValueError naming the expected shape."""
    array = np.asarray(image)
    if array.ndim != 2:
        raise ValueError(f"{name} must be a 2-D grayscale image (H, W); got shape {array.shape}")
    return array


def _points(points: ArrayLike, name: str = "keypoints") -> NDArray[np.float64]:
    """Return ``points`` as an (N, 2) float array or raise ValueError naming the expected shape."""
    array = np.asarray(points, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 2))
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) as (x, y) pixels; got {array.shape}")
    return array


def plot_structure_tensor_classes(image: ArrayLike, response: ArrayLike, classes: ArrayLike,
                                  clip: float = 0.05) -> "Figure":
    """Return a three-panel figure: the image, a corner response (red > 0, blue < 0, with its colour bar) and a
    flat/edge/corner map.

    Args:
        image: (H, W) grayscale image.
        response: (H, W) corner response, e.g. Harris's R = det M - k tr(M)^2.
        classes: (H, W) integers, 0 = flat, 1 = edge, 2 = corner.
        clip: the colour scale ends at ``clip * max |response|``.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_structure_tensor_classes(np.zeros((8, 8)), np.ones((8, 8)), np.zeros((8, 8), int))
    >>> len(fig.axes), fig.axes[3].get_ylabel()
    (4, 'R (colour scale clipped at ±5 % of max |R|)')
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    image, response, classes = _image(image), _image(response, "response"), _image(classes, "classes")
    if not image.shape == response.shape == classes.shape:
        raise ValueError(f"image, response and classes must share one shape; got {image.shape}, {response.shape}, "
                         f"{classes.shape}")
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.6))
    axes[0].imshow(image, cmap="gray")
    axes[0].set_title("image")
    lim = max(float(np.abs(response).max()) * clip, 1e-12)
    shown = axes[1].imshow(response, cmap="coolwarm", vmin=-lim, vmax=lim)
    axes[1].set_title("corner response R (clipped)")
    fig.colorbar(shown, ax=axes[1], fraction=0.046, pad=0.03).set_label(
        f"R (colour scale clipped at ±{clip:.0%} of max |R|)".replace("%", " %"))
    axes[2].imshow(classes, cmap=ListedColormap(["black", "tab:blue", "tab:orange"]), vmin=0, vmax=2,
                   interpolation="nearest")
    axes[2].set_title("flat (black) / edge (blue) / corner (orange)")
    for ax in axes:
        ax.axis("off")
    fig.tight_layout()
    return fig


def plot_keypoints(image: ArrayLike, keypoints: Mapping[str, ArrayLike], ncols: int = 3, ranked: bool = False,
                   size: float = 10.0, panel_in: float = 5.0) -> "Figure":
    """Return a grid of panels, one per detector, each showing the image with that detector's keypoints.

    Args:
        image: (H, W) grayscale image, shown under every panel.
        keypoints: detector name -> (N, 2) keypoints (x, y) in pixels; the panel title gives the count.
        ncols: panels per row.
        ranked: colour the points by rank (yellow = weaker, assuming strongest first) instead of one colour; one
            colour bar gives the rank as a fraction of each panel's count (0 = strongest, 1 = weakest).
        size: marker size.
        panel_in: width of one panel in inches.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_keypoints(np.zeros((20, 30)), {"a": [[1.0, 2.0]], "b": np.zeros((0, 2))}, ncols=2)
    >>> [ax.get_title() for ax in fig.axes]
    ['a: 1', 'b: 0']
    """
    import matplotlib.pyplot as plt

    image = _image(image)
    if not keypoints:
        raise ValueError("keypoints must name at least one detector")
    if ncols < 1:
        raise ValueError(f"ncols must be >= 1; got {ncols}")
    n = len(keypoints)
    ncols = min(ncols, n)
    nrows = -(-n // ncols)
    aspect = image.shape[0] / image.shape[1]
    fig, axes = plt.subplots(nrows, ncols, figsize=(panel_in * ncols, panel_in * aspect * nrows + 0.4 * nrows),
                             squeeze=False)
    for ax, (name, points) in zip(axes.ravel(), keypoints.items()):
        points = _points(points, f"keypoints[{name!r}]")
        ax.imshow(image, cmap="gray")
        if ranked:
            rank = np.arange(len(points)) / max(len(points) - 1, 1)
            shown = ax.scatter(points[:, 0], points[:, 1], s=size, c=rank, cmap="autumn", vmin=0, vmax=1)
        else:
            ax.scatter(points[:, 0], points[:, 1], s=size, c="tab:orange")
        ax.set_title(f"{name}: {len(points)}")
    for ax in axes.ravel():
        ax.axis("off")
    fig.tight_layout()
    if ranked:
        fig.colorbar(shown, ax=axes.ravel().tolist(), fraction=0.025, pad=0.01).set_label(
            "rank / count (0 = strongest, 1 = weakest)")
    return fig


def plot_fast_circle(image: ArrayLike, centre: Sequence[int], circle: ArrayLike, score: float,
                     keypoints: ArrayLike | None = None) -> "Figure":
    """Return FAST's segment test at one pixel: the 16-pixel circle coloured by the test, and all keypoints.

    A circle pixel is red when it is brighter than the centre by more than ``score``, blue when darker by more.

    Args:
        image: (H, W) grayscale image.
        centre: (x, y) integer pixel of the tested point, at least 5 px from the border.
        circle: (16, 2) integer offsets (dx, dy) of the circle pixels.
        score: the threshold t used to colour the circle (FAST's score of the point).
        keypoints: (N, 2) keypoints to show on the whole image in the second panel.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> circle = np.array([(3, 0), (0, 3), (-3, 0), (0, -3)] * 4)
    >>> len(plot_fast_circle(np.zeros((20, 20)), (10, 10), circle, 5.0).axes)
    2
    """
    import matplotlib.pyplot as plt

    image = _image(image)
    circle = np.asarray(circle, dtype=int)
    if circle.ndim != 2 or circle.shape[1] != 2:
        raise ValueError(f"circle must have shape (16, 2) as (dx, dy) offsets; got {circle.shape}")
    px, py = int(centre[0]), int(centre[1])
    if not (5 <= px < image.shape[1] - 5 and 5 <= py < image.shape[0] - 5):
        raise ValueError(f"centre must lie at least 5 px inside the {image.shape} image; got ({px}, {py})")
    d = image[py + circle[:, 1], px + circle[:, 0]].astype(np.float64) - float(image[py, px])  # I_k - I_p
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    axes[0].imshow(image[py - 5: py + 6, px - 5: px + 6], cmap="gray", extent=(-5.5, 5.5, 5.5, -5.5))
    colours = np.where(d > score, "tab:red", np.where(d < -score, "tab:blue", "white"))
    axes[0].scatter(circle[:, 0], circle[:, 1], s=120, facecolors="none", edgecolors=colours, linewidths=2)
    axes[0].plot(0, 0, "g+", ms=14, mew=2)
    axes[0].set_title("the 16-pixel circle (red brighter, blue darker by > s)")
    axes[0].set_xlabel("x − x_p (px)")
    axes[0].set_ylabel("y − y_p (px)")
    axes[1].imshow(image, cmap="gray")
    points = _points(keypoints if keypoints is not None else np.zeros((0, 2)))
    axes[1].scatter(points[:, 0], points[:, 1], s=10, c="tab:orange")
    axes[1].set_title(f"FAST: {len(points)} keypoints")
    axes[1].axis("off")
    fig.tight_layout()
    return fig


def plot_scale_space(dogs: Sequence[ArrayLike], sigmas: Sequence[float], image: ArrayLike,
                     keypoints: ArrayLike, clip_percentile: float = 99.5) -> "Figure":
    """Return one row: the difference-of-Gaussian levels (red > 0, blue < 0) and the image with SIFT keypoints.

    Every level is drawn on one symmetric colour range, +-``clip_percentile`` of |D| over all levels (a few strong
    responses would otherwise wash the rest out), with one colour bar.

    Args:
        dogs: K (H, W) difference-of-Gaussian images D = G(k sigma) * I - G(sigma) * I.
        sigmas: K scales sigma, one per level (used in the titles).
        image: (H, W) grayscale image.
        keypoints: (N, 2) keypoints (x, y).
        clip_percentile: the percentile of |D| (over every level) where the colour scale ends, in (0, 100].

    >>> import matplotlib; matplotlib.use("Agg")
    >>> len(plot_scale_space([np.ones((4, 4))], [1.6], np.zeros((4, 4)), [[1.0, 1.0]]).axes)  # and a colour bar
    3
    """
    import matplotlib.pyplot as plt

    if len(dogs) != len(sigmas) or len(dogs) == 0:
        raise ValueError(f"dogs and sigmas must be non-empty and of equal length; got {len(dogs)} and {len(sigmas)}")
    image, points = _image(image), _points(keypoints)
    if not 0 < clip_percentile <= 100:
        raise ValueError(f"clip_percentile must lie in (0, 100]; got {clip_percentile}")
    dogs = [_image(dog, "dog") for dog in dogs]
    magnitudes = np.concatenate([np.abs(dog).ravel() for dog in dogs])
    lim = max(float(np.percentile(magnitudes, clip_percentile)), 1e-12)  # one colour range for every level
    fig, axes = plt.subplots(1, len(dogs) + 1, figsize=(4 * (len(dogs) + 1) + 0.8, 4.3), layout="constrained")
    for ax, dog, sigma in zip(axes, dogs, sigmas):
        shown = ax.imshow(dog, cmap="coolwarm", vmin=-lim, vmax=lim)
        ax.set_title(f"DoG, sigma = {sigma:.2f}")
        ax.axis("off")
    extend = "both" if lim < magnitudes.max() else "neither"
    fig.colorbar(shown, ax=list(axes[:-1]), fraction=0.02, pad=0.01, extend=extend).set_label(
        "D (image intensity units)")
    axes[-1].imshow(image, cmap="gray")
    axes[-1].scatter(points[:, 0], points[:, 1], s=10, c="tab:orange")
    axes[-1].set_title(f"SIFT: {len(points)} keypoints")
    axes[-1].axis("off")
    return fig


def plot_binary_descriptors(bits: ArrayLike, n_rows: int = 12, title: str = "") -> "Figure":
    """Return the first ``n_rows`` binary descriptors as a black-and-white bit image (black = 1).

    Args:
        bits: (N, B) array of 0/1 bits, e.g. ``np.unpackbits(descriptors, axis=1)``.
        n_rows: number of descriptors (rows) to show.
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> len(plot_binary_descriptors(np.eye(4, 16, dtype=np.uint8)).axes)
    1
    """
    import matplotlib.pyplot as plt

    bits = np.asarray(bits)
    if bits.ndim != 2 or not np.isin(bits, (0, 1)).all():
        raise ValueError(f"bits must be an (N, B) array of zeros and ones; got shape {bits.shape}")
    fig, ax = plt.subplots(figsize=(12, 2.4))
    ax.imshow(bits[:n_rows], cmap="gray_r", aspect="auto", interpolation="nearest", vmin=0, vmax=1)
    ax.set_xlabel("bit")
    ax.set_ylabel("keypoint")
    ax.set_title(title)
    return fig


def plot_repeatability_pair(image1: ArrayLike, image2: ArrayLike, keypoints1_in_2: ArrayLike, keypoints2: ArrayLike,
                            found: ArrayLike, keypoints1: ArrayLike, eps: float) -> "Figure":
    """Return two panels: image 1 with its points (green: found again within eps, red: not), image 2 with both sets.

    Args:
        image1, image2: (H, W) grayscale images, image 2 = image 1 warped by a homography H.
        keypoints1_in_2: (N1, 2) points of image 1 that image 2 sees, warped into image 2 (H x_i).
        keypoints2: (N2, 2) points detected in image 2.
        found: (N1,) booleans, True where a point of image 2 lies within ``eps`` of ``keypoints1_in_2``.
        keypoints1: (N1, 2) the same points of image 1 before the warp.
        eps: the distance threshold in pixels (titles only).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> p = np.array([[2.0, 3.0]])
    >>> len(plot_repeatability_pair(np.zeros((9, 9)), np.zeros((9, 9)), p, p, [True], p, 3).axes)
    2
    """
    import matplotlib.pyplot as plt

    image1, image2 = _image(image1, "image1"), _image(image2, "image2")
    warped, points2, points1 = _points(keypoints1_in_2), _points(keypoints2), _points(keypoints1)
    found = np.asarray(found, dtype=bool)
    if not len(found) == len(warped) == len(points1):
        raise ValueError(f"found, keypoints1_in_2 and keypoints1 must have one row per point; got {len(found)}, "
                         f"{len(warped)}, {len(points1)}")
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    axes[0].imshow(image1, cmap="gray")
    axes[0].scatter(points1[:, 0], points1[:, 1], s=12, c=np.where(found, "lime", "red"))
    axes[0].set_title(f"image 1 (green: found again within {eps:g} px)")
    axes[1].imshow(image2, cmap="gray")
    axes[1].scatter(points2[:, 0], points2[:, 1], s=12, c="tab:orange", label="detected in image 2")
    axes[1].scatter(warped[:, 0], warped[:, 1], s=30, facecolors="none", edgecolors="cyan",
                    label="image-1 points warped by H")
    axes[1].legend(loc="lower right", fontsize=8)
    axes[1].set_title("image 2 = image 1 warped by a random homography")
    for ax in axes:
        ax.axis("off")
    fig.tight_layout()
    return fig


def plot_repeatability_bars(table: Mapping[str, Mapping[str, ArrayLike]], eps_list: Sequence[float]) -> "Figure":
    """Return one bar chart per split: the repeatability of every detector at every threshold eps.

    Args:
        table: detector -> split name -> (len(eps_list),) repeatability values in [0, 1].
        eps_list: the thresholds in pixels, one bar per threshold.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_repeatability_bars({"harris": {"viewpoint": [0.5, 0.7]}}, (1, 3))
    >>> fig.axes[0].get_title()
    'viewpoint changes'
    """
    import matplotlib.pyplot as plt

    names = list(table)
    if not names:
        raise ValueError("table must hold at least one detector")
    splits = list(table[names[0]])
    for name in names:
        for split in splits:
            if np.shape(table[name][split]) != (len(eps_list),):
                raise ValueError(f"table[{name!r}][{split!r}] must hold one value per eps ({len(eps_list)}); "
                                 f"got shape {np.shape(table[name][split])}")
    fig, axes = plt.subplots(1, len(splits), figsize=(6.5 * len(splits), 4), sharey=True, squeeze=False)
    x = np.arange(len(names))
    width = 0.8 / len(eps_list)
    for ax, split in zip(axes[0], splits):
        for k, eps in enumerate(eps_list):
            ax.bar(x + (k - (len(eps_list) - 1) / 2) * width, [table[n][split][k] for n in names], width=width,
                   label=f"eps = {eps:g} px")
        ax.set_xticks(x, names, rotation=20)
        ax.set_title(f"{split} changes")
        ax.set_ylim(0, 1)
    axes[0, 0].set_ylabel("repeatability")
    axes[0, 0].legend()
    fig.tight_layout()
    return fig


def plot_training_curve(train_loss: ArrayLike, validation: Sequence[Mapping[str, float]],
                        ylabel: str = "loss", reference: tuple[float, str] | None = None,
                        log_scale: bool = False) -> "Figure":
    """Return the training loss per step, its running mean over ~5 % of the run, and the validation loss.

    Args:
        train_loss: (S,) training loss of every step.
        validation: records with at least ``"step"`` and ``"loss"`` (``TrainResult.validation``).
        ylabel: label of the loss axis.
        reference: optional (value, label) of a horizontal reference line, e.g. (log 65, "uniform guess").
        log_scale: draw the loss on a logarithmic axis.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_training_curve([3.0, 2.0, 1.0], [{"step": 2, "loss": 1.5}])
    >>> len(fig.axes[0].lines)
    3
    """
    import matplotlib.pyplot as plt

    losses = np.asarray(train_loss, dtype=np.float64)
    if losses.ndim != 1 or len(losses) == 0:
        raise ValueError(f"train_loss must be a non-empty 1-D sequence; got shape {losses.shape}")
    window = max(1, len(losses) // 20)
    smooth = np.convolve(losses, np.ones(window) / window, mode="valid")
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.plot(np.arange(1, len(losses) + 1), losses, color="0.75", lw=0.8, label="training loss (per step)")
    ax.plot(np.arange(window, len(losses) + 1), smooth, color="tab:blue", label=f"training loss ({window}-step mean)")
    ax.plot([v["step"] for v in validation], [v["loss"] for v in validation], "o-", color="tab:red",
            label="validation loss")
    if reference is not None:
        ax.axhline(reference[0], color="k", ls=":", lw=0.8, label=reference[1])
    if log_scale:
        ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel(ylabel)
    ax.legend()
    fig.tight_layout()
    return fig


def plot_matches(image1: ArrayLike, image2: ArrayLike, results: Mapping[str, tuple], tolerance: float = 3.0
                 ) -> "Figure":
    """Return one panel per network: the two images side by side with its matches (green correct, red wrong).

    Args:
        image1, image2: (H, W) grayscale images of the same size.
        results: name -> (keypoints1 (N1, 2), keypoints2 (N2, 2), matches (M, 2) index pairs, correct (M,) bools).
        tolerance: the correctness threshold in pixels (titles only).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> kp = np.array([[1.0, 1.0]])
    >>> len(plot_matches(np.zeros((5, 5)), np.zeros((5, 5)), {"a": (kp, kp, np.array([[0, 0]]), [True])}).axes)
    1
    """
    import matplotlib.pyplot as plt

    image1, image2 = _image(image1, "image1"), _image(image2, "image2")
    if image1.shape != image2.shape:
        raise ValueError(f"image1 and image2 must have one shape; got {image1.shape} and {image2.shape}")
    width = image1.shape[1]
    fig, axes = plt.subplots(1, len(results), figsize=(8 * len(results), 8 * image1.shape[0] / (2 * width) + 0.6),
                             squeeze=False)
    for ax, (name, (kp1, kp2, matches, correct)) in zip(axes[0], results.items()):
        kp1, kp2 = _points(kp1, "keypoints1"), _points(kp2, "keypoints2")
        matches, correct = np.asarray(matches, dtype=int).reshape(-1, 2), np.asarray(correct, dtype=bool)
        ax.imshow(np.hstack([image1, image2]), cmap="gray", vmin=0, vmax=1)
        for (i, j), ok in zip(matches, correct):
            ax.plot([kp1[i, 0], kp2[j, 0] + width], [kp1[i, 1], kp2[j, 1]], color="lime" if ok else "red", lw=0.7)
        ax.set_title(f"{name}: {int(correct.sum())} of {len(matches)} matches correct (green, <= {tolerance:g} px)")
        ax.axis("off")
    fig.tight_layout()
    return fig


def plot_detections(images: Sequence[ArrayLike], labels: Sequence[ArrayLike],
                    detections: Mapping[str, Sequence[ArrayLike]], titles: Sequence[str] | None = None) -> "Figure":
    """Return a grid with one row per detector and one column per image: labels (green circles), detections (red).

    Args:
        images: K (H, W) grayscale images in [0, 1].
        labels: K (N_k, 2) true keypoints (x, y).
        detections: detector name -> K (M_k, 2) detected keypoints (x, y), one array per image.
        titles: optional K column titles (e.g. the shape kind), prefixed by the detector name.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_detections([np.zeros((8, 8))], [[[1.0, 1.0]]], {"a": [[[2.0, 2.0]]], "b": [np.zeros((0, 2))]})
    >>> [ax.get_title() for ax in fig.axes]
    ['a', 'b']
    """
    import matplotlib.pyplot as plt

    if len(images) == 0 or len(labels) != len(images):
        raise ValueError(f"images and labels must be non-empty and of equal length; got {len(images)} and "
                         f"{len(labels)}")
    for name, rows in detections.items():
        if len(rows) < len(images):
            raise ValueError(f"detections[{name!r}] must hold one (M, 2) array per image ({len(images)}); "
                             f"got {len(rows)}")
    if titles is not None and len(titles) != len(images):
        raise ValueError(f"titles must hold one title per image ({len(images)}); got {len(titles)}")
    n_rows, n_cols = max(len(detections), 1), len(images)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(4 * n_cols, 3.1 * n_rows), squeeze=False)
    for row, (name, rows) in enumerate(detections.items()):
        for col, image in enumerate(images):
            ax = axes[row, col]
            truth, found = _points(labels[col], "labels"), _points(rows[col], "detections")
            ax.imshow(_image(image), cmap="gray", vmin=0, vmax=1)
            ax.scatter(truth[:, 0], truth[:, 1], s=40, facecolors="none", edgecolors="lime", linewidths=1.5)
            ax.scatter(found[:, 0], found[:, 1], s=10, color="red")
            ax.set_title(name if titles is None else f"{name}: {titles[col]}", fontsize=9)
            ax.axis("off")
    fig.suptitle("green circles: labels, red dots: detections")
    fig.tight_layout()
    return fig


def plot_heatmap_row(images: Sequence[ArrayLike], titles: Sequence[str], cmaps: Sequence[str] | str = "magma",
                     points: Mapping[int, ArrayLike] | None = None, panel_in: float = 4.2,
                     colorbar_labels: Mapping[int, str] | None = None,
                     shared: Sequence[Sequence[int]] = ()) -> "Figure":
    """Return one row of image panels (e.g. an image, detector heatmaps), with keypoints circled on chosen panels.

    Every panel that is not grayscale gets a colour bar (a heatmap's colour means a value); a grayscale panel gets
    one only when ``colorbar_labels`` names it.

    Args:
        images: K (H, W) arrays; grayscale panels (cmap "gray") are drawn on [0, 1].
        titles: K panel titles.
        cmaps: one colour map for every panel, or K of them.
        points: panel index -> (N, 2) keypoints (x, y) to circle in red on that panel.
        panel_in: width of one panel in inches.
        colorbar_labels: panel index -> the label of its colour bar (the quantity and its unit).
        shared: groups of panel indices drawn on one colour range (the smallest minimum and largest maximum of the
            group), e.g. ``[(1, 2)]`` for two heatmaps of the same quantity.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_heatmap_row([np.zeros((4, 4)), np.ones((4, 4))], ["a", "b"], ["gray", "magma"], {0: [[1.0, 2.0]]},
    ...                        colorbar_labels={1: "probability"})
    >>> [ax.get_title() for ax in fig.axes], fig.axes[2].get_ylabel()
    (['a', 'b', ''], 'probability')
    """
    import matplotlib.pyplot as plt

    if len(images) == 0 or len(titles) != len(images):
        raise ValueError(f"images and titles must be non-empty and of equal length; got {len(images)} and "
                         f"{len(titles)}")
    cmaps = [cmaps] * len(images) if isinstance(cmaps, str) else list(cmaps)
    if len(cmaps) != len(images):
        raise ValueError(f"cmaps must be one name or one per image ({len(images)}); got {len(cmaps)}")
    points = dict(points or {})
    if any(not 0 <= k < len(images) for k in points):
        raise ValueError(f"points keys must be panel indices in [0, {len(images)}); got {sorted(points)}")
    labels = dict(colorbar_labels or {})
    if any(not 0 <= k < len(images) for k in labels):
        raise ValueError(f"colorbar_labels keys must be panel indices in [0, {len(images)}); got {sorted(labels)}")
    arrays = [_image(image) for image in images]
    limits: dict[int, dict[str, float]] = {k: dict(vmin=0, vmax=1) for k, cmap in enumerate(cmaps) if cmap == "gray"}
    for group in shared:
        if not group or any(not 0 <= k < len(images) for k in group):
            raise ValueError(f"shared must hold non-empty groups of panel indices in [0, {len(images)}); "
                             f"got {[list(g) for g in shared]}")
        low = min(float(np.nanmin(arrays[k])) for k in group)
        high = max(float(np.nanmax(arrays[k])) for k in group)
        for k in group:
            limits[k] = dict(vmin=low, vmax=high)
    first = arrays[0]
    fig, axes = plt.subplots(1, len(images), figsize=(panel_in * len(images), panel_in * first.shape[0] / first.shape[1]
                                                      + 0.5), squeeze=False)
    for k, (ax, image, title, cmap) in enumerate(zip(axes[0], arrays, titles, cmaps)):
        shown = ax.imshow(image, cmap=cmap, **limits.get(k, {}))
        if k in points:
            marks = _points(points[k])
            ax.scatter(marks[:, 0], marks[:, 1], s=20, facecolors="none", edgecolors="red")
        ax.set_title(title, fontsize=10)
        ax.axis("off")
        if cmap != "gray" or k in labels:
            fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02).set_label(labels.get(k, ""))
    fig.tight_layout()
    return fig


def plot_cell_correspondences(image1: ArrayLike, image2: ArrayLike, centres: ArrayLike, S: ArrayLike) -> "Figure":
    """Return the cell correspondences of a warped pair: matching cells in the same colour, and the matrix S itself.

    Args:
        image1, image2: (H, W) grayscale images in [0, 1], image 2 = image 1 warped by H.
        centres: (Hc * Wc, 2) cell centres (x, y), row-major, the same grid in both images.
        S: (Hc * Wc, Hc * Wc) 0/1 correspondences, rows = cells of image 1, columns = cells of image 2 (Eq. 10).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> c = np.array([[3.5, 3.5], [11.5, 3.5]])
    >>> len(plot_cell_correspondences(np.zeros((8, 16)), np.zeros((8, 16)), c, np.eye(2)).axes)
    3
    """
    import matplotlib.pyplot as plt

    centres, S = _points(centres, "centres"), np.asarray(S)
    if S.shape != (len(centres), len(centres)):
        raise ValueError(f"S must have shape (N, N) for N = {len(centres)} cell centres; got {S.shape}")
    rows, cols = np.nonzero(S)
    colours = plt.cm.tab20(np.arange(len(rows)) % 20)
    fig, axes = plt.subplots(1, 3, figsize=(16, 3.8))
    axes[0].imshow(_image(image1, "image1"), cmap="gray", vmin=0, vmax=1)
    axes[1].imshow(_image(image2, "image2"), cmap="gray", vmin=0, vmax=1)
    axes[0].scatter(centres[rows, 0], centres[rows, 1], c=colours, s=25)
    axes[1].scatter(centres[cols, 0], centres[cols, 1], c=colours, s=25)
    axes[0].set_title("image 1: cells with a correspondence")
    axes[1].set_title("image 2 = H(image 1): the matching cells")
    for ax in axes[:2]:
        ax.axis("off")
    axes[2].imshow(S, cmap="gray_r", interpolation="nearest")
    axes[2].set_title("S (Eq. 10): black = corresponding cells (1), white = 0", fontsize=9)
    axes[2].set_xlabel("cell of image 2 (index, row-major)")
    axes[2].set_ylabel("cell of image 1 (index, row-major)")
    fig.tight_layout()
    return fig


def plot_labelled_images(images: Sequence[ArrayLike], keypoints: Sequence[ArrayLike], titles: Sequence[str],
                         masks: Sequence[ArrayLike] | None = None, ncols: int = 5, panel_in: float = 3.2
                         ) -> "Figure":
    """Return a grid of images in [0, 1] with their keypoint labels circled in red (and valid masks outlined).

    Args:
        images: K (H, W) grayscale images in [0, 1], e.g. Synthetic Shapes (thesis §3.2.1).
        keypoints: K (N_k, 2) keypoint labels (x, y) in pixels; an image may have none.
        titles: K panel titles.
        masks: optional K (H, W) valid masks (1 = pixel shows the image); their 0.5 contour is drawn in yellow.
        ncols: panels per row; panels left over in the last row are hidden.
        panel_in: width of one panel in inches.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> points = [[[1.0, 2.0]], np.zeros((0, 2)), [[3.0, 3.0]]]
    >>> fig = plot_labelled_images([np.zeros((6, 8))] * 3, points, "abc", ncols=2)
    >>> [ax.get_title() for ax in fig.axes if ax.get_visible()]
    ['a', 'b', 'c']
    """
    import matplotlib.pyplot as plt

    if len(images) == 0 or not len(images) == len(keypoints) == len(titles):
        raise ValueError(f"images, keypoints and titles must be non-empty and of equal length; got {len(images)}, "
                         f"{len(keypoints)} and {len(titles)}")
    if masks is not None and len(masks) != len(images):
        raise ValueError(f"masks must hold one (H, W) mask per image ({len(images)}); got {len(masks)}")
    if ncols < 1:
        raise ValueError(f"ncols must be >= 1; got {ncols}")
    images = [_image(image, f"images[{k}]") for k, image in enumerate(images)]
    points = [_points(p, f"keypoints[{k}]") for k, p in enumerate(keypoints)]
    if masks is not None:
        masks = [_image(mask, f"masks[{k}]") for k, mask in enumerate(masks)]
        for k, (image, mask) in enumerate(zip(images, masks)):
            if mask.shape != image.shape:
                raise ValueError(f"masks[{k}] must have the shape of images[{k}] {image.shape}; got {mask.shape}")
    ncols = min(ncols, len(images))
    nrows = -(-len(images) // ncols)
    aspect = images[0].shape[0] / images[0].shape[1]
    fig, axes = plt.subplots(nrows, ncols, figsize=(panel_in * ncols, (panel_in * aspect + 0.4) * nrows),
                             squeeze=False)
    for k, ax in enumerate(axes.ravel()):
        ax.axis("off")
        if k >= len(images):
            ax.set_visible(False)
            continue
        ax.imshow(images[k], cmap="gray", vmin=0, vmax=1)
        if masks is not None:
            ax.contour(masks[k], levels=[0.5], colors="yellow", linewidths=0.8)
        ax.scatter(points[k][:, 0], points[k][:, 1], s=24, facecolors="none", edgecolors="red", linewidths=1.5)
        ax.set_title(titles[k])
    fig.tight_layout()
    return fig


def plot_cell_probabilities(cell_probabilities: ArrayLike, heatmap: ArrayLike, cell: int = 8,
                            cell_name: str = "") -> "Figure":
    """Return SuperPoint's cell softmax: one cell's cell^2 + 1 probabilities (dustbin last) and the full heatmap.

    The right panel draws the heatmap after depth-to-space with white lines on the borders of the cell x cell cells.
    Each panel has its colour bar (probabilities from 0; the left one holds the dustbin, often far the largest).

    Args:
        cell_probabilities: (cell^2 + 1,) softmax of one cell's logits, the dustbin last (thesis Fig. 12).
        heatmap: (H, W) keypoint probabilities after dropping the dustbin and depth-to-space; H, W multiples of cell.
        cell: side of a cell in pixels (8 in SuperPoint).
        cell_name: how the titles name the cell shown on the left, e.g. "(0, 1)".

    Reference: thesis §3.2.4, Fig. 12; DeTone et al. 2018, §3.2.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_cell_probabilities(np.full(65, 1 / 65), np.zeros((16, 24)))
    >>> fig.axes[1].get_title(), fig.axes[3].get_ylabel()
    ('depth-to-space: 16 x 24 heatmap', 'keypoint probability')
    """
    import matplotlib.pyplot as plt

    if cell < 1:
        raise ValueError(f"cell must be a positive number of pixels; got {cell}")
    probabilities = np.asarray(cell_probabilities, dtype=np.float64)
    if probabilities.shape != (cell * cell + 1,):
        raise ValueError(f"cell_probabilities must have shape (cell^2 + 1,) = ({cell * cell + 1},); "
                         f"got {probabilities.shape}")
    heatmap = _image(np.asarray(heatmap, dtype=np.float64), "heatmap")
    if heatmap.shape[0] % cell or heatmap.shape[1] % cell:
        raise ValueError(f"heatmap must have a height and width that are multiples of cell = {cell}; "
                         f"got {heatmap.shape}")
    fig, axes = plt.subplots(1, 2, figsize=(13.5, 3.2), gridspec_kw={"width_ratios": [2.4, 1]})
    strip = axes[0].imshow(probabilities[None], cmap="viridis", aspect="auto", vmin=0,
                   extent=(-0.5, len(probabilities) - 0.5, 0.5, -0.5))
    name = f"cell {cell_name}" if cell_name else "one cell"
    axes[0].set_title(f"{len(probabilities)} probabilities of {name}: {cell * cell} pixels + dustbin (last)")
    axes[0].set_yticks([])
    axes[0].set_xlabel(f"bin: pixel y * {cell} + x of the cell (0-{cell * cell - 1}), then the dustbin "
                       f"({cell * cell})")
    shown = axes[1].imshow(heatmap, cmap="viridis", vmin=0)
    axes[1].set_xlabel("x (px)")
    axes[1].set_ylabel("y (px)")
    for x in np.arange(cell, heatmap.shape[1], cell) - 0.5:  # borders between cells, at pixel edges
        axes[1].axvline(x, color="w", lw=0.6)
    for y in np.arange(cell, heatmap.shape[0], cell) - 0.5:
        axes[1].axhline(y, color="w", lw=0.6)
    axes[1].set_title(f"depth-to-space: {heatmap.shape[0]} x {heatmap.shape[1]} heatmap")
    fig.colorbar(strip, ax=axes[0], fraction=0.04, pad=0.01).set_label("probability")
    fig.colorbar(shown, ax=axes[1], fraction=0.046, pad=0.02).set_label("keypoint probability")
    fig.tight_layout()
    return fig


def plot_repeated_points(image2: ArrayLike, keypoints1_in_2: ArrayLike, keypoints2: ArrayLike, repeated: ArrayLike,
                         eps: float, title: str = "") -> "Figure":
    """Return image 2 with its detections (blue circles) and image 1's points warped by H: green repeated, red not.

    Args:
        image2: (H, W) grayscale image 2 in [0, 1].
        keypoints1_in_2: (N1, 2) points of image 1 in the shared view, warped into image 2 (H x_i).
        keypoints2: (N2, 2) points detected in image 2 (in the shared view).
        repeated: (N1,) booleans, True where a detection of image 2 lies within ``eps`` of H x_i (thesis Eq. 15).
        eps: the threshold in pixels (legend only).
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_repeated_points(np.zeros((9, 9)), [[1.0, 1.0], [5.0, 5.0]], [[1.0, 2.0]], [True, False], 3)
    >>> [len(c.get_offsets()) for c in fig.axes[0].collections]
    [1, 1, 1]
    """
    import matplotlib.pyplot as plt

    image2 = _image(image2, "image2")
    warped, detected = _points(keypoints1_in_2, "keypoints1_in_2"), _points(keypoints2, "keypoints2")
    repeated = np.asarray(repeated)
    if repeated.shape != (len(warped),) or (repeated.size and repeated.dtype != bool):
        raise ValueError(f"repeated must be ({len(warped)},) booleans, one per point of keypoints1_in_2; got "
                         f"shape {repeated.shape} dtype {repeated.dtype}")
    fig, ax = plt.subplots(figsize=(7.5, 5.6))
    ax.imshow(image2, cmap="gray", vmin=0, vmax=1)
    ax.scatter(detected[:, 0], detected[:, 1], s=22, facecolors="none", edgecolors="tab:blue",
               label="detected in image 2")
    ax.scatter(warped[repeated, 0], warped[repeated, 1], s=8, c="tab:green", label=f"H x_i, repeated (eps = {eps:g})")
    ax.scatter(warped[~repeated, 0], warped[~repeated, 1], s=8, c="tab:red", label="H x_i, not repeated")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize=8)
    ax.axis("off")
    fig.tight_layout()
    return fig


def plot_homography_corners(image2: ArrayLike, corners_true: ArrayLike, corners_estimated: ArrayLike,
                            margin: float = 20.0) -> "Figure":
    """Return image 2 with image 1's corners warped by the true H (green) and the estimated H (magenta, dashed).

    The title gives the mean corner distance 1/4 sum_j ||H_est c_j - H c_j|| (thesis Eq. 17); the axes extend
    beyond image 2 so that corners landing outside it stay visible.

    Args:
        image2: (H, W) grayscale image 2 in [0, 1].
        corners_true: (4, 2) corners (x, y) of image 1 warped by the true H, in the order top-left, top-right,
            bottom-left, bottom-right (the order of ``evaluate.corner_error``).
        corners_estimated: (4, 2) the same corners warped by the estimated H.
        margin: pixels of empty border around the corners and the image.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> c = np.array([[0.0, 0.0], [9.0, 0.0], [0.0, 7.0], [9.0, 7.0]])
    >>> plot_homography_corners(np.zeros((8, 10)), c, c + [3.0, 4.0]).axes[0].get_title()
    "image 1's corners in image 2: mean error 5.00 px"
    """
    import matplotlib.pyplot as plt

    image2 = _image(image2, "image2")
    true, estimated = np.asarray(corners_true, dtype=np.float64), np.asarray(corners_estimated, dtype=np.float64)
    for name, corners in (("corners_true", true), ("corners_estimated", estimated)):
        if corners.shape != (4, 2):
            raise ValueError(f"{name} must have shape (4, 2): top-left, top-right, bottom-left, bottom-right (x, y); "
                             f"got {corners.shape}")
    if not np.isfinite(true).all():
        raise ValueError("corners_true must be finite")
    error = float(np.linalg.norm(estimated - true, axis=1).mean())  # 1/4 sum_j ||c^'_j - c'_j||
    height, width = image2.shape
    order = [0, 1, 3, 2, 0]  # walk the corners around the quadrilateral
    fig, ax = plt.subplots(figsize=(8, 6))
    ax.imshow(image2, cmap="gray", vmin=0, vmax=1)
    ax.plot(true[order, 0], true[order, 1], "g-", lw=3, label="corners warped by the true H")
    ax.plot(estimated[order, 0], estimated[order, 1], "m--", lw=2, label="corners warped by the estimated H")
    ax.set_xlim(min(true[:, 0].min(), -10) - margin, max(true[:, 0].max(), width) + margin)
    ax.set_ylim(max(true[:, 1].max(), height) + margin, min(true[:, 1].min(), -10) - margin)
    ax.set_title(f"image 1's corners in image 2: mean error {error:.2f} px")
    ax.set_xlabel("x in image 2 (px)")
    ax.set_ylabel("y in image 2 (px)")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig


def plot_match_grid(pairs: Mapping[str, tuple[ArrayLike, ArrayLike]], results: Mapping[str, Mapping[str, tuple]],
                    rng: np.random.Generator | int = 0, max_drawn: int = 150, gap: int = 10) -> "Figure":
    """Return a grid of match panels, one column per image pair and one row per method (thesis Appendix B style).

    Each panel shows the pair side by side (``gap`` white pixels between) and a random subset of at most
    ``max_drawn`` matches, green when correct and red otherwise; its title counts all matches. The top row's titles
    start with the column's name in capitals. Subsets are drawn column by column, row by row.

    Args:
        pairs: column name (e.g. the split) -> (image1 (H1, W1), image2 (H2, W2)) grayscale images in [0, 1].
        results: column name -> method name -> (keypoints1 (N1, 2), keypoints2 (N2, 2), matches (M, 2) index
            pairs, correct (M,) booleans); every column lists the same methods.
        rng: generator (or seed) that picks the drawn subset.
        max_drawn: most matches drawn in one panel.
        gap: white pixels between the two images.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> kp = np.array([[1.0, 1.0]])
    >>> fig = plot_match_grid({"a": (np.zeros((4, 4)), np.zeros((4, 4)))}, {"a": {"m": (kp, kp, [[0, 0]], [True])}})
    >>> fig.axes[0].get_title()
    'A — m: 1 of 1 matches correct (100%)'
    """
    import matplotlib.pyplot as plt

    if not pairs or set(results) != set(pairs):
        raise ValueError(f"pairs and results must name the same non-empty columns; got {list(pairs)} and "
                         f"{list(results)}")
    methods = list(next(iter(results.values())))
    for column, by_method in results.items():
        if list(by_method) != methods or not methods:
            raise ValueError(f"results[{column!r}] must list the same non-empty methods as the first column "
                             f"{methods}; got {list(by_method)}")
    if max_drawn < 0 or gap < 0:
        raise ValueError(f"max_drawn and gap must be >= 0; got {max_drawn} and {gap}")
    rng = np.random.default_rng(rng)
    fig, axes = plt.subplots(len(methods), len(pairs), figsize=(7 * len(pairs), 3 * len(methods)), squeeze=False)
    for col, (column, (image1, image2)) in enumerate(pairs.items()):
        image1, image2 = _image(image1, "image1"), _image(image2, "image2")
        offset = image1.shape[1] + gap
        canvas = np.ones((max(image1.shape[0], image2.shape[0]), offset + image2.shape[1]), np.float32)
        canvas[: image1.shape[0], : image1.shape[1]] = image1
        canvas[: image2.shape[0], offset:] = image2
        for row, method in enumerate(methods):
            kp1, kp2, matches, correct = results[column][method]
            kp1, kp2 = _points(kp1, "keypoints1"), _points(kp2, "keypoints2")
            matches, correct = np.asarray(matches, dtype=int).reshape(-1, 2), np.asarray(correct, dtype=bool)
            if correct.shape != (len(matches),):
                raise ValueError(f"results[{column!r}][{method!r}]: correct must hold one boolean per match "
                                 f"({len(matches)}); got shape {correct.shape}")
            ax = axes[row, col]
            ax.imshow(canvas, cmap="gray", vmin=0, vmax=1)
            for k in rng.permutation(len(matches))[:max_drawn]:
                (i, j), ok = matches[k], correct[k]
                ax.plot([kp1[i, 0], kp2[j, 0] + offset], [kp1[i, 1], kp2[j, 1]], "-", lw=0.7,
                        color="tab:green" if ok else "tab:red")
            share = f" ({correct.mean():.0%})" if len(correct) else ""
            title = f"{method}: {int(correct.sum())} of {len(matches)} matches correct{share}"
            ax.set_title(f"{column.upper()} — {title}" if row == 0 else title, fontsize=9)
            ax.axis("off")
    fig.tight_layout()
    return fig


def plot_oracle_corner_errors(diagnoses: Mapping[str, tuple[ArrayLike, ArrayLike]], eps: float = 3.0) -> "Figure":
    """Return a log-log scatter, one colour per detector: correct matches of a pair against its oracle corner error.

    The oracle is the least-squares homography fitted to the correct matches alone (``evaluate.diagnose_matches``).
    For the log axes the counts are drawn at least 1 and the errors clipped to [0.05, 1000] px (inf, from fewer than
    4 correct matches, sits at the top). A dashed line marks the threshold ``eps``.

    Args:
        diagnoses: detector name -> (n_correct (P,), corner_error_oracle (P,)), one value per pair.
        eps: the correctness threshold in pixels.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_oracle_corner_errors({"sift": ([40, 3], [1.2, np.inf])})
    >>> fig.axes[0].collections[0].get_offsets().tolist()
    [[40.0, 1.2], [3.0, 1000.0]]
    """
    import matplotlib.pyplot as plt

    if not diagnoses:
        raise ValueError("diagnoses must name at least one detector")
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, (n_correct, oracle_error) in diagnoses.items():
        n_correct, oracle_error = np.asarray(n_correct, dtype=np.float64), np.asarray(oracle_error, dtype=np.float64)
        if n_correct.ndim != 1 or n_correct.shape != oracle_error.shape:
            raise ValueError(f"diagnoses[{name!r}] must be two (P,) arrays of equal length, n_correct and "
                             f"corner_error_oracle; got shapes {n_correct.shape} and {oracle_error.shape}")
        ax.scatter(np.maximum(n_correct, 1), np.clip(oracle_error, 0.05, 1e3), label=name, alpha=0.7)
    ax.axhline(eps, color="k", ls="--", lw=1, label=f"ε = {eps:g} px")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("correct matches in the pair")
    ax.set_ylabel("oracle corner error (px)")
    ax.set_title("least squares on the correct matches only: what perfect RANSAC would reach")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig



# --- schematics: the ideas of lessons 05 and 08 drawn on a small made-up scene ----------------------------------------

_SCENE_SHAPE = (120, 160)  # (height, width) of the drawn scene, pixels


def _schematic_scene() -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Return a drawn (120, 160) scene in [0, 1] (a bright square, a dark triangle, slightly blurred) and its 7
    corners (x, y)."""
    import cv2

    image = np.full(_SCENE_SHAPE, 0.45, np.float32)
    image[34:74, 28:68] = 0.9  # square: pixel rows 34..73, columns 28..67
    triangle = np.array([[92, 96], [134, 96], [110, 34]], np.int32)
    cv2.fillPoly(image, [triangle], 0.08)
    image = cv2.GaussianBlur(image, (0, 0), 0.8)
    corners = np.array([[27.5, 33.5], [67.5, 33.5], [27.5, 73.5], [67.5, 73.5], *triangle.astype(np.float64)])
    return image, corners


def _schematic_homography() -> NDArray[np.float64]:
    """Return the homography of the drawn scene: a 10 degree rotation and a zoom of 1.05 about its centre, a little
    perspective and a shift."""
    height, width = _SCENE_SHAPE
    c = np.array([(width - 1) / 2, (height - 1) / 2])
    a = np.deg2rad(10.0)
    A = np.eye(3)
    A[:2, :2] = 1.05 * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    P = np.eye(3)
    P[2, 0] = 3e-4
    to_centre, back = np.eye(3), np.eye(3)
    to_centre[:2, 2], back[:2, 2] = -c, c + [3.0, -2.0]
    return back @ A @ P @ to_centre


def _side_by_side(image1: NDArray, image2: NDArray, gap: int) -> tuple[NDArray, int]:
    """Return the two images on one white canvas with ``gap`` pixels between them, and the x offset of image 2."""
    offset = image1.shape[1] + gap
    canvas = np.ones((max(image1.shape[0], image2.shape[0]), offset + image2.shape[1]), np.float32)
    canvas[: image1.shape[0], : image1.shape[1]] = image1
    canvas[: image2.shape[0], offset:] = image2
    return canvas, offset


def _window_change(patch: NDArray, shift: tuple[int, int], half: int) -> float:
    """Sum of squared differences between the centred (2 half + 1)^2 window of ``patch`` and the window shifted."""
    cy, cx = patch.shape[0] // 2, patch.shape[1] // 2
    dx, dy = shift
    window = patch[cy - half: cy + half + 1, cx - half: cx + half + 1]
    moved = patch[cy + dy - half: cy + dy + half + 1, cx + dx - half: cx + dx + half + 1]
    return float(np.sum((moved - window) ** 2))


def _structure_tensor_eigenvalues(patch: NDArray, half: int) -> tuple[float, float]:
    """Eigenvalues (large, small) of the structure tensor of the centred window, central-difference gradients."""
    gy, gx = np.gradient(patch.astype(np.float64))
    cy, cx = patch.shape[0] // 2, patch.shape[1] // 2
    sl = (slice(cy - half, cy + half + 1), slice(cx - half, cx + half + 1))
    M = np.array([[np.sum(gx[sl] ** 2), np.sum(gx[sl] * gy[sl])], [np.sum(gx[sl] * gy[sl]), np.sum(gy[sl] ** 2)]])
    small, large = np.linalg.eigvalsh(M)
    return float(large), float(max(small, 0.0))


def _pair_panel(ax, image1: NDArray, image2: NDArray, gap: int) -> int:
    """Draw the two images side by side with an arrow labelled H between them; return image 2's x offset."""
    canvas, offset = _side_by_side(image1, image2, gap)
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=1)
    y = image1.shape[0] / 2
    ax.annotate("", xy=(offset - 3, y), xytext=(image1.shape[1] + 3, y),
                arrowprops=dict(arrowstyle="-|>", lw=2, color="k"))
    ax.text(image1.shape[1] + gap / 2, y - 5, "H", ha="center", va="bottom", fontsize=12, weight="bold")
    ax.set_xlim(-0.5, canvas.shape[1] - 0.5)
    ax.set_ylim(canvas.shape[0] - 0.5, -0.5)
    ax.set_axis_off()
    return offset


# view 2's detections in the schematics, offsets from H x_i in pixels: all close but the third (9 px off)
_DETECTION_OFFSETS = np.array([[1.0, -0.7], [-0.5, 1.2], [7.0, 5.5], [0.8, 0.3], [-1.1, -0.9], [0.6, -1.3], [0.4, 0.9]])


def plot_feature_schematic(eps: float = 3.0) -> "Figure":
    """Return the ideas of a feature front end drawn on a made-up scene (notebook 05's opening figure).

    Top row: a **detector** picks distinctive points (keypoints, each an (x, y) position and a score); a
    **descriptor** turns the patch around each keypoint into a vector (here 4 cells x 8 gradient-direction bins,
    weighted by gradient magnitude and scaled to unit length: a small SIFT-like histogram) that is compared between
    images. Bottom row: why corners: a window shifted in 8 directions over a flat patch, an edge and a corner (an
    arrow is solid green where the shift changes the window, dotted grey where it does not), with the eigenvalues of
    each window's structure tensor; and **repeatability**: view 1's keypoints carried into view 2 by the homography
    H, repeated (green circle) when a detection of view 2 lies within ``eps`` pixels, not repeated (red) otherwise.

    The scene and view 2's detections are drawn by hand; the window changes, the eigenvalues, the descriptor and the
    repeatability are computed from the drawn pixels and points.

    Args:
        eps: the repeatability threshold of the bottom-right panel, pixels (> 0).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_feature_schematic()
    >>> [ax.get_title().split(":")[0] for ax in fig.axes]
    ['detector', 'one keypoint', 'descriptor', 'flat', 'edge', 'corner', 'repeatability']
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    from evio_lib.geometry.homography import warp_image, warp_points

    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number of pixels; got {eps!r}")
    image, corners = _schematic_scene()
    fig = plt.figure(figsize=(15.5, 8.4))
    top = fig.add_gridspec(1, 3, left=0.03, right=0.98, top=0.94, bottom=0.56, width_ratios=[1.3, 0.85, 1.55],
                           wspace=0.22)
    bottom = fig.add_gridspec(1, 4, left=0.01, right=0.99, top=0.44, bottom=0.02, width_ratios=[1, 1, 1, 2.3],
                              wspace=0.1)

    # detector: keypoints on the scene, one patch outlined
    ax = fig.add_subplot(top[0])
    ax.imshow(image, cmap="gray", vmin=0, vmax=1)
    ax.scatter(corners[:, 0], corners[:, 1], s=40, c="tab:orange", edgecolors="k", zorder=3)
    half = 8
    k = 6  # the triangle's apex
    kx, ky = corners[k]
    ax.add_patch(Rectangle((kx - half - 0.5, ky - half - 0.5), 2 * half + 1, 2 * half + 1, fill=False, ec="cyan",
                           lw=2))
    ax.set_title(f"detector: {len(corners)} keypoints, each (x, y) and a score", fontsize=10)
    ax.set_axis_off()

    # the patch around one keypoint, zoomed
    ax = fig.add_subplot(top[1])
    x0, y0 = int(kx) - half, int(ky) - half
    patch = image[y0: y0 + 2 * half + 1, x0: x0 + 2 * half + 1]
    ax.imshow(patch, cmap="gray", vmin=0, vmax=1, extent=(-half - 0.5, half + 0.5, half + 0.5, -half - 0.5))
    ax.plot(0, 0, "o", color="tab:orange", mec="k", ms=8)
    ax.set_xlabel("x − x_keypoint (px)")
    ax.set_ylabel("y − y_keypoint (px)")
    ax.set_title(f"one keypoint: its {2 * half + 1} x {2 * half + 1} px patch", fontsize=10)

    # descriptor: a 2 x 2 x 8 orientation histogram of that patch
    gy, gx = np.gradient(patch.astype(np.float64))
    magnitude, angle = np.hypot(gx, gy), np.mod(np.arctan2(gy, gx), 2 * np.pi)
    bins = np.minimum((angle / (2 * np.pi) * 8).astype(int), 7)
    descriptor = np.zeros((2, 2, 8))
    for cy in range(2):
        for cx in range(2):
            sl = (slice(cy * half, cy * half + half + 1), slice(cx * half, cx * half + half + 1))
            descriptor[cy, cx] = np.bincount(bins[sl].ravel(), magnitude[sl].ravel(), minlength=8)
    descriptor = descriptor.ravel() / max(np.linalg.norm(descriptor), 1e-12)
    ax = fig.add_subplot(top[2])
    colours = np.repeat(["tab:blue", "tab:orange", "tab:green", "tab:purple"], 8)
    ax.bar(np.arange(32), descriptor, color=colours)
    for cell, name in enumerate(("top-left", "top-right", "bottom-left", "bottom-right")):
        ax.text(8 * cell + 3.5, 1.03 * descriptor.max(), f"{name}\nquarter", ha="center", va="bottom", fontsize=8)
    ax.set_ylim(0, 1.3 * descriptor.max())
    ax.set_xticks(np.arange(0, 33, 8))
    ax.set_xlabel("entry: 4 quarters of the patch x 8 gradient directions")
    ax.set_ylabel("weight (vector of unit length)")
    ax.set_title("descriptor: the patch as a vector; matched to the nearest vector of the other image",
                 fontsize=10)

    # flat, edge, corner: which shifts change the window
    n = 21
    yy, xx = np.mgrid[:n, :n]
    patches = {"flat": np.full((n, n), 0.5),
               "edge": np.where(xx > n // 2, 0.85, 0.15),
               "corner": np.where((xx > n // 2) & (yy > n // 2), 0.85, 0.15)}
    verdicts = {"flat": "no shift changes the window", "edge": "a shift along it changes nothing",
                "corner": "every shift changes it"}
    window, step, c = 4, 3, n // 2
    directions = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)]
    for k, (name, p) in enumerate(patches.items()):
        ax = fig.add_subplot(bottom[k])
        ax.imshow(p, cmap="gray", vmin=0, vmax=1)
        ax.add_patch(Rectangle((c - window - 0.5, c - window - 0.5), 2 * window + 1, 2 * window + 1, fill=False,
                               ec="gold", lw=2))
        for dx, dy in directions:
            changed = _window_change(p, (step * dx, step * dy), window) > 1e-9
            ax.annotate("", xy=(c + 2.6 * step * dx, c + 2.6 * step * dy), xytext=(c, c),
                        arrowprops=dict(arrowstyle="-|>", lw=1.8 if changed else 1.2, ls="-" if changed else ":",
                                        color="tab:green" if changed else "0.6"))
        large, small = _structure_tensor_eigenvalues(p, window)
        ax.set_title(f"{name}: {verdicts[name]}", fontsize=9.5)
        ax.text(c, n + 0.4, f"structure tensor: λ1 = {large:.2f}, λ2 = {small:.2f}", ha="center", va="top",
                fontsize=9)
        ax.set_xlim(-0.5, n - 0.5)
        ax.set_ylim(n + 2.6, -0.5)
        ax.set_axis_off()

    # repeatability between two views
    H = _schematic_homography()
    view2 = warp_image(image, H, border_value=1.0)
    carried = warp_points(H, corners)  # H x_i
    detected = carried + _DETECTION_OFFSETS
    within = np.linalg.norm(carried[:, None] - detected[None], axis=2) <= eps
    repeated1, repeated2 = within.any(axis=1), within.any(axis=0)
    ax = fig.add_subplot(bottom[3])
    shift = _pair_panel(ax, image, view2, gap=30)
    ax.scatter(corners[:, 0], corners[:, 1], s=30, c="tab:orange", edgecolors="k", zorder=3)
    ax.scatter(detected[:, 0] + shift, detected[:, 1], s=22, marker="s", c="tab:blue", edgecolors="w", zorder=3)
    for (x, y), ok in zip(carried, repeated1):
        ax.add_patch(Circle((x + shift, y), eps, fill=False, ec="tab:green" if ok else "tab:red", lw=2, zorder=4))
    rep = (repeated1.sum() + repeated2.sum()) / (len(corners) + len(detected))
    ax.set_title(f"repeatability: view 1's keypoints (orange) carried into view 2 by H, circles of ε = {eps:g} px;\n"
                 f"green: a detection of view 2 (blue) inside, red: none.  Rep = ({repeated1.sum()} + "
                 f"{repeated2.sum()}) / ({len(corners)} + {len(detected)}) = {rep:.2f}", fontsize=9.5)
    return fig


def plot_evaluation_schematic(eps: float = 3.0) -> "Figure":
    """Return the feature benchmark's protocol drawn on a made-up scene (notebook 08's opening figure).

    1. a pair: image 2 is image 1 warped by a known homography H, so every point has a true partner;
    2. repeatability (the detector alone): image 1's keypoints carried into image 2 by H, repeated when a detection
       of image 2 lies within ``eps`` pixels;
    3. matching (detector and descriptor): each keypoint matched to the nearest descriptor of the other image; a
       match is correct when ||H x_1 - x_2|| <= eps;
    4. homography estimation: RANSAC fits an estimate H_est to the matches; image 1's four corners carried by H and
       by H_est; the pair counts as correct when their mean distance is at most ``eps``.

    The detections, the two wrong matches and H_est are drawn by hand to show the idea; the repeatability, the
    correct matches and the corner distance written on the figure are computed from them.

    Args:
        eps: the threshold in pixels (> 0).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_evaluation_schematic()
    >>> [ax.get_title().split(":")[0] for ax in fig.axes]
    ['1. a pair', '2. repeatability', '3. matching', '4. homography estimation']
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    from evio_lib.geometry.homography import warp_image, warp_points

    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number of pixels; got {eps!r}")
    image1, corners = _schematic_scene()
    H = _schematic_homography()
    image2 = warp_image(image1, H, border_value=1.0)
    height, width = image1.shape
    carried = warp_points(H, corners)
    detected = carried + _DETECTION_OFFSETS  # image 2's detections, drawn near H x_i
    fig, axes = plt.subplots(2, 2, figsize=(15, 8.4), gridspec_kw={"width_ratios": [2.2, 1.25]})
    gap = 30

    # 1. the pair
    ax = axes[0, 0]
    shift = _pair_panel(ax, image1, image2, gap)
    frame = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], float)
    ax.scatter(corners[:, 0], corners[:, 1], s=25, c="tab:orange", edgecolors="k", zorder=3)
    ax.scatter(carried[:, 0] + shift, carried[:, 1], s=25, c="tab:orange", edgecolors="k", zorder=3)
    ax.set_title("1. a pair: image 2 = image 1 warped by a known homography H;\nevery point x of image 1 has its "
                 "true place H x in image 2", fontsize=10)

    # 2. repeatability
    ax = axes[0, 1]
    ax.imshow(image2, cmap="gray", vmin=0, vmax=1)
    within = np.linalg.norm(carried[:, None] - detected[None], axis=2) <= eps
    repeated1, repeated2 = within.any(axis=1), within.any(axis=0)
    ax.scatter(detected[:, 0], detected[:, 1], s=22, marker="s", c="tab:blue", edgecolors="w", zorder=3)
    for (x, y), ok in zip(carried, repeated1):
        ax.add_patch(Circle((x, y), eps, fill=False, ec="tab:green" if ok else "tab:red", lw=2, zorder=4))
    rep = (repeated1.sum() + repeated2.sum()) / (len(corners) + len(detected))
    ax.set_title(f"2. repeatability: the detector alone; circles of ε = {eps:g} px around H x_i,\n"
                 f"green: a detection x_j (blue) inside.  Rep = ({repeated1.sum()} + {repeated2.sum()}) / "
                 f"({len(corners)} + {len(detected)}) = {rep:.2f}", fontsize=10)
    ax.set_axis_off()

    # 3. matching
    ax = axes[1, 0]
    shift = _pair_panel(ax, image1, image2, gap)
    partner = np.arange(len(corners))
    partner[[1, 4]] = partner[[4, 1]]  # two descriptors matched to the wrong point
    correct = np.linalg.norm(carried - detected[partner], axis=1) <= eps
    for i, (j, ok) in enumerate(zip(partner, correct)):
        ax.plot([corners[i, 0], detected[j, 0] + shift], [corners[i, 1], detected[j, 1]], "-", lw=1.6,
                color="tab:green" if ok else "tab:red")
    ax.scatter(corners[:, 0], corners[:, 1], s=25, c="tab:orange", edgecolors="k", zorder=3)
    ax.scatter(detected[:, 0] + shift, detected[:, 1], s=25, c="tab:orange", edgecolors="k", zorder=3)
    ax.set_title(f"3. matching: detector + descriptor; each point to the nearest descriptor of the other image;\n"
                 f"green: correct, ||H x_1 − x_2|| ≤ ε ({correct.sum()} of {len(correct)}); red: wrong", fontsize=10)

    # 4. homography estimation
    ax = axes[1, 1]
    H_est = H @ np.array([[1.0, 0.012, 2.0], [-0.01, 1.0, -1.5], [3e-5, 1.2e-4, 1.0]])  # an estimate, a little off
    c_true, c_est = warp_points(H, frame), warp_points(H_est, frame)
    error = float(np.linalg.norm(c_est - c_true, axis=1).mean())
    ax.imshow(image2, cmap="gray", vmin=0, vmax=1)
    loop = [0, 1, 2, 3, 0]
    ax.plot(c_true[loop, 0], c_true[loop, 1], "-", color="tab:green", lw=2.5, label="image 1's corners by H")
    ax.plot(c_est[loop, 0], c_est[loop, 1], "--", color="m", lw=2, label="by H_est, fitted to the matches (RANSAC)")
    margin = 14
    ax.set_xlim(min(c_true[:, 0].min(), c_est[:, 0].min(), 0) - margin,
                max(c_true[:, 0].max(), c_est[:, 0].max(), width) + margin)
    ax.set_ylim(max(c_true[:, 1].max(), c_est[:, 1].max(), height) + margin,
                min(c_true[:, 1].min(), c_est[:, 1].min(), 0) - margin)
    verdict = "correct" if error <= eps else "not correct"
    ax.set_title(f"4. homography estimation: mean corner distance {error:.1f} px,\n{verdict} at ε = {eps:g} px",
                 fontsize=10)
    ax.set_xlabel("x in image 2 (px)")
    ax.set_ylabel("y in image 2 (px)")
    ax.legend(loc="lower center", fontsize=8)
    fig.tight_layout()
    return fig
