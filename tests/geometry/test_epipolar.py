"""Tests for evio_lib.geometry.epipolar against closed forms and OpenCV on synthetic two-view scenes."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.epipolar import (
    decompose_essential,
    eight_point,
    epipolar_residuals,
    essential_from_pose,
    estimate_essential_ransac,
    fundamental_from_essential,
    recover_pose,
    refine_essential,
    sampson_distance,
    triangulate_dlt,
)

K = np.array([[200.0, 0.0, 120.0], [0.0, 200.0, 90.0], [0.0, 0.0, 1.0]])


def make_scene(rng: np.random.Generator, n: int = 100, noise_px: float = 0.0):
    """Return (R_C1toC2, p_C1inC2, X_C1 (n, 3), xy1, xy2, uv1, uv2) of random points in front of both cameras."""
    R = Rotation.from_rotvec(rng.normal(0.0, 0.15, 3)).as_matrix()
    centre_C2inC1 = rng.normal(0.0, 0.5, 3)
    p_C1inC2 = -R @ centre_C2inC1  # X_C2 = R X_C1 + t, camera-2 centre c satisfies R c + t = 0
    X_C1 = np.column_stack([rng.uniform(-2.0, 2.0, n), rng.uniform(-1.5, 1.5, n), rng.uniform(3.0, 8.0, n)])
    X_C2 = X_C1 @ R.T + p_C1inC2
    assert (X_C2[:, 2] > 0.5).all()
    uv1 = X_C1 @ K.T
    uv1 = uv1[:, :2] / uv1[:, 2:] + rng.normal(0.0, noise_px, (n, 2)) * (noise_px > 0)
    uv2 = X_C2 @ K.T
    uv2 = uv2[:, :2] / uv2[:, 2:] + rng.normal(0.0, noise_px, (n, 2)) * (noise_px > 0)
    xy1 = (uv1 - K[:2, 2]) / K[0, 0]
    xy2 = (uv2 - K[:2, 2]) / K[0, 0]
    return R, p_C1inC2, X_C1, xy1, xy2, uv1, uv2


def same_up_to_scale(A: np.ndarray, B: np.ndarray) -> float:
    """Return the max abs difference between A and B after scaling both to unit norm with matching sign."""
    a = A / np.linalg.norm(A)
    b = B / np.linalg.norm(B)
    return float(min(np.abs(a - b).max(), np.abs(a + b).max()))


def rotation_angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """Return the angle of R1^T R2 in degrees."""
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(R1.T @ R2).as_rotvec())))


# ------------------------------------------------------------------------------------------ essential / fundamental
def test_essential_from_pose_closed_form(rng):
    R, t, X_C1, xy1, xy2, _, _ = make_scene(rng)
    E = essential_from_pose(R, t)
    v = rng.normal(size=3)
    np.testing.assert_allclose(E @ v, np.cross(t, R @ v), atol=1e-12)  # E v = t x (R v)
    np.testing.assert_allclose(np.linalg.svd(E, compute_uv=False), [np.linalg.norm(t)] * 2 + [0.0], atol=1e-12)
    assert np.abs(epipolar_residuals(E, xy1, xy2)).max() < 1e-12
    assert not np.abs(epipolar_residuals(E, xy1, xy2[::-1])).max() < 1e-3  # wrong matches violate it
    assert essential_from_pose(R, t[:, None]).shape == (3, 3)


def test_essential_from_pose_bad_input():
    with pytest.raises(ValueError, match=r"R_C1toC2 must have shape \(3, 3\)"):
        essential_from_pose(np.eye(2), [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="R_C1toC2 must be a rotation matrix"):
        essential_from_pose(2.0 * np.eye(3), [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"p_C1inC2 must have shape \(3,\)"):
        essential_from_pose(np.eye(3), [1.0, 0.0])
    with pytest.raises(ValueError, match="p_C1inC2 must be finite"):
        essential_from_pose(np.eye(3), [np.nan, 0.0, 0.0])


def test_fundamental_matches_opencv_eight_point(rng):
    R, t, _, _, _, uv1, uv2 = make_scene(rng, n=60)
    F = fundamental_from_essential(essential_from_pose(R, t), K, K)
    u1h = np.column_stack([uv1, np.ones(len(uv1))])
    u2h = np.column_stack([uv2, np.ones(len(uv2))])
    scale = np.linalg.norm(F) * np.linalg.norm(u1h, axis=1) * np.linalg.norm(u2h, axis=1)
    assert (np.abs(np.einsum("ni,ij,nj->n", u2h, F, u1h)) / scale).max() < 1e-12
    F_cv, _ = cv2.findFundamentalMat(uv1, uv2, cv2.FM_8POINT)
    assert same_up_to_scale(F, F_cv) < 1e-6
    K2 = K.copy()
    K2[0, 0] = 300.0
    np.testing.assert_allclose(fundamental_from_essential(np.eye(3), K, K2), np.linalg.inv(K2).T @ np.linalg.inv(K))


def test_fundamental_bad_input():
    with pytest.raises(ValueError, match="K1 must be an invertible"):
        fundamental_from_essential(np.eye(3), np.zeros((3, 3)), K)
    with pytest.raises(ValueError, match=r"K2 must have shape \(3, 3\)"):
        fundamental_from_essential(np.eye(3), K, K[:2])
    with pytest.raises(ValueError, match=r"E must have shape \(3, 3\)"):
        fundamental_from_essential(np.eye(4), K, K)


# ------------------------------------------------------------------------------------------ eight-point
def test_eight_point_noise_free_exact(rng):
    for n in (8, 9, 50):
        R, t, _, xy1, xy2, _, _ = make_scene(rng, n=n)
        E = eight_point(xy1, xy2)
        assert same_up_to_scale(E, essential_from_pose(R, t)) < 1e-9
        np.testing.assert_allclose(np.linalg.svd(E, compute_uv=False), [1.0, 1.0, 0.0], atol=1e-9)


def test_eight_point_matches_opencv_find_essential(rng):
    R, t, _, xy1, xy2, uv1, uv2 = make_scene(rng, n=80)
    E_cv, _ = cv2.findEssentialMat(uv1, uv2, K, method=cv2.RANSAC, prob=0.999, threshold=0.1)
    assert E_cv.shape == (3, 3)
    assert same_up_to_scale(eight_point(xy1, xy2), E_cv[:3]) < 1e-6


def test_eight_point_with_pixel_noise_close_to_truth_and_opencv(rng):
    R, t, _, xy1, xy2, uv1, uv2 = make_scene(rng, n=200, noise_px=0.5)
    E = eight_point(xy1, xy2)
    R_est, t_est, mask = recover_pose(E, xy1, xy2)
    E_cv, _ = cv2.findEssentialMat(uv1, uv2, K, method=cv2.LMEDS)
    _, R_cv, t_cv, _ = cv2.recoverPose(E_cv[:3], uv1, uv2, K)
    err_ours = rotation_angle_deg(R, R_est)
    err_cv = rotation_angle_deg(R, R_cv)
    assert err_ours < 0.5, err_ours
    t_dir = t / np.linalg.norm(t)
    ang_ours = np.degrees(np.arccos(np.clip(t_est @ t_dir, -1, 1)))
    ang_cv = np.degrees(np.arccos(np.clip(t_cv.ravel() @ t_dir, -1, 1)))
    assert ang_ours < 5.0, ang_ours
    # least squares over all points is at least as good as OpenCV's five-point + LMedS, give or take
    assert err_ours < 2.0 * err_cv + 0.05 and ang_ours < 2.0 * ang_cv + 0.5
    assert mask.mean() > 0.95


def test_eight_point_is_invariant_to_input_order_and_does_not_modify_inputs(rng):
    _, _, _, xy1, xy2, _, _ = make_scene(rng, n=30, noise_px=0.5)
    copies = xy1.copy(), xy2.copy()
    perm = rng.permutation(30)
    np.testing.assert_allclose(eight_point(xy1, xy2), eight_point(xy1[perm], xy2[perm]), atol=1e-10)
    np.testing.assert_array_equal(xy1, copies[0])
    np.testing.assert_array_equal(xy2, copies[1])


def test_eight_point_bad_input(rng):
    _, _, _, xy1, xy2, _, _ = make_scene(rng, n=10)
    with pytest.raises(ValueError, match=r"at least 8 correspondences .*got N = 7"):
        eight_point(xy1[:7], xy2[:7])
    with pytest.raises(ValueError, match="same number of correspondences"):
        eight_point(xy1, xy2[:9])
    with pytest.raises(ValueError, match=r"xy1 must have shape \(N, 2\)"):
        eight_point(np.ones((10, 3)), xy2)
    bad = xy2.copy()
    bad[3, 0] = np.inf
    with pytest.raises(ValueError, match="xy2 must be finite"):
        eight_point(xy1, bad)


# ------------------------------------------------------------------------------------------ decomposition, cheirality
def test_decompose_essential_contains_truth_and_matches_opencv(rng):
    for _ in range(5):
        R, t, _, xy1, xy2, _, _ = make_scene(rng, n=30)
        E = essential_from_pose(R, t)
        poses = decompose_essential(-3.0 * E)  # scale and sign must not matter
        assert len(poses) == 4
        for R_c, t_c in poses:
            np.testing.assert_allclose(R_c @ R_c.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(R_c) == pytest.approx(1.0, abs=1e-12)
            assert np.linalg.norm(t_c) == pytest.approx(1.0, abs=1e-12)
            assert same_up_to_scale(essential_from_pose(R_c, t_c), E) < 1e-9
        t_unit = t / np.linalg.norm(t)
        hits = [np.abs(R_c - R).max() < 1e-9 and np.abs(t_c - t_unit).max() < 1e-9 for R_c, t_c in poses]
        assert sum(hits) == 1
        Ra_cv, Rb_cv, t_cv = cv2.decomposeEssentialMat(E)
        for R_cv in (Ra_cv, Rb_cv):
            assert any(np.abs(R_c - R_cv).max() < 1e-9 for R_c, _ in poses)
        assert any(np.abs(np.abs(t_c) - np.abs(t_cv.ravel())).max() < 1e-9 for _, t_c in poses)


def test_recover_pose_picks_truth_and_agrees_with_opencv(rng):
    for _ in range(5):
        R, t, _, xy1, xy2, _, _ = make_scene(rng, n=40)
        R_est, t_est, mask = recover_pose(essential_from_pose(R, t), xy1, xy2)
        np.testing.assert_allclose(R_est, R, atol=1e-9)
        np.testing.assert_allclose(t_est, t / np.linalg.norm(t), atol=1e-9)
        assert mask.dtype == bool and mask.shape == (40,) and mask.all()
        _, R_cv, t_cv, _ = cv2.recoverPose(eight_point(xy1, xy2), xy1, xy2, np.eye(3))
        np.testing.assert_allclose(R_cv, R, atol=1e-8)
        np.testing.assert_allclose(t_cv.ravel(), t_est, atol=1e-8)


def test_recover_pose_mask_rejects_points_behind_camera(rng):
    R, t, X_C1, xy1, xy2, _, _ = make_scene(rng, n=40)
    X_behind = X_C1[:5] * np.array([1.0, 1.0, -1.0])  # mirrored behind camera 1
    X_behind_C2 = X_behind @ R.T + t
    xy1_all = np.vstack([xy1, X_behind[:, :2] / X_behind[:, 2:]])
    xy2_all = np.vstack([xy2, X_behind_C2[:, :2] / X_behind_C2[:, 2:]])
    R_est, _, mask = recover_pose(essential_from_pose(R, t), xy1_all, xy2_all)
    np.testing.assert_allclose(R_est, R, atol=1e-9)
    assert mask[:40].all() and not mask[40:].any()


def test_decompose_and_recover_bad_input():
    with pytest.raises(ValueError, match="E must be a non-zero"):
        decompose_essential(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"E must have shape \(3, 3\)"):
        recover_pose(np.eye(2), np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="at least 1 correspondences"):
        recover_pose(np.eye(3), np.zeros((0, 2)), np.zeros((0, 2)))


# ------------------------------------------------------------------------------------------ triangulation
def test_triangulate_noise_free_exact_normalised_and_pixels(rng):
    R, t, X_C1, xy1, xy2, uv1, uv2 = make_scene(rng, n=50)
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t[:, None]])
    np.testing.assert_allclose(triangulate_dlt(P1, P2, xy1, xy2), X_C1, atol=1e-9)
    np.testing.assert_allclose(triangulate_dlt(K @ P1, K @ P2, uv1, uv2), X_C1, atol=1e-9)
    assert triangulate_dlt(P1, P2, np.zeros((0, 2)), np.zeros((0, 2))).shape == (0, 3)


def test_triangulate_matches_opencv_with_noise(rng):
    R, t, X_C1, _, _, uv1, uv2 = make_scene(rng, n=50, noise_px=0.5)
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K @ np.hstack([R, t[:, None]])
    X = triangulate_dlt(P1, P2, uv1, uv2)
    X_cv_h = cv2.triangulatePoints(P1, P2, uv1.T.copy(), uv2.T.copy())
    X_cv = (X_cv_h[:3] / X_cv_h[3]).T
    np.testing.assert_allclose(X, X_cv, rtol=1e-6, atol=1e-9)
    assert np.median(np.linalg.norm(X - X_C1, axis=1)) < 0.2  # noisy but sensible


def test_triangulate_bad_input():
    P = np.hstack([np.eye(3), np.zeros((3, 1))])
    with pytest.raises(ValueError, match=r"P1 must have shape \(3, 4\)"):
        triangulate_dlt(np.eye(3), P, np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="same number of correspondences"):
        triangulate_dlt(P, P, np.zeros((2, 2)), np.zeros((3, 2)))


# ------------------------------------------------------------------------------------------ residuals
def test_residuals_equal_pixel_residuals_with_fundamental(rng):
    R, t, _, xy1, xy2, uv1, uv2 = make_scene(rng, n=20, noise_px=1.0)
    E = essential_from_pose(R, t)
    F = fundamental_from_essential(E, K, K)
    np.testing.assert_allclose(epipolar_residuals(E, xy1, xy2), epipolar_residuals(F, uv1, uv2), atol=1e-12)


def test_sampson_distance_matches_opencv_and_is_scale_free(rng):
    R, t, _, xy1, xy2, uv1, uv2 = make_scene(rng, n=20, noise_px=1.0)
    E = essential_from_pose(R, t)
    d = sampson_distance(E, xy1, xy2)
    d_cv = [
        cv2.sampsonDistance(np.array([*a, 1.0]), np.array([*b, 1.0]), E) for a, b in zip(xy1, xy2)
    ]  # OpenCV returns the squared distance
    np.testing.assert_allclose(d**2, d_cv, rtol=1e-9)
    np.testing.assert_allclose(sampson_distance(-7.0 * E, xy1, xy2), d, rtol=1e-12)
    # pixels with F: distances scale by the focal length
    np.testing.assert_allclose(sampson_distance(fundamental_from_essential(E, K, K), uv1, uv2), 200.0 * d, rtol=1e-9)


def test_sampson_distance_exact_for_rectified_pair():
    # horizontal baseline, no rotation: the smallest fix moves both points vertically by half the row gap
    E = essential_from_pose(np.eye(3), [1.0, 0.0, 0.0])
    gaps = np.array([0.0, 0.01, 0.2])
    xy1 = np.column_stack([[0.1, 0.3, -0.2], [0.0, 0.1, 0.05]])
    xy2 = xy1 + np.column_stack([[-0.2, 0.1, 0.0], gaps])
    np.testing.assert_allclose(sampson_distance(E, xy1, xy2), np.sqrt(2 * (gaps / 2) ** 2), atol=1e-15)


# ------------------------------------------------------------------------------------------ refinement
def test_refine_essential_converges_to_truth_noise_free(rng):
    R, t, _, xy1, xy2, _, _ = make_scene(rng, n=30)
    R_off = Rotation.from_rotvec([0.01, -0.02, 0.015]).as_matrix() @ R
    E_start = essential_from_pose(R_off, t + np.array([0.05, -0.03, 0.02]))
    E = refine_essential(E_start, xy1, xy2)
    assert same_up_to_scale(E, essential_from_pose(R, t)) < 1e-8
    np.testing.assert_allclose(np.linalg.svd(E, compute_uv=False), [1.0, 1.0, 0.0], atol=1e-12)


def test_refine_essential_lowers_sampson_error_and_pose_error(rng):
    rot_linear, rot_refined = [], []
    for _ in range(8):
        R, t, _, xy1, xy2, _, _ = make_scene(rng, n=100, noise_px=0.5)
        E_linear = eight_point(xy1, xy2)
        E = refine_essential(E_linear, xy1, xy2)
        d_truth = sampson_distance(essential_from_pose(R, t), xy1, xy2)
        # it minimises the summed squared Sampson distance: at most the truth's, and below the linear estimate's
        assert np.sum(sampson_distance(E, xy1, xy2) ** 2) <= np.sum(d_truth**2) * (1 + 1e-6)
        assert np.sum(sampson_distance(E, xy1, xy2) ** 2) < np.sum(sampson_distance(E_linear, xy1, xy2) ** 2)
        rot_linear.append(rotation_angle_deg(R, recover_pose(E_linear, xy1, xy2)[0]))
        rot_refined.append(rotation_angle_deg(R, recover_pose(E, xy1, xy2)[0]))
    assert np.median(rot_refined) < np.median(rot_linear)


def test_refine_essential_bad_input(rng):
    _, _, _, xy1, xy2, _, _ = make_scene(rng, n=10)
    with pytest.raises(ValueError, match="at least 5 correspondences"):
        refine_essential(np.eye(3), xy1[:4], xy2[:4])
    with pytest.raises(ValueError, match="max_iterations must be a positive integer"):
        refine_essential(np.eye(3), xy1, xy2, max_iterations=0)
    with pytest.raises(ValueError, match="E must be a non-zero"):
        refine_essential(np.zeros((3, 3)), xy1, xy2)


# ------------------------------------------------------------------------------------------ RANSAC
def test_ransac_finds_inliers_with_20_percent_outliers(rng):
    R, t, _, xy1, xy2, _, _ = make_scene(rng, n=200, noise_px=0.5)
    outliers = rng.choice(200, size=40, replace=False)
    xy2 = xy2.copy()
    xy2[outliers] = rng.uniform([-0.6, -0.45], [0.6, 0.45], size=(40, 2))
    truly_out = sampson_distance(essential_from_pose(R, t), xy1, xy2) > 4 * 0.5 / 200.0
    E, mask = estimate_essential_ransac(xy1, xy2, np.random.default_rng(7), threshold=1.5 / 200.0)
    assert mask.dtype == bool and mask.shape == (200,)
    assert not (mask & truly_out).any()  # no clear outlier accepted
    assert mask[np.setdiff1d(np.arange(200), outliers)].mean() > 0.95  # inliers kept
    R_est, t_est, _ = recover_pose(E, xy1[mask], xy2[mask])
    assert rotation_angle_deg(R, R_est) < 0.5
    assert np.degrees(np.arccos(np.clip(t_est @ t / np.linalg.norm(t), -1, 1))) < 5.0
    # same seed, same answer; an int seed works too
    E2, mask2 = estimate_essential_ransac(xy1, xy2, np.random.default_rng(7), threshold=1.5 / 200.0)
    np.testing.assert_array_equal(E, E2)
    np.testing.assert_array_equal(mask, mask2)
    E3, _ = estimate_essential_ransac(xy1, xy2, 7, threshold=1.5 / 200.0)
    np.testing.assert_array_equal(E, E3)


def test_ransac_noise_free_exact(rng):
    R, t, _, xy1, xy2, _, _ = make_scene(rng, n=30)
    E, mask = estimate_essential_ransac(xy1, xy2, rng, threshold=1e-6, max_iterations=10)
    assert mask.all()
    assert same_up_to_scale(E, essential_from_pose(R, t)) < 1e-9


def test_ransac_bad_input(rng):
    xy = rng.normal(size=(10, 2))
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        estimate_essential_ransac(xy, xy, None)
    with pytest.raises(ValueError, match="threshold must be a positive"):
        estimate_essential_ransac(xy, xy, rng, threshold=0.0)
    with pytest.raises(ValueError, match="max_iterations must be a positive integer"):
        estimate_essential_ransac(xy, xy, rng, max_iterations=0)
    with pytest.raises(ValueError, match="at least 8 correspondences"):
        estimate_essential_ransac(xy[:5], xy[:5], rng)
