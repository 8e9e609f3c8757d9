# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 12 — Triangulation and the MSCKF update
#
# Lesson 11 built the filter's state and let the IMU push it forward; the uncertainty only grew. This lesson closes
# the loop: a feature tracked over several images says where the cameras were *relative to each other*, and the
# MSCKF turns that into a correction of the whole sliding window. It follows the thesis (Friedel 2020, §3.3.6-3.3.7,
# Eqs. 41-79) and Mourikis & Roumeliotis (2007), who introduced the filter.
#
# The chain for one feature, drawn below:
#
# 1. **triangulate** its 3-D position from the estimated camera poses (inverse depth, Gauss-Newton);
# 2. **predict** its image coordinates in every camera and form the residual and Jacobians $H_x$, $H_f$;
# 3. **whiten** each observation by its own noise covariance, so that every row has unit noise;
# 4. **project out** the feature error with the left nullspace of $H_f$;
# 5. **gate** it with a chi-square test;
# 6. stack all features, **compress** by QR and apply one **Kalman** update in Joseph form.
#
# Each step is one function of `evio_lib.msckf`. Section 10 writes the whole filter loop out with them, runs it on a
# simulated `boxes_like` sequence and checks it against the library's `Msckf.run`.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")
import dataclasses

import matplotlib.pyplot as plt
import numpy as np
import scipy.linalg
from IPython.display import Markdown, display
from scipy.stats import chi2

from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_msckf import (
    plot_feature_update_schematic,
    plot_trajectory_errors,
    plot_triangulation_error,
)
from evio_lib.evaluation.trajectory_metrics import summarize
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import quat_to_rot, so3_exp
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.geometry.pixel_noise import observation_covariance
from evio_lib.msckf.experiment import VioSimConfig
from evio_lib.msckf.feature_database import whitening_matrices
from evio_lib.msckf.filter import Msckf
from evio_lib.msckf.initialization import initial_state_from_truth
from evio_lib.msckf.propagation import propagate
from evio_lib.msckf.state import remove_camera_states
from evio_lib.msckf.triangulation import (
    relative_to_anchor,
    triangulate_inverse_depth,
    triangulate_inverse_depth_batch,
    triangulation_jacobian,
    triangulation_residual,
)
from evio_lib.msckf.update import (
    chi_square_gate,
    chi_square_threshold,
    feature_jacobians,
    gating_mean_shrink,
    kalman_update,
    measurement_compress,
    nullspace_project,
)
from evio_lib.sim.imu import ImuNoiseParams, synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.tracks import simple_geometry, simulate_feature_tracks
from evio_lib.sim.trajectory import trajectory_from_preset

FAST = fast_mode()
rng = np.random.default_rng(11)
camera = PinholeRadtan.davis240c()
ext = CameraImuExtrinsics.default()
SIGMA = 1.0 / camera.fx  # 1 pixel in normalised image units

# %% [markdown]
# The update of one feature in three pictures: (a) a feature seen from several camera clones (the poses the state
# holds); its position is not in the state, it is triangulated from the clones. (b) In each image the measured point
# and its prediction give a residual $r_i$; its noise $\Sigma_i$ is an ellipse (the lens's undistortion stretches the
# pixel noise), and multiplying by $W_i = L_i^{-1}$ turns it into a unit circle. (c) The stacked residual is split: the
# part an error of the feature could explain is dropped, the rest, $r_o = A^T r$, constrains the clones.

# %%
fig = plot_feature_update_schematic(num_clones=5)
plt.show()

# %% [markdown]
# ## 1. A feature track from the simulator
#
# We take ten images (20 Hz) of the simulated hand-held `boxes_like` motion, compute the true camera poses
# $(R_{G\to C_i}, p_{C_i}^G)$ from the IMU poses and the extrinsics, and project one landmark 2.5 m in front of the
# first camera. The observations $z_i = (X/Z, Y/Z)$ are undistorted normalised coordinates, the filter's input.

# %%
traj = trajectory_from_preset("boxes_like", duration=10.0, seed=0)
times = 2.0 + 0.05 * np.arange(10)
truth = traj.evaluate(times)
R_CtoG, p_CinG = ext.camera_pose(truth.R_ItoG, truth.p_IinG)
R_GtoC = np.swapaxes(R_CtoG, 1, 2)
p_FinG_true = p_CinG[0] + R_CtoG[0] @ np.array([0.3, -0.2, 2.5])  # a point 2.5 m in front of camera 0


def project(R_GtoC, p_CinG, p_FinG):
    """z_i = [X/Z, Y/Z] of p_FinC_i = R_GtoC_i (p_FinG - p_CinG_i)   (Eqs. 41-42)."""
    p_C = np.einsum("mij,mj->mi", R_GtoC, p_FinG - p_CinG)
    return p_C[:, :2] / p_C[:, 2:]


z_true = project(R_GtoC, p_CinG, p_FinG_true)
baseline = np.linalg.norm(p_CinG - p_CinG[0], axis=1).max()
print(f"camera centres moved by {baseline:.3f} m")
print("observations (normalised):\n", np.round(z_true[:3], 4))

# %% [markdown]
# ## 2. The inverse-depth parametrisation (Eqs. 59-67, 79)
#
# Express the feature in the **anchor** camera $A$ (its first observation) by $\theta = (\alpha, \beta, \rho) =
# (X/Z, Y/Z, 1/Z)$. With the anchor's pose in camera $i$, $R_{A\to C_i}$ and $p_A^{C_i}$,
#
# $$p_F^{C_i} = R_{A\to C_i}\, p_F^A + p_A^{C_i}
#   = Z_A \Big( R_{A\to C_i} \begin{bmatrix}\alpha\\ \beta\\ 1\end{bmatrix} + \rho\, p_A^{C_i} \Big) = Z_A\, h_i(\theta),
# \qquad g_i(\theta) = \frac{1}{h_{i3}} \begin{bmatrix} h_{i1} \\ h_{i2} \end{bmatrix}.$$
#
# The unknown depth $Z_A$ cancels in the projection. Two things make this the favourite parametrisation of
# monocular SLAM: $h_i$ is *linear* in $\theta$, and a very far point is just $\rho \to 0$, with no infinity in
# sight. The estimate returns to the world frame by (Eq. 79)
# $p_F^G = R_{G\to A}^T [\alpha, \beta, 1]^T / \rho + p_A^G$.
#
# Below, a few lines of NumPy evaluate $g_i$ and agree with the library's `triangulation_residual`; the analytic
# Jacobian (Eqs. 72-78) agrees with central finite differences.

# %%
R_AtoC, p_AinC = relative_to_anchor(R_GtoC, p_CinG, anchor=0)
p_FinA = R_GtoC[0] @ (p_FinG_true - p_CinG[0])
theta_true = np.array([p_FinA[0] / p_FinA[2], p_FinA[1] / p_FinA[2], 1.0 / p_FinA[2]])


