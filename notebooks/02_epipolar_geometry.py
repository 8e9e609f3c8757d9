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
# # 02 — Epipolar geometry: motion from two views
#
# Lesson 01 showed that one image loses depth: a pixel stands for a whole ray. With a **second** view from a different
# place the two rays of the same scene point meet, and — more useful for odometry — the way pixels move between the
# views tells us how the camera moved. This lesson builds the two-view toolbox that every visual odometry front end
# uses, following §2.1.2 and Fig. 2 of the thesis (Friedel 2020, *Event-based visual-inertial odometry using smart
# features*):
#
# 1. the **epipolar constraint** $\mathbf{x}_2^\top E\,\mathbf{x}_1 = 0$ and the **essential matrix**
#    $E = [\mathbf{t}\times]R$ (thesis Eqs. 2-3), and the epipolar lines it draws in the images;
# 2. estimating $E$ from point matches with the **normalised eight-point algorithm**, and robustly with RANSAC;
# 3. splitting $E$ into **four** candidate motions and picking the right one with the **cheirality** test;
# 4. **triangulating** the points, and how the depth error depends on pixel noise and on the baseline;
# 5. why the translation comes out **without a scale**, and why a VIO system therefore needs an IMU.
#
# The library functions live in `evio_lib.geometry.epipolar` (tested against OpenCV's `findEssentialMat`,
# `recoverPose` and `triangulatePoints`).

# %% [markdown]
# First the idea as a picture. Left: two cameras look at one point $X$. Their centres $C_1$, $C_2$ and $X$ span the
# **epipolar plane** (green). The **baseline** $C_1C_2$ pierces each image plane at an **epipole** ($e_1$, $e_2$):
# the image of the other camera's centre. The epipolar plane cuts each image plane along a line through the
# epipole and the point's image ($x_1$, $x_2$): the **epipolar line**. The relative pose is a rotation
# $R = R_{C1\to C2}$ and a translation $\mathbf t$, where camera 1's centre sits seen from camera 2 (the arrow).
# Right: image 2 of the same scene. The points of camera 1's ray through $x_1$ at several depths $Z_1$ all land on
# one line, the epipolar line $E\mathbf x_1$ that passes through $e_2$: wherever $X$ lies on its ray, its match lies on
# this line. Sections 2-4 turn that into algebra; the drawing's pose is chosen so that both epipoles fall near the
# images, unlike the scene of §1.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_epipolar import plot_epipolar_schematic

fig = plot_epipolar_schematic()
plt.show()

# %%
import cv2
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_epipolar import plot_cheirality, plot_epipolar_lines
from evio_lib.geometry.camera import PinholeRadtan
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
from evio_lib.geometry.homography import homography_from_plane, warp_points
from evio_lib.geometry.rotation import skew, so3_exp

FAST = fast_mode()
rng = np.random.default_rng(2)

# %% [markdown]
# ## 1. A synthetic two-view scene
#
# We use an ideal pinhole camera the size of a DAVIS240 sensor (240 × 180 pixels, $f = 200$ px, no lens distortion
# — lesson 01 showed how to remove it) and scatter points 3 to 9 m in front of it.
#
# The relative pose uses the convention of the whole course: a point's coordinates in camera 2 are
#
# $$\mathbf{X}_{C2} = R_{C1\to C2}\,\mathbf{X}_{C1} + \mathbf{p}_{C1\,\mathrm{in}\,C2},$$
#
# where $\mathbf{p}_{C1\,\mathrm{in}\,C2}$ (the thesis's $\mathbf{t}_{k-1}^{k}$) is where camera 1's centre sits,
# seen from camera 2. Here camera 2 is 0.6 m to the right of and 0.2 m ahead of camera 1, and turned by a few degrees.

# %%
cam = PinholeRadtan(fx=200.0, fy=200.0, cx=120.0, cy=90.0, width=240, height=180)
K = cam.K

R_C1toC2 = so3_exp([0.02, -0.08, 0.03])  # a small rotation: so3_exp(w) turns by |w| rad about the axis w / |w|
p_C2inC1 = np.array([0.6, 0.05, 0.2])  # camera 2's centre in frame C1
p_C1inC2 = -R_C1toC2 @ p_C2inC1  # X_C2 = R (X_C1 - p_C2inC1)  =>  t = -R p_C2inC1

n_points = 150
X_C1 = np.column_stack([rng.uniform(-3, 4, n_points), rng.uniform(-2.0, 2.0, n_points), rng.uniform(3, 9, n_points)])
X_C2 = X_C1 @ R_C1toC2.T + p_C1inC2
visible = (X_C2[:, 2] > 0) & cam.in_image(cam.project(X_C1)) & cam.in_image(cam.project(X_C2))
X_C1, X_C2 = X_C1[visible], X_C2[visible]
uv1, uv2 = cam.project(X_C1), cam.project(X_C2)  # pixels
xy1, xy2 = cam.unproject(uv1), cam.unproject(uv2)  # normalised coordinates x = X/Z, y = Y/Z
print(f"{len(X_C1)} points seen by both cameras; |p_C1inC2| = {np.linalg.norm(p_C1inC2):.3f} m")

