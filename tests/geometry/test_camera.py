"""Tests for evio_lib.geometry.camera: the pinhole-radtan model checked against OpenCV and finite differences."""
import dataclasses

import cv2
import numpy as np
import pytest

from evio_lib.geometry.camera import PinholeRadtan

# Cameras with different kinds of distortion: none, the strong barrel of the DAVIS240C, pincushion + tangential, k3.
CAMERAS = {
    "pinhole": PinholeRadtan(fx=200.0, fy=210.0, cx=119.5, cy=89.5, width=240, height=180),
    "davis240c": PinholeRadtan.davis240c(),
    "pincushion_tangential": PinholeRadtan(
        fx=320.0, fy=318.0, cx=161.0, cy=118.0, width=320, height=240, k1=0.12, k2=-0.03, p1=0.004, p2=-0.003
    ),
    "with_k3": PinholeRadtan(
        fx=225.0, fy=226.0, cx=161.0, cy=120.5, width=320, height=240, k1=-0.28, k2=0.09, p1=0.001, p2=0.0005, k3=-0.01
    ),
}


@pytest.fixture(params=list(CAMERAS))
def camera(request) -> PinholeRadtan:
    return CAMERAS[request.param]


def pixel_grid(camera: PinholeRadtan) -> np.ndarray:
    """Every pixel centre (u, v) of the camera, row-major, as (H*W, 2)."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def opencv_undistort_tight(uv: np.ndarray, camera: PinholeRadtan, P: np.ndarray | None = None) -> np.ndarray:
    """cv2.undistortPoints run to convergence (300 fixed-point iterations), not OpenCV's default 5 iterations."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 300, 1e-16)
    src = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
        out = cv2.undistortPointsIter(src, camera.K, camera.dist_coeffs, None, P, criteria)
    else:  # OpenCV 5.x: undistortPoints takes the criteria directly
        out = cv2.undistortPoints(src, camera.K, camera.dist_coeffs, P=P, criteria=criteria)
    return out.reshape(-1, 2)


