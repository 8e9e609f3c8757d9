"""Tests of evio_lib.evaluation.trajectory_metrics against closed forms, scipy, hand examples and the evo package."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from evio_lib.evaluation.trajectory_metrics import (
    absolute_trajectory_error,
    align_umeyama,
    chi2_bounds,
    distance_travelled,
    final_error,
    format_table,
    nees,
    orientation_errors,
    percent_of_distance,
    position_errors,
    relative_errors_by_length,
    relative_pose_error,
    rmse,
    subtrajectory_lengths,
    summarize,
)


def _helix(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 20.0, n)
    p = np.stack([3.0 * np.cos(0.3 * t), 3.0 * np.sin(0.3 * t), 0.1 * t + 0.5 * np.sin(t)], axis=1)
    return t, p


def test_identical_trajectories_give_zero(rng: np.random.Generator) -> None:
    t, p = _helix()
    errors = position_errors(t, p, t, p)
    assert errors.shape == (t.size, 3) and np.all(errors == 0.0)
    assert rmse(errors) == 0.0 and final_error(errors) == 0.0
    R = Rotation.random(t.size, random_state=1).as_matrix()
    rpe = relative_pose_error(t, R, p, R, p, delta=1.0)
    np.testing.assert_allclose(rpe.translation, 0.0, atol=1e-12)
    np.testing.assert_allclose(rpe.rotation, 0.0, atol=1e-7)
    angle, yaw, tilt = orientation_errors(R, R)
    np.testing.assert_allclose(np.stack([angle, yaw, tilt]), 0.0, atol=1e-7)
    assert absolute_trajectory_error(p, p) < 1e-12


def test_constant_offset_rmse_equals_offset() -> None:
    t, p = _helix()
    offset = np.array([0.3, -0.4, 1.2])  # |offset| = 1.3
    errors = position_errors(t, p + offset, t, p)
    np.testing.assert_allclose(errors, np.broadcast_to(offset, errors.shape), atol=1e-12)
    assert rmse(errors) == pytest.approx(1.3, abs=1e-12)
    assert final_error(errors) == pytest.approx(1.3, abs=1e-12)
    assert rmse(np.linalg.norm(errors, axis=1)) == pytest.approx(1.3, abs=1e-12)  # norms are accepted too
    # a constant offset is removed by any alignment
    assert absolute_trajectory_error(p + offset, p) < 1e-9
    assert absolute_trajectory_error(p + offset, p, yaw_only=False) < 1e-9


def test_position_errors_interpolates_ground_truth() -> None:
    # ground truth p(t) = [t, t^2, 0] sampled every h = 0.01 s; estimates at off-grid times are compared to the
    # linear interpolant, which exceeds t^2 by exactly (t - t_i)(t_i+1 - t)
    t_gt = np.linspace(0.0, 2.0, 201)
    p_gt = np.stack([t_gt, t_gt**2, np.zeros_like(t_gt)], axis=1)
    t_est = np.array([0.005, 0.777, 1.2345, 1.999])
    p_est = np.stack([t_est, t_est**2, np.zeros_like(t_est)], axis=1)
    errors = position_errors(t_est, p_est, t_gt, p_gt)
    np.testing.assert_allclose(errors[:, 0], 0.0, atol=1e-12)
    t_i = np.floor(t_est / 0.01 + 1e-9) * 0.01
    np.testing.assert_allclose(errors[:, 1], -(t_est - t_i) * (t_i + 0.01 - t_est), atol=1e-12)


def test_percent_of_distance_hand_example() -> None:
    # square path 0 -> (4,0) -> (4,3): D = 7 m; errors 0, 0.7, 1.4 m -> mean 0.7 m -> 10 %
    p_gt = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 3.0, 0.0]])
    assert distance_travelled(p_gt) == pytest.approx(7.0)
    p_est = p_gt + np.array([[0.0, 0.0, 0.0], [0.0, 0.7, 0.0], [0.0, 0.0, 1.4]])
    errors = position_errors([0.0, 1.0, 2.0], p_est, [0.0, 1.0, 2.0], p_gt)
    assert percent_of_distance(errors, 7.0) == pytest.approx(10.0)
    row = summarize([0.0, 1.0, 2.0], p_est, [0.0, 1.0, 2.0], p_gt, name="hand")
    assert row["distance_m"] == pytest.approx(7.0)
    assert row["percent_of_distance"] == pytest.approx(10.0)
    assert row["rmse_m"] == pytest.approx(np.sqrt((0.49 + 1.96) / 3))
    assert row["final_error_m"] == pytest.approx(1.4) and row["max_error_m"] == pytest.approx(1.4)
    # the thesis's Table 6 relation on the Boxes IMU-only row: % = mean |e| / D, so mean |e| = 26.34 % of 69.8 m
    assert percent_of_distance(np.full(10, 0.2634 * 69.8), 69.8) == pytest.approx(26.34)


def test_summarize_uses_distance_over_estimate_span() -> None:
    t = np.linspace(0.0, 10.0, 101)
    p = np.stack([t, np.zeros_like(t), np.zeros_like(t)], axis=1)  # 1 m/s along x
    t_est = np.linspace(2.0, 6.0, 9)
    p_est = np.stack([t_est, np.full_like(t_est, 0.2), np.zeros_like(t_est)], axis=1)
    row = summarize(t_est, p_est, t, p)
    assert row["distance_m"] == pytest.approx(4.0)
    assert row["percent_of_distance"] == pytest.approx(5.0)
    assert row["n"] == 9


def _umeyama_reference(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Sim(3) reference through the 4x4 quaternion eigenproblem (Horn 1987), independent of the SVD route."""
    mu_a, mu_b = a.mean(0), b.mean(0)
    A, B = a - mu_a, b - mu_b
    M = A.T @ B
    Sxx, Sxy, Sxz, Syx, Syy, Syz, Szx, Szy, Szz = M.ravel()
    N = np.array([
        [Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx],
        [Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz],
        [Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy],
        [Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz],
    ])
    w, v = np.linalg.eigh(N)
    q = v[:, -1]  # [w, x, y, z]
    R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    s = np.sum(B * (A @ R.T)) / np.sum(A**2)
    return s, R, mu_b - s * R @ mu_a


