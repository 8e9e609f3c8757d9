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
# # 11 — The MSCKF state, its covariance and IMU propagation
#
# Notebook 09 integrated the IMU's *nominal* state. A Kalman filter must also know how *uncertain* that state
# is, and how the uncertainty grows between images. The Kalman filter itself (predict, update, NEES, an error-state
# filter) is the previous lesson's subject; here it meets the full IMU. The MSCKF (Multi-State Constraint Kalman
# Filter, Mourikis & Roumeliotis 2007; the thesis, Friedel 2020, §3.3.2-3.3.4) is an **error-state** extended Kalman
# filter (EKF: a Kalman filter on a linearisation around the current estimate). This lesson builds it piece by piece
# with `evio_lib.msckf`:
#
# 1. the **error state**: its ordering, and the 3-DoF attitude error behind the error quaternion (Eqs. 22-26),
# 2. the continuous error dynamics **F** and **G** (Eqs. 33-35), checked by finite differences of the real
#    nonlinear integrator,
# 3. their discretisation **Φ** and **Q_d** (Eqs. 36-37), checked against `scipy.linalg.expm` and Van Loan's method,
# 4. **covariance propagation** (Eqs. 38-40) and its growth: 3σ bounds against seeded Monte-Carlo IMU-only runs,
# 5. **state augmentation** with a camera pose (Eqs. 27-30) and its Jacobian **J** (finite-difference check),
# 6. what the full covariance looks like, as an image.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from IPython.display import Markdown, display  # noqa: E402

from evio_lib.course import fast_mode  # noqa: E402

FAST = fast_mode()
rng = np.random.default_rng(1010)
DURATION = 2.0 if FAST else 10.0  # seconds of IMU-only propagation in section 4
N_RUNS = 20 if FAST else 100  # Monte-Carlo runs
print(f"section 4: {DURATION:g} s of IMU-only propagation, {N_RUNS} Monte-Carlo runs")

# %% [markdown]
# The filter of lessons 11-13 in one picture. Top: the state this lesson builds, an IMU state of 15 error states
# followed by a window of camera clones, 6 each. Bottom: what lesson 12 does with a feature track, step by step —
# note that the feature's position is never part of the state.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_schematics import plot_msckf_schematic

fig = plot_msckf_schematic(num_clones=5)
plt.show()

# %% [markdown]
# ## 1. The error state
#
# The nominal IMU state $X_{IMU} = [\bar q_{GtoI}, \mathbf b_g, \mathbf v_{IinG}, \mathbf b_a, \mathbf p_{IinG}]$ has 16 numbers,
# but a unit quaternion has only 3 degrees of freedom; a covariance over all four components would be singular. The
# filter therefore estimates the **error** of the state (thesis Eq. 22), 15 numbers:
#
# $$\tilde{\mathbf x}_{IMU} = [\delta\boldsymbol\theta^T, \delta\mathbf b_g^T, \delta\mathbf v^T, \delta\mathbf b_a^T, \delta\mathbf p^T]^T,$$
#
# additive for biases, velocity and position ($\mathbf x = \hat{\mathbf x} + \delta\mathbf x$), and *multiplicative* for the
# attitude (Eqs. 23-24):
#
# $$\bar q = \delta\bar q\otimes\hat{\bar q},\qquad \delta\bar q \approx \begin{bmatrix}\tfrac12\delta\boldsymbol\theta\\ 1\end{bmatrix}.$$
#
# $\delta\boldsymbol\theta$ is a small rotation vector expressed in $I$: $C(\delta\bar q) \approx I_3 - [\delta\boldsymbol\theta\times]$. The library uses
# the exact $\delta\bar q = $ `quat_from_rotvec(δθ)`, whose first-order form is Eq. 24. Each of the $N$ camera poses
# in the window adds $[\delta\boldsymbol\theta_{C_i}, \delta\mathbf p_{C_i}]$ (Eqs. 25-26), so the covariance is
# $(15 + 6N) \times (15 + 6N)$.
# The index slices are exported by `evio_lib.msckf.state`:

# %%
from evio_lib.msckf.state import BA, BG, POS, THETA, VEL

for name, sl in (("δθ", THETA), ("δb_g", BG), ("δv", VEL), ("δb_a", BA), ("δp", POS)):
    print(f"{name:>5}: error-state indices {sl.start}..{sl.stop - 1}")
print("camera i: 15 + 6 i + (0..2) attitude, 15 + 6 i + (3..5) position")