def points_in_view(camera: PinholeRadtan, rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) points in front of the camera whose rays pass through random pixels of the image."""
    uv = rng.uniform([0.0, 0.0], [camera.width - 1.0, camera.height - 1.0], size=(n, 2))
    xy = opencv_undistort_tight(uv, camera)
    depth = rng.uniform(0.5, 20.0, size=n)
    return np.concatenate([xy * depth[:, None], depth[:, None]], axis=1)


# ---------------------------------------------------------------- construction
def test_davis240c_values_and_opencv_order():
    cam = PinholeRadtan.davis240c()
    assert (cam.width, cam.height) == (240, 180)
    np.testing.assert_allclose(
        cam.K, [[199.092366542, 0.0, 132.192071378], [0.0, 198.82882047, 110.712660011], [0.0, 0.0, 1.0]]
    )
    np.testing.assert_allclose(
        cam.dist_coeffs, [-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0]
    )
    assert cam.K.shape == (3, 3) and cam.dist_coeffs.shape == (5,)


def test_camera_is_frozen_and_hashable():
    cam = PinholeRadtan.davis240c()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.fx = 1.0
    assert cam == PinholeRadtan.davis240c() and hash(cam) == hash(PinholeRadtan.davis240c())
    cam.K[0, 0] = 0.0  # K is a fresh copy each time, so this must not change the camera
    assert cam.K[0, 0] == pytest.approx(199.092366542)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"fx": 0.0}, "fx must be a positive focal length"),
        ({"fy": -5.0}, "fy must be a positive focal length"),
        ({"cx": float("nan")}, "cx must be a finite real number"),
        ({"k1": float("inf")}, "k1 must be a finite real number"),
        ({"p2": "0.1"}, "p2 must be a finite real number"),
        ({"width": 0}, "width must be a positive integer"),
        ({"height": 180.5}, "height must be a positive integer"),
        ({"height": float("inf")}, "height must be a positive integer"),
        ({"width": -240}, "width must be a positive integer"),
        ({"width": True}, "width must be a positive integer"),
    ],
)
def test_constructor_rejects_bad_parameters(kwargs, match):
    params = dict(fx=200.0, fy=200.0, cx=120.0, cy=90.0, width=240, height=180)
    params.update(kwargs)
    with pytest.raises(ValueError, match=match):
        PinholeRadtan(**params)


def test_constructor_accepts_numpy_scalars():
    cam = PinholeRadtan(fx=np.float32(200.0), fy=np.float64(200.0), cx=120, cy=90.0, width=np.int64(240), height=180.0)
    assert type(cam.fx) is float and type(cam.width) is int and type(cam.height) is int
    assert cam == PinholeRadtan(fx=200.0, fy=200.0, cx=120.0, cy=90.0, width=240, height=180)


# ---------------------------------------------------------------- projection vs OpenCV
def test_project_matches_opencv_projectpoints(camera, rng):
    points_C = points_in_view(camera, rng, 2000)
    # also points somewhat outside the field of view, where the polynomial is still well behaved
    points_C = np.concatenate([points_C, np.c_[rng.uniform(-0.3, 0.3, (200, 2)), np.ones(200)]])
    uv = camera.project(points_C)
    uv_cv, _ = cv2.projectPoints(points_C, np.zeros(3), np.zeros(3), camera.K, camera.dist_coeffs)
    assert uv.shape == (points_C.shape[0], 2)
    np.testing.assert_allclose(uv, uv_cv.reshape(-1, 2), atol=1e-6, rtol=0)


def test_project_pinhole_by_hand():
    cam = PinholeRadtan(fx=100.0, fy=120.0, cx=50.0, cy=40.0, width=100, height=80)
    # u = fx X / Z + cx, v = fy Y / Z + cy
    np.testing.assert_allclose(cam.project([1.0, -2.0, 4.0]), [100.0 * 0.25 + 50.0, 120.0 * -0.5 + 40.0])


def test_project_is_scale_invariant(rng):
    cam = PinholeRadtan.davis240c()
    points_C = points_in_view(cam, rng, 50)
    np.testing.assert_allclose(cam.project(points_C), cam.project(3.7 * points_C), atol=1e-10)


def test_normalized_to_pixels_matches_project(camera, rng):
    points_C = points_in_view(camera, rng, 100)
    xy = points_C[:, :2] / points_C[:, 2:]
    np.testing.assert_allclose(camera.normalized_to_pixels(xy), camera.project(points_C), atol=1e-9)


def test_distort_normalized_closed_form():
    k1, k2, p1, p2, k3 = 0.1, 0.01, 0.002, 0.003, 0.001
    cam = PinholeRadtan(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=1, height=1, k1=k1, k2=k2, p1=p1, p2=p2, k3=k3)
    x, y = 0.3, -0.4
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    expected = [
        x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
    ]
    np.testing.assert_allclose(cam.distort_normalized([x, y]), expected, rtol=1e-14)


# ---------------------------------------------------------------- unprojection vs OpenCV and round trips
def test_unproject_matches_converged_opencv_on_full_grid(camera):
    """Compares with cv2.undistortPoints run to convergence (tight criteria), over every pixel incl. the corners."""
    uv = pixel_grid(camera)
    xy = camera.unproject(uv)
    np.testing.assert_allclose(xy, opencv_undistort_tight(uv, camera), atol=1e-8, rtol=0)


def test_unproject_round_trip_on_full_grid(camera):
    uv = pixel_grid(camera)
    xy = camera.unproject(uv)
    np.testing.assert_allclose(camera.normalized_to_pixels(xy), uv, atol=1e-8, rtol=0)


def test_undistort_normalized_inverts_distort(camera, rng):
    uv = rng.uniform([0.0, 0.0], [camera.width - 1.0, camera.height - 1.0], size=(500, 2))
    xy = opencv_undistort_tight(uv, camera)  # undistorted normalised coordinates inside the field of view
    np.testing.assert_allclose(camera.undistort_normalized(camera.distort_normalized(xy)), xy, atol=1e-10, rtol=0)


def test_undistort_normalized_iterations_matter():
    cam = PinholeRadtan.davis240c()
    corner_d = (np.array([0.0, 0.0]) - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    one_step = cam.undistort_normalized(corner_d, iterations=1)
    converged = cam.undistort_normalized(corner_d)
    assert np.abs(cam.distort_normalized(converged) - corner_d).max() < 1e-14
    assert np.abs(cam.distort_normalized(one_step) - corner_d).max() > 1e-6


def test_undistort_points_matches_opencv_with_P_equal_K(camera, rng):
    uv = np.concatenate([pixel_grid(camera)[::97], rng.uniform(0, [camera.width - 1, camera.height - 1], (300, 2))])
    expected = opencv_undistort_tight(uv, camera, P=camera.K)
    np.testing.assert_allclose(camera.undistort_points(uv), expected, atol=1e-6, rtol=0)


def test_pixel_rays_are_unit_and_project_back(camera, rng):
    uv = rng.uniform(0, [camera.width - 1, camera.height - 1], (400, 2))
    rays = camera.pixel_rays(uv)
    assert rays.shape == (400, 3)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-14)
    assert np.all(rays[:, 2] > 0)
    np.testing.assert_allclose(camera.project(rays * 5.0), uv, atol=1e-8)


def test_principal_point_ray_is_optical_axis():
    cam = PinholeRadtan.davis240c()
    np.testing.assert_allclose(cam.pixel_rays([cam.cx, cam.cy]), [0.0, 0.0, 1.0], atol=1e-15)


# ---------------------------------------------------------------- whole-image helpers
def test_normalized_grid_layout_cache_and_read_only():
    cam = PinholeRadtan.davis240c()
    grid = cam.normalized_grid()
    assert grid.shape == (180, 240, 2) and grid.dtype == np.float64
    assert grid is cam.normalized_grid()  # computed once
    assert not grid.flags.writeable
    with pytest.raises(ValueError):
        grid[0, 0, 0] = 1.0
    # entry [v, u] is pixel column u, row v
    np.testing.assert_allclose(grid[10, 200], cam.unproject([200.0, 10.0]), atol=1e-15)
    np.testing.assert_allclose(grid.reshape(-1, 2), opencv_undistort_tight(pixel_grid(cam), cam), atol=1e-8)


def test_undistort_image_matches_opencv(camera, rng):
    noise = rng.random((camera.height, camera.width)).astype(np.float32)
    image = cv2.GaussianBlur(noise, (0, 0), 2.0)
    ours = camera.undistort_image(image)
    assert ours.shape == image.shape and ours.dtype == np.float32
    # Same float32 tables as OpenCV's own map -> identical remap.
    map_x, map_y = cv2.initUndistortRectifyMap(
        camera.K, camera.dist_coeffs, None, camera.K, (camera.width, camera.height), cv2.CV_32FC1
    )
    reference = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    np.testing.assert_allclose(ours, reference, atol=1e-6)
    # cv2.undistort itself interpolates with fixed-point (1/32 pixel) tables, hence the small tolerance; compared
    # where all four interpolation neighbours exist (the two differ in how they treat the half-pixel rim).
    diff = np.abs(ours - cv2.undistort(image, camera.K, camera.dist_coeffs))
    inside = camera.in_image(np.stack([map_x.ravel(), map_y.ravel()], axis=1)).reshape(image.shape)
    assert inside.mean() > 0.5
    assert diff[inside].max() < 3e-3 and diff[inside].mean() < 5e-4


def test_undistort_image_recovers_pattern_of_ideal_pixels():
    """Raw image = known function of the UNdistorted pixel position; undistorting must give that function back."""
    cam = PinholeRadtan.davis240c()

    def pattern(uv):  # smooth stripes in the ideal (undistorted) image
        return 0.5 + 0.4 * np.sin(uv[:, 0] / 6.0) * np.cos(uv[:, 1] / 9.0)

    uv_raw = pixel_grid(cam)
    raw = pattern(opencv_undistort_tight(uv_raw, cam, P=cam.K)).reshape(cam.height, cam.width).astype(np.float32)
    ideal = cam.undistort_image(raw)
    uv_ideal = pixel_grid(cam)
    sampled_at = cam.normalized_to_pixels((uv_ideal - [cam.cx, cam.cy]) / [cam.fx, cam.fy])
    inside = cam.in_image(sampled_at, border=1.0)
    error = np.abs(ideal.reshape(-1) - pattern(uv_ideal))[inside]
    assert inside.mean() > 0.8
    assert error.max() < 0.01  # bilinear interpolation error of a smooth pattern


def test_undistort_image_dtypes_and_channels():
    cam = PinholeRadtan.davis240c()
    gray_u8 = np.full((180, 240), 200, dtype=np.uint8)
    out = cam.undistort_image(gray_u8)
    assert out.dtype == np.uint8 and out[90, 120] == 200
    rgb = np.zeros((180, 240, 3), dtype=np.float32)
    rgb[..., 1] = 0.25
    out = cam.undistort_image(rgb, interpolation=cv2.INTER_NEAREST)
    assert out.shape == (180, 240, 3) and out[90, 120, 1] == np.float32(0.25)
    assert cam.undistort_image(np.ones((180, 240, 1), np.float32)).shape == (180, 240, 1)


def test_undistort_image_does_not_modify_input():
    cam = PinholeRadtan.davis240c()
    image = np.random.default_rng(3).random((180, 240)).astype(np.float32)
    copy = image.copy()
    cam.undistort_image(image)
    np.testing.assert_array_equal(image, copy)


def test_undistort_image_rejects_bad_input():
    cam = PinholeRadtan.davis240c()
    with pytest.raises(ValueError, match=r"image must have shape \(180, 240\)"):
        cam.undistort_image(np.zeros((240, 180), np.float32))
    with pytest.raises(ValueError, match="image must have dtype"):
        cam.undistort_image(np.zeros((180, 240), np.int64))


def test_in_image_boundaries():
    cam = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
    uv = np.array([[0.0, 0.0], [99.0, 79.0], [-0.01, 5.0], [99.01, 5.0], [5.0, 79.5], [2.0, 2.0]])
    np.testing.assert_array_equal(cam.in_image(uv), [True, True, False, False, False, True])
    np.testing.assert_array_equal(cam.in_image(uv, border=2.0), [False, False, False, False, False, True])
    assert cam.in_image(uv).shape == (6,)
    assert bool(cam.in_image([50.0, 40.0])) is True
    with pytest.raises(ValueError, match="border must be a finite number"):
        cam.in_image(uv, border=float("nan"))


# ---------------------------------------------------------------- scaling
def test_scaled_camera_sees_the_same_lens(rng):
    cam = PinholeRadtan.davis240c()
    points_C = points_in_view(cam, rng, 100)
    for factor in (2.0, 0.5, 4):
        big = cam.scaled(factor)
        assert (big.width, big.height) == (int(240 * factor), int(180 * factor))
        # pixel centres at integer coordinates: u' = s (u + 1/2) - 1/2
        np.testing.assert_allclose(big.project(points_C), factor * (cam.project(points_C) + 0.5) - 0.5, atol=1e-9)
        np.testing.assert_allclose(big.dist_coeffs, cam.dist_coeffs)
    assert cam.scaled(1.0) == cam


def test_scaled_block_average_matches_original_pixel():
    """A 2x sensor's 2x2 block of pixels averages to the centre of the original pixel."""
    cam = PinholeRadtan(fx=100.0, fy=100.0, cx=49.5, cy=39.5, width=100, height=80)
    big = cam.scaled(2)
    ray = np.array([0.1, -0.05, 1.0])
    u, v = cam.project(ray)
    u2, v2 = big.project(ray)
    assert (u2 + 0.5) / 2 - 0.5 == pytest.approx(u) and (v2 + 0.5) / 2 - 0.5 == pytest.approx(v)


