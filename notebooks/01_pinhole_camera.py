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
# # 01 — The pinhole camera and lens distortion
#
# Everything in visual(-inertial) odometry starts with one question: *where in the image does a 3-D point
# appear?* An event camera answers it exactly like an ordinary camera — its pixels sit behind the same kind of
# lens — so the first lesson of the course is the camera model that every later notebook uses, here for the
# DAVIS240C (a 240 × 180-pixel event camera that also records ordinary frames, the camera of the thesis's data
# sets). The course follows the thesis of Friedel (2020), *Event-based visual-inertial odometry using smart
# features* ("the thesis" from here on); this lesson is its §2.1.1, with the lens model the thesis leaves to
# textbooks:
#
# 1. the **pinhole projection** from a 3-D point to a pixel (thesis §2.1.1, Eq. 1 and Fig. 1),
# 2. the **intrinsic parameters** $f_x, f_y, c_x, c_y$ and what they mean,
# 3. **radial-tangential lens distortion** (the OpenCV "plumb-bob" model), and
# 4. how to **remove** it, from single pixels and from whole images.
#
# The library class is `evio_lib.geometry.camera.PinholeRadtan`. We build each idea in a few lines of NumPy and
# check it against the library (and the library is tested against OpenCV).

# %% [markdown]
# First the idea as a picture. Left: the camera frame $C$ sits at the optical centre, $z$ along the optical axis.
# A 3-D point $P$ and the optical centre define a ray; it crosses the image plane one metre in front of the centre
# at $p = (X/Z, Y/Z, 1)$, the normalised coordinates of §1, and the calibration matrix $K$ turns $p$ into a pixel.
# The principal point is where the optical axis pierces that plane. Right: the sensor in pixels. A perfect lens
# would put $P$ at $K p$ (open circle); the real lens of the DAVIS240C moves it towards the image centre (filled dot;
# the title gives the shift) and bends straight lines of the plane (blue): the distortion of §2.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_epipolar import plot_pinhole_schematic

fig = plot_pinhole_schematic()
plt.show()

# %%
import dataclasses

import cv2
import matplotlib.pyplot as plt
import numpy as np
import skimage.data
from IPython.display import Markdown, display

from evio_lib.course import fast_mode
from evio_lib.geometry.camera import PinholeRadtan

FAST = fast_mode()
rng = np.random.default_rng(2020)

# %% [markdown]
# ## 1. The pinhole projection
#
# Put the camera frame $C$ at the optical centre: $x$ to the right, $y$ down, $z$ forward along the optical axis.
# A point $\mathbf{P}_C = (X, Y, Z)$ with $Z > 0$ is first divided by its depth, giving **normalised coordinates**
# (its position on a virtual image plane one metre in front of the camera):
#
# $$x = \frac{X}{Z}, \qquad y = \frac{Y}{Z}.$$
#
# The **calibration matrix** $K$ then turns metres-on-that-plane into pixels:
#
# $$
# \begin{bmatrix} u \\ v \\ 1 \end{bmatrix}
# = K \,\frac{1}{Z}\begin{bmatrix} X \\ Y \\ Z \end{bmatrix},
# \qquad
# K = \begin{bmatrix} f_x & 0 & c_x \\ 0 & f_y & c_y \\ 0 & 0 & 1 \end{bmatrix}.
# $$
#
# * $f_x, f_y$ — the **focal length in pixels** (focal length in mm divided by the pixel pitch in mm). A larger focal
#   length means a narrower view: the same angle spans more pixels. $f_x \ne f_y$ only if pixels are not square.
# * $c_x, c_y$ — the **principal point**, the pixel where the optical axis pierces the sensor; near, but rarely
#   exactly at, the image centre.
#
# Pixel centres are at integer coordinates: the top-left pixel covers $u, v \in [-0.5, 0.5]$.

# %%
cam = PinholeRadtan.davis240c()  # the DAVIS240C of the RPG Event-Camera Dataset
print(cam)
print("K =\n", cam.K.round(2))