# %% [markdown]
# Check the error quaternion: for a small $\delta\boldsymbol\theta$ the exact $\delta\bar q$ agrees with $[\tfrac12\delta\boldsymbol\theta, 1]$ up to
# second order, $C(\delta\bar q)$ is $I - [\delta\boldsymbol\theta\times]$ up to second order, and `inject_error` / `state_difference` are
# exact inverses (the filter's $\boxplus$ and $\boxminus$).

# %%
from evio_lib.geometry.rotation import quat_from_rotvec, quat_to_rot, skew, so3_exp
from evio_lib.msckf.state import FilterState, ImuState, inject_error, state_difference

dtheta = np.array([0.004, -0.002, 0.003])
dq = quat_from_rotvec(dtheta)
print("exact δq       :", dq.round(8))
print("[δθ/2, 1] (Eq.24):", np.r_[dtheta / 2, 1.0].round(8))
assert np.abs(dq - np.r_[dtheta / 2, 1.0]).max() < np.dot(dtheta, dtheta)  # differ at second order only
assert np.abs(quat_to_rot(dq) - (np.eye(3) - skew(dtheta))).max() < np.dot(dtheta, dtheta)

imu = ImuState.from_pose(so3_exp([0.3, -0.2, 0.5]), [1.0, 2.0, 3.0], [0.5, -0.2, 0.1], 0.0,
                         b_g=[0.01, 0.02, -0.01], b_a=[0.1, -0.1, 0.05])
est = FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15))
dx = rng.normal(0.0, 0.05, 15)
assert np.allclose(state_difference(inject_error(est, dx), est), dx, atol=1e-12)  # (x ⊞ δx) ⊟ x = δx

# %% [markdown]
# ## 2. The continuous error dynamics F and G
#
# Linearising the IMU equations of notebook 09 around the estimate gives (thesis Eqs. 33-35)
#
# $$\dot{\tilde{\mathbf x}}_{IMU} = F\,\tilde{\mathbf x}_{IMU} + G\,\mathbf n_{IMU},\qquad \mathbf n_{IMU} = [\mathbf n_g, \mathbf n_{wg}, \mathbf n_a, \mathbf n_{wa}],$$
#
# $$F = \begin{bmatrix} -[\hat{\boldsymbol\omega}\times] & -I_3 & 0 & 0 & 0\\ 0&0&0&0&0\\ -R_{ItoG}[\hat{\mathbf a}\times] & 0&0& -R_{ItoG} & 0\\
# 0&0&0&0&0\\ 0&0&I_3&0&0\end{bmatrix},\qquad
# G = \begin{bmatrix} -I_3 & 0&0&0\\ 0& I_3 &0&0\\ 0&0&-R_{ItoG}&0\\ 0&0&0&I_3\\ 0&0&0&0\end{bmatrix}.$$
#
# Reading the rows: an attitude error is rotated by the body rate and fed by a gyro-bias error; a velocity error
# comes from the tilted specific force and from the accelerometer-bias error; a position error integrates the
# velocity error.
#
# **Finite-difference check.** Rather than trusting the derivation, we measure F and G on the real nonlinear
# integrator. Start the estimate and a perturbed "true" state $\mathbf x = \hat{\mathbf x}\boxplus\delta\mathbf x$, feed the true
# state with measurements disturbed by a constant noise $\mathbf n$, integrate both over $\tau = 1$ ms and read the error
# $\delta\mathbf x(\tau) = \mathbf x(\tau)\boxminus\hat{\mathbf x}(\tau)$. Central differences in $(\delta\mathbf x, \mathbf n)$ give the Jacobian $M$ of
# this map. For (nearly) constant F and G, $M = \exp\!\left(\begin{bmatrix}F & G\\ 0 & 0\end{bmatrix}\tau\right)$, so $\log(M)/\tau$
# returns F and the columns of G.

# %%
import scipy.linalg

from evio_lib.msckf.propagation import error_state_jacobians, integrate_imu
from evio_lib.sim.imu import GRAVITY_G

w_hat, a_hat = np.array([0.4, -0.3, 0.8]), np.array([0.5, 0.2, 9.7])  # bias-corrected rate and specific force
tau, K = 1e-3, 10
t_fd = np.linspace(0.0, tau, K + 1)
w_m, a_m = w_hat + imu.b_g, a_hat + imu.b_a  # what the IMU measured


