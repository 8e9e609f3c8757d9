"""Synthetic Shapes: seeded grayscale images of simple shapes with unambiguous corner/junction keypoints.

The dataset that bootstraps the detector (MagicPoint) in thesis §3.2.1 (Fig. 9): checkerboards, cubes, ellipses,
lines, polygons, stars, stripes and Gaussian noise, drawn over a smooth random background. Ellipses and noise
have no keypoints, so the network learns to ignore blobs and noise. The "Gaussian noise" images are per-pixel
uniform noise, as in SuperPoint's generator of that name.

Proportions (thesis §3.2.1): 10,000 images of each kind except ellipses (3,000), stripes (2,000) and Gaussian
noise (1,000), 66,000 in all. The thesis lists eight kind names but 66,000 only adds up with SuperPoint's nine
generators (its "polygons" are two: one polygon, and several non-overlapping polygons), so ``polygon`` and
``multiple_polygons`` get 10,000 each; the counts equal SuperPoint's truncation (ellipses 0.3, stripes 0.2,
noise 0.1 of 10,000). See :data:`SHAPE_COUNTS`.

Drawing. Every shape is drawn with OpenCV polygons/lines/ellipses (fixed-point, 1/16 pixel) on a canvas
``SUPERSAMPLE`` = 4 times larger than the output, then area-averaged down (anti-aliasing) and slightly
Gaussian-blurred (sigma 0.3-0.6 px, like SuperPoint's blur before its 8x downsampling). An output pixel centre
``x`` sits at canvas coordinate ``4 x + 1.5``, so keypoints are exact in output pixels (centres at integers).
Shape colours differ from the local background (and from adjacent faces/cells) by at least 0.2, shapes of
one image do not overlap, polygon corners are neither flat nor needle-sharp (25-155 degrees), and keypoints are
kept only when they fall inside the image.

Reference: thesis §3.2.1, Fig. 9, §3.2.5.1; DeTone, Malisiewicz & Rabinovich, "SuperPoint", CVPRW 2018, §4
(Synthetic Shapes) and its public re-implementation's generator (sizes and counts).
"""
from __future__ import annotations

import math
from numbers import Integral
from typing import Any, Callable

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from evio_lib.features.training.augment import (
    HOMOGRAPHIC_SYNTHETIC,
    PHOTOMETRIC_SYNTHETIC,
    HomographicConfig,
    PhotometricConfig,
    Sample,
    as_rng,
    filter_keypoints,
    homographic_augment,
    keypoints_to_map,
    photometric_augment,
)

__all__ = [
    "SHAPE_KINDS",
    "SHAPE_COUNTS",
    "UNLABELLED_KINDS",
    "SUPERSAMPLE",
    "generate_shape_image",
    "kind_schedule",
    "SyntheticShapes",
]

SHAPE_KINDS = ("checkerboard", "cube", "ellipses", "lines", "polygon", "multiple_polygons", "star", "stripes",
               "gaussian_noise")
#: images per kind in the thesis's 66,000-image set (§3.2.1); used as sampling proportions.
SHAPE_COUNTS = {"checkerboard": 10000, "cube": 10000, "ellipses": 3000, "lines": 10000, "polygon": 10000,
                "multiple_polygons": 10000, "star": 10000, "stripes": 2000, "gaussian_noise": 1000}
UNLABELLED_KINDS = ("ellipses", "gaussian_noise")
SUPERSAMPLE = 4  # canvas pixels per output pixel
_SHIFT = 4  # OpenCV fixed-point bits (1/16 canvas pixel)
_MIN_CONTRAST = 0.2
_SPLIT_CODES = {"train": 0, "val": 1, "test": 2}


# ============================================================================================== drawing helpers
def _fixed(points: np.ndarray) -> np.ndarray:
    """Return output-pixel points (N, 2) as int32 fixed-point canvas coordinates: ``X = 4 x + 1.5``, times 2^shift."""
    canvas = np.asarray(points, np.float64) * SUPERSAMPLE + (SUPERSAMPLE - 1) / 2.0  # pixel centre -> canvas centre
    return np.rint(canvas * (1 << _SHIFT)).astype(np.int32)