def test_umeyama_recovers_known_similarity(rng: np.random.Generator) -> None:
    a = rng.normal(size=(50, 3)) * [3.0, 2.0, 1.0]
    R_true = Rotation.from_rotvec([0.4, -1.1, 2.0]).as_matrix()
    s_true, t_true = 1.7, np.array([5.0, -2.0, 0.3])
    b = s_true * a @ R_true.T + t_true
    fit = align_umeyama(a, b, with_scale=True)
    assert fit.scale == pytest.approx(s_true, rel=1e-12)
    np.testing.assert_allclose(fit.R, R_true, atol=1e-12)
    np.testing.assert_allclose(fit.t, t_true, atol=1e-10)
    np.testing.assert_allclose(fit.apply(a), b, atol=1e-10)
    assert absolute_trajectory_error(a, b, with_scale=True, yaw_only=False) < 1e-10
    # without scale, the SE(3) part; with noise, agrees with the Horn quaternion reference
    noisy = b + 0.05 * rng.normal(size=b.shape)
    fit = align_umeyama(a, noisy, with_scale=True)
    s_ref, R_ref, t_ref = _umeyama_reference(a, noisy)
    assert fit.scale == pytest.approx(s_ref, rel=1e-9)
    np.testing.assert_allclose(fit.R, R_ref, atol=1e-9)
    np.testing.assert_allclose(fit.t, t_ref, atol=1e-8)
    rigid = align_umeyama(a, a @ R_true.T + t_true)
    assert rigid.scale == 1.0
    np.testing.assert_allclose(rigid.R, R_true, atol=1e-12)
    # a reflection is never returned
    assert np.linalg.det(align_umeyama(a, a * [1.0, 1.0, -1.0]).R) == pytest.approx(1.0)


