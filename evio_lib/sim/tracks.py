"""Perfect-data-association feature tracks: simulated landmarks projected into the moving camera, like a front end.

The MSCKF (thesis §3.3) consumes, per image, a list of (track id, undistorted normalised coordinates). This module
produces exactly that from the simulator's ground truth, with no matching errors, so the back end can be tested
alone ("perfect-data-association runs").

At each frame time t_k the camera pose follows from the IMU pose and the extrinsics (thesis Eqs. 27-28)::

    R_CtoG = R_ItoG R_CtoI,   p_CinG = p_IinG + R_ItoG p_CinI
    p_C = R_CtoG^T (p_G - p_CinG)                        (landmark in the camera frame)
    (x, y) = (X / Z, Y / Z),  uv = distort + K           (thesis Eq. 1 and the radtan model)

A landmark is *visible* when Z >= min_depth, its pixel lies at least ``border_px`` inside the image and, with an
occluding scene, the first surface hit by the ray from the camera centre towards it is the landmark itself.

Track management imitates a grid-based front end (the thesis's MSCKF keeps the strongest features per image
region, at most 60 new ones per image, §4.5): existing tracks are kept while their landmark stays visible; when
fewer than ``features_per_frame`` remain, new landmarks are chosen among the visible, untracked candidates,
emptiest grid cell first; a track ends for good when its landmark leaves the view (or reaches
``max_track_length``); track ids are increasing integers that are never reused. Observations get Gaussian pixel
noise and are then unprojected to undistorted normalised coordinates, the filter's input.

Landmarks come either from a fixed (L, 3) array or from a scene (anything with ``intersect(origins_G,
directions_G) -> (distance, ...)``, e.g. :class:`evio_lib.sim.scene.Scene`): then new landmarks are created on demand
where rays through random pixels first hit the scene, so there are always enough candidates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "FeatureFrame",
    "SimpleGeometry",
    "simple_geometry",
    "simulate_feature_tracks",
    "landmarks_for_preset",
    "track_lengths",
]

_OCCLUSION_REL_TOL = 1e-6  # a surface hit closer than (1 - tol) * distance - abs tol occludes the landmark
_OCCLUSION_ABS_TOL = 1e-6  # metres
_CANDIDATES_PER_NEEDED = 8  # scene mode: random pixels ray-cast per missing feature


@dataclass(frozen=True, eq=False)
class FeatureFrame:
    """Feature observations of one image (K tracked features).

    Attributes:
        t: image time, s.
        ids: (K,) int64 track ids (increasing, never reused across the sequence).
        xy: (K, 2) float64 undistorted normalised coordinates (X/Z, Y/Z) of the noisy observations (filter input).
        uv: (K, 2) float64 noisy distorted pixel coordinates (x = column, y = row).
        landmarks_G: (K, 3) float64 true landmark positions in G, metres (ground truth, for tests and triangulation).
    """

    t: float
    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    uv: NDArray[np.float64]
    landmarks_G: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.ids.shape[0])


# ==================================================================================================== geometry
class SimpleGeometry:
    """Analytic stand-in for a preset scene: axis-aligned boxes seen from inside (a room) or outside, and planes z = c.

    ``intersect(origins_G, directions_G)`` has the same form as ``Scene.intersect``: (distance (N,), index (N,),
    s (N,), t (N,)) with distance inf / index -1 for misses (s and t are always NaN here).

    Args:
        rooms: (R, 2, 3) boxes [min corner, max corner] hit from the inside (the ray leaves through a wall).
        boxes: (B, 2, 3) solid boxes hit from the outside (slab method).
        grounds: (G, 5) horizontal rectangles [z, x_min, x_max, y_min, y_max], seen from above.
    """

    def __init__(self, rooms: ArrayLike = (), boxes: ArrayLike = (), grounds: ArrayLike = ()) -> None:
        self.rooms = np.asarray(rooms, dtype=np.float64).reshape(-1, 2, 3)
        self.boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 2, 3)
        self.grounds = np.asarray(grounds, dtype=np.float64).reshape(-1, 5)

    def intersect(self, origins_G: ArrayLike, directions_G: ArrayLike
                  ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Return the nearest hit of each ray: (distance (N,), surface index (N,), NaN (N,), NaN (N,)).

        Slabs: t_i = (b_i - o_i) / d_i per axis; entry = max_i min(t_lo, t_hi), exit = min_i max(t_lo, t_hi).
        A solid box is hit at its entry (if 0 < entry <= exit); a room at its exit. Ground: t = (z - o_z) / d_z.
        """
        o = _points(origins_G, "origins_G")
        d = _points(directions_G, "directions_G")
        if o.shape != d.shape:
            raise ValueError(f"origins_G and directions_G must have the same shape (N, 3); got {o.shape} and {d.shape}")
        norms = np.linalg.norm(d, axis=1)
        if np.any(norms == 0.0):
            raise ValueError(f"directions_G must be non-zero; row {int(np.argmax(norms == 0.0))} is zero")
        d = d / norms[:, None]
        candidates = [np.full(o.shape[0], np.inf)]
        with np.errstate(divide="ignore", invalid="ignore"):
            for lo_hi, inside in ((self.rooms, True), (self.boxes, False)):
                for lo, hi in lo_hi:
                    t_lo, t_hi = (lo - o) / d, (hi - o) / d  # t_i = (b_i - o_i) / d_i
                    entry = np.nanmax(np.minimum(t_lo, t_hi), axis=1)
                    exit_ = np.nanmin(np.maximum(t_lo, t_hi), axis=1)
                    hit = exit_ if inside else entry
                    ok = (entry <= exit_) & (hit > 0)
                    candidates.append(np.where(ok, hit, np.inf))
            for z, x0, x1, y0, y1 in self.grounds:
                lam = (z - o[:, 2]) / d[:, 2]  # t = (z - o_z) / d_z, from above only (d_z < 0)
                p = o + lam[:, None] * d
                ok = (d[:, 2] < 0) & (lam > 0) & (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
                candidates.append(np.where(ok, lam, np.inf))
        stacked = np.stack(candidates, axis=1)
        index = np.argmin(stacked, axis=1)
        distance = stacked[np.arange(o.shape[0]), index]
        hit = np.isfinite(distance)
        nan = np.full(o.shape[0], np.nan)
        return distance, np.where(hit, index - 1, -1).astype(np.int64), nan, nan.copy()


def simple_geometry(name: str) -> SimpleGeometry:
    """Return the analytic geometry of a preset ('boxes_like' | 'aerial_like'), a light stand-in for its scene.

    ``boxes_like``: the room x, y in [-4, 4] m, z in [0, 3] m with four boxes (one stacked) at x in [-1.5, 1.5],
    y in [1.5, 3.5]. ``aerial_like``: the ground z = 0, x, y in [-1500, 1500] m.

    >>> geometry = simple_geometry("aerial_like")
    >>> float(geometry.intersect([[0.0, 0.0, 250.0]], [[0.0, 0.0, -1.0]])[0][0])
    250.0
    """
    if name == "boxes_like":
        boxes = [
            [[-1.3, 1.8, 0.0], [-0.6, 2.5, 0.8]],
            [[-0.4, 2.4, 0.0], [0.4, 3.2, 1.0]],
            [[0.6, 1.7, 0.0], [1.4, 2.4, 0.6]],
            [[0.75, 1.85, 0.6], [1.25, 2.25, 0.9]],
        ]
        return SimpleGeometry(rooms=[[[-4.0, -4.0, 0.0], [4.0, 4.0, 3.0]]], boxes=boxes)
    if name == "aerial_like":
        return SimpleGeometry(grounds=[[0.0, -1500.0, 1500.0, -1500.0, 1500.0]])
    raise ValueError(f"name must be one of ['aerial_like', 'boxes_like']; got {name!r}")


# ==================================================================================================== validation
def _points(value: Any, name: str) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 (N, 3) array, else raise ValueError naming ``name``."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3); got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must contain only finite values; got non-finite entries")
    return array


