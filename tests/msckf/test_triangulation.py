"""Tests for evio_lib.msckf.triangulation: exact recovery on noise-free tracks, agreement with scipy's least_squares
(an independent optimiser in plain XYZ) on noisy tracks, every rejection reason, the analytic Jacobian against finite
differences, the batched solver against the single one, and bad input."""
import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.stats import norm
from scipy.spatial.transform import Rotation

from evio_lib.msckf.triangulation import (
    TRIANGULATION_REASONS,
    TriangulationResult,
    as_camera_poses,
    relative_to_anchor,
    triangulate_inverse_depth,
    triangulate_inverse_depth_batch,
    triangulate_two_view_initial,
    triangulation_jacobian,
    triangulation_residual,
)

FOCAL_PX = 200.0  # the noise model: 1 px at f = 200 px


# ---------------------------------------------------------------- helpers (independent of the library)


def project(R_GtoC: np.ndarray, p_CinG: np.ndarray, p_FinG: np.ndarray) -> np.ndarray:
    """Normalised coordinates (M, 2) of p_FinG in each camera: [X/Z, Y/Z] of R_GtoC (p_FinG - p_CinG)."""
    p_C = np.einsum("mij,mj->mi", R_GtoC, p_FinG - p_CinG)
    return p_C[:, :2] / p_C[:, 2:]


def random_track(rng: np.random.Generator, M: int, depth: float = 5.0, spread: float = 0.7, tilt: float = 0.25):
    """Cameras scattered around the origin looking roughly along +z_G at a feature about ``depth`` away.

    Returns (R_GtoC (M, 3, 3), p_CinG (M, 3), p_FinG (3,), obs (M, 2) noise-free)."""
    p_FinG = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), depth])
    p_CinG = rng.normal(scale=spread, size=(M, 3))
    R_CtoG = Rotation.from_rotvec(rng.normal(scale=tilt, size=(M, 3))).as_matrix()
    R_GtoC = np.swapaxes(R_CtoG, 1, 2)
    return R_GtoC, p_CinG, p_FinG, project(R_GtoC, p_CinG, p_FinG)


def jpl_quaternions(R_GtoC: np.ndarray) -> np.ndarray:
    """JPL q_GtoC: the Hamilton (scipy) quaternion of the transposed matrix."""
    return Rotation.from_matrix(np.swapaxes(R_GtoC, 1, 2)).as_quat()