def test_yaw_only_alignment_recovers_yaw_and_leaves_roll_pitch(rng: np.random.Generator) -> None:
    _, p = _helix()
    yaw_rot = Rotation.from_euler("z", 0.8).as_matrix()
    moved = p @ yaw_rot.T + [10.0, -3.0, 2.0]
    fit = align_umeyama(p, moved, yaw_only=True)
    np.testing.assert_allclose(fit.R, yaw_rot, atol=1e-12)
    assert absolute_trajectory_error(p, moved, yaw_only=True) < 1e-10
    # a roll/pitch error cannot be removed by the 4-DoF alignment, but is by the SE(3) one
    tilted = p @ Rotation.from_euler("xy", [0.2, -0.15]).as_matrix().T
    assert absolute_trajectory_error(p, tilted, yaw_only=True) > 0.1
    assert absolute_trajectory_error(p, tilted, yaw_only=False) < 1e-10
    fit = align_umeyama(p, tilted, yaw_only=True)
    assert fit.R[2, 2] == 1.0 and np.allclose(fit.R[:2, 2], 0.0) and np.allclose(fit.R[2, :2], 0.0)


def test_orientation_errors_split_yaw_and_tilt() -> None:
    R_gt = Rotation.random(20, random_state=4).as_matrix()
    dyaw = Rotation.from_euler("z", 0.3).as_matrix()
    angle, yaw, tilt = orientation_errors(dyaw @ R_gt, R_gt)  # world-frame yaw error
    np.testing.assert_allclose(angle, 0.3, atol=1e-12)
    np.testing.assert_allclose(yaw, 0.3, atol=1e-12)
    np.testing.assert_allclose(tilt, 0.0, atol=1e-7)
    dtilt = Rotation.from_euler("x", -0.2).as_matrix()
    angle, yaw, tilt = orientation_errors(dtilt @ R_gt, R_gt)
    np.testing.assert_allclose(tilt, 0.2, atol=1e-12)
    np.testing.assert_allclose(yaw, 0.0, atol=1e-12)
    # angle agrees with scipy's magnitude of the relative rotation
    R_est = Rotation.random(20, random_state=5).as_matrix()
    angle, _, _ = orientation_errors(R_est, R_gt)
    ref = (Rotation.from_matrix(R_est) * Rotation.from_matrix(R_gt).inv()).magnitude()
    np.testing.assert_allclose(angle, ref, atol=1e-9)


def test_relative_pose_error_scale_drift_and_time_mode() -> None:
    # straight line at 1 m/s; the estimate is scaled by 1.1 -> relative translation error 0.1 * delta
    t = np.linspace(0.0, 10.0, 101)
    p = np.stack([t, np.zeros_like(t), np.zeros_like(t)], axis=1)
    R = np.repeat(np.eye(3)[None], t.size, axis=0)
    rpe = relative_pose_error(t, R, 1.1 * p, R, p, delta=2.0)
    np.testing.assert_array_equal(rpe.j - rpe.i, 20)
    np.testing.assert_allclose(rpe.translation, 0.2, atol=1e-9)
    rpe_t = relative_pose_error(t, R, 1.1 * p, R, p, delta=1.0, mode="time")
    np.testing.assert_allclose(rpe_t.translation, 0.1, atol=1e-9)
    assert rpe_t.i.size == 91
    # a constant global rigid transform of the whole estimate leaves the RPE at zero
    g = Rotation.from_rotvec([0.3, 0.2, -0.5]).as_matrix()
    _, ph = _helix(101)
    Rh = Rotation.from_rotvec(np.outer(t, [0.05, 0.1, 0.2])).as_matrix()
    rpe = relative_pose_error(t, g @ Rh, ph @ g.T + 1.0, Rh, ph, delta=3.0)
    np.testing.assert_allclose(rpe.translation, 0.0, atol=1e-9)
    np.testing.assert_allclose(rpe.rotation, 0.0, atol=1e-7)