def g_by_hand(theta):
    h = R_AtoC @ np.array([theta[0], theta[1], 1.0]) + theta[2] * p_AinC  # h_i = R [α, β, 1] + ρ p   (Eqs. 60-64)
    return h[:, :2] / h[:, 2:]  # g_i = [h1, h2] / h3                                                  (Eq. 67)


assert np.allclose(g_by_hand(theta_true), z_true, atol=1e-12)
assert np.allclose(triangulation_residual(theta_true, R_AtoC, p_AinC, z_true), 0.0, atol=1e-12)

J = triangulation_jacobian(theta_true, R_AtoC, p_AinC)
eps = 1e-6
J_fd = np.column_stack([(g_by_hand(theta_true + eps * e) - g_by_hand(theta_true - eps * e)).ravel() / (2 * eps)
                        for e in np.eye(3)])
print("max |J - J_fd| =", f"{np.abs(J - J_fd).max():.1e}")
assert np.allclose(J, J_fd, atol=1e-7)

# %% [markdown]
# ## 3. Gauss-Newton on noisy tracks
#
# The estimate minimises $\sum_i |g_i(\theta) - z_i|^2$ with Gauss-Newton steps
# $\Delta\theta = H^{-1} b$, $H = \sum J_i^T \Omega J_i$, $b = -\sum J_i^T \Omega e_i$, with $e_i = g_i(\theta) - z_i$
# and $\Omega = \sigma^{-2} I$ the information matrix of a measurement (Eqs. 68-71). The library damps the steps in
# the Levenberg-Marquardt way: it adds $\lambda\,\mathrm{diag}(H)$ to $H$, raising $\lambda$ after a step that made
# the cost worse (towards small gradient steps) and lowering it after one that helped (towards Gauss-Newton). It
# starts from the midpoint of the anchor camera's viewing ray and the ray of the camera farthest from it.
# How good is it? A Monte-Carlo over pixel noise and over the number of views of the same track;
# `triangulate_inverse_depth_batch` solves all trials of a setting at once. A median from a finite number of trials
# has its own scatter: its standard error comes from a bootstrap (the median of the trials resampled with replacement,
# 200 times), drawn as ±2 standard errors.

# %%
n_trials = 400 if FAST else 4000
noise_levels_px = [0.0, 0.5, 1.0, 2.0]
view_counts = [2, 3, 5, 10]
median_error = np.zeros((len(noise_levels_px), len(view_counts)))
median_se = np.zeros_like(median_error)  # bootstrap standard error of each median
failed = np.zeros(median_error.shape, dtype=int)
iterations = []  # Levenberg-Marquardt iterations of every noisy solve
for a, noise_px in enumerate(noise_levels_px):
    for b, m in enumerate(view_counts):
        idx = np.linspace(0, 9, m).round().astype(int)  # always spans the same 0.45 s of motion
        z = z_true[idx] + noise_px * SIGMA * rng.standard_normal((n_trials, m, 2))
        results = triangulate_inverse_depth_batch([(R_GtoC[idx], p_CinG[idx], z_k) for z_k in z])
        errs = np.array([np.linalg.norm(res.p_FinG - p_FinG_true) if res.success else np.nan for res in results])
        failed[a, b] = np.count_nonzero(np.isnan(errs))
        median_error[a, b] = np.nanmedian(errs)
        median_se[a, b] = np.nanmedian(rng.choice(errs, size=(200, n_trials)), axis=1).std()
        if noise_px > 0:
            iterations += [res.iterations for res in results]

fig = plot_triangulation_error(view_counts, median_error[1:], noise_levels_px[1:],  # the noisy rows
                               title="Triangulation error, feature at 2.5 m", standard_error=median_se[1:])
plt.show()
print("noise-free error [m]:", median_error[0].round(12))
print(f"median error [cm] of {n_trials} trials (± bootstrap standard error)  views:"
      + "".join(f"{m:13d}" for m in view_counts))
for a, noise_px in enumerate(noise_levels_px[1:], start=1):
    print(f"        {noise_px:3g} px noise" + " " * 36
          + "".join(f"{100 * e:7.1f} ±{100 * s:4.1f}" for e, s in zip(median_error[a], median_se[a])))
print("failed triangulations (left out of the medians):", failed[1:].tolist())
drop5 = 1 - median_error[1:, 2] / median_error[1:, 0]  # 2 -> 5 views, per noise level
gain = median_error[1:, 0] / median_error[1:, -1]  # 2 -> 10 views
# two medians are ranked when they differ by more than 2 standard errors of their difference
separated = np.abs(np.diff(median_error[1:], axis=1)) > 2 * np.hypot(median_se[1:, 1:], median_se[1:, :-1])
print(f"Gauss-Newton (LM) iterations per noisy solve: median {np.median(iterations):.0f}, "
      f"90th percentile {np.percentile(iterations, 90):.0f}")
assert median_error[0].max() < 1e-6  # exact data -> exact point
assert np.all(median_error[1:, -1] < median_error[1:, 0])  # 10 views of the same motion beat 2, at every noise level
assert np.all(np.diff(median_error[1:], axis=0) > 0)  # more noise -> worse, at every number of views
assert np.all(gain < np.sqrt(10 / 2))  # ... but by less than 1/sqrt(M)
assert np.median(iterations) <= 6  # the solver stops at 10
sigma_Z = 2.5**2 * 1.0 / (camera.fx * baseline)  # linear depth error for 1 px: Z^2 σ / (f b)
assert sigma_Z < median_error[2, 0] < 3 * sigma_Z

# %%
pairs = [f"{view_counts[b]} and {view_counts[b + 1]} views at {noise_levels_px[a + 1]:g} px"
         for a, b in zip(*np.nonzero(~separated))]
display(Markdown(
    f"The error grows with the pixel noise at every number of views, and more views help: from 2 to 5 views the "
    f"median falls by {100 * drop5.min():.0f}-{100 * drop5.max():.0f} % across the noise levels, from 2 to 10 views "
    f"it is divided by {gain.min():.2f}-{gain.max():.2f}, much less than the $\\sqrt{{10/2}}$ = "
    f"{np.sqrt(5):.2f} that $1/\\sqrt{{M}}$ would give. "
    + (f"Neighbouring view counts are not always ranked by these {n_trials} trials: "
       f"{', '.join(pairs)} differ by less than two standard errors. " if pairs else
       f"Every neighbouring pair of view counts differs by more than two standard errors here. ")
    + f"The extra views of the same 0.45 s lie *between* the two end cameras, so they add observations but little "
    f"new parallax (their baselines to the anchor are shorter). The parallax is what limits the depth: the cameras "
    f"move only {baseline:.3f} m while the point is 2.5 m away, so the two end rays meet at an angle of only "
    f"{np.degrees(baseline / 2.5):.1f}°, and one pixel of noise ({np.degrees(1 / camera.fx):.2f}° for this camera) "
    f"already moves the point by decimetres. Depth is the weak direction; to linear order its error is "
    f"$\\sigma_Z \\approx Z^2\\sigma/(f\\,b)$ ($\\sigma$ and $f$ in pixels), here {sigma_Z:.2f} m for 1 px against "
    f"a measured median of {median_error[2, 0]:.2f} m with 2 views, so it grows with the square of the depth and "
    f"shrinks only with a longer baseline. Gauss-Newton needs a median of {np.median(iterations):.0f} iterations."))