@pytest.mark.parametrize("factor, match", [(0.0, "factor must be a positive"), (-1.0, "factor must be a positive"),
                                           (float("nan"), "factor must be a positive"),
                                           (0.33, "whole number of pixels")])
def test_scaled_rejects_bad_factor(factor, match):
    with pytest.raises(ValueError, match=match):
        PinholeRadtan.davis240c().scaled(factor)


# ---------------------------------------------------------------- Jacobian
def test_projection_jacobian_matches_finite_differences(camera, rng):
    points_C = points_in_view(camera, rng, 200)
    jac = camera.projection_jacobian(points_C)
    assert jac.shape == (200, 2, 3)
    step = 1e-6 * points_C[:, 2:3]  # relative step: the Jacobian scales with 1/Z
    numeric = np.empty_like(jac)
    for axis in range(3):
        delta = np.zeros_like(points_C)
        delta[:, axis] = step[:, 0]
        numeric[:, :, axis] = (camera.project(points_C + delta) - camera.project(points_C - delta)) / (2 * step)
    scale = np.abs(jac).max(axis=(1, 2), keepdims=True)
    assert np.abs(jac - numeric).max() < 1e-6 * scale.max()
    np.testing.assert_allclose(jac, numeric, atol=1e-6 * scale.max(), rtol=1e-6)