# %% [markdown]
# ## 2. The epipolar constraint and the essential matrix
#
# The two camera centres and a scene point span a plane, the **epipolar plane**. Written in frame C2 the three
# vectors in it are $\mathbf{X}_{C2}$, the baseline $\mathbf{t} = \mathbf{p}_{C1\,\mathrm{in}\,C2}$ and
# $R\,\mathbf{X}_{C1} = \mathbf{X}_{C2} - \mathbf{t}$. Coplanarity means the triple product vanishes:
#
# $$\mathbf{X}_{C2}^\top\,\big(\mathbf{t} \times R\,\mathbf{X}_{C1}\big) = 0
# \quad\Longleftrightarrow\quad
# \mathbf{x}_2^\top \underbrace{[\mathbf{t}\times] R}_{E}\;\mathbf{x}_1 = 0 ,$$
#
# after dividing by the two (positive, unknown) depths, with $\mathbf{x} = [x, y, 1]^\top$ in normalised coordinates
# and the skew matrix of thesis Eq. 3,
# $[\mathbf{t}\times] = \begin{bmatrix} 0 & -t_z & t_y \\ t_z & 0 & -t_x \\ -t_y & t_x & 0 \end{bmatrix}$
# (the thesis prints $t_z$ where the last row needs $t_x$; the cell below checks this form against the cross product).
# The **essential matrix** $E = [\mathbf{t}\times]R$ (thesis Eq. 2) holds the whole relative motion, and the
# constraint involves only pixels — no depths. That is what makes it usable for estimating the motion.

# %%
tx, ty, tz = p_C1inC2
assert np.allclose(skew(p_C1inC2), [[0, -tz, ty], [tz, 0, -tx], [-ty, tx, 0]])  # the form written above
assert np.allclose(skew(p_C1inC2) @ X_C1[0], np.cross(p_C1inC2, X_C1[0]))  # [t x] v = t x v
E_by_hand = skew(p_C1inC2) @ R_C1toC2  # E = [t x] R
x1h = np.column_stack([xy1, np.ones(len(xy1))])
x2h = np.column_stack([xy2, np.ones(len(xy2))])
residual_by_hand = np.einsum("ni,ij,nj->n", x2h, E_by_hand, x1h)  # x2^T E x1 for every point

E_true = essential_from_pose(R_C1toC2, p_C1inC2)
assert np.allclose(E_by_hand, E_true)
assert np.allclose(residual_by_hand, epipolar_residuals(E_true, xy1, xy2))
print(f"max |x2^T E x1| over {len(xy1)} true matches: {np.abs(residual_by_hand).max():.1e}")
print(f"max |x2^T E x1| for shuffled (wrong) matches: {np.abs(epipolar_residuals(E_true, xy1, xy2[::-1])).max():.2f}")
assert np.abs(residual_by_hand).max() < 1e-12

# %% [markdown]
# $E$ has a special shape: its singular values are $(\lVert\mathbf{t}\rVert, \lVert\mathbf{t}\rVert, 0)$. It has
# 5 degrees of freedom (3 for $R$, 2 for the direction of $\mathbf{t}$), and it is only defined **up to scale** —
# multiplying it by any number leaves the constraint unchanged.

# %%
singular_values_E = np.linalg.svd(E_true, compute_uv=False)
print("singular values of E:", singular_values_E.round(4), " |t| =", np.linalg.norm(p_C1inC2).round(4))
assert np.allclose(singular_values_E, [np.linalg.norm(p_C1inC2)] * 2 + [0.0], atol=1e-12)

# %% [markdown]
# ### Epipolar lines and the fundamental matrix
#
# Fix a point $\mathbf{x}_1$: the constraint $\mathbf{x}_2^\top (E\mathbf{x}_1) = 0$ is a line in image 2, the
# **epipolar line** $\mathbf{l}_2 = E\mathbf{x}_1$, on which the match must lie. A matcher only has to search along
# this line instead of the whole image. In pixels ($\mathbf{x} = K^{-1}\mathbf{u}$) the same constraint reads
# $\mathbf{u}_2^\top F\,\mathbf{u}_1 = 0$ with the **fundamental matrix** $F = K_2^{-\top} E K_1^{-1}$.
#
# All epipolar lines of an image meet at the **epipole**, the image of the other camera's centre. In image 2 that is
# the projection of $\mathbf{p}_{C1\,\mathrm{in}\,C2}$, the null vector of $F^\top$.

# %%
F = fundamental_from_essential(E_true, K, K)
fig = plot_epipolar_lines(uv1, uv2, F, cam.width, cam.height, max_points=10)
plt.show()

_, _, Vt = np.linalg.svd(F.T)
epipole2 = Vt[-1, :2] / Vt[-1, 2]  # F^T e2 = 0
epipole2_expected = (K @ p_C1inC2)[:2] / p_C1inC2[2]  # camera 1's centre projected into camera 2
print("epipole in image 2:", epipole2.round(2), " projection of camera 1's centre:", epipole2_expected.round(2))
assert np.allclose(epipole2, epipole2_expected)
assert not cam.in_image(epipole2[None])[0]  # the epipole lies outside the image (see below)