def propagate_nominal(state, n_g=np.zeros(3), n_a=np.zeros(3), t=t_fd):
    """The state integrated over t with constant measurements ω_m - n_g, a_m - n_a (biases held)."""
    q, v, p = integrate_imu(state.imu, t, np.tile(w_m - n_g, (len(t), 1)), np.tile(a_m - n_a, (len(t), 1)), GRAVITY_G)
    return FilterState.initial(ImuState(q[-1], state.imu.b_g, v[-1], state.imu.b_a, p[-1], t[-1]),
                               np.eye(3), np.zeros(3), np.eye(15))


est_end = propagate_nominal(est)


def error_after(z):
    """δx(τ) for the initial error z[:15] and the measurement noise n_g = z[15:18], n_a = z[18:21]."""
    return state_difference(propagate_nominal(inject_error(est, z[:15]), z[15:18], z[18:21]), est_end)


eps = 1e-6
M = np.eye(21)  # the noise part stays constant: bottom rows [0, I]
for i in range(21):
    e = np.zeros(21)
    e[i] = eps
    M[:15, i] = (error_after(e) - error_after(-e)) / (2 * eps)
L = scipy.linalg.logm(M).real / tau

t_mid = np.linspace(0.0, tau / 2, K + 1)  # F and G use the orientation at the middle of the interval
R_mid = propagate_nominal(est, t=t_mid).imu.R_ItoG
F, G = error_state_jacobians(R_mid, w_hat, a_hat)
err_F = np.abs(L[:15, :15] - F).max()
err_G = np.abs(L[:15, 15:] - G[:, [0, 1, 2, 6, 7, 8]]).max()  # the n_g and n_a columns
print(f"max |F_fd - F| = {err_F:.1e} (max |F| = {np.abs(F).max():.1f});  max |G_fd - G| = {err_G:.1e}")
assert err_F < 1e-6 and err_G < 1e-6

# %%
display(Markdown(
    f"Finite differences and the analytic F, G agree to {max(err_F, err_G):.0e}, against entries of F up to "
    f"{np.abs(F).max():.1f}. The remaining two column blocks of G (the bias random walks) need no check: "
    f"$\\dot{{\\mathbf b}} = \\mathbf n_w$ *defines* the bias model."))

# %% [markdown]
# ## 3. Discretisation: Φ and Q_d
#
# Between two IMU samples ($\Delta t = t_{k+1} - t_k$) the filter needs the **transition matrix** and the
# **discrete process noise** (thesis Eqs. 36-37):
#
# $$\Phi_k = \exp\!\left(\int_{t_k}^{t_{k+1}} F(\tau)\,d\tau\right),\qquad
# Q_{d,k} = \int_{t_k}^{t_{k+1}}\Phi(t_{k+1},\tau)\,G\,Q_{IMU}\,G^T\,\Phi(t_{k+1},\tau)^T d\tau,$$
#
# with $Q_{IMU} = \mathrm{diag}(\sigma_g^2 I, \sigma_{wg}^2 I, \sigma_a^2 I, \sigma_{wa}^2 I)$, the squared noise densities.
# `transition_matrix` evaluates $\exp(F\Delta t)$ in closed form (F frozen at the state it is given; `propagate`
# passes the interval's midpoint), and `discrete_noise_covariance` integrates $Q_d$ by Gauss-Legendre quadrature (a
# weighted sum of the integrand at three points, exact for polynomials up to degree 5). Independent references:
# `scipy.linalg.expm` for Φ, and **Van Loan's method** for $Q_d$: the exponential of one block matrix gives both at once,
#
# $$\exp\!\left(\begin{bmatrix}-F & GQG^T\\ 0 & F^T\end{bmatrix}\Delta t\right) = \begin{bmatrix}\cdot & B_{12}\\ 0 & B_{22}\end{bmatrix},\qquad
# \Phi = B_{22}^T,\quad Q_d = \Phi\,B_{12}.$$

# %%
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.propagation import discrete_noise_covariance, transition_matrix