def test_projection_jacobian_pinhole_closed_form():
    cam = PinholeRadtan(fx=100.0, fy=120.0, cx=50.0, cy=40.0, width=100, height=80)
    X, Y, Z = 0.4, -0.2, 2.0
    expected = [[100.0 / Z, 0.0, -100.0 * X / Z**2], [0.0, 120.0 / Z, -120.0 * Y / Z**2]]
    np.testing.assert_allclose(cam.projection_jacobian([X, Y, Z]), expected, rtol=1e-14)


# ---------------------------------------------------------------- shapes and bad input
def test_single_points_return_matching_shapes():
    cam = PinholeRadtan.davis240c()
    assert cam.project([0.1, 0.2, 1.0]).shape == (2,)
    assert cam.normalized_to_pixels([0.1, 0.2]).shape == (2,)
    assert cam.distort_normalized([0.1, 0.2]).shape == (2,)
    assert cam.undistort_normalized([0.1, 0.2]).shape == (2,)
    assert cam.unproject([10.0, 20.0]).shape == (2,)
    assert cam.undistort_points([10.0, 20.0]).shape == (2,)
    assert cam.pixel_rays([10.0, 20.0]).shape == (3,)
    assert cam.projection_jacobian([0.1, 0.2, 1.0]).shape == (2, 3)