# %% [markdown]
# Camera 2 moved mostly sideways, so the epipole lies far outside the image (the line above: the image is 240 px
# wide) and the lines are nearly parallel.
# For a camera moving forward the epipole sits inside the image (the "focus of expansion") and the lines radiate
# from it.
#
# ## 3. Estimating E: the normalised eight-point algorithm
#
# Each match gives one equation that is **linear** in the nine entries of $E$:
# $\mathbf{x}_2^\top E\,\mathbf{x}_1 = (\mathbf{x}_2 \otimes \mathbf{x}_1)^\top \mathrm{vec}(E) = 0$. Stacking
# $N \ge 8$ matches gives $A\,\mathrm{vec}(E) = 0$, solved in the least-squares sense by the right singular vector
# of $A$ with the smallest singular value. Two refinements make it work well (Hartley 1997):
#
# * **normalisation**: shift each view's points to zero mean and scale them to mean distance $\sqrt2$ before
#   building $A$ (undo with $E = T_2^\top E' T_1$), which keeps $A$ well conditioned;
# * **projection onto the essential matrices**: replace the singular values by $(1, 1, 0)$.
#
# Here is the bare linear step in three lines, checked against the library on noise-free matches:

# %%
A = np.einsum("ni,nj->nij", x2h, x1h).reshape(-1, 9)  # one row (x2 kron x1) per match
E_linear = np.linalg.svd(A)[2][-1].reshape(3, 3)  # null vector of A
E_eight = eight_point(xy1, xy2)


def up_to_scale(E):
    """Scale a matrix to unit norm with a fixed sign, so that two estimates can be compared."""
    return E / np.linalg.norm(E) * np.sign(E.ravel() @ E_true.ravel())


assert np.allclose(up_to_scale(E_linear), up_to_scale(E_true), atol=1e-9)
assert np.allclose(up_to_scale(E_eight), up_to_scale(E_true), atol=1e-9)
print("eight-point E (unit norm):\n", up_to_scale(E_eight).round(4))

# %% [markdown]
# With noise the linear solution is no longer exact. We add 0.5 px of Gaussian noise to the pixels and compare our
# estimate with OpenCV's five-point solver (a minimal solver that needs five matches, run here inside LMedS, least
# median of squares: it solves many random five-match subsets and keeps the solution whose median residual is
# smallest; RANSAC, at the end of this section, works alike). Errors are measured as the angle of the rotation error and the angle between
# true and estimated translation **directions** (the length is unknown, see §7).

# %%
def rotation_error_deg(R_a, R_b):
    return np.degrees(np.arccos(np.clip((np.trace(R_a.T @ R_b) - 1) / 2, -1, 1)))


def direction_error_deg(t_a, t_b):
    return np.degrees(np.arccos(np.clip(t_a @ t_b / np.linalg.norm(t_a) / np.linalg.norm(t_b), -1, 1)))


uv1_noisy = uv1 + rng.normal(0, 0.5, uv1.shape)
uv2_noisy = uv2 + rng.normal(0, 0.5, uv2.shape)
xy1_noisy, xy2_noisy = cam.unproject(uv1_noisy), cam.unproject(uv2_noisy)

E_noisy = eight_point(xy1_noisy, xy2_noisy)
R_est, t_est, _ = recover_pose(E_noisy, xy1_noisy, xy2_noisy)
E_cv, _ = cv2.findEssentialMat(uv1_noisy, uv2_noisy, K, method=cv2.LMEDS)
_, R_cv, t_cv, _ = cv2.recoverPose(E_cv[:3], uv1_noisy, uv2_noisy, K)
print(f"eight-point   : rotation error {rotation_error_deg(R_C1toC2, R_est):.3f} deg, "
      f"direction error {direction_error_deg(p_C1inC2, t_est):.2f} deg")
print(f"OpenCV 5-point: rotation error {rotation_error_deg(R_C1toC2, R_cv):.3f} deg, "
      f"direction error {direction_error_deg(p_C1inC2, t_cv.ravel()):.2f} deg")
assert rotation_error_deg(R_C1toC2, R_est) < 2.0 and direction_error_deg(p_C1inC2, t_est) < 10.0
assert rotation_error_deg(R_C1toC2, R_cv) < 2.0 and direction_error_deg(p_C1inC2, t_cv.ravel()) < 10.0
rotation_errors = (rotation_error_deg(R_C1toC2, R_est), rotation_error_deg(R_C1toC2, R_cv))
direction_errors = (direction_error_deg(p_C1inC2, t_est), direction_error_deg(p_C1inC2, t_cv.ravel()))
display(Markdown(
    f"Both land close to the truth: rotation errors of {rotation_errors[0]:.3f}° (ours) and {rotation_errors[1]:.3f}° "
    f"(OpenCV), direction errors of {direction_errors[0]:.2f}° and {direction_errors[1]:.2f}°. A single noise draw "
    f"cannot rank the two solvers; the many draws later in this section measure how ours fares on average."))

# %% [markdown]
# ### The price of the projection, and a non-linear refinement
#
# How well does each estimate explain the data? The natural yardstick is the **Sampson distance**, the first-order
# distance (in both images together) by which a match misses its epipolar line:
#
# $$d = \frac{|\mathbf{x}_2^\top E\,\mathbf{x}_1|}{\sqrt{(E\mathbf{x}_1)_1^2 + (E\mathbf{x}_1)_2^2
#   + (E^\top\mathbf{x}_2)_1^2 + (E^\top\mathbf{x}_2)_2^2}} .$$
#
# Below, in pixels ($d \cdot f$), for the raw linear solution, for the same after forcing the singular values to
# $(1, 1, 0)$ (= `eight_point`), for the truth, and after `refine_essential`, which minimises $\sum d^2$ over the
# five degrees of freedom of $(R, \mathbf{t})$ with Levenberg-Marquardt (a damped Gauss-Newton least-squares
# solver), starting from the eight-point estimate.

