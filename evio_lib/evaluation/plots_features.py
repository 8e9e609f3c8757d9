"""Figures for the feature lessons (notebooks 05-07): keypoints on images, the FAST circle, scale space, binary
descriptors, repeatability, training curves and descriptor matches.

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
    """Return a three-panel figure: the image, a corner response (red > 0, blue < 0) and a flat/edge/corner map.

    Args:
        image: (H, W) grayscale image.
        response: (H, W) corner response, e.g. Harris's R = det M - k tr(M)^2.
        classes: (H, W) integers, 0 = flat, 1 = edge, 2 = corner.
        clip: the colour scale ends at ``clip * max |response|``.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_structure_tensor_classes(np.zeros((8, 8)), np.ones((8, 8)), np.zeros((8, 8), int))
    >>> len(fig.axes)
    3
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
    axes[1].imshow(response, cmap="coolwarm", vmin=-lim, vmax=lim)
    axes[1].set_title("corner response R (clipped)")
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
        ranked: colour the points by rank (yellow = weaker, assuming strongest first) instead of one colour.
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
        colour = np.arange(len(points)) if ranked else "tab:orange"
        ax.scatter(points[:, 0], points[:, 1], s=size, c=colour, cmap="autumn" if ranked else None)
        ax.set_title(f"{name}: {len(points)}")
    for ax in axes.ravel():
        ax.axis("off")
    fig.tight_layout()
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
    axes[1].imshow(image, cmap="gray")
    points = _points(keypoints if keypoints is not None else np.zeros((0, 2)))
    axes[1].scatter(points[:, 0], points[:, 1], s=10, c="tab:orange")
    axes[1].set_title(f"FAST: {len(points)} keypoints")
    axes[1].axis("off")
    fig.tight_layout()
    return fig


def plot_scale_space(dogs: Sequence[ArrayLike], sigmas: Sequence[float], image: ArrayLike,
                     keypoints: ArrayLike) -> "Figure":
    """Return one row: the difference-of-Gaussian levels (red > 0, blue < 0) and the image with SIFT keypoints.

    Args:
        dogs: K (H, W) difference-of-Gaussian images D = G(k sigma) * I - G(sigma) * I.
        sigmas: K scales sigma, one per level (used in the titles).
        image: (H, W) grayscale image.
        keypoints: (N, 2) keypoints (x, y).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> len(plot_scale_space([np.ones((4, 4))], [1.6], np.zeros((4, 4)), [[1.0, 1.0]]).axes)
    2
    """
    import matplotlib.pyplot as plt

    if len(dogs) != len(sigmas) or len(dogs) == 0:
        raise ValueError(f"dogs and sigmas must be non-empty and of equal length; got {len(dogs)} and {len(sigmas)}")
    image, points = _image(image), _points(keypoints)
    fig, axes = plt.subplots(1, len(dogs) + 1, figsize=(4 * (len(dogs) + 1), 4.3))
    for ax, dog, sigma in zip(axes, dogs, sigmas):
        dog = _image(dog, "dog")
        lim = max(float(np.abs(dog).max()), 1e-12)
        ax.imshow(dog, cmap="coolwarm", vmin=-lim, vmax=lim)
        ax.set_title(f"DoG, sigma = {sigma:.2f}")
        ax.axis("off")
    axes[-1].imshow(image, cmap="gray")
    axes[-1].scatter(points[:, 0], points[:, 1], s=10, c="tab:orange")
    axes[-1].set_title(f"SIFT: {len(points)} keypoints")
    axes[-1].axis("off")
    fig.tight_layout()
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
                     points: Mapping[int, ArrayLike] | None = None, panel_in: float = 4.2) -> "Figure":
    """Return one row of image panels (e.g. an image, detector heatmaps), with keypoints circled on chosen panels.

    Args:
        images: K (H, W) arrays; grayscale panels (cmap "gray") are drawn on [0, 1].
        titles: K panel titles.
        cmaps: one colour map for every panel, or K of them.
        points: panel index -> (N, 2) keypoints (x, y) to circle in red on that panel.
        panel_in: width of one panel in inches.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_heatmap_row([np.zeros((4, 4)), np.ones((4, 4))], ["a", "b"], ["gray", "magma"], {0: [[1.0, 2.0]]})
    >>> [ax.get_title() for ax in fig.axes]
    ['a', 'b']
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
    first = _image(images[0])
    fig, axes = plt.subplots(1, len(images), figsize=(panel_in * len(images), panel_in * first.shape[0] / first.shape[1]
                                                      + 0.5), squeeze=False)
    for k, (ax, image, title, cmap) in enumerate(zip(axes[0], images, titles, cmaps)):
        limits = dict(vmin=0, vmax=1) if cmap == "gray" else {}
        ax.imshow(_image(image), cmap=cmap, **limits)
        if k in points:
            marks = _points(points[k])
            ax.scatter(marks[:, 0], marks[:, 1], s=20, facecolors="none", edgecolors="red")
        ax.set_title(title, fontsize=10)
        ax.axis("off")
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
    axes[2].set_title("S (Eq. 10): row = cell of image 1, col = cell of image 2", fontsize=9)
    fig.tight_layout()
    return fig
