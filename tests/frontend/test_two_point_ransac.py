"""Tests of evio_lib.frontend.two_point_ransac on synthetic correspondences with a known rotation and translation."""
import numpy as np
import pytest

from evio_lib.frontend.two_point_ransac import (
    _sampson,
    compensate_rotation,
    translation_constraints,
    two_point_ransac,
)
from evio_lib.geometry.epipolar import sampson_distance
from evio_lib.geometry.rotation import skew, so3_exp

FOCAL = 200.0


def _scene(rng, n=80, R=None, t=(0.1, -0.05, 0.08), noise_px=0.0, outliers=0, outlier_px=(8.0, 40.0)):
    """Return (x1, x2, R, t, is_outlier): points at 2-6 m seen from two cameras, X_C2 = R X_C1 + t."""
    R = so3_exp([0.05, -0.08, 0.03]) if R is None else R
    t = np.asarray(t, dtype=float)
    X1 = rng.uniform([-2.0, -1.5, 2.0], [2.0, 1.5, 6.0], size=(n, 3))
    X2 = X1 @ R.T + t
    x1 = X1[:, :2] / X1[:, 2:]
    x2 = X2[:, :2] / X2[:, 2:]
    x1 = x1 + rng.normal(0.0, noise_px / FOCAL, x1.shape)
    x2 = x2 + rng.normal(0.0, noise_px / FOCAL, x2.shape)
    bad = np.zeros(n, bool)
    bad[rng.choice(n, outliers, replace=False)] = True
    angle = rng.uniform(0, 2 * np.pi, outliers)
    size = rng.uniform(*outlier_px, outliers) / FOCAL
    x2[bad] += np.stack([np.cos(angle), np.sin(angle)], axis=1) * size[:, None]
    return x1, x2, R, t, bad


def _epipolar_px(x1, x2, R, t):
    """Sampson distance (px) of each match to the true essential matrix [t x] R (geometry.epipolar)."""
    return sampson_distance(skew(t) @ R, x1, x2) * FOCAL


def test_keeps_every_inlier_and_finds_the_translation_without_noise():
    rng = np.random.default_rng(0)
    x1, x2, R, t, _ = _scene(rng)
    res = two_point_ransac(x1, x2, R, focal_px=FOCAL)
    assert res.inliers.all() and not res.degenerate
    assert abs(abs(res.t_dir @ t) / np.linalg.norm(t) - 1.0) < 1e-9  # parallel to the true t, up to sign
    assert res.residuals_px.max() < 1e-9


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rejects_injected_outliers_and_keeps_noisy_inliers(seed):
    rng = np.random.default_rng(seed)
    x1, x2, R, t, bad = _scene(rng, n=100, noise_px=0.3, outliers=30)
    res = two_point_ransac(x1, x2, R, focal_px=FOCAL, threshold_px=1.5, rng=seed)
    truth_px = _epipolar_px(x1, x2, R, t)
    # an outlier that lands on (or within noise of) its epipolar line cannot be told apart: check those 2x beyond
    detectable = bad & (truth_px > 3.0)
    assert detectable.sum() >= 25
    assert not res.inliers[detectable].any()
    assert res.inliers[~bad].mean() >= 0.97  # 0.3 px noise: a few inliers near the threshold may go
    angle = np.degrees(np.arccos(min(1.0, abs(res.t_dir @ t) / np.linalg.norm(t))))
    assert angle < 5.0


def test_the_gyro_prior_matters_under_rotation():
    rng = np.random.default_rng(4)
    # a roll of 8.6 deg about the optical axis (up to 40 px of flow); a small pan or tilt would look like a sideways
    # translation and fit without the prior
    x1, x2, R, _, _ = _scene(rng, R=so3_exp([0.0, 0.0, 0.15]))
    assert two_point_ransac(x1, x2, R, focal_px=FOCAL).inliers.all()
    without = two_point_ransac(x1, x2, None, focal_px=FOCAL)  # the identity: the rotation is not removed
    assert without.inliers.mean() < 0.5


def test_pure_rotation_is_degenerate_and_classified_by_displacement():
    rng = np.random.default_rng(5)
    x1, x2, R, _, bad = _scene(rng, t=(0.0, 0.0, 0.0), noise_px=0.2, outliers=10)
    res = two_point_ransac(x1, x2, R, focal_px=FOCAL)
    assert res.degenerate and np.all(res.t_dir == 0.0)
    np.testing.assert_array_equal(res.inliers, ~bad)  # outliers move >= 8 px, inliers < 1 px
    displacement = np.linalg.norm(compensate_rotation(x1, R) - x2, axis=1) * FOCAL
    np.testing.assert_allclose(res.residuals_px, displacement)


