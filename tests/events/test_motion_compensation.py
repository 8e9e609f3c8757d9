"""Motion-compensated event frames against a closed form (pure rotation), the gyro integrator and real ECD slices."""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events.array import make_events
from evio_lib.events.motion_compensation import accumulate_bilinear, motion_compensated_frame, warp_events
from evio_lib.frontend.gyro_prior import gyro_orientations, integrate_gyro
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import so3_exp


def _rates(t: np.ndarray) -> np.ndarray:
    """A varying angular velocity in the IMU frame, rad/s (axis and speed change over the window)."""
    t = np.asarray(t, dtype=np.float64)
    return np.stack([1.0 + 0.5 * np.sin(3.0 * t), -2.0 + 0.0 * t, 0.8 * np.cos(5.0 * t)], axis=-1)


def _orientations(times: np.ndarray, step: float = 1e-5) -> np.ndarray:
    """R_ItoG at ``times`` with R_ItoG(0) = I, integrated finely (midpoint rule) from the continuous rates."""
    n = int(np.ceil(np.max(times) / step)) + 1
    steps = so3_exp(_rates((np.arange(n) + 0.5) * step) * step)
    grid = np.empty((n + 1, 3, 3))
    grid[0] = np.eye(3)
    for k in range(n):
        grid[k + 1] = grid[k] @ steps[k]
    k = np.floor(np.asarray(times) / step).astype(int)
    rest = np.asarray(times) - k * step
    return grid[k] @ so3_exp(_rates(k * step + 0.5 * rest) * rest[:, None])


R_CtoI = so3_exp(np.array([0.3, -1.2, 0.4]))  # a camera turned with respect to the IMU


@pytest.fixture(scope="module")
def camera() -> PinholeRadtan:
    return PinholeRadtan.davis240c()  # with radial-tangential distortion


def test_gyro_orientations_follow_the_continuous_rotation():
    """The cumulative gyro integration that the warp reads (frontend.gyro_prior.gyro_orientations) against the
    fine integration of the continuous rates, at every breakpoint; its end is integrate_gyro's rotation."""
    imu_t = np.arange(0.0, 1.0, 0.001)
    gyro = _rates(imu_t)
    breaks, A, w = gyro_orientations(imu_t, gyro, 0.1003, 0.1317)
    assert breaks[0] == 0.1003 and breaks[-1] == 0.1317 and np.all(np.diff(breaks) > 0)
    assert A.shape == (breaks.size, 3, 3) and w.shape == (breaks.size - 1, 3)
    R_ItoG = _orientations(breaks)
    expected = np.swapaxes(R_ItoG[0], -1, -2) @ R_ItoG  # R_{I(t) -> I(t_a)} = R_ItoG(t_a)^T R_ItoG(t)
    np.testing.assert_allclose(A, expected, atol=1e-6)
    np.testing.assert_array_equal(A[-1].T, integrate_gyro(imu_t, gyro, 0.1003, 0.1317))


def test_warp_matches_the_true_rotation_of_each_ray(camera):
    """Pure rotation: every event's ray, turned by the true camera rotation from t_e to t_ref, lands where
    warp_events puts it (the truth integrates the continuous rates finely; the IMU samples them at 1 kHz)."""
    rng = np.random.default_rng(0)
    imu_t = np.arange(0.0, 0.3, 0.001)
    gyro = _rates(imu_t)
    n = 300
    t_e = np.sort(rng.uniform(0.1, 0.14, n))
    x = rng.integers(10, 230, n)
    y = rng.integers(10, 170, n)
    events = make_events(t_e, x, y, np.ones(n))
    t_ref = 0.12
    warped = warp_events(events, camera, t_ref, imu_t, gyro, R_CtoI)

    R_ItoG = _orientations(np.concatenate([t_e, [t_ref]]))
    rays = camera.pixel_rays(np.stack([x, y], axis=1).astype(float))
    d_G = np.einsum("nij,jk,nk->ni", R_ItoG[:-1], R_CtoI, rays)  # each event's ray in the world frame
    expected = camera.project(d_G @ R_ItoG[-1] @ R_CtoI)  # seen from the camera at t_ref: R_CtoI^T R_ref^T d
    moved = np.linalg.norm(expected - np.stack([x, y], axis=1), axis=1)
    assert moved.max() > 5.0  # the rotation over 20 ms moves the rays by pixels: the test sees a wrong sign
    np.testing.assert_allclose(warped, expected, atol=0.02)