def _generator(rng: Any) -> np.random.Generator:
    """Return a Generator from a Generator or an integer seed, else raise ValueError."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise ValueError(f"rng must be a numpy.random.Generator or an int seed; got {type(rng).__name__}")


def _positive_int(value: Any, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}; got {value!r}")
    return int(value)


def _nonnegative(value: Any, name: str, strict: bool = False) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    ok = ok and math.isfinite(float(value)) and (float(value) > 0 if strict else float(value) >= 0)
    if not ok:
        raise ValueError(f"{name} must be a finite number {'>' if strict else '>='} 0; got {value!r}")
    return float(value)


# ==================================================================================================== observation
class _Observer:
    """Visibility test and projection of world points for one camera (vectorised over points)."""

    def __init__(self, camera: Any, min_depth: float, border_px: float, occluder: Any | None) -> None:
        self.camera, self.min_depth, self.border, self.occluder = camera, min_depth, border_px, occluder
        # Normalised coordinates beyond those of the image border are rejected before distortion, so that a
        # non-monotonic radtan model can never fold far-away points back into the image.
        w, h = camera.width, camera.height
        edge = np.linspace(0.0, 1.0, 64)
        zero, one = np.zeros_like(edge), np.ones_like(edge)
        border_uv = np.concatenate([
            np.stack([edge * (w - 1), zero], 1), np.stack([edge * (w - 1), one * (h - 1)], 1),
            np.stack([zero, edge * (h - 1)], 1), np.stack([one * (w - 1), edge * (h - 1)], 1),
        ])
        xy = camera.unproject(border_uv)
        span = xy.max(axis=0) - xy.min(axis=0)
        self.xy_lo = xy.min(axis=0) - 0.05 * span
        self.xy_hi = xy.max(axis=0) + 0.05 * span

    def observe(self, points_G: NDArray[np.float64], R_CtoG: NDArray[np.float64], p_CinG: NDArray[np.float64]
                ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """Return (visible (N,) bool, uv (N, 2) true pixels, NaN where not visible)."""
        n = points_G.shape[0]
        uv = np.full((n, 2), np.nan)
        visible = np.zeros(n, dtype=bool)
        if n == 0:
            return visible, uv
        p_C = (points_G - p_CinG) @ R_CtoG  # p_C = R_CtoG^T (p_G - p_CinG), as row vectors
        front = p_C[:, 2] >= self.min_depth  # depth Z >= min_depth
        xy = p_C[front, :2] / p_C[front, 2:3]  # x = X / Z, y = Y / Z
        in_range = np.all((xy >= self.xy_lo) & (xy <= self.xy_hi), axis=1)
        idx = np.flatnonzero(front)[in_range]
        if idx.size == 0:
            return visible, uv
        uv_idx = self.camera.project(p_C[idx])
        inside = self.camera.in_image(uv_idx, border=self.border)
        idx, uv_idx = idx[inside], uv_idx[inside]
        if self.occluder is not None and idx.size:
            rays = points_G[idx] - p_CinG
            distance = np.linalg.norm(rays, axis=1)
            hit = self.occluder.intersect(np.broadcast_to(p_CinG, rays.shape), rays)[0]
            clear = hit >= distance * (1.0 - _OCCLUSION_REL_TOL) - _OCCLUSION_ABS_TOL  # first hit = the landmark
            idx, uv_idx = idx[clear], uv_idx[clear]
        visible[idx] = True
        uv[idx] = uv_idx
        return visible, uv


def _grid_shape(camera: Any, cells: int) -> tuple[int, int]:
    """Return (rows, cols) with rows * cols ~ cells and cells roughly square in pixels."""
    cols = max(1, int(round(math.sqrt(cells * camera.width / camera.height))))
    rows = max(1, int(round(cells / cols)))
    return rows, cols


def _cell_of(uv: NDArray[np.float64], camera: Any, grid: tuple[int, int]) -> NDArray[np.int64]:
    """Return the grid cell index (row * cols + col) of each pixel (N,)."""
    rows, cols = grid
    col = np.clip((uv[:, 0] / camera.width * cols).astype(np.int64), 0, cols - 1)
    row = np.clip((uv[:, 1] / camera.height * rows).astype(np.int64), 0, rows - 1)
    return row * cols + col


def _select_spread(cand_cells: NDArray[np.int64], occupancy: NDArray[np.int64], need: int,
                   rng: np.random.Generator) -> NDArray[np.int64]:
    """Return indices of up to ``need`` candidates, emptiest cells first, random within a cell.

    Priority of a candidate = tracks already in its cell + its rank among the (shuffled) candidates of that cell;
    the ``need`` smallest priorities win, so cells are filled level by level (a vectorised round-robin).
    """
    n = cand_cells.shape[0]
    if n == 0 or need <= 0:
        return np.zeros(0, dtype=np.int64)
    order = rng.permutation(n)
    cells = cand_cells[order]
    by_cell = np.argsort(cells, kind="stable")
    sorted_cells = cells[by_cell]
    first = np.searchsorted(sorted_cells, sorted_cells, side="left")
    rank = np.empty(n, dtype=np.int64)
    rank[by_cell] = np.arange(n) - first  # rank of each shuffled candidate within its cell
    priority = occupancy[cells] + rank
    chosen = np.argsort(priority, kind="stable")[:need]
    return order[chosen]


# ==================================================================================================== simulation
def simulate_feature_tracks(
    trajectory: Any,
    extrinsics: Any,
    camera: Any,
    landmarks_G: Any,
    frame_times: ArrayLike,
    rng: np.random.Generator | int,
    pixel_noise_px: float = 1.0,
    features_per_frame: int = 60,
    min_depth: float = 0.3,
    border_px: float = 5.0,
    max_track_length: int | None = None,
    occlusion: Any | None = None,
    grid: tuple[int, int] | None = None,
) -> list[FeatureFrame]:
    """Return one :class:`FeatureFrame` per frame time: tracked landmark observations with pixel noise.

    Args:
        trajectory: ground truth with ``evaluate(t) -> TrajectorySample`` (R_ItoG (N,3,3), p_IinG (N,3)).
        extrinsics: :class:`~evio_lib.sim.rig.CameraImuExtrinsics` (``camera_pose(R_ItoG, p_IinG)``).
        camera: :class:`~evio_lib.geometry.camera.PinholeRadtan` (project, unproject, in_image, width, height).
        landmarks_G: (L, 3) landmark positions in G (metres), or a scene with ``intersect`` on whose surfaces new
            landmarks are created on demand (rays through random pixels; their first hits).
        frame_times: (F,) strictly increasing image times inside the trajectory, s.
        rng: Generator or int seed (pixel noise, candidate order, new-landmark pixels).
        pixel_noise_px: standard deviation of the Gaussian noise added to u and v, pixels (0 = exact).
        features_per_frame: number of tracks maintained (replenished when fewer remain visible).
        min_depth: minimum depth Z in the camera frame, metres.
        border_px: minimum distance of a true projection from the edge pixel centres, pixels.
        max_track_length: end a track after this many observations (None = only when its landmark leaves the view).
        occlusion: scene with ``intersect`` used to drop landmarks hidden behind a surface (None = no occlusion
            test). When ``landmarks_G`` is a scene and ``occlusion`` is None, that scene is the occluder.
        grid: (rows, cols) of the replenishment grid; None gives about features_per_frame / 2 near-square cells.

    Returns:
        list of F FeatureFrame (t, ids (K,), xy (K, 2) undistorted normalised, uv (K, 2) pixels, landmarks_G (K, 3)),
        features of existing tracks first (in track order), then new tracks (ids increasing).

    Reference: thesis §3.3 (MSCKF input: feature tracks, undistorted coordinates), §4.5 (60 features per image,
    per-region selection), camera model Eq. 1 and Eqs. 27-28.

    >>> from evio_lib.sim.trajectory import trajectory_from_preset
    >>> from evio_lib.sim.rig import CameraImuExtrinsics
    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> traj = trajectory_from_preset("boxes_like", duration=2.0, seed=0)
    >>> frames = simulate_feature_tracks(traj, CameraImuExtrinsics.default(), PinholeRadtan.davis240c(),
    ...                                  simple_geometry("boxes_like"), np.arange(0.0, 2.0, 0.05), rng=0)
    >>> len(frames), len(frames[0]), frames[1].ids[:3].tolist()
    (40, 60, [0, 1, 2])
    """
    rng = _generator(rng)
    times = np.asarray(frame_times, dtype=np.float64)
    if times.ndim != 1 or times.shape[0] == 0:
        raise ValueError(f"frame_times must have shape (F,) with F >= 1; got {times.shape}")
    if not np.isfinite(times).all() or np.any(np.diff(times) <= 0):
        raise ValueError("frame_times must be finite and strictly increasing; got non-finite or unsorted times")
    noise = _nonnegative(pixel_noise_px, "pixel_noise_px")
    target = _positive_int(features_per_frame, "features_per_frame")
    min_depth = _nonnegative(min_depth, "min_depth", strict=True)
    border = _nonnegative(border_px, "border_px")
    max_len = None if max_track_length is None else _positive_int(max_track_length, "max_track_length")
    if occlusion is not None and not callable(getattr(occlusion, "intersect", None)):
        raise ValueError(f"occlusion must be None or a scene with an intersect method; got {type(occlusion).__name__}")
    scene_mode = callable(getattr(landmarks_G, "intersect", None))
    if scene_mode:
        scene = landmarks_G
        landmarks = np.zeros((0, 3))
        occluder = occlusion if occlusion is not None else scene
    else:
        try:
            landmarks = _points(landmarks_G, "landmarks_G")
        except (TypeError, ValueError):
            shape = getattr(np.asarray(landmarks_G, dtype=object), "shape", None)
            raise ValueError(f"landmarks_G must be an array of shape (L, 3) or a scene with intersect; got shape "
                             f"{shape}") from None
        occluder = occlusion
    if grid is None:
        grid = _grid_shape(camera, max(1, target // 2))
    elif (len(grid) != 2 or any(isinstance(g, bool) or not isinstance(g, (int, np.integer)) or g < 1 for g in grid)):
        raise ValueError(f"grid must be None or (rows, cols) of positive ints; got {grid!r}")
    n_cells = int(grid[0]) * int(grid[1])

    sample = trajectory.evaluate(times)
    R_CtoG_all, p_CinG_all = extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)
    observer = _Observer(camera, min_depth, border, occluder)

    active_p = np.zeros((0, 3))  # tracked landmark positions
    active_lm = np.zeros(0, dtype=np.int64)  # their rows in `landmarks` (array mode; -1 in scene mode)
    active_id = np.zeros(0, dtype=np.int64)
    active_len = np.zeros(0, dtype=np.int64)
    next_id = 0
    frames: list[FeatureFrame] = []
    for k in range(times.shape[0]):
        R_CtoG, p_CinG = R_CtoG_all[k], p_CinG_all[k]
        # 1. keep the tracks whose landmark is still visible (and not too long)
        if scene_mode:
            vis_active, uv_active = observer.observe(active_p, R_CtoG, p_CinG)
        else:
            vis_all, uv_all = observer.observe(landmarks, R_CtoG, p_CinG)
            vis_active, uv_active = vis_all[active_lm], uv_all[active_lm]
        keep = vis_active if max_len is None else vis_active & (active_len < max_len)
        previously_tracked = active_lm
        active_p, active_lm, active_id = active_p[keep], active_lm[keep], active_id[keep]
        active_len, uv_keep = active_len[keep] + 1, uv_active[keep]

        # 2. replenish, emptiest grid cell first
        need = target - active_p.shape[0]
        new_p, new_lm, new_uv = np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        if need > 0:
            occupancy = np.bincount(_cell_of(uv_keep, camera, grid), minlength=n_cells)
            if scene_mode:
                cand_p, cand_uv = _spawn_on_scene(scene, observer, camera, R_CtoG, p_CinG, need, border, rng)
                cand_lm = np.full(cand_p.shape[0], -1, dtype=np.int64)
            else:
                free = vis_all.copy()
                free[previously_tracked] = False  # a landmark tracked until now is not re-detected in this frame
                cand_lm = np.flatnonzero(free)
                cand_p, cand_uv = landmarks[cand_lm], uv_all[cand_lm]
            chosen = _select_spread(_cell_of(cand_uv, camera, grid), occupancy, need, rng)
            new_p, new_lm, new_uv = cand_p[chosen], cand_lm[chosen], cand_uv[chosen]
        n_new = new_p.shape[0]
        active_p = np.concatenate([active_p, new_p])
        active_lm = np.concatenate([active_lm, new_lm])
        active_id = np.concatenate([active_id, np.arange(next_id, next_id + n_new, dtype=np.int64)])
        active_len = np.concatenate([active_len, np.ones(n_new, dtype=np.int64)])
        next_id += n_new
        uv_true = np.concatenate([uv_keep, new_uv])

        # 3. noisy measurement: uv~ = uv + n, n ~ N(0, sigma^2 I); xy = undistort((uv~ - c) / f)
        uv_meas = uv_true + noise * rng.standard_normal(uv_true.shape) if noise > 0 else uv_true.copy()
        xy = camera.unproject(uv_meas) if uv_meas.shape[0] else np.zeros((0, 2))
        frames.append(FeatureFrame(t=float(times[k]), ids=active_id.copy(), xy=np.asarray(xy, dtype=np.float64),
                                   uv=uv_meas, landmarks_G=active_p.copy()))
    return frames


def _spawn_on_scene(scene: Any, observer: _Observer, camera: Any, R_CtoG: NDArray[np.float64],
                    p_CinG: NDArray[np.float64], need: int, border: float, rng: np.random.Generator
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return candidate landmarks (M, 3) and their pixels (M, 2): first hits of rays through random pixels."""
    m = max(_CANDIDATES_PER_NEEDED * need, 32)
    lo = np.array([border, border])
    hi = np.array([camera.width - 1 - border, camera.height - 1 - border])
    uv = lo + rng.random((m, 2)) * (hi - lo)
    xy = camera.unproject(uv)
    rays_G = np.concatenate([xy, np.ones((m, 1))], axis=1) @ R_CtoG.T  # d_G = R_CtoG [x, y, 1]
    distance = scene.intersect(np.broadcast_to(p_CinG, rays_G.shape), rays_G)[0]
    hit = np.isfinite(distance)
    points = p_CinG + distance[hit, None] * rays_G[hit] / np.linalg.norm(rays_G[hit], axis=1, keepdims=True)
    visible, uv_true = observer.observe(points, R_CtoG, p_CinG)  # depth, border and (rounding-safe) self-occlusion
    return points[visible], uv_true[visible]