# %%
def hartley_normalisation(xy):
    """Similarity T moving the points' centroid to 0 and their mean distance to sqrt(2)."""
    centroid = xy.mean(axis=0)
    scale = np.sqrt(2) / np.linalg.norm(xy - centroid, axis=1).mean()
    return np.array([[scale, 0, -scale * centroid[0]], [0, scale, -scale * centroid[1]], [0, 0, 1]])


T1, T2 = hartley_normalisation(xy1_noisy), hartley_normalisation(xy2_noisy)
x1n = np.column_stack([xy1_noisy, np.ones(len(xy1_noisy))]) @ T1.T  # x' = T x
x2n = np.column_stack([xy2_noisy, np.ones(len(xy2_noisy))]) @ T2.T
E_normalised = np.linalg.svd(np.einsum("ni,nj->nij", x2n, x1n).reshape(-1, 9))[2][-1].reshape(3, 3)
E_raw = T2.T @ E_normalised @ T1  # E = T2^T E' T1, before the projection
singular_values = np.linalg.svd(E_raw, compute_uv=False)
print("singular values of the raw linear solution:", (singular_values / singular_values[0]).round(3))

E_refined = refine_essential(E_noisy, xy1_noisy, xy2_noisy)
for name, E_candidate in (("raw linear (not essential)", E_raw), ("eight_point (1, 1, 0)", E_noisy),
                          ("truth", E_true), ("refine_essential", E_refined)):
    d_px = cam.fx * sampson_distance(E_candidate, xy1_noisy, xy2_noisy)
    print(f"{name:27s}: median Sampson distance {np.median(d_px):.2f} px")
R_ref, t_ref, _ = recover_pose(E_refined, xy1_noisy, xy2_noisy)
print(f"refined       : rotation error {rotation_error_deg(R_C1toC2, R_ref):.3f} deg, "
      f"direction error {direction_error_deg(p_C1inC2, t_ref):.2f} deg")

U, _, Vt = np.linalg.svd(E_raw)
assert np.allclose(up_to_scale(U @ np.diag([1, 1, 0]) @ Vt), up_to_scale(E_noisy), atol=1e-9)  # = eight_point
assert np.sum(sampson_distance(E_refined, xy1_noisy, xy2_noisy) ** 2) <= np.sum(
    sampson_distance(E_true, xy1_noisy, xy2_noisy) ** 2) * (1 + 1e-6)
median_sampson = {name: np.median(sampson_distance(E, xy1_noisy, xy2_noisy))
                  for name, E in (("raw", E_raw), ("eight_point", E_noisy), ("truth", E_true), ("refined", E_refined))}
assert median_sampson["raw"] < 1.2 * median_sampson["truth"]  # the raw solution fits as well as the truth
assert median_sampson["eight_point"] > 3 * median_sampson["truth"]  # the projection pushes the lines away
assert median_sampson["refined"] < 1.2 * median_sampson["truth"]  # the refinement brings the fit back
assert rotation_error_deg(R_C1toC2, R_ref) < rotation_error_deg(R_C1toC2, R_est)  # this draw: rotation better,
assert direction_error_deg(p_C1inC2, t_ref) > direction_error_deg(p_C1inC2, t_est)  # direction worse
sampson_px = {name: cam.fx * value for name, value in median_sampson.items()}
display(Markdown(
    f"Here the eight-point estimate misses the matches by a median {sampson_px['eight_point']:.2f} px, "
    f"{sampson_px['eight_point'] / sampson_px['truth']:.1f} times the truth's {sampson_px['truth']:.2f} px; the raw "
    f"linear solution ({sampson_px['raw']:.2f} px) and the refined one ({sampson_px['refined']:.2f} px) fit about as "
    f"well as the truth. On this draw the refinement took the rotation error from "
    f"{rotation_error_deg(R_C1toC2, R_est):.3f}° to {rotation_error_deg(R_C1toC2, R_ref):.3f}°, and the direction "
    f"error from {direction_error_deg(p_C1inC2, t_est):.2f}° to {direction_error_deg(p_C1inC2, t_ref):.2f}°."))

# %% [markdown]
# The raw linear solution fits the noisy matches as well as the truth does, but it is not an essential matrix:
# its two large singular values differ (the first printed line). Forcing them equal gives the closest essential
# matrix in the *algebraic* (Frobenius) sense, not in pixels, and here it pushes the epipolar lines away from the
# matches (the distances above). With this camera's narrow field of view a small rotation about the vertical axis
# looks almost like a sideways translation, so the data pin that combination down poorly and the projection is free
# to shift it. Refining the Sampson error on the essential matrices brings the fit back to the truth's level.
#
# Does a better fit mean a better motion? Not on every draw: on this one the refinement cut the rotation error but
# the direction error *rose* — the data explain a rotation error and a direction error of the same mixture almost
# equally well, and one noisy draw can tip either way. The fair question is what happens on average, so we repeat
# the experiment over many noise draws:

# %%
n_draws = 10 if FAST else 50
errors = {"eight_point": [], "refined": []}  # (rotation, direction) error in degrees per draw
draws = np.random.default_rng(12)
for _ in range(n_draws):
    x1 = cam.unproject(uv1 + draws.normal(0, 0.5, uv1.shape))
    x2 = cam.unproject(uv2 + draws.normal(0, 0.5, uv2.shape))
    E_8 = eight_point(x1, x2)
    for name, E_candidate in (("eight_point", E_8), ("refined", refine_essential(E_8, x1, x2))):
        R_k, t_k, _ = recover_pose(E_candidate, x1, x2)
        errors[name].append((rotation_error_deg(R_C1toC2, R_k), direction_error_deg(p_C1inC2, t_k)))
