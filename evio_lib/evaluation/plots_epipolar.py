"""Figures for the epipolar-geometry lesson: epipolar lines in two views and the four cheirality configurations.

Plotting only; the geometry lives in :mod:`evio_lib.geometry.epipolar`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.epipolar import triangulate_dlt

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["line_segments_in_image", "plot_epipolar_lines", "plot_cheirality"]


def line_segments_in_image(lines: ArrayLike, width: int, height: int) -> NDArray[np.float64]:
    """Return (N, 2, 2) end points ((x0, y0), (x1, y1)) of lines a x + b y + c = 0 clipped to an image.

    The image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]`` (pixel centres at integers). Lines that miss
    the image get NaN end points.

    Args:
        lines: (N, 3) homogeneous lines (a, b, c), e.g. epipolar lines ``F @ u1h``.
        width, height: image size in pixels.

    >>> line_segments_in_image([[0.0, 1.0, -10.0]], 100, 50)   # the row y = 10
    array([[[-0.5, 10. ],
            [99.5, 10. ]]])
    """
    lines = np.asarray(lines, dtype=np.float64)
    if lines.ndim != 2 or lines.shape[1] != 3:
        raise ValueError(f"lines must have shape (N, 3) as (a, b, c) rows; got {lines.shape}")
    a, b, c = lines[:, 0:1], lines[:, 1:2], lines[:, 2:3]
    x_lo, x_hi, y_lo, y_hi = -0.5, width - 0.5, -0.5, height - 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = np.array([x_lo, x_hi])[None, :]
        ys = np.array([y_lo, y_hi])[None, :]
        y_at_x = -(a * xs + c) / b  # crossings of the left / right borders: y = -(a x + c) / b
        x_at_y = -(b * ys + c) / a  # crossings of the top / bottom borders: x = -(b y + c) / a
    px = np.concatenate([np.broadcast_to(xs, y_at_x.shape), x_at_y], axis=1)  # (N, 4)
    py = np.concatenate([y_at_x, np.broadcast_to(ys, x_at_y.shape)], axis=1)
    tol = 1e-9
    inside = (
        np.isfinite(px) & np.isfinite(py)
        & (px >= x_lo - tol) & (px <= x_hi + tol) & (py >= y_lo - tol) & (py <= y_hi + tol)
    )
    # order the crossings along the line direction (b, -a) and keep the two extremes
    along = np.where(inside, b * px - a * py, np.nan)
    has_two = inside.sum(axis=1) >= 2
    first = np.nanargmin(np.where(has_two[:, None], along, 0.0), axis=1)
    last = np.nanargmax(np.where(has_two[:, None], along, 0.0), axis=1)
    rows = np.arange(len(lines))
    out = np.stack(
        [np.stack([px[rows, first], py[rows, first]], -1), np.stack([px[rows, last], py[rows, last]], -1)], axis=1
    )
    out[~has_two] = np.nan
    return out


def _draw_view(ax, uv: NDArray[np.float64], lines: NDArray[np.float64], width: int, height: int, title: str) -> None:
    """Draw one image frame with its points and the epipolar lines of the other view's points."""
    colours = [f"C{i % 10}" for i in range(len(uv))]
    for (p0, p1), colour in zip(line_segments_in_image(lines, width, height), colours):
        ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=colour, lw=1.0, alpha=0.8)
    ax.scatter(uv[:, 0], uv[:, 1], c=colours, s=25, edgecolors="k", zorder=3)
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)  # image rows grow downwards
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.set_xlabel("x [px]")
    ax.set_ylabel("y [px]")


