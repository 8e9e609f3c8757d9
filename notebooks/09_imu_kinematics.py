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
# # 09 — IMU kinematics: quaternions, RK4 dead reckoning and what biases do
#
# The feature-evaluation lesson ended with what the filter asks of the front end: tracks of the same scene points over several images,
# as undistorted coordinates with about a pixel of noise. Those tracks only *correct* the estimate. The back-end of
# the thesis this course follows (Friedel 2020, *Event-based visual-inertial odometry using smart features*, §3.3),
# the MSCKF (multi-state constraint Kalman filter), is an *IMU-driven* filter: between two images the state is carried forward by integrating the
# gyroscope and the accelerometer, and the camera corrects it afterwards. This lesson is about that first half, with
# no camera at all:
#
# 1. the **JPL quaternion** (the convention of NASA's Jet Propulsion Laboratory technical reports, Trawny &
#    Roumeliotis) and its kinematics $\dot{\bar q} = \tfrac12\,\Omega(\omega)\,\bar q$ (thesis Eqs. 18-21, 31-32),
# 2. a **hand-written RK4 step** (the classic fourth-order Runge-Kutta method) of the IMU equations, checked against
#    the library's integrator,
# 3. the **IMU measurement model**: angular rate, *specific force* (not acceleration!), gravity, biases and noise,
# 4. **dead reckoning** over a simulated trajectory: how small the integration error is with perfect data,
# 5. what **uncorrected biases** do (the experiment of the thesis's §4.4, Figs. 19-22): quadratic and cubic error
#    growth,
# 6. **static initialisation**: gravity direction and gyroscope bias from an IMU at rest (simulated, and on a real
#    recording of the public EuRoC drone data set when it is available).
#
# Library pieces used: `evio_lib.geometry.rotation` (quaternions), `evio_lib.sim` (trajectories, IMU synthesis),
# `evio_lib.msckf.propagation.integrate_imu` (the filter's nominal integrator) and
# `evio_lib.msckf.initialization.static_initialization`.

# %% [markdown]
# First the idea as a picture. Left, to scale in m/s²: a body pitched by 20° that accelerates forward. Gravity pulls
# it down, but an accelerometer cannot feel gravity as such (it falls along with the body): it measures the
# **specific force** $\mathbf f = \mathbf a - \mathbf g$, the orange sum of the acceleration and "$-\mathbf g$", and it
# measures it along its own axes $x_I, z_I$ (the title gives the two components). Right: the model of section 3. The
# gyroscope adds a bias and white noise to the true angular rate, the accelerometer adds its own bias and noise to the
# true specific force; each bias wanders slowly (a random walk). Dead reckoning subtracts its estimates of the biases
# and integrates: the rate into the attitude $\bar q_{GtoI}$, the specific force, rotated into the world frame $G$ by
# that attitude and with gravity added back, into the velocity and then the position (thesis Eq. 31).

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_imu import plot_imu_model_schematic

fig = plot_imu_model_schematic(tilt_deg=20.0, accel_G=(4.0, 0.0))
plt.show()

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from IPython.display import Markdown, display  # noqa: E402

import evio_lib  # noqa: E402
from evio_lib.course import fast_mode  # noqa: E402
from evio_lib.evaluation.plots_imu import plot_pose_errors  # noqa: E402
from evio_lib.evaluation.plots_msckf import plot_error_growth  # noqa: E402
from evio_lib.evaluation.plots_sim import plot_imu_vs_truth  # noqa: E402
from evio_lib.geometry.rotation import (  # noqa: E402
    omega_matrix,
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_to_rot,
    quat_to_rotvec,
    rot_to_quat,
)
from evio_lib.msckf.initialization import static_initialization  # noqa: E402
from evio_lib.msckf.propagation import integrate_imu  # noqa: E402
from evio_lib.msckf.state import ImuState  # noqa: E402
from evio_lib.sim.imu import GRAVITY_G, ImuNoiseParams, integrate_imu_rk4, synthesize_imu  # noqa: E402
from evio_lib.sim.trajectory import trajectory_from_preset  # noqa: E402

FAST = fast_mode()
rng = np.random.default_rng(909)
DURATION = 3.0 if FAST else 10.0  # seconds of simulated motion
print(f"{DURATION:g} s of simulated IMU data")

# %% [markdown]
# ## 1. JPL quaternions and their kinematics
#
# The library stores attitudes as unit quaternions in the JPL convention, **scalar last**:
# $\bar q = [q_x, q_y, q_z, q_w]^T = [\mathbf q_v^T, q_w]^T$. The quaternion $\bar q_{GtoI}$ has the rotation matrix
#
# $$C(\bar q) = (2q_w^2 - 1)\,I_3 - 2q_w[\mathbf q_v\times] + 2\mathbf q_v\mathbf q_v^T = R_{GtoI},$$
#
# a *passive* matrix: it maps the coordinates of a vector in $G$ to its coordinates in $I$,
# $\mathbf v_I = R_{GtoI}\mathbf v_G$. The JPL product is defined so that $C(\bar q\otimes\bar p) = C(\bar q)\,C(\bar p)$,
# i.e. rotations chain like matrices. (The thesis writes Eq. 18 scalar first; the library keeps the scalar last
# everywhere.)
#
# When $I$ turns with angular velocity $\boldsymbol\omega$ (expressed in $I$), the quaternion obeys the linear ODE
# (thesis Eqs. 31-32)
#
# $$\dot{\bar q}_{GtoI} = \tfrac12\,\Omega(\boldsymbol\omega)\,\bar q_{GtoI},\qquad
# \Omega(\boldsymbol\omega) = \begin{bmatrix} -[\boldsymbol\omega\times] & \boldsymbol\omega\\ -\boldsymbol\omega^T & 0\end{bmatrix}.$$
#
# For a **constant** rate it has a closed-form solution: a rotation by the angle $|\boldsymbol\omega| t$ about
# $\boldsymbol\omega$, $\bar q(t) = \delta\bar q(\boldsymbol\omega t)\otimes\bar q(0)$ with
# $\delta\bar q(\boldsymbol\theta) = [\sin(|\boldsymbol\theta|/2)\,\boldsymbol\theta/|\boldsymbol\theta|,\ \cos(|\boldsymbol\theta|/2)]$
# (`quat_from_rotvec`). Let us check the ODE numerically: a finite difference of the closed form must equal
# $\tfrac12\Omega\bar q$.

