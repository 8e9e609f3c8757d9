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
# # 12 — Observability and consistency
#
# A filter is **consistent** when the covariance it reports matches the errors it actually makes. An overconfident
# filter trusts its estimate too much, gates away good measurements and cannot recover. Visual-inertial odometry
# has a structural trap here: some directions of the state can never be observed, and a plain EKF can *believe*
# it observes them. This lesson (thesis §3.3.8, Eqs. 80-86)
#
# 1. writes down the four unobservable directions and checks them on the filter's own matrices;
# 2. shows how the standard EKF breaks them, and how the observability-constrained EKF (OC-EKF) restores them;
# 3. measures consistency with the **NEES** over Monte-Carlo runs, OC on and off.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")
import time

import matplotlib.pyplot as plt
import numpy as np

from evio_lib.evaluation.trajectory_metrics import chi2_bounds
from evio_lib.geometry.rotation import quat_to_rot, rot_to_quat
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.experiment import run_vio_sim
from evio_lib.msckf.initialization import initial_state_from_truth
from evio_lib.msckf.observability import (
    constrain_feature_jacobians,
    constrain_transition,
    imu_nullspace,
    state_nullspace,
)
from evio_lib.msckf.propagation import propagate
from evio_lib.msckf.update import feature_jacobians
from evio_lib.sim.imu import synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import trajectory_from_preset

FAST = os.environ.get("EVIO_FAST", "0") == "1"  # CI sets EVIO_FAST=1: a few short Monte-Carlo runs
rng = np.random.default_rng(12)
config = MsckfConfig()
g = config.gravity
ext = CameraImuExtrinsics.default()

# %% [markdown]
# ## 1. Four directions nobody can see
#
# Gravity makes roll and pitch observable (the accelerometer feels "down"), and the camera sees relative motion.
# But if the whole world — trajectory and landmarks together — is **shifted** by any vector, or **rotated about
# the gravity axis** (yaw), every IMU sample and every image stays exactly the same. Those four directions of the
# error state $[\delta\theta, \delta b_g, \delta v, \delta b_a, \delta p]$ span the nullspace (Eq. 80)
#
# $$N = \begin{bmatrix} 0_3 & R_{G\to I}\, g^G \\ 0_3 & 0 \\ 0_3 & -[v_I^G\times] g^G \\ 0_3 & 0 \\
#   I_3 & -[p_I^G\times] g^G \end{bmatrix},$$
#
# first block: translation; last column: a small yaw $\epsilon$ about $g$ moves the attitude by
# $\epsilon R_{G\to I}\hat g$, the velocity and position by $\epsilon\, \hat g \times v$ and $\epsilon\, \hat g \times p$.
# A check of the yaw column by brute force: rotate the true state about $z_G$ and take differences.

# %%
traj = trajectory_from_preset("boxes_like", duration=6.0, seed=0)
s = traj.evaluate(1.0)
R_ItoG, v, p = s.R_ItoG[0], s.v_IinG[0], s.p_IinG[0]
eps = 1e-7
Rz = np.array([[1.0, -eps, 0.0], [eps, 1.0, 0.0], [0.0, 0.0, 1.0]])  # a small yaw about z_G (first order)
# δx = x_rotated ⊟ x, with R_GtoI,new ≈ (I - [δθ x]) R_GtoI  ->  [δθ x] = I - R_GtoI,new R_GtoI^T
dR = np.eye(3) - (Rz @ R_ItoG).T @ R_ItoG
yaw_direction = np.concatenate([[dR[2, 1], dR[0, 2], dR[1, 0]], np.zeros(3), Rz @ v - v, np.zeros(3), Rz @ p - p])
N = imu_nullspace(rot_to_quat(R_ItoG.T), v, p, g)
# the library's column is written with g = (0, 0, -9.81): a yaw ε about +z_G is -ε/|g| times it
print("max |brute force + ε/|g| N[:, 3]| =", f"{np.abs(yaw_direction + eps / np.linalg.norm(g) * N[:, 3]).max():.1e}")
assert np.allclose(yaw_direction, -eps / np.linalg.norm(g) * N[:, 3], atol=1e-15)