# %% [markdown]
# ### When triangulation refuses
#
# A bad 3-D point would poison the update, so the library checks every result and names the first failed check
# (`TriangulationResult.reason`). Constructed examples for each reason but `not_converged`, which Exercise 2
# provokes:

# %%
eye3 = np.stack([np.eye(3)] * 3)
line = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.4, 0.0, 0.0]])  # cameras on a line, looking along +z


def observe(point, R=eye3, p=line):
    return project(R, p, np.asarray(point, dtype=float))


cases = {
    "too_few_observations": (eye3[:1], line[:1], observe([0.0, 0.0, 3.0])[:1]),
    "insufficient_baseline": (eye3, np.zeros((3, 3)) + [0.0, 0.0, 0.0], observe([0.0, 0.0, 3.0], p=np.zeros((3, 3)))),
    "behind_camera": (eye3, line, -observe([0.1, 0.0, 3.0])),  # rays that only meet behind the cameras
    "too_close": (eye3, line, observe([0.2, 0.0, 0.05])),
    "too_far": (eye3, line * 1e-2, observe([0.0, 0.0, 2000.0], p=line * 1e-2)),
    "large_residual": (eye3, line, observe([0.0, 0.0, 3.0]) + [[0.0, 0.0], [0.1, 0.05], [-0.1, 0.0]]),
    "ok": (eye3, line, observe([0.1, -0.1, 3.0])),
}
for expected, (R, p, z) in cases.items():
    res = triangulate_inverse_depth(R, p, z, min_baseline_ratio=1e-6 if expected == "too_far" else 0.002)
    print(f"{expected:22s} -> {res.reason:22s} rms residual {res.rms_residual / SIGMA:7.2f} px")
    assert res.reason == expected

# %% [markdown]
# ## 4. Measurement model and Jacobians (Eqs. 41-48)
#
# For the filter the feature position is now fixed at its triangulated value $\hat p_F^G$ and every observation
# gives a residual $r_i = z_i - \hat z_i$. Linearised around the estimate (attitude error
# $R_{G\to C,\text{true}} \approx (I - [\delta\theta\times]) \hat R_{G\to C}$, position error $\delta p$):
#
# $$r_i \approx H_{C_i} \begin{bmatrix}\delta\theta_{C_i}\\ \delta p_{C_i}\end{bmatrix} + H_{f_i}\, \delta p_F^G + n_i,
# \quad H_{C_i} = J_i \big[ [p_F^{C_i}\times],\; -R_{G\to C_i} \big], \quad H_{f_i} = J_i R_{G\to C_i},\quad
# J_i = \frac{1}{Z}\begin{bmatrix}1 & 0 & -X/Z\\ 0 & 1 & -Y/Z\end{bmatrix}.$$
#
# A finite-difference check of both Jacobians on a window of five camera states (columns $15 + 6i$):

# %%
win = np.arange(0, 10, 2)  # five camera states in the window
M = len(win)
state_dim = 15 + 6 * M
cols = 15 + 6 * np.arange(M)
z_meas = z_true[win] + SIGMA * rng.standard_normal((M, 2))
r, H_x, H_f = feature_jacobians(R_GtoC[win], p_CinG[win], cols, p_FinG_true, z_meas, state_dim)


def z_hat_after(dx, dp_F):
    """Predicted measurements after the error-state perturbation dx (state_dim,) and feature error dp_F (3,)."""
    blocks = dx[15:].reshape(M, 6)
    R_pert = np.stack([so3_exp(-b[:3]) for b in blocks]) @ R_GtoC[win]  # R_true = exp(-[δθ x]) R
    return project(R_pert, p_CinG[win] + blocks[:, 3:], p_FinG_true + dp_F).ravel()


z0 = z_hat_after(np.zeros(state_dim), np.zeros(3))
H_x_fd = np.column_stack([(z_hat_after(eps * e, np.zeros(3)) - z_hat_after(-eps * e, np.zeros(3))) / (2 * eps)
                          for e in np.eye(state_dim)])
H_f_fd = np.column_stack([(z_hat_after(np.zeros(state_dim), eps * e) - z_hat_after(np.zeros(state_dim), -eps * e))
                          / (2 * eps) for e in np.eye(3)])
print("max |H_x - FD| =", f"{np.abs(H_x - H_x_fd).max():.1e}", " max |H_f - FD| =", f"{np.abs(H_f - H_f_fd).max():.1e}")
assert np.allclose(H_x, H_x_fd, atol=1e-7) and np.allclose(H_f, H_f_fd, atol=1e-7)
assert np.allclose(r, z_meas.ravel() - z0)  # r = z_meas - z_hat   (Eq. 43)

# %% [markdown]
# ## 5. Whitening: every observation with its own noise
#
# The residual's noise is not always the same for every observation. The tracker measures pixels in the *distorted*
# image, and the filter works in undistorted normalised coordinates: undistortion maps a pixel-noise circle to an
# ellipse, larger towards the border of a wide-angle lens. To first order, observation $i$ has the covariance
# $\Sigma_i = \sigma_{px}^2 J_i J_i^T$ with $J_i$ the Jacobian of the undistortion at its pixel
# (`observation_covariance`). With the Cholesky factor $\Sigma_i = L_i L_i^T$ and $W_i = L_i^{-1}$,
#
# $$W_i r_i \approx W_i H_{C_i}\,\delta x_{C_i} + W_i H_{f_i}\,\delta p_F + W_i n_i,\qquad
# \mathrm{Cov}(W_i n_i) = W_i \Sigma_i W_i^T = I:$$
#
# multiplying the two rows of each observation (of $r$, $H_x$ and $H_f$) by its $W_i$ gives a system whose noise is
# $N(0, I)$, the same for every row. This **whitening** comes *before* the nullspace projection of section 6 (next
# section: why). With the same $\sigma$ for all, $W_i = I/\sigma$ is a mere rescaling. A feature near the image corner
# shows the difference: the same track geometry as section 4, but the point seen near the border.