def test_nees_of_correct_gaussian_errors_averages_dimension(rng: np.random.Generator) -> None:
    runs, steps, d = 30, 200, 3
    A = rng.normal(size=(steps, d, d))
    P = A @ np.swapaxes(A, 1, 2) + 0.5 * np.eye(d)  # (steps, d, d) SPD
    L = np.linalg.cholesky(P)
    e = np.einsum("kij,rkj->rki", L, rng.normal(size=(runs, steps, d)))  # e ~ N(0, P)
    values = nees(e, np.broadcast_to(P, (runs, steps, d, d)))
    assert values.shape == (runs, steps)
    assert values.mean() == pytest.approx(d, rel=0.03)
    lo, hi = chi2_bounds(d, runs)
    inside = np.mean((values.mean(axis=0) >= lo) & (values.mean(axis=0) <= hi))
    assert 0.9 <= inside <= 0.99  # ~95 % of the time steps
    # an over-confident filter (covariance 4x too small) is detected
    assert nees(e, np.broadcast_to(P / 4.0, (runs, steps, d, d))).mean(axis=0).mean() > hi
    # closed form for a diagonal covariance
    assert nees([0.3, -0.4], np.diag([0.09, 0.16])) == pytest.approx(2.0)


def test_chi2_bounds_against_scipy_and_bar_shalom() -> None:
    for dof, runs, prob in ((3, 1, 0.95), (6, 20, 0.95), (3, 50, 0.99), (2, 50, 0.95)):
        lo, hi = chi2_bounds(dof, runs, prob)
        assert lo == pytest.approx(chi2.ppf((1 - prob) / 2, dof * runs) / runs, rel=1e-12)
        assert hi == pytest.approx(chi2.ppf((1 + prob) / 2, dof * runs) / runs, rel=1e-12)
        assert chi2.cdf(hi * runs, dof * runs) - chi2.cdf(lo * runs, dof * runs) == pytest.approx(prob, abs=1e-9)
    # Bar-Shalom, Li & Kirubarajan (2001), Example in §5.4: 50 runs, n_x = 2 -> [1.5, 2.6]
    lo, hi = chi2_bounds(2, 50)
    assert round(lo, 1) == 1.5 and round(hi, 1) == 2.6
    # one run of a 3-D error: the classical [0.216, 9.35]
    lo, hi = chi2_bounds(3, 1)
    assert lo == pytest.approx(0.2158, abs=1e-4) and hi == pytest.approx(9.3484, abs=1e-4)


def test_format_table_markdown() -> None:
    rows = [{"name": "IMU-only (bias corrected)", "rmse_m": 29.19, "final_error_m": 88.71,
             "percent_of_distance": 26.34},
            {"name": "MSCKF", "rmse_m": 0.4371, "final_error_m": 0.968, "percent_of_distance": 0.447}]
    table = format_table(rows).splitlines()
    assert table[0] == "| Method | RMSE [m] | Final Error [m] | % Error |"
    assert table[1] == "|---|---|---|---|"
    assert table[2] == "| IMU-only (bias corrected) | 29.19 | 88.71 | 26.34 % |"
    assert table[3] == "| MSCKF | 0.437 | 0.968 | 0.447 % |"
    custom = format_table([{"name": "x", "n": 3}], columns=[("name", "Run"), ("n", "N"), ("ate_4dof_m", "ATE")])
    assert custom.splitlines()[2] == "| x | 3 | - |"