def test_a_lone_far_match_is_not_confirmed_by_static_points():
    rng = np.random.default_rng(6)
    x1, x2, R, _, _ = _scene(rng, n=40, t=(0.0, 0.0, 0.0))
    x2[0] += [30.0 / FOCAL, 0.0]  # one match moved 30 px, everything else still
    x2[1] += [0.0, 20.0 / FOCAL]  # and another one, in another direction: two always fit a translation
    res = two_point_ransac(x1, x2, R, focal_px=FOCAL)
    assert res.degenerate and not res.inliers[:2].any() and res.inliers[2:].all()


def test_max_displacement_rejects_outright():
    rng = np.random.default_rng(7)
    x1, x2, R, t, _ = _scene(rng, t=(0.4, 0.0, 0.0))  # a large sideways step: up to 40 px of flow
    flow = np.linalg.norm(compensate_rotation(x1, R) - x2, axis=1) * FOCAL
    res = two_point_ransac(x1, x2, R, focal_px=FOCAL, max_displacement_px=25.0)
    np.testing.assert_array_equal(res.inliers, flow <= 25.0)


def test_constraints_and_sampson_match_independent_formulas():
    rng = np.random.default_rng(8)
    g = rng.normal(0, 0.3, (20, 2))
    f = g + rng.normal(0, 0.02, (20, 2))
    c = translation_constraints(g, f)
    np.testing.assert_allclose(c, np.cross(np.c_[g, np.ones(20)], np.c_[f, np.ones(20)]), atol=1e-15)
    t = rng.normal(size=(3, 3))
    expected = np.stack([sampson_distance(skew(ti), g, f) for ti in t])
    np.testing.assert_allclose(_sampson(t, g, f), expected, rtol=1e-12)


def test_compensate_rotation_and_points_turned_behind():
    xy = np.array([[0.0, 0.0], [0.5, -0.2]])
    R = so3_exp([0.0, 0.2, 0.0])
    g = compensate_rotation(xy, R)
    f = np.c_[xy, np.ones(2)] @ R.T
    np.testing.assert_allclose(g, f[:, :2] / f[:, 2:], atol=1e-15)
    behind = compensate_rotation(xy, so3_exp([0.0, np.pi, 0.0]))
    assert np.isnan(behind).all()


def test_few_matches_are_kept_and_outputs_are_deterministic():
    x = np.array([[0.1, 0.2], [0.3, -0.1]])
    res = two_point_ransac(x, x + 0.05, np.eye(3), focal_px=FOCAL)
    assert res.inliers.tolist() == [True, True] and not res.degenerate
    empty = two_point_ransac(np.zeros((0, 2)), np.zeros((0, 2)), None, focal_px=FOCAL)
    assert empty.inliers.shape == (0,)
    rng = np.random.default_rng(9)
    x1, x2, R, _, _ = _scene(rng, noise_px=0.5, outliers=20)
    a = two_point_ransac(x1, x2, R, focal_px=FOCAL, rng=3)
    b = two_point_ransac(x1, x2, R, focal_px=FOCAL, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a.inliers, b.inliers)
    np.testing.assert_array_equal(a.t_dir, b.t_dir)


def test_inputs_are_not_modified():
    rng = np.random.default_rng(10)
    x1, x2, R, _, _ = _scene(rng, outliers=5)
    copies = x1.copy(), x2.copy(), R.copy()
    two_point_ransac(x1, x2, R, focal_px=FOCAL)
    for before, after in zip(copies, (x1, x2, R)):
        np.testing.assert_array_equal(before, after)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(xy_prev=np.zeros((3, 3))), "xy_prev must have shape"),
        (dict(xy_curr=np.zeros((4, 2))), "same shape"),
        (dict(xy_prev=np.full((3, 2), np.nan)), "finite"),
        (dict(R_prev_to_curr=np.ones((3, 3))), "must be a rotation"),
        (dict(R_prev_to_curr=np.eye(2)), r"\(3, 3\)"),
        (dict(focal_px=0.0), "focal_px"),
        (dict(threshold_px=-1.0), "threshold_px"),
        (dict(iterations=0), "iterations"),
        (dict(max_displacement_px=0.0), "max_displacement_px"),
        (dict(rng=-1), "rng"),
    ],
)
def test_bad_input_raises_a_clear_error(kwargs, message):
    args = dict(xy_prev=np.zeros((3, 2)), xy_curr=np.zeros((3, 2)), R_prev_to_curr=np.eye(3), focal_px=FOCAL)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        two_point_ransac(args.pop("xy_prev"), args.pop("xy_curr"), args.pop("R_prev_to_curr"), **args)