median_errors = {name: np.median(values, axis=0) for name, values in errors.items()}
for name, (rot, direction) in median_errors.items():
    print(f"{name:12s}: median rotation error {rot:.3f} deg, median direction error {direction:.2f} deg "
          f"({n_draws} noise draws)")
assert np.all(median_errors["refined"] < 0.5 * median_errors["eight_point"])  # refinement wins on average
(rot_8, dir_8), (rot_r, dir_r) = median_errors["eight_point"], median_errors["refined"]
display(Markdown(
    f"On average the refinement clearly wins: over {n_draws} noise draws it takes the median rotation error from "
    f"{rot_8:.3f}° to {rot_r:.3f}° ({rot_r / rot_8:.0%} of it) and the median direction error from {dir_8:.2f}° to "
    f"{dir_r:.2f}° ({dir_r / dir_8:.0%})."))

# %% [markdown]
# A linear estimate is a starting point, to be followed by a non-linear refinement of an error measured in pixels.
#
# ### Wrong matches: RANSAC
#
# Real matches contain outliers, and a single wrong match can ruin a least-squares fit. RANSAC fits $E$ to many
# random 8-point subsets, counts for each how many matches agree (Sampson distance — the first-order distance of a
# match from satisfying the constraint — below a threshold), and refits on the largest consensus set. We replace
# 20 % of the matches in view 2 by random pixels:

# %%
n_bad = len(uv2_noisy) // 5
bad = rng.choice(len(uv2_noisy), n_bad, replace=False)
uv2_outliers = uv2_noisy.copy()
uv2_outliers[bad] = rng.uniform([0, 0], [cam.width, cam.height], (n_bad, 2))
xy2_outliers = cam.unproject(uv2_outliers)

R_plain, _, _ = recover_pose(eight_point(xy1_noisy, xy2_outliers), xy1_noisy, xy2_outliers)
E_ransac, inliers = estimate_essential_ransac(xy1_noisy, xy2_outliers, rng, threshold=1.5 / cam.fx)
R_ransac, t_ransac, _ = recover_pose(E_ransac, xy1_noisy[inliers], xy2_outliers[inliers])
flagged = np.zeros(len(inliers), bool)
flagged[bad] = True
print(f"plain eight-point with outliers: rotation error {rotation_error_deg(R_C1toC2, R_plain):.2f} deg")
print(f"RANSAC: rotation error {rotation_error_deg(R_C1toC2, R_ransac):.3f} deg, kept {inliers.sum()} matches, "
      f"{np.sum(inliers & flagged)} of them replaced ones (one survives only if it lands near its epipolar line)")
assert rotation_error_deg(R_C1toC2, R_ransac) < 1.0
assert rotation_error_deg(R_C1toC2, R_plain) > rotation_error_deg(R_C1toC2, R_ransac)
assert np.all(sampson_distance(E_true, xy1_noisy[inliers], xy2_outliers[inliers]) < 3.0 / cam.fx)

# %% [markdown]
# ## 4. Four motions from one E, and the cheirality test
#
# Write $E = U\,\mathrm{diag}(1, 1, 0)\,V^\top$ (with $\det U = \det V = +1$) and
# $W = \begin{bmatrix} 0 & -1 & 0 \\ 1 & 0 & 0 \\ 0 & 0 & 1\end{bmatrix}$. Every pair
#
# $$R \in \{U W V^\top,\; U W^\top V^\top\}, \qquad \mathbf{t} \in \{+\mathbf{u}_3, -\mathbf{u}_3\}$$
#
# gives back $E$ up to sign, so the algebra leaves **four** candidates: the translation can point either way, and
# the second rotation is the first one followed by a half-turn about the baseline. Only one of them puts the scene
# **in front of both cameras** (positive depth, "cheirality"). We triangulate the matches with each candidate
# and count.

# %%
candidates = decompose_essential(E_eight)
print(" k | rotation error [deg] | direction error [deg] | points in front of both")
in_front_counts = []
for k, (R_k, t_k) in enumerate(candidates):
    X_k = triangulate_dlt(np.hstack([np.eye(3), np.zeros((3, 1))]), np.hstack([R_k, t_k[:, None]]), xy1, xy2)
    in_front = (X_k[:, 2] > 0) & ((X_k @ R_k.T + t_k)[:, 2] > 0)  # Z1 > 0 and Z2 > 0
    print(f" {k} | {rotation_error_deg(R_C1toC2, R_k):20.1f} | {direction_error_deg(p_C1inC2, t_k):21.1f} | "
          f"{in_front.sum():3d} / {len(in_front)}")
    in_front_counts.append(int(in_front.sum()))
assert sorted(in_front_counts) == [0, 0, 0, len(xy1)]  # one candidate has every point in front, the others none

fig = plot_cheirality(candidates, xy1, xy2, baseline=np.linalg.norm(p_C1inC2))
plt.show()