def scipy_triangulate(R_GtoC, p_CinG, obs, start):
    """Independent least-squares solution in Cartesian p_FinG (scipy's trust-region reflective solver)."""

    def fun(x):
        return (project(R_GtoC, p_CinG, x) - obs).ravel()

    return least_squares(fun, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x


# ---------------------------------------------------------------- noise-free: exact


def test_noise_free_random_tracks_are_recovered_exactly(rng):
    worst = 0.0
    for k in range(60):
        M = int(rng.integers(2, 16))
        R, p, p_F, obs = random_track(rng, M, depth=rng.uniform(2.0, 20.0))
        result = triangulate_inverse_depth(R, p, obs)
        assert isinstance(result, TriangulationResult)
        assert result.success and result.reason == "ok", (k, result)
        assert result.p_FinG.shape == (3,) and result.inverse_depth.shape == (3,)
        worst = max(worst, float(np.abs(result.p_FinG - p_F).max()))
        assert result.cost < 1e-20 and result.max_residual < 1e-10 and result.rms_residual < 1e-10
    assert worst < 1e-8


def test_noise_free_with_large_rotations_and_quaternion_input(rng):
    # cameras on a circle around the feature, all looking at it: rotations up to ±60 degrees
    p_F = np.array([0.2, -0.1, 0.3])
    angles = np.linspace(-1.0, 1.0, 7)
    p_C = np.column_stack([4.0 * np.sin(angles), 0.1 * angles, -4.0 * np.cos(angles)]) + p_F
    R_CtoG = Rotation.from_rotvec(np.column_stack([np.zeros(7), -angles, np.zeros(7)])).as_matrix()
    R_GtoC = np.swapaxes(R_CtoG, 1, 2)
    obs = project(R_GtoC, p_C, p_F)
    assert np.all(np.abs(obs) < 0.1)  # the construction really looks at the feature
    for poses in (R_GtoC, jpl_quaternions(R_GtoC)):
        result = triangulate_inverse_depth(poses, p_C, obs)
        assert result.success
        np.testing.assert_allclose(result.p_FinG, p_F, atol=1e-9)


def test_converges_from_a_poor_initial_guess(rng):
    R, p, p_F, obs = random_track(rng, 8, depth=6.0)
    result = triangulate_inverse_depth(R, p, obs, initial_p_FinG=p_F + np.array([0.5, -0.4, 2.5]))
    assert result.success and result.iterations > 2
    np.testing.assert_allclose(result.p_FinG, p_F, atol=1e-8)


def test_inverse_depth_parameters_and_anchor_choice(rng):
    R, p, p_F, obs = random_track(rng, 6)
    for anchor in (0, 3, -1):
        result = triangulate_inverse_depth(R, p, obs, anchor=anchor)
        a = anchor % 6
        assert result.anchor == a
        p_FinA = R[a] @ (p_F - p[a])  # (α, β, ρ) = (X/Z, Y/Z, 1/Z) in the anchor camera
        np.testing.assert_allclose(result.inverse_depth, [*(p_FinA[:2] / p_FinA[2]), 1 / p_FinA[2]], atol=1e-10)
        np.testing.assert_allclose(result.p_FinG, p_F, atol=1e-8)
        baseline = np.linalg.norm(p - p[a], axis=1).max()
        assert result.baseline_ratio == pytest.approx(baseline / p_FinA[2], rel=1e-9)


def test_inputs_are_not_modified(rng):
    R, p, _, obs = random_track(rng, 5)
    copies = [R.copy(), p.copy(), obs.copy()]
    triangulate_inverse_depth(R, p, obs)
    triangulate_inverse_depth_batch([(R, p, obs)])
    for before, after in zip(copies, (R, p, obs)):
        np.testing.assert_array_equal(before, after)


# ---------------------------------------------------------------- noisy: the least-squares optimum


def test_noisy_tracks_reach_the_least_squares_optimum_and_error_statistics(rng):
    sigma = 1.0 / FOCAL_PX
    rel_errors, gaps = [], []
    for _ in range(40):
        R, p, p_F, obs = random_track(rng, int(rng.integers(4, 16)), depth=rng.uniform(3.0, 10.0))
        noisy = obs + rng.normal(scale=sigma, size=obs.shape)
        result = triangulate_inverse_depth(R, p, noisy)
        assert result.success, result
        reference = scipy_triangulate(R, p, noisy, p_F)
        gaps.append(np.linalg.norm(result.p_FinG - reference) / np.linalg.norm(reference - p.mean(0)))
        # the optimum is at least as good as the truth in the least-squares sense
        truth_cost = np.sum((project(R, p, p_F) - noisy) ** 2)
        assert result.cost <= truth_cost * (1 + 1e-9)
        # and its residual is what reprojecting p_FinG gives
        assert result.cost == pytest.approx(np.sum((project(R, p, result.p_FinG) - noisy) ** 2), rel=1e-9)
        rel_errors.append(np.linalg.norm(result.p_FinG - p_F) / np.linalg.norm(p_F - p[0]))
    assert max(gaps) < 1e-6  # same minimum as an independent solver in another parametrisation
    rel_errors = np.array(rel_errors)
    print(f"1 px at f = 200: relative position error median {np.median(rel_errors):.4f}, max {rel_errors.max():.4f}")
    # 1 px at f = 200 with ~1.4 m baselines at 3-10 m: errors of a few percent, never wild
    assert np.median(rel_errors) < 0.03 and rel_errors.max() < 0.2


def test_batch_matches_single_calls(rng):
    tracks, singles = [], []
    for k in range(25):
        R, p, _, obs = random_track(rng, int(rng.integers(1, 12)))
        noisy = obs + rng.normal(scale=1.0 / FOCAL_PX, size=obs.shape)
        poses = jpl_quaternions(R) if k % 3 == 0 else R
        tracks.append((poses, p, noisy))
        singles.append(triangulate_inverse_depth(poses, p, noisy))
    tracks.append((np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 2))))
    singles.append(triangulate_inverse_depth(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 2))))
    batch = triangulate_inverse_depth_batch(tracks)
    assert len(batch) == len(tracks)
    for one, many in zip(singles, batch):
        assert (one.reason, one.success, one.iterations, one.anchor) == (many.reason, many.success, many.iterations,
                                                                         many.anchor)
        np.testing.assert_allclose(many.p_FinG, one.p_FinG, atol=1e-10)
        np.testing.assert_allclose(many.inverse_depth_std, one.inverse_depth_std, rtol=1e-9)
    assert triangulate_inverse_depth_batch([]) == []