def test_bad_input_raises() -> None:
    t, p = _helix(10)
    with pytest.raises(ValueError, match=r"p_est must have shape \(N, 3\); got \(10, 2\)"):
        position_errors(t, p[:, :2], t, p)
    with pytest.raises(ValueError, match="t_est must lie inside the ground truth"):
        position_errors(t + 100.0, p, t, p)
    with pytest.raises(ValueError, match="t_gt must be non-empty and strictly increasing"):
        position_errors(t, p, t[::-1], p)
    with pytest.raises(ValueError, match="t_est and p_est must have the same length"):
        position_errors(t[:5], p, t, p)
    with pytest.raises(ValueError, match=r"errors must have shape \(N,\) or \(N, d\)"):
        rmse(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="distance must be a finite distance > 0"):
        percent_of_distance([1.0], 0.0)
    with pytest.raises(ValueError, match="p_est must hold at least 3 points"):
        align_umeyama(p[:2], p[:2])
    with pytest.raises(ValueError, match=r"covariances must have shape errors.shape \+ \(d,\)"):
        nees(np.zeros((4, 3)), np.zeros((4, 2, 2)))
    with pytest.raises(ValueError, match="covariances must be positive definite"):
        nees(np.ones((1, 2)), np.zeros((1, 2, 2)))
    with pytest.raises(ValueError, match="dof must be an int >= 1"):
        chi2_bounds(0, 5)
    with pytest.raises(ValueError, match=r"probability must be in \(0, 1\)"):
        chi2_bounds(3, 5, 1.5)
    R = np.repeat(np.eye(3)[None], 10, axis=0)
    with pytest.raises(ValueError, match="delta must be a finite number > 0"):
        relative_pose_error(t, R, p, R, p, delta=-1.0)
    with pytest.raises(ValueError, match="mode must be 'distance' or 'time'"):
        relative_pose_error(t, R, p, R, p, delta=1.0, mode="frames")
    with pytest.raises(ValueError, match=r"R_est must have shape \(N, 3, 3\)"):
        orientation_errors(np.eye(3), R)
    with pytest.raises(ValueError, match="rows\\[0\\] must be a dict"):
        format_table([[1, 2]])