def test_no_rotation_or_the_reference_time_leaves_events_in_place(camera):
    events = make_events([0.1, 0.11, 0.12], [5, 100, 230], [7, 90, 170], [1, -1, 1])
    imu_t = np.arange(0.0, 0.3, 0.001)
    still = warp_events(events, camera, 0.12, imu_t, np.zeros((imu_t.size, 3)), R_CtoI)
    np.testing.assert_allclose(still, [[5, 7], [100, 90], [230, 170]], atol=1e-6)
    turning = warp_events(events, camera, 0.12, imu_t, _rates(imu_t), R_CtoI)
    np.testing.assert_allclose(turning[2], [230, 170], atol=1e-6)  # the event at t_ref stays
    assert np.linalg.norm(turning[0] - [5, 7]) > 1.0
    # a bias equal to the rates removes the rotation
    unbiased = warp_events(events, camera, 0.12, imu_t, np.tile([0.4, -0.3, 0.2], (imu_t.size, 1)), R_CtoI,
                           gyro_bias=[0.4, -0.3, 0.2])
    np.testing.assert_allclose(unbiased, still, atol=1e-9)


def test_accumulate_bilinear_conserves_the_points_inside():
    rng = np.random.default_rng(1)
    points = rng.uniform([-3.0, -3.0], [43.0, 33.0], (2000, 2))
    image = accumulate_bilinear(points, 40, 30)
    assert image.shape == (30, 40) and image.dtype == np.float32
    inside = (points[:, 0] >= 0) & (points[:, 0] <= 39) & (points[:, 1] >= 0) & (points[:, 1] <= 29)
    partly = (points[:, 0] > -1) & (points[:, 0] < 40) & (points[:, 1] > -1) & (points[:, 1] < 30)
    assert inside.sum() - 1e-3 <= image.sum() <= partly.sum() + 1e-3
    one = accumulate_bilinear([[3.0, 4.0], [3.5, 4.5]], 8, 8)
    assert one[4, 3] == pytest.approx(1.25) and one[5, 4] == pytest.approx(0.25) and one.sum() == pytest.approx(2.0)
    assert accumulate_bilinear(np.zeros((0, 2)), 5, 4).sum() == 0.0


def test_frame_is_scaled_to_unit_range_and_checks_its_options(camera):
    rng = np.random.default_rng(2)
    events = make_events(np.sort(rng.uniform(0.1, 0.11, 5000)), rng.integers(0, 240, 5000),
                         rng.integers(0, 180, 5000), np.ones(5000))
    imu_t = np.arange(0.0, 0.3, 0.001)
    frame = motion_compensated_frame(events, camera, 0.11, imu_t, _rates(imu_t), R_CtoI)
    assert frame.shape == (180, 240) and frame.dtype == np.float32
    assert frame.min() >= 0.0 and frame.max() == pytest.approx(1.0)
    empty = motion_compensated_frame(events[:0], camera, 0.11, imu_t, _rates(imu_t), R_CtoI)
    assert empty.shape == (180, 240) and not empty.any()
    with pytest.raises(ValueError, match="saturation_quantile"):
        motion_compensated_frame(events, camera, 0.11, imu_t, _rates(imu_t), R_CtoI, saturation_quantile=0.0)
    with pytest.raises(ValueError, match="blur_sigma_px"):
        motion_compensated_frame(events, camera, 0.11, imu_t, _rates(imu_t), R_CtoI, blur_sigma_px=-1.0)