# %% [markdown]
# ### Field of view
# A ray at angle $\theta$ from the axis lands $f_x \tan\theta$ pixels from the principal point, so (ignoring the lens
# distortion for now) the horizontal field of view is
# $\mathrm{FOV}_x = \arctan\frac{c_x + 0.5}{f_x} + \arctan\frac{W - 0.5 - c_x}{f_x}$, roughly $2\arctan\frac{W}{2 f_x}$.
# The real lens bends rays at the border (see §2), so the true field of view comes from casting the rays of the
# edge pixels with `pixel_rays`, which includes the distortion.

# %%
fov_x_pinhole = np.degrees(2 * np.arctan(cam.width / (2 * cam.fx)))
fov_y_pinhole = np.degrees(2 * np.arctan(cam.height / (2 * cam.fy)))
left, right = cam.pixel_rays(np.array([[-0.5, cam.cy], [cam.width - 0.5, cam.cy]]))
top, bottom = cam.pixel_rays(np.array([[cam.cx, -0.5], [cam.cx, cam.height - 0.5]]))
fov_x_true = np.degrees(np.arccos(left @ right))
fov_y_true = np.degrees(np.arccos(top @ bottom))
print(f"pinhole FOV  : {fov_x_pinhole:.1f} deg x {fov_y_pinhole:.1f} deg")
print(f"with the lens: {fov_x_true:.1f} deg x {fov_y_true:.1f} deg  (barrel distortion squeezes a wider view in)")
assert round(fov_x_pinhole) == 62 and round(fov_y_pinhole) == 49  # the summary's 62 x 49 degrees
assert fov_x_true > fov_x_pinhole and fov_y_true > fov_y_pinhole

# %% [markdown]
# ### Projecting by hand
# Take a camera with the DAVIS240C's $K$ but a perfect lens, project a few points with the two lines of the
# equation above, and compare with the library.

# %%
ideal_cam = PinholeRadtan(fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy, width=cam.width, height=cam.height)
points_C = np.array([[0.0, 0.0, 2.0],     # on the optical axis -> the principal point
                     [0.5, 0.0, 2.0],     # half a metre to the right at 2 m
                     [-0.3, -0.2, 1.0],   # up and to the left
                     [1.0, 0.75, 4.0]])

homogeneous = (cam.K @ points_C.T).T           # K [X, Y, Z]^T
uv_by_hand = homogeneous[:, :2] / homogeneous[:, 2:]   # divide by Z
print(np.c_[points_C, uv_by_hand].round(2))
assert np.allclose(uv_by_hand, ideal_cam.project(points_C), atol=1e-9)

# %% [markdown]
# Two consequences worth remembering: scaling a point $(X, Y, Z) \to (sX, sY, sZ)$ does not move its pixel — a
# single camera cannot see depth — and each pixel therefore stands for a whole **ray** of points.

# %%
assert np.allclose(ideal_cam.project(3.0 * points_C), ideal_cam.project(points_C))
ray = ideal_cam.pixel_rays(uv_by_hand[2])
print("unit ray through the third pixel:", ray.round(4))
print("P / |P| of the third point:      ", (points_C[2] / np.linalg.norm(points_C[2])).round(4))

# %% [markdown]
# ## 2. Radial-tangential distortion
#
# Real lenses, especially the short wide-angle ones of small event cameras, do not keep straight lines straight.
# The plumb-bob model moves the normalised coordinates $(x, y)$ before $K$ is applied, with $r^2 = x^2 + y^2$:
#
# $$
# \begin{aligned}
# x_d &= x\,(1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + 2 p_1 x y + p_2 (r^2 + 2x^2),\\
# y_d &= y\,(1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + p_1 (r^2 + 2y^2) + 2 p_2 x y,\\
# u &= f_x x_d + c_x, \qquad v = f_y y_d + c_y .
# \end{aligned}
# $$
#
# * The **radial** terms $k_1, k_2, k_3$ scale a point along its radius. $k_1 < 0$ pulls the border inwards
#   (**barrel** distortion), $k_1 > 0$ pushes it out (**pincushion**).
# * The **tangential** terms $p_1, p_2$ model a lens that is slightly tilted with respect to the sensor.
#
# The DAVIS240C has strong barrel distortion ($k_1 \approx -0.37$). OpenCV keeps the coefficients in the order
# $(k_1, k_2, p_1, p_2, k_3)$, as `dist_coeffs` does.

# %%
print("dist_coeffs (k1, k2, p1, p2, k3):", cam.dist_coeffs)
assert round(cam.dist_coeffs[0], 2) == -0.37  # k1: strong barrel distortion