# %%
p_F_corner = p_CinG[0] + R_CtoG[0] @ (2.5 * np.array([0.5, 0.36, 1.0]))  # near the corner of camera 0
p_FinC_corner = np.einsum("mij,mj->mi", R_GtoC[win], p_F_corner - p_CinG[win])
uv_corner = camera.project(p_FinC_corner)  # distorted pixels
Sigma = observation_covariance(camera, uv_corner, 1.0)  # (M, 2, 2): 1 px of pixel noise, undistorted
W = whitening_matrices(Sigma)
axes_sd = np.sqrt(np.linalg.eigvalsh(Sigma)) * camera.fx  # the ellipses' semi-axes, in units of 1/f
print("pixels (u, v):", uv_corner.round(0).tolist())
print("noise ellipse semi-axes in units of 1/f (1 = an undistorted pixel):", axes_sd.round(2).tolist())
assert np.allclose(W @ Sigma @ np.swapaxes(W, 1, 2), np.eye(2), atol=1e-9)  # W Σ W^T = I
assert np.all((uv_corner >= 0) & (uv_corner < [camera.width, camera.height]))  # inside the image
assert axes_sd.max() > 1.3  # visibly anisotropic near the corner

# %% [markdown]
# ## 6. Projecting out the feature (Eq. 50)
#
# $\hat p_F^G$ was computed *from* the camera poses, so its error is correlated with the state error and $r$ cannot
# be used as it is. The MSCKF removes it: with $A$ an orthonormal basis of the **left nullspace** of the whitened
# $H_f$ ($A^T H_f = 0$, $A^T A = I$, size $2M \times (2M-3)$),
#
# $$r_o = A^T r \approx A^T H_x\, \delta x + A^T n,$$
#
# a residual that depends on the state only. Three of the $2M$ rows are spent on the unknown point. A basis: the last
# $2M - 3$ columns of a complete QR of $H_f$ (the thesis takes it from an SVD of $H_f$, §3.3.6.2; any orthonormal
# basis of the nullspace gives the same update, checked below). Because $A^T A = I$, the whitened noise stays
# white: $\mathrm{Cov}(A^T n) = A^T I A = I$. First the track of section 4 (the same $\sigma$ for all):

# %%
W_iso = np.eye(2 * M) / SIGMA  # whitening with Σ_i = σ² I
r_w, H_x_w, H_f_w = W_iso @ r, W_iso @ H_x, W_iso @ H_f
Q_full, _ = np.linalg.qr(H_f_w, mode="complete")
A = Q_full[:, 3:]
print("A:", A.shape, " max |A^T H_f| =", f"{np.abs(A.T @ H_f_w).max():.1e}")
assert np.allclose(A.T @ H_f_w, 0.0, atol=1e-9) and np.allclose(A.T @ A, np.eye(2 * M - 3), atol=1e-12)

H_o, r_o = nullspace_project(H_x_w, H_f_w, r_w)
# any orthonormal basis of the same nullspace gives the same information H_o^T H_o and H_o^T r_o
assert np.allclose(H_o.T @ H_o, (A.T @ H_x_w).T @ (A.T @ H_x_w), rtol=1e-9, atol=1e-6)
assert np.allclose(H_o.T @ r_o, (A.T @ H_x_w).T @ (A.T @ r_w), rtol=1e-9, atol=1e-9)

# %% [markdown]
# **Why whiten first.** Take the corner feature. Projected *after* whitening, the noise of $r_o$ has covariance
# $I$, and the information $H_o^T H_o$ it gives about the cameras is exactly what the full Gaussian model says once
# the feature is eliminated: $H_x^T\Sigma^{-1}H_x - H_x^T\Sigma^{-1}H_f (H_f^T\Sigma^{-1}H_f)^{-1}H_f^T\Sigma^{-1}H_x$
# (a Schur complement, with $\Sigma$ the block-diagonal of the $\Sigma_i$). Projected on the nullspace of the raw
# $H_f$ and then treated as $\sigma^2 I$, the noise $A^T n$ has covariance $A^T\Sigma A$, which is not $\sigma^2 I$:
# the gate and the update would assume the wrong noise.

# %%
_, H_x_c, H_f_c = feature_jacobians(R_GtoC[win], p_CinG[win], cols, p_F_corner, p_FinC_corner[:, :2]
                                    / p_FinC_corner[:, 2:], state_dim)
W_big = scipy.linalg.block_diag(*W)  # rows 2i, 2i+1 multiplied by W_i
Sigma_big = scipy.linalg.block_diag(*Sigma)
A_w = np.linalg.qr(W_big @ H_f_c, mode="complete")[0][:, 3:]  # whiten, then project
A_raw = np.linalg.qr(H_f_c, mode="complete")[0][:, 3:]  # project the raw rows
cov_whitened = A_w.T @ W_big @ Sigma_big @ W_big.T @ A_w
cov_raw = A_raw.T @ Sigma_big @ A_raw / SIGMA**2  # in units of the σ² the filter would assume
info_whitened = (A_w.T @ W_big @ H_x_c).T @ (A_w.T @ W_big @ H_x_c)
S_inv = np.linalg.inv(Sigma_big)
info_exact = H_x_c.T @ S_inv @ H_x_c - H_x_c.T @ S_inv @ H_f_c @ np.linalg.solve(H_f_c.T @ S_inv @ H_f_c,
                                                                                   H_f_c.T @ S_inv @ H_x_c)
info_raw = (A_raw.T @ H_x_c).T @ (A_raw.T @ H_x_c) / SIGMA**2
scale = np.abs(info_exact).max()
eig_raw = np.linalg.eigvalsh(cov_raw)
print(f"whiten, then project: max |Cov(r_o) - I| = {np.abs(cov_whitened - np.eye(2 * M - 3)).max():.1e}; "
      f"information off the exact one by {np.abs(info_whitened - info_exact).max() / scale:.1e} (relative)")
print(f"project, then assume σ² I: eigenvalues of Cov(r_o)/σ² from {eig_raw.min():.2f} to {eig_raw.max():.2f}; "
      f"information off by {np.abs(info_raw - info_exact).max() / scale:.2f} (relative)")
assert np.abs(cov_whitened - np.eye(2 * M - 3)).max() < 1e-9
assert np.abs(info_whitened - info_exact).max() < 1e-8 * scale
assert eig_raw.max() > 1.2 and np.abs(info_raw - info_exact).max() > 0.05 * scale

# %% [markdown]
# ## 7. QR compression (Eqs. 51-55)
#
# Stacking $L$ features gives $H_o$ with many more rows than the state has columns. Its thin QR
# $H_o = [Q_1\ Q_2] \begin{bmatrix} T_H \\ 0\end{bmatrix}$ lets us keep only $r_n = Q_1^T r_o = T_H\, \delta x + Q_1^T n_o$:
# $Q_2^T r_o$ is pure noise. The update is unchanged because the information is:
# $H_o^T H_o = T_H^T T_H$ and $H_o^T r_o = T_H^T r_n$.