def _fill_polygons(canvas: np.ndarray, polygons: list[np.ndarray], value: float) -> None:
    """Fill polygons given in output pixels with one value."""
    cv2.fillPoly(canvas, [_fixed(p).reshape(-1, 1, 2) for p in polygons], float(value), cv2.LINE_8, _SHIFT)


def _draw_line(canvas: np.ndarray, p0: np.ndarray, p1: np.ndarray, value: float, thickness_px: float) -> None:
    """Draw a segment between two output-pixel points, ``thickness_px`` output pixels thick."""
    a, b = _fixed(np.array([p0, p1]))
    thickness = max(1, int(round(thickness_px * SUPERSAMPLE)))
    cv2.line(canvas, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), float(value), thickness, cv2.LINE_8, _SHIFT)


def _local(background: np.ndarray, point: np.ndarray) -> float:
    """Return the background value (output resolution) at the pixel nearest to ``point`` (clamped)."""
    height, width = background.shape
    col = int(np.clip(round(float(point[0])), 0, width - 1))
    row = int(np.clip(round(float(point[1])), 0, height - 1))
    return float(background[row, col])


def _colour(rng: np.random.Generator, *avoid: float, min_diff: float = _MIN_CONTRAST) -> float:
    """Return a uniform random intensity at least ``min_diff`` away from every value in ``avoid`` (best effort)."""
    best, best_gap = 0.5, -1.0
    for _ in range(30):
        value = float(rng.random())
        gap = min((abs(value - a) for a in avoid), default=1.0)
        if gap >= min_diff:
            return value
        if gap > best_gap:
            best, best_gap = value, gap
    return best


def _corner_angles(polygon: np.ndarray) -> np.ndarray:
    """Return the unsigned angle (radians, (0, pi)) between the two edges at every vertex of a closed polygon."""
    prev = np.roll(polygon, 1, axis=0) - polygon
    nxt = np.roll(polygon, -1, axis=0) - polygon
    cos = (prev * nxt).sum(1) / np.maximum(np.linalg.norm(prev, axis=1) * np.linalg.norm(nxt, axis=1), 1e-12)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _good_polygon(polygon: np.ndarray, min_edge: float) -> bool:
    """Return whether every corner lies in [25, 155] degrees and every edge is at least ``min_edge`` long."""
    angles = np.degrees(_corner_angles(polygon))
    edges = np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
    return bool((angles >= 25.0).all() and (angles <= 155.0).all() and (edges >= min_edge).all())


def _random_polygon(rng: np.random.Generator, centre: np.ndarray, radius: float, min_edge: float,
                    max_sides: int = 8) -> np.ndarray:
    """Return a star-shaped polygon (K, 2), 3 <= K <= max_sides, vertices at radius U(0.5, 1) r around ``centre``."""
    for _ in range(50):
        n = int(rng.integers(3, max_sides + 1))
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
        gaps = np.diff(np.append(angles, angles[0] + 2.0 * np.pi))
        if gaps.min() < 0.35 or gaps.max() > np.pi - 0.2:  # vertices well apart, centre inside the polygon
            continue
        radii = radius * rng.uniform(0.5, 1.0, n)
        polygon = centre + radii[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        if _good_polygon(polygon, min_edge):
            return polygon
    angles = rng.uniform(0.0, 2.0 * np.pi) + np.arange(3) * 2.0 * np.pi / 3.0  # fallback: equilateral triangle
    return centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def _random_quad(rng: np.random.Generator, shape: tuple[int, int], size: np.ndarray, jitter: float
                 ) -> np.ndarray | None:
    """Return a convex quadrilateral (4, 2): a rotated rectangle of ``size`` (w, h) with corners jittered, or None."""
    height, width = shape
    centre = np.array([width, height]) / 2.0 + rng.uniform(-0.15, 0.15, 2) * [width, height]
    angle = rng.uniform(-np.pi / 2, np.pi / 2)
    c, s = math.cos(angle), math.sin(angle)
    rect = (np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]) * size) @ np.array([[c, s], [-s, c]])
    quad = centre + rect + rng.normal(0.0, jitter, (4, 2)) * size.min()
    edges = np.roll(quad, -1, axis=0) - quad
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    angles = np.degrees(_corner_angles(quad))
    if not ((cross > 0).all() or (cross < 0).all()) or angles.min() < 45.0 or angles.max() > 135.0:
        return None
    return quad