def test_inverse_depth_std_matches_the_spread_over_noise_draws(rng):
    """The reported σ of (α, β, ρ) against the empirical spread of the estimates over 1 500 noise draws, for a
    distant point seen over a short baseline (aerial-like: 300 m away, 3 m of travel): ρ's noise is then about as
    large as ρ itself, so a fair share of the draws land behind the cameras, as the filter sees in flight."""
    M, sigma = 6, 1.0 / FOCAL_PX
    p_F = np.array([20.0, -10.0, 300.0])
    p = np.column_stack([np.linspace(0.0, 3.0, M), np.zeros(M), np.zeros(M)])
    R = Rotation.from_rotvec(rng.normal(scale=0.02, size=(M, 3))).as_matrix().transpose(0, 2, 1)
    obs = project(R, p, p_F)
    draws = [(R, p, obs + rng.normal(scale=sigma, size=obs.shape)) for _ in range(1500)]
    results = triangulate_inverse_depth_batch(draws, max_depth=1e9)
    theta = np.array([r.inverse_depth for r in results])
    reported = sigma * np.array([r.inverse_depth_std for r in results])
    empirical = theta.std(axis=0)
    print(f"rho {1 / 300:.5f}: empirical std {empirical.round(6)}, reported (median) {np.median(reported, 0).round(6)}")
    np.testing.assert_allclose(np.median(reported, axis=0), empirical, rtol=0.1)
    # noise alone puts some behind the cameras, as many as a normal ρ with that σ predicts
    behind, predicted = np.mean(theta[:, 2] <= 0), norm.cdf(-(1 / 300) / empirical[2])
    assert behind > 0.02 and behind == pytest.approx(predicted, abs=0.02)
    # the noise-free track: the closed form for a lateral baseline, σ_ρ ≈ σ / sqrt(Σ (b_i - b̄)^2)
    exact = triangulate_inverse_depth(R, p, obs, max_depth=1e9)
    b = p[:, 0] - p[0, 0]
    assert sigma * exact.inverse_depth_std[2] == pytest.approx(sigma / np.sqrt(np.sum((b - b.mean()) ** 2)), rel=0.1)
    # without a baseline the depth is not measured at all
    same_centre = triangulate_inverse_depth(R, np.zeros((M, 3)), obs)
    assert same_centre.reason == "insufficient_baseline" and same_centre.inverse_depth_std[2] == np.inf


# ---------------------------------------------------------------- rejections


def two_cameras_at(offset: np.ndarray, p_F: np.ndarray):
    R = np.stack([np.eye(3)] * 3)
    p = np.array([[0.0, 0.0, 0.0], offset, 0.5 * offset + [0.0, 0.3 * np.linalg.norm(offset), 0.0]])
    return R, p, project(R, p, p_F)