config = MsckfConfig()
q_imu = config.continuous_noise_psd()  # diag(Q_IMU)
R0 = imu.R_ItoG
F0, G0 = error_state_jacobians(R0, w_hat, a_hat)
rows = []
for dt in (0.001, 0.005, 0.05):
    Phi = transition_matrix(R0, w_hat, a_hat, dt)
    Q_d = discrete_noise_covariance(R0, w_hat, a_hat, dt, q_imu)
    B = scipy.linalg.expm(np.block([[-F0, G0 @ np.diag(q_imu) @ G0.T], [np.zeros((15, 15)), F0.T]]) * dt)
    Phi_vl = B[15:, 15:].T
    Q_vl = Phi_vl @ B[:15, 15:]
    s = np.sqrt(np.diag(Q_vl))
    err_phi = np.abs(Phi - scipy.linalg.expm(F0 * dt)).max()
    err_q = np.abs((Q_d - Q_vl) / np.outer(s, s)).max()  # normalised by σ_i σ_j
    # the common first-order shortcuts Φ ≈ I + F Δt and Q_d ≈ G Q G^T Δt, for comparison
    err_phi1 = np.abs(np.eye(15) + F0 * dt - Phi_vl).max()
    Q1 = G0 @ np.diag(q_imu) @ G0.T * dt
    err_q1 = np.abs((Q1 - Q_vl) / np.outer(s, s)).max()
    rest = np.r_[0:12]  # every block but the position's
    err_q1_rest = np.abs((Q1 - Q_vl) / np.outer(s, s))[np.ix_(rest, rest)].max()
    rows.append((dt, err_phi, err_q, err_phi1, err_q1, err_q1_rest))
    assert err_phi < 1e-12 and err_q < 1e-9
    assert np.all(Q1[12:15, :] == 0)  # G has no position rows: the first-order Q_d puts no noise on δp
assert rows[0][3] < 1e-5  # ... while I + FΔt is close to Φ at 1 kHz
assert rows[0][5] < 0.01  # and outside the position block the first-order Q_d is close at 1 kHz
print(" Δt [s]   |Φ - expm|   |Q_d - VanLoan|/σσ   first order: |I+FΔt - Φ|   |GQGᵀΔt - Q_d|/σσ   (without δp)")
for dt, e1, e2, e3, e4, e5 in rows:
    print(f"{dt:7.3f}   {e1:10.1e}   {e2:18.1e}   {e3:26.1e}   {e4:17.2f}   {e5:12.1e}")

# %% [markdown]
# The library matches both references to round-off. The first-order shortcuts that many implementations use
# are not bad for Φ at 1 kHz, but $G Q G^T\Delta t$ puts no noise at all on the position: in $Q_d$ a velocity noise
# already moves the position within the step, and $G$ has no position rows. So its relative error in the position
# entries is exactly 1 at every step size (the second-last column); in the other entries it is small at 1 kHz (the
# last column).
#
# ## 4. Covariance propagation and its growth
#
# Partition the covariance into the IMU block, the camera block and their cross-correlation (thesis Eqs. 38-40):
#
# $$P = \begin{bmatrix} P_{II} & P_{IC}\\ P_{IC}^T & P_{CC}\end{bmatrix}
# \;\longrightarrow\;
# \begin{bmatrix} \Phi P_{II}\Phi^T + Q_d & \Phi P_{IC}\\ P_{IC}^T\Phi^T & P_{CC}\end{bmatrix}.$$
#
# The camera poses are frozen in the past, so only the IMU block and its correlations move. `propagate` applies this
# to all IMU samples between two images at once and integrates the nominal state too.
#
# Is the predicted uncertainty *right*? A Monte-Carlo test answers it. We draw many noisy IMU recordings of the same
# trajectory (different noise and biases each time, all seeded) and start each estimate from the truth corrupted
# by an initial error drawn from $P_0$. Then we propagate IMU-only and compare the actual errors with the filter's
# $\pm3\sigma$. For a consistent filter the errors fill the bounds: not much smaller (noise overestimated: a
# pessimistic filter) and not outside them (noise underestimated: an overconfident filter). The **NEES** (normalised
# estimation error squared) $\epsilon = \tilde{\mathbf x}^T P^{-1}\tilde{\mathbf x}$ of the 6-DoF pose follows a
# $\chi^2$ law with 6 degrees of freedom when the filter is consistent, so its average over $N$ runs times $N$ follows
# $\chi^2(6N)$ (`chi2_bounds(6, N_RUNS)`, narrower as runs are added): the average should lie inside that 95 %
# interval at nearly all image times.

# %%
import time

import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_msckf import plot_monte_carlo_bounds
from evio_lib.geometry.rotation import quat_inverse, quat_multiply, quat_to_rotvec, rot_to_quat
from evio_lib.msckf.initialization import initial_state_from_truth
from evio_lib.msckf.propagation import propagate
from evio_lib.sim.imu import ImuNoiseParams, synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import trajectory_from_preset