# %%
H_stack, r_stack = [], []
for k in range(30):  # 30 landmarks around the first one, all seen by the same five cameras
    p_F = p_FinG_true + rng.normal(0.0, 0.5, 3)
    z_k = project(R_GtoC[win], p_CinG[win], p_F) + SIGMA * rng.standard_normal((M, 2))
    r_k, Hx_k, Hf_k = feature_jacobians(R_GtoC[win], p_CinG[win], cols, p_F, z_k, state_dim)
    Ho_k, ro_k = nullspace_project(Hx_k / SIGMA, Hf_k / SIGMA, r_k / SIGMA)  # whitened (Σ = σ² I), projected
    H_stack.append(Ho_k)
    r_stack.append(ro_k)
H_big, r_big = np.vstack(H_stack), np.concatenate(r_stack)
T_H, r_n = measurement_compress(H_big, r_big)
print(f"stacked rows {H_big.shape[0]} -> compressed rows {T_H.shape[0]} (state size {state_dim})")
assert T_H.shape[0] <= state_dim  # at most the state size
assert np.allclose(T_H.T @ T_H, H_big.T @ H_big, atol=1e-9)
assert np.allclose(T_H.T @ r_n, H_big.T @ r_big, atol=1e-12)

# %% [markdown]
# ## 8. The chi-square gate
#
# Before a feature enters the update it must be *plausible*: if the filter is right, $r_o \sim \mathcal N(0, S)$
# with $S = H_o P H_o^T + I$ (whitened rows: unit noise), so the Mahalanobis distance $\gamma = r_o^T S^{-1} r_o$ follows a
# $\chi^2$ law with $2M - 3$ degrees of freedom. A gate at **95 %** accepts the feature when $\gamma$ is below the
# 95 % quantile: 95 % of good features pass, a gross outlier does not. S-MSCKF (Sun et al. 2018, a stereo MSCKF whose
# code is msckf_vio) describes such a gate, but msckf_vio's own lookup table is filled with
# `chi_squared_distribution.quantile(0.05)`, the *5 %* quantile: it rejects ~95 % of correct features unless
# its noise is set very large. The thesis describes no such gate: its outliers are removed earlier, by two-point
# RANSAC in the front-end (§3.3.5), and §3.3.6.1 selects features by track length only. A Monte-Carlo check with
# errors drawn from the filter's own covariance:

# %%
P_cam = np.diag(np.tile([1e-4] * 3 + [1e-4] * 3, M))  # 0.01 rad and 1 cm per camera state
P = np.zeros((state_dim, state_dim))
P[:15, :15] = np.eye(15) * 1e-4
P[15:, 15:] = P_cam
n_gate = 400 if FAST else 4000
L_P = np.linalg.cholesky(P)
dof = H_o.shape[0]
gammas, passed = [], []
for _ in range(n_gate):
    dx = L_P @ rng.standard_normal(state_dim)
    r_sample = H_o @ dx + rng.standard_normal(dof)  # r_o = H_o δx + n_o, n_o ~ N(0, I): whitened rows
    ok, gamma = chi_square_gate(H_o, r_sample, P, 1.0)
    passed.append(ok)
    gammas.append(gamma)
rate = np.mean(passed)
wrong_threshold = chi2.ppf(0.05, dof)
print(f"dof {dof}: threshold 95% = {chi_square_threshold(dof):.2f}, pass rate {100 * rate:.1f} %")
print(f"with the 5% quantile ({wrong_threshold:.2f}) only {100 * np.mean(np.array(gammas) < wrong_threshold):.1f} % "
      "of correct features would pass")
wrong_rate = np.mean(np.array(gammas) < wrong_threshold)
assert abs(rate - 0.95) < (0.035 if FAST else 0.012) and abs(wrong_rate - 0.05) < (0.035 if FAST else 0.012)

outlier = r_o + 20 * np.r_[1.0, -1.0, np.zeros(dof - 2)]  # two whitened rows of r_o off by 20 σ (σ = 1 px)
print("a 20-pixel outlier passes?", chi_square_gate(H_o, outlier, P, 1.0)[0])
assert not chi_square_gate(H_o, outlier, P, 1.0)[0]

# %% [markdown]
# **The price of a gate.** A gate also drops 5 % of the *correct* features, and not at random: the ones with the
# largest residuals. When the state is off by $\delta x$, a correct residual is $r = \mu + n$ with $\mu = H\delta x$, and
# the residuals that survive the gate point less far along $\mu$ than the whole population does: to first order
# their mean is $s\,\mu$ with $s = F_{k+2}(c)/F_k(c)$ ($F_k$ the $\chi^2_k$ CDF, $c$ the threshold;
# `gating_mean_shrink`). Each update then corrects only a fraction $s$ of the error it sees while $P$ shrinks as if
# it had corrected all of it: the filter becomes overconfident. S-MSCKF's two-state prune gives 1-row features
# ($k = 1$), where $s = 0.76$ at 95 %. The library therefore gates every feature on its whole track (larger $k$:
# $s = 0.97$ at 95 % for 20 observations, $k = 37$). The filter's default gate stays at 95 %
# (`MsckfConfig.chi2_probability`, the gate of section 10); only the Monte-Carlo consistency experiment of
# lesson 13 (`evio_lib.msckf.experiment`, `VioSimConfig.gate_probability`), whose simulated tracks hold no outliers,
# gates at 0.99 ($s = 0.99$ for $k = 37$). A Monte-Carlo check of the closed form, with its standard error:

# %%
k_rows, mu = 1, 0.1  # one whitened residual row shifted by 0.1 sigma
n_mc = 2_000_000
r_mc = mu + rng.standard_normal((n_mc, k_rows))
shrink, shrink_se = {}, {}
for prob in (0.95, 0.99, 0.999):
    kept = np.einsum("ij,ij->i", r_mc, r_mc) < chi_square_threshold(k_rows, prob)
    shrink[prob] = r_mc[kept, 0].mean() / mu
    shrink_se[prob] = r_mc[kept, 0].std() / np.sqrt(kept.sum()) / mu  # standard error of the ratio
    print(f"gate {prob}: mean of kept residuals / mu = {shrink[prob]:.3f} ± {shrink_se[prob]:.3f}  "
          f"(closed form {gating_mean_shrink(k_rows, prob):.3f})")
print(f"closed form s at 0.95: {gating_mean_shrink(1, 0.95):.2f} for k = 1, {gating_mean_shrink(37, 0.95):.2f} for "
      f"k = 37 (20 observations); at 0.99: {gating_mean_shrink(37, 0.99):.2f} for k = 37")