def plot_epipolar_lines(
    uv1: ArrayLike, uv2: ArrayLike, F: ArrayLike, width: int, height: int, *, max_points: int = 12
) -> "Figure":
    """Return a two-panel figure: each view with its points and the epipolar lines of the other view's points.

    In view 2 the line of ``u1`` is ``l2 = F u1h``; in view 1 the line of ``u2`` is ``l1 = F^T u2h``. A correct
    correspondence lies on its line (same colour).

    Args:
        uv1, uv2: (N, 2) corresponding pixels in view 1 and view 2.
        F: (3, 3) fundamental matrix with ``u2h^T F u1h = 0``.
        width, height: image size in pixels (both views).
        max_points: draw at most this many correspondences (the first ones).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])   # rectified pair: same rows
    >>> fig = plot_epipolar_lines([[50.0, 20.0]], [[30.0, 20.0]], F, 100, 60)
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt

    uv1 = np.asarray(uv1, dtype=np.float64)[:max_points]
    uv2 = np.asarray(uv2, dtype=np.float64)[:max_points]
    F = np.asarray(F, dtype=np.float64)
    if uv1.shape != uv2.shape or uv1.ndim != 2 or uv1.shape[1] != 2:
        raise ValueError(f"uv1 and uv2 must both have shape (N, 2); got {uv1.shape} and {uv2.shape}")
    if F.shape != (3, 3):
        raise ValueError(f"F must have shape (3, 3); got {F.shape}")
    u1h = np.column_stack([uv1, np.ones(len(uv1))])
    u2h = np.column_stack([uv2, np.ones(len(uv2))])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    _draw_view(axes[0], uv1, u2h @ F, width, height, "view 1: points and lines F^T u2")  # l1 = F^T u2h
    _draw_view(axes[1], uv2, u1h @ F.T, width, height, "view 2: points and lines F u1")  # l2 = F u1h
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], ls="", marker="o", mfc="0.6", mec="k", label="point (one colour per correspondence)"),
               Line2D([], [], color="0.6", lw=1.0, label="epipolar line of the same-colour point of the other view")]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return fig


def plot_cheirality(
    candidates: Sequence[tuple[ArrayLike, ArrayLike]], xy1: ArrayLike, xy2: ArrayLike, *, baseline: float = 1.0
) -> "Figure":
    """Return a 2x2 figure, seen from above (x-z plane of C1), of the four (R, t) candidates of an essential matrix.

    For each candidate the correspondences are triangulated with ``P1 = [I | 0]``, ``P2 = [R | baseline * t]``;
    points in front of both cameras are green, the others red. Camera 2's centre is ``c = -R^T t`` and its optical
    axis ``R^T e_z`` in frame C1.

    Args:
        candidates: four (R_C1toC2 (3, 3), t_unit (3,)) pairs, e.g. from ``decompose_essential``.
        xy1, xy2: (N, 2) corresponding normalised image coordinates.
        baseline: length given to the unit translation when drawing.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> from evio_lib.geometry.epipolar import decompose_essential, essential_from_pose
    >>> xy = np.array([[0.0, 0.0], [0.1, 0.0]])
    >>> fig = plot_cheirality(decompose_essential(essential_from_pose(np.eye(3), [-1.0, 0, 0])), xy, xy - [0.2, 0])
    >>> len(fig.axes)
    4
    """
    import matplotlib.pyplot as plt

    if len(candidates) != 4:
        raise ValueError(f"candidates must hold the four (R, t) pairs of an essential matrix; got {len(candidates)}")
    xy1 = np.asarray(xy1, dtype=np.float64)
    xy2 = np.asarray(xy2, dtype=np.float64)
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    fig, axes = plt.subplots(2, 2, figsize=(10, 8))
    for k, (ax, (R, t)) in enumerate(zip(axes.ravel(), candidates)):
        R = np.asarray(R, dtype=np.float64)
        t = baseline * np.asarray(t, dtype=np.float64).reshape(3)
        X_C1 = triangulate_dlt(P1, np.hstack([R, t[:, None]]), xy1, xy2)
        depth2 = X_C1 @ R[2] + t[2]  # Z in camera 2: (R X + t)_z
        front = (X_C1[:, 2] > 0) & (depth2 > 0)
        centre2 = -R.T @ t  # camera 2's centre in C1
        axis2 = R[2]  # R^T e_z: camera 2's optical axis in C1
        finite = np.isfinite(X_C1).all(axis=1)
        extent = max(3.0 * baseline, float(np.percentile(np.abs(X_C1[finite][:, [0, 2]]), 95)) if finite.any() else 1.0)
        ax.scatter(X_C1[front, 0], X_C1[front, 2], s=8, c="tab:green", label="in front of both cameras")
        ax.scatter(X_C1[~front, 0], X_C1[~front, 2], s=8, c="tab:red", label="behind a camera")
        for centre, axis, name, colour in (
            (np.zeros(3), np.array([0.0, 0.0, 1.0]), "C1", "tab:blue"),
            (centre2, axis2, "C2", "tab:orange"),
        ):
            ax.plot(centre[0], centre[2], "o", color=colour, ms=7, label=f"{name} centre, arrow = optical axis")
            ax.arrow(centre[0], centre[2], 0.25 * extent * axis[0], 0.25 * extent * axis[2], color=colour,
                     width=0.01 * extent, head_width=0.06 * extent, length_includes_head=True, zorder=4)
        ax.set_xlim(-1.2 * extent, 1.2 * extent)
        ax.set_ylim(-1.2 * extent, 1.2 * extent)
        ax.set_aspect("equal")
        ax.set_xlabel("x in C1 [m]")
        ax.set_ylabel("z in C1 [m]")
        ax.set_title(f"candidate {k}: {int(front.sum())}/{len(front)} in front")
        ax.grid(alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return fig