R_rec, t_rec, mask = recover_pose(E_eight, xy1, xy2)
assert np.allclose(R_rec, R_C1toC2, atol=1e-9) and np.allclose(t_rec, p_C1inC2 / np.linalg.norm(p_C1inC2), atol=1e-9)
assert mask.all()

# %% [markdown]
# The winning candidate has every point in front; the other three put all of them behind one camera or the other.
# With noisy data near-degenerate points (far away, or close to the baseline) can vote wrongly, which is why
# `recover_pose` counts votes rather than asking every point to agree.
#
# ## 5. Triangulation
#
# Knowing both projection matrices $P_1 = [I \mid \mathbf{0}]$, $P_2 = [R \mid \mathbf{t}]$, each view gives two
# linear equations in the homogeneous point $\mathbf{X} = [X, Y, Z, 1]^\top$ (defined up to scale: divide by the last
# entry to get the 3-D point; the cross product $\mathbf{x} \times P\mathbf{X} = 0$):
#
# $$\begin{bmatrix} x_1 P_1^{3\top} - P_1^{1\top} \\ y_1 P_1^{3\top} - P_1^{2\top} \\
# x_2 P_2^{3\top} - P_2^{1\top} \\ y_2 P_2^{3\top} - P_2^{2\top}\end{bmatrix} \mathbf{X} = 0 ,$$
#
# where $P^{i\top}$ is row $i$ of $P$. Again the smallest right singular vector solves it (the "DLT", direct linear
# transformation). With the
# true pose the points come back exactly, and the library agrees with OpenCV:

# %%
P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
P2 = np.hstack([R_C1toC2, p_C1inC2[:, None]])
X_tri = triangulate_dlt(P1, P2, xy1, xy2)
assert np.allclose(X_tri, X_C1, atol=1e-9)

X_cv = cv2.triangulatePoints(K @ P1, K @ P2, uv1_noisy.T, uv2_noisy.T)
X_tri_noisy = triangulate_dlt(K @ P1, K @ P2, uv1_noisy, uv2_noisy)
assert np.allclose(X_tri_noisy, (X_cv[:3] / X_cv[3]).T, rtol=1e-6)
depth_error = np.abs(X_tri_noisy[:, 2] - X_C1[:, 2])
print(f"0.5 px noise, {np.linalg.norm(p_C1inC2):.2f} m baseline: median depth error {np.median(depth_error):.3f} m "
      f"at a median depth of {np.median(X_C1[:, 2]):.1f} m")

# %% [markdown]
# ## 6. How accurate is the depth? A Monte-Carlo experiment
#
# For a sideways baseline $b$ and a point at depth $Z$, the disparity between the two images is $d = f b / Z$ pixels.
# An error $\delta d$ in the disparity moves the depth by
#
# $$\delta Z \approx \frac{Z^2}{f\,b}\,\delta d ,$$
#
# so we expect the depth error to grow **linearly with the pixel noise** and to shrink like **$1/b$** with the
# baseline (and to grow with $Z^2$). We check both with repeated random scenes: points 4 to 8 m away, camera 2
# shifted sideways by $b$ and turned slightly, Gaussian pixel noise $\sigma$ in both images. Two cases are compared:
# triangulation with the **true pose**, and with the pose **estimated** from the same noisy matches (eight-point +
# refinement, its translation scaled to the true length, as an IMU would supply).

# %%
n_trials = 10 if FAST else 150


def depth_errors(noise_px, baseline, n_trials, rng):
    """Median relative depth error (known pose, estimated pose) over n_trials random scenes."""
    known, estimated = [], []
    for _ in range(n_trials):
        R = so3_exp(rng.normal(0, 0.03, 3))
        t = -R @ np.array([baseline, 0.0, 0.0])  # camera 2 shifted sideways by the baseline
        X = np.column_stack([rng.uniform(-2, 2, 100), rng.uniform(-1.5, 1.5, 100), rng.uniform(4, 8, 100)])
        u1 = cam.project(X) + rng.normal(0, noise_px, (100, 2))
        u2 = cam.project(X @ R.T + t) + rng.normal(0, noise_px, (100, 2))
        x1, x2 = cam.unproject(u1), cam.unproject(u2)
        Z_known = triangulate_dlt(P1, np.hstack([R, t[:, None]]), x1, x2)[:, 2]
        R_e, t_e, _ = recover_pose(refine_essential(eight_point(x1, x2), x1, x2), x1, x2)
        Z_est = triangulate_dlt(P1, np.hstack([R_e, baseline * t_e[:, None]]), x1, x2)[:, 2]
        known.append(np.abs(Z_known - X[:, 2]) / X[:, 2])
        estimated.append(np.abs(Z_est - X[:, 2]) / X[:, 2])
    return np.median(known), np.median(estimated)


noise_levels = np.array([0.1, 0.25, 0.5, 1.0, 2.0])
baselines = np.array([0.1, 0.2, 0.4, 0.8, 1.6])
vs_noise = np.array([depth_errors(s, 0.4, n_trials, rng) for s in noise_levels])
vs_baseline = np.array([depth_errors(0.5, b, n_trials, rng) for b in baselines])

fig, axes = plt.subplots(1, 2, figsize=(11, 4))
for ax, x, errors, label in ((axes[0], noise_levels, vs_noise, "pixel noise sigma [px] (baseline 0.4 m)"),
                             (axes[1], baselines, vs_baseline, "baseline [m] (noise 0.5 px)")):
    ax.loglog(x, 100 * errors[:, 0], "o-", label="true pose")
    ax.loglog(x, 100 * errors[:, 1], "s--", label="estimated pose (scale from truth)")
    ax.set_xlabel(label)
    ax.set_ylabel("median relative depth error [%]")
    ax.grid(True, which="both", alpha=0.3)