# %% [markdown]
# ## 2. Propagation: the EKF keeps the directions only if it linearises at the right point
#
# For the true system $\Phi_k N_k = N_{k+1}$: what is unobservable stays unobservable. The EKF evaluates
# $\Phi_k$ at the *corrected* estimate $x_{k|k}$, while the nullspace it inherited was built at the earlier
# prediction $x_{k|k-1}$; after every update the two differ and $\Phi_k N_k \ne N_{k+1}$. Information then
# leaks into the yaw direction and the yaw variance shrinks although no measurement saw it (Huang et al. 2010,
# Hesch et al. 2014). The OC-EKF keeps the **first estimates** $x_{k|k-1}$ and changes $\Phi$ minimally so that
#
# $$\Phi_{11} = R_{G\to I,k+1|k} R_{G\to I,k|k-1}^T,\qquad \Phi_{31} u = ([v_{k|k-1}\times] - [v_{k+1|k}\times]) g,
# \qquad \Phi_{51} u = (\delta t [v_{k|k-1}\times] + [p_{k|k-1}\times] - [p_{k+1|k}\times]) g$$
#
# with $u = R_{G\to I,k|k-1} g$, each "$A u = w$" solved by $A^* = A - (Au - w)(u^T u)^{-1} u^T$ (Eqs. 81-84;
# the $[p_{k|k-1}\times]$ term, missing in the thesis's Eq. 83, is needed — see the module docstring).
#
# Experiment: propagate, apply a correction as an update would (the first estimates stay), propagate again and
# compare $\Phi_k N_k$ with $N_{k+1}$ on every IMU interval.

# %%
imu = synthesize_imu(traj, 1000.0, None, t_start=0.9, t_end=1.3)  # noise-free samples
s1 = traj.evaluate(1.0)
state = initial_state_from_truth(1.0, s1.R_ItoG[0], s1.p_IinG[0], s1.v_IinG[0], ext.R_CtoI, ext.p_CinI, config)
state = propagate(state, imu.t, imu.gyro, imu.accel, 1.05, config)  # first estimates = this prediction
correction = np.concatenate([[0.01, -0.02, 0.015], np.zeros(3), [0.05, -0.03, 0.02], np.zeros(3), [0.02, 0.01, -0.03]])
state = state.inject_error(correction)  # an "update": the estimate moves, the first estimates stay


def nullspace_mismatch(oc):
    captured = {}

    def hook(Phi, steps):
        Phi = constrain_transition(Phi, steps) if oc else Phi
        captured.update(Phi=Phi.copy(), steps=steps)
        return Phi

    propagate(state, imu.t, imu.gyro, imu.accel, 1.1, config, transition_hook=hook)
    st = captured["steps"]
    N_k = imu_nullspace(st.q_GtoI_prev, st.v_IinG_prev, st.p_IinG_prev, g)  # first estimates at each interval start
    N_k1 = imu_nullspace(st.q_GtoI[1:], st.v_IinG[1:], st.p_IinG[1:], g)  # predictions at each interval end
    return np.abs(captured["Phi"] @ N_k - N_k1).max(axis=(1, 2))


mismatch_plain, mismatch_oc = nullspace_mismatch(False), nullspace_mismatch(True)
print(f"max |Φ N_k - N_k+1|: standard EKF {mismatch_plain.max():.2e} (first interval {mismatch_plain[0]:.2e}), "
      f"OC-EKF {mismatch_oc.max():.1e}")
assert mismatch_oc.max() < 1e-9
assert mismatch_plain[0] > 1e-3