def _segment_distances(p0: np.ndarray, p1: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """Return distances (M,) between the segment p0-p1 and each segment a0[i]-a1[i] (0 where they cross)."""

    def point_to_segments(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
        d = s1 - s0
        t = np.clip(((p - s0) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
        return np.linalg.norm(s0 + t[..., None] * d - p, axis=-1)

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    d = p1 - p0
    e = a1 - a0
    crosses = (np.sign(cross(d, a0 - p0)) != np.sign(cross(d, a1 - p0))) & (
        np.sign(cross(e, p0 - a0)) != np.sign(cross(e, p1 - a0)))
    dist = np.minimum.reduce([point_to_segments(p0, a0, a1), point_to_segments(p1, a0, a1),
                              point_to_segments(a0, p0[None], p1[None]), point_to_segments(a1, p0[None], p1[None])])
    return np.where(crosses, 0.0, dist)


def _background(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Return a smooth random background (H, W) float32: thresholded noise and blobs under a wide (twice) box blur."""
    height, width = shape
    dim = max(height, width)
    bg = (rng.random((height, width), dtype=np.float32) > rng.random()).astype(np.float32)
    mean = float(bg.mean())
    n_blobs = 100
    centres = rng.uniform(0.0, 1.0, (n_blobs, 2)) * [width, height]
    radii = rng.uniform(0.01, 0.05, n_blobs) * dim
    for (cx, cy), radius in zip(centres, radii):  # 100 blobs, not pixels
        cv2.circle(bg, (int(cx), int(cy)), max(1, int(radius)), _colour(rng, mean), -1)
    kernel = max(3, int(rng.uniform(50.0, 300.0) / 960.0 * dim + 0.5))  # SuperPoint's 50-300 px at 960 px
    bg = cv2.blur(bg, (kernel, kernel), borderType=cv2.BORDER_REFLECT_101)
    return cv2.blur(bg, (kernel, kernel), borderType=cv2.BORDER_REFLECT_101)  # twice: no blocky box artefacts


# ============================================================================================== generators
# each draws on the canvas (SUPERSAMPLE x the output) and returns keypoints (N, 2) in output pixels
def _draw_polygon(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    radius = rng.uniform(0.15, 0.45) * dim
    centre = rng.uniform(0.2, 0.8, 2) * [width, height]
    polygon = _random_polygon(rng, centre, radius, min_edge=0.06 * dim)
    _fill_polygons(canvas, [polygon], _colour(rng, _local(bg, centre), *(_local(bg, p) for p in polygon)))
    return polygon


def _draw_multiple_polygons(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]
                            ) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    discs: list[tuple[np.ndarray, float]] = []
    keypoints: list[np.ndarray] = []
    for _ in range(30):  # attempts, SuperPoint-like
        radius = rng.uniform(0.06, 0.18) * dim
        centre = rng.uniform(0.0, 1.0, 2) * [width, height]
        if any(np.linalg.norm(centre - c) < radius + r + 2.0 for c, r in discs):
            continue  # no overlap: every vertex stays a visible corner
        polygon = _random_polygon(rng, centre, radius, min_edge=0.05 * dim)
        discs.append((centre, radius))
        _fill_polygons(canvas, [polygon], _colour(rng, _local(bg, centre), *(_local(bg, p) for p in polygon)))
        keypoints.append(polygon)
    return np.concatenate(keypoints) if keypoints else np.zeros((0, 2))


def _draw_lines(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    thick: list[float] = []
    n_lines = int(rng.integers(1, 11))
    for _ in range(4 * n_lines):
        if len(starts) == n_lines:
            break
        p0, p1 = rng.uniform(0.02, 0.98, (2, 2)) * [width, height]
        thickness = rng.uniform(1.0, 2.5)
        if np.linalg.norm(p1 - p0) < 0.15 * dim:
            continue
        if starts:  # keep segments apart: no crossings (no unlabelled junctions)
            gaps = _segment_distances(p0, p1, np.array(starts), np.array(ends))
            if (gaps < (thickness + np.array(thick)) / 2.0 + 2.0).any():
                continue
        starts.append(p0)
        ends.append(p1)
        thick.append(thickness)
    for p0, p1, thickness in zip(starts, ends, thick):
        value = _colour(rng, _local(bg, p0), _local(bg, p1), _local(bg, (p0 + p1) / 2))
        _draw_line(canvas, p0, p1, value, thickness)
    return np.array(starts + ends) if starts else np.zeros((0, 2))


def _draw_star(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    centre = rng.uniform(0.25, 0.75, 2) * [width, height]
    n = int(rng.integers(3, 6))
    for _ in range(50):
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
        if np.diff(np.append(angles, angles[0] + 2.0 * np.pi)).min() >= 0.6:
            break
    else:
        angles = rng.uniform(0.0, 2.0 * np.pi) + np.arange(n) * 2.0 * np.pi / n
    radii = rng.uniform(0.5, 1.0, n) * rng.uniform(0.2, 0.45) * dim
    tips = centre + radii[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    value = _colour(rng, _local(bg, centre), *(_local(bg, t) for t in tips))
    thickness = rng.uniform(1.0, 2.5)
    for tip in tips:
        _draw_line(canvas, centre, tip, value, thickness)
    return np.vstack([centre[None], tips])


def _draw_checkerboard(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]
                       ) -> np.ndarray:
    height, width = shape
    rows, cols = int(rng.integers(3, 8)), int(rng.integers(3, 8))
    for _ in range(30):
        cell = rng.uniform(0.5, 1.0) * min(height, width) / max(rows, cols) * rng.uniform(0.9, 1.4)
        quad = _random_quad(rng, shape, np.array([cols, rows]) * cell, jitter=0.06)
        if quad is not None:
            break
    else:
        quad = np.array([[0.2, 0.2], [0.8, 0.2], [0.8, 0.8], [0.2, 0.8]]) * [width, height]
    board = np.array([[0, 0], [cols, 0], [cols, rows], [0, rows]], np.float32)
    H = cv2.getPerspectiveTransform(board, quad.astype(np.float32)).astype(np.float64)
    gu, gv = np.meshgrid(np.arange(cols + 1, dtype=np.float64), np.arange(rows + 1, dtype=np.float64))
    grid = np.stack([gu, gv, np.ones_like(gu)], -1) @ H.T
    grid = grid[..., :2] / grid[..., 2:]  # (rows + 1, cols + 1, 2) corners in the image: x = H [u, v, 1]
    values = np.zeros((rows, cols))
    for r in range(rows):  # <= 49 cells: each differs from its left and upper neighbours and the background
        for c in range(cols):
            centre = grid[r : r + 2, c : c + 2].reshape(4, 2).mean(0)
            avoid = [_local(bg, centre)]
            avoid += [values[r, c - 1]] if c > 0 else []
            avoid += [values[r - 1, c]] if r > 0 else []
            values[r, c] = _colour(rng, *avoid)
            cell_poly = np.array([grid[r, c], grid[r, c + 1], grid[r + 1, c + 1], grid[r + 1, c]])
            _fill_polygons(canvas, [cell_poly], values[r, c])
    return grid.reshape(-1, 2)


def _draw_stripes(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    for _ in range(30):
        n = int(rng.integers(5, 14))
        widths = rng.uniform(1.0, 3.0, n)
        bounds = np.concatenate([[0.0], np.cumsum(widths) / widths.sum()])
        size = rng.uniform(0.5, 0.95, 2) * [width, height]
        quad = _random_quad(rng, shape, size, jitter=0.04)
        if quad is None:
            continue
        H = cv2.getPerspectiveTransform(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32),
                                        quad.astype(np.float32)).astype(np.float64)
        unit = np.concatenate([np.stack([bounds, np.zeros_like(bounds)], 1),
                               np.stack([bounds, np.ones_like(bounds)], 1)])
        mapped = np.concatenate([unit, np.ones((len(unit), 1))], 1) @ H.T
        points = mapped[:, :2] / mapped[:, 2:]  # tops (n + 1) then bottoms (n + 1)
        top, bottom = points[: n + 1], points[n + 1 :]
        if min(np.linalg.norm(np.diff(top, axis=0), axis=1).min(),
               np.linalg.norm(np.diff(bottom, axis=0), axis=1).min()) < 3.0:
            continue  # stripes at least 3 px wide: corners stay apart
        previous = _local(bg, points.mean(0))
        for i in range(n):
            value = _colour(rng, previous, _local(bg, (top[i] + bottom[i + 1]) / 2))
            _fill_polygons(canvas, [np.array([top[i], top[i + 1], bottom[i + 1], bottom[i]])], value)
            previous = value
        return points
    return np.zeros((0, 2))


_CUBE_FACES = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])


def _draw_cube(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, x, y, z = q  # rotation matrix of the unit quaternion (w, x, y, z)
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        dims = rng.uniform(0.6, 1.0, 3) * rng.uniform(0.25, 0.5) * dim
        vertices = (corners * dims) @ R.T
        centres = np.array([vertices[f].mean(0) for f in _CUBE_FACES])
        normals_z = centres[:, 2] / np.linalg.norm(centres, axis=1)  # outward normal . viewing axis (+z)
        visible = normals_z < -0.25  # orthographic camera looking along +z sees faces pointing to -z
        if visible.sum() == 3:  # three faces, none seen too obliquely
            break
    projected = vertices[:, :2]
    extent = projected.max(0) - projected.min(0)
    low = projected.min(0)
    offset = rng.uniform(0.0, 1.0, 2) * np.maximum([width, height] - extent, 1.0) - low  # keep it in the image
    projected = projected + offset
    shown: list[float] = [_local(bg, projected.mean(0))]
    keep = np.zeros(8, bool)
    for face in _CUBE_FACES[visible]:
        value = _colour(rng, *shown)
        shown.append(value)
        _fill_polygons(canvas, [projected[face]], value)
        keep[face] = True
    return projected[keep]  # the seven vertices of the three visible faces


def _draw_ellipses(canvas: np.ndarray, bg: np.ndarray, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    height, width = shape
    dim = min(height, width)
    discs: list[tuple[np.ndarray, float]] = []
    for _ in range(20):
        axes = rng.uniform(0.04, 0.2, 2) * dim
        centre = rng.uniform(0.0, 1.0, 2) * [width, height]
        if any(np.linalg.norm(centre - c) < axes.max() + r + 2.0 for c, r in discs):
            continue
        discs.append((centre, float(axes.max())))
        box = (tuple(float(v) for v in centre * SUPERSAMPLE + (SUPERSAMPLE - 1) / 2.0),
               tuple(float(v) for v in 2.0 * axes * SUPERSAMPLE), float(rng.uniform(0.0, 180.0)))
        cv2.ellipse(canvas, box, _colour(rng, _local(bg, centre)), -1, cv2.LINE_8)
    return np.zeros((0, 2))


_GENERATORS: dict[str, Callable[..., np.ndarray]] = {
    "checkerboard": _draw_checkerboard,
    "cube": _draw_cube,
    "ellipses": _draw_ellipses,
    "lines": _draw_lines,
    "polygon": _draw_polygon,
    "multiple_polygons": _draw_multiple_polygons,
    "star": _draw_star,
    "stripes": _draw_stripes,
}


def _check_shape(shape: Any) -> tuple[int, int]:
    try:
        height, width = (int(v) for v in shape)
        ok = (height, width) == tuple(shape) and height >= 16 and width >= 16
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"shape must be (height, width) of ints >= 16; got {shape!r}")
    return height, width


def generate_shape_image(kind: str, shape: tuple[int, int] = (120, 160), rng: np.random.Generator | int = 0
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Return one Synthetic Shapes image (H, W) float32 in [0, 1] and its keypoints (N, 2) float32 (x, y) pixels.

    The image is a smooth random background with one kind of shape drawn on it (or pure uniform noise for
    ``gaussian_noise``); keypoints are the shape's corners and junctions that lie inside the image (none for
    ``ellipses`` and ``gaussian_noise``). Deterministic for a given seed.

    Args:
        kind: one of :data:`SHAPE_KINDS`.
        shape: (height, width) of the image, each >= 16 (thesis: 120 x 160).
        rng: Generator or seed.

    Reference: thesis §3.2.1, Fig. 9; SuperPoint §4 (Synthetic Shapes).

    >>> image, keypoints = generate_shape_image("cube", (120, 160), rng=3)
    >>> image.shape, image.dtype, keypoints.shape
    ((120, 160), dtype('float32'), (7, 2))
    >>> generate_shape_image("ellipses", rng=3)[1].shape
    (0, 2)
    """
    if kind not in SHAPE_KINDS:
        raise ValueError(f"kind must be one of {SHAPE_KINDS}; got {kind!r}")
    height, width = _check_shape(shape)
    gen = as_rng(rng)
    if kind == "gaussian_noise":
        image = gen.random((height, width), dtype=np.float32)  # uniform noise, no keypoints
        keypoints = np.zeros((0, 2))
    else:
        bg = _background(gen, (height, width))
        canvas = cv2.resize(bg, (width * SUPERSAMPLE, height * SUPERSAMPLE), interpolation=cv2.INTER_LINEAR)
        keypoints = _GENERATORS[kind](canvas, bg, gen, (height, width))
        image = cv2.resize(canvas, (width, height), interpolation=cv2.INTER_AREA)  # area average = anti-aliasing
    image = cv2.GaussianBlur(image, (0, 0), float(gen.uniform(0.3, 0.6)), borderType=cv2.BORDER_REFLECT_101)
    keypoints = np.asarray(keypoints, np.float64).reshape(-1, 2)
    keypoints = keypoints[filter_keypoints(keypoints, (height, width))]
    return np.clip(image, 0.0, 1.0).astype(np.float32), keypoints.astype(np.float32)


# ============================================================================================== dataset
def kind_schedule(counts: dict[str, int] | None = None, seed: int = 0) -> list[str]:
    """Return one shuffled cycle of kinds whose frequencies equal ``counts`` reduced by their gcd.

    With the thesis's counts the cycle has 66 entries: 10 of each labelled kind, 3 ellipses, 2 stripes, 1 noise.

    Args:
        counts: images per kind (default :data:`SHAPE_COUNTS`); kinds with count 0 are left out.
        seed: shuffles the cycle.

    >>> cycle = kind_schedule()
    >>> len(cycle), cycle.count("ellipses"), cycle.count("stripes"), cycle.count("gaussian_noise")
    (66, 3, 2, 1)
    """
    counts = dict(SHAPE_COUNTS if counts is None else counts)
    for kind, count in counts.items():
        if kind not in SHAPE_KINDS:
            raise ValueError(f"counts keys must be kinds from {SHAPE_KINDS}; got {kind!r}")
        if isinstance(count, bool) or not isinstance(count, Integral) or count < 0:
            raise ValueError(f"counts[{kind!r}] must be a non-negative int; got {count!r}")
    counts = {k: int(v) for k, v in counts.items() if v > 0}
    if not counts:
        raise ValueError("counts must give at least one kind a positive count; got none")
    step = math.gcd(*counts.values())
    cycle = [kind for kind in SHAPE_KINDS if kind in counts for _ in range(counts[kind] // step)]
    order = np.random.default_rng([int(seed), 66]).permutation(len(cycle))
    return [cycle[i] for i in order]


class SyntheticShapes(Dataset):
    """Torch dataset of Synthetic Shapes generated on the fly: item i is the same image for the same seed.

    ``dataset[i]`` is a :class:`~evio_lib.features.training.augment.Sample` of tensors: image (1, H, W) float32,
    keypoint_map (H, W) float32 (1 at keypoint pixels), valid_mask (H, W) float32. With augmentation (default on the
    train split, off on val/test as in thesis §3.2.2) the image is photometrically augmented, then warped by a
    random homography together with its keypoints and valid mask (thesis §3.2.5); the augmentation varies with
    :meth:`set_epoch`, the underlying image does not. Kinds follow :func:`kind_schedule` (thesis proportions).
    Image i of split s uses ``default_rng([seed, s, i])``, so splits never share images.

    Args:
        n_images: length of the dataset (default 66,000 for train, 3,200 for val/test as in §3.2.1-3.2.2).
        split: "train", "val" or "test".
        seed: base seed.
        shape: (height, width), default (120, 160) (thesis §3.2.5.1).
        counts: images per kind (proportions), default :data:`SHAPE_COUNTS`.
        augment: apply augmentation (None: only for "train").
        photometric, homographic: augmentation configs (None disables that part); SuperPoint's shapes presets
            by default.

    >>> data = SyntheticShapes(10, seed=0)
    >>> image, keypoint_map, valid_mask = data[0]
    >>> tuple(image.shape), tuple(keypoint_map.shape), image.dtype
    ((1, 120, 160), (120, 160), torch.float32)
    """

    def __init__(self, n_images: int | None = None, *, split: str = "train", seed: int = 0,
                 shape: tuple[int, int] = (120, 160), counts: dict[str, int] | None = None,
                 augment: bool | None = None, photometric: PhotometricConfig | None = PHOTOMETRIC_SYNTHETIC,
                 homographic: HomographicConfig | None = HOMOGRAPHIC_SYNTHETIC) -> None:
        if split not in _SPLIT_CODES:
            raise ValueError(f"split must be one of {sorted(_SPLIT_CODES)}; got {split!r}")
        if n_images is None:
            n_images = 66000 if split == "train" else 3200
        if isinstance(n_images, bool) or not isinstance(n_images, Integral) or n_images < 1:
            raise ValueError(f"n_images must be a positive int; got {n_images!r}")
        if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
            raise ValueError(f"seed must be a non-negative int; got {seed!r}")
        if photometric is not None and not isinstance(photometric, PhotometricConfig):
            raise ValueError(f"photometric must be a PhotometricConfig or None; got {type(photometric).__name__}")
        if homographic is not None and not isinstance(homographic, HomographicConfig):
            raise ValueError(f"homographic must be a HomographicConfig or None; got {type(homographic).__name__}")
        self.n_images = int(n_images)
        self.split = split
        self.seed = int(seed)
        self.shape = _check_shape(shape)
        self.augment = (split == "train") if augment is None else bool(augment)
        self.photometric = photometric
        self.homographic = homographic
        self.schedule = kind_schedule(counts, self.seed)
        self.epoch = 0

    def __len__(self) -> int:
        return self.n_images

    def set_epoch(self, epoch: int) -> None:
        """Change the augmentation draws (not the images) for a new epoch."""
        if isinstance(epoch, bool) or not isinstance(epoch, Integral) or epoch < 0:
            raise ValueError(f"epoch must be a non-negative int; got {epoch!r}")
        self.epoch = int(epoch)

    def _index(self, index: int) -> int:
        if isinstance(index, bool) or not isinstance(index, Integral):
            raise ValueError(f"index must be an int; got {index!r}")
        i = int(index) + (self.n_images if index < 0 else 0)
        if not 0 <= i < self.n_images:
            raise IndexError(f"index {index} out of range for {self.n_images} images")
        return i

    def kind_of(self, index: int) -> str:
        """Return the kind of image ``index``."""
        return self.schedule[self._index(index) % len(self.schedule)]

    def raw(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the un-augmented image (H, W) float32 and keypoints (N, 2) float32 of item ``index``."""
        i = self._index(index)
        rng = np.random.default_rng([self.seed, _SPLIT_CODES[self.split], i])
        return generate_shape_image(self.kind_of(i), self.shape, rng)

    def sample(self, index: int) -> dict[str, Any]:
        """Return item ``index`` as NumPy arrays: image, keypoints, valid_mask (bool), homography, kind."""
        i = self._index(index)
        image, keypoints = self.raw(i)
        mask = np.ones(self.shape, bool)
        H = np.eye(3)
        if self.augment:
            rng = np.random.default_rng([self.seed, _SPLIT_CODES[self.split], i, self.epoch, 1])
            if self.photometric is not None:
                image = photometric_augment(image, rng, self.photometric)  # photometric, then homographic
            if self.homographic is not None:
                image, keypoints, mask, H = homographic_augment(image, keypoints, rng, self.homographic)
        return {"image": image, "keypoints": keypoints, "valid_mask": mask, "homography": H, "kind": self.kind_of(i)}

    def __getitem__(self, index: int) -> Sample:
        item = self.sample(index)
        label = keypoints_to_map(item["keypoints"], self.shape, item["valid_mask"])
        return Sample(torch.from_numpy(item["image"][None].copy()), torch.from_numpy(label),
                      torch.from_numpy(item["valid_mask"].astype(np.float32)))