axes[0].loglog(noise_levels, 100 * vs_noise[2, 0] * noise_levels / 0.5, "k:", lw=2, label="proportional to sigma")
axes[1].loglog(baselines, 100 * vs_baseline[2, 0] * 0.4 / baselines, "k:", lw=2, label="proportional to 1 / b")
for ax in axes:
    ax.legend()
plt.tight_layout()
plt.show()

follows_noise = vs_noise[:, 0] / (vs_noise[2, 0] * noise_levels / 0.5)  # measured / first-order prediction
follows_baseline = vs_baseline[:, 0] / (vs_baseline[2, 0] * 0.4 / baselines)
penalty = np.concatenate([vs_noise[:, 1] / vs_noise[:, 0], vs_baseline[:, 1] / vs_baseline[:, 0]])
print("true pose, measured / predicted:", follows_noise.round(2), "(noise)", follows_baseline.round(2), "(baseline)")
print(f"estimated pose / true pose: {penalty.min():.1f}x to {penalty.max():.1f}x")
assert np.all(np.diff(vs_noise[:, 0]) > 0), "depth error must grow with pixel noise"
assert np.all(np.diff(vs_baseline[:, 0]) < 0), "depth error must shrink with the baseline"
assert np.all(np.abs(follows_noise - 1) < 0.2) and np.all(np.abs(follows_baseline - 1) < 0.2)  # the formula holds
assert np.all(penalty > 2)  # an estimated pose costs depth accuracy everywhere: several times
worst = max(np.abs(follows_noise - 1).max(), np.abs(follows_baseline - 1).max())
display(Markdown(
    f"With the true pose both trends follow the first-order formula to within {worst:.0%} (dotted lines; the worst "
    f"of the ten points, {n_trials} scenes each). With the estimated pose the error is {penalty.min():.1f} to "
    f"{penalty.max():.1f} times larger."))

# %% [markdown]
# The estimated pose costs that much because the same pixel noise now also corrupts the rotation and the direction
# of travel, and every depth inherits those errors.
#
# ## 7. The missing scale
#
# Scale the whole world — every point and the camera translation — by the same factor $s$. Every pixel stays
# where it was, because projection divides by depth:

# %%
s = 3.7
uv2_scaled = cam.project((s * X_C1) @ R_C1toC2.T + s * p_C1inC2)
assert np.allclose(cam.project(s * X_C1), uv1) and np.allclose(uv2_scaled, uv2)
assert np.allclose(up_to_scale(essential_from_pose(R_C1toC2, s * p_C1inC2)), up_to_scale(E_true))
print("pixels and E are identical for the scene and its 3.7x scaled copy")

# %% [markdown]
# So two images (of a static scene) can never tell a small room seen from a short step from a large hall seen
# from a long one: $E$, and everything we got from it, fixes the translation only as a **direction**, and the
# triangulated points only **up to the same unknown factor**. Monocular visual odometry can keep that factor
# consistent from frame to frame (thesis Eq. 6 compares distances between triangulated points of successive pairs),
# but never learn its value, and the factor slowly drifts.
#
# This is the main reason to add an **IMU**: the accelerometer measures metric acceleration (plus gravity); with
# gravity removed and the velocity known, integrating it twice over the short time between two frames gives a
# metric displacement. One number — the length of the
# translation — turns the up-to-scale reconstruction into metres:

# %%
X_up_to_scale = triangulate_dlt(P1, np.hstack([R_rec, t_rec[:, None]]), xy1, xy2)  # |t| = 1: unknown units
imu_displacement = np.linalg.norm(p_C2inC1)  # metres travelled between the frames, as the IMU would report
X_metric = imu_displacement * X_up_to_scale
print(f"depth of the first point: {X_up_to_scale[0, 2]:.3f} (baseline units) -> {X_metric[0, 2]:.3f} m; "
      f"truth {X_C1[0, 2]:.3f} m")
assert np.allclose(X_metric, X_C1, atol=1e-8)

# %% [markdown]
# The IMU also observes the direction of gravity, which fixes two more quantities a camera alone cannot (roll and
# pitch with respect to the world). Later lessons fuse both sensors in a filter.
#
# ## 8. When E fails: pure rotation and planes
#
# If the camera only **rotates** ($\mathbf{t} = 0$), $E = [\mathbf{0}\times]R = 0$: the constraint says nothing and
# no depth can be triangulated (the two rays of a point coincide). The pixels are still related — by the
# **homography** $H = K R K^{-1}$, the special case $\mathbf{t} = 0$ of the plane-induced homography
# $H = K(R + \mathbf{t}\mathbf{n}^\top/d)K^{-1}$ that also maps points of any single **plane** between two views.
# Homographies return in the feature-learning lessons, where SuperPoint trains on randomly warped images.

# %%
uv2_rotation_only = cam.project(X_C1 @ R_C1toC2.T)  # same points, camera only turned
H_rotation = homography_from_plane(R_C1toC2, np.zeros(3), [0.0, 0.0, 1.0], 1.0, K, K)  # any plane: t = 0
assert np.allclose(warp_points(H_rotation, uv1), uv2_rotation_only, atol=1e-9)
print("pure rotation: every pixel moves by the homography K R K^-1, whatever the depth")