def distort_by_hand(xy, k1, k2, p1, p2, k3):
    x, y = xy[:, 0], xy[:, 1]
    r2 = x**2 + y**2
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return np.c_[x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x**2),
                 y * radial + p1 * (r2 + 2 * y**2) + 2 * p2 * x * y]


xy = rng.uniform(-0.6, 0.6, size=(1000, 2))
assert np.allclose(distort_by_hand(xy, *cam.dist_coeffs), cam.distort_normalized(xy), atol=1e-14)

# %% [markdown]
# ### Where straight lines bend
# Draw a square grid of straight lines in undistorted normalised coordinates and map it through the lens into
# pixels. Near the centre $r$ is small and nothing happens; towards the corners the lines bow outwards — the
# classic barrel shape. The black rectangle is the sensor; the grey lines are the ideal, straight grid.

# %%
samples_per_line = 50 if FAST else 200
# a grid that covers the sensor: its corners see x from -0.86 to 0.69 and y from -0.72 to 0.44
# (not symmetric: the principal point is right of and below the image centre)
sensor_corners = cam.unproject(np.array([[-0.5, -0.5], [cam.width - 0.5, -0.5], [-0.5, cam.height - 0.5],
                                         [cam.width - 0.5, cam.height - 0.5]]))
print("normalised coordinates of the sensor corners:\n", sensor_corners.round(2))
x_values = np.linspace(-0.9, 0.9, 7 if FAST else 13)
y_values = np.linspace(-0.75, 0.75, 5 if FAST else 11)
assert x_values.min() < sensor_corners[:, 0].min() and sensor_corners[:, 0].max() < x_values.max()
assert y_values.min() < sensor_corners[:, 1].min() and sensor_corners[:, 1].max() < y_values.max()
along_x = np.linspace(-0.9, 0.9, samples_per_line)
along_y = np.linspace(-0.75, 0.75, samples_per_line)

fig, ax = plt.subplots(figsize=(7, 5.5))
lines = [np.c_[np.full_like(along_y, x), along_y] for x in x_values]    # vertical lines x = const
lines += [np.c_[along_x, np.full_like(along_x, y)] for y in y_values]  # horizontal lines y = const
for xy_line in lines:
    ideal_uv = ideal_cam.normalized_to_pixels(xy_line)
    real_uv = cam.normalized_to_pixels(xy_line)
    ax.plot(ideal_uv[:, 0], ideal_uv[:, 1], color="0.75", lw=0.8)
    ax.plot(real_uv[:, 0], real_uv[:, 1], color="tab:blue", lw=1.2)
ax.add_patch(plt.Rectangle((-0.5, -0.5), cam.width, cam.height, fill=False, ec="k", lw=2))
ax.plot([], [], color="0.75", label="ideal pinhole (straight)")
ax.plot([], [], color="tab:blue", label="DAVIS240C lens")
ax.set(xlim=(-60, 300), ylim=(250, -60), aspect="equal", xlabel="u [px]", ylabel="v [px]",
       title="A straight grid seen through the DAVIS240C lens")
ax.legend(loc="lower center", ncol=2, fontsize=8)
plt.show()

# %% [markdown]
# ### The displacement field
# For every pixel of an ideal image, how far does the lens move it? The arrows point from the ideal position
# $K[x, y, 1]^\top$ to the distorted one. The leading term of the model predicts a length growing like $r^3$ (the
# $k_1 r^2$ term times $r$); a straight-line fit of $\log$ length against $\log r$ measures the power.

# %%
step = 30 if FAST else 15
u, v = np.meshgrid(np.arange(0, cam.width, step, dtype=float), np.arange(0, cam.height, step, dtype=float))
ideal_pixels = np.c_[u.ravel(), v.ravel()]
xy_ideal = (ideal_pixels - [cam.cx, cam.cy]) / [cam.fx, cam.fy]       # x = (u - cx) / fx
shift = cam.normalized_to_pixels(xy_ideal) - ideal_pixels

fig, ax = plt.subplots(figsize=(7, 5.5))
q = ax.quiver(ideal_pixels[:, 0], ideal_pixels[:, 1], shift[:, 0], shift[:, 1], np.linalg.norm(shift, axis=1),
              angles="xy", scale_units="xy", scale=1, cmap="viridis")