# %%
w = np.array([0.3, -1.2, 0.8])  # rad/s, in I
q0 = quat_from_rotvec([0.2, 0.4, -0.1])  # some attitude q_GtoI
h = 1e-6
q_plus = quat_multiply(quat_from_rotvec(w * h), q0)
q_minus = quat_multiply(quat_from_rotvec(-w * h), q0)
qdot_fd = (q_plus - q_minus) / (2 * h)  # central difference of the closed-form solution
qdot_ode = 0.5 * omega_matrix(w) @ q0  # ½ Ω(ω) q
print("finite difference:", qdot_fd.round(6))
print("½ Ω(ω) q         :", qdot_ode.round(6))
assert np.allclose(qdot_fd, qdot_ode, atol=1e-9)

# the matrix convention: C(q ⊗ p) = C(q) C(p), and R_GtoI maps G coordinates into I
p = quat_from_rotvec([-0.5, 0.1, 0.3])
assert np.allclose(quat_to_rot(quat_multiply(q0, p)), quat_to_rot(q0) @ quat_to_rot(p))

# %% [markdown]
# ## 2. The IMU equations and one RK4 step by hand
#
# The nominal IMU state (the estimate itself, as opposed to the error state a filter tracks, next lesson)
# is $X_{IMU} = [\bar q_{GtoI}, \mathbf b_g, \mathbf v_{IinG}, \mathbf b_a, \mathbf p_{IinG}]$
# (thesis Eq. 21). With bias-corrected measurements $\boldsymbol\omega = \boldsymbol\omega_m - \mathbf b_g$ and
# $\mathbf a = \mathbf a_m - \mathbf b_a$ it moves as (thesis Eq. 31)
#
# $$\dot{\bar q}_{GtoI} = \tfrac12\Omega(\boldsymbol\omega)\bar q_{GtoI},\quad \dot{\mathbf b}_g = \mathbf 0,\quad
# \dot{\mathbf v}_{IinG} = R_{ItoG}\,\mathbf a + \mathbf g_G,\quad \dot{\mathbf b}_a = \mathbf 0,\quad
# \dot{\mathbf p}_{IinG} = \mathbf v_{IinG}.$$
#
# The thesis integrates this with the classic 4th-order Runge-Kutta method at every IMU sample. Between two samples
# $t_k, t_{k+1}$ ($h = t_{k+1}-t_k$) the measurements are interpolated linearly, so stages 2 and 3 use the mean of
# the two samples. With $\mathbf x = (\bar q, \mathbf v, \mathbf p)$ and $\mathbf f$ the right-hand side above:
#
# $$\mathbf k_1 = \mathbf f(\mathbf x_k, \mathbf u_k),\ \ \mathbf k_2 = \mathbf f(\mathbf x_k + \tfrac h2\mathbf k_1, \mathbf u_{k+\frac12}),\ \
# \mathbf k_3 = \mathbf f(\mathbf x_k + \tfrac h2\mathbf k_2, \mathbf u_{k+\frac12}),\ \ \mathbf k_4 = \mathbf f(\mathbf x_k + h\mathbf k_3, \mathbf u_{k+1}),$$
# $$\mathbf x_{k+1} = \mathbf x_k + \tfrac h6(\mathbf k_1 + 2\mathbf k_2 + 2\mathbf k_3 + \mathbf k_4),\qquad \bar q_{k+1}\leftarrow\bar q_{k+1}/|\bar q_{k+1}|.$$
#
# Below is that step in a dozen lines. The library's `integrate_imu` does the same job vectorised over all samples
# (it integrates the quaternion in closed form on each half step and uses Simpson's rule for $\mathbf v$, which is
# what RK4 reduces to when the right-hand side does not depend on $\mathbf v$); the two must agree.

# %%
G = GRAVITY_G


def imu_rhs(q, v, w, a):
    """(q̇, v̇, ṗ) of thesis Eq. 31 for bias-corrected w, a (the stage quaternion is normalised for C(q))."""
    R_ItoG = quat_to_rot(q / np.linalg.norm(q)).T
    return 0.5 * omega_matrix(w) @ q, R_ItoG @ a + G, v


def rk4_step(q, v, p, w0, w1, a0, a1, h):
    """One classic RK4 step over [t_k, t_k + h] with linearly interpolated measurements."""
    wm, am = 0.5 * (w0 + w1), 0.5 * (a0 + a1)
    k1 = imu_rhs(q, v, w0, a0)
    k2 = imu_rhs(q + h / 2 * k1[0], v + h / 2 * k1[1], wm, am)
    k3 = imu_rhs(q + h / 2 * k2[0], v + h / 2 * k2[1], wm, am)
    k4 = imu_rhs(q + h * k3[0], v + h * k3[1], w1, a1)
    q1, v1, p1 = ((x + h / 6 * (a + 2 * b + 2 * c + d)) for x, a, b, c, d in zip((q, v, p), k1, k2, k3, k4))
    return q1 / np.linalg.norm(q1), v1, p1