def test_every_rejection_reason_is_triggered(rng):
    seen = {}
    p_F = np.array([0.3, -0.2, 5.0])

    # too few observations
    R, p, obs = two_cameras_at(np.array([1.0, 0.0, 0.0]), p_F)
    seen["too_few_observations"] = triangulate_inverse_depth(R[:1], p[:1], obs[:1])
    # all cameras at one centre (pure rotation): depth unobservable
    R_rot = np.swapaxes(Rotation.from_rotvec(rng.normal(scale=0.1, size=(4, 3))).as_matrix(), 1, 2)
    p_same = np.tile([1.0, 2.0, 3.0], (4, 1))
    no_baseline = triangulate_inverse_depth(R_rot, p_same, project(R_rot, p_same, p_F + [1.0, 2.0, 3.0]))
    assert no_baseline.reason == "insufficient_baseline"
    # a 1 mm baseline at 5 m (ratio 2e-4 < 2e-3): converges exactly but is rejected
    R, p, obs = two_cameras_at(np.array([0.001, 0.0, 0.0]), p_F)
    seen["insufficient_baseline"] = triangulate_inverse_depth(R, p, obs)
    # one Levenberg-Marquardt step from a poor guess cannot converge
    R, p, obs = two_cameras_at(np.array([1.0, 0.0, 0.0]), p_F)
    seen["not_converged"] = triangulate_inverse_depth(R, p, obs, max_iterations=1, initial_p_FinG=p_F + [1.0, 1.0, 3.0])
    # rays that meet behind the cameras: the least-squares point has negative depth
    R, p, obs = two_cameras_at(np.array([1.0, 0.0, 0.0]), np.array([0.3, -0.2, -5.0]))
    seen["behind_camera"] = triangulate_inverse_depth(R, p, obs)
    # a feature 5 cm in front of the cameras
    R, p, obs = two_cameras_at(np.array([0.02, 0.0, 0.0]), np.array([0.01, 0.0, 0.05]))
    seen["too_close"] = triangulate_inverse_depth(R, p, obs)
    # a feature at 50 m when at most 20 m is allowed
    R, p, obs = two_cameras_at(np.array([2.0, 0.0, 0.0]), np.array([1.0, 2.0, 50.0]))
    seen["too_far"] = triangulate_inverse_depth(R, p, obs, max_depth=20.0)
    # one gross outlier among six observations
    R, p, p_true, obs = random_track(rng, 6)
    obs[2] += [0.3, -0.2]
    seen["large_residual"] = triangulate_inverse_depth(R, p, obs)
    # and a good one
    R, p, obs = two_cameras_at(np.array([1.0, 0.0, 0.0]), p_F)
    seen["ok"] = triangulate_inverse_depth(R, p, obs)

    assert set(seen) == set(TRIANGULATION_REASONS)
    for reason, result in seen.items():
        assert result.reason == reason, (reason, result)
        assert result.success == (reason == "ok")
        for value in (result.p_FinG, result.inverse_depth, result.cost, result.max_residual, result.baseline_ratio):
            assert np.all(np.isfinite(value))
    assert seen["behind_camera"].inverse_depth[2] < 0
    assert seen["large_residual"].rms_residual > 0.025
    assert seen["insufficient_baseline"].baseline_ratio == pytest.approx(0.001 / 5.0, rel=1e-6)


def test_thresholds_are_honoured(rng):
    R, p, p_F, obs = random_track(rng, 5, depth=8.0)
    ok = triangulate_inverse_depth(R, p, obs)
    assert ok.success
    assert triangulate_inverse_depth(R, p, obs, min_baseline_ratio=ok.baseline_ratio * 1.01).reason == \
        "insufficient_baseline"
    assert triangulate_inverse_depth(R, p, obs, min_depth=8.0 * 1.5).reason == "too_close"
    noisy = obs + rng.normal(scale=0.01, size=obs.shape)
    loose = triangulate_inverse_depth(R, p, noisy, max_rms_residual=1.0)
    assert loose.success
    tight = triangulate_inverse_depth(R, p, noisy, max_rms_residual=0.5 * loose.rms_residual)
    assert tight.reason == "large_residual"


def test_random_garbage_never_gives_nan(rng):
    tracks = []
    for _ in range(200):
        M = int(rng.integers(0, 8))
        R = np.swapaxes(Rotation.random(M, random_state=rng).as_matrix(), 1, 2) if M else np.zeros((0, 3, 3))
        scale = 10.0 ** rng.uniform(-4, 1)
        tracks.append((R, rng.normal(scale=scale, size=(M, 3)), rng.uniform(-3, 3, size=(M, 2))))
    results = triangulate_inverse_depth_batch(tracks)
    reasons = {r.reason for r in results}
    assert reasons <= set(TRIANGULATION_REASONS) and len(reasons) >= 3
    for r in results:
        assert all(np.all(np.isfinite(v)) for v in (r.p_FinG, r.inverse_depth, r.cost, r.max_residual,
                                                    r.rms_residual, r.baseline_ratio))