# %% [markdown]
# The first interval, right after the correction, carries almost all of the standard EKF's mismatch; within an
# uninterrupted propagation the prediction is its own first estimate and only discretisation errors remain.
#
# ## 3. Update: $H N = 0$ only at one linearisation point
#
# A feature measurement depends on the camera poses and the feature, so the directions act on them too: a camera
# block gets $[R_{G\to C} g;\ I_3, -[p_C\times] g]$ and the feature $N_f = [I_3, -[p_F\times] g]$. The plain
# Jacobians (Eqs. 45-47) satisfy $H_x N + H_f N_f = 0$ at the *current* estimate — but the nullspace that
# propagation preserved is the one of the *first estimates*. The OC-EKF projects each camera block so that
# $H_{C} u = 0$ with the first-estimate $u$ and rebuilds $H_f = -H_C[:, 3{:}6]$ (Eqs. 85-86):

# %%
cam_state = state
for k, t_img in enumerate([1.1, 1.15, 1.2, 1.25]):
    cam_state = augment_state(propagate(cam_state, imu.t, imu.gyro, imu.accel, t_img, config), camera_id=k)
dx = np.zeros(cam_state.dim)
dx[15:] = rng.normal(0.0, 0.01, cam_state.dim - 15)  # an update moves the camera poses, not their first estimates
cam_state = cam_state.inject_error(dx)

q_C, p_C = cam_state.camera_poses
R_C = quat_to_rot(q_C)
p_F = p_C[0] + R_C[0].T @ np.array([0.2, 0.1, 2.0])  # a landmark 2 m in front of the first camera
p_FinC = np.einsum("mij,mj->mi", R_C, p_F - p_C)
z = p_FinC[:, :2] / p_FinC[:, 2:]
cols = 15 + 6 * np.arange(cam_state.num_cameras)
_, H_x, H_f = feature_jacobians(R_C, p_C, cols, p_F, z, cam_state.dim)
N_f = np.column_stack([np.eye(3), -np.cross(p_F, g)])  # [I_3, -[p_F x] g]
N_now = state_nullspace(cam_state, g, first_estimates=False)
N_first = state_nullspace(cam_state, g, first_estimates=True)
R_null = np.array([quat_to_rot(c.q_GtoC_null) for c in cam_state.cameras.values()])
p_null = np.array([c.p_CinG_null for c in cam_state.cameras.values()])
H_x_oc, H_f_oc = constrain_feature_jacobians(H_x, H_f, cols, R_null, p_null, p_F, g)

residual = {
    "plain H, current estimate": np.abs(H_x @ N_now + H_f @ N_f).max(),
    "plain H, first estimates": np.abs(H_x @ N_first + H_f @ N_f).max(),
    "OC H, first estimates": np.abs(H_x_oc @ N_first + H_f_oc @ N_f).max(),
}
for name, value in residual.items():
    print(f"max |H N + H_f N_f|  {name:28s} {value:.2e}")
assert residual["plain H, current estimate"] < 1e-9
assert residual["plain H, first estimates"] > 1e-4
assert residual["OC H, first estimates"] < 1e-9

# %% [markdown]
# ## 4. Consistency: NEES over Monte-Carlo runs
#
# With the pose error $e_k = [\delta\theta_I; \delta p]$ and its reported covariance $P_k$ (6x6), the
# **normalised estimation error squared** $\epsilon_k = e_k^T P_k^{-1} e_k$ of a consistent filter is
# $\chi^2_6$-distributed: mean 6. Averaged over $n$ independent runs, $n\bar\epsilon_k \sim \chi^2_{6n}$, which
# gives a 95 % band (Bar-Shalom et al. 2001). The yaw alone has 1 DoF. `evio_lib.msckf.experiment.run_vio_sim`
# runs the perfect-data-association experiment (boxes_like, 60 tracks, 1 px, noisy IMU with unknown biases, the
# initial error drawn from $P_0$) and returns these NEES series; each seed is one Monte-Carlo run. As in
# `bench/msckf_monte_carlo.py`, the initial velocity std is 0.03 m/s (see section 5 for why).

# %%
n_runs = 3 if FAST else 8
duration = 3.0 if FAST else 10.0
start = {"init_sigma_velocity": 0.03}
results = {}
t0 = time.perf_counter()
for oc in (True, False):
    results[oc] = [run_vio_sim("boxes_like", duration=duration, seed=100 + k, oc=oc, baselines=False,
                               msckf_overrides=start) for k in range(n_runs)]