# %% [markdown]
# Try it on 2 s of the simulator's `boxes_like` trajectory (a hand-held camera shaken in front of a scene) with a
# perfect 200 Hz IMU, starting from the true state:

# %%
traj = trajectory_from_preset("boxes_like", duration=DURATION + 1.0, seed=1)
imu_short = synthesize_imu(traj, rate_hz=200.0, noise=None, t_end=2.0)  # perfect measurements
s0 = traj.evaluate(0.0)
start = ImuState.from_pose(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], timestamp=0.0)

q, v, p_hand = start.q_GtoI.copy(), start.v_IinG.copy(), start.p_IinG.copy()
for k in range(len(imu_short) - 1):  # an illustration: the library vectorises this
    q, v, p_hand = rk4_step(q, v, p_hand, imu_short.gyro[k], imu_short.gyro[k + 1], imu_short.accel[k],
                            imu_short.accel[k + 1], imu_short.t[k + 1] - imu_short.t[k])

q_lib, v_lib, p_lib = integrate_imu(start, imu_short.t, imu_short.gyro, imu_short.accel, G)
dtheta = np.linalg.norm(quat_to_rotvec(quat_multiply(q, quat_inverse(q_lib[-1]))))
print(f"hand RK4 vs library after 2 s: attitude {dtheta:.2e} rad, velocity {np.linalg.norm(v - v_lib[-1]):.2e} m/s,"
      f" position {np.linalg.norm(p_hand - p_lib[-1]):.2e} m")
truth_2s = traj.evaluate(2.0)
lib_vs_truth = np.linalg.norm(p_lib[-1] - truth_2s.p_IinG[0])
print(f"library vs ground truth     : position {lib_vs_truth:.2e} m")
R_ref, p_ref, v_ref = integrate_imu_rk4(imu_short, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0])
print(f"hand RK4 vs sim.imu.integrate_imu_rk4: position {np.linalg.norm(p_hand - p_ref[-1]):.2e} m")
assert np.linalg.norm(p_hand - p_ref[-1]) < 1e-8  # the same RK4 scheme: identical up to round-off
assert dtheta < 1e-5 and np.linalg.norm(p_hand - p_lib[-1]) < 3e-6  # the filter's integrator: ~1 µm apart
assert 3e-5 < lib_vs_truth < 1e-4 and lib_vs_truth > 20 * np.linalg.norm(p_hand - p_lib[-1])
display(Markdown(
    f"The hand-written step reproduces the simulator's reference RK4 integrator (`integrate_imu_rk4`) to round-off "
    f"({np.linalg.norm(p_hand - p_ref[-1]):.0e} m). The filter's integrator differs from it by "
    f"{np.linalg.norm(p_hand - p_lib[-1]) * 1e6:.1f} µm after 2 s: it rotates the quaternion in closed form with the "
    f"mean rate of each half step, which is exact for a constant rate but only second order for a changing one. Both "
    f"are {lib_vs_truth * 1e6:.0f} µm from the truth, {lib_vs_truth / np.linalg.norm(p_hand - p_lib[-1]):.0f} times "
    f"what they differ by."))

# %% [markdown]
# That remaining error is *not* RK4's fault, as section 4 shows: with a cubic mid-point the same RK4 comes within a
# tiny fraction of it.
#
# ## 3. The IMU measurement model
#
# A strapdown IMU (fixed rigidly to the body, so it measures along the body's axes) measures,
# in its own frame $I$ (the simulator's model, `evio_lib.sim.imu`):
#
# $$\boldsymbol\omega_m = \boldsymbol\omega_I + \mathbf b_g + \mathbf n_g,\qquad
# \mathbf a_m = R_{GtoI}\,(\mathbf a_{IinG} - \mathbf g_G) + \mathbf b_a + \mathbf n_a,$$
#
# * the accelerometer feels the **specific force**: acceleration *minus gravity*. At rest it reads $+9.81$ m/s²
#   "up", in free fall it reads zero. That is why $\dot{\mathbf v} = R_{ItoG}\mathbf a + \mathbf g_G$ adds gravity back.
# * $\mathbf n_g, \mathbf n_a$ are white noises. Data sheets give their **noise densities** $\sigma_g$ [rad/s/√Hz],
#   $\sigma_a$ [m/s²/√Hz]; a sample taken at rate $f$ has standard deviation $\sigma\sqrt f$.
# * the biases $\mathbf b_g, \mathbf b_a$ start at some unknown value and wander as **random walks**,
#   $\dot{\mathbf b} = \mathbf n_w$ with densities $\sigma_{wg}$ [rad/s²/√Hz], $\sigma_{wa}$ [m/s³/√Hz]: after a time
#   $T$ a bias has drifted by about $\sigma_w\sqrt T$ per axis ($\sigma_w\sqrt{3T}$ for the length of the 3-axis
#   drift, printed below; one random draw, so it may come out well below or above).
#
# The simulator's defaults describe the MPU-6150-class IMU inside the DAVIS240C:

# %%
noise = ImuNoiseParams()
print(noise)
rate = 1000.0
imu_true = synthesize_imu(traj, rate_hz=rate, noise=None, t_end=DURATION)  # what a perfect IMU would read
imu_noisy = synthesize_imu(traj, rate_hz=rate, noise=noise, rng=rng, t_end=DURATION)