# ---------------------------------------------------------------- two-view initial guess


def test_two_view_midpoint(rng):
    R, p, p_F, obs = random_track(rng, 5)
    point, ok = triangulate_two_view_initial(R, p, obs)
    assert ok
    np.testing.assert_allclose(point, p_F, atol=1e-10)
    point, ok = triangulate_two_view_initial(jpl_quaternions(R), p, obs, pair=(3, 1))
    assert ok
    np.testing.assert_allclose(point, p_F, atol=1e-10)
    # skew rays: the midpoint of the common perpendicular (closed form for rays along x and y axes)
    R2 = np.stack([np.eye(3), np.eye(3)])
    p2 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    point, ok = triangulate_two_view_initial(R2, p2, [[0.0, 0.0], [-0.2, 0.02]])
    # ray 1: (0, 0, s); ray 2: (1 - 0.2 t, 0.02 t, t); least squares by scipy as the truth
    sol = least_squares(lambda st: [-(1 - 0.2 * st[1]), -0.02 * st[1], st[0] - st[1]], [1.0, 1.0]).x
    truth = 0.5 * (np.array([0.0, 0.0, sol[0]]) + np.array([1 - 0.2 * sol[1], 0.02 * sol[1], sol[1]]))
    assert ok
    np.testing.assert_allclose(point, truth, atol=1e-8)


def test_two_view_reports_parallel_and_backward_rays():
    R = np.stack([np.eye(3)] * 2)
    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    point, ok = triangulate_two_view_initial(R, p, [[0.1, 0.2], [0.1, 0.2]])  # parallel rays
    assert not ok and np.all(np.isfinite(point))
    point, ok = triangulate_two_view_initial(R, p, [[-0.1, 0.0], [0.1, 0.0]])  # rays diverge: meet behind
    assert not ok and np.all(np.isfinite(point))


# ---------------------------------------------------------------- residual and Jacobian