def test_empty_inputs_give_empty_outputs():
    cam = PinholeRadtan.davis240c()
    assert cam.project(np.zeros((0, 3))).shape == (0, 2)
    assert cam.unproject(np.zeros((0, 2))).shape == (0, 2)
    assert cam.pixel_rays(np.zeros((0, 2))).shape == (0, 3)
    assert cam.projection_jacobian(np.zeros((0, 3))).shape == (0, 2, 3)
    assert cam.in_image(np.zeros((0, 2))).shape == (0,)


def test_inputs_are_not_modified(rng):
    cam = PinholeRadtan.davis240c()
    points_C = points_in_view(cam, rng, 20)
    uv = cam.project(points_C)
    points_copy, uv_copy = points_C.copy(), uv.copy()
    cam.projection_jacobian(points_C)
    cam.unproject(uv)
    cam.undistort_normalized(uv / 200.0)
    cam.pixel_rays(uv)
    np.testing.assert_array_equal(points_C, points_copy)
    np.testing.assert_array_equal(uv, uv_copy)


def test_points_behind_camera_are_rejected_with_count():
    cam = PinholeRadtan.davis240c()
    points_C = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.1, 0.0, -2.0], [0.0, 0.1, 3.0]])
    with pytest.raises(ValueError, match=r"2 of 4 point\(s\) have Z <= 0, first at index 1"):
        cam.project(points_C)
    with pytest.raises(ValueError, match=r"Z <= 0"):
        cam.projection_jacobian(points_C)


@pytest.mark.parametrize(
    "method, value, match",
    [
        ("project", np.zeros((5, 2)), r"points_C must have shape \(N, 3\) or \(3,\); got \(5, 2\)"),
        ("project", np.array([[0.0, np.nan, 1.0]]), "points_C must be finite; found 1 row"),
        ("projection_jacobian", np.ones((2, 3, 1)), r"points_C must have shape \(N, 3\)"),
        ("unproject", np.zeros((3,)), r"uv must have shape \(N, 2\) or \(2,\); got \(3,\)"),
        ("unproject", np.array([[1.0, np.inf]]), "uv must be finite"),
        ("pixel_rays", np.zeros((4, 3)), r"uv must have shape \(N, 2\)"),
        ("undistort_points", [[1.0, 2.0, 3.0]], r"uv must have shape \(N, 2\)"),
        ("in_image", np.array([[np.nan, 1.0]]), "uv must be finite"),
        ("distort_normalized", np.zeros((2, 2, 2)), r"xy must have shape \(N, 2\)"),
        ("normalized_to_pixels", np.array([[np.nan, 0.0]]), "xy must be finite"),
        ("undistort_normalized", np.zeros((1, 3)), r"xy_d must have shape \(N, 2\)"),
    ],
)
def test_bad_points_are_rejected(method, value, match):
    cam = PinholeRadtan.davis240c()
    with pytest.raises(ValueError, match=match):
        getattr(cam, method)(value)


def test_undistort_normalized_rejects_bad_options():
    cam = PinholeRadtan.davis240c()
    with pytest.raises(ValueError, match="iterations must be a positive integer"):
        cam.undistort_normalized([0.1, 0.1], iterations=0)
    with pytest.raises(ValueError, match="tol must be a finite non-negative number"):
        cam.undistort_normalized([0.1, 0.1], tol=-1.0)


def test_no_distortion_is_plain_pinhole(rng):
    cam = CAMERAS["pinhole"]
    xy = rng.normal(size=(50, 2))
    np.testing.assert_array_equal(cam.distort_normalized(xy), xy)
    np.testing.assert_array_equal(cam.undistort_normalized(xy), xy)