window = imu_true.t <= 1.0
fig = plot_imu_vs_truth(imu_true.t[window], imu_noisy.gyro[window], imu_true.gyro[window],
                        imu_noisy.accel[window], imu_true.accel[window])
fig.suptitle("noisy 1 kHz IMU (thin) over the noise-free measurement (grey), first second of boxes_like")
fig.tight_layout()
plt.show()

# %% [markdown]
# The noise-free measurement is exactly the model above evaluated on the ground truth (check it with the trajectory's
# own $\boldsymbol\omega_I$, $R_{ItoG}$ and $\mathbf a_{IinG}$), and the noisy one minus the drawn biases has the
# per-sample standard deviation $\sigma\sqrt f$:

# %%
truth = traj.evaluate(imu_true.t)
specific_force = np.einsum("nji,nj->ni", truth.R_ItoG, truth.a_IinG - G)  # R_GtoI (a - g), R_GtoI = R_ItoG^T
assert np.allclose(imu_true.gyro, truth.w_I) and np.allclose(imu_true.accel, specific_force)

n_g = imu_noisy.gyro - imu_noisy.bias_gyro - imu_true.gyro
n_a = imu_noisy.accel - imu_noisy.bias_accel - imu_true.accel
print(f"gyro noise std  {n_g.std():.5f} rad/s   expected σ_g √f = {noise.gyro_noise_density * np.sqrt(rate):.5f}")
print(f"accel noise std {n_a.std():.5f} m/s²    expected σ_a √f = {noise.accel_noise_density * np.sqrt(rate):.5f}")
print("drawn biases: b_g =", imu_noisy.bias_gyro[0].round(4), "rad/s,  b_a =", imu_noisy.bias_accel[0].round(3), "m/s²")
bias_to_noise_g = np.linalg.norm(imu_noisy.bias_gyro[0]) / n_g.std()
bias_to_noise_a = np.linalg.norm(imu_noisy.bias_accel[0]) / n_a.std()
print(f"|b_g| / (gyro noise std) = {bias_to_noise_g:.1f},  |b_a| / (accel noise std) = {bias_to_noise_a:.1f}")
drift = np.linalg.norm(imu_noisy.bias_accel[-1] - imu_noisy.bias_accel[0])
print(f"accelerometer bias drift over {DURATION:g} s: {drift:.3f} m/s² "
      f"(σ_wa √(3T) = {noise.accel_random_walk * np.sqrt(3 * DURATION):.3f})")
assert abs(n_g.std() / (noise.gyro_noise_density * np.sqrt(rate)) - 1) < 0.05
assert abs(n_a.std() / (noise.accel_noise_density * np.sqrt(rate)) - 1) < 0.05
assert 0.002 < n_g.std() < 0.004 and 0.1 < n_a.std() < 0.15  # a few mrad/s and about 0.1 m/s² per sample
assert bias_to_noise_g > 8 and 1 < bias_to_noise_a < 3  # the biases are not small next to one sample's noise
display(Markdown(
    f"Per sample, the noise is {n_g.std() * 1e3:.1f} mrad/s and {n_a.std():.2f} m/s² at {rate / 1e3:g} kHz, "
    f"zero-mean: it averages out in the integration. The biases drawn here are larger still: the gyroscope's "
    f"({np.linalg.norm(imu_noisy.bias_gyro[0]):.3f} rad/s) is {bias_to_noise_g:.1f} times the noise of one sample, "
    f"the accelerometer's ({np.linalg.norm(imu_noisy.bias_accel[0]):.2f} m/s²) {bias_to_noise_a:.1f} times."))

# %% [markdown]
# And unlike the noise the biases never average out: they are what ruins dead reckoning (section 5).
#
# ## 4. Dead reckoning with perfect measurements
#
# Integrating a *perfect* IMU from the true initial state should reproduce the trajectory. The residual error comes
# from the numerics only: RK4 is 4th order, but the linear interpolation of the measurements between samples is
# only 2nd order, so the error should shrink like $h^2$ (25× from 200 Hz to 1 kHz).

# %%
t_grid = np.arange(0.0, DURATION + 1e-9, 0.01)
dead_reckoning = {}
for rate_hz in (200.0, 500.0, 1000.0):
    imu_r = synthesize_imu(traj, rate_hz=rate_hz, noise=None, t_end=DURATION)
    _, _, p_r = integrate_imu(start, imu_r.t, imu_r.gyro, imu_r.accel, G)
    err = np.linalg.norm(p_r - traj.evaluate(imu_r.t).p_IinG, axis=1)
    dead_reckoning[f"{rate_hz:g} Hz"] = np.interp(t_grid, imu_r.t, err)
# the simulator's reference integrator with a cubic (4th-order) mid-point isolates the RK4 error itself
imu_1k = synthesize_imu(traj, rate_hz=1000.0, noise=None, t_end=DURATION)
_, p_cubic, _ = integrate_imu_rk4(imu_1k, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], midpoint="cubic")
dead_reckoning["1000 Hz, cubic mid-point"] = np.interp(
    t_grid, imu_1k.t, np.linalg.norm(p_cubic - traj.evaluate(imu_1k.t).p_IinG, axis=1))

for label, err in dead_reckoning.items():
    print(f"{label:>26}: position error after {DURATION:g} s = {err[-1]:.1e} m")
assert dead_reckoning["1000 Hz, cubic mid-point"][-1] < 1e-3 * dead_reckoning["1000 Hz"][-1]  # not RK4's error
plot_error_growth(t_grid, dead_reckoning, ylabel="|p_est - p_true| [m]",
                  title="dead reckoning with a perfect IMU (boxes_like)")