ax.plot(cam.cx, cam.cy, "r+", ms=12, label="principal point")
ax.set(xlim=(-20, cam.width + 20), ylim=(cam.height + 20, -20), aspect="equal", xlabel="u [px]", ylabel="v [px]",
       title="Lens displacement (arrows drawn to scale)")
fig.colorbar(q, ax=ax, label="displacement [px]")
ax.legend(loc="lower right")
plt.show()
print(f"largest displacement on this grid: {np.linalg.norm(shift, axis=1).max():.1f} px")
r = np.linalg.norm(xy_ideal, axis=1)
far = r > 0.3  # away from the centre, where the power law is measurable
cubic_fit = np.polyfit(np.log(r[far]), np.log(np.linalg.norm(shift, axis=1)[far]), 1)[0]
k1_only = dataclasses.replace(cam, k2=0.0)  # the same lens without its r^4 term
shift_k1 = k1_only.normalized_to_pixels(xy_ideal) - ideal_pixels
k1_fit = np.polyfit(np.log(r[far]), np.log(np.linalg.norm(shift_k1, axis=1)[far]), 1)[0]
print(f"displacement ~ r^{cubic_fit:.2f} (log-log slope); without the k2 term: r^{k1_fit:.2f}")
assert 2.5 < cubic_fit < 3.0 and abs(k1_fit - 3.0) < 0.05  # k2 > 0 gives some of the k1 r^3 back

# %%
display(Markdown(
    f"The fitted power is {cubic_fit:.1f}, a little under 3: the $k_2 r^4$ term ($k_2 = {cam.k2:+.2f}$, the "
    f"opposite sign of $k_1$) gives back part of the displacement far from the centre. The same lens without it "
    f"follows $r^{{{k1_fit:.2f}}}$. The largest arrow is {np.linalg.norm(shift, axis=1).max():.1f} px long."))

# %% [markdown]
# ## 3. Removing the distortion
#
# Going from a measured pixel back to its ray needs the **inverse** of the distortion, which has no closed form.
# A simple iteration (the one OpenCV uses) rewrites the model as
# $\mathbf{x} = \big(\mathbf{x}_d - \boldsymbol{\delta}_t(\mathbf{x})\big) / \rho(r^2)$,
# with $\rho$ the radial factor and $\boldsymbol{\delta}_t$ the tangential term, and repeats it from
# $\mathbf{x} = \mathbf{x}_d$. It converges, but only linearly, and slowest where the lens bends most steeply
# (near the left and right borders of the DAVIS240C), so OpenCV's default of 5 iterations stops short of the exact
# answer there; the figure below measures by how much.
#
# The library instead solves $\mathbf{d}(\mathbf{x}) - \mathbf{x}_d = 0$ with **Newton's method**, using the
# $2\times2$ Jacobian of the distortion (the matrix of partial derivatives $\partial(x_d, y_d)/\partial(x, y)$); the
# error roughly squares at every step.

# %%
u, v = np.meshgrid(np.arange(0, cam.width, 4 if FAST else 1, dtype=float),
                   np.arange(0, cam.height, 4 if FAST else 1, dtype=float))
sensor_pixels = np.c_[u.ravel(), v.ravel()]
xy_d = (sensor_pixels - [cam.cx, cam.cy]) / [cam.fx, cam.fy]     # x_d = (u - cx) / fx
xy_converged = cam.unproject(sensor_pixels)                       # the library's answer, run to convergence
k1, k2, p1, p2, k3 = cam.dist_coeffs

