"""Tests of evio_lib.sim.aps (grayscale APS frames: motion blur, noise, saturation, gamma, 8 bits)."""
import numpy as np
import pytest

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import so3_exp
from evio_lib.sim.aps import (
    ApsParams,
    aps_exposure,
    aps_sensor_response,
    choose_n_subframes,
    exposure_sample_times,
    render_aps_frame,
    render_aps_frames,
)
from evio_lib.sim.scene import Scene, TexturedPlane, indoor_room
from evio_lib.sim.textures import procedural_texture, rescale_contrast

R_LOOK_PLUS_Y = np.column_stack([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
NOISELESS = dict(read_noise_sigma=0.0, shot_noise_scale=0.0)


@pytest.fixture(scope="module")
def camera() -> PinholeRadtan:
    return PinholeRadtan.davis240c().scaled(0.5)  # 120 x 90: keeps the tests fast


@pytest.fixture(scope="module")
def wall_scene() -> Scene:
    """A textured wall 3 m in front of a camera at the origin looking along +z."""
    texture = rescale_contrast(procedural_texture("rectangles", (256, 256), seed=5, scale_px=16), 0.05, 0.95)
    return Scene([TexturedPlane([-4.0, -4.0, 3.0], [8.0, 0, 0], [0, 8.0, 0], texture)])


def rotating(rate_rad_s: float):
    """Return pose_at for a camera at the origin turning about its y axis (pan) at ``rate_rad_s``."""
    def pose_at(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R = np.stack([so3_exp([0.0, rate_rad_s * t, 0.0]) for t in times])
        return R, np.zeros((len(times), 3))
    return pose_at


def gradient_energy(frame: np.ndarray) -> float:
    gy, gx = np.gradient(frame.astype(np.float64))
    return float(np.mean(gx**2 + gy**2))


def test_params_validation():
    with pytest.raises(ValueError, match="exposure_s must be a finite positive number"):
        ApsParams(exposure_s=0.0)
    with pytest.raises(ValueError, match="read_noise_sigma must be a finite non-negative number"):
        ApsParams(read_noise_sigma=-0.1)
    with pytest.raises(ValueError, match="n_subframes must be an int >= 0"):
        ApsParams(n_subframes=1.5)
    with pytest.raises(ValueError, match="gamma"):
        ApsParams(gamma=np.nan)
    assert ApsParams(**NOISELESS).noiseless and not ApsParams().noiseless


def test_exposure_sample_times_are_midpoints():
    times = exposure_sample_times(2.0, 0.01, 4)
    np.testing.assert_allclose(times, [1.99625, 1.99875, 2.00125, 2.00375])
    assert times.mean() == pytest.approx(2.0)
    with pytest.raises(ValueError, match="n must be an int >= 1"):
        exposure_sample_times(0.0, 0.01, 0)


def test_static_camera_gives_the_quantised_render(camera, wall_scene):
    params = ApsParams(**NOISELESS)
    frame = render_aps_frame(wall_scene, camera, rotating(0.0), 0.3, params, None)
    assert frame.shape == (90, 120) and frame.dtype == np.uint8
    image = wall_scene.render_intensity(camera, np.eye(3), np.zeros(3)).astype(np.float64)
    expected = np.round(255.0 * np.clip(image, 0.0, 1.0) ** (1 / 2.2)).astype(np.uint8)  # independent formula
    assert np.abs(frame.astype(int) - expected).max() <= 1
    assert np.mean(frame == expected) > 0.999
    assert choose_n_subframes(wall_scene, camera, rotating(0.0), 0.3, params) == 1


def test_exposure_is_the_mean_of_sub_renders(camera, wall_scene):
    params = ApsParams(exposure_s=0.02, n_subframes=5, **NOISELESS)
    pose_at = rotating(1.0)
    exposure = aps_exposure(wall_scene, camera, pose_at, 0.5, params)
    R, p = pose_at(exposure_sample_times(0.5, 0.02, 5))
    manual = np.mean([wall_scene.render_intensity(camera, Ri, pi) for Ri, pi in zip(R, p)], axis=0)
    np.testing.assert_allclose(exposure, manual, atol=1e-6)
    linear = render_aps_frame(wall_scene, camera, pose_at, 0.5, ApsParams(exposure_s=0.02, n_subframes=5, gamma=1.0,
                                                                        **NOISELESS), None)
    np.testing.assert_allclose(linear / 255.0, manual, atol=0.5 / 255 + 1e-6)


def test_blur_grows_with_angular_speed(camera, wall_scene):
    params = ApsParams(exposure_s=0.02, **NOISELESS)
    energies = [gradient_energy(render_aps_frame(wall_scene, camera, rotating(rate), 0.1, params, None))
                for rate in (0.0, 0.5, 3.0)]
    assert energies[0] > energies[1] > energies[2]
    assert energies[2] < 0.6 * energies[0]
    # the automatic sub-render count follows the image motion: rate * T * f / 0.5 px, capped
    f = camera.fx
    n_slow = choose_n_subframes(wall_scene, camera, rotating(0.5), 0.1, params)
    assert n_slow == pytest.approx(np.ceil(0.5 * 0.02 * f / 0.5), abs=1)
    assert choose_n_subframes(wall_scene, camera, rotating(50.0), 0.1, params) == params.max_subframes
    # equal frames for a static camera, whatever the exposure
    a = render_aps_frame(wall_scene, camera, rotating(0.0), 0.1, ApsParams(exposure_s=0.001, **NOISELESS), None)
    b = render_aps_frame(wall_scene, camera, rotating(0.0), 0.1, ApsParams(exposure_s=0.05, **NOISELESS), None)
    np.testing.assert_array_equal(a, b)


def test_clipping_gain_and_dtype():
    params = ApsParams(gain=4.0, gamma=1.0, **NOISELESS)
    frame = aps_sensor_response(np.array([[0.0, 0.1, 0.2, 0.25, 0.5, 3.0]]), params, None)
    assert frame.dtype == np.uint8
    assert frame.tolist() == [[0, 102, 204, 255, 255, 255]]  # round(255 min(4 E, 1))
    clip = aps_sensor_response(np.array([[0.5, 1.0]]), ApsParams(clip=0.5, gamma=1.0, **NOISELESS), None)
    assert clip.tolist() == [[255, 255]]
    encoded = aps_sensor_response(np.array([[0.25]]), ApsParams(**NOISELESS), None)
    assert encoded[0, 0] == round(255 * 0.25 ** (1 / 2.2))
    with pytest.raises(ValueError, match=r"exposure must have shape \(H, W\)"):
        aps_sensor_response(np.zeros(3), params, None)


def test_noise_statistics_and_seeded_determinism():
    params = ApsParams(gamma=1.0, read_noise_sigma=0.01, shot_noise_scale=0.003)  # stronger than the defaults
    exposure = np.full((200, 200), 0.25)
    frame = aps_sensor_response(exposure, params, np.random.default_rng(7)).astype(np.float64) / 255.0
    expected_sigma = np.sqrt(0.003 * 0.25 + 0.01**2)  # sqrt(k S + sigma_read^2)
    assert frame.std() == pytest.approx(np.sqrt(expected_sigma**2 + 1 / 12 / 255**2), rel=0.05)
    assert frame.mean() == pytest.approx(0.25, abs=0.003)
    again = aps_sensor_response(exposure, params, np.random.default_rng(7))
    np.testing.assert_array_equal(again, aps_sensor_response(exposure, params, 7))
    assert not np.array_equal(again, aps_sensor_response(exposure, params, 8))
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator or an int seed when the noise is on"):
        aps_sensor_response(exposure, params, None)


def test_render_aps_frames_sequence(camera, wall_scene):
    params = ApsParams(exposure_s=0.005)
    times = np.array([0.1, 0.2, 0.3])
    frames = render_aps_frames(wall_scene, camera, rotating(0.3), times, params, np.random.default_rng(3))
    assert frames.shape == (3, 90, 120) and frames.dtype == np.uint8
    again = render_aps_frames(wall_scene, camera, rotating(0.3), times, params, np.random.default_rng(3))
    np.testing.assert_array_equal(frames, again)
    single = render_aps_frame(wall_scene, camera, rotating(0.3), 0.1, params, np.random.default_rng(3))
    np.testing.assert_array_equal(frames[0], single)  # one random stream, frames in order
    assert not np.array_equal(frames[0], frames[2])  # the camera turned
    with pytest.raises(ValueError, match=r"times must be a finite \(F,\) array"):
        render_aps_frames(wall_scene, camera, rotating(0.3), np.zeros((2, 2)), params, 0)


def test_pose_function_is_checked(camera, wall_scene):
    bad = lambda times: (np.eye(3), np.zeros(3))  # noqa: E731  (not batched)
    with pytest.raises(ValueError, match=r"pose_at\(times\) must return R_CtoG of shape"):
        render_aps_frame(wall_scene, camera, bad, 0.1, ApsParams(n_subframes=2, **NOISELESS), None)
    with pytest.raises(ValueError, match="params must be an ApsParams"):
        render_aps_frame(wall_scene, camera, rotating(0.0), 0.1, {"exposure_s": 0.01}, None)


def test_room_frame_is_plausible(camera):
    """A DAVIS-like frame of the room: full use of the 8 bits, saturation only with a large gain."""
    room = indoor_room(seed=0)

    def pose_at(times):
        R = np.stack([so3_exp([-0.25, 0.2 * t, 0.0]) @ R_LOOK_PLUS_Y for t in times])
        return R, np.tile([0.0, 0.0, 1.4], (len(times), 1))

    frame = render_aps_frame(room, camera, pose_at, 0.5, ApsParams(), np.random.default_rng(0))
    assert frame.std() > 20 and np.mean(frame == 255) < 0.01
    bright = render_aps_frame(room, camera, pose_at, 0.5, ApsParams(gain=3.0), np.random.default_rng(0))
    assert np.mean(bright == 255) > 0.1