plt.yscale("log")
plt.show()
assert dead_reckoning["1000 Hz"][-1] < 1e-3  # under a millimetre at 1 kHz
assert 20 < dead_reckoning["200 Hz"][-1] / dead_reckoning["1000 Hz"][-1] < 30  # ~ (1000 / 200)^2 = 25: 2nd order
display(Markdown(
    f"With perfect data, 1 kHz and RK4 the integrator drifts by {dead_reckoning['1000 Hz'][-1] * 1e3:.2f} mm over "
    f"the {DURATION:g} s run, and the ratio of {dead_reckoning['200 Hz'][-1] / dead_reckoning['1000 Hz'][-1]:.1f} "
    f"between 200 Hz and 1 kHz confirms the $h^2$ law of the linear interpolation ($5^2 = 25$). With the cubic "
    f"mid-point the same RK4 is off by {dead_reckoning['1000 Hz, cubic mid-point'][-1]:.0e} m."))

# %% [markdown]
# Integration error is therefore not the problem of an IMU-only estimate. Sensor errors are.
#
# ## 5. What uncorrected biases do (thesis §4.4, Figs. 19-22)
#
# In §4.4 the thesis propagates the IMU alone through its datasets, once without and once with bias corrections,
# and watches the estimate diverge. We repeat that on the simulator, where the truth is exact. The IMU below is
# the noisy one of section 3 plus the biases the thesis estimated for its *Boxes* dataset,
# $\mathbf b_g = [0.049, 0.012, 0.002]$ rad/s and $\mathbf b_a = [0.0275, -0.135, 0.14]$ m/s². We integrate it
#
# * **without bias correction** (the filter believes $\mathbf b_g = \mathbf b_a = 0$), and
# * **with bias correction** (the filter knows the true biases; only white noise and the bias random walk are
#   left).

# %%
b_g_thesis = np.array([0.049, 0.012, 0.002])
b_a_thesis = np.array([0.0275, -0.135, 0.14])
gyro_m = imu_noisy.gyro + b_g_thesis
accel_m = imu_noisy.accel + b_a_thesis
true_b_g = imu_noisy.bias_gyro[0] + b_g_thesis
true_b_a = imu_noisy.bias_accel[0] + b_a_thesis

runs = {
    "no bias correction": ImuState.from_pose(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], 0.0),
    "with bias correction": ImuState.from_pose(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], 0.0, b_g=true_b_g,
                                               b_a=true_b_a),
}
q_true = rot_to_quat(np.swapaxes(truth.R_ItoG, 1, 2))  # q_GtoI of the ground truth
errors = {}
for label, state in runs.items():
    q_e, v_e, p_e = integrate_imu(state, imu_noisy.t, gyro_m, accel_m, G)
    errors[label] = (np.degrees(np.linalg.norm(quat_to_rotvec(quat_multiply(q_true, quat_inverse(q_e))), axis=1)),
                     np.linalg.norm(v_e - truth.v_IinG, axis=1),  # attitude [deg], velocity [m/s], position [m]
                     np.linalg.norm(p_e - truth.p_IinG, axis=1))
plot_pose_errors(imu_noisy.t, errors, title="IMU-only propagation on boxes_like with the thesis's Boxes biases")
plt.show()
i3 = np.searchsorted(imu_noisy.t, 3.0 - 1e-9)  # the sample at 3 s
final = {label: (att[-1], vel[-1], pos[-1], pos[i3]) for label, (att, vel, pos) in errors.items()}
for label, (a_deg, v_err, p_err, p_3s) in final.items():
    print(f"{label:>22}: after {DURATION:g} s attitude {a_deg:6.2f} deg, velocity {v_err:6.2f} m/s, "
          f"position {p_err:7.2f} m (after 3 s: {p_3s:.2f} m)")
att_rate = final["no bias correction"][0] / imu_noisy.t[-1]
print(f"attitude error rate {att_rate:.2f} deg/s; total gyroscope bias |b_g| = "
      f"{np.degrees(np.linalg.norm(true_b_g)):.2f} deg/s")
assert final["no bias correction"][2] > 10 * final["with bias correction"][2]
assert abs(att_rate / np.degrees(np.linalg.norm(true_b_g)) - 1) < 0.15  # attitude error ≈ |b_g| t
assert final["no bias correction"][3] > 1.0 and (FAST or final["no bias correction"][2] > 10)  # m after 3 s, tens after 10
assert final["with bias correction"][3] < 0.1 and (FAST or 0.2 < final["with bias correction"][2] < 1.0)


def position_errors(run):
    """'x m after 3 s' and, for a longer run, 'and y m after T s' (run: the tuple of `final`)."""
    text = f"{run[3]:.2f} m after 3 s"
    return text + (f" and {run[2]:.2f} m after {DURATION:g} s" if DURATION > 3 else "")


display(Markdown(
    f"Without correction the attitude error grows linearly at the rate of the total gyroscope bias "
    f"({np.linalg.norm(true_b_g):.3f} rad/s here, {np.degrees(np.linalg.norm(true_b_g)):.2f}° per second; the "
    f"measured rate is {att_rate:.2f}°/s), and the position is off by {position_errors(final['no bias correction'])}. "
    f"With the true biases the white noise and the bias random walk still make the error grow, only more slowly: "
    f"{position_errors(final['with bias correction'])}."))