max_iterations = 12
fixed_point_errors, newton_errors = [], []
xy_fp = xy_d.copy()
for iterations in range(1, max_iterations + 1):
    x, y = xy_fp[:, 0], xy_fp[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    tangential = np.c_[2 * p1 * x * y + p2 * (r2 + 2 * x * x), p1 * (r2 + 2 * y * y) + 2 * p2 * x * y]
    xy_fp = (xy_d - tangential) / radial[:, None]                 # fixed-point step
    fixed_point_errors.append(np.abs(xy_fp - xy_converged).max())
    if iterations == 5:
        error_after_5 = np.abs(xy_fp - xy_converged).max(axis=1)  # per pixel, at OpenCV's default
    xy_newton = cam.undistort_normalized(xy_d, iterations=iterations, tol=0.0)
    newton_errors.append(np.abs(xy_newton - xy_converged).max())

fig, ax = plt.subplots(figsize=(6, 3.5))
steps = range(1, max_iterations + 1)
ax.semilogy(steps, np.maximum(fixed_point_errors, 1e-17), "o-", label="fixed point (OpenCV's scheme)")
ax.semilogy(steps, np.maximum(newton_errors, 1e-17), "s-", label="Newton (evio_lib)")
ax.axvline(5, color="0.6", ls="--", lw=1)
ax.text(5.2, 1e-12, "OpenCV default: 5", color="0.4")
ax.set(xlabel="iterations", ylabel="worst error over the sensor\n[normalised units; x f_x for pixels]",
       title="Undistorting the DAVIS240C's pixels")
ax.legend()
plt.show()
print(f"after 5 iterations: fixed point {fixed_point_errors[4]:.1e}, Newton {newton_errors[4]:.1e} "
      f"(normalised units; x fx = {fixed_point_errors[4] * cam.fx:.2f} px for the fixed point)")
worst_pixel = sensor_pixels[np.argmax(error_after_5)]
slowest = error_after_5 >= np.quantile(error_after_5, 0.99)  # the 1 % of pixels that converge slowest
near_side = (sensor_pixels[slowest, 0] < 10) | (sensor_pixels[slowest, 0] > cam.width - 11)
print(f"the fixed point's worst pixel after 5 iterations: (u, v) = ({worst_pixel[0]:.0f}, {worst_pixel[1]:.0f}); "
      f"{near_side.mean():.0%} of the slowest 1 % lie within 10 px of the left or right border")
assert newton_errors[4] < 1e-14  # Newton: machine precision after 5 steps
assert near_side.mean() > 0.5  # the slow pixels sit at the left and right borders
assert 1e-4 < fixed_point_errors[4] < 5e-4 and fixed_point_errors[4] * cam.fx < 0.1  # hundredths of a pixel
display(Markdown(
    f"After OpenCV's default of 5 iterations the fixed point is still {fixed_point_errors[4]:.1e} off in normalised "
    f"coordinates, {fixed_point_errors[4] * cam.fx:.2f} px; Newton's method is at {newton_errors[4]:.0e}, the "
    f"rounding error of double precision. The slow pixels are where the text said: the worst sits at "
    f"({worst_pixel[0]:.0f}, {worst_pixel[1]:.0f}), and {near_side.mean():.0%} of the slowest 1 % lie within 10 px "
    f"of the left or right border."))

# %% [markdown]
# The claim of this section: `unproject` (pixel → ray) and `normalized_to_pixels` (ray → pixel) are exact
# inverses over the **whole** sensor, corners included.

# %%
pixel_step = 4 if FAST else 1
u, v = np.meshgrid(np.arange(0, cam.width, pixel_step, dtype=float), np.arange(0, cam.height, pixel_step, dtype=float))
all_pixels = np.c_[u.ravel(), v.ravel()]
corners = [[0, 0], [cam.width - 1, 0], [0, cam.height - 1], [cam.width - 1, cam.height - 1]]
all_pixels = np.unique(np.r_[all_pixels, corners], axis=0)  # the four corner pixels, whatever the step
round_trip = cam.normalized_to_pixels(cam.unproject(all_pixels))
round_trip_error = np.abs(round_trip - all_pixels).max()
print(f"{len(all_pixels)} pixels, worst round-trip error {round_trip_error:.1e} px")
assert round_trip_error < 1e-8

# %% [markdown]
# ### The ray of every pixel at once: `normalized_grid()`
#
# Renderers and dense methods need the ray of *every* pixel. `normalized_grid()` returns them as an
# $H \times W \times 2$ array: entry `[v, u]` holds the undistorted normalised coordinates $(x, y)$ of pixel
# $(u, v)$, so the ray through it is $[x, y, 1]^\top$ in frame $C$. It is computed once per camera (with
# `unproject`) and kept read-only; the scene renderer of lesson 03 casts exactly these rays.

# %%
grid = cam.normalized_grid()
rays_C = np.concatenate([grid, np.ones((*grid.shape[:2], 1))], axis=2)  # (H, W, 3) rays [x, y, 1]
print("normalized_grid():", grid.shape, "| ray of the top-left pixel:", rays_C[0, 0].round(3))
assert grid.shape == (cam.height, cam.width, 2) and not grid.flags.writeable
assert np.allclose(grid[all_pixels[:, 1].astype(int), all_pixels[:, 0].astype(int)], cam.unproject(all_pixels))
assert np.allclose(cam.normalized_to_pixels(grid.reshape(-1, 2)).reshape(grid.shape)[10, 20], [20.0, 10.0])

# %% [markdown]
# `undistort_points` does the same but returns pixels of an *ideal* camera with the same $K$ — handy to see how
# far each measured pixel really is from where a perfect lens would have put it.

# %%
corners = np.array([[0.0, 0.0], [cam.width - 1.0, 0.0], [0.0, cam.height - 1.0], [cam.width - 1.0, cam.height - 1.0]])
corner_shift = np.linalg.norm(cam.undistort_points(corners) - corners, axis=1)
print("  u      v    | ideal u  ideal v | shift [px]")
print(np.c_[corners, cam.undistort_points(corners), corner_shift].round(1))
print(f"the lens moves the four corner pixels by {corner_shift.min():.1f} to {corner_shift.max():.1f} px")
assert corner_shift.min() > 20  # tens of pixels at every corner

# %% [markdown]
# ## 4. Undistorting a whole image
#
# To undistort an image we go **backwards**: for every pixel $(u, v)$ of the ideal output image compute where
# that ray hits the real sensor,
# $(u_d, v_d) = \texttt{normalized\_to\_pixels}\big((u - c_x)/f_x,\ (v - c_y)/f_y\big)$,
# and sample the raw image there with bilinear interpolation (`cv2.remap`). No iteration is needed in this
# direction, and the lookup tables are computed once per camera.
#
# To see it work, we fake a raw DAVIS240C picture of a checkerboard: start from an ideal checkerboard image
# (`skimage.data.checkerboard()`), and build the raw image the lens would have produced by looking up, for every
# raw pixel, its ideal position with `undistort_points`.

# %%
board = skimage.data.checkerboard().astype(np.float32) / 255.0          # 200 x 200, 25-pixel squares
ideal_image = np.tile(board, (2, 2))[: cam.height, : cam.width]          # crop to 180 x 240

u, v = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
raw_pixels = np.c_[u.ravel(), v.ravel()]                                 # every pixel of the raw image
ideal_positions = cam.undistort_points(raw_pixels).astype(np.float32).reshape(cam.height, cam.width, 2)
raw_image = cv2.remap(ideal_image, ideal_positions[..., 0], ideal_positions[..., 1], cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0.5)
recovered = cam.undistort_image(raw_image)

fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
for ax, image, title in zip(axes, (ideal_image, raw_image, recovered),
                            ("ideal (perfect lens)", "raw: through the DAVIS240C lens", "undistort_image(raw)")):
    shown = ax.imshow(image, cmap="gray", vmin=0, vmax=1)
    ax.set(title=title, xlabel="u [px]")
axes[0].set_ylabel("v [px]")
fig.colorbar(shown, ax=axes, label="intensity [0-1]", shrink=0.8)
plt.show()

# %% [markdown]
# The grey rim of the fake raw image is where the lens sees *more* than the ideal picture contains: barrel
# distortion squeezes a wider field of view onto the sensor. Undistorting with the same $K$ keeps the ideal
# camera's narrower view, so that extra rim is cropped away, and every output pixel finds something to sample
# (a pincushion lens would instead leave black corners). The checkerboard comes back; what differs should sit on
# the square edges, where two rounds of bilinear interpolation blur a sharp step. The cell below measures both:
# the share of output pixels that find something to sample, and how much of the error lies next to an edge.

# %%
ideal_uv = raw_pixels  # the same pixel grid, read as pixels of the ideal image
sampled_at = cam.normalized_to_pixels((ideal_uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy])
valid = cam.in_image(sampled_at, border=1.0).reshape(cam.height, cam.width)
error = np.abs(recovered - ideal_image)[valid]
edges = np.zeros_like(ideal_image, dtype=bool)  # the pixels on either side of a step of the ideal image
edges[:, 1:] |= ideal_image[:, 1:] != ideal_image[:, :-1]
edges[:, :-1] |= ideal_image[:, 1:] != ideal_image[:, :-1]
edges[1:, :] |= ideal_image[1:, :] != ideal_image[:-1, :]
edges[:-1, :] |= ideal_image[1:, :] != ideal_image[:-1, :]
all_error = np.abs(recovered - ideal_image)
on_edges = all_error[edges].sum() / all_error.sum()
bad_on_edges = (all_error > 0.25)[edges].sum() / (all_error > 0.25).sum()
print(f"valid pixels {valid.mean():.0%}, mean abs error {error.mean():.3f}, "
      f"pixels off by more than 0.25: {(error > 0.25).mean():.1%}")
print(f"pixels next to a square edge: {edges.mean():.0%} of the image, {on_edges:.0%} of the total error, "
      f"{bad_on_edges:.0%} of the pixels off by more than 0.25")
assert valid.all()  # every output pixel finds something to sample
assert error.mean() < 0.05 and (error > 0.25).mean() < 0.1
assert on_edges > 0.8 and bad_on_edges > 0.95 and edges.mean() < 0.4

# %% [markdown]
# ## Summary
#
# * The pinhole model maps $(X, Y, Z)$ to $(u, v)$ by dividing by depth and applying $K$; depth is lost, so a pixel
#   stands for a ray.
# * $f_x, f_y$ are focal lengths in pixels and set the field of view (the DAVIS240C's $K$ alone gives 62° × 49°,
#   the first line of the field-of-view cell; the lens's barrel distortion widens it, the second line);
#   $(c_x, c_y)$ is where the optical axis meets the sensor.
# * Radial-tangential distortion acts on normalised coordinates; the DAVIS240C lens moves every corner pixel by
#   tens of pixels (the corner table of §3), so ignoring it would ruin any geometry done near the border.
# * Distorting is a formula; undistorting is an iteration. Newton's method reaches machine precision in a few
#   steps, where the fixed-point scheme used by OpenCV by default stops short.
# * Whole images are undistorted by a backward lookup plus interpolation (`undistort_image`), and
#   `normalized_grid()` gives the ray of every pixel at once (section 3) — the scene renderer of lesson 03 casts
#   exactly these rays.
#
# ## Exercises
#
# 1. Change the sign of $k_1$ (build a `PinholeRadtan` by hand) and redraw the grid figure. Which way do the
#    lines bend now, and does the field of view grow or shrink?
#
#    *Hint:* `dataclasses.replace(cam, k1=-cam.k1)` gives the lens; cast the rays of the edge pixels with `pixel_rays`
#    as in §1.
# 2. Derive $\partial(u, v)/\partial(X, Y, Z)$ for the ideal pinhole by hand and compare it with
#    `ideal_cam.projection_jacobian`. Then check the distorted version against central finite differences.
#
#    *Hint:* write $u = f_x X/Z + c_x$ and differentiate; for the distorted model perturb each coordinate by $\pm h$
#    and divide by $2h$.
# 3. Find the smallest number of OpenCV-style fixed-point iterations that undistorts every DAVIS240C pixel to
#    $10^{-8}$ in normalised coordinates. How many Newton steps does the library need?
#
#    *Hint:* copy the fixed-point loop of §3 and stop when `np.abs(xy - cam.unproject(pixels)).max() < 1e-8`;
#    `undistort_normalized(..., iterations=n, tol=0.0)` runs n Newton steps.
# 4. `cam.scaled(2)` describes the same lens with a sensor of twice the resolution. Why is
#    $c_x' = 2(c_x + 0.5) - 0.5$ and not simply $2c_x$?
#
#    *Hint:* a pixel $u$ covers $[u - 0.5, u + 0.5]$: where is the sensor's left edge, and what does doubling the
#    resolution do to it?
# 5. Project a 3-D point that lies far outside the field of view (for instance at 80° from the axis). What does the
#    polynomial model predict, and why should a tracker never trust projections outside the image?
#
#    *Hint:* compute $x = \tan 80°$ and the radial factor $1 + k_1 x^2 + k_2 x^4$ the calibration was never fitted at.
#
# Worked solutions, with the code to run: [docs/solutions/01_pinhole_camera.md](../docs/solutions/01_pinhole_camera.md).