# %% [markdown]
# A **plane** is the other trap. When all points lie on one plane, the matches obey a homography, and the eight-point
# system $A\,\mathrm{vec}(E) = 0$ loses rank: $A$ has **three** zero singular values instead of one, so a whole
# three-dimensional family of matrices satisfies every equation, even without noise. `eight_point` returns one
# member of it, which is not the true $E$:

# %%
plane_rng = np.random.default_rng(8)  # its own generator: the same plane whatever ran above
X_plane = np.column_stack([plane_rng.uniform(-2, 2, 100), plane_rng.uniform(-1.5, 1.5, 100),
                           np.full(100, 5.0)])  # every point on the plane z = 5 m
xy1_plane = cam.unproject(cam.project(X_plane))
xy2_plane = cam.unproject(cam.project(X_plane @ R_C1toC2.T + p_C1inC2))  # noise-free
A_plane = np.einsum("ni,nj->nij", np.column_stack([xy2_plane, np.ones(100)]),
                    np.column_stack([xy1_plane, np.ones(100)])).reshape(-1, 9)
sv_plane = np.linalg.svd(A_plane, compute_uv=False)
n_null = int(np.sum(sv_plane < 1e-10 * sv_plane[0]))
E_plane = eight_point(xy1_plane, xy2_plane)
plane_error = np.abs(up_to_scale(E_plane) - up_to_scale(E_true)).max()
print(f"100 coplanar noise-free matches: {n_null} zero singular values of A; "
      f"largest entry error of the unit-norm E: {plane_error:.3f}")
assert n_null == 3 and plane_error > 0.01

# %% [markdown]
# ## Summary
#
# * Two views of a static point satisfy the epipolar constraint $\mathbf{x}_2^\top E\,\mathbf{x}_1 = 0$ with
#   $E = [\mathbf{t}\times]R$ (thesis Eqs. 2-3); in pixels the same holds with $F = K_2^{-\top}EK_1^{-1}$. A point
#   in one image constrains its match to a line in the other.
# * $E$ is linear in the constraint, so eight or more matches in general position (not all on one plane) give it
#   by SVD. Normalising the points keeps the system well conditioned; forcing the singular values to $(1, 1, 0)$
#   makes the result an essential matrix but can pull it away from the matches, so a non-linear refinement of the
#   Sampson distance follows (on average it beat the linear estimate on rotation and direction, §3); RANSAC makes
#   it robust to wrong matches.
# * Decomposing $E$ gives four $(R, \mathbf{t})$ candidates; triangulating the matches and keeping the one with the
#   points in front of both cameras (cheirality) picks the real motion.
# * Linear (DLT) triangulation recovers the points; their depth error grows linearly with pixel noise and as
#   $Z^2/(f b)$, so a short baseline or a far scene gives poor depth.
# * Translation and structure come out only up to a common scale. A monocular camera cannot measure it; an IMU can,
#   which is one reason for visual-*inertial* odometry.
#
# ## Exercises
#
# 1. Build the three-line linear system of `E_linear` from **pixel** coordinates (no normalisation at all), convert
#    the result to $E = K^\top F K$ and repeat the 0.5 px noise experiment. How much worse is the rotation error? Why
#    does conditioning matter more in pixels than in normalised coordinates?
#
#    *Hint:* build $A$ from `np.c_[uv, ones]` instead of normalised points, take $F$ from its null vector and $E = K^T
#    F K$; compare the singular values of both $A$ matrices.
# 2. Move camera 2 straight **forward** instead of sideways. Where is the epipole now, and how do the epipolar
#    lines look? Which points are hard to triangulate?
#
#    *Hint:* the epipole is the null vector of $F$ (`np.linalg.svd(F)[2][-1]`); what does a pure $z$ translation
#    project to?
# 3. Repeat the depth experiment as a function of the point depth $Z$ (fixed noise and baseline). Do you find the
#    predicted $Z^2$ law?
#
#    *Hint:* fix the baseline and noise, put all points at one depth $Z$ per trial, and fit the slope of $\log$ error
#    against $\log Z$.
# 4. Shrink the baseline towards zero with the estimated pose. At which baseline does `recover_pose` start picking
#    the wrong candidate, and what does `estimate_essential_ransac` return when $\mathbf{t} = 0$ exactly?
#
#    *Hint:* sweep the baseline down from 0.4 m and count the trials where
#    `t_est @ t_true / np.linalg.norm(t_true) > 0.9`; for $t = 0$ ask
#    which $E = [t\times]R$ satisfy $x_2 \propto R x_1$.
# 5. Section 8 showed that coplanar points leave $A$ with three zero singular values. Why three? (Hint: a homography
#    has 8 degrees of freedom; count the independent equations it leaves for the 9 entries of $E$.) Estimate the
#    homography with `cv2.findHomography` instead and decompose it with `cv2.decomposeHomographyMat`: how many
#    candidate motions do you get, and which one is right?
#
#    *Hint:* $x_2^\top E x_1 = x_1^\top H^\top E x_1$: which part of $H^\top E$ does a quadratic form see?
#    `cv2.filterHomographyDecompByVisibleRefpoints` takes normalised points.
#
# Worked solutions, with the code to run:
# [docs/solutions/02_epipolar_geometry.md](../docs/solutions/02_epipolar_geometry.md).