noise = ImuNoiseParams(gyro_bias_init_sigma=0.002, accel_bias_init_sigma=0.02)  # a calibrated IMU
cfg = MsckfConfig(init_sigma_attitude=2e-3, init_sigma_velocity=0.01, init_sigma_position=1e-3).with_imu_noise(noise)
traj = trajectory_from_preset("boxes_like", duration=DURATION + 1.0, seed=3)
ext = CameraImuExtrinsics.default()
rate = 500.0
t_img = np.arange(0.0, DURATION + 1e-9, 0.05)  # 20 Hz "image" times at which P is read out
gt = traj.evaluate(t_img)
s0 = traj.evaluate(0.0)

tic = time.perf_counter()
imu_ref = synthesize_imu(traj, rate, None, t_end=DURATION)
state = initial_state_from_truth(0.0, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], ext.R_CtoI, ext.p_CinI, cfg)
P_hist = [state.P]
for t_k in t_img[1:]:
    state = propagate(state, imu_ref.t, imu_ref.gyro, imu_ref.accel, t_k, cfg)
    P_hist.append(state.P)
P_hist = np.array(P_hist)
t_cov = time.perf_counter() - tic

q_true = rot_to_quat(np.swapaxes(gt.R_ItoG, 1, 2))  # q_GtoI of the truth at the image times
idx = np.searchsorted(imu_ref.t, t_img)
errors = np.zeros((N_RUNS, t_img.size, 6))  # [δθ, δp] per run and time
tic = time.perf_counter()
for r in range(N_RUNS):
    imu_r = synthesize_imu(traj, rate, noise, rng, t_end=DURATION)
    est_r = initial_state_from_truth(0.0, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], ext.R_CtoI, ext.p_CinI, cfg,
                                     b_g=imu_r.bias_gyro[0], b_a=imu_r.bias_accel[0], rng=rng)  # x̂0 = x0 ⊞ N(0, P0)
    q_e, _, p_e = integrate_imu(est_r.imu, imu_r.t, imu_r.gyro, imu_r.accel, GRAVITY_G)
    errors[r, :, :3] = quat_to_rotvec(quat_multiply(q_true, quat_inverse(q_e[idx])))  # δθ = x ⊟ x̂
    errors[r, :, 3:] = gt.p_IinG - p_e[idx]
t_mc = time.perf_counter() - tic
print(f"covariance propagation {t_cov:.2f} s for {DURATION:g} s of 500 Hz IMU; {N_RUNS} Monte-Carlo runs {t_mc:.2f} s")

pose = [0, 1, 2, 12, 13, 14]  # δθ and δp in the error state
P_pose = P_hist[:, pose][:, :, pose]
sigma = np.sqrt(np.diagonal(P_pose, axis1=1, axis2=2))
labels = ["δθ_x [rad]", "δθ_y [rad]", "δθ_z [rad]", "δp_x [m]", "δp_y [m]", "δp_z [m]"]
plot_monte_carlo_bounds(t_img, errors, sigma, labels, title="IMU-only propagation on boxes_like: errors vs ±3σ")
plt.show()

# %%
from evio_lib.evaluation.plots_msckf import plot_nees
from evio_lib.evaluation.trajectory_metrics import chi2_bounds, nees

anees = nees(errors[:, 1:], np.broadcast_to(P_pose[1:], (N_RUNS,) + P_pose[1:].shape)).mean(axis=0)
lo, hi = chi2_bounds(6, N_RUNS)
inside = np.mean((anees >= lo) & (anees <= hi))
plot_nees(t_img[1:], anees, (lo, hi), dof=6, n_runs=N_RUNS, title="IMU-only propagation: average pose NEES")
plt.show()
spread = errors[:, -1].std(axis=0) / sigma[-1]  # sample std over the runs / the filter's σ, at the last image
print(f"final 1σ: attitude {np.degrees(sigma[-1, :3]).round(3)} deg, position {sigma[-1, 3:].round(3)} m")
print("sample std / filter σ at the end:", spread.round(2))
print(f"average NEES: mean {anees.mean():.2f} (expected 6), inside [{lo:.2f}, {hi:.2f}] at {100 * inside:.0f} % "
      "of the image times")
assert inside >= 0.9
assert np.all((spread > 0.6) & (spread < 1.4))  # the runs' spread follows the predicted σ