# ---------------------------------------------------------------------------------------------- cross-check with evo
def _perturbed_trajectory(seed: int = 3, n: int = 400) -> tuple[np.ndarray, ...]:
    """A 40 s helix-like ground truth (R_ItoG, p_IinG) and an estimate with a global SE(3) offset, a random-walk
    drift in position and attitude, white noise and a 1 % scale error: what a VIO run looks like."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 40.0, n)
    p_gt = np.stack([4.0 * np.cos(0.2 * t), 3.0 * np.sin(0.25 * t), 0.05 * t + 0.3 * np.sin(0.7 * t)], axis=1)
    R_gt = Rotation.from_rotvec(np.stack([0.2 * np.sin(0.3 * t), 0.1 * np.cos(0.2 * t), 0.2 * t], axis=1)).as_matrix()
    drift_p = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0)
    drift_R = Rotation.from_rotvec(np.cumsum(rng.normal(0.0, 0.002, (n, 3)), axis=0)).as_matrix()
    offset = Rotation.from_rotvec([0.1, -0.05, 0.8]).as_matrix()
    p_est = (1.01 * p_gt + drift_p + rng.normal(0.0, 0.02, (n, 3))) @ offset.T + [1.0, -2.0, 0.5]
    R_est = offset @ drift_R @ R_gt
    return t, R_est, p_est, R_gt, p_gt


def _evo_trajectory(t: np.ndarray, R: np.ndarray, p: np.ndarray):
    from evo.core import trajectory

    q_xyzw = Rotation.from_matrix(R).as_quat()
    return trajectory.PoseTrajectory3D(positions_xyz=p, orientations_quat_wxyz=np.roll(q_xyzw, 1, axis=1),
                                       timestamps=t)


@pytest.mark.parametrize("with_scale", [False, True])
def test_ate_equals_evo_ape_after_alignment(with_scale: bool) -> None:
    from evo.core import metrics

    t, R_est, p_est, R_gt, p_gt = _perturbed_trajectory()
    ref, est = _evo_trajectory(t, R_gt, p_gt), _evo_trajectory(t, R_est, p_est)
    est.align(ref, correct_scale=with_scale)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    ours = absolute_trajectory_error(p_est, p_gt, with_scale=with_scale, yaw_only=False)
    assert ours == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
    np.testing.assert_allclose(align_umeyama(p_est, p_gt, with_scale=with_scale).apply(p_est), est.positions_xyz,
                               atol=1e-9)
    # 4 DoF keeps roll and pitch: never below the SE(3) error, and a pure yaw + shift is undone exactly
    assert absolute_trajectory_error(p_est, p_gt, yaw_only=True) >= ours - 1e-12
    Rz = Rotation.from_rotvec([0.0, 0.0, 1.3]).as_matrix()
    assert absolute_trajectory_error(p_gt @ Rz.T + [3.0, 1.0, -2.0], p_gt, yaw_only=True) < 1e-9


def test_relative_errors_by_length_equal_evo_rpe_over_all_pairs() -> None:
    from evo.core import metrics

    t, R_est, p_est, R_gt, p_gt = _perturbed_trajectory()
    fit = align_umeyama(p_est, p_gt)
    ref, est = _evo_trajectory(t, R_gt, p_gt), _evo_trajectory(t, fit.apply_rotation(R_est), fit.apply(p_est))
    results = relative_errors_by_length(fit.apply_rotation(R_est), fit.apply(p_est), R_gt, p_gt)
    np.testing.assert_allclose([r.length_m for r in results], subtrajectory_lengths(p_gt))
    for result in results:
        for relation, ours in ((metrics.PoseRelation.translation_part, result.translation_m),
                               (metrics.PoseRelation.rotation_angle_rad, result.rotation_rad)):
            rpe = metrics.RPE(relation, delta=result.length_m, delta_unit=metrics.Unit.meters, rel_delta_tol=0.2,
                              all_pairs=True, pairs_from_reference=True)
            rpe.process_data((ref, est))
            assert rpe.delta_ids == result.j.tolist()  # the same pairs (evo stores their end indices)
            np.testing.assert_allclose(ours, rpe.error, rtol=1e-9, atol=1e-12)
        assert result.i.size > 50
        np.testing.assert_allclose(result.translation_percent, 100.0 * result.translation_m / result.length_m)
    # the relative errors do not depend on a global alignment of the estimate
    raw = relative_errors_by_length(R_est, p_est, R_gt, p_gt)
    for a, b in zip(raw, results):
        np.testing.assert_allclose(a.translation_m, b.translation_m, atol=1e-9)
        np.testing.assert_allclose(a.rotation_rad, b.rotation_rad, atol=1e-9)


def test_relative_errors_split_yaw_and_tilt_in_the_world_frame() -> None:
    # the estimate turns 0.01 rad/m more slowly about the world z axis: a pure yaw drift, no tilt
    n = 201
    s = np.linspace(0.0, 20.0, n)  # metres along a straight line in x
    p = np.stack([s, np.zeros(n), np.zeros(n)], axis=1)
    R_gt = Rotation.from_rotvec(np.stack([0.2 * np.ones(n), np.zeros(n), 0.05 * s], axis=1)).as_matrix()
    R_est = Rotation.from_rotvec(np.outer(-0.01 * s, [0.0, 0.0, 1.0])).as_matrix() @ R_gt  # dR = Rz(-0.01 s)
    result = relative_errors_by_length(R_est, p, R_gt, p, lengths=[5.0])[0]
    separation = s[result.j] - s[result.i]  # 5 m, and 4-5 m near the end (within the 20 % tolerance)
    assert separation.min() > 4.0 and np.sum(np.isclose(separation, 5.0)) == 151
    np.testing.assert_allclose(result.yaw_rad, 0.01 * separation, atol=1e-9)  # 0.01 rad/m
    np.testing.assert_allclose(result.tilt_rad, 0.0, atol=1e-9)
    np.testing.assert_allclose(result.rotation_rad, 0.01 * separation, atol=1e-9)
    # positions agree, but the estimate's heading at i is off by 0.01 s_i, so the step p_j - p_i (horizontal),
    # seen from pose i, turns by that angle: |t(E)| = 2 |p_j - p_i| sin(0.01 s_i / 2)
    np.testing.assert_allclose(result.translation_m, 2.0 * separation * np.sin(0.005 * s[result.i]), atol=1e-12)
    summary = result.summary()
    assert summary["pairs"] == result.i.size
    assert summary["yaw_deg_mean"] == pytest.approx(np.degrees(np.mean(0.01 * separation)))


def test_relative_errors_pair_the_closest_length_within_tolerance() -> None:
    # poses 1 m apart, then a 10 m jump: lengths of 3 m pair i with i + 3 until the jump breaks the tolerance
    p = np.array([[float(x), 0.0, 0.0] for x in [0, 1, 2, 3, 4, 5, 15, 16, 17, 18]])
    R = np.repeat(np.eye(3)[None], len(p), axis=0)
    result = relative_errors_by_length(R, p, R, p, lengths=[3.0])[0]
    assert list(zip(result.i.tolist(), result.j.tolist())) == [(0, 3), (1, 4), (2, 5), (6, 9)]
    assert relative_errors_by_length(R, p, R, p, lengths=[50.0])[0].i.size == 0
    assert np.isnan(relative_errors_by_length(R, p, R, p, lengths=[50.0])[0].summary()["translation_m_mean"])


def test_summarize_reports_both_ates() -> None:
    t, _, p_est, _, p_gt = _perturbed_trajectory()
    row = summarize(t, p_est, t, p_gt)
    assert row["ate_se3_m"] == pytest.approx(absolute_trajectory_error(p_est, p_gt, yaw_only=False))
    assert row["ate_4dof_m"] == pytest.approx(absolute_trajectory_error(p_est, p_gt, yaw_only=True))
    assert row["ate_se3_m"] <= row["ate_4dof_m"]


def test_relative_errors_bad_input() -> None:
    t, R_est, p_est, R_gt, p_gt = _perturbed_trajectory(n=20)
    with pytest.raises(ValueError, match="lengths must be"):
        relative_errors_by_length(R_est, p_est, R_gt, p_gt, lengths=[-1.0])
    with pytest.raises(ValueError, match="percentages must be"):
        relative_errors_by_length(R_est, p_est, R_gt, p_gt, percentages=[])
    with pytest.raises(ValueError, match="max_length_diff"):
        relative_errors_by_length(R_est, p_est, R_gt, p_gt, max_length_diff=0.0)
    with pytest.raises(ValueError, match="R_est and p_gt must have the same length"):
        relative_errors_by_length(R_est, p_est, R_gt, p_gt[:5])
    with pytest.raises(ValueError, match=r"R_gt must have shape \(N, 3, 3\)"):
        relative_errors_by_length(R_est, p_est, R_gt[:, :2], p_gt)


def test_camera_motion_is_the_simulated_speed_and_rate():
    """On a short simulated stretch of the room: the speed is the trajectory's |v|, the rate its |w| within the
    gyro's bias and noise."""
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence
    from evio_lib.sim.trajectory import boxes_like
    from evio_lib.evaluation.trajectory_metrics import camera_motion

    seq = simulate_sequence(SimulationConfig(preset="boxes_like", duration=1.0, start_time=50.0, trajectory_duration=60.0,
                                             seed=2, with_events=False, with_frames=False))
    t = np.linspace(50.1, 50.9, 41)
    speed, _ = camera_motion(seq, t)
    _, rate = camera_motion(seq, t, smoothing_s=0.001)  # one sample: |w| + the bias and the noise
    truth = boxes_like(60.0, seed=2).evaluate(t)
    np.testing.assert_allclose(speed, np.linalg.norm(truth.v_IinG, axis=1), rtol=0.03)  # differences over 40 ms
    assert np.abs(rate - np.linalg.norm(truth.w_I, axis=1)).max() < 0.1 < np.linalg.norm(truth.w_I, axis=1).min()
    with pytest.raises(ValueError, match="at least 2 increasing times"):
        camera_motion(seq, [50.5])
