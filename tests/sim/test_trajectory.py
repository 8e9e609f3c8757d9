"""Tests of evio_lib.sim.trajectory (ground-truth trajectories) and evio_lib.sim.rig (camera-IMU extrinsics)."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import so3_exp, so3_log
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import (
    TimeScaledTrajectory,
    Trajectory,
    TrajectorySample,
    aerial_like,
    boxes_like,
    trajectory_from_preset,
)

PRESET_CASES = [
    ("boxes_like", boxes_like(duration=60.0, seed=3)),
    ("aerial_like", aerial_like(duration=40.0, seed=3)),
    ("boxes_like_10s", boxes_like(duration=10.0, seed=1)),
    ("aerial_like_10s", aerial_like(duration=10.0, seed=1)),
    ("boxes_like_twice_as_fast", TimeScaledTrajectory(boxes_like(duration=20.0, seed=2), 2.0)),
    ("aerial_like_slower", TimeScaledTrajectory(aerial_like(duration=10.0, seed=2), 0.5)),
]


def _fd4(f, t, h):
    """4th-order central difference of f (array-valued) at times t: (-f(t+2h) + 8 f(t+h) - 8 f(t-h) + f(t-2h)) / 12h."""
    return (-f(t + 2 * h) + 8 * f(t + h) - 8 * f(t - h) + f(t - 2 * h)) / (12 * h)


def _step(traj: Trajectory, h: float) -> float:
    """A finite-difference step h of a preset's own clock, on the clock of ``traj`` (shorter when played faster, so
    the truncation error stays that of the preset)."""
    return h / getattr(traj, "speed", 1.0)


def _query_times(traj: Trajectory, n: int = 40) -> np.ndarray:
    rng = np.random.default_rng(7)
    return np.sort(rng.uniform(traj.t_start + 0.01, traj.t_end - 0.01, n))


# ------------------------------------------------------------------------------------------------ trajectory basics
@pytest.mark.parametrize("name,traj", PRESET_CASES)
def test_evaluate_shapes_and_rotation_validity(name, traj):
    s = traj.evaluate(_query_times(traj, 25))
    assert isinstance(s, TrajectorySample) and len(s) == 25
    assert s.t.shape == (25,)
    for arr in (s.p_IinG, s.v_IinG, s.a_IinG, s.w_I, s.dw_I):
        assert arr.shape == (25, 3) and np.all(np.isfinite(arr))
    assert s.R_ItoG.shape == (25, 3, 3)
    eye = np.broadcast_to(np.eye(3), (25, 3, 3))
    np.testing.assert_allclose(s.R_ItoG @ np.swapaxes(s.R_ItoG, 1, 2), eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(s.R_ItoG), 1.0, atol=1e-12)
    one = traj.evaluate(traj.t_start)  # a float gives a batch of one
    assert len(one) == 1 and one.p_IinG.shape == (1, 3)
    assert traj.duration == pytest.approx(traj.t_end - traj.t_start)


@pytest.mark.parametrize("name,traj", PRESET_CASES)
def test_velocity_and_acceleration_are_derivatives_of_position(name, traj):
    t = _query_times(traj)
    s = traj.evaluate(t)
    h = _step(traj, 5e-4)
    v_fd = _fd4(lambda x: traj.evaluate(x).p_IinG, t, h)
    a_fd = _fd4(lambda x: traj.evaluate(x).v_IinG, t, h)
    np.testing.assert_allclose(s.v_IinG, v_fd, rtol=0, atol=2e-8)
    np.testing.assert_allclose(s.a_IinG, a_fd, rtol=0, atol=2e-7)


@pytest.mark.parametrize("name,traj", PRESET_CASES)
def test_angular_velocity_is_derivative_of_orientation(name, traj):
    """w_I vs finite differences of R_ItoG: log(R(t-h)^T R(t+h)) = 2h w_I + c h^3 + O(h^5), Richardson-combined."""
    t = _query_times(traj)
    s = traj.evaluate(t)

    def log_chord(h):
        Rm, Rp = traj.evaluate(t - h).R_ItoG, traj.evaluate(t + h).R_ItoG
        return so3_log(np.swapaxes(Rm, 1, 2) @ Rp)

    h = _step(traj, 5e-4)
    w_fd = (8 * log_chord(h) - log_chord(2 * h)) / (12 * h)  # cancels the h^3 term
    np.testing.assert_allclose(s.w_I, w_fd, rtol=0, atol=1e-8)
    # and the body-frame convention: dR/dt = R [w x] (not [w x] R)
    dR_fd = _fd4(lambda x: traj.evaluate(x).R_ItoG, t, _step(traj, 1e-3))
    w_skew = np.swapaxes(s.R_ItoG, 1, 2) @ dR_fd
    np.testing.assert_allclose(w_skew[:, 2, 1], s.w_I[:, 0], atol=1e-8)
    np.testing.assert_allclose(w_skew[:, 0, 2], s.w_I[:, 1], atol=1e-8)
    np.testing.assert_allclose(w_skew[:, 1, 0], s.w_I[:, 2], atol=1e-8)
    dw_fd = _fd4(lambda x: traj.evaluate(x).w_I, t, _step(traj, 5e-4))
    np.testing.assert_allclose(s.dw_I, dw_fd, rtol=0, atol=1e-6)


def test_derivatives_are_continuous_across_the_aerial_turn_boundaries():
    """The turn rolls in/out with C4 smoothsteps: w_I and a_IinG must have no jumps at the breakpoints."""
    traj = aerial_like(duration=40.0, seed=0, turbulence=0.0)
    t = np.linspace(0.0, 40.0, 40001)  # 1 ms steps; a jump would exceed the smooth change per step
    s = traj.evaluate(t)
    for arr, bound in ((s.w_I, 1e-3), (s.dw_I, 3e-3), (s.a_IinG, 1e-2)):
        assert np.abs(np.diff(arr, axis=0)).max() < bound


# ------------------------------------------------------------------------------------------------ preset properties
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_boxes_like_motion_grows_and_camera_sees_the_boxes(seed):
    traj = boxes_like(duration=60.0, seed=seed)
    t = np.linspace(0.0, 60.0, 12001)
    s = traj.evaluate(t)
    speed = np.linalg.norm(s.v_IinG, axis=1)
    rate = np.linalg.norm(s.w_I, axis=1)
    quarter, half = t < 15.0, t >= 30.0
    assert 0.15 < speed[quarter].mean() < 0.5 and speed[quarter].max() < 1.0
    assert 0.2 < rate[quarter].mean() < 0.7 and rate[quarter].max() < 1.2
    assert 2.5 < speed[half].max() < 5.0
    assert 3.5 < rate[half].max() < 7.0
    assert speed[half].mean() > 3 * speed[quarter].mean()
    assert np.linalg.norm(s.p_IinG - [0.0, 0.0, 1.4], axis=1).max() < 0.6
    R_CtoG, p_CinG = CameraImuExtrinsics.default().camera_pose(s.R_ItoG, s.p_IinG)
    axis, x_cam, y_cam = R_CtoG[:, :, 2], R_CtoG[:, :, 0], R_CtoG[:, :, 1]
    assert np.degrees(np.arccos(axis @ [0.0, 1.0, 0.0])).max() < 35.0  # looks toward +y (boxes, wall at y = 4)
    assert (x_cam @ [1.0, 0.0, 0.0]).min() > 0.8  # image x ≈ +x_G
    assert (y_cam @ [0.0, 0.0, -1.0]).min() > 0.8  # image down ≈ -z_G
    # every optical ray hits the wall y = 4 m inside the room (x in [-4, 4], z in [0, 3])
    lam = (4.0 - p_CinG[:, 1]) / axis[:, 1]
    hit = p_CinG + lam[:, None] * axis
    assert np.abs(hit[:, 0]).max() < 4.0 and hit[:, 2].min() > 0.0 and hit[:, 2].max() < 3.0


def test_boxes_like_duration_stretches_the_envelope():
    short, long_ = boxes_like(duration=20.0, seed=0), boxes_like(duration=60.0, seed=0)
    s_short = short.evaluate(np.linspace(0.0, 20.0, 4001))
    s_long = long_.evaluate(np.linspace(0.0, 60.0, 12001))
    peak_short = np.linalg.norm(s_short.v_IinG, axis=1).max()
    peak_long = np.linalg.norm(s_long.v_IinG, axis=1).max()
    assert peak_short == pytest.approx(peak_long, rel=0.35)  # same end intensity, reached over the whole duration
    first = np.linalg.norm(s_short.v_IinG[:1000], axis=1).mean()
    assert first < 0.25 * np.linalg.norm(s_short.v_IinG[-1000:], axis=1).mean()


def test_aerial_like_flight_turn_altitude_and_downward_camera():
    traj = aerial_like(duration=40.0, seed=0)
    t = np.linspace(0.0, 40.0, 4001)
    s = traj.evaluate(t)
    speed = np.linalg.norm(s.v_IinG, axis=1)
    assert np.all((speed > 19.0) & (speed < 21.0))
    assert np.abs(s.p_IinG[:, 2] - 250.0).max() < 3.0
    heading = np.degrees(np.unwrap(np.arctan2(s.v_IinG[:, 1], s.v_IinG[:, 0])))
    assert heading[-1] - heading[0] == pytest.approx(90.0, abs=3.0)
    straight = (t < 10.0) | (t > 30.0)
    assert np.abs(np.diff(heading[straight & (t < 10.0)])).max() < 0.05  # straight first (only turbulence)
    R_CtoG, _ = CameraImuExtrinsics.default().camera_pose(s.R_ItoG, s.p_IinG)
    off_nadir = np.degrees(np.arccos(R_CtoG[:, :, 2] @ [0.0, 0.0, -1.0]))
    assert off_nadir.max() < 35.0 and off_nadir[straight].max() < 8.0
    # image top = flight direction: -y_C points along the horizontal velocity
    fwd = -R_CtoG[:, :, 1]
    cos_fwd = np.einsum("ni,ni->n", fwd[:, :2], s.v_IinG[:, :2]) / (np.linalg.norm(fwd[:, :2], axis=1) * speed)
    assert cos_fwd.min() > 0.95


def test_aerial_like_turn_is_coordinated_with_25_degree_bank():
    """Independent check of the bank: tan(bank) = V * (heading rate of the velocity) / g, no side force."""
    traj = aerial_like(duration=40.0, seed=0, turbulence=0.0)
    s = traj.evaluate(np.linspace(0.0, 40.0, 801))
    v, a = s.v_IinG, s.a_IinG
    psi_dot = (v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0]) / (v[:, 0] ** 2 + v[:, 1] ** 2)
    wing_left = -s.R_ItoG[:, :, 0]  # aircraft y axis (left wing) = -x_I
    bank = np.arcsin(-wing_left[:, 2])  # positive = left wing down = banked into the (left) turn
    expected = np.arctan(np.linalg.norm(v, axis=1) * psi_dot / 9.81)
    np.testing.assert_allclose(bank, expected, atol=np.radians(0.1))
    assert np.degrees(bank).max() == pytest.approx(25.0, abs=0.5)
    assert np.abs(np.degrees(bank[:100])).max() < 1e-6  # level before the turn
    specific_force = a - [0.0, 0.0, -9.81]
    assert np.abs(np.einsum("ni,ni->n", specific_force, wing_left)).max() < 0.01  # no side force


@pytest.mark.parametrize("duration,turn_deg,bank_deg", [(10.0, 57.0, 30.0), (18.0, 90.0, 26.9), (60.0, 90.0, 25.0)])
def test_aerial_like_short_and_long_flights_keep_a_coordinated_turn(duration, turn_deg, bank_deg):
    traj = aerial_like(duration=duration, seed=2, turbulence=0.0)
    s = traj.evaluate(np.linspace(0.0, duration, 2001))
    heading = np.degrees(np.unwrap(np.arctan2(s.v_IinG[:, 1], s.v_IinG[:, 0])))
    assert heading[-1] - heading[0] == pytest.approx(turn_deg, abs=1.5)
    bank = np.degrees(np.arcsin(s.R_ItoG[:, 2, 0]))  # x_I = right wing: up = banked left, into the turn
    assert bank.max() == pytest.approx(bank_deg, abs=0.5)
    assert abs(bank[0]) < 1e-6 and abs(bank[-1]) < 1e-6  # straight and level at both ends
    assert np.abs(s.p_IinG[:, 2] - 250.0).max() < 1e-9


def test_presets_are_deterministic_per_seed():
    t = np.linspace(0.0, 20.0, 50)
    for factory in (boxes_like, aerial_like):
        s1, s2, s3 = factory(seed=5).evaluate(t), factory(seed=5).evaluate(t), factory(seed=6).evaluate(t)
        np.testing.assert_array_equal(s1.p_IinG, s2.p_IinG)
        np.testing.assert_array_equal(s1.R_ItoG, s2.R_ItoG)
        assert np.abs(s1.p_IinG - s3.p_IinG).max() > 1e-3


def test_trajectory_from_preset():
    assert trajectory_from_preset("boxes_like").duration == 60.0
    assert trajectory_from_preset("aerial_like", duration=30.0).duration == 30.0
    t = np.linspace(0.0, 10.0, 11)
    np.testing.assert_array_equal(
        trajectory_from_preset("boxes_like", duration=10.0, seed=4).evaluate(t).p_IinG,
        boxes_like(duration=10.0, seed=4).evaluate(t).p_IinG,
    )
    with pytest.raises(ValueError, match="name must be one of"):
        trajectory_from_preset("circle")


def test_time_scaled_trajectory_is_the_base_played_faster():
    """Same path and attitudes at speed * t; rates x speed, accelerations x speed^2 (the derivative tests above check
    that these are the derivatives of the scaled path)."""
    base = boxes_like(duration=60.0, seed=0)
    fast = trajectory_from_preset("boxes_like", seed=0, speed=2.5)
    assert isinstance(fast, TimeScaledTrajectory) and (fast.t_start, fast.t_end) == (0.0, 24.0)
    t = np.linspace(0.0, 24.0, 37)
    f, b = fast.evaluate(t), base.evaluate(2.5 * t)
    np.testing.assert_array_equal(f.p_IinG, b.p_IinG)
    np.testing.assert_array_equal(f.R_ItoG, b.R_ItoG)
    np.testing.assert_allclose(f.v_IinG, 2.5 * b.v_IinG, rtol=1e-15)
    np.testing.assert_allclose(f.w_I, 2.5 * b.w_I, rtol=1e-15)
    np.testing.assert_allclose(f.a_IinG, 6.25 * b.a_IinG, rtol=1e-15)
    np.testing.assert_allclose(f.dw_I, 6.25 * b.dw_I, rtol=1e-15)
    np.testing.assert_array_equal(f.t, t)
    # a duration is the played one: the preset's 60 s at speed 2 last 30 s, its first 20 s at speed 2 last 10 s
    assert trajectory_from_preset("boxes_like", duration=10.0, speed=2.0).duration == 10.0
    np.testing.assert_array_equal(trajectory_from_preset("boxes_like", duration=10.0, seed=1, speed=2.0).evaluate(t[:5]).p_IinG,
                                  boxes_like(duration=20.0, seed=1).evaluate(2.0 * t[:5]).p_IinG)
    assert trajectory_from_preset("aerial_like", speed=1.0).__class__ is not TimeScaledTrajectory
    for bad in (0.0, -1.0, np.nan, np.inf, True, "2"):
        with pytest.raises(ValueError, match="speed must be a finite number > 0"):
            trajectory_from_preset("boxes_like", speed=bad)
        with pytest.raises(ValueError, match="speed must be a finite number > 0"):
            TimeScaledTrajectory(base, bad)
    with pytest.raises(ValueError, match="longer than the longest trajectory, 1800 s at speed 2"):
        trajectory_from_preset("boxes_like", duration=2000.0, speed=2.0)


def test_trajectory_bad_inputs():
    traj = boxes_like(duration=10.0)
    with pytest.raises(ValueError, match=r"t must lie in \[t_start, t_end\]"):
        traj.evaluate([0.0, 10.5])
    with pytest.raises(ValueError, match=r"t must lie in"):
        traj.evaluate(-0.1)
    with pytest.raises(ValueError, match=r"t must be a float or an array of shape \(N,\)"):
        traj.evaluate(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="t must contain only finite"):
        traj.evaluate([np.nan])
    with pytest.raises(ValueError, match="duration must be >= 2"):
        boxes_like(duration=-1.0)
    with pytest.raises(ValueError, match="duration must be a finite number"):
        boxes_like(duration=np.inf)
    with pytest.raises(ValueError, match="duration must be >= 2"):
        aerial_like(duration=1.0)
    with pytest.raises(ValueError, match="turbulence must be a finite scale"):
        aerial_like(turbulence=-1.0)


# ------------------------------------------------------------------------------------------------ rig
def test_default_extrinsics_are_small_but_not_identity():
    ext = CameraImuExtrinsics.default()
    angle = np.degrees(np.linalg.norm(so3_log(ext.R_CtoI)))
    assert 1.0 < angle < 5.0
    assert 0.01 < np.linalg.norm(ext.p_CinI) < 0.06
    np.testing.assert_allclose(ext.R_CtoI, Rotation.from_rotvec([0.02, -0.035, 0.015]).as_matrix(), atol=1e-12)


def test_camera_pose_maps_camera_points_like_the_chain_of_frames(rng):
    ext = CameraImuExtrinsics.default()
    R_ItoG = Rotation.random(5, random_state=1).as_matrix()
    p_IinG = rng.normal(size=(5, 3))
    R_CtoG, p_CinG = ext.camera_pose(R_ItoG, p_IinG)
    assert R_CtoG.shape == (5, 3, 3) and p_CinG.shape == (5, 3)
    x_C = rng.normal(size=3)
    x_I = ext.R_CtoI @ x_C + ext.p_CinI  # camera point in I
    x_G_chain = np.einsum("nij,j->ni", R_ItoG, x_I) + p_IinG
    np.testing.assert_allclose(np.einsum("nij,j->ni", R_CtoG, x_C) + p_CinG, x_G_chain, atol=1e-12)
    R_back, p_back = ext.imu_pose(R_CtoG, p_CinG)
    np.testing.assert_allclose(R_back, R_ItoG, atol=1e-12)
    np.testing.assert_allclose(p_back, p_IinG, atol=1e-12)
    # inverse transform properties
    np.testing.assert_allclose(ext.R_ItoC @ ext.R_CtoI, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(ext.R_ItoC @ x_I + ext.p_IinC, x_C, atol=1e-12)
    R1, p1 = ext.camera_pose(np.eye(3), np.zeros(3))  # unbatched
    assert R1.shape == (3, 3) and p1.shape == (3,)
    np.testing.assert_allclose(p1, ext.p_CinI)


def test_extrinsics_dict_round_trip_through_json():
    ext = CameraImuExtrinsics(so3_exp([0.1, 0.2, -0.3]), [0.01, 0.02, 0.03])
    back = CameraImuExtrinsics.from_dict(json.loads(json.dumps(ext.to_dict())))
    assert back == ext
    assert back != CameraImuExtrinsics.identity()


def test_extrinsics_bad_inputs():
    with pytest.raises(ValueError, match=r"R_CtoI must have shape \(3, 3\)"):
        CameraImuExtrinsics(np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="R_CtoI must be a rotation matrix"):
        CameraImuExtrinsics(2.0 * np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="R_CtoI must be a rotation matrix"):
        CameraImuExtrinsics(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    with pytest.raises(ValueError, match=r"p_CinI must have shape \(3,\)"):
        CameraImuExtrinsics(np.eye(3), np.zeros(2))
    ext = CameraImuExtrinsics.default()
    with pytest.raises(ValueError, match="must have matching leading dimensions"):
        ext.camera_pose(np.broadcast_to(np.eye(3), (4, 3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"R_CtoG must have shape"):
        ext.imu_pose(np.zeros((3, 2)), np.zeros(3))
    with pytest.raises(ValueError, match="data must be a dict with keys"):
        CameraImuExtrinsics.from_dict({"R": np.eye(3).tolist()})
    with pytest.raises(Exception):  # frozen
        ext.p_CinI = np.zeros(3)