# %%
bias_alone = np.degrees(noise.gyro_bias_init_sigma * DURATION)  # a constant gyro-bias error integrated over the run
white_alone = np.degrees(noise.gyro_noise_density * np.sqrt(DURATION))  # the gyro's white noise alone
attitude_deg = np.degrees(sigma[:, :3]).mean(axis=1)  # σ per axis, averaged over the three axes
assert bias_alone > 0.5 * attitude_deg[-1] and white_alone < 0.1 * attitude_deg[-1]  # mostly the bias
display(Markdown(
    f"The grey traces fill the red ±3σ tube and the empirical spread (blue) follows it: at the last image the runs' "
    f"standard deviation is {spread.min():.2f}-{spread.max():.2f} times the filter's σ across the six axes, and the "
    f"average NEES lies inside its interval at {100 * inside:.0f} % of the image times (mean {anees.mean():.2f}, "
    f"expected 6). The propagated covariance predicts the real error growth. The position uncertainty grows quickly "
    f"(to {sigma[-1, 3:].max():.2f} m after {DURATION:g} s), because the initial velocity error, the accelerometer "
    f"noise and bias, and the tilt error (through gravity) are integrated into it. The attitude uncertainty grows "
    f"from {attitude_deg[0]:.2f}° to {attitude_deg[-1]:.2f}° per axis, mostly from the gyroscope-bias uncertainty: "
    f"{noise.gyro_bias_init_sigma:g} rad/s integrated over {DURATION:g} s gives at most {bias_alone:.2f}° (as the body "
    f"turns, the attitude error a constant bias error makes turns with it, and adds up to a little less), while the "
    f"gyroscope's white noise alone gives {white_alone:.3f}°. Nothing in IMU-only propagation can stop this growth; "
    f"bounding it is the job of the camera updates (notebook 12)."))

# %% [markdown]
# ## 5. State augmentation and its Jacobian J
#
# At each image the current camera pose is appended to the state (thesis Eqs. 27-28):
#
# $$\bar q_{GtoC} = \bar q_{ItoC}\otimes\bar q_{GtoI},\qquad \mathbf p_{CinG} = \mathbf p_{IinG} + R_{ItoG}\,\mathbf p_{CinI},$$
#
# and the covariance grows by the Jacobian $J$ of the new camera's error with respect to the current error state
# (Eqs. 29-30):
#
# $$P \leftarrow \begin{bmatrix} I\\ J\end{bmatrix} P \begin{bmatrix} I\\ J\end{bmatrix}^T,\qquad
# J = \begin{bmatrix} R_{ItoC} & 0_{3\times9} & 0_3 & 0_{3\times 6N}\\ -R_{ItoG}[\mathbf p_{CinI}\times] & 0_{3\times9} & I_3 & 0_{3\times 6N}\end{bmatrix}.$$
#
# The lower-left block carries a minus sign and no inner $R$, unlike the thesis's print of Eq. 30. This is the form that
# matches the error convention $\bar q = \delta\bar q\otimes\hat{\bar q}$ with $\delta\boldsymbol\theta$ in $I$ (see the docstring of
# `evio_lib.msckf.augmentation`). Let the finite differences decide: perturb the IMU error state, recompute the camera
# pose with `camera_pose_from_imu`, and differentiate the camera error.

# %%
from evio_lib.msckf.augmentation import augment_state, augmentation_jacobian, camera_pose_from_imu

state_a = initial_state_from_truth(0.0, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], ext.R_CtoI, ext.p_CinI, cfg)
state_a = augment_state(propagate(state_a, imu_ref.t, imu_ref.gyro, imu_ref.accel, 0.05, cfg), camera_id=0)
state_a = propagate(state_a, imu_ref.t, imu_ref.gyro, imu_ref.accel, 0.10, cfg)  # one camera in the window
J = augmentation_jacobian(state_a)
q_C0, p_C0 = camera_pose_from_imu(state_a.imu.q_GtoI, state_a.imu.p_IinG, ext.R_CtoI, ext.p_CinI)


def camera_error(dx):
    """[δθ_C, δp_C] of the camera pose computed from the IMU state x̂ ⊞ dx, relative to the one from x̂."""
    s = inject_error(state_a, dx)
    q_C, p_C = camera_pose_from_imu(s.imu.q_GtoI, s.imu.p_IinG, ext.R_CtoI, ext.p_CinI)
    return np.r_[quat_to_rotvec(quat_multiply(q_C, quat_inverse(q_C0))), p_C - p_C0]


