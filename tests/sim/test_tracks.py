"""Tests of evio_lib.sim.tracks: perfect-data-association feature tracks and preset landmarks."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.tracks import (
    FeatureFrame,
    SimpleGeometry,
    landmarks_for_preset,
    simple_geometry,
    simulate_feature_tracks,
    track_lengths,
)
from evio_lib.sim.trajectory import trajectory_from_preset

CAMERA = PinholeRadtan.davis240c()
EXTRINSICS = CameraImuExtrinsics.default()


class StaticTrajectory:
    """A trajectory that stays at one pose (IMU = world axes unless given), for hand-made geometry."""

    t_start, t_end = 0.0, 10.0

    def __init__(self, R_ItoG: np.ndarray | None = None, p_IinG: np.ndarray | None = None) -> None:
        self.R = np.eye(3) if R_ItoG is None else R_ItoG
        self.p = np.zeros(3) if p_IinG is None else p_IinG

    def evaluate(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return SimpleNamespace(t=t, R_ItoG=np.repeat(self.R[None], t.size, 0),
                               p_IinG=np.repeat(self.p[None], t.size, 0))


@pytest.fixture(scope="module")
def boxes_tracks() -> tuple:
    """Noise-free 4 s of boxes_like tracks at 20 Hz on the analytic room (scene mode), with the trajectory."""
    traj = trajectory_from_preset("boxes_like", duration=4.0, seed=1)
    times = np.arange(0.0, 4.0, 0.05)
    frames = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, simple_geometry("boxes_like"), times, rng=3,
                                     pixel_noise_px=0.0)
    return traj, times, frames


def _true_camera_points(traj, t: float, points_G: np.ndarray) -> np.ndarray:
    """p_C from first principles: R_CtoG = R_ItoG R_CtoI, p_CinG = p_IinG + R_ItoG p_CinI, p_C = R_CtoG^T (p - p_C)."""
    s = traj.evaluate(t)
    R_ItoG, p_IinG = s.R_ItoG[0], s.p_IinG[0]
    R_CtoG = R_ItoG @ EXTRINSICS.R_CtoI
    p_CinG = p_IinG + R_ItoG @ EXTRINSICS.p_CinI
    return (R_CtoG.T @ (points_G - p_CinG).T).T


def test_noise_free_tracks_reproject_exactly(boxes_tracks) -> None:
    traj, times, frames = boxes_tracks
    assert len(frames) == times.size
    for frame in frames[::7]:
        p_C = _true_camera_points(traj, frame.t, frame.landmarks_G)
        assert np.all(p_C[:, 2] >= 0.3)
        np.testing.assert_allclose(frame.xy, p_C[:, :2] / p_C[:, 2:], atol=1e-9)  # x = X / Z
        # independent pixel check with OpenCV's projection of the same points
        import cv2
        uv_cv, _ = cv2.projectPoints(p_C, np.zeros(3), np.zeros(3), CAMERA.K, CAMERA.dist_coeffs)
        np.testing.assert_allclose(frame.uv, uv_cv[:, 0], atol=1e-6)
        assert np.all((frame.uv >= 5.0) & (frame.uv <= [CAMERA.width - 6, CAMERA.height - 6]))


def test_scene_mode_landmarks_lie_on_the_room_surfaces(boxes_tracks) -> None:
    _, _, frames = boxes_tracks
    points = np.concatenate([f.landmarks_G for f in frames])
    geometry = simple_geometry("boxes_like")
    on_room = np.any(np.isclose(points, [-4.0, -4.0, 0.0], atol=1e-9) | np.isclose(points, [4.0, 4.0, 3.0], atol=1e-9),
                     axis=1)
    on_box = np.zeros(len(points), dtype=bool)
    for lo, hi in geometry.boxes:
        inside = np.all((points >= lo - 1e-9) & (points <= hi + 1e-9), axis=1)
        on_face = np.any(np.isclose(points, lo, atol=1e-9) | np.isclose(points, hi, atol=1e-9), axis=1)
        on_box |= inside & on_face
    assert np.all(on_room | on_box)
    assert on_box.mean() > 0.03  # the boxes in front of the camera are seen too (not only the walls)


def test_features_per_frame_and_spread(boxes_tracks) -> None:
    _, _, frames = boxes_tracks
    counts = np.array([len(f) for f in frames])
    assert counts.max() <= 60 and counts.mean() >= 0.98 * 60
    # grid replenishment spreads features: most 4x4 image regions hold a feature in the first frame
    uv = frames[0].uv
    cells = (uv[:, 0] // (CAMERA.width / 4)).astype(int) * 4 + (uv[:, 1] // (CAMERA.height / 4)).astype(int)
    assert np.unique(cells).size >= 14


def test_ids_unique_never_reused_and_landmark_fixed(boxes_tracks) -> None:
    _, _, frames = boxes_tracks
    first_seen: dict[int, int] = {}
    last_seen: dict[int, int] = {}
    landmark: dict[int, np.ndarray] = {}
    observations = 0
    for k, frame in enumerate(frames):
        assert frame.ids.dtype == np.int64 and np.unique(frame.ids).size == len(frame)
        for i, p in zip(frame.ids.tolist(), frame.landmarks_G):
            if i in last_seen:
                assert last_seen[i] == k - 1, f"track {i} reappears after a gap"
                np.testing.assert_array_equal(landmark[i], p)
            else:
                assert all(i > j for j in first_seen), "new ids must be fresh (larger than every earlier id)"
                first_seen[i] = k
                landmark[i] = p
            last_seen[i] = k
            observations += 1
    assert track_lengths(frames).sum() == observations


def test_tracks_end_only_when_landmark_leaves_view() -> None:
    traj = trajectory_from_preset("boxes_like", duration=3.0, seed=2)
    rng = np.random.default_rng(5)
    points = landmarks_for_preset("boxes_like", traj, EXTRINSICS, CAMERA, 800, rng, scene=simple_geometry("boxes_like"))
    times = np.arange(0.0, 3.0, 0.05)
    frames = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, points, times, rng=rng, pixel_noise_px=0.0)
    ended = 0
    for prev, nxt in zip(frames[:-1], frames[1:]):
        gone = ~np.isin(prev.ids, nxt.ids)
        if not gone.any():
            continue
        p_C = _true_camera_points(traj, nxt.t, prev.landmarks_G[gone])
        in_front = p_C[:, 2] >= 0.3
        visible = in_front.copy()
        uv = CAMERA.project(p_C[in_front])
        visible[in_front] = CAMERA.in_image(uv, border=5.0)
        assert not visible.any(), "a track ended although its landmark was still visible"
        ended += int(gone.sum())
    assert ended > 20


def test_occluded_landmarks_are_excluded() -> None:
    # camera at the origin looking along +z (identity extrinsics); landmarks on the plane z = 5;
    # a solid box x, y in [-0.5, 0.5], z in [2, 3] hides exactly those with |X| <= 1.25 and |Y| <= 1.25 (ray at z = 2)
    xs = np.linspace(-2.4, 2.4, 13)
    X, Y = np.meshgrid(xs, xs[:9] * 0.75)
    points = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 5.0)], axis=1)
    occluder = SimpleGeometry(boxes=[[[-0.5, -0.5, 2.0], [0.5, 0.5, 3.0]]])
    ext = CameraImuExtrinsics.identity()
    common = dict(pixel_noise_px=0.0, features_per_frame=500, border_px=0.0)
    free = simulate_feature_tracks(StaticTrajectory(), ext, CAMERA, points, [0.0], rng=0, **common)[0]
    hidden = simulate_feature_tracks(StaticTrajectory(), ext, CAMERA, points, [0.0], rng=0, occlusion=occluder,
                                     **common)[0]
    behind_box = (np.abs(free.landmarks_G[:, 0]) <= 1.25) & (np.abs(free.landmarks_G[:, 1]) <= 1.25)
    assert behind_box.sum() >= 20 and (~behind_box).sum() >= 20
    expected = {tuple(p) for p in free.landmarks_G[~behind_box]}
    assert {tuple(p) for p in hidden.landmarks_G} == expected


def test_deterministic_per_seed_and_noise_statistics() -> None:
    traj = trajectory_from_preset("aerial_like", duration=3.0, seed=0)
    times = np.arange(0.0, 3.0, 0.05)
    geometry = simple_geometry("aerial_like")
    a = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=np.random.default_rng(11))
    b = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=np.random.default_rng(11))
    c = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=np.random.default_rng(12))
    for fa, fb in zip(a, b):
        np.testing.assert_array_equal(fa.ids, fb.ids)
        np.testing.assert_array_equal(fa.xy, fb.xy)
    assert not np.array_equal(a[0].uv, c[0].uv)
    # pixel noise: uv - project(true point) ~ N(0, 1 px^2) per axis; xy = unproject(uv)
    residual, xy_err = [], []
    for frame in a:
        p_C = _true_camera_points(traj, frame.t, frame.landmarks_G)
        residual.append(frame.uv - CAMERA.project(p_C))
        xy_err.append(frame.xy - CAMERA.unproject(frame.uv))
    residual = np.concatenate(residual)
    assert residual.shape[0] > 3000
    assert abs(residual.mean()) < 0.05 and np.all(np.abs(residual.std(axis=0) - 1.0) < 0.05)
    np.testing.assert_allclose(np.concatenate(xy_err), 0.0, atol=1e-12)


def test_max_track_length_caps_tracks() -> None:
    traj = trajectory_from_preset("aerial_like", duration=3.0, seed=0)
    frames = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, simple_geometry("aerial_like"),
                                     np.arange(0.0, 3.0, 0.05), rng=0, max_track_length=10, features_per_frame=30)
    lengths = track_lengths(frames)
    assert lengths.max() == 10
    assert all(len(f) == 30 for f in frames)


@pytest.mark.parametrize("name, low, high", [("boxes_like", 4, 40), ("aerial_like", 40, 200)])
def test_track_length_distribution_at_20_hz(name: str, low: float, high: float) -> None:
    duration = 12.0
    traj = trajectory_from_preset(name, duration=duration, seed=0)
    frames = simulate_feature_tracks(traj, EXTRINSICS, CAMERA, simple_geometry(name),
                                     np.arange(0.0, duration, 0.05), rng=0)
    lengths = track_lengths(frames)
    finished = lengths[:-60] if lengths.size > 60 else lengths  # tracks still alive at the end are cut short
    assert low <= np.median(finished) <= high
    assert lengths.min() >= 1


def test_landmarks_for_preset_visible_and_on_surfaces(rng: np.random.Generator) -> None:
    traj = trajectory_from_preset("aerial_like", duration=20.0, seed=0)
    points = landmarks_for_preset("aerial_like", traj, EXTRINSICS, CAMERA, 500, rng,
                                  scene=simple_geometry("aerial_like"))
    assert points.shape == (500, 3)
    np.testing.assert_allclose(points[:, 2], 0.0, atol=1e-9)
    # every landmark is inside the image of at least one camera along the trajectory (and in front of it)
    s = traj.evaluate(np.linspace(0.0, 20.0, 100))  # the default n_poses = 100 poses the rays start from
    R_CtoG = s.R_ItoG @ EXTRINSICS.R_CtoI
    p_CinG = s.p_IinG + s.R_ItoG @ EXTRINSICS.p_CinI
    p_C = np.einsum("kji,nkj->nki", R_CtoG, points[:, None, :] - p_CinG[None])  # (points, poses, 3)
    xy = p_C[..., :2] / p_C[..., 2:]
    uv = CAMERA.normalized_to_pixels(xy.reshape(-1, 2)).reshape(xy.shape)
    upper = [CAMERA.width - 1 + 1e-6, CAMERA.height - 1 + 1e-6]
    seen = (p_C[..., 2] > 0) & np.all((uv > -1e-6) & (uv < upper), axis=-1)
    assert seen.any(axis=1).all()
    # with the default textured scene, when it can be built
    scene_module = pytest.importorskip("evio_lib.sim.scene")
    boxes = trajectory_from_preset("boxes_like", duration=5.0, seed=0)
    scene = scene_module.scene_from_preset("boxes_like")
    room = landmarks_for_preset("boxes_like", boxes, EXTRINSICS, CAMERA, 300, 0, scene=scene)
    assert np.all((room >= [-4 - 1e-6, -4 - 1e-6, -1e-6]) & (room <= [4 + 1e-6, 4 + 1e-6, 3 + 1e-6]))
    frames = simulate_feature_tracks(boxes, EXTRINSICS, CAMERA, room, np.arange(0.0, 1.0, 0.05), rng=0,
                                     occlusion=scene, features_per_frame=40)
    assert np.mean([len(f) for f in frames]) > 30


def test_simple_geometry_hits_closed_form() -> None:
    room = simple_geometry("boxes_like")
    distance, index, _, _ = room.intersect([[0.0, 0.0, 1.4], [0.0, 0.0, 1.4], [0.0, 0.0, 0.5]],
                                           [[0.0, -1.0, 0.0], [0.0, 0.0, 2.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(distance, [4.0, 1.6, 2.4])  # wall y = -4, ceiling z = 3, near face y = 2.4 of a box
    assert index[2] >= 1  # a box, not the room


def test_bad_input_raises() -> None:
    traj = trajectory_from_preset("boxes_like", duration=2.0, seed=0)
    times = np.arange(0.0, 1.0, 0.1)
    geometry = simple_geometry("boxes_like")
    with pytest.raises(ValueError, match=r"landmarks_G must .*shape \(L, 3\)"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, np.zeros((5, 2)), times, rng=0)
    with pytest.raises(ValueError, match="frame_times must be finite and strictly increasing"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times[::-1], rng=0)
    with pytest.raises(ValueError, match=r"frame_times must have shape \(F,\)"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, np.zeros((2, 2)), rng=0)
    with pytest.raises(ValueError, match="pixel_noise_px must be a finite number >= 0"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, pixel_noise_px=-1.0)
    with pytest.raises(ValueError, match="features_per_frame must be an int >= 1"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, features_per_frame=0)
    with pytest.raises(ValueError, match="min_depth must be a finite number > 0"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, min_depth=0.0)
    with pytest.raises(ValueError, match="max_track_length must be an int >= 1"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, max_track_length=0)
    with pytest.raises(ValueError, match="occlusion must be None or a scene"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, occlusion=np.zeros(3))
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator or an int seed"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng="seed")
    with pytest.raises(ValueError, match=r"grid must be None or \(rows, cols\)"):
        simulate_feature_tracks(traj, EXTRINSICS, CAMERA, geometry, times, rng=0, grid=(0, 3))
    with pytest.raises(ValueError, match="name must be one of"):
        landmarks_for_preset("forest", traj, EXTRINSICS, CAMERA, 10, 0)
    with pytest.raises(ValueError, match="n must be an int >= 0"):
        landmarks_for_preset("boxes_like", traj, EXTRINSICS, CAMERA, -1, 0, scene=geometry)
    with pytest.raises(ValueError, match="name must be one of"):
        simple_geometry("forest")
    with pytest.raises(ValueError, match=r"origins_G must have shape \(N, 3\)"):
        geometry.intersect(np.zeros((2, 2)), np.ones((2, 2)))


def test_feature_frame_len_and_empty_lengths() -> None:
    frame = FeatureFrame(0.0, np.array([3], dtype=np.int64), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 3)))
    assert len(frame) == 1
    assert track_lengths([]).shape == (0,)