assert all(abs(shrink[p] - gating_mean_shrink(k_rows, p)) < 4 * shrink_se[p] for p in shrink)
assert gating_mean_shrink(1, 0.95) < 0.8 < 0.98 < gating_mean_shrink(37, 0.99)
assert round(gating_mean_shrink(1, 0.95), 2) == 0.76 and round(gating_mean_shrink(37, 0.95), 2) == 0.97
assert round(gating_mean_shrink(37, 0.99), 2) == 0.99
assert MsckfConfig().chi2_probability == 0.95 and VioSimConfig().gate_probability == 0.99  # the two gates named above

# %%
display(Markdown(
    f"The Monte-Carlo ratios lie within "
    f"{max(abs(shrink[p] - gating_mean_shrink(k_rows, p)) / shrink_se[p] for p in shrink):.1f} "
    f"standard errors of the closed form (standard error {shrink_se[0.95]:.3f}): at this $\\mu$ the Monte-Carlo "
    f"cannot tell the closed form's first-order error from its own noise."))

# %% [markdown]
# ## 9. The Kalman update in Joseph form (Eqs. 56-58)
#
# $$K = P T_H^T (T_H P T_H^T + R_n)^{-1}, \qquad \Delta x = K r_n, \qquad
#   P^+ = (I - K T_H) P (I - K T_H)^T + K R_n K^T ,$$
#
# with $R_n = I$ for whitened rows. This is the standard Kalman (EKF) update of the Kalman-filter lesson:
# $T_H P T_H^T + R_n$ is the covariance the filter predicts for the residual $r_n$, and the gain $K$ weighs that
# residual against the prior $P$ to give the correction $\Delta x$ and the smaller posterior $P^+$. For the optimal
# gain the Joseph form equals the short $(I - KH)P$, but it stays symmetric and positive semi-definite under
# rounding. The compressed and the full stacked systems give the same update:

# %%
dx_c, P_c = kalman_update(P, T_H, r_n, 1.0)  # whitened rows: R_n = I
dx_full, P_full = kalman_update(P, H_big, r_big, 1.0)
S = H_big @ P @ H_big.T + np.eye(H_big.shape[0])
K = np.linalg.solve(S, H_big @ P).T  # K = P H^T S^-1 written out
assert np.allclose(dx_c, dx_full, atol=1e-12) and np.allclose(P_c, P_full, atol=1e-12)
assert np.allclose(dx_full, K @ r_big, atol=1e-12)
assert np.allclose(P_full, (np.eye(state_dim) - K @ H_big) @ P, atol=1e-12)
print("sigma of camera 0 position before / after [mm]:", np.round(1e3 * np.sqrt(np.diag(P)[18:21]), 2),
      np.round(1e3 * np.sqrt(np.diag(P_c)[18:21]), 2))
print("smallest eigenvalue of P+:", f"{np.linalg.eigvalsh(P_c).min():.2e}")

# %% [markdown]
# ## 10. The filter loop, written out
#
# Everything above, chained over a sequence of images, is the MSCKF. Per image:
#
# 1. **propagate** the state with the IMU samples to the image time (lesson 11);
# 2. **augment** the state with a clone of the camera pose;
# 3. append the image's observations to their tracks, each with its whitening matrix $W_i$;
# 4. **collect** the tracks that ended (not seen in this image) and are long enough to triangulate, and, when the
#    window is over $N_{max}$ clones, the tracks seen by at least two of the oldest third, which is about to go;
# 5. for each: **triangulate**, the residual and Jacobians, **whiten**, **project** on the left nullspace, **gate**
#    (on the whole track: a pruned track's update uses only the rows of the clones about to go);
# 6. **stack** the survivors, **compress** by QR and apply one **Kalman update** with $R = I$ (the rows are white);
# 7. **marginalise** the oldest clones (drop their rows and columns of $P$).
#
# With the defaults of `MsckfConfig` the window holds $N_{max} = 40$ clones and the oldest third of a full window is
# used and removed at once (Mourikis & Roumeliotis 2007). S-MSCKF (Sun et al. 2018) keeps 20 and prunes two at a
# time, chosen by a keyframe rule (the second-latest state if it barely moved from the one before it, else the
# oldest); the thesis prunes two states by the same kind of rule (§3.3.6.1) and gives no value of $N_{max}$. Every
# feature is gated at 95 %. The library's default also constrains the filter's linearisation so that it cannot gain
# information about directions no sensor observes (the observability-constrained EKF, lesson 13); it is switched off
# here (`observability_constrained=False`), so this is the plain EKF that the loop below writes out.
#
# The data: the simulator's tracks with perfect data association, landmarks in the `boxes_like` room, ~60 tracks
# per image at 20 Hz, 1 px of pixel noise in the distorted image (each observation's $\Sigma_i$ from its pixel, as
# in section 5), and a noisy 1 kHz IMU whose biases the filter does not know.

# %%
duration = 4.0 if FAST else 10.0
sim_rng = np.random.default_rng(5)
traj = trajectory_from_preset("boxes_like", duration=duration, seed=0)
imu_noise = ImuNoiseParams()
imu = synthesize_imu(traj, 1000.0, imu_noise, sim_rng)
frame_times = np.arange(0.05, duration - 1e-9, 0.05)
frames = simulate_feature_tracks(traj, ext, camera, simple_geometry("boxes_like"), frame_times, sim_rng,
                                 pixel_noise_px=1.0, features_per_frame=60)
frame_input = [(f.t, f.ids, f.xy, observation_covariance(camera, f.uv, 1.0)) for f in frames]
config = dataclasses.replace(MsckfConfig().with_imu_noise(imu_noise), observability_constrained=False)
print(f"{len(frames)} images; window N_max = {config.max_camera_states}, prune a third: {config.marginalize_third}, "
      f"gate {config.chi2_probability}, tracks need >= {config.min_track_length} observations")
assert config.max_camera_states == 40 and config.marginalize_third and config.chi2_probability == 0.95
s0 = traj.evaluate(0.0)
state0 = initial_state_from_truth(0.0, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], ext.R_CtoI, ext.p_CinI, config)