print(f"{2 * n_runs} runs of {duration:g} s in {time.perf_counter() - t0:.1f} s")
t = results[True][0].t
lo6, hi6 = chi2_bounds(6, n_runs)
lo1, hi1 = chi2_bounds(1, n_runs)
summary = {}
for oc, runs in results.items():
    pose = np.mean([r.nees_pose for r in runs], axis=0)
    yaw = np.mean([r.nees_yaw for r in runs], axis=0)
    rmse = np.mean([r.metrics["rmse_m"] for r in runs])
    summary[oc] = dict(pose=pose, yaw=yaw)
    print(f"OC {'on ' if oc else 'off'}: mean pose NEES {pose.mean():6.2f} (band [{lo6:.2f}, {hi6:.2f}], "
          f"{100 * np.mean((pose >= lo6) & (pose <= hi6)):.0f} % of images inside); mean yaw NEES {yaw.mean():6.2f} "
          f"(band [{lo1:.2f}, {hi1:.2f}]); mean RMSE {rmse:.3f} m")
assert all(np.all(np.isfinite(r.nees_pose)) and np.all(np.isfinite(r.nees_yaw)) for rs in results.values() for r in rs)
# the lesson's claim: with OC on, the time-averaged pose NEES is that of a consistent filter (6), not 2x or 5x it
assert summary[True]["pose"].mean() < (2.0 if FAST else 1.5) * 6

# %%
fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
for oc, style in ((True, "C0-"), (False, "C3-")):
    axes[0].semilogy(t, summary[oc]["pose"], style, label=f"OC {'on' if oc else 'off'}")
    axes[1].semilogy(t, summary[oc]["yaw"], style, label=f"OC {'on' if oc else 'off'}")
for ax, (lo, hi), title in ((axes[0], (lo6, hi6), "average pose NEES (6 DoF)"),
                            (axes[1], (lo1, hi1), "average yaw NEES (1 DoF)")):
    ax.axhspan(lo, hi, color="0.8", label=f"95 % band, {n_runs} runs")
    ax.set(xlabel="t [s]", title=title)
    ax.legend(fontsize=8)
for oc, color in ((True, "C0"), (False, "C3")):
    for r in results[oc][:3]:
        axes[2].plot(r.t, np.sign(r.yaw_error) * np.sqrt(r.nees_yaw), color=color, lw=0.8)
axes[2].axhline(3, color="k", ls="--")
axes[2].axhline(-3, color="k", ls="--")
axes[2].set(xlabel="t [s]", ylabel="yaw error / σ_yaw", title="yaw error in units of its σ (blue: OC on)")
plt.tight_layout()
plt.show()