@pytest.mark.parametrize("name", ["boxes_rotation", "dynamic_rotation", "poster_rotation", "shapes_rotation"])
def test_real_rotation_slices_get_sharper(real_data_dir, name):
    """Real ECD slices (DAVIS240C, rotation only) with the angular velocity estimated upstream: warping with it
    sharpens the image of events (higher variance, the contrast-maximisation measure); warping with its opposite
    blurs it. Measured: variance up 16-180 % with the rate, down 31-37 % with its opposite."""
    from evio_lib.io.ecd import read_calib, read_ecd_events

    folder = real_data_dir / "ecd_rotation_slices" / name
    events = read_ecd_events(folder / "events.txt", sensor_size=(240, 180))
    camera = read_calib(folder / "calib.txt", 240, 180)
    w_C = np.loadtxt(folder / "motion.txt")  # rad/s in the camera frame: an IMU aligned with the camera
    imu_t = np.array([events["t"][0] - 0.01, events["t"][-1] + 0.01])

    def variance(sign: float) -> float:
        pixels = warp_events(events, camera, float(events["t"][-1]), imu_t, np.tile(sign * w_C, (2, 1)), np.eye(3))
        return float(accumulate_bilinear(pixels, 240, 180).var())

    plain, compensated, opposite = variance(0.0), variance(1.0), variance(-1.0)
    assert compensated > 1.1 * plain
    assert opposite < 0.8 * plain


@pytest.mark.parametrize("blur", [0.0, 0.75])
def test_numba_kernel_makes_the_numpy_frame(camera, monkeypatch, blur):
    """The compiled warp-and-count (events.warp_kernels) against the NumPy reference: the same frame up to the
    rounding of the sums, on a distorted camera, with events off the sensor after the warp, before and after t_ref,
    and with a gyro bias."""
    pytest.importorskip("numba")
    from evio_lib.events.motion_compensation import mc_backend

    rng = np.random.default_rng(5)
    n = 40000
    events = make_events(np.sort(rng.uniform(0.1, 0.13, n)), rng.integers(0, 240, n), rng.integers(0, 180, n),
                         rng.choice([-1, 1], n))
    imu_t = np.arange(0.0, 0.3, 0.001)
    gyro = 3.0 * _rates(imu_t)  # fast enough that the warp moves the border events off the sensor
    args = (events, camera, 0.117, imu_t, gyro, R_CtoI, np.array([0.01, -0.02, 0.03]))
    frames, raw = {}, {}
    for backend in ("numpy", "numba"):
        monkeypatch.setenv("EVIO_MC_BACKEND", backend)
        assert mc_backend() == backend
        frames[backend] = motion_compensated_frame(*args, blur_sigma_px=blur, saturation_quantile=1.0)
    np.testing.assert_allclose(frames["numba"], frames["numpy"], atol=1e-6)
    from evio_lib.events.motion_compensation import _interval_rotations
    from evio_lib.events.warp_kernels import warp_and_count

    breaks, w_C, M = _interval_rotations(events["t"], 0.117, imu_t, gyro, R_CtoI, args[-1])
    intrinsics = np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.k1, camera.k2, camera.p1, camera.p2,
                           camera.k3])
    counts = warp_and_count(events["x"], events["y"], events["t"], camera.normalized_grid().reshape(-1, 2), breaks,
                            w_C, M.reshape(-1, 9), intrinsics, 240, 180)
    reference = accumulate_bilinear(warp_events(*args), 240, 180)
    np.testing.assert_allclose(counts, reference, atol=1e-4)  # float32 reference
    assert 0.5 * n < counts.sum() < n - 100  # most events land, some leave the sensor
    bad_gyro = gyro.copy()
    bad_gyro[110:120] = np.nan
    monkeypatch.setenv("EVIO_MC_BACKEND", "numba")
    with pytest.raises(ValueError, match="finite"):  # the gyro integrator refuses NaN rates
        motion_compensated_frame(events, camera, 0.117, imu_t, bad_gyro, R_CtoI)
    with pytest.raises(ValueError, match="sorted by time and lie on the 240 x 180 sensor"):
        motion_compensated_frame(events[::-1], camera, 0.117, imu_t, gyro, R_CtoI)
    monkeypatch.setenv("EVIO_MC_BACKEND", "gpu")
    with pytest.raises(ValueError, match="EVIO_MC_BACKEND must be one of auto, numba, numpy"):
        mc_backend()