def track_lengths(frames: list[FeatureFrame]) -> NDArray[np.int64]:
    """Return the number of observations of every track (T,), ordered by track id.

    >>> f = [FeatureFrame(0.0, np.array([0, 1]), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 3))),
    ...      FeatureFrame(0.1, np.array([1, 2]), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 3)))]
    >>> track_lengths(f).tolist()
    [1, 2, 1]
    """
    if not frames:
        return np.zeros(0, dtype=np.int64)
    ids = np.concatenate([frame.ids for frame in frames])
    _, counts = np.unique(ids, return_counts=True)
    return counts.astype(np.int64)


# ==================================================================================================== landmarks
def landmarks_for_preset(
    name: str,
    trajectory: Any,
    extrinsics: Any,
    camera: Any,
    n: int,
    rng: np.random.Generator | int,
    scene: Any | None = None,
    n_poses: int = 100,
) -> NDArray[np.float64]:
    """Return (n, 3) landmarks in G on the preset's surfaces, each visible from some pose along the trajectory.

    Each landmark is the first surface hit of the ray through a uniformly random pixel of the camera at one of
    ``n_poses`` poses evenly spaced along the trajectory (so landmarks are spread over what the camera sees).

    Args:
        name: 'boxes_like' or 'aerial_like'.
        trajectory: ground truth with ``evaluate``, ``t_start`` and ``t_end``.
        extrinsics: camera-IMU extrinsics (``camera_pose``).
        camera: camera model (unproject, width, height).
        n: number of landmarks (>= 0).
        rng: Generator or int seed.
        scene: object with ``intersect`` to cast rays on; None builds the preset's textured scene
            (``evio_lib.sim.scene.scene_from_preset``) when it can be imported, else uses :func:`simple_geometry`.
        n_poses: number of poses along the trajectory the rays start from.

    >>> from evio_lib.sim.trajectory import trajectory_from_preset
    >>> from evio_lib.sim.rig import CameraImuExtrinsics
    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> traj = trajectory_from_preset("aerial_like", duration=10.0)
    >>> pts = landmarks_for_preset("aerial_like", traj, CameraImuExtrinsics.default(), PinholeRadtan.davis240c(),
    ...                            100, rng=0, scene=simple_geometry("aerial_like"))
    >>> pts.shape, bool(np.abs(pts[:, 2]).max() < 1e-9)
    ((100, 3), True)
    """
    if name not in ("boxes_like", "aerial_like"):
        raise ValueError(f"name must be one of ['aerial_like', 'boxes_like']; got {name!r}")
    n = _positive_int(n, "n", minimum=0)
    n_poses = _positive_int(n_poses, "n_poses")
    rng = _generator(rng)
    if scene is None:
        try:
            from evio_lib.sim.scene import scene_from_preset
        except ImportError:  # the textured scene is optional here
            scene = simple_geometry(name)
        else:
            scene = scene_from_preset(name)
    elif not callable(getattr(scene, "intersect", None)):
        raise ValueError(f"scene must be None or an object with an intersect method; got {type(scene).__name__}")
    times = np.linspace(trajectory.t_start, trajectory.t_end, n_poses)
    sample = trajectory.evaluate(times)
    R_CtoG, p_CinG = extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)
    found: list[NDArray[np.float64]] = []
    total = 0
    for _ in range(50):  # resample the rays that miss every surface
        if total >= n:
            break
        m = max(2 * (n - total), 16)
        pose = rng.integers(0, n_poses, size=m)
        uv = rng.random((m, 2)) * [camera.width - 1, camera.height - 1]
        xy = camera.unproject(uv)
        d_C = np.concatenate([xy, np.ones((m, 1))], axis=1)
        d_G = np.einsum("nij,nj->ni", R_CtoG[pose], d_C)  # d_G = R_CtoG [x, y, 1]
        distance = scene.intersect(p_CinG[pose], d_G)[0]
        hit = np.isfinite(distance)
        unit = d_G[hit] / np.linalg.norm(d_G[hit], axis=1, keepdims=True)
        found.append(p_CinG[pose[hit]] + distance[hit, None] * unit)
        total += int(hit.sum())
    points = np.concatenate(found) if found else np.zeros((0, 3))
    if points.shape[0] < n:
        raise ValueError(f"the trajectory sees too little of the {name} scene: found {points.shape[0]} of {n} "
                         "landmarks")
    return points[:n]
