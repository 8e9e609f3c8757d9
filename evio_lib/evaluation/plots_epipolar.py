"""Figures for the camera and two-view lessons (notebooks 01 and 02).

- :func:`plot_pinhole_schematic` (notebook 01): the pinhole projection drawn in 3-D (optical centre, optical axis,
  image plane, a 3-D point, its ray and its pixel) beside the sensor in pixels, where the lens moves that pixel.
- :func:`plot_epipolar_schematic` (notebook 02): two camera frames, the baseline, the epipolar plane of a point,
  the epipoles and the epipolar line, and the relative pose (R, t) between the frames.
- :func:`plot_epipolar_lines`, :func:`plot_cheirality`: epipolar lines in two views and the four candidate motions
  of an essential matrix.

Plotting only; the geometry lives in :mod:`evio_lib.geometry.camera` and :mod:`evio_lib.geometry.epipolar`, and
every point, line and epipole drawn is computed with them. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.epipolar import essential_from_pose, triangulate_dlt

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "line_segments_in_image",
    "plot_pinhole_schematic",
    "plot_epipolar_schematic",
    "plot_epipolar_lines",
    "plot_cheirality",
]


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


def _in_plot(points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Camera-style coordinates (x right, y down, z forward) -> matplotlib 3-D axes (x, z, up = -y)."""
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    return p[:, 0], p[:, 2], -p[:, 1]