# %% [markdown]
# ## 5. Discussion
#
# Sections 2 and 3 are exact algebra: with the OC modifications the filter's linearised model has the same four
# unobservable directions as the true system, without them it does not. Section 4 is the empirical side. Read the
# printed numbers with their band: a mean NEES *above* the band means the filter is overconfident, below it
# means it is pessimistic.
#
# **What it took to reach the band** (`bench/msckf_monte_carlo.py`, 20 runs of 20 s, measured): the OC fix alone
# was not it. With S-MSCKF's settings (window 20, two states pruned at a time, a 95 % gate on the rows used) and a
# 0.1 m/s initial velocity std the average pose NEES was 177, and 37 even on a typical seed. Three things mattered, each measured on its own:
#
# * **The gate's bias** (notebook 11, section 7): 1-row residuals gated at 95 % under-correct by 24 %. Gating
#   each feature on its whole track and, for these outlier-free tracks, at 0.99: NEES 10.0 -> 7.35.
# * **Pruning a third of the window** (Mourikis & Roumeliotis 2007) instead of two keyframe-selected states, in a
#   window of 40: 7.46 vs 10.0 at window 20, and 0.12 % instead of 0.40 % of distance on 60 s of boxes_like.
# * **The start.** boxes_like begins slowly (0.2-0.4 m/s). A velocity error of 0.3-0.4 m/s — a 3-4 σ draw when
#   P0 says 0.1 m/s — makes the first window's relative poses so wrong that every triangulation fails and the
#   filter never locks on (2 of 20 seeds). The runs here start with 0.03 m/s; an iterated update or a static start
#   would be the cure.
#
# With those, OC on and OC off are *both* inside the band in these runs (7.35 vs 7.40; 60 s runs 7.03 vs 6.98;
# yaw NEES 0.97 vs 1.03). The spurious yaw information of the plain EKF is real (section 3 shows it exactly) but
# small here: an MSCKF uses each observation once, so the same feature is not re-linearised at ever-changing
# estimates as in EKF-SLAM, and with a 1 mrad initial attitude error the estimates barely move. Start with 3°
# (`python bench/msckf_monte_carlo.py --init-sigma-attitude 0.05`, 20 runs of 20 s, measured) and it shows: the
# plain EKF's yaw NEES is 7.16, far above the band [0.48, 1.71], and its yaw standard deviation *falls* from 2.87° to
# 1.62° although nothing can observe yaw; with OC it stays near 2.7° and the yaw NEES is 2.25. The OC-EKF pays for
# its first estimates, though: linearised that far from the truth, its roll/pitch and position become overconfident
# (pose NEES 44.9 vs 17.4) and one run of 20 diverges. First-estimate methods want small initial errors.
#
# **Which update-side constraint the library uses.** Eq. 86 changes every camera block by the smallest Frobenius-norm
# amount that gives $H_C u = 0$, mixing radian and metre columns. At 250 m depth (`aerial_like`) the position columns
# are only about $1/Z$, and the change alters them by 0.5-3.5 %: 4 of 10 aerial seeds diverged with it (measured).
# `Msckf` therefore constrains the feature's Jacobian *after* the nullspace projection instead,
# $H_o^* = H_o\,(I - N (N^\top N)^{-1} N^\top)$ with the observing cameras' first-estimate nullspace $N$ — the same
# property $H N = 0$ with one condition per direction and feature rather than two per camera
# (`Msckf(config, state, oc_update="projected")`, the default; `oc_update="eq86"` is the thesis's form).
#
# ## Summary
#
# * VIO has **four unobservable directions**: global translation (3) and yaw about gravity (1), Eq. 80.
# * The standard EKF evaluates $\Phi$ and $H$ at different estimates, so $\Phi N \ne N$ and $H N \ne 0$ for
#   the directions it carries: it **gains spurious yaw information**.
# * The **OC-EKF** keeps first estimates and minimally modifies $\Phi$ (Eqs. 81-84) and every camera block of
#   $H$ (Eqs. 85-86), restoring both properties exactly.
# * **NEES** over Monte-Carlo runs against $\chi^2$ bands is the test of consistency; yaw alone is the sharpest.
# * Consistency needed more than OC: an unbiased use of the gate, the oldest third pruned from a window of 40,
#   and a start the linearisation can survive. Then the pose NEES sits in the band (7.35, band [4.58, 7.61]).
#
# ## Exercises
#
# 1. Increase `duration` and `n_runs` (and try `preset="aerial_like"`): does the OC on/off yaw NEES gap open?
# 2. In section 2, scale the correction up and down: how does the first-interval mismatch of the standard EKF
#    scale?
# 3. Show that the OC modification of $H$ does not touch the translation directions (why does it suffice to
#    constrain only $u$, the yaw column?).
# 4. Rerun section 4 with S-MSCKF's settings, `msckf_overrides={"init_sigma_velocity": 0.03,
#    "marginalize_third": False, "max_camera_states": 20}` and `gate_probability=0.95`: which part of the pose NEES
#    grows — position or attitude (`nees_position`, `nees_attitude`)? Compare with `gating_mean_shrink(1, 0.95)`.
