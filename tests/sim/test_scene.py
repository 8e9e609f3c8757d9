"""Tests of evio_lib.sim.scene (ray casting renderer, presets) and evio_lib.sim.textures."""
import socket

import numpy as np
import pytest

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import so3_exp
from evio_lib.sim import textures
from evio_lib.sim.scene import (
    RenderResult,
    Scene,
    TexturedPlane,
    aerial_ground,
    indoor_room,
    scene_from_preset,
)

# camera frame looking along +y_G with z_G up: x_C = +x_G, y_C = -z_G, z_C = +y_G (columns of R_CtoG)
R_LOOK_PLUS_Y = np.column_stack([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
R_LOOK_DOWN = np.column_stack([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


@pytest.fixture(scope="module")
def camera() -> PinholeRadtan:
    return PinholeRadtan.davis240c()


@pytest.fixture(scope="module")
def room() -> Scene:
    return indoor_room(seed=0)


def _random_rotation(rng: np.random.Generator, scale: float = 0.2) -> np.ndarray:
    return so3_exp(rng.normal(0.0, scale, 3))


def _plane_residuals(scene: Scene, points: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (distance to plane, s, t) of points on the planes given by index, by least squares (independent)."""
    dist, s_all, t_all = [], [], []
    for point, k in zip(points, index):
        plane = scene.planes[k]
        A = np.column_stack([plane.axis_u_G, plane.axis_v_G])
        (s, t), *_ = np.linalg.lstsq(A, point - plane.origin_G, rcond=None)
        dist.append(np.linalg.norm(plane.origin_G + A @ [s, t] - point))
        s_all.append(s)
        t_all.append(t)
    return np.array(dist), np.array(s_all), np.array(t_all)


# ------------------------------------------------------------------------------------------------ TexturedPlane
def test_plane_validation_and_properties():
    texture = np.full((4, 6), 0.5, np.float32)
    plane = TexturedPlane([0, 0, 1], [2, 0, 0], [0, 3, 0], texture, name="p")
    assert plane.texture.flags.writeable is False and plane.texture is not texture
    np.testing.assert_allclose(plane.normal_G, [0, 0, 1])
    assert plane.area_m2 == pytest.approx(6.0)
    assert plane.texel_size_m == pytest.approx(min(2.0 / 5, 3.0 / 3))
    np.testing.assert_allclose(plane.corners_G[2], [2, 3, 1])
    with pytest.raises(ValueError, match="origin_G must have shape"):
        TexturedPlane([0, 0], [1, 0, 0], [0, 1, 0], texture)
    with pytest.raises(ValueError, match="not parallel"):
        TexturedPlane([0, 0, 0], [1, 0, 0], [2, 0, 0], texture)
    with pytest.raises(ValueError, match="texture must have shape"):
        TexturedPlane([0, 0, 0], [1, 0, 0], [0, 1, 0], np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match=r"texture must hold finite intensities in \[0, 1\]"):
        TexturedPlane([0, 0, 0], [1, 0, 0], [0, 1, 0], np.full((2, 2), 1.5))
    with pytest.raises(ValueError, match="texture_repeat"):
        TexturedPlane([0, 0, 0], [1, 0, 0], [0, 1, 0], texture, texture_repeat=(0.0, 1.0))


def test_scene_validation():
    plane = TexturedPlane([0, 0, 1], [1, 0, 0], [0, 1, 0], np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="at least one TexturedPlane"):
        Scene([])
    with pytest.raises(ValueError, match=r"planes\[1\] must be a TexturedPlane"):
        Scene([plane, "wall"])
    with pytest.raises(ValueError, match="background"):
        Scene([plane], background=2.0)


# ------------------------------------------------------------------------------------------------ geometry
def test_depth_of_a_fronto_parallel_plane_is_exact(camera):
    """A plane z = 2 m in front of the camera renders depth 2 everywhere (closed form), through real distortion."""
    wall = TexturedPlane([-10.0, -10.0, 2.0], [20.0, 0, 0], [0, 20.0, 0], np.full((8, 8), 0.3, np.float32))
    result = Scene([wall]).render(camera, np.eye(3), np.zeros(3))
    assert isinstance(result, RenderResult)
    assert result.intensity.shape == (180, 240) and result.intensity.dtype == np.float32
    assert result.depth.dtype == np.float32 and result.points_G.shape == (180, 240, 3)
    assert result.plane_index.dtype == np.int32 and np.all(result.plane_index == 0)
    np.testing.assert_array_equal(result.depth, 2.0)
    np.testing.assert_allclose(result.intensity, 0.3, atol=1e-6)


def test_depth_of_a_tilted_plane_matches_closed_form(camera, rng):
    """z-depth of the plane n . X_C = h is h / (n . [x, y, 1]) (closed form from the normalised grid)."""
    R = _random_rotation(rng)
    p = np.array([0.3, -0.2, 0.5])
    normal_C = np.array([0.2, -0.1, -1.0])  # plane facing the camera, tilted
    normal_C /= np.linalg.norm(normal_C)
    h = -3.0  # n . X_C = h, points at z ~ 3 m
    centre_C = h * normal_C
    axis_a = np.cross(normal_C, [0.0, 1.0, 0.0])
    axis_a /= np.linalg.norm(axis_a)
    axis_b = np.cross(normal_C, axis_a)
    origin_C = centre_C - 20 * axis_a - 20 * axis_b
    to_G = lambda v: R @ v  # noqa: E731
    plane = TexturedPlane(to_G(origin_C) + p, to_G(40 * axis_a), to_G(40 * axis_b), np.full((4, 4), 0.5, np.float32))
    result = Scene([plane]).render(camera, R, p)
    grid = camera.normalized_grid()
    rays = np.concatenate([grid, np.ones(grid.shape[:2] + (1,))], axis=-1)
    expected = h / (rays @ normal_C)
    assert np.all(result.plane_index == 0)
    np.testing.assert_allclose(result.depth, expected, rtol=1e-6)


def test_points_reproject_onto_their_pixels(camera, room, rng):
    R = _random_rotation(rng, 0.15) @ R_LOOK_PLUS_Y
    p = np.array([0.1, 0.2, 1.3])
    result = room.render(camera, R, p)
    hit = result.plane_index >= 0
    assert hit.all()  # closed room
    points_C = (result.points_G[hit] - p) @ R  # R_GtoC (X - p)
    np.testing.assert_allclose(points_C[:, 2], result.depth[hit], rtol=1e-6)
    uv = camera.project(points_C)
    rows, cols = np.nonzero(hit)
    assert np.abs(uv - np.stack([cols, rows], axis=1)).max() < 1e-6
    # every hit point lies on (the extension of) its plane, within its bounds
    sample = rng.choice(points_C.shape[0], 300, replace=False)
    dist, s, t = _plane_residuals(room, result.points_G[hit][sample], result.plane_index[hit][sample])
    assert dist.max() < 1e-9
    assert s.min() > -1e-6 and s.max() < 1 + 1e-6 and t.min() > -1e-6 and t.max() < 1 + 1e-6


def test_hit_points_are_the_render_points_without_the_texture_lookup(camera, room, rng):
    """hit_points (the motion-blur planner's geometry) gives render's points_G bit for bit, NaN where nothing is hit."""
    R = _random_rotation(rng, 0.3) @ R_LOOK_PLUS_Y
    p = np.array([0.3, -0.1, 1.1])
    expected = room.render(camera, R, p).points_G
    np.testing.assert_array_equal(room.hit_points(camera, R, p), expected)
    outside = np.array([0.0, -50.0, 1.0])  # far outside the room, looking away: some rays hit nothing
    np.testing.assert_array_equal(room.hit_points(camera, R, outside), room.render(camera, R, outside).points_G)


def test_intersect_matches_brute_force(room, rng):
    origins = rng.uniform([-3, -3, 0.2], [3, 3, 2.8], size=(150, 3))
    directions = rng.normal(size=(150, 3))
    distance, index, s, t = room.intersect(origins, directions)
    for i in range(150):  # reference: solve o + l d = O + s U + t V with np.linalg.solve per plane
        unit = directions[i] / np.linalg.norm(directions[i])
        best = (np.inf, -1, np.nan, np.nan)
        for k, plane in enumerate(room.planes):
            A = np.column_stack([plane.axis_u_G, plane.axis_v_G, -unit])
            ss, tt, lam = np.linalg.solve(A, origins[i] - plane.origin_G)
            front = plane.two_sided or unit @ plane.normal_G > 0
            if 0 <= ss <= 1 and 0 <= tt <= 1 and lam > 0 and front and lam < best[0]:
                best = (lam, k, ss, tt)
        assert distance[i] == pytest.approx(best[0], rel=1e-9)
        assert index[i] == best[1]
        np.testing.assert_allclose([s[i], t[i]], best[2:], atol=1e-9)
    assert np.isfinite(distance).all()  # closed room: every ray hits


def test_intersect_misses_and_bad_input():
    plane = TexturedPlane([0, 0, 5], [1, 0, 0], [0, 1, 0], np.zeros((2, 2), np.float32), two_sided=False)
    scene = Scene([plane])
    origins = [[0.5, 0.5, 0], [0.5, 0.5, 0], [3, 3, 0]]
    distance, index, s, t = scene.intersect(origins, [[0, 0, 1], [0, 0, -1], [0, 0, 1]])
    assert distance[0] == pytest.approx(5.0) and index.tolist() == [0, -1, -1]
    assert np.isinf(distance[1:]).all() and np.isnan(s[1:]).all() and np.isnan(t[1:]).all()
    # single-sided: seen from below (axis_u x axis_v = +z points away from the viewer) but not from above
    assert scene.intersect([[0.5, 0.5, 9]], [[0, 0, -1]])[1][0] == -1
    with pytest.raises(ValueError, match=r"origins_G must have shape \(N, 3\)"):
        scene.intersect(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="same shape"):
        scene.intersect(np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="non-zero"):
        scene.intersect(np.zeros((1, 3)), np.zeros((1, 3)))


def test_occlusion_nearest_plane_wins_in_any_order(camera):
    texture_wall = np.full((4, 4), 0.2, np.float32)
    texture_box = np.full((4, 4), 0.9, np.float32)
    wall = TexturedPlane([-10, -10, 5.0], [20, 0, 0], [0, 20, 0], texture_wall, name="wall")
    box = TexturedPlane([-0.5, -0.5, 2.0], [1, 0, 0], [0, 1, 0], texture_box, name="box front")
    for planes, box_index in (([wall, box], 1), ([box, wall], 0)):
        result = Scene(planes).render(camera, np.eye(3), np.zeros(3))
        centre = camera.project(np.array([0.0, 0.0, 1.0])).round().astype(int)
        assert result.plane_index[centre[1], centre[0]] == box_index
        assert result.depth[centre[1], centre[0]] == pytest.approx(2.0)
        assert result.intensity[centre[1], centre[0]] == pytest.approx(0.9, abs=1e-5)
        assert result.plane_index[5, 5] == 1 - box_index and result.depth[5, 5] == pytest.approx(5.0)
        # the box covers exactly the pixels whose rays pass through it: |x|, |y| <= 0.25 at z = 2
        grid = camera.normalized_grid()
        inside = (np.abs(grid[..., 0]) < 0.25 - 1e-6) & (np.abs(grid[..., 1]) < 0.25 - 1e-6)
        outside = (np.abs(grid[..., 0]) > 0.25 + 1e-6) | (np.abs(grid[..., 1]) > 0.25 + 1e-6)
        assert np.all(result.plane_index[inside] == box_index)
        assert np.all(result.plane_index[outside] == 1 - box_index)


def test_single_sided_plane_is_invisible_from_behind(camera):
    texture = np.full((2, 2), 0.7, np.float32)
    facing = TexturedPlane([-1, -1, 2.0], [2, 0, 0], [0, 2, 0], texture, two_sided=False)  # u x v = +z: seen
    behind = TexturedPlane([-1, -1, 2.0], [0, 2, 0], [2, 0, 0], texture, two_sided=False)  # u x v = -z: culled
    both = TexturedPlane([-1, -1, 2.0], [0, 2, 0], [2, 0, 0], texture, two_sided=True)
    centre = (90, 130)
    assert Scene([facing]).render(camera, np.eye(3), np.zeros(3)).plane_index[centre] == 0
    result = Scene([behind], background=0.1).render(camera, np.eye(3), np.zeros(3))
    assert np.all(result.plane_index == -1) and np.all(np.isinf(result.depth))
    assert np.all(np.isnan(result.points_G)) and np.allclose(result.intensity, 0.1)
    assert Scene([both]).render(camera, np.eye(3), np.zeros(3)).plane_index[centre] == 0


def test_plane_crossing_behind_the_camera(camera):
    """A floor extending behind the camera (clipped at the near plane for culling) still renders exactly."""
    floor = TexturedPlane([-50, 50, 0.0], [100, 0, 0], [0, -100, 0], np.full((4, 4), 0.5, np.float32))
    p = np.array([0.0, 0.0, 1.5])
    result = Scene([floor]).render(camera, R_LOOK_PLUS_Y, p)
    grid = camera.normalized_grid()
    below = grid[..., 1] > 1.5 / 50 * 1.01  # rays that reach the floor within the 50 m extent
    assert np.all(result.plane_index[below] == 0)
    np.testing.assert_allclose(result.depth[below], 1.5 / grid[..., 1][below], rtol=1e-6)  # z = h / y
    assert np.all(result.plane_index[grid[..., 1] <= 0] == -1)


# ------------------------------------------------------------------------------------------------ texturing
def test_texture_sampling_at_texel_centres_returns_texel_values(rng):
    texture = rng.random((5, 7)).astype(np.float32)
    tiled = rng.random((4, 8)).astype(np.float32)
    planes = [TexturedPlane([0, 0, 1], [1, 0, 0], [0, 1, 0], texture),
              TexturedPlane([0, 0, 2], [1, 0, 0], [0, 1, 0], tiled, texture_repeat=(3.0, 2.0))]
    scene = Scene(planes)
    rows, cols = np.mgrid[0:5, 0:7]
    values = scene.sample_texture(np.zeros(35, int), cols.ravel() / 6.0, rows.ravel() / 4.0)
    np.testing.assert_allclose(values, texture.ravel(), atol=1e-7)
    # tiled: texel (col, row) = (s (3 * 8 - 1), t (2 * 4 - 1)) wraps modulo the texture size
    cols_t, rows_t = np.mgrid[0:23, 0:7]
    values = scene.sample_texture(np.ones(cols_t.size, int), cols_t.ravel() / 23.0, rows_t.ravel() / 7.0)
    np.testing.assert_allclose(values, tiled[rows_t.ravel() % 4, cols_t.ravel() % 8], atol=1e-6)
    # between texel centres: bilinear interpolation
    mid = scene.sample_texture(np.array([0]), np.array([0.5 / 6]), np.array([0.5 / 4]))
    assert mid[0] == pytest.approx(texture[:2, :2].mean(), abs=1e-6)
    with pytest.raises(ValueError, match="plane_index must lie in"):
        scene.sample_texture(np.array([2]), np.array([0.0]), np.array([0.0]))
    with pytest.raises(ValueError, match="s and t must have shape"):
        scene.sample_texture(np.array([0, 0]), np.array([0.0]), np.array([0.0]))


def test_rendered_pixels_hit_texel_centres_when_magnified(rng):
    """Pixel centres aligned on texel centres render the texel values (bilinear at level 0)."""
    texture = rng.random((6, 8)).astype(np.float32)
    camera = PinholeRadtan(fx=100.0, fy=100.0, cx=3.5, cy=2.5, width=8, height=6)
    # at z = 1 pixel u sees X = (u - 3.5) / 100: the plane spans the 8 x 6 pixel centres
    plane = TexturedPlane([-0.035, -0.025, 1.0], [0.07, 0, 0], [0, 0.05, 0], texture)
    image = Scene([plane], lod_bias=-3.0).render_intensity(camera, np.eye(3), np.zeros(3))
    np.testing.assert_allclose(image, texture, atol=2e-5)


def test_mip_mapping_removes_aliasing(camera):
    """A fine checkerboard far away averages to its mean; without the mip-map (lod bias -20) it aliases."""
    board = np.indices((1024, 1024)).sum(axis=0) % 2 * np.float32(0.8) + np.float32(0.1)
    # texel 0.2 m, pixel footprint 100 m / 199 = 0.5 m: ~2.6 texels per pixel, far beyond Nyquist
    wall = TexturedPlane([-100, -100, 100.0], [200, 0, 0], [0, 200, 0], board.astype(np.float32))
    filtered = Scene([wall]).render_intensity(camera, np.eye(3), np.zeros(3))
    aliased = Scene([wall], lod_bias=-20.0).render_intensity(camera, np.eye(3), np.zeros(3))
    assert abs(filtered.mean() - 0.5) < 0.01 and filtered.std() < 0.02
    assert aliased.std() > 0.08


def test_level_of_detail_blends_continuously(rng):
    texture = rng.random((64, 64)).astype(np.float32)
    scene = Scene([TexturedPlane([0, 0, 1], [1, 0, 0], [0, 1, 0], texture)])
    s = rng.random(200)
    t = rng.random(200)
    index = np.zeros(200, int)
    below, above = (scene.sample_texture(index, s, t, lod) for lod in (1.0 - 1e-6, 1.0 + 1e-6))
    assert np.abs(below - above).max() < 1e-5  # no jump at a level boundary (trilinear)
    level1 = scene.sample_texture(index, s, t, 1.0)
    level0 = scene.sample_texture(index, s, t, 0.0)
    np.testing.assert_allclose(scene.sample_texture(index, s, t, 0.5), 0.5 * (level0 + level1), atol=1e-6)
    # a constant texture stays constant at every level
    flat = Scene([TexturedPlane([0, 0, 1], [1, 0, 0], [0, 1, 0], np.full((10, 6), 0.4, np.float32))])
    np.testing.assert_allclose(flat.sample_texture(np.zeros(5, int), s[:5], t[:5], 7.0), 0.4, atol=1e-6)


def test_render_intensity_matches_render(camera, room, rng):
    R = _random_rotation(rng, 0.2) @ R_LOOK_PLUS_Y
    p = np.array([-0.2, 0.1, 1.5])
    fast = room.render_intensity(camera, R, p)
    full = room.render(camera, R, p)
    assert fast.dtype == np.float32 and fast.shape == (180, 240)
    assert np.mean(np.abs(fast - full.intensity) > 1e-3) < 1e-3  # same visibility up to float32 edge pixels
    assert 0.0 <= fast.min() and fast.max() <= 1.0


def test_render_bad_input(camera, room):
    with pytest.raises(ValueError, match=r"R_CtoG must have shape \(3, 3\)"):
        room.render_intensity(camera, np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="R_CtoG must be a rotation matrix"):
        room.render(camera, 2.0 * np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="R_CtoG must be a rotation matrix"):
        room.render(camera, np.diag([1.0, 1.0, -1.0]), np.zeros(3))  # reflection, det = -1
    with pytest.raises(ValueError, match=r"p_CinG must have shape \(3,\)"):
        room.render_intensity(camera, np.eye(3), np.zeros(2))
    with pytest.raises(ValueError, match="p_CinG must be finite"):
        room.render_intensity(camera, np.eye(3), [0.0, np.nan, 0.0])


# ------------------------------------------------------------------------------------------------ landmarks
def test_landmarks_are_on_surfaces_and_visible(camera, room, rng):
    R = _random_rotation(rng, 0.1) @ R_LOOK_PLUS_Y
    p = np.array([0.0, 0.0, 1.4])
    points = room.sample_landmarks(200, rng, camera=camera, R_CtoG=R, p_CinG=p)
    assert points.shape == (200, 3)
    directions = points - p
    distance, index, s, t = room.intersect(np.broadcast_to(p, points.shape), directions)
    np.testing.assert_allclose(distance, np.linalg.norm(directions, axis=1), rtol=1e-9)  # first hit = the point
    assert np.all(camera.in_image(camera.project((points - p) @ R)))
    free = room.sample_landmarks(100, np.random.default_rng(1))
    dist = np.min([np.abs((free - pl.origin_G) @ pl.normal_G) for pl in room.planes], axis=0)
    assert free.shape == (100, 3) and dist.max() < 1e-9
    with pytest.raises(ValueError, match="given together"):
        room.sample_landmarks(5, rng, camera=camera)
    with pytest.raises(ValueError, match="n must be a non-negative int"):
        room.sample_landmarks(-1, rng)


# ------------------------------------------------------------------------------------------------ presets
def test_indoor_room_layout_and_determinism(camera, room):
    names = [plane.name for plane in room.planes]
    assert {"floor", "ceiling", "wall +y", "wall -y", "wall +x", "wall -x"} <= set(names)
    box_faces = [plane for plane in room.planes if plane.name.startswith("box")]
    n_boxes = len({plane.name.split()[1] for plane in box_faces})
    assert 5 <= n_boxes <= 8 and len(box_faces) == 5 * n_boxes
    corners = np.concatenate([plane.corners_G for plane in box_faces])
    assert corners[:, 0].min() >= -1.5 - 1e-9 and corners[:, 0].max() <= 1.5 + 1e-9
    assert corners[:, 1].min() >= 1.5 - 1e-9 and corners[:, 1].max() <= 3.5 + 1e-9
    assert corners[:, 2].min() >= -1e-9
    bottoms = {round(float(plane.corners_G[:, 2].min()), 9) for plane in box_faces if plane.name.endswith("side")}
    assert 0.0 in bottoms and len(bottoms) >= 2  # boxes stand on the floor, some on other boxes
    again = indoor_room(seed=0)
    other = indoor_room(seed=1)
    assert all(np.array_equal(a.texture, b.texture) and np.array_equal(a.origin_G, b.origin_G)
               for a, b in zip(room.planes, again.planes))
    assert not all(np.array_equal(a.origin_G, b.origin_G) for a, b in zip(room.planes, other.planes))
    image = room.render(camera, R_LOOK_PLUS_Y, np.array([0.0, 0.0, 1.4]))
    assert np.all(image.plane_index >= 0)  # closed room: nothing escapes
    np.testing.assert_array_equal(image.intensity, again.render(camera, R_LOOK_PLUS_Y, np.array([0, 0, 1.4])).intensity)
    assert len(np.unique(image.plane_index)) >= 5


def test_room_has_contrast_everywhere(camera, room):
    """No large uniform regions: local log-intensity contrast in every 30 x 30 block of the view."""
    image = room.render_intensity(camera, so3_exp([-0.25, 0, 0]) @ R_LOOK_PLUS_Y, np.array([0.0, 0.0, 1.4]))
    log_image = np.log(image)
    blocks = log_image[:180, :240].reshape(6, 30, 8, 30).transpose(0, 2, 1, 3).reshape(48, -1)
    spread = np.percentile(blocks, 95, axis=1) - np.percentile(blocks, 5, axis=1)
    assert spread.min() > 0.1  # log-intensity steps of tens of per cent in every block
    assert image.min() >= 0.04 and image.max() <= 0.96


def test_aerial_ground_covers_a_long_flight(camera):
    ground = aerial_ground(seed=0)
    assert ground.planes[0].corners_G[:, :2].min() == pytest.approx(-1500.0)
    assert ground.planes[0].texture.shape == (4096, 4096)
    # the aerial_like flight stays within ~350 m of the origin; allow 1 km and 25 degrees of bank
    for p_xy, roll in (([0.0, 0.0], 0.0), ([1000.0, 0.0], 0.45), ([700.0, 700.0], -0.45), ([-1000.0, 300.0], 0.3)):
        R = so3_exp([0.0, roll, 0.0]) @ R_LOOK_DOWN
        result = ground.render(camera, R, np.array([*p_xy, 250.0]))
        assert np.all(result.plane_index == 0)
        image = result.intensity
        gradient = np.hypot(*np.gradient(np.log(image)))
        assert np.mean(gradient > 0.05) > 0.2  # texture everywhere: strong log-gradients in many pixels
    with pytest.raises(ValueError, match="extent_m"):
        aerial_ground(extent_m=-1.0)


def test_scene_from_preset():
    scene = scene_from_preset("aerial_like", seed=0)
    assert len(scene.planes) == 1
    with pytest.raises(ValueError, match="name must be one of"):
        scene_from_preset("forest")


# ------------------------------------------------------------------------------------------------ textures
def test_textures_load_offline(monkeypatch):
    def no_network(*args, **kwargs):
        raise AssertionError("texture loading tried to use the network")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    names = textures.available_textures()
    assert {"camera", "brick", "grass", "gravel", "coins", "astronaut"} <= set(names)
    for name in names:
        texture = textures.load_texture(name, size=(32, 48))
        assert texture.shape == (32, 48) and texture.dtype == np.float32
        assert 0.0 <= texture.min() and texture.max() <= 1.0 and texture.std() > 0.01
    with pytest.raises(ValueError, match="name must be one of"):
        textures.load_texture("lena")


def test_srgb_to_linear_matches_the_standard_curve():
    c = np.linspace(0, 1, 11)
    expected = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(textures.srgb_to_linear(c), expected, rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="image_srgb"):
        textures.srgb_to_linear(np.array([1.5]))


@pytest.mark.parametrize("kind", textures.PROCEDURAL_KINDS)
def test_procedural_textures_are_seeded_and_contrasted(kind):
    a = textures.procedural_texture(kind, (64, 96), seed=3, scale_px=12)
    b = textures.procedural_texture(kind, (64, 96), seed=3, scale_px=12)
    c = textures.procedural_texture(kind, (64, 96), seed=4, scale_px=12)
    assert a.shape == (64, 96) and a.dtype == np.float32
    assert 0.0 <= a.min() and a.max() <= 1.0 and a.max() - a.min() > 0.5
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_procedural_texture_bad_input():
    with pytest.raises(ValueError, match="kind must be one of"):
        textures.procedural_texture("plaid", (8, 8))
    with pytest.raises(ValueError, match=r"shape must be a \(height, width\)"):
        textures.procedural_texture("stripes", (8,))
    with pytest.raises(ValueError, match="seed"):
        textures.procedural_texture("stripes", (8, 8), seed=-1)


def test_aerial_terrain_texture_is_seeded():
    a = textures.aerial_terrain_texture(128, seed=1, metres_per_pixel=4.0)
    b = textures.aerial_terrain_texture(128, seed=1, metres_per_pixel=4.0)
    c = textures.aerial_terrain_texture(128, seed=2, metres_per_pixel=4.0)
    assert a.shape == (128, 128) and a.dtype == np.float32 and a.min() >= 0.02 and a.max() <= 1.0
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    with pytest.raises(ValueError, match="size_px"):
        textures.aerial_terrain_texture(10)
    with pytest.raises(ValueError, match="metres_per_pixel"):
        textures.aerial_terrain_texture(128, metres_per_pixel=0.0)


def test_supersampling_integrates_over_the_pixel_area():
    """With 2 x 2 samples per pixel, a pixel cut in half by an occlusion edge gets the mean of both sides."""
    camera = PinholeRadtan(fx=8.0, fy=8.0, cx=3.5, cy=3.5, width=8, height=8)
    left = TexturedPlane([-1.0, -1.0, 1.0], [1.0 - 0.0625, 0, 0], [0, 2.0, 0], np.full((2, 2), 0.2, np.float32))
    right = TexturedPlane([-0.0625, -1.0, 1.0], [1.0625, 0, 0], [0, 2.0, 0], np.full((2, 2), 0.8, np.float32))
    scene = Scene([left, right])  # edge at x = -1/16: through the centre of pixel column 3
    image = scene.render_intensity(camera, np.eye(3), np.zeros(3), supersample=2)
    assert image.shape == (8, 8) and image.dtype == np.float32
    np.testing.assert_allclose(image[:, :3], 0.2, atol=1e-6)
    np.testing.assert_allclose(image[:, 3], 0.5, atol=1e-6)  # half of each side
    np.testing.assert_allclose(image[:, 4:], 0.8, atol=1e-6)
    point_sampled = scene.render_intensity(camera, np.eye(3), np.zeros(3))[:, 3]  # one side or the other
    assert np.all(np.isclose(point_sampled, 0.2, atol=1e-6) | np.isclose(point_sampled, 0.8, atol=1e-6))
    with pytest.raises(ValueError, match="supersample must be an int >= 1"):
        scene.render_intensity(camera, np.eye(3), np.zeros(3), supersample=0)
