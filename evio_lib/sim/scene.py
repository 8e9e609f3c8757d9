"""A world of textured rectangles and its ray-casting renderer (intensity, depth, 3-D points, plane index).

Geometry. A :class:`TexturedPlane` is the parallelogram ``X(s, t) = origin_G + s axis_u_G + t axis_v_G`` with
``s, t`` in [0, 1]; its texture is indexed as ``(col, row) = (s (r_u W_t - 1), t (r_v H_t - 1))`` where
``(H_t, W_t)`` is the texture size and ``(r_u, r_v)`` the ``texture_repeat`` (1 = the texture spans the plane
once, texel centres on the borders; > 1 tiles it). Seen like an image, ``axis_u`` points right and ``axis_v``
down, so ``axis_u x axis_v`` points *away* from the viewer (like a camera's z axis).

Ray casting. The ray through a pixel is ``d_C = [x, y, 1]`` with ``(x, y)`` its undistorted normalised
coordinates (``camera.normalized_grid()``), so ``z d_C`` is the point at z-depth ``z``. With the plane in the
camera frame (``o, u, v`` = origin and axes, ``n = u x v``, ``h = n . o``), solving
``z d = o + s u + t v`` with scalar triple products gives three *linear* forms of ``d`` (a homography)::

    1/z = (n . d) / h,      s = (d . (v x o)) / (n . d),      t = (d . (o x u)) / (n . d)

With ``W = 1/z``, ``S = d.(v x o)/h``, ``T = d.(o x u)/h`` a pixel sees the plane iff the four "edge
functions" ``S, W - S, T, W - T`` are all >= 0 (they imply W >= 0, i.e. in front of the camera), and the
nearest plane is the one with the largest ``W``. The renderer evaluates these forms per plane over the pixel
rectangle that can contain the plane (frustum culling; single-sided planes seen from behind are skipped) and
keeps, per pixel, the maximum of a 32-bit key ``(float bits of W with the low bits replaced by the plane
number)`` -- a z-buffer and an index buffer in one ``np.maximum``.

Anti-aliasing (events are sensitive to aliasing). Textures are pre-filtered into a mip-map (each level is
the previous one filtered with the binomial kernel [1, 3, 3, 1] / 8 and decimated by 2, centred so that level
texel i covers level-0 texels 2i and 2i+1). The level of detail is chosen per pixel from the pixel footprint
on the surface: a pixel subtending the solid angle ``dOmega`` sees, at range ``r`` and incidence ``theta``,
a patch whose long axis is about ``r sqrt(dOmega) / cos(theta)``; with ``r = z |d|``, ``cos(theta) = |n^ . d| / |d|``
and ``z = 1 / W`` this is ``sqrt(|d|) sqrt(A_px) / (h^ W^2)``, where ``A_px`` is the pixel's area in normalised
coordinates and ``h^`` the camera's distance to the plane; ``lod = log2(long axis / texel size)``.
Samples are trilinear (bilinear in the two nearest levels, blended), so intensities change continuously
as the camera moves.

Reference: ray/plane intersection by Cramer's rule; mip-mapping: L. Williams, "Pyramidal parametrics",
SIGGRAPH 1983; the thesis (§2.2) for why event cameras need smooth, contrasted intensity.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from evio_lib.geometry.rotation import cross3
from evio_lib.sim.textures import (
    aerial_terrain_texture,
    load_texture,
    procedural_texture,
    rescale_contrast,
)

__all__ = [
    "RENDERER_ENV",
    "renderer_backend",
    "TexturedPlane",
    "RenderResult",
    "Scene",
    "indoor_room",
    "photo_room",
    "aerial_ground",
    "scene_from_preset",
    "PRESETS",
]

RENDERER_ENV = "EVIO_RENDERER"
"""Environment variable that picks the intensity renderer: ``numba`` (compiled kernels), ``numpy``, or ``auto``."""
_KERNELS_PROBLEM: list[str] = []  # memo: "" when the compiled kernels load here, else why they do not


def renderer_backend() -> str:
    """Return the backend of :meth:`Scene.render_intensity`: ``"numba"`` or ``"numpy"`` (same numbers, bit for bit).

    ``EVIO_RENDERER`` = ``numba`` | ``numpy`` | ``auto`` (default: the compiled kernels when they load, else NumPy
    with one warning saying why). The kernels (:mod:`evio_lib.sim.render_kernels`) render faster
    (docs/results/speed.md#the-simulator); NumPy is the reference they are tested against. They need the numba package
    and a writable cache folder for their machine code (``evio_lib/sim/__pycache__``, else Numba's user cache, else
    ``NUMBA_CACHE_DIR``).
    """
    from evio_lib.compiled import compiled_backend

    return compiled_backend(RENDERER_ENV, "evio_lib.sim.render_kernels", _KERNELS_PROBLEM,
                            "rendering with NumPy (about 2x slower, same images)")


_Z_NEAR = 1e-9  # near-plane for frustum culling only (metres); visibility itself needs no near plane
_ROT_TOL = 1e-6


# ============================================================================================== validation
def _vector3(value: Any, name: str) -> np.ndarray:
    """Return ``value`` as a finite float64 (3,) array, else raise ValueError."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(f"{name} must have shape (3,); got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite; got {array.tolist()}")
    return array


def _rotation(value: Any, name: str) -> np.ndarray:
    """Return ``value`` as a float64 (3, 3) rotation matrix (R R^T = I, det = +1 within 1e-6), else raise ValueError."""
    R = np.asarray(value, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3); got {R.shape}")
    if not np.isfinite(R).all():
        raise ValueError(f"{name} must be finite")
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if err > _ROT_TOL or abs(det - 1.0) > _ROT_TOL:
        raise ValueError(
            f"{name} must be a rotation matrix ({name} @ {name}.T = I, det = +1, tol {_ROT_TOL:g}); "
            f"got max |R R^T - I| = {err:.3g}, det = {det:.6g}"
        )
    return R


def _points(value: Any, name: str) -> np.ndarray:
    """Return ``value`` as a finite float64 (N, 3) array, else raise ValueError."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3); got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite")
    return array


# ============================================================================================== planes
@dataclass(frozen=True, eq=False)
class TexturedPlane:
    """A textured parallelogram ``origin_G + s axis_u_G + t axis_v_G``, ``s, t`` in [0, 1].

    Args:
        origin_G: (3,) corner at ``s = t = 0`` in the world frame G, metres.
        axis_u_G: (3,) edge vector along which ``s`` (texture column) grows, metres.
        axis_v_G: (3,) edge vector along which ``t`` (texture row) grows, metres (not parallel to ``axis_u_G``).
        texture: (H_t, W_t) intensities in [0, 1] (stored as a read-only float32 copy); texel
            ``(col, row) = (s (r_u W_t - 1), t (r_v H_t - 1))``.
        name: a label.
        texture_repeat: (r_u, r_v) > 0; 1 spans the texture once (edges clamp), > 1 tiles it (wraps).
            Tiled textures should have sizes divisible by a power of two (mip levels stop at odd sizes).
        two_sided: if False the plane is seen only from the side opposite to ``axis_u x axis_v``
            (where ``axis_u`` looks right and ``axis_v`` down); faces of closed boxes and the room use this.

    >>> plane = TexturedPlane(np.zeros(3), [2.0, 0, 0], [0, 1.0, 0], np.full((4, 8), 0.5, np.float32))
    >>> plane.point_at([0.5], [1.0]).tolist(), plane.normal_G.tolist()
    ([[1.0, 1.0, 0.0]], [0.0, 0.0, 1.0])
    """

    origin_G: np.ndarray
    axis_u_G: np.ndarray
    axis_v_G: np.ndarray
    texture: np.ndarray
    name: str = ""
    texture_repeat: tuple[float, float] = (1.0, 1.0)
    two_sided: bool = True

    def __post_init__(self) -> None:
        for attr in ("origin_G", "axis_u_G", "axis_v_G"):
            array = _vector3(getattr(self, attr), attr).copy()
            array.setflags(write=False)
            object.__setattr__(self, attr, array)
        normal = np.cross(self.axis_u_G, self.axis_v_G)
        scale = float(np.linalg.norm(self.axis_u_G) * np.linalg.norm(self.axis_v_G))
        if scale == 0.0 or float(np.linalg.norm(normal)) <= 1e-9 * scale:
            raise ValueError(
                f"axis_u_G and axis_v_G must be non-zero and not parallel; got {self.axis_u_G.tolist()} and "
                f"{self.axis_v_G.tolist()}"
            )
        texture = np.asarray(self.texture)
        if texture.ndim != 2 or texture.shape[0] < 1 or texture.shape[1] < 1:
            raise ValueError(f"texture must have shape (H_t, W_t); got {texture.shape}")
        if not (texture.dtype == np.float32 and texture.flags.c_contiguous and not texture.flags.writeable):
            texture = np.array(texture, dtype=np.float32, copy=True, order="C")  # private read-only copy
        if not np.isfinite(texture).all() or texture.min() < 0.0 or texture.max() > 1.0:
            raise ValueError(
                f"texture must hold finite intensities in [0, 1]; got range "
                f"[{float(np.nanmin(texture)):.3g}, {float(np.nanmax(texture)):.3g}]"
            )
        texture.setflags(write=False)
        object.__setattr__(self, "texture", texture)
        try:
            repeat = tuple(float(r) for r in self.texture_repeat)
        except (TypeError, ValueError):
            raise ValueError(
                f"texture_repeat must be a pair of positive numbers; got {self.texture_repeat!r}"
            ) from None
        spans = (repeat[0] * texture.shape[1] - 1.0, repeat[1] * texture.shape[0] - 1.0) if len(repeat) == 2 else ()
        if len(repeat) != 2 or not all(np.isfinite(r) and r > 0 for r in repeat) or min(spans) < 0:
            raise ValueError(
                f"texture_repeat must be a pair of positive numbers with r_u W_t >= 1 and r_v H_t >= 1; "
                f"got {self.texture_repeat!r}"
            )
        object.__setattr__(self, "texture_repeat", repeat)
        object.__setattr__(self, "two_sided", bool(self.two_sided))
        object.__setattr__(self, "name", str(self.name))

    @property
    def normal_G(self) -> np.ndarray:
        """Return the (3,) unit normal ``axis_u x axis_v / |axis_u x axis_v|`` (points away from the front side)."""
        normal = np.cross(self.axis_u_G, self.axis_v_G)
        return normal / np.linalg.norm(normal)

    @property
    def corners_G(self) -> np.ndarray:
        """Return the (4, 3) corners at (s, t) = (0, 0), (1, 0), (1, 1), (0, 1)."""
        o, u, v = self.origin_G, self.axis_u_G, self.axis_v_G
        return np.stack([o, o + u, o + u + v, o + v])

    @property
    def area_m2(self) -> float:
        """Return the area |axis_u x axis_v| in square metres."""
        return float(np.linalg.norm(np.cross(self.axis_u_G, self.axis_v_G)))

    @property
    def texel_size_m(self) -> float:
        """Return the smaller texel edge on the surface, metres: min(|u| / (r_u W_t - 1), |v| / (r_v H_t - 1))."""
        span_u, span_v = self.texel_spans
        sizes = [np.linalg.norm(self.axis_u_G) / span_u if span_u > 0 else np.inf,
                 np.linalg.norm(self.axis_v_G) / span_v if span_v > 0 else np.inf]
        smallest = float(min(sizes))
        if np.isfinite(smallest):
            return smallest
        return float(max(np.linalg.norm(self.axis_u_G), np.linalg.norm(self.axis_v_G)))

    @property
    def texel_spans(self) -> tuple[float, float]:
        """Return (r_u W_t - 1, r_v H_t - 1): the texel coordinate reached at s = 1 and at t = 1."""
        height, width = self.texture.shape
        return self.texture_repeat[0] * width - 1.0, self.texture_repeat[1] * height - 1.0

    def point_at(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Return the (N, 3) points ``origin_G + s axis_u_G + t axis_v_G`` for (N,) plane coordinates."""
        s_arr = np.atleast_1d(np.asarray(s, dtype=np.float64))
        t_arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if s_arr.ndim != 1 or s_arr.shape != t_arr.shape:
            raise ValueError(f"s and t must have the same shape (N,); got {s_arr.shape} and {t_arr.shape}")
        return self.origin_G + s_arr[:, None] * self.axis_u_G + t_arr[:, None] * self.axis_v_G


@dataclass(frozen=True)
class RenderResult:
    """What one camera sees: intensity (H, W) float32 in [0, 1] (``background`` where nothing is hit),
    depth (H, W) float32 z-depth in the camera frame (inf where nothing is hit), points_G (H, W, 3) float64
    hit points in G (NaN where nothing is hit), plane_index (H, W) int32 (-1 where nothing is hit)."""

    intensity: np.ndarray
    depth: np.ndarray
    points_G: np.ndarray
    plane_index: np.ndarray


# ============================================================================================== mip-map atlas
def _downsample(level: np.ndarray, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Return the next mip level: [1, 3, 3, 1] / 8 filter on each axis, decimated by 2 (texel i <- 2i, 2i + 1).

    Output texel i is centred on input coordinate 2i + 0.5, using input texels 2i - 1 ... 2i + 2 (padded by
    wrapping or by repeating the edge).
    """
    out = level
    for axis, wrap in ((1, wrap_u), (0, wrap_v)):
        size = out.shape[axis]
        n_out = (size + 1) // 2
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 2 * n_out + 2 - size)  # padded index j <-> source j - 1; needs up to 2 n_out + 1
        padded = np.pad(out, pad, mode="wrap" if wrap else "edge")
        take = [slice(None), slice(None)]
        parts = []
        for offset in range(4):  # source texels 2i - 1 + offset  ->  padded 2i + offset
            take[axis] = slice(offset, offset + 2 * n_out, 2)
            parts.append(padded[tuple(take)])
        out = (parts[0] + 3.0 * parts[1] + 3.0 * parts[2] + parts[3]) * np.float32(0.125)
    return np.ascontiguousarray(out, dtype=np.float32)


def _mip_levels(texture: np.ndarray, wrap_u: bool, wrap_v: bool) -> list[np.ndarray]:
    """Return the mip pyramid of ``texture`` (level 0 first) down to one texel (or to an odd size when tiled)."""
    levels = [texture]
    while max(levels[-1].shape) > 1:
        height, width = levels[-1].shape
        if (wrap_u and width % 2) or (wrap_v and height % 2):  # a tiled texture's period must stay whole
            break
        levels.append(_downsample(levels[-1], wrap_u, wrap_v))
    return levels


class _TextureAtlas:
    """All mip levels of all textures packed into one 2-D float32 image (shelf packing), with 1-texel borders.

    Each level is stored with a border filled by wrapping (tiled axes) or by repeating the edge (clamped axes),
    so bilinear lookups never leave it. ``base[slot * n_levels + L]`` is the flat index of texel (0, 0) of level
    L of the texture of ``slot``; texel (c, r) lies at ``base + r * stride + c``. Slot 0 is the background
    (a 1 x 1 texture); plane k uses slot k + 1.
    """

    def __init__(self, planes: Sequence[TexturedPlane], background: float) -> None:
        textures = [np.full((1, 1), background, dtype=np.float32)] + [p.texture for p in planes]
        wraps = [(False, False)] + [(p.texture_repeat[0] > 1.0, p.texture_repeat[1] > 1.0) for p in planes]
        pyramids: dict[tuple[int, bool, bool], list[np.ndarray]] = {}
        slot_keys = []
        for texture, wrap in zip(textures, wraps):
            key = (id(texture), *wrap)
            if key not in pyramids:
                pyramids[key] = [
                    np.pad(np.pad(level, [(0, 0), (1, 1)], mode="wrap" if wrap[0] else "edge"),
                           [(1, 1), (0, 0)], mode="wrap" if wrap[1] else "edge")
                    for level in _mip_levels(texture, *wrap)
                ]
            slot_keys.append(key)
        # shelf packing, tallest first: (key, level) -> (row, col) of the padded block's top-left corner
        blocks = [(key, level, block) for key, levels in pyramids.items() for level, block in enumerate(levels)]
        blocks.sort(key=lambda item: -item[2].shape[0])
        self.stride = max(2048, max(block.shape[1] for _, _, block in blocks))
        places: dict[tuple[tuple[int, bool, bool], int], tuple[int, int]] = {}
        shelf_top, shelf_height, cursor = 0, 0, 0
        for key, level, block in blocks:
            height, width = block.shape
            if cursor + width > self.stride:  # next shelf
                shelf_top, shelf_height, cursor = shelf_top + shelf_height, 0, 0
            places[(key, level)] = (shelf_top, cursor)
            shelf_height = max(shelf_height, height)
            cursor += width
        image = np.zeros((shelf_top + shelf_height, self.stride), dtype=np.float32)
        for key, level, block in blocks:
            top, left = places[(key, level)]
            image[top : top + block.shape[0], left : left + block.shape[1]] = block
        image.setflags(write=False)
        self.image = image
        self.data = image.ravel()
        self.n_levels = max(len(levels) for levels in pyramids.values())
        n_slots = len(textures)
        self.base = np.zeros(n_slots * self.n_levels, dtype=np.int64)
        self.max_level = np.zeros(n_slots)
        self.period_u = np.full(n_slots, 1e30)  # level-0 wrap periods in texels (1e30: clamped axis)
        self.period_v = np.full(n_slots, 1e30)
        for slot, key in enumerate(slot_keys):
            levels = pyramids[key]
            self.max_level[slot] = len(levels) - 1
            for level in range(self.n_levels):
                top, left = places[(key, min(level, len(levels) - 1))]
                self.base[slot * self.n_levels + level] = (top + 1) * self.stride + left + 1  # skip the border
            if wraps[slot][0]:
                self.period_u[slot] = textures[slot].shape[1]
            if wraps[slot][1]:
                self.period_v[slot] = textures[slot].shape[0]
        self.any_wrap = bool(np.any(self.period_u < 1e30) or np.any(self.period_v < 1e30))
        # float32 copies for the compiled path (render_kernels.sample_atlas), the numbers NumPy's path casts to
        self.period_u32, self.period_v32 = self.period_u.astype(np.float32), self.period_v.astype(np.float32)
        self.max_level32 = self.max_level.astype(np.float32)

    def sample_fast(self, slot: np.ndarray, col: np.ndarray, row: np.ndarray, lod: np.ndarray) -> np.ndarray:
        """Return :meth:`sample` in float32 from the compiled kernel (bit-identical; (H, W) arrays)."""
        from evio_lib.sim.render_kernels import sample_atlas

        return sample_atlas(slot, col, row, lod, self.data, self.base, self.n_levels, self.stride,
                            self.period_u32, self.period_v32, self.max_level32, self.any_wrap)

    def sample(self, slot: np.ndarray, col: np.ndarray, row: np.ndarray, lod: np.ndarray, dtype: type) -> np.ndarray:
        """Return trilinear samples at level-0 texel coordinates (col, row) >= 0 with level of detail ``lod`` >= 0.

        ``slot``: int64 array; ``col, row, lod``: arrays of ``dtype`` with the same shape.
        """
        one, half = dtype(1.0), dtype(0.5)
        if self.any_wrap:  # tiled axes: c = c - floor(c / P) P  (P = 1e30 leaves clamped axes unchanged)
            period_u = np.take(self.period_u.astype(dtype), slot)
            period_v = np.take(self.period_v.astype(dtype), slot)
            col = col - np.floor(col / period_u) * period_u
            row = row - np.floor(row / period_v) * period_v
        max_level = np.take(self.max_level.astype(dtype), slot)
        lod = np.minimum(lod, max_level)
        level0 = np.floor(lod)
        blend = lod - level0  # trilinear weight of the coarser level
        level1 = np.minimum(level0 + one, max_level)
        slot_base = slot * self.n_levels
        values = []
        for level in (level0, level1):
            base = np.take(self.base, slot_base + level.astype(np.int32))
            scale = np.exp2(-level)  # 0.5^L
            c = (col + half) * scale - half  # level-L texel coordinate: c_L = (c + 1/2) 0.5^L - 1/2
            r = (row + half) * scale - half
            c0, r0 = np.floor(c), np.floor(r)
            fc, fr = c - c0, r - r0
            index = base + (r0.astype(np.int32) * np.int32(self.stride) + c0.astype(np.int32))
            index_down = index + self.stride
            data = self.data
            top_left, top_right = np.take(data, index), np.take(data, index + 1)
            bottom_left, bottom_right = np.take(data, index_down), np.take(data, index_down + 1)
            top = top_left + fc * (top_right - top_left)  # bilinear: lerp along columns, then rows
            bottom = bottom_left + fc * (bottom_right - bottom_left)
            values.append(top + fr * (bottom - top))
        return (values[0] + blend * (values[1] - values[0])).astype(dtype, copy=False)


# ============================================================================================== camera cache
class _CameraTables:
    """Per-camera constants of the renderer: ray grids (float32 and float64), culling ranges, footprint term."""

    def __init__(self, camera: Any) -> None:
        grid = np.asarray(camera.normalized_grid(), dtype=np.float64)
        if grid.ndim != 3 or grid.shape[2] != 2 or grid.shape[0] < 2 or grid.shape[1] < 2:
            raise ValueError(f"camera.normalized_grid() must have shape (H, W, 2) with H, W >= 2; got {grid.shape}")
        if not np.isfinite(grid).all():  # e.g. a distortion with no inverse at some pixels
            bad = int(np.count_nonzero(~np.isfinite(grid).all(axis=2)))
            raise ValueError(f"camera.normalized_grid() must be finite; {bad} pixels have NaN/inf rays")
        self.grid_ref = camera.normalized_grid()
        self.height, self.width = grid.shape[:2]
        self.x64 = np.ascontiguousarray(grid[..., 0])
        self.y64 = np.ascontiguousarray(grid[..., 1])
        self.x32 = self.x64.astype(np.float32)
        self.y32 = self.y64.astype(np.float32)
        # culling: the range of x over each column and of y over each row (exact for distorted grids)
        self.col_min, self.col_max = self.x64.min(axis=0), self.x64.max(axis=0)
        self.row_min, self.row_max = self.y64.min(axis=1), self.y64.max(axis=1)
        # footprint term: log2(sqrt(|d|) sqrt(A_px)), A_px = |det d(x, y)/d(u, v)| (pixel area, normalised units)
        dx_du = np.gradient(self.x64, axis=1)
        dx_dv = np.gradient(self.x64, axis=0)
        dy_du = np.gradient(self.y64, axis=1)
        dy_dv = np.gradient(self.y64, axis=0)
        area = np.abs(dx_du * dy_dv - dx_dv * dy_du)
        norm_d = np.sqrt(self.x64**2 + self.y64**2 + 1.0)
        self.footprint64 = 0.5 * np.log2(norm_d) + 0.5 * np.log2(np.maximum(area, 1e-300))
        self.footprint32 = self.footprint64.astype(np.float32)


def _level_of_detail(tables: _CameraTables, w: np.ndarray, dtype: type) -> np.ndarray:
    """Return the mip-map level per pixel, ``lod = max(footprint - 2 log2(lambda W), 0)``, in ``dtype``."""
    footprint = tables.footprint32 if dtype == np.float32 else tables.footprint64
    return np.maximum(footprint - dtype(2.0) * np.log2(w), dtype(0.0))


# ============================================================================================== the scene
class Scene:
    """A set of textured planes with a ray-casting renderer.

    Args:
        planes: the :class:`TexturedPlane` s (kept as a tuple; at most 65535).
        background: intensity in [0, 1] of pixels that hit nothing.
        lod_bias: added to every level of detail (> 0 blurs more, < 0 sharpens and may alias).

    The z-buffer key keeps ``bit_length(P)`` bits for the plane number, so two surfaces whose depths differ by
    less than ~2^(bit_length(P) - 23) relative (1e-5 for 40 planes) may be resolved in either order.

    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> wall = TexturedPlane([-1.0, -1.0, 2.0], [2.0, 0, 0], [0, 2.0, 0], np.full((8, 8), 0.25, np.float32))
    >>> scene = Scene([wall])
    >>> camera = PinholeRadtan(fx=50.0, fy=50.0, cx=15.5, cy=11.5, width=32, height=24)
    >>> result = scene.render(camera, np.eye(3), np.zeros(3))
    >>> float(result.depth[12, 16]), round(float(result.intensity[12, 16]), 3), int(result.plane_index[0, 0])
    (2.0, 0.25, 0)
    """

    def __init__(self, planes: Sequence[TexturedPlane], background: float = 0.5, lod_bias: float = 0.0) -> None:
        planes = tuple(planes)
        if not planes:
            raise ValueError("planes must contain at least one TexturedPlane; got an empty sequence")
        for i, plane in enumerate(planes):
            if not isinstance(plane, TexturedPlane):
                raise ValueError(f"planes[{i}] must be a TexturedPlane; got {type(plane).__name__}")
        if len(planes) > 65535:
            raise ValueError(f"planes must hold at most 65535 planes; got {len(planes)}")
        if not (np.isfinite(background) and 0.0 <= background <= 1.0):
            raise ValueError(f"background must be an intensity in [0, 1]; got {background!r}")
        if not np.isfinite(lod_bias):
            raise ValueError(f"lod_bias must be finite; got {lod_bias!r}")
        self.planes: tuple[TexturedPlane, ...] = planes
        self.background = float(background)
        self.lod_bias = float(lod_bias)
        self._origins = np.stack([p.origin_G for p in planes])
        self._axes_u = np.stack([p.axis_u_G for p in planes])
        self._axes_v = np.stack([p.axis_v_G for p in planes])
        self._two_sided = np.array([p.two_sided for p in planes])
        self._spans = np.array([p.texel_spans for p in planes])  # (P, 2)
        self._log2_texel = np.log2(np.array([p.texel_size_m for p in planes]))
        self._areas = np.array([p.area_m2 for p in planes])
        self._index_bits = max(1, len(planes).bit_length())
        self._atlas = _TextureAtlas(planes, self.background)
        self._camera_tables: dict[int, _CameraTables] = {}
        self._scaled_cameras: dict[tuple[int, int], tuple[Any, Any]] = {}

    def __repr__(self) -> str:
        return f"Scene({len(self.planes)} planes, background={self.background}, lod_bias={self.lod_bias})"

    # ------------------------------------------------------------------------------------------ helpers
    def _tables(self, camera: Any) -> _CameraTables:
        """Return the cached per-camera tables (keyed by the identity of the camera's normalised grid)."""
        grid = camera.normalized_grid()
        tables = self._camera_tables.get(id(grid))
        if tables is None or tables.grid_ref is not grid:
            if len(self._camera_tables) > 4:
                self._camera_tables.clear()
            tables = _CameraTables(camera)
            self._camera_tables[id(grid)] = tables
        return tables

    def _planes_in_camera(self, R_CtoG: np.ndarray, p_CinG: np.ndarray) -> dict[str, np.ndarray]:
        """Return per-plane camera-frame quantities: the forms W, S, T (P, 3), validity, distance to the plane."""
        # v_C = R_GtoC v_G = R_CtoG^T v_G  ->  row vectors: v_C^T = v_G^T R_CtoG
        o_C = (self._origins - p_CinG) @ R_CtoG
        u_C = self._axes_u @ R_CtoG
        v_C = self._axes_v @ R_CtoG
        n_C = cross3(u_C, v_C)
        h = np.einsum("ij,ij->i", n_C, o_C)  # h = n . o
        n_norm = np.linalg.norm(n_C, axis=1)
        usable = np.abs(h) > 1e-12 * n_norm * (1.0 + np.linalg.norm(o_C, axis=1))  # camera not in the plane
        usable &= self._two_sided | (h > 0)  # single-sided planes: only from the front (h > 0)
        safe_h = np.where(usable, h, 1.0)[:, None]
        forms = np.stack([n_C / safe_h, cross3(v_C, o_C) / safe_h, cross3(o_C, u_C) / safe_h], axis=1)
        return {"forms": forms, "usable": usable, "distance": np.abs(h) / n_norm,
                "corners": np.stack([o_C, o_C + u_C, o_C + u_C + v_C, o_C + v_C], axis=1)}

    @staticmethod
    def _clip_near(polygon: np.ndarray) -> np.ndarray:
        """Return ``polygon`` (K, 3) clipped to z >= _Z_NEAR (Sutherland-Hodgman), possibly empty."""
        out = []
        count = len(polygon)
        for i in range(count):
            a, b = polygon[i], polygon[(i + 1) % count]
            a_in, b_in = a[2] >= _Z_NEAR, b[2] >= _Z_NEAR
            if a_in:
                out.append(a)
            if a_in != b_in:
                out.append(a + (_Z_NEAR - a[2]) / (b[2] - a[2]) * (b - a))
        return np.array(out).reshape(-1, 3)

    def _pixel_boxes(self, tables: _CameraTables, frame: dict[str, np.ndarray]) -> list[tuple[int, int, int, int, int]]:
        """Return (plane, r0, r1, c0, c1) for every plane that may be visible, with its pixel rectangle."""
        corners = frame["corners"]
        z = corners[..., 2]
        candidate = frame["usable"] & (z.max(axis=1) > _Z_NEAR)
        indices = np.flatnonzero(candidate)
        if indices.size == 0:
            return []
        # normalised-coordinate bounding box of each plane (corners behind the near plane clipped first)
        corners_in = corners[indices]
        z_in = np.maximum(corners_in[..., 2:3], _Z_NEAR)
        xy = corners_in[..., :2] / z_in
        lo, hi = xy.min(axis=1), xy.max(axis=1)
        for j in np.flatnonzero(z[indices].min(axis=1) < _Z_NEAR):  # few planes cross the camera plane
            clipped = self._clip_near(corners_in[j])
            xy_clipped = clipped[:, :2] / clipped[:, 2:3]
            lo[j], hi[j] = xy_clipped.min(axis=0), xy_clipped.max(axis=0)
        rows = (tables.row_max[None, :] >= lo[:, 1:2]) & (tables.row_min[None, :] <= hi[:, 1:2])
        cols = (tables.col_max[None, :] >= lo[:, 0:1]) & (tables.col_min[None, :] <= hi[:, 0:1])
        has = rows.any(axis=1) & cols.any(axis=1)
        r0 = rows.argmax(axis=1)
        r1 = rows.shape[1] - rows[:, ::-1].argmax(axis=1)
        c0 = cols.argmax(axis=1)
        c1 = cols.shape[1] - cols[:, ::-1].argmax(axis=1)
        return [(int(k), int(a), int(b), int(c), int(d))
                for k, a, b, c, d, ok in zip(indices, r0, r1, c0, c1, has) if ok]

    def _visibility(self, tables: _CameraTables, frame: dict[str, np.ndarray]) -> np.ndarray:
        """Return the (H, W) int32 slot of the nearest plane per pixel (0 = nothing, k + 1 = plane k)."""
        keys = np.zeros((tables.height, tables.width), dtype=np.int32)
        clear = np.int32(~((1 << self._index_bits) - 1))
        forms = frame["forms"]
        for k, r0, r1, c0, c1 in self._pixel_boxes(tables, frame):
            x = tables.x32[r0:r1, c0:c1]
            y = tables.y32[r0:r1, c0:c1]
            (wa, wb, wc), (sa, sb, sc), (ta, tb, tc) = forms[k].tolist()
            w = x * wa  # W = 1/z = a x + b y + c
            w += y * wb
            w += wc
            s = x * sa  # S = s W
            s += y * sb
            s += sc
            t = x * ta  # T = t W
            t += y * tb
            t += tc
            edge = np.minimum(s, t)  # inside iff min(S, W - S, T, W - T) >= 0
            np.minimum(edge, w - s, out=edge)
            np.minimum(edge, w - t, out=edge)
            key = np.copysign(w, edge).view(np.int32)  # negative (never wins) outside the parallelogram
            key &= clear
            key |= np.int32(k + 1)
            view = keys[r0:r1, c0:c1]
            np.maximum(view, key, out=view)  # z-buffer: keep the largest 1/z
        return keys & np.int32((1 << self._index_bits) - 1)

    def _shade(self, tables: _CameraTables, frame: dict[str, np.ndarray], slot: np.ndarray, dtype: type,
               sample: bool = True) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """Return (intensity, W = 1/z, slot) for per-pixel slots (0 = background) in ``dtype`` arithmetic.

        ``sample=False`` skips the texture lookup (the costly part) and returns None for the intensity; W and the
        slots are the same numbers.

        Per slot the forms are pre-scaled so that one gather gives texel coordinates and the level of detail:
        the S and T rows by the texel spans (``col = span_u S / W``), and all three rows by
        ``lambda = 2^(-c / 2)`` with ``c = -log2(h^ texel) + bias``, so that ``-2 log2(lambda W) = -2 log2 W + c``
        (the ratio S / W is unchanged).
        """
        x, y = (tables.x32, tables.y32) if dtype == np.float32 else (tables.x64, tables.y64)
        columns, scale, spans = self._shade_tables(frame, dtype)
        slot = slot.astype(np.int64)
        coef = [np.take(columns[i], slot) for i in range(9)]
        w = coef[0] * x + coef[1] * y + coef[2]  # lambda W
        col_w = coef[3] * x + coef[4] * y + coef[5]  # lambda span_u S
        row_w = coef[6] * x + coef[7] * y + coef[8]  # lambda span_v T
        miss = w <= 0  # numerically degenerate hits (ray parallel to the plane): treat as background
        if miss.any():
            slot = np.where(miss, 0, slot)
            w, col_w, row_w = np.where(miss, 1, w), np.where(miss, 0, col_w), np.where(miss, 0, row_w)
        if not sample:
            return None, w / np.take(scale, slot), slot
        inv_w = dtype(1.0) / w
        col = np.minimum(np.maximum(col_w * inv_w, dtype(0.0)), np.take(spans[:, 0], slot))  # col = span_u S / W
        row = np.minimum(np.maximum(row_w * inv_w, dtype(0.0)), np.take(spans[:, 1], slot))  # row = span_v T / W
        intensity = self._atlas.sample(slot, col, row, _level_of_detail(tables, w, dtype), dtype)
        return intensity, w / np.take(scale, slot), slot

    def _shade_tables(self, frame: dict[str, np.ndarray], dtype: type) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the per-slot shading tables in ``dtype``: pre-scaled forms (9, n_slots), lambda, texel spans."""
        n_slots = len(self.planes) + 1
        forms = np.zeros((n_slots, 3, 3))
        forms[0, 0, 2] = 1.0  # background: W = 1, S = T = 0 -> texel (0, 0) of the 1 x 1 background texture
        forms[1:] = frame["forms"]
        forms[1:, 1] *= self._spans[:, 0:1]  # S * span_u
        forms[1:, 2] *= self._spans[:, 1:2]  # T * span_v
        lod_const = np.zeros(n_slots)
        with np.errstate(divide="ignore"):
            lod_const[1:] = -np.log2(np.maximum(frame["distance"], 1e-300)) - self._log2_texel + self.lod_bias
        lod_const[~np.isfinite(lod_const)] = 0.0
        scale = np.exp2(-0.5 * lod_const)  # lambda
        forms *= scale[:, None, None]
        columns = forms.reshape(n_slots, 9).T.astype(dtype)  # (9, n_slots) contiguous rows for np.take
        spans = np.concatenate([[[0.0, 0.0]], self._spans]).astype(dtype)
        return columns, scale.astype(dtype), spans

    def _render_intensity_compiled(self, tables: _CameraTables, frame: dict[str, np.ndarray]) -> np.ndarray:
        """Return the float32 intensity of :meth:`_visibility` + :meth:`_shade` from the Numba kernels (same bits)."""
        from evio_lib.sim import render_kernels

        boxes = np.array(self._pixel_boxes(tables, frame), dtype=np.int64).reshape(-1, 5)
        forms = frame["forms"].reshape(len(self.planes), 9).astype(np.float32)
        slot = render_kernels.visible_slots(tables.x32, tables.y32, boxes, forms, self._index_bits)
        columns, _, spans = self._shade_tables(frame, np.float32)
        w, col, row, slot = render_kernels.shade_slots(tables.x32, tables.y32, slot, np.ascontiguousarray(columns),
                                                       spans)
        return self._atlas.sample_fast(slot, col, row, _level_of_detail(tables, w, np.float32))  # NumPy's log2

    # ------------------------------------------------------------------------------------------ public API
    def render_intensity(self, camera: Any, R_CtoG: np.ndarray, p_CinG: np.ndarray, supersample: int = 1
                         ) -> np.ndarray:
        """Return the (H, W) float32 linear intensity image seen by ``camera`` at pose (R_CtoG, p_CinG).

        The fast path (float32) used to simulate events at ~1 kHz; same visibility as :meth:`render`.
        Each pixel samples the scene at its centre (textures are anti-aliased by the mip-map, occlusion edges
        are not); ``supersample = k`` renders ``camera.scaled(k)`` and averages k x k blocks, which integrates
        over the pixel area (edges too) at k^2 the cost.

        Args:
            camera: a camera with ``normalized_grid()`` (e.g. ``PinholeRadtan``); frame C: x right, y down, z forward.
            R_CtoG: (3, 3) rotation taking camera-frame vectors into the world frame G.
            p_CinG: (3,) camera centre in G, metres.
            supersample: samples per pixel along each axis (>= 1; > 1 needs ``camera.scaled``).
        """
        R = _rotation(R_CtoG, "R_CtoG")
        p = _vector3(p_CinG, "p_CinG")
        if isinstance(supersample, (bool, np.bool_)) or not isinstance(supersample, (int, np.integer)) \
                or supersample < 1:
            raise ValueError(f"supersample must be an int >= 1; got {supersample!r}")
        factor = int(supersample)
        if factor > 1:
            key = (id(camera), factor)
            cached = self._scaled_cameras.get(key)
            if cached is None or cached[0] is not camera:
                if not hasattr(camera, "scaled"):
                    raise ValueError("supersample > 1 needs a camera with a scaled(factor) method (PinholeRadtan)")
                cached = (camera, camera.scaled(factor))
                self._scaled_cameras[key] = cached
            fine_camera = cached[1]
        else:
            fine_camera = camera
        tables = self._tables(fine_camera)
        frame = self._planes_in_camera(R, p)
        if renderer_backend() == "numba":
            image = self._render_intensity_compiled(tables, frame)
        else:
            slot = self._visibility(tables, frame)
            image = self._shade(tables, frame, slot, np.float32)[0]
        if factor > 1:  # fine pixels k u ... k u + k - 1 make up coarse pixel u
            height, width = tables.height // factor, tables.width // factor
            image = image.reshape(height, factor, width, factor).mean(axis=(1, 3), dtype=np.float32)
        return image

    def render(self, camera: Any, R_CtoG: np.ndarray, p_CinG: np.ndarray) -> RenderResult:
        """Return intensity, z-depth, hit points in G and plane index for every pixel (see :class:`RenderResult`).

        Geometry is evaluated in float64 from the exact per-pixel rays, so ``points_G`` re-project onto their
        pixel centres; the intensity equals :meth:`render_intensity` up to float32 rounding.

        Args:
            camera: a camera with ``normalized_grid()`` (e.g. ``PinholeRadtan``).
            R_CtoG: (3, 3) rotation from the camera frame C to the world frame G.
            p_CinG: (3,) camera centre in G, metres.
        """
        intensity, depth, points_G, slot = self._cast(camera, R_CtoG, p_CinG, sample=True)
        return RenderResult(
            intensity=intensity.astype(np.float32),
            depth=depth.astype(np.float32),
            points_G=points_G,
            plane_index=(slot - 1).astype(np.int32),
        )

    def hit_points(self, camera: Any, R_CtoG: np.ndarray, p_CinG: np.ndarray) -> np.ndarray:
        """Return the (H, W, 3) float64 hit points in G of :meth:`render` (NaN where nothing is hit), same numbers.

        The textures are not sampled, so it costs less than :meth:`render`
        (docs/results/speed.md#small-costs-behind-the-codes-choices); the motion-blur planner of the APS frames needs
        only the geometry.

        Args:
            camera, R_CtoG, p_CinG: as in :meth:`render`.
        """
        return self._cast(camera, R_CtoG, p_CinG, sample=False)[2]

    def _cast(self, camera: Any, R_CtoG: np.ndarray, p_CinG: np.ndarray, sample: bool
              ) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """Return (intensity or None, depth, points_G, slot) in float64 from the exact per-pixel rays."""
        R = _rotation(R_CtoG, "R_CtoG")
        p = _vector3(p_CinG, "p_CinG")
        tables = self._tables(camera)
        frame = self._planes_in_camera(R, p)
        slot = self._visibility(tables, frame)
        intensity, w, slot = self._shade(tables, frame, slot, np.float64, sample=sample)
        hit = slot > 0
        depth = np.where(hit, 1.0 / w, np.inf)  # z = 1 / W
        rays_C = np.stack([tables.x64, tables.y64, np.ones_like(tables.x64)], axis=-1)
        points_G = p + depth[..., None] * (rays_C @ R.T)  # X_G = p + z R_CtoG [x, y, 1]
        points_G[~hit] = np.nan
        return intensity, depth, points_G, slot

    def sample_texture(self, plane_index: np.ndarray, s: np.ndarray, t: np.ndarray, lod: np.ndarray | float = 0.0
                       ) -> np.ndarray:
        """Return (N,) float64 trilinear texture samples of planes at plane coordinates (s, t).

        Args:
            plane_index: (N,) ints in [0, P).
            s, t: (N,) plane coordinates in [0, 1] (clipped); texel ``(s (r_u W_t - 1), t (r_v H_t - 1))``.
            lod: level of detail (scalar or (N,)); 0 = full resolution, 1 = half, ... (clipped to >= 0).
        """
        index = np.asarray(plane_index)
        if index.ndim != 1 or not np.issubdtype(index.dtype, np.integer):
            raise ValueError(f"plane_index must be a (N,) integer array; got shape {index.shape}, dtype {index.dtype}")
        if index.size and (index.min() < 0 or index.max() >= len(self.planes)):
            raise ValueError(
                f"plane_index must lie in [0, {len(self.planes)}); got range [{index.min()}, {index.max()}]"
            )
        s_arr = np.asarray(s, dtype=np.float64)
        t_arr = np.asarray(t, dtype=np.float64)
        if s_arr.shape != index.shape or t_arr.shape != index.shape:
            raise ValueError(f"s and t must have shape {index.shape}; got {s_arr.shape} and {t_arr.shape}")
        lod_arr = np.broadcast_to(np.maximum(np.asarray(lod, dtype=np.float64), 0.0), index.shape)
        slot = index.astype(np.int64) + 1
        spans = self._spans[index]
        col = np.clip(s_arr, 0.0, 1.0) * spans[:, 0]
        row = np.clip(t_arr, 0.0, 1.0) * spans[:, 1]
        return self._atlas.sample(slot, col, row, np.ascontiguousarray(lod_arr), np.float64)

    def intersect(self, origins_G: np.ndarray, directions_G: np.ndarray, chunk: int = 8192
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the nearest hit of each ray: (distance (N,), plane_index (N,), s (N,), t (N,)).

        Ray ``X(l) = origin + l d / |d|``, ``l > 0``; Cramer's rule on ``o + l d = O + s U + t V`` with
        ``r = o - O``, ``n = U x V``: ``l = -(r . n) / (d . n)``, ``s = r . (V x d) / (d . n)``,
        ``t = d . (U x r) / (d . n)``. Single-sided planes are hit only from their front (``d . n > 0``).
        Misses give distance inf, plane_index -1, s = t = NaN.

        Args:
            origins_G: (N, 3) ray origins in G, metres.
            directions_G: (N, 3) ray directions in G (normalised internally, must be non-zero).
            chunk: rays processed at once (bounds memory to about chunk x planes).

        >>> plane = TexturedPlane([0.0, 0.0, 5.0], [1.0, 0, 0], [0, 1.0, 0], np.zeros((2, 2), np.float32))
        >>> distance, index, s, t = Scene([plane]).intersect([[0.25, 0.5, 0.0]], [[0.0, 0.0, 2.0]])
        >>> distance.tolist(), index.tolist(), s.tolist(), t.tolist()
        ([5.0], [0], [0.25], [0.5])
        """
        origins = _points(origins_G, "origins_G")
        directions = _points(directions_G, "directions_G")
        if origins.shape != directions.shape:
            raise ValueError(f"origins_G and directions_G must have the same shape (N, 3); got {origins.shape} and "
                             f"{directions.shape}")
        norms = np.linalg.norm(directions, axis=1)
        if np.any(norms == 0):
            raise ValueError(f"directions_G must be non-zero; row {int(np.argmax(norms == 0))} is zero")
        directions = directions / norms[:, None]
        n_rays = origins.shape[0]
        distance = np.full(n_rays, np.inf)
        index = np.full(n_rays, -1, dtype=np.int64)
        s_out = np.full(n_rays, np.nan)
        t_out = np.full(n_rays, np.nan)
        normals = np.cross(self._axes_u, self._axes_v)  # (P, 3)
        for start in range(0, n_rays, max(1, int(chunk))):
            o = origins[start : start + chunk, None, :]  # (n, 1, 3)
            d = directions[start : start + chunk, None, :]
            r = o - self._origins[None]  # (n, P, 3)
            d_n = directions[start : start + chunk] @ normals.T  # d . n, (n, P)
            with np.errstate(divide="ignore", invalid="ignore"):
                lam = -np.einsum("ijk,jk->ij", r, normals) / d_n  # l = -(r . n) / (d . n)
                s = np.einsum("ijk,ijk->ij", r, np.cross(self._axes_v[None], d)) / d_n  # s = r . (V x d) / (d . n)
                t = np.einsum("ijk,ijk->ij", d, np.cross(self._axes_u[None], r)) / d_n  # t = d . (U x r) / (d . n)
            valid = (d_n != 0) & (lam > 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
            valid &= self._two_sided[None] | (d_n > 0)
            lam = np.where(valid, lam, np.inf)
            best = np.argmin(lam, axis=1)
            rows = np.arange(lam.shape[0])
            best_lam = lam[rows, best]
            hit = np.isfinite(best_lam)
            sl = slice(start, start + lam.shape[0])
            distance[sl] = best_lam
            index[sl] = np.where(hit, best, -1)
            s_out[sl] = np.where(hit, s[rows, best], np.nan)
            t_out[sl] = np.where(hit, t[rows, best], np.nan)
        return distance, index, s_out, t_out

    def sample_landmarks(self, n: int, rng: np.random.Generator, camera: Any = None, R_CtoG: np.ndarray | None = None,
                         p_CinG: np.ndarray | None = None) -> np.ndarray:
        """Return (n, 3) random points on the scene's surfaces, in G.

        Without a pose: uniform over the total surface area. With a camera and a pose: points visible from it,
        i.e. the first hit of the ray through a uniformly random (continuous) pixel position.

        Args:
            n: number of points (>= 0).
            rng: ``numpy.random.Generator``.
            camera: optional camera with ``unproject``, ``width`` and ``height`` (e.g. ``PinholeRadtan``).
            R_CtoG, p_CinG: the camera pose (both given with ``camera``, or none of the three).
        """
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"n must be a non-negative int; got {n!r}")
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
        given = [camera is not None, R_CtoG is not None, p_CinG is not None]
        if any(given) and not all(given):
            raise ValueError("camera, R_CtoG and p_CinG must be given together (or none of them)")
        if not any(given):
            plane = rng.choice(len(self.planes), size=n, p=self._areas / self._areas.sum())
            s, t = rng.random(n), rng.random(n)
            return self._origins[plane] + s[:, None] * self._axes_u[plane] + t[:, None] * self._axes_v[plane]
        R = _rotation(R_CtoG, "R_CtoG")
        p = _vector3(p_CinG, "p_CinG")
        found: list[np.ndarray] = []
        total = 0
        for _ in range(50):
            if total >= n:
                break
            batch = max(2 * (n - total), 16)
            uv = rng.random((batch, 2)) * [camera.width - 1, camera.height - 1]
            xy = camera.unproject(uv)
            rays_G = np.concatenate([xy, np.ones((batch, 1))], axis=1) @ R.T  # d_G = R_CtoG [x, y, 1]
            distance, _, _, _ = self.intersect(np.broadcast_to(p, (batch, 3)), rays_G)
            hit = np.isfinite(distance)
            unit = rays_G[hit] / np.linalg.norm(rays_G[hit], axis=1, keepdims=True)
            found.append(p + distance[hit, None] * unit)
            total += int(hit.sum())
        points = np.concatenate(found, axis=0) if found else np.zeros((0, 3))
        if points.shape[0] < n:
            raise ValueError(f"the camera sees too little of the scene: found {points.shape[0]} of {n} landmarks")
        return points[:n]


# ============================================================================================== presets
def _face(centre: np.ndarray, toward_viewer: np.ndarray, down: np.ndarray, width: float, height: float,
          texture: np.ndarray, name: str, repeat: tuple[float, float] = (1.0, 1.0)) -> TexturedPlane:
    """Return a single-sided rectangle centred at ``centre``, seen from the side ``toward_viewer`` points to.

    The viewer looks along ``-toward_viewer``; image-down is ``down``; image-right = down x forward.
    """
    forward = -np.asarray(toward_viewer, dtype=np.float64)
    down = np.asarray(down, dtype=np.float64)
    right = np.cross(down, forward)  # x = y x z for a camera-like frame
    axis_u, axis_v = right * width, down * height
    origin = np.asarray(centre, dtype=np.float64) - 0.5 * axis_u - 0.5 * axis_v
    return TexturedPlane(origin, axis_u, axis_v, texture, name=name, texture_repeat=repeat, two_sided=False)


def _paste(canvas: np.ndarray, picture: np.ndarray, row: int, col: int, frame_value: float) -> None:
    """Paste ``picture`` with a 4-texel frame of ``frame_value`` into ``canvas`` at (row, col) (in place)."""
    height, width = picture.shape
    canvas[row - 4 : row + height + 4, col - 4 : col + width + 4] = frame_value
    canvas[row : row + height, col : col + width] = picture


def _box_faces(centre_xy: np.ndarray, size: np.ndarray, yaw: float, z0: float, label: str,
               texture: Any) -> list[TexturedPlane]:
    """Return the top and four sides of a box standing at height ``z0``, rotated by ``yaw`` about z, each face with
    ``texture()`` (called for the top, then for each side, in that order)."""
    ez = np.array([0.0, 0.0, 1.0])
    bx = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    by = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    width, depth, height = size
    middle = np.array([centre_xy[0], centre_xy[1], z0 + 0.5 * height])
    faces = [_face(middle + 0.5 * height * ez, ez, -by, width, depth, texture(), f"{label} top")]
    for axis, half, side_width in ((by, depth, width), (-by, depth, width), (bx, width, depth), (-bx, width, depth)):
        faces.append(_face(middle + 0.5 * half * axis, axis, -ez, side_width, height, texture(), f"{label} side"))
    return faces


def indoor_room(seed: int = 0) -> Scene:
    """Return a textured room (x, y in [-4, 4] m, z in [0, 3] m) with 5-8 textured boxes in front of the camera.

    Floor (tiles), ceiling (panels), four walls (brick with framed photographs) and boxes of 0.3-1 m standing
    on the floor at x in [-1.5, 1.5], y in [1.5, 3.5] (some stacked), each box a set of single-sided faces.
    Textures are rescaled to the albedo range [0.05, 0.95]. The intended camera moves near (0, 0, 1.4) m
    looking toward +y (like the "boxes" sequence of the Event-Camera Dataset, thesis §3.4.1); a slight downward
    pitch (10-20 degrees) puts the boxes in the middle of the image.

    Args:
        seed: seed of every random choice (layout, textures).

    >>> scene = indoor_room(seed=0)
    >>> 5 * 5 + 6 <= len(scene.planes) <= 8 * 5 + 6
    True
    """
    rng = np.random.default_rng(seed)
    ex, ey, ez = np.eye(3)
    photos = {name: load_texture(name, size=(256, 256)) for name in
              ("camera", "astronaut", "coffee", "chelsea", "rocket", "coins", "text", "page", "motorcycle", "gravel",
               "grass", "brick", "ihc")}

    def albedo(texture: np.ndarray) -> np.ndarray:
        return rescale_contrast(texture, 0.05, 0.95)

    planes: list[TexturedPlane] = []
    floor = albedo(procedural_texture("tiles", (512, 512), rng, scale_px=64))
    planes.append(_face([0.0, 0.0, 0.0], ez, -ey, 8.0, 8.0, floor, "floor", repeat=(2.0, 2.0)))
    ceiling = albedo(procedural_texture("tiles", (512, 512), rng, scale_px=128) * 0.6 + 0.4)
    planes.append(_face([0.0, 0.0, 3.0], -ez, ey, 8.0, 8.0, ceiling, "ceiling", repeat=(2.0, 2.0)))
    brick = np.ascontiguousarray(np.rot90(photos["brick"]))  # the photograph's courses run vertically
    walls = [("wall +y", [0.0, 4.0, 1.5], -ey), ("wall -y", [0.0, -4.0, 1.5], ey),
             ("wall +x", [4.0, 0.0, 1.5], -ex), ("wall -x", [-4.0, 0.0, 1.5], ex)]
    names = sorted(photos)
    for name, centre, toward in walls:
        canvas = np.tile(brick, (3, 8))[:384, :1024].copy()  # 8 m x 3 m at ~7.8 mm per texel
        canvas *= 0.6 + 0.4 * procedural_texture("value_noise", canvas.shape, rng, scale_px=96)
        for _ in range(int(rng.integers(3, 6))):  # framed photographs
            picture = photos[names[int(rng.integers(len(names)))]]
            side = int(rng.integers(80, 180))
            picture = picture[:: max(1, 256 // side), :: max(1, 256 // side)][:side, :side]
            row, col = int(rng.integers(20, 384 - side - 20)), int(rng.integers(20, 1024 - side - 20))
            _paste(canvas, picture, row, col, float(rng.choice([0.02, 0.98])))
        planes.append(_face(centre, toward, -ez, 8.0, 3.0, albedo(np.clip(canvas, 0, 1)), name))

    # boxes: rejection sampling of non-overlapping footprints (bounding circles), then a few stacked boxes
    kinds = ("rectangles", "blobs", "checkerboard", "stripes", "fractal_noise", "tiles")
    face_count = [0]

    def face_texture() -> np.ndarray:
        face_count[0] += 1
        if rng.random() < 0.5:
            scale = float(rng.uniform(12, 40))
            return albedo(procedural_texture(kinds[int(rng.integers(len(kinds)))], (256, 256), rng, scale_px=scale))
        photo = photos[names[int(rng.integers(len(names)))]]
        return albedo(np.ascontiguousarray(np.rot90(photo, int(rng.integers(4)))))

    def add_box(centre_xy: np.ndarray, size: np.ndarray, yaw: float, z0: float, label: str) -> None:
        planes.extend(_box_faces(centre_xy, size, yaw, z0, label, face_texture))

    n_boxes = int(rng.integers(5, 9))
    n_stacked = int(rng.integers(1, 3))
    n_floor = n_boxes - n_stacked
    floor_boxes: list[tuple[np.ndarray, np.ndarray, float]] = []
    for _ in range(2000):
        if len(floor_boxes) == n_floor:
            break
        size = np.array([rng.uniform(0.35, 0.9), rng.uniform(0.35, 0.9), rng.uniform(0.3, 1.0)])
        radius = 0.5 * float(np.hypot(size[0], size[1]))
        centre = np.array([rng.uniform(-1.5 + radius, 1.5 - radius), rng.uniform(1.5 + radius, 3.5 - radius)])
        if all(np.linalg.norm(centre - c) > radius + 0.5 * np.hypot(s[0], s[1]) + 0.05 for c, s, _ in floor_boxes):
            floor_boxes.append((centre, size, float(rng.uniform(-0.6, 0.6))))
    for i, (centre, size, yaw) in enumerate(floor_boxes):
        add_box(centre, size, yaw, 0.0, f"box {i}")
    for j, lower in enumerate(rng.choice(len(floor_boxes), size=min(n_stacked, len(floor_boxes)), replace=False)):
        centre, size, yaw = floor_boxes[int(lower)]
        top_size = np.array([size[0] * rng.uniform(0.5, 0.9), size[1] * rng.uniform(0.5, 0.9), rng.uniform(0.2, 0.5)])
        add_box(centre, top_size, yaw + float(rng.uniform(-0.2, 0.2)), float(size[2]), f"box {len(floor_boxes) + j}")
    return Scene(planes, background=0.5)


def photo_room(photos: Sequence[str], seed: int = 0, gamma: float = 2.2) -> Scene:
    """Return a room like :func:`indoor_room` whose every surface is one of ``photos``, in linear light.

    Floor, ceiling, the four walls and 5-8 boxes (x in [-1.2, 1.2] m, y in [1.8, 3.2] m), each face a whole photograph
    of the list resized to the face, so that large smooth regions, dark and bright, fill much of the view. The
    photographs' values V are display-encoded; the scene's intensity is I = V^gamma with V first rescaled to
    [0.05, 0.95], so the scene spans 0.05^2.2 to 0.95^2.2, about 650 to 1 for the default gamma (a renderer in linear
    light; ``gamma=1`` keeps the display values). A held-out recording for the reconstructors: the photographs
    come from a split the networks never trained on, and its light is that of a simulator that decodes its textures.

    Args:
        photos: paths of photographs (e.g. ``list_photos(folder, "val")``), at least one.
        seed: seed of the layout and of which photograph goes where.
        gamma: the display encoding undone, I = V^gamma (> 0).
    """
    import cv2

    from evio_lib.sim.photos import load_photo

    if len(photos) == 0:
        raise ValueError("photo_room needs at least one photograph; got an empty list")
    if not (np.isfinite(gamma) and gamma > 0):
        raise ValueError(f"gamma must be a positive number; got {gamma!r}")
    rng = np.random.default_rng(seed)
    ex, ey, ez = np.eye(3)

    def texture(shape: tuple[int, int]) -> np.ndarray:
        photo = load_photo(photos[int(rng.integers(len(photos)))])
        photo = cv2.resize(photo, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
        return rescale_contrast(photo.astype(np.float64), 0.05, 0.95) ** gamma

    planes = [_face([0.0, 0.0, 0.0], ez, -ey, 8.0, 8.0, texture((512, 512)), "floor"),
              _face([0.0, 0.0, 3.0], -ez, ey, 8.0, 8.0, texture((512, 512)), "ceiling")]
    for name, centre, toward in (("wall +y", [0.0, 4.0, 1.5], -ey), ("wall -y", [0.0, -4.0, 1.5], ey),
                                 ("wall +x", [4.0, 0.0, 1.5], -ex), ("wall -x", [-4.0, 0.0, 1.5], ex)):
        planes.append(_face(centre, toward, -ez, 8.0, 3.0, texture((384, 1024)), name))
    for i in range(int(rng.integers(5, 9))):  # boxes may overlap: the renderer draws the nearest surface
        size = rng.uniform([0.35, 0.35, 0.3], [0.9, 0.9, 1.0])
        centre_xy = np.array([rng.uniform(-1.2, 1.2), rng.uniform(1.8, 3.2)])
        yaw = float(rng.uniform(-0.6, 0.6))
        planes.extend(_box_faces(centre_xy, size, yaw, 0.0, f"box {i}", lambda: texture((256, 256))))
    return Scene(planes, background=0.5)


def aerial_ground(seed: int = 0, extent_m: float = 3000.0) -> Scene:
    """Return flat terrain: the square z = 0, x, y in [-extent/2, extent/2] m, with the aerial terrain texture.

    The texture has up to 4096 x 4096 texels (0.73 m per texel for the default 3 km), so a 240 x 180 camera
    at 250 m altitude (~1.2 m per pixel) sees texture everywhere. A flight at 20 m/s for 60 s starting above the
    origin covers 1.2 km and stays inside the plane (with its ~300 m wide field of view). Seen from above only.
    Stands in for the Camp Atterbury flight test (thesis §3.4.2).

    Args:
        seed: seed of the terrain texture.
        extent_m: side of the square in metres (> 0).

    >>> scene = aerial_ground(seed=0, extent_m=200.0)
    >>> len(scene.planes), scene.planes[0].name
    (1, 'ground')
    """
    if not (isinstance(extent_m, (int, float, np.floating)) and np.isfinite(extent_m) and extent_m > 0):
        raise ValueError(f"extent_m must be a positive finite number of metres; got {extent_m!r}")
    size_px = int(min(4096, max(64, 2 ** int(np.ceil(np.log2(extent_m / 0.75))))))
    texture = aerial_terrain_texture(size_px, seed=seed, metres_per_pixel=float(extent_m) / size_px)
    ex, ey, ez = np.eye(3)
    ground = _face(np.zeros(3), ez, -ey, float(extent_m), float(extent_m), texture, "ground")
    return Scene([ground], background=0.5)


PRESETS = {"boxes_like": indoor_room, "aerial_like": aerial_ground}


def scene_from_preset(name: str, seed: int = 0) -> Scene:
    """Return the scene of a named preset: ``'boxes_like'`` (:func:`indoor_room`), ``'aerial_like'`` (:func:`aerial_ground`).

    >>> scene_from_preset("nope")
    Traceback (most recent call last):
    ...
    ValueError: name must be one of ['aerial_like', 'boxes_like']; got 'nope'
    """
    if name not in PRESETS:
        raise ValueError(f"name must be one of {sorted(PRESETS)}; got {name!r}")
    return PRESETS[name](seed=seed)