# %%
def msckf_by_hand(config, state, imu, frames):
    """The MSCKF loop; frames: (t, ids, xy, xy_cov) per image. Returns positions, features used per image, state."""
    tracks, positions, n_used = {}, [], []  # tracks: feature id -> [(clone id, xy, W)]
    for clone, (t_k, ids, xy, xy_cov) in enumerate(frames):
        state = propagate(state, imu.t, imu.gyro, imu.accel, t_k, config)  # 1. IMU to the image time
        state = augment_state(state, camera_id=clone)  # 2. clone the camera pose
        for fid, z, W_i in zip(ids.tolist(), xy, whitening_matrices(xy_cov)):  # 3. observations, W_i = L_i^-1
            tracks.setdefault(fid, []).append((clone, z, W_i))
        seen = set(ids.tolist())
        ended = [tracks.pop(fid) for fid in list(tracks) if fid not in seen]  # 4. tracks that ended ...
        uses = [(track, np.ones(len(track), bool)) for track in ended if len(track) >= config.min_track_length]
        window = state.camera_ids
        old = window[: len(window) // 3] if len(window) > config.max_camera_states else ()
        for fid, track in tracks.items():  # ... and tracks seen by >= 2 of the oldest third
            involved = np.array([c in old for c, _, _ in track])
            if involved.sum() >= 2:
                uses.append((track, involved))
            tracks[fid] = [obs for obs in track if obs[0] not in old]
        q_C, p_C = state.camera_poses
        R_C, slot = quat_to_rot(q_C), {c: i for i, c in enumerate(window)}
        H_rows, r_rows = [], []
        for track, involved in uses:  # 5. per feature
            i = np.array([slot[c] for c, _, _ in track])
            z = np.array([obs[1] for obs in track])
            result = triangulate_inverse_depth(R_C[i], p_C[i], z, **config.triangulation_settings())
            if not result.success:
                continue
            r, H_x, H_f = feature_jacobians(R_C[i], p_C[i], 15 + 6 * i, result.p_FinG, z, state.dim)
            W_t = scipy.linalg.block_diag(*[obs[2] for obs in track])
            r, H_x, H_f = W_t @ r, W_t @ H_x, W_t @ H_f  # whiten: unit noise on every row
            H_o, r_o = nullspace_project(H_x, H_f, r)  # the feature drops out
            if not chi_square_gate(H_o, r_o, state.P, 1.0, config.chi2_probability)[0]:
                continue
            if not involved.all():  # a pruned track: only the rows of the clones about to go
                rows = np.repeat(involved, 2)
                H_o, r_o = nullspace_project(H_x[rows], H_f[rows], r[rows])
            H_rows.append(H_o)
            r_rows.append(r_o)
        if H_rows:  # 6. one update
            T_H, r_n = measurement_compress(np.vstack(H_rows), np.concatenate(r_rows))
            dx, P_new = kalman_update(state.P, T_H, r_n, 1.0)
            state = state.inject_error(dx).replace(P=P_new)
        state = remove_camera_states(state, old)  # 7. marginalise the oldest third
        tracks = {fid: track for fid, track in tracks.items() if track}
        positions.append(state.imu.p_IinG)
        n_used.append(len(H_rows))
    return np.array(positions), np.array(n_used), state


# %% [markdown]
# The same data through the hand-written loop and through the library's `Msckf.run`, which does the same steps with
# the features batched by track length:

# %%
p_hand, used_hand, state_hand = msckf_by_hand(config, state0, imu, frame_input)
msckf = Msckf(config, state0)
outputs = msckf.run(imu.t, imu.gyro, imu.accel, frame_input)
t = np.array([o.t for o in outputs])
p_est = np.array([o.p_IinG for o in outputs])
used_lib = np.array([o.n_features_used for o in outputs])
gap = np.linalg.norm(p_hand - p_est, axis=1)
first = int(np.argmax(gap > 0)) if np.any(gap > 0) else None
print(f"features used: {used_hand.sum()} by the loop, {used_lib.sum()} by Msckf.run, "
      f"the same at every image: {np.array_equal(used_hand, used_lib)}")
print(f"largest position difference {gap.max():.1e} m"
      + (f"; the first, at image {first} (t = {t[first]:.2f} s), {gap[first]:.1e} m "
         f"= {gap[first] / np.linalg.norm(p_est[first]):.0e} of the position" if first is not None else ""))
print(f"largest covariance difference at the end {np.abs(state_hand.P - msckf.state.P).max():.1e} "
      f"(largest entry {np.abs(msckf.state.P).max():.1e})")
assert np.array_equal(used_hand, used_lib)  # the same features pass the same gates
assert gap.max() < 1e-6 and np.abs(state_hand.P - msckf.state.P).max() < 1e-6 * np.abs(msckf.state.P).max()

# %%
display(Markdown(
    f"The loop and `Msckf.run` use the same features at every image and end at the same estimate"
    + (f": the first difference, at image {first}, is {gap[first]:.0e} m, "
       f"{gap[first] / np.linalg.norm(p_est[first]):.0e} of the position, a rounding in the last digit (the library "
       f"computes the same sums in another order, all features of one track length at once); "
       f"later updates carry such differences on, and the largest is {gap.max():.0e} m, "
       f"nanometres." if first is not None else ", bit for bit.")
    + " From here on, `Msckf.run` is the filter of this lesson."))

# %% [markdown]
# Dead reckoning from the same start (IMU only: the same loop without updates) is the baseline:

# %%
imu_only = Msckf(dataclasses.replace(config, imu_only=True), state0).run(imu.t, imu.gyro, imu.accel, frame_input)
p_imu = np.array([o.p_IinG for o in imu_only])
sigma_p = np.array([o.sigma[12:15] for o in outputs])
p_gt = traj.evaluate(t).p_IinG
row = summarize(t, p_est, t, p_gt, name="MSCKF")
row_imu = summarize(t, p_imu, t, p_gt, name="IMU-only")
for rw in (row, row_imu):
    print(f"{rw['name']:9s} RMSE {rw['rmse_m']:7.3f} m  final {rw['final_error_m']:7.3f} m  "
          f"{rw['percent_of_distance']:7.2f} % of {rw['distance_m']:.1f} m")
n_used = int(used_lib.sum())
chi2_share = msckf.rejections["chi2"] / (msckf.rejections["chi2"] + n_used)
print(f"rejections: {dict(msckf.rejections)}; features used in updates {n_used}; the gate rejected "
      f"{msckf.rejections['chi2']} ({100 * chi2_share:.1f} % of those it tested)")
plot_trajectory_errors(t, p_gt, {"MSCKF": p_est, "IMU only": p_imu}, sigma_p)
plt.show()
inside = np.mean(np.abs(p_est - p_gt) <= 3 * sigma_p)
print(f"share of position errors inside ±3σ: {100 * inside:.1f} %")
assert np.all(np.isfinite(p_est))
assert row["rmse_m"] < row_imu["rmse_m"] / 5  # the visual updates beat dead reckoning by far
assert row["rmse_m"] < 0.1 and row_imu["final_error_m"] > 2.0

# %%
display(Markdown(
    f"The IMU alone drifts to {row_imu['final_error_m']:.1f} m of error in {duration:g} s (unknown biases, "
    f"integrated twice), while the MSCKF stays at {100 * row['rmse_m']:.1f} cm RMSE. "
    f"The gate rejected {100 * chi2_share:.1f} % of the features it tested, close to the 5 % that a 95 % gate drops "
    f"from correct features by design (every track here is correct). `too_few_observations` counts the tracks that "
    f"ended after fewer than {config.min_track_length} images; any other reason is a triangulation that failed one "
    f"of the checks of section 3. For a consistent filter about 99.7 % of the errors of each axis would lie inside "
    f"±3σ; the printed {100 * inside:.1f} % is a first hint only, because the errors of consecutive images are "
    f"correlated: lesson 13 measures consistency over many runs."))

# %% [markdown]
# ### The same noise for every observation
#
# What if the filter ignored the lens and assumed $\sigma = 1/f$ for every observation (frames without the 4th
# item)? Towards the border of the DAVIS240C's wide-angle lens, undistortion stretches one pixel of noise; the line
# below prints by how much, over all observations of the run:

# %%
stretch = np.concatenate([np.sqrt(np.linalg.eigvalsh(c)[:, -1]) * camera.fx for _, _, _, c in frame_input])
print(f"1 px of noise after undistortion, in units of 1/f (largest direction): median {np.median(stretch):.2f}, "
      f"max {stretch.max():.2f} over {stretch.size} observations")
msckf_iso = Msckf(config, state0)
outputs_iso = msckf_iso.run(imu.t, imu.gyro, imu.accel, [(t_k, ids, xy) for t_k, ids, xy, _ in frame_input])
n_used_iso = sum(o.n_features_used for o in outputs_iso)
chi2_share_iso = msckf_iso.rejections["chi2"] / (msckf_iso.rejections["chi2"] + n_used_iso)
row_iso = summarize(t, np.array([o.p_IinG for o in outputs_iso]), t, p_gt, name="same noise for all")
for name, share, n_rej, rw in (("per-observation noise", chi2_share, msckf.rejections["chi2"], row),
                               ("same noise for all", chi2_share_iso, msckf_iso.rejections["chi2"], row_iso)):
    print(f"{name:22s}: gate rejected {n_rej:4d} = {100 * share:4.1f} % of the tested features; "
          f"RMSE {rw['rmse_m']:.3f} m")
assert np.median(stretch) > 1.05 and stretch.max() > 1.4  # undistortion stretches the noise
assert chi2_share_iso > 2 * chi2_share and chi2_share < 0.1  # the designed 5 % only with the right noise model

# %%
better = row_iso["rmse_m"] / row["rmse_m"]
display(Markdown(
    f"With the same $\\sigma$ for all, the gate rejects {100 * chi2_share_iso:.0f} % of the tested features instead "
    f"of {100 * chi2_share:.0f} %: the residuals of border features are larger than the filter expects, so it throws "
    f"them out, although every track is correct. A gate that rejects far more than its design rate says that the "
    f"noise model is wrong. " + (
        f"The error follows: {row_iso['rmse_m']:.3f} m RMSE against {row['rmse_m']:.3f} m with each observation's own "
        f"covariance ({better:.1f}x)." if better > 1.5 else
        f"On this run the error barely shows it: {row_iso['rmse_m']:.3f} m RMSE against {row['rmse_m']:.3f} m with "
        f"each observation's own covariance.")))

# %% [markdown]
# ## Summary
#
# * The **inverse-depth** parametrisation $(\alpha, \beta, \rho)$ makes the projection model linear inside and
#   handles far points gracefully; Gauss-Newton (damped, Levenberg-Marquardt) converges in a few iterations from a
#   two-ray midpoint guess.
# * Triangulation **rejects** features it cannot trust: too few views, no baseline, behind or too near / far,
#   large residual.
# * Each observation gives $r_i \approx H_{C_i}\delta x_{C_i} + H_{f_i}\delta p_F + n_i$. **Whitening** by
#   $W_i = L_i^{-1}$ ($\Sigma_i = L_i L_i^T$) gives every row unit noise; the **left nullspace** of the whitened
#   $H_f$ then removes the feature error and keeps the noise white, leaving $2M - 3$ rows per feature. Projecting
#   before whitening would leave noise the filter does not model.
# * **QR compression** shrinks the stacked system to at most the state size without changing the update.
# * A 95 % **chi-square gate** throws out implausible features, and 5 % of correct ones by design; when it rejects
#   many more, the noise model is wrong (here: undistortion stretches the pixel noise at the image border). The
#   **Joseph-form** update keeps $P$ symmetric.
# * A gate biases the residuals it keeps towards zero: each update corrects only a fraction
#   $s = F_{k+2}(c)/F_k(c)$ of the error it sees, which makes the filter overconfident; gating whole tracks (large
#   $k$) keeps $s$ near 1.
# * The whole filter is a loop of about forty lines over these functions; `Msckf.run` is that loop, with the
#   features batched. `Msckf` composes three parts you can read one at a time: `msckf.imu_buffer` (the IMU samples
#   and the propagation), `msckf.feature_database` (the tracks in the window, which end and which are pruned) and
#   `msckf.updater` (sections 2-9 as one batched update).
# * Depth is the weak direction: with a short baseline one pixel of noise costs decimetres, and extra views of the
#   same motion help less than $1/\sqrt{M}$.
#
# ## Exercises
#
# 1. Repeat the triangulation Monte-Carlo with the feature at 10 m. How does the error scale with depth?
#
#    *Hint:* move the point along its ray, `p_CinG[0] + R_CtoG[0] @ (d * np.array([0.3, -0.2, 2.5]) / 2.5)`, and keep
#    an eye on `result.reason`.
# 2. Initialise Gauss-Newton far from the truth (`initial_p_FinG`); when does it fail, and with which reason?
#
#    *Hint:* pass `initial_p_FinG=` far along the ray, to the side, behind the anchor and in the anchor's plane $Z_A =
#    0$; print `reason` and `iterations`.
# 3. Set `chi2_probability=0.05` in `MsckfConfig` (msckf_vio's table) and rerun section 10: how many features are
#    left, and what happens to the error?
#
#    *Hint:* `dataclasses.replace(config, chi2_probability=0.05)`; `chi2_probability` is the share of correct features
#    the gate keeps.
# 4. Rerun section 10 with other seeds and with S-MSCKF's window, `max_camera_states=20` and `marginalize_third=False`
#    (two states pruned at a time). Which settings are robust, and why might the window's keyframe rule matter when
#    tracks live long?
#
#    *Hint:* loop over `np.random.default_rng(seed)` for the simulation and compare the RMSE and `n_features_used` of
#    both windows on each seed.
#
# Solutions, with the code to run (checked by `tests/test_solutions.py`):
# [docs/solutions/12_triangulation_and_update.md](../docs/solutions/12_triangulation_and_update.md).