def test_residual_is_the_reprojection_error(rng):
    R, p, p_F, obs = random_track(rng, 7)
    noisy = obs + rng.normal(scale=0.01, size=obs.shape)
    R_AtoC, p_AinC = relative_to_anchor(R, p, anchor=2)
    p_FinA = R[2] @ (p_F - p[2])
    theta = np.array([p_FinA[0] / p_FinA[2], p_FinA[1] / p_FinA[2], 1.0 / p_FinA[2]])
    e = triangulation_residual(theta, R_AtoC, p_AinC, noisy)
    np.testing.assert_allclose(e, (obs - noisy).ravel(), atol=1e-12)
    np.testing.assert_allclose(R_AtoC[2], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(p_AinC[2], 0.0, atol=1e-12)


def test_jacobian_matches_central_differences(rng):
    for _ in range(10):
        R, p, p_F, obs = random_track(rng, int(rng.integers(2, 9)))
        R_AtoC, p_AinC = relative_to_anchor(R, p)
        theta = np.array([*rng.uniform(-0.3, 0.3, 2), rng.uniform(0.05, 0.5)])
        J = triangulation_jacobian(theta, R_AtoC, p_AinC)
        assert J.shape == (2 * len(p), 3)
        numeric = np.zeros_like(J)
        step = 1e-6
        for k in range(3):
            d = np.zeros(3)
            d[k] = step
            numeric[:, k] = (triangulation_residual(theta + d, R_AtoC, p_AinC, obs)
                             - triangulation_residual(theta - d, R_AtoC, p_AinC, obs)) / (2 * step)
        np.testing.assert_allclose(J, numeric, rtol=1e-6, atol=1e-8)


# ---------------------------------------------------------------- bad input


def test_bad_input_raises(rng):
    R, p, _, obs = random_track(rng, 4)
    with pytest.raises(ValueError, match=r"R_GtoC must have shape \(M, 3, 3\)"):
        triangulate_inverse_depth(R[:, :2], p, obs)
    with pytest.raises(ValueError, match=r"p_CinG must have shape \(M, 3\)"):
        triangulate_inverse_depth(R, p[:, :2], obs)
    with pytest.raises(ValueError, match="p_CinG must have one row per camera"):
        triangulate_inverse_depth(R, p[:3], obs)
    with pytest.raises(ValueError, match=r"obs_xy must have shape \(M, 2\)"):
        triangulate_inverse_depth(R, p, obs.ravel())
    with pytest.raises(ValueError, match="obs_xy must have one row per camera"):
        triangulate_inverse_depth(R, p, obs[:2])
    bad = obs.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="obs_xy must contain only finite"):
        triangulate_inverse_depth(R, p, bad)
    with pytest.raises(ValueError, match="p_CinG must contain only finite"):
        triangulate_inverse_depth(R, p + [np.inf, 0, 0], obs)
    with pytest.raises(ValueError, match="R_GtoC must hold rotation matrices"):
        triangulate_inverse_depth(R * 1.1, p, obs)
    with pytest.raises(ValueError, match="non-zero norms"):
        as_camera_poses(np.zeros((4, 4)), p)
    with pytest.raises(ValueError, match="max_iterations must be a positive integer"):
        triangulate_inverse_depth(R, p, obs, max_iterations=0)
    with pytest.raises(ValueError, match="max_depth must exceed min_depth"):
        triangulate_inverse_depth(R, p, obs, min_depth=5.0, max_depth=2.0)
    with pytest.raises(ValueError, match="step_tol must be a finite number > 0"):
        triangulate_inverse_depth(R, p, obs, step_tol=-1.0)
    with pytest.raises(ValueError, match="anchor must index every track"):
        triangulate_inverse_depth(R, p, obs, anchor=4)
    with pytest.raises(ValueError, match="anchor must be an integer"):
        triangulate_inverse_depth(R, p, obs, anchor=0.5)
    with pytest.raises(ValueError, match=r"initial_p_FinG must have shape \(3,\)"):
        triangulate_inverse_depth(R, p, obs, initial_p_FinG=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"tracks\[1\]\[2\] \(obs_xy\) must have one row per camera"):
        triangulate_inverse_depth_batch([(R, p, obs), (R, p, obs[:3])])
    with pytest.raises(ValueError, match=r"tracks\[0\] must be a tuple"):
        triangulate_inverse_depth_batch([R])
    with pytest.raises(ValueError, match=r"tracks\[1\]\[0\] \(R_GtoC\) must hold rotation matrices"):
        triangulate_inverse_depth_batch([(R, p, obs), (2 * R, p, obs)])
    with pytest.raises(ValueError, match=r"initial_p_FinG must have shape \(2, 3\)"):
        triangulate_inverse_depth_batch([(R, p, obs), (R, p, obs)], initial_p_FinG=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="at least 2 observations"):
        triangulate_two_view_initial(R[:1], p[:1], obs[:1])
    with pytest.raises(ValueError, match="pair must name two distinct cameras"):
        triangulate_two_view_initial(R, p, obs, pair=(1, 1))
    with pytest.raises(ValueError, match=r"pair\[1\] must be an integer camera index"):
        triangulate_two_view_initial(R, p, obs, pair=(0, 9))
    R_AtoC, p_AinC = relative_to_anchor(R, p)
    with pytest.raises(ValueError, match=r"inverse_depth must have shape \(3,\)"):
        triangulation_jacobian([0.1, 0.2], R_AtoC, p_AinC)
    with pytest.raises(ValueError, match="inverse_depth must contain only finite"):
        triangulation_residual([0.1, np.nan, 0.2], R_AtoC, p_AinC, obs)
    with pytest.raises(ValueError, match=r"p_AinC must have shape \(4, 3\)"):
        triangulation_jacobian([0.1, 0.2, 0.2], R_AtoC, p_AinC[:2])
    with pytest.raises(ValueError, match="off every camera's plane"):
        triangulation_jacobian([0.0, 0.0, 1.0], np.eye(3)[None], [[0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match="anchor must be an integer camera index"):
        relative_to_anchor(R, p, anchor=7)