# %% [markdown]
# The uncorrected run diverges like the thesis's Fig. 19 (Boxes) and Fig. 21 (Camp Atterbury). Knowing the biases
# does not make the IMU good enough on its own either: the thesis's corrected runs (Figs. 20 and 22) still reach an
# RMSE of 29.19 m on Boxes and 77.18 m on Camp Atterbury, with final errors of 88.71 m and 203.65 m (quoted in its
# §4.5), over whole recordings of tens of seconds.
#
# **Why these powers of t?** A constant accelerometer bias is a wrong acceleration: the velocity error grows like
# $\mathbf b_a t$ and the position error like $\tfrac12\mathbf b_a t^2$. A gyroscope bias is worse: the attitude error grows
# like $\mathbf b_g t$, so gravity ($g = 9.81$ m/s², by far the largest specific force) is rotated into the wrong
# direction and leaks into the horizontal acceleration by about $g\,b_g t$. Integrated twice, this gives a
# position error of about $\tfrac16 g\,b_g t^3$. The error from a gyroscope bias therefore grows with the *cube* of time.
# Below, the perfect IMU gets one bias at a time; on log-log axes the curves are straight lines of slope 2 and 3.

# %%
single = {
    "accel bias 0.1 m/s² only": (np.zeros(3), np.array([0.1, 0.0, 0.0])),
    "gyro bias 0.01 rad/s only": (np.array([0.01, 0.0, 0.0]), np.zeros(3)),
}
growth, slopes = {}, {}
fit = (imu_true.t > 0.5) & (imu_true.t <= DURATION)
for label, (bg, ba) in single.items():
    _, _, p_e = integrate_imu(start, imu_true.t, imu_true.gyro + bg, imu_true.accel + ba, G)
    e = np.linalg.norm(p_e - truth.p_IinG, axis=1)
    growth[label] = e
    slopes[label] = np.polyfit(np.log(imu_true.t[fit]), np.log(e[fit]), 1)[0]  # log e = k log t + c
    print(f"{label:>26}: slope of log(error) vs log(t) = {slopes[label]:.2f}, error after {DURATION:g} s = "
          f"{e[-1]:.2f} m")
T = DURATION
guides = [(2.0, 0.5 * 0.1 * T**2, "½ b_a t²"), (3.0, 9.81 * 0.01 * T**3 / 6, "g b_g t³ / 6")]
plot_error_growth(imu_true.t, growth, loglog=True, guides=guides,
                  title="position error from a single constant bias (perfect IMU otherwise)")
plt.show()
assert abs(slopes["accel bias 0.1 m/s² only"] - 2.0) < 0.2 and abs(slopes["gyro bias 0.01 rad/s only"] - 3.0) < 0.3
t_cross = 3 * 0.1 / (9.81 * 0.01)  # ½ b_a t² = ⅙ g b_g t³  ->  t = 3 b_a / (g b_g)
ratio_end = growth["gyro bias 0.01 rad/s only"][-1] / growth["accel bias 0.1 m/s² only"][-1]
print(f"the laws cross at t = 3 b_a / (g b_g) = {t_cross:.2f} s; after {DURATION:g} s gyro / accel error = "
      f"{ratio_end:.2f} (the laws: t / t_cross = {DURATION / t_cross:.2f})")
assert abs(ratio_end / (DURATION / t_cross) - 1) < 0.2
display(Markdown(
    f"The fitted slopes are {slopes['accel bias 0.1 m/s² only']:.2f} (accelerometer) and "
    f"{slopes['gyro bias 0.01 rad/s only']:.2f} (gyroscope). "
    f"A gyroscope bias of only 0.01 rad/s ({np.degrees(0.01):.2f}°/s) costs as much position as an accelerometer bias "
    f"of 0.1 m/s² after {t_cross:.2f} s (where $\\tfrac12 b_a t^2 = \\tfrac16 g\\,b_g t^3$), and after that ever "
    f"more, in proportion to $t$: "
    + (f"{ratio_end:.1f} times as much after {DURATION:g} s." if DURATION > t_cross + 1 else
       f"this run stops at {DURATION:g} s, where the two errors are about equal ({ratio_end:.2f}).")))

# %% [markdown]
# The curves follow the two laws closely, not exactly: the body turns during the trajectory, so the direction of
# the bias in $G$ changes. This is why the MSCKF keeps both biases in its state and lets the camera estimate them,
# and why a good **initial** gyroscope bias matters.
#
# ## 6. Static initialisation
#
# While the IMU rests, $\boldsymbol\omega_I = 0$ and $\mathbf a_{IinG} = 0$, so the model of section 3 becomes
#
# $$\boldsymbol\omega_m = \mathbf b_g + \mathbf n_g,\qquad \mathbf a_m = -R_{GtoI}\,\mathbf g_G + \mathbf b_a + \mathbf n_a.$$
#
# Averaging a second of data therefore gives the gyroscope bias directly, $\hat{\mathbf b}_g = \overline{\boldsymbol\omega_m}$,
# and the direction of "up" in $I$, $\mathbf z_I = \overline{\mathbf a_m}/|\overline{\mathbf a_m}|$ (because $-\mathbf g_G$ points
# up), which fixes roll and pitch. Yaw stays unknown: gravity says nothing about the heading, so it is set to 0 by
# choice. The accelerometer bias cannot be separated from a small tilt: it moves $\mathbf z_I$ by about
# $|\mathbf b_{a,\perp}|/g$ rad, with $\mathbf b_{a,\perp}$ the part of $\mathbf b_a$ across gravity.
#
# **On simulated data**, where the truth is known: a tilted IMU at rest, with biases (a dozen lines that apply the
# model above):