def _plane_patch(ax, corners: NDArray[np.float64], colour: str, alpha: float = 0.25):
    """Add a filled 3-D polygon with the given (N, 3) corners (camera-style coordinates)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    vertices = np.column_stack(_in_plot(corners))
    ax.add_collection3d(Poly3DCollection([vertices], facecolor=colour, alpha=alpha, edgecolor="0.3", linewidth=0.8))


def _line3d(ax, a: ArrayLike, b: ArrayLike, **options) -> None:
    x, y, z = _in_plot(np.vstack([a, b]))
    ax.plot(x, y, z, **options)


def _arrow3d(ax, start: ArrayLike, vector: ArrayLike, colour: str, label: str = "", **text_options) -> None:
    (x,), (y,), (z,) = _in_plot(start)
    (u,), (v,), (w,) = _in_plot(vector)
    ax.quiver(x, y, z, u, v, w, color=colour, arrow_length_ratio=0.18, linewidth=1.6)
    if label:
        tip = np.asarray(start, dtype=np.float64) + 1.12 * np.asarray(vector, dtype=np.float64)
        (tx,), (ty,), (tz,) = _in_plot(tip)
        ax.text(tx, ty, tz, label, color=colour, fontsize=9, **text_options)


def _text3d(ax, point: ArrayLike, text: str, **options) -> None:
    (x,), (y,), (z,) = _in_plot(point)
    options.setdefault("fontsize", 8.5)
    ax.text(x, y, z, text, **options)


def plot_pinhole_schematic(camera: PinholeRadtan | None = None, point_C: ArrayLike = (1.0, -0.9, 2.0)) -> "Figure":
    """Return the pinhole camera drawn in 3-D (left) beside the sensor in pixels (right).

    Left: the camera frame C at the optical centre (x right, y down, z forward along the optical axis), the image
    plane one metre in front of it (the normalised plane z = 1, cut to the sensor's field of view), the principal
    point where the axis pierces it, a 3-D point P, its ray through the optical centre and the point
    p = (X/Z, Y/Z, 1) where the ray crosses the plane. Right: the sensor in pixels with the principal point
    (c_x, c_y), the pixel K p a perfect lens gives P, the pixel the camera's lens gives it (``camera.project``),
    and two straight lines of the plane through p as the ideal pinhole and as the lens draw them.

    Args:
        camera: the camera (default: the DAVIS240C, :meth:`PinholeRadtan.davis240c`).
        point_C: the 3-D point (X, Y, Z) in the camera frame [m], Z > 0.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_pinhole_schematic()
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    cam = PinholeRadtan.davis240c() if camera is None else camera
    P = np.asarray(point_C, dtype=np.float64)
    if P.shape != (3,) or not np.all(np.isfinite(P)) or P[2] <= 0:
        raise ValueError(f"point_C must be a finite 3-D point (X, Y, Z) [m] with Z > 0; got {point_C!r}")
    xy = P[:2] / P[2]
    x_lo, x_hi = (-0.5 - cam.cx) / cam.fx, (cam.width - 0.5 - cam.cx) / cam.fx
    y_lo, y_hi = (-0.5 - cam.cy) / cam.fy, (cam.height - 0.5 - cam.cy) / cam.fy

    fig = plt.figure(figsize=(14.5, 5.8))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.3, 1.0))
    ax = fig.add_subplot(grid[0], projection="3d")
    _plane_patch(ax, np.array([[x_lo, y_lo, 1.0], [x_hi, y_lo, 1.0], [x_hi, y_hi, 1.0], [x_lo, y_hi, 1.0]]),
                 "tab:blue", alpha=0.18)
    depth = 1.15 * P[2]
    _line3d(ax, [0.0, 0.0, 0.0], [0.0, 0.0, depth], color="0.35", ls="--", lw=1.2)
    _arrow3d(ax, [0.0, 0.0, 0.0], [0.4, 0.0, 0.0], "tab:red", "x_C")
    _arrow3d(ax, [0.0, 0.0, 0.0], [0.0, 0.4, 0.0], "tab:green", "y_C")
    _arrow3d(ax, [0.0, 0.0, 0.0], [0.0, 0.0, 0.4], "tab:blue", "z_C")
    ax.scatter(*_in_plot([0.0, 0.0, 0.0]), color="k", s=35)
    ax.scatter(*_in_plot([0.0, 0.0, 1.0]), color="tab:purple", marker="+", s=90, linewidths=2)
    _line3d(ax, [0.0, 0.0, 0.0], P, color="tab:orange", lw=1.6)
    ax.scatter(*_in_plot(P), color="tab:orange", s=45)
    _text3d(ax, P, "  P", color="tab:orange", fontsize=12)
    p = np.array([xy[0], xy[1], 1.0])
    ax.scatter(*_in_plot(p), color="k", s=25)
    _text3d(ax, p, "  p", fontsize=12, va="bottom")
    ax.set_xlim(x_lo - 0.1, max(x_hi, P[0]) + 0.1)
    ax.set_ylim(0.0, depth)
    ax.set_zlim(min(-y_hi, -0.45) - 0.05, max(-y_lo, -P[1]) + 0.05)
    ax.set_box_aspect((np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())))
    ax.set_xlabel("x_C [m]")
    ax.set_ylabel("z_C [m]")
    ax.set_zlabel("−y_C (up) [m]")
    ax.view_init(elev=18, azim=-50)
    ax.set_title("the pinhole projection (thesis §2.1.1, Eq. 1)", fontsize=10)
    ax.legend(handles=[
        Line2D([], [], ls="", marker="o", color="k", label="optical centre C (origin of the camera frame)"),
        Line2D([], [], color="0.35", ls="--", label="optical axis z_C"),
        Patch(facecolor="tab:blue", alpha=0.3, label="image plane z = 1 m (normalised coordinates)"),
        Line2D([], [], ls="", marker="+", mew=2, ms=9, color="tab:purple", label="principal point: axis meets plane"),
        Line2D([], [], color="tab:orange", marker="o", label="3-D point P = (X, Y, Z) and its ray"),
        Line2D([], [], ls="", marker="o", ms=5, color="k", label="p = (X/Z, Y/Z, 1); pixel (u, v) = K p"),
    ], fontsize=8, loc="upper left", framealpha=0.9)

    ax2 = fig.add_subplot(grid[1])
    ax2.add_patch(plt.Rectangle((-0.5, -0.5), cam.width, cam.height, fill=False, ec="k", lw=1.6))
    span_x = np.linspace(x_lo - 0.08, x_hi + 0.08, 120)
    span_y = np.linspace(y_lo - 0.08, y_hi + 0.08, 120)
    ideal = PinholeRadtan(fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy, width=cam.width, height=cam.height)
    for k, line in enumerate((np.c_[span_x, np.full_like(span_x, xy[1])], np.c_[np.full_like(span_y, xy[0]), span_y])):
        straight, bent = ideal.normalized_to_pixels(line), cam.normalized_to_pixels(line)
        ax2.plot(straight[:, 0], straight[:, 1], color="0.6", lw=1.0,
                 label="straight lines through p: a perfect lens" if k == 0 else None)
        ax2.plot(bent[:, 0], bent[:, 1], color="tab:blue", lw=1.3,
                 label="the same lines through the real lens" if k == 0 else None)
    ideal_uv = ideal.normalized_to_pixels(xy[None])[0]
    real_uv = cam.project(P)
    ax2.plot(cam.cx, cam.cy, "+", color="tab:purple", ms=12, mew=2, label="principal point (c_x, c_y)")
    ax2.plot(*ideal_uv, "o", mfc="none", mec="k", ms=9, label="K p: P's pixel with a perfect lens")
    ax2.plot(*real_uv, "o", color="tab:orange", ms=7, label="P's pixel through the real lens")
    ax2.annotate("", xy=tuple(real_uv), xytext=tuple(ideal_uv), arrowprops=dict(arrowstyle="-|>", color="k", lw=1.2))
    shift = float(np.linalg.norm(real_uv - ideal_uv))
    ax2.set(xlim=(-30, cam.width + 30), ylim=(cam.height + 30, -30), aspect="equal", xlabel="u [px]", ylabel="v [px]")
    ax2.set_title(f"the sensor ({cam.width} x {cam.height} px): the lens moves P's pixel by {shift:.1f} px",
                  fontsize=10)
    ax2.legend(fontsize=8, loc="lower left", framealpha=0.9)
    fig.tight_layout()
    return fig