J_fd = np.zeros_like(J)
for i in range(state_a.dim):
    e = np.zeros(state_a.dim)
    e[i] = 1e-6
    J_fd[:, i] = (camera_error(e) - camera_error(-e)) / 2e-6
print(f"max |J_fd - J| = {np.abs(J_fd - J).max():.1e};  J shape {J.shape} (15 + 6N with N = 1)")
assert np.abs(J_fd - J).max() < 1e-9

R_ItoG = state_a.imu.R_ItoG
J_thesis_print = J.copy()
J_thesis_print[3:6, 0:3] = skew(R_ItoG @ ext.p_CinI)  # [R_ItoG p_CinI x], Eq. 30 as printed
print(f"the printed form differs from the finite differences by {np.abs(J_fd - J_thesis_print).max():.2f}")
assert np.abs(J_fd - J_thesis_print).max() > 0.01  # the printed Eq. 30 is not this convention's Jacobian

P_aug = augment_state(state_a, camera_id=1).P
IJ = np.vstack([np.eye(state_a.dim), J])
assert np.allclose(P_aug, IJ @ state_a.P @ IJ.T, atol=1e-15)  # Eq. 29
print("augmented covariance:", state_a.P.shape, "->", P_aug.shape)

# %% [markdown]
# The finite differences reproduce the library's J (the printed difference), and `augment_state` produces exactly
# $[I; J]\,P\,[I; J]^T$. Note that the new camera is *fully correlated* with the IMU pose at that instant: it is a
# copy of it, so it carries no new information, only a memory of where the IMU was.
#
# ## 6. The structure of the covariance
#
# Propagate and augment through a few images (still IMU-only) and look at the whole matrix as correlations
# $\rho_{ij} = P_{ij}/\sqrt{P_{ii}P_{jj}}$. The blocks are the IMU error state and then one 6×6 block per camera,
# oldest first.

# %%
from evio_lib.evaluation.plots_msckf import correlation_matrix, plot_covariance_structure

n_cams = 4 if FAST else 6
s = initial_state_from_truth(0.0, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], ext.R_CtoI, ext.p_CinI, cfg)
for k in range(n_cams):
    s = augment_state(propagate(s, imu_ref.t, imu_ref.gyro, imu_ref.accel, 0.05 * (k + 1), cfg), camera_id=k)
s = propagate(s, imu_ref.t, imu_ref.gyro, imu_ref.accel, 0.05 * (n_cams + 0.5), cfg)
print(f"{s.num_cameras} cameras: P is {s.P.shape}, symmetric: {np.allclose(s.P, s.P.T)}, "
      f"min eigenvalue {np.linalg.eigvalsh(s.P).min():.1e}")
plot_covariance_structure(s.P, title=f"IMU-only: correlations of the {s.dim} error states")
plt.show()
assert np.linalg.eigvalsh(s.P).min() > -1e-12  # a covariance stays positive semi-definite
rho = correlation_matrix(s.P)
block = {name: slice(3 * k, 3 * k + 3) for k, name in enumerate(("θ", "b_g", "v", "b_a", "p"))}
strongest = {f"{a}-{b}": np.abs(rho[block[a], block[b]]).max() for a, b in
             (("v", "p"), ("θ", "v"), ("b_g", "θ"), ("b_a", "v"))}
strongest["C1-θ"] = np.abs(rho[15:18, block["θ"]]).max()
strongest["C1-p"] = np.abs(rho[18:21, block["p"]]).max()
print("largest |ρ| between blocks:", {k: round(float(v), 2) for k, v in strongest.items()})
assert strongest["v-p"] > 0.5 and strongest["θ-v"] > 0.3  # velocity -> position, tilt -> velocity
assert strongest["C1-θ"] > 0.5 and strongest["C1-p"] > 0.5  # a camera is a copy of an IMU pose
assert 0.15 < strongest["b_g-θ"] < 0.4 and 0.3 < strongest["b_a-v"] < 0.6  # bias errors already show