# %%
R_ItoG_rest = quat_to_rot(quat_from_rotvec([0.15, -0.3, 1.0])).T  # tilted and yawed
b_g_rest, b_a_rest = np.array([0.02, -0.01, 0.03]), np.array([0.05, -0.08, 0.02])
t_rest = np.arange(0.0, 1.0, 1.0 / rate)
n_rest = t_rest.shape[0]
rng_rest = np.random.default_rng(919)  # its own generator: this second of rest does not depend on the cells above
gyro_rest = b_g_rest + noise.gyro_noise_density * np.sqrt(rate) * rng_rest.standard_normal((n_rest, 3))
accel_rest = (R_ItoG_rest.T @ (-G) + b_a_rest
              + noise.accel_noise_density * np.sqrt(rate) * rng_rest.standard_normal((n_rest, 3)))

q_init, b_g_init, stats = static_initialization(t_rest, gyro_rest, accel_rest, duration=1.0)


def tilt_error_deg(R_GtoI_est, R_GtoI_true):
    """Angle [deg] between the 'up' directions seen in I: the roll/pitch error, free of the unobservable yaw."""
    up_est, up_true = R_GtoI_est @ [0.0, 0.0, 1.0], R_GtoI_true @ [0.0, 0.0, 1.0]
    return np.degrees(np.arccos(np.clip(up_est @ up_true, -1.0, 1.0)))


tilt = tilt_error_deg(quat_to_rot(q_init), R_ItoG_rest.T)
horizontal_ba = np.linalg.norm(b_a_rest - (b_a_rest @ stats.up_I) * stats.up_I)  # b_a across the gravity direction
sigma_mean = noise.gyro_noise_density * np.sqrt(rate) / np.sqrt(n_rest)  # std of a mean of M samples, per axis
print(f"gyro bias error {np.linalg.norm(b_g_init - b_g_rest):.2e} rad/s (expected about √3 σ_g √f / √M = "
      f"{np.sqrt(3) * sigma_mean:.1e})")
print(f"tilt error {tilt:.3f} deg; expected from the horizontal accel bias: {np.degrees(horizontal_ba / 9.81):.3f} deg")
assert np.linalg.norm(b_g_init - b_g_rest) < 5e-4
assert 1 / 3 < np.linalg.norm(b_g_init - b_g_rest) / (np.sqrt(3) * sigma_mean) < 3  # the size averaging predicts
assert abs(tilt - np.degrees(horizontal_ba / 9.81)) < 0.05
display(Markdown(
    f"The gyroscope bias error is {np.linalg.norm(b_g_init - b_g_rest) / (np.sqrt(3) * sigma_mean):.2f} times what "
    f"the averaging of $M = {n_rest}$ samples predicts, and the tilt error ({tilt:.3f}°) is almost entirely the "
    f"accelerometer bias seen as a tilt ({np.degrees(horizontal_ba / 9.81):.3f}°)."))

# %% [markdown]
# **On the real EuRoC recording** (a public data set of micro-aerial-vehicle flights with an IMU and ground truth;
# V1_01_easy: a micro aerial vehicle standing on the ground with its rotors
# spinning for the first seconds), when the data folder is present next to the repository. The ground truth comes
# with the biases estimated offline, so we can grade the static initialisation, then dead-reckon 5 s from the true
# state with three choices of biases.

# %%
def find_euroc() -> Path | None:
    """Return the EuRoC slice folder, looked up beside the repository (from the package, then from here)."""
    name = Path("shared") / "data" / "real" / "euroc_V1_01_easy_micro"
    repo_root = Path(evio_lib.__file__).resolve().parents[1]
    for base in (repo_root.parent, Path.cwd().parent, Path.cwd().parent.parent):
        if (base / name / "mav0").is_dir():
            return base / name
    return None


euroc_dir = find_euroc()
if euroc_dir is None:
    print("EuRoC slice ../shared/data/real/euroc_V1_01_easy_micro not found: skipping the real-data part "
          "(the simulated static initialisation above shows the same idea).")
else:
    from evio_lib.io.euroc import read_euroc

    seq = read_euroc(euroc_dir, load_frames=False)
    imu_r, gt = seq.imu, seq.groundtruth_imu
    q_e, b_g_e, st = static_initialization(imu_r.t, imu_r.gyro, imu_r.accel, duration=1.5)
    i0 = int(np.searchsorted(gt.t, st.t_start))
    R_GtoI_gt = quat_to_rot(gt.interpolate([st.t_start]).q_GtoB[0])
    print(f"EuRoC static window: {st.n_samples} samples, raw accel std {st.accel_std.round(2)} m/s² (rotors!)")
    print("gyro bias  static init:", b_g_e.round(4), " ground truth:", gt.bias_gyro[i0].round(4), "rad/s")
    print(f"gyro bias error {np.linalg.norm(b_g_e - gt.bias_gyro[i0]):.1e} rad/s; "
          f"gravity direction error {tilt_error_deg(quat_to_rot(q_e), R_GtoI_gt):.2f} deg")
    assert np.linalg.norm(b_g_e - gt.bias_gyro[i0]) < 3e-3
    assert tilt_error_deg(quat_to_rot(q_e), R_GtoI_gt) < 1.0

# %% [markdown]
# Dead reckoning on the real IMU from the ground-truth state at the first sample, with no biases, with the static
# initialisation's gyroscope bias (no accelerometer bias: it is not observable at rest), and with the ground-truth
# biases:

# %%
if euroc_dir is not None:
    t0 = imu_r.t[0]
    m = imu_r.t <= t0 + 5.0 + 1e-9
    g0 = gt.interpolate([t0])
    choices = {"no biases": (np.zeros(3), np.zeros(3)), "static-init b_g": (b_g_e, np.zeros(3)),
               "ground-truth biases": (gt.bias_gyro[0], gt.bias_accel[0])}
    p_gt = gt.interpolate(imu_r.t[m]).p_BinG
    euroc_err = {}
    for label, (bg, ba) in choices.items():
        start_r = ImuState(g0.q_GtoB[0], bg, g0.v_BinG[0], ba, g0.p_BinG[0], t0)
        _, _, p_r = integrate_imu(start_r, imu_r.t[m], imu_r.gyro[m], imu_r.accel[m], G)
        euroc_err[label] = np.linalg.norm(p_r - p_gt, axis=1)
        print(f"{label:>20}: position error after 2 s {euroc_err[label][400]:.2f} m, after 5 s "
              f"{euroc_err[label][-1]:.2f} m")
    plot_error_growth(imu_r.t[m] - t0, euroc_err, title="EuRoC V1_01_easy: IMU-only dead reckoning")
    plt.yscale("log")
    plt.show()
    assert euroc_err["ground-truth biases"][-1] < euroc_err["no biases"][-1] / 5
    assert 10 < euroc_err["no biases"][-1] < 25 and euroc_err["ground-truth biases"][-1] < 1.0  # ~16 m -> < 1 m
    assert euroc_err["static-init b_g"][-1] < 0.15 * euroc_err["no biases"][-1]  # most of the damage is the gyro bias
    assert 1.0 < euroc_err["static-init b_g"][-1] < 1.6
    display(Markdown(
        f"On the real IMU the ground-truth biases take the error after 5 s from {euroc_err['no biases'][-1]:.1f} m "
        f"down to {euroc_err['ground-truth biases'][-1]:.2f} m. The static gyroscope bias alone already removes most "
        f"of the damage ({euroc_err['static-init b_g'][-1]:.2f} m left)."))
else:
    print("EuRoC slice not found: skipped.")

# %% [markdown]
# The gyroscope bias is the big one because it drives the cubic term. What is left comes from the accelerometer
# bias and from vibration, which a camera must correct: that is the MSCKF of the next lessons.
#
# ## Summary
#
# * Attitude is a JPL unit quaternion $\bar q_{GtoI}$ (scalar last, $C(\bar q) = R_{GtoI}$); it evolves as
#   $\dot{\bar q} = \frac12\Omega(\boldsymbol\omega)\bar q$, exactly solvable for a constant rate.
# * The nominal IMU state $[\bar q, \mathbf b_g, \mathbf v, \mathbf b_a, \mathbf p]$ follows thesis Eq. 31; RK4 at every IMU sample
#   integrates it, and our twelve-line RK4 step agrees with `evio_lib.msckf.propagation.integrate_imu`.
# * The accelerometer measures the specific force $R_{GtoI}(\mathbf a - \mathbf g)$; both sensors add a bias (a random walk)
#   and white noise given as densities (per-sample std $= \sigma\sqrt f$).
# * With perfect data, dead reckoning at 1 kHz stays within a fraction of a millimetre (section 4); the error shrinks
#   like $h^2$ because of the linear interpolation between samples.
# * Uncorrected biases make the position error grow like $t^2$ (accelerometer) and $t^3$ (gyroscope, through gravity);
#   without a camera, even corrected biases leave an error that grows (white noise and the bias random walk), and
#   uncorrected ones a far larger one (section 5 renders both).
# * At rest, averaging gives the gyroscope bias and the gravity direction (roll and pitch); yaw and the accelerometer
#   bias are not observable there.
#
# ## Exercises
#
# 1. Replace the linear mid-point in `rk4_step` by the 4-point cubic interpolation and show that the dead-reckoning
#    error at 200 Hz drops by orders of magnitude (compare with `integrate_imu_rk4(..., midpoint="cubic")`).
#
#    *Hint:* the cubic through $u_{k-1}, u_k, u_{k+1}, u_{k+2}$ at the mid-point is $(-u_{k-1} + 9u_k + 9u_{k+1} -
#    u_{k+2})/16$; one-sided at the two ends.
# 2. Use a simple Euler step $\bar q_{k+1} = \bar q_k + h\,\tfrac12\Omega\bar q_k$, $\mathbf v_{k+1} = \mathbf v_k + h\,\mathbf f_k$
#    and measure its error on the same trajectory. Which order do you find?
#
#    *Hint:* run the Euler loop at 200 Hz and 1 kHz; the order is $\log(e_{200}/e_{1000})/\log 5$.
# 3. Derive the $\tfrac16 g\,b_g t^3$ law for a level, non-rotating IMU, and check it numerically with a constant
#    gyroscope bias about the $x$ axis.
#
#    *Hint:* a tilt of $b_g t$ misreads gravity as a horizontal acceleration $g\, b_g t$; integrate twice.
#    Numerically: a level IMU at rest reads `accel = -G`, `gyro = [b, 0, 0]`.
# 4. How long must the IMU rest so that the static gyroscope bias is better than 1e-4 rad/s with the default noise
#    density? Check your answer with `static_initialization`.
#
#    *Hint:* the mean of $fT$ samples of std $\sigma_g\sqrt f$ has std $\sigma_g/\sqrt T$ per axis; solve $\sqrt
#    3\,\sigma_g/\sqrt T < 10^{-4}$.
# 5. On the EuRoC data, move the static window to after take-off (`t_start=imu_r.t[0] + 8`) and read the error message.
#    Which test rejects the window?
#
#    *Hint:* catch the `ValueError` and read which of the three tests (gyro spread, accelerometer spread, $|a|$
#    against $g$) exceeded its limit.
#
# Worked solutions, with the code to run: [docs/solutions/09_imu_kinematics.md](../docs/solutions/09_imu_kinematics.md).