def _rot_y(angle: float) -> NDArray[np.float64]:
    """Rotation by ``angle`` [rad] about the y axis: it turns e_z towards +x."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def plot_epipolar_schematic(toe_in_deg: float = 30.0, baseline: float = 2.4, focal: float = 0.5) -> "Figure":
    """Return two views of one point drawn in 3-D (left) and image 2 with the epipolar line of that point (right).

    Left: camera 1 at the origin and camera 2 ``baseline`` metres to its right, each turned ``toe_in_deg``
    towards the other; each image plane drawn ``focal`` metres in front of its centre; a scene point X, its two
    rays, its images x1 and x2, the epipolar plane (C1, C2, X), the baseline C1-C2, the epipoles e1 and e2 where
    the baseline pierces the image planes, the epipolar lines (the epipolar plane cut by each image plane) and the
    relative pose: ``R = R_C1toC2`` and ``t = p_C1inC2``, camera 1's centre seen from camera 2.
    Right: image 2 in normalised coordinates: points of camera 1's ray through x1 at several depths project onto
    one line, the epipolar line ``l2 = E x1`` with ``E = [t x] R``, which passes through the epipole e2.

    Args:
        toe_in_deg: how far each camera is turned towards the other [deg], in (5, 80).
        baseline: distance between the two centres [m], > 0.
        focal: distance of the drawn image planes from their centres [m], > 0 (drawing only).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_epipolar_schematic()
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not 5.0 < toe_in_deg < 80.0:
        raise ValueError(f"toe_in_deg must lie in (5, 80) degrees; got {toe_in_deg!r}")
    if not (np.isfinite(baseline) and baseline > 0 and np.isfinite(focal) and focal > 0):
        raise ValueError(f"baseline and focal must be positive lengths [m]; got {baseline!r} and {focal!r}")
    alpha = np.radians(toe_in_deg)
    centres = (np.zeros(3), np.array([baseline, 0.0, 0.0]))  # drawing frame W: x right, y down, z forward
    R_CtoW = (_rot_y(alpha), _rot_y(-alpha))
    meet = 0.5 * baseline / np.tan(alpha)  # depth where the two optical axes cross
    X_W = np.array([0.58 * baseline, -0.3 * baseline, 1.1 * meet])
    R_C1toC2 = R_CtoW[1].T @ R_CtoW[0]
    p_C1inC2 = R_CtoW[1].T @ (centres[0] - centres[1])
    E = essential_from_pose(R_C1toC2, p_C1inC2)

    def to_camera(i: int, points_W: ArrayLike) -> NDArray[np.float64]:
        return (np.atleast_2d(points_W) - centres[i]) @ R_CtoW[i]  # R_WtoC (X - c), row-wise

    def to_world(i: int, points_C: ArrayLike) -> NDArray[np.float64]:
        return np.atleast_2d(points_C) @ R_CtoW[i].T + centres[i]

    images, epipoles = [], []
    for i in (0, 1):
        X_C = to_camera(i, X_W)[0]
        other = to_camera(i, centres[1 - i])[0]
        images.append(X_C[:2] / X_C[2])
        epipoles.append(other[:2] / other[2])

    fig = plt.figure(figsize=(14.5, 6.0))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.45, 1.0))
    ax = fig.add_subplot(grid[0], projection="3d")
    colours = ("tab:blue", "tab:orange")
    for i in (0, 1):
        x_img, e = images[i], epipoles[i]
        line = e + np.linspace(-0.2, 1.4, 2)[:, None] * (x_img - e)  # the epipolar line, a bit past x and e
        lo = np.minimum(line.min(axis=0), [-0.3, -0.3]) - 0.1
        hi = np.maximum(line.max(axis=0), [0.3, 0.3]) + 0.1
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        on_plane = lambda uv: to_world(i, focal * np.c_[uv, np.ones(len(uv))])  # noqa: E731
        _plane_patch(ax, on_plane(corners), colours[i], alpha=0.2)
        c = centres[i]
        ax.scatter(*_in_plot(c), color=colours[i], s=45)
        _text3d(ax, c + [0.0, 0.12, 0.0], f"C{i + 1}", color=colours[i], fontsize=12, ha="center", va="top")
        _arrow3d(ax, c, R_CtoW[i] @ [0.0, 0.0, 0.7], colours[i], f"z_C{i + 1}")
        _arrow3d(ax, c, R_CtoW[i] @ [0.4, 0.0, 0.0], colours[i], f"x_C{i + 1}")
        _line3d(ax, c, X_W, color=colours[i], lw=1.3)
        x_W = on_plane(x_img[None])[0]
        e_W = on_plane(e[None])[0]
        ax.scatter(*_in_plot(x_W), color="k", s=22, zorder=5)
        _text3d(ax, x_W, f" x{i + 1}", fontsize=11, va="bottom")
        ax.scatter(*_in_plot(e_W), color="tab:red", s=32, marker="s", zorder=5)
        _text3d(ax, e_W + [0.0, 0.08, 0.0], f"e{i + 1}", color="tab:red", fontsize=11, va="top", ha="center")
        segment = on_plane(line)
        _line3d(ax, segment[0], segment[1], color="tab:red", lw=1.8)
    _plane_patch(ax, np.vstack([centres[0], centres[1], X_W]), "tab:green", alpha=0.15)
    _line3d(ax, centres[0], centres[1], color="k", lw=1.6)
    ax.scatter(*_in_plot(X_W), color="tab:green", s=50)
    _text3d(ax, X_W, "  X", color="tab:green", fontsize=12)
    (tx,), (ty,), (tz,) = _in_plot(centres[1])
    (u,), (v,), (w,) = _in_plot(0.35 * (centres[0] - centres[1]))
    ax.quiver(tx, ty, tz, u, v, w, color="k", arrow_length_ratio=0.25, linewidth=2.2)
    _text3d(ax, centres[1] + 0.2 * (centres[0] - centres[1]) + [0.0, 0.1, 0.0], "t", fontsize=12, va="top")
    ax.set_xlim(-0.4, baseline + 0.4)
    ax.set_ylim(-0.1, X_W[2] + 0.2)
    ax.set_zlim(-0.35, -X_W[1] + 0.15)
    ax.set_box_aspect((np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_zlabel("−y (up) [m]")
    ax.view_init(elev=28, azim=-70)
    ax.set_title("two views of one point X (thesis §2.1.2, Fig. 2)", fontsize=10)
    ax.legend(handles=[
        Line2D([], [], ls="", marker="o", color=colours[0], label="camera 1: centre C1, axes x_C1, z_C1, image plane"),
        Line2D([], [], ls="", marker="o", color=colours[1], label="camera 2, turned by R = R_C1toC2"),
        Line2D([], [], color="k", lw=2, label="baseline; arrow t = p_C1inC2 (C1's centre seen from C2)"),
        Patch(facecolor="tab:green", alpha=0.3, label="epipolar plane through C1, C2 and X"),
        Line2D([], [], ls="", marker="s", color="tab:red",
               label="epipoles e1, e2: where the baseline meets the planes"),
        Line2D([], [], color="tab:red", lw=1.8, label="epipolar lines: the plane cut by each image plane"),
    ], fontsize=8, loc="upper left", framealpha=0.9)

    ax2 = fig.add_subplot(grid[1])
    x1h = np.array([images[0][0], images[0][1], 1.0])
    depth_X = to_camera(0, X_W)[0, 2]
    depths = np.array([0.25, 0.5, 1.0, 2.0, 4.0, 16.0]) * depth_X
    along_ray = to_camera(1, to_world(0, depths[:, None] * x1h))
    seen = along_ray[:, :2] / along_ray[:, 2:]
    l2 = E @ x1h  # the epipolar line a x + b y + c = 0 in image 2 (normalised coordinates)
    xs = np.linspace(min(seen[:, 0].min(), epipoles[1][0]) - 0.2, max(seen[:, 0].max(), epipoles[1][0]) + 0.2, 2)
    ax2.plot(xs, -(l2[0] * xs + l2[2]) / l2[1], color="tab:red", lw=1.6, label="epipolar line l2 = E x1")
    ax2.plot(*epipoles[1], "s", color="tab:red", ms=8, label="epipole e2: C1's centre seen by camera 2")
    ax2.plot(seen[:, 0], seen[:, 1], "o", color="tab:blue", ms=6, zorder=3,
             label="points of C1's ray through x1, at depth Z1 in C1")
    for (u, v), z in zip(seen, depths):
        ax2.annotate(f"Z1 = {z:.1f} m", (u, v), xytext=(6, -12), textcoords="offset points", fontsize=8)
    ax2.plot(*images[1], "*", color="tab:green", ms=15, label="x2: the image of X", zorder=4)
    ax2.set(xlabel="x2 = X/Z in camera 2 [normalised]", ylabel="y2 = Y/Z in camera 2 [normalised]")
    ax2.invert_yaxis()  # image rows grow downwards
    ax2.grid(alpha=0.3)
    ax2.set_title("image 2: every point of C1's ray through x1 lands on one line", fontsize=10)
    ax2.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return fig


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