# %%
display(Markdown(
    "What the picture shows:\n\n"
    "* **δv and δp** are correlated (a velocity error has been integrated into the position), and δv is correlated, "
    "through gravity, with the tilt part of **δθ**.\n"
    "* Each camera block is almost a copy of the IMU pose at its time: strong correlations with δθ and δp, and with "
    "each other, because they share the same history of IMU errors.\n"
    f"* δb_g and δb_a are already visibly correlated with what they drive (|ρ| up to {strongest['b_g-θ']:.2f} between "
    f"δb_g and δθ, {strongest['b_a-v']:.2f} between δb_a and δv), although only {0.05 * (n_cams + 0.5):.3g} s have "
    "passed (Φ_θbg ≈ -I Δt, Φ_vba ≈ -R Δt): this calibrated IMU starts with a velocity known to "
    f"{100 * cfg.init_sigma_velocity:g} cm/s, so even a small bias error soon matters next to it. The camera updates "
    "of notebook 12 use these correlations: an observed pose error is partly blamed on the biases, which is how the "
    "MSCKF learns them."))

# %% [markdown]
# ## Summary
#
# * The MSCKF estimates a 15 + 6N **error state**: $[\delta\boldsymbol\theta, \delta\mathbf b_g, \delta\mathbf v, \delta\mathbf b_a, \delta\mathbf p]$ and
#   $[\delta\boldsymbol\theta_{C_i}, \delta\mathbf p_{C_i}]$ per camera, with the attitude error $\bar q = \delta\bar q\otimes\hat{\bar q}$,
#   $\delta\bar q\approx[\tfrac12\delta\boldsymbol\theta, 1]$.
# * **F** and **G** (Eqs. 33-35) describe how errors and noise flow through the IMU equations; finite differences of
#   the nonlinear integrator confirm them.
# * **Φ = exp(FΔt)** and **Q_d** (Eqs. 36-37) match `scipy.linalg.expm` and Van Loan's method to round-off. The
#   first-order $Q_d\approx GQG^T\Delta t$ puts no noise on the position within a step.
# * **Covariance propagation** (Eqs. 38-40) predicts the actual IMU-only error growth: the Monte-Carlo errors fill
#   the ±3σ bounds and the average NEES stays in its χ² interval at nearly all image times.
# * **Augmentation** (Eqs. 27-30) clones the camera pose; J agrees with finite differences, with the position row
#   $-R_{ItoG}[\mathbf p_{CinI}\times]$ for this error convention.
# * The covariance shows each camera as a near-copy of a past IMU pose, and early bias-state correlations that let
#   the camera updates learn the biases.
#
# ## Exercises
#
# 1. Replace `discrete_noise_covariance` by $GQG^T\Delta t$ in a hand-written propagation loop and repeat the
#    Monte-Carlo test. Does the NEES notice the difference at 500 Hz? At 50 Hz?
#
#    *Hint:* propagate $P$ sample by sample with `transition_matrix` and either `discrete_noise_covariance` or
#    `G @ diag(q) @ G.T * dt`; read it out at times that are IMU samples at both rates.
# 2. Double the accelerometer noise density in the *simulator* only (keep the filter's config). What happens to the
#    NEES curve, and why is an overconfident filter dangerous for the chi-square gating of notebook 12?
#
#    *Hint:* `import dataclasses`; `dataclasses.replace(noise, accel_noise_density=2 * noise.accel_noise_density)` in
#    `synthesize_imu` only; also compare how much of the position variance the accelerometer's white noise makes.
# 3. Derive the block $\Phi_{p\theta}$ for $\boldsymbol\omega = 0$ from $\exp(F\Delta t)$ by hand (the series stops after a few terms)
#    and compare with `transition_matrix`.
#
#    *Hint:* with $\omega = 0$, $F$ maps $\delta\theta \to \delta v \to \delta p$; $F^3$ and higher powers vanish on
#    that chain.
# 4. Show that $J$ of a camera with $\mathbf p_{CinI} = 0$ makes the camera block of P equal to the IMU pose block, up
#    to the rotation $R_{ItoC}$ of its attitude part.
#    What changes for a lever arm of 10 cm?
#
#    *Hint:* build the state with `p_CinI = np.zeros(3)` and compare `P[15:21, 15:21]` with the IMU pose block; mind
#    the rotation $R_{ItoC}$ of the attitude part.
# 5. Which entries of the correlation image change if the initial velocity uncertainty (`init_sigma_velocity`) is
#    raised to 0.5 m/s? Predict first, then check.
#
#    *Hint:* compute section 6's `strongest` correlations with both configs; which blocks does the initial velocity
#    variance feed?
#
# Solutions, with the code to run (checked by `tests/test_solutions.py`):
# [docs/solutions/11_msckf_state_and_propagation.md](../docs/solutions/11_msckf_state_and_propagation.md).
