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
# 3. measures consistency with the **NEES** over Monte-Carlo runs, OC on and off, first with the small initial
#    errors the filter normally starts with, then with a 3° attitude error, where the plain EKF visibly learns a yaw
#    it cannot see.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")
import time

import matplotlib.pyplot as plt
import numpy as np

from evio_lib.evaluation.plots_msckf import plot_consistency
from evio_lib.evaluation.trajectory_metrics import chi2_bounds
from evio_lib.geometry.rotation import quat_to_rot, rot_to_quat
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.experiment import run_vio_sim, run_vio_sim_seeds
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
# error state $[\delta\theta, \delta b_g, \delta v, \delta b_a, \delta p]$ span the nullspace of the observability
# matrix (Eq. 80), the directions along which no sequence of IMU samples and images can tell two errors apart:
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
print(f"max |Φ N_k - N_k+1|: standard EKF {mismatch_plain.max():.2e} (first interval {mismatch_plain[0]:.2e}, "
      f"later ones {mismatch_plain[1:].max():.1e}), "
      f"OC-EKF {mismatch_oc.max():.1e}")
assert mismatch_oc.max() < 1e-9
assert mismatch_plain[0] > 1e-3 and mismatch_plain[1:].max() < 1e-2 * mismatch_plain[0]  # the first carries it

# %% [markdown]
# The first interval, right after the correction, carries almost all of the standard EKF's mismatch; within an
# uninterrupted propagation the prediction is its own first estimate and only discretisation errors remain.
#
# ## 3. Update: $H N = 0$ only at one linearisation point
#
# A feature measurement depends on the camera poses and the feature, so the directions act on them too: a camera's
# (attitude, position) block gets $N_C = \begin{bmatrix} 0_3 & R_{G\to C}\, g \\ I_3 & -[p_C\times] g
# \end{bmatrix}$ and the feature $N_f = [I_3,\ -[p_F\times] g]$. The plain Jacobians (Eqs. 45-47) satisfy
# $H_x N + H_f N_f = 0$ at the *current* estimate — but the nullspace that propagation preserved is the one of the
# *first estimates*. The OC-EKF projects each camera's 2 x 6 block so that $H_C u_C = 0$ with
# $u_C = [R_{G\to C}\, g;\ [(p_F - p_C)\times] g]$ built from the camera's first estimates (the camera's and the
# feature's yaw columns combined), and rebuilds $H_f = -H_C[:, 3{:}6]$ (Eqs. 85-86):

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
# With the pose error $e_k = [\delta\theta_I; \delta p]$ and its reported covariance $P_k$ (6x6), the **normalised
# estimation error squared** $\epsilon_k = e_k^T P_k^{-1} e_k$ of a consistent filter is $\chi^2_6$-distributed: mean
# 6. Averaged over $n$ independent runs, $n\bar\epsilon_k \sim \chi^2_{6n}$, which gives a 95 % band (Bar-Shalom et
# al. 2001). The yaw alone has 1 DoF. `evio_lib.msckf.experiment.run_vio_sim` runs the perfect-data-association
# experiment (boxes_like, 60 tracks, 1 px, noisy IMU with unknown biases, the initial error drawn from $P_0$) and
# returns these NEES series; each seed is one Monte-Carlo run. The initial errors are small: 1 mrad of attitude and,
# instead of the library's 0.1 m/s, 0.03 m/s of velocity (`boxes_like` starts slowly, and a 3-4σ velocity draw at 0.1
# m/s can make every early triangulation fail; [docs/msckf_consistency.md](../docs/msckf_consistency.md) has the
# measurements). `run_vio_sim_seeds` runs one experiment per seed; in full mode it spreads them over worker processes
# (one per core, at most four, or `EVIO_JOBS`; fast mode's short runs go one after the other). Each run draws only
# from its own seed, so the numbers are the same either way.

# %%
n_runs = 3 if FAST else 8
jobs = 1 if FAST else None  # worker processes (None: one per core, at most 4); fast mode's runs are too short for them
duration = 3.0 if FAST else 10.0
start = {"init_sigma_velocity": 0.03}
results = {}
t0 = time.perf_counter()
for oc in (True, False):  # independent runs: the same numbers in worker processes as one by one
    results[oc] = run_vio_sim_seeds([100 + k for k in range(n_runs)], preset="boxes_like", duration=duration, oc=oc,
                                    baselines=False, msckf_overrides=start, jobs=jobs)
print(f"{2 * n_runs} runs of {duration:g} s in {time.perf_counter() - t0:.1f} s")
t = results[True][0].t
lo6, hi6 = chi2_bounds(6, n_runs)
lo1, hi1 = chi2_bounds(1, n_runs)
summary = {}
for oc, runs in results.items():
    summary[oc] = dict(pose=np.mean([r.nees_pose for r in runs], axis=0), yaw=np.mean([r.nees_yaw for r in runs], axis=0),
                       yaw_sigma_deg=np.degrees(np.mean([r.sigma_yaw for r in runs], axis=0)))
    pose, yaw = summary[oc]["pose"], summary[oc]["yaw"]
    rmse = summary[oc]["rmse"] = np.mean([r.metrics["rmse_m"] for r in runs])
    print(f"OC {'on ' if oc else 'off'}: mean pose NEES {pose.mean():6.2f} (band [{lo6:.2f}, {hi6:.2f}], "
          f"{100 * np.mean((pose >= lo6) & (pose <= hi6)):.0f} % of images inside); mean yaw NEES {yaw.mean():6.2f} "
          f"(band [{lo1:.2f}, {hi1:.2f}]); mean RMSE {rmse:.3f} m")
curves = {f"OC {'on' if oc else 'off'}": {k: c[k] for k in ("pose", "yaw", "yaw_sigma_deg")} for oc, c in summary.items()}
plot_consistency(t, curves, (lo6, hi6), (lo1, hi1), n_runs,
                 title="small initial errors (1 mrad attitude)")
plt.show()
assert all(np.all(np.isfinite(r.nees_pose)) and np.all(np.isfinite(r.nees_yaw)) for rs in results.values() for r in rs)
for oc in (True, False):  # both variants: time-averaged pose and yaw NEES inside this notebook's 95 % bands
    assert lo6 < summary[oc]["pose"].mean() < hi6 and lo1 < summary[oc]["yaw"].mean() < hi1
assert abs(summary[True]["pose"].mean() / summary[False]["pose"].mean() - 1) < 0.05  # and within 5 % of each other
assert summary[True]["rmse"] < 0.1  # centimetres

# %% [markdown]
# The time means above can hide stretches of images outside the band. Image by image:


# %%
def excursions(mask):
    """'k stretches, t0-t1 s' for the images where mask is True (a stretch: consecutive images)."""
    if not mask.any():
        return "none"
    n_stretches = int(np.sum(np.diff(np.r_[0, mask.astype(int)]) == 1))
    return f"{n_stretches} stretch{'es' if n_stretches > 1 else ''} within {t[mask].min():.2f}-{t[mask].max():.2f} s"


below, above, outside = {}, {}, {}
for oc in (True, False):  # image by image: what the time average hides
    pose = summary[oc]["pose"]
    below[oc], above[oc] = pose < lo6, pose > hi6
    outside[oc] = below[oc] | above[oc]
    print(f"OC {'on ' if oc else 'off'}: pose NEES inside the band on {100 * np.mean(~outside[oc]):.0f} % of the "
          f"images; below on {100 * np.mean(below[oc]):.0f} % ({excursions(below[oc])}), "
          f"above on {100 * np.mean(above[oc]):.0f} % ({excursions(above[oc])})")
both_out = np.mean(outside[True] & outside[False]) / np.mean(outside[True] | outside[False])
print(f"images outside for OC on or off: {100 * both_out:.0f} % of them are outside for both")
for oc in (True, False):  # about two thirds of the images inside, not the 95 % a consistent filter would give
    assert 0.55 < np.mean(~outside[oc]) < 0.8
assert both_out > 0.7  # the excursions are shared by OC on and off
if FAST:  # 3 runs of 3 s: excursions both ways, mostly below the band
    assert all(below[oc].mean() > above[oc].mean() > 0 for oc in (True, False))
else:  # 8 runs of 10 s: every excursion above the band, all within the first 6 s
    assert all(not below[oc].any() and above[oc].mean() > 0.25 and t[above[oc]].max() < 6.0 for oc in (True, False))

# %% [markdown]
# Averaged over time, both variants sit inside the band printed above, and they differ by a few per cent. Image by
# image they do not: a consistent filter would keep each image's average pose NEES inside its 95 % band on about 95 %
# of the images, and here only about two thirds are (the printed shares). In the 10 s runs of full mode every
# excursion lies *above* the band (overconfident) in stretches within the first 6 s, and the pose NEES stays inside
# after that; in the 3 runs of 3 s of fast mode they go both ways, mostly *below* the band (pessimistic). The time
# mean hides these stretches. Both variants leave the band on largely the same images (the printed share), so the
# excursions are not what the observability constraint is about; what causes them is not measured here (section 6
# lists what else the filter's consistency depends on), and the consecutive images of a run are correlated, which is
# why the excursions come in stretches rather than as scattered images.
#
# Is the OC-EKF pointless, then? No: the spurious yaw information of the plain EKF is real (section 3 shows it
# exactly) but it grows with the distance between the current estimate and the first estimate, and with a 1 mrad
# initial attitude error the estimates barely move. An MSCKF also uses each observation only once, so the same
# feature is not re-linearised at ever-changing estimates as in EKF-SLAM (which keeps the landmarks in its state and
# linearises their measurements again at every update).
#
# ## 5. A 3° attitude error: the plain EKF learns a yaw it cannot see
#
# Start the same experiment with an initial attitude standard deviation of 0.05 rad (about 3°) per axis. Roll and
# pitch become observable through gravity and their standard deviation shrinks quickly (the printed roll/pitch σ).
# Yaw cannot: an ideal filter, which takes no yaw information from anywhere, would keep its yaw standard deviation
# near 2.9° (the gyroscope's noise would even add a little); the OC-EKF keeps close to 90 % of it (printed below).
# Watch `sigma_yaw`, the filter's own yaw standard deviation.

# %%
n_runs_att, duration_att = (3, 3.0) if FAST else (8, 10.0)
big_start = {"init_sigma_velocity": 0.03, "init_sigma_attitude": 0.05}
t0 = time.perf_counter()
results_att = {oc: run_vio_sim_seeds([100 + k for k in range(n_runs_att)], preset="boxes_like", duration=duration_att,
                                     oc=oc, baselines=False, msckf_overrides=big_start, jobs=jobs)
               for oc in (True, False)}
print(f"{2 * n_runs_att} runs of {duration_att:g} s in {time.perf_counter() - t0:.1f} s")
lo6a, hi6a = chi2_bounds(6, n_runs_att)
lo1a, hi1a = chi2_bounds(1, n_runs_att)
summary_att, yaw_kept = {}, {}
for oc, runs in results_att.items():
    summary_att[oc] = dict(pose=np.mean([r.nees_pose for r in runs], axis=0),
                           yaw=np.mean([r.nees_yaw for r in runs], axis=0),
                           yaw_sigma_deg=np.degrees(np.mean([r.sigma_yaw for r in runs], axis=0)))
    yaw_kept[oc] = np.mean([r.sigma_yaw[-1] / r.sigma_yaw[0] for r in runs])  # σ_yaw at the end / at the start
    # roll/pitch: the attitude variance that is not yaw (the trace is rotation-invariant), per axis, in degrees
    tilt_deg = np.degrees(np.mean([np.sqrt(np.maximum((r.sigma[:, :3] ** 2).sum(axis=1) - r.sigma_yaw**2, 0.0) / 2)
                                   for r in runs], axis=0))
    summary_att[oc]["tilt_sigma_deg"] = tilt_deg
    sig = summary_att[oc]["yaw_sigma_deg"]
    tilt = summary_att[oc]["tilt_sigma_deg"]
    one_s = np.searchsorted(results_att[oc][0].t, results_att[oc][0].t[0] + 1.0)  # the image 1 s after the first
    summary_att[oc]["tilt_1s"] = tilt[one_s]
    print(f"OC {'on ' if oc else 'off'}: roll/pitch σ {tilt[0]:.2f}° -> {tilt[one_s]:.2f}° after 1 s -> "
          f"{tilt[-1]:.2f}° at the end")
    print(f"OC {'on ' if oc else 'off'}: yaw σ {sig[0]:.2f}° -> {sig[-1]:.2f}° (kept {100 * yaw_kept[oc]:.0f} %); "
          f"mean yaw NEES {summary_att[oc]['yaw'].mean():.2f} (band [{lo1a:.2f}, {hi1a:.2f}]); "
          f"mean pose NEES {summary_att[oc]['pose'].mean():.2f} (band [{lo6a:.2f}, {hi6a:.2f}])")
plot_consistency(results_att[True][0].t, {f"OC {'on' if oc else 'off'}": c for oc, c in summary_att.items()},
                 (lo6a, hi6a), (lo1a, hi1a), n_runs_att, title="3° initial attitude error")
plt.show()

# %% [markdown]
# Which part of the pose NEES is off, the attitude or the position? Each has 3 degrees of freedom, and its own band:

# %%
lo3a, hi3a = chi2_bounds(3, n_runs_att)
att_nees, pos_nees = {}, {}
for oc, runs in results_att.items():  # which part of the pose NEES: attitude (roll, pitch, yaw) or position?
    att_nees[oc] = np.mean([r.nees_attitude for r in runs])
    pos_nees[oc] = np.mean([r.nees_position for r in runs])
    print(f"OC {'on ' if oc else 'off'}: mean attitude NEES {att_nees[oc]:.2f}, mean position NEES {pos_nees[oc]:.2f} "
          f"(band of each [{lo3a:.2f}, {hi3a:.2f}])")
for oc in (True, False):
    tilt = summary_att[oc]["tilt_sigma_deg"]
    assert summary_att[oc]["tilt_1s"] < 0.4 * tilt[0] and tilt[-1] < 0.25 * tilt[0]  # roll/pitch: observable
assert 0.85 < yaw_kept[True] < 0.92  # the OC-EKF keeps most of its yaw uncertainty ("close to 90 %")
assert yaw_kept[False] < yaw_kept[True] - 0.1  # the plain EKF loses a good part of it
yaw_nees = {oc: c["yaw"].mean() for oc, c in summary_att.items()}
pose_nees = {oc: c["pose"].mean() for oc, c in summary_att.items()}
assert pose_nees[True] > pose_nees[False]  # the price of the first estimates
assert FAST or (yaw_nees[False] > 2 * hi1a and lo1a < yaw_nees[True] < hi1a and pose_nees[False] > hi6a)
assert not FAST or all(lo1a < yaw_nees[oc] < hi1a for oc in (True, False))  # 3 s: neither has left the yaw band
if FAST:  # 3 s: the OC-EKF's attitude and position NEES still inside their bands
    assert lo3a < att_nees[True] < hi3a and lo3a < pos_nees[True] < hi3a
else:  # 10 s: OC on: attitude far above (yaw inside: roll/pitch), position just above
    assert att_nees[True] > 2 * hi3a and hi3a < pos_nees[True] < 1.2 * hi3a and lo1a < yaw_nees[True] < hi1a

# %% [markdown]
# Now the difference is plain to see in the right-hand panel. The plain EKF's yaw standard deviation *falls* within
# seconds, although nothing in the measurements can observe yaw: that is the spurious information of sections 2
# and 3, and a filter that believes it knows its heading better than it does. The OC-EKF keeps most of its yaw
# uncertainty (close to 90 % in these runs, the printed "kept" share; why not all of it is not measured here). Over
# the 10 s runs of full mode the plain EKF's yaw error then outgrows its shrunken σ: its average yaw NEES lies well
# above the band (more than twice its upper end), while the OC-EKF's stays inside it (in the 3 s runs of fast mode
# both are still inside).
#
# The OC-EKF does worse elsewhere, though, with first estimates as far from the truth as a 3° error puts them: its
# pose NEES is higher than the plain EKF's, and in full mode both are above the band, the OC-EKF's most. The split
# printed last shows where: in full mode the OC-EKF's attitude NEES is more than twice the upper end of its band
# while its yaw NEES is inside, so roll and pitch are overconfident, and its position NEES is just above its band; in
# the 3 s runs of fast mode both parts are still inside. First-estimate methods want small initial errors.
# [docs/msckf_consistency.md](../docs/msckf_consistency.md) has the same experiment with 20 runs of 20 s.
#
# %% [markdown]
# ## 6. Discussion
#
# Sections 2 and 3 are exact algebra: with the OC modifications the filter's linearised model has the same four
# unobservable directions as the true system, without them it does not. Sections 4 and 5 are the empirical side. Read
# the printed numbers with their band: a mean NEES *above* the band means the filter is overconfident, below it means
# it is pessimistic.
#
# Consistency needs more than the OC-EKF. Three things in this library's filter matter as much, and you have met
# two of them: the gate's bias (notebook 11, section 7: the whole track is gated, and at 0.99 for these outlier-free
# tracks), pruning the oldest third of a window of 40 (notebook 11, section 9), and a start the linearisation
# survives (section 4). How each was measured, with 20 runs of 20 s, is told in
# [docs/msckf_consistency.md](../docs/msckf_consistency.md).
#
# **Which update-side constraint the library uses.** Eq. 86 changes every camera block by the smallest Frobenius-norm
# amount that gives $H_C u = 0$, mixing radian and metre columns. Far from the scene (`aerial_like`, 250 m) the
# position columns are only about $1/Z$, and the change alters them by 0.5-3.5 %, enough to make 4 of 10 `aerial_like`
# seeds diverge (measured in [docs/msckf_consistency.md](../docs/msckf_consistency.md), not in this notebook).
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
#   $H$ (Eqs. 85-86), restoring both properties exactly (the library's default update constrains the projected
#   Jacobian instead: section 6).
# * **NEES** over Monte-Carlo runs against $\chi^2$ bands is the test of consistency; yaw alone is the sharpest.
# * With small initial errors, OC on and off behave alike: their time-averaged NEES lies inside this notebook's band,
#   but only about two thirds of the images do, the rest in stretches outside it on largely the same images
#   (section 4). With a 3° attitude error the plain EKF's yaw standard deviation falls although yaw is unobservable;
#   the OC-EKF keeps most of it, and over 10 s pays with overconfident roll and pitch (section 5).
# * Consistency needs more than OC: an unbiased use of the gate, the oldest third pruned from a window of 40,
#   and a start the linearisation can survive.
#
# ## Exercises
#
# 1. Section 5 started the room's runs 3° off. Run the same experiment over the aerial terrain (`preset="aerial_like"`,
#    8 runs of 10 s for each variant: a few minutes), then again with section 4's small start. Does the OC-EKF keep
#    its yaw NEES inside the band, and its yaw σ, in both cases? What does the answer say about first-estimate methods?
#
#    *Hint:* `run_vio_sim_seeds([100 + k for k in range(8)], preset="aerial_like", duration=10.0, oc=oc,
#    baselines=False, msckf_overrides=big_start)` (then `start`); compare the mean yaw NEES with `chi2_bounds(1, 8)`
#    and the share of yaw σ kept, `sigma_yaw[-1] / sigma_yaw[0]`, as section 5 does.
# 2. In section 2, scale the correction up and down: how does the first-interval mismatch of the standard EKF
#    scale?
#
#    *Hint:* inject `scale * correction` for a few scales and divide the first-interval mismatch by the scale.
# 3. Show that the OC modification of $H$ does not touch the translation directions (why does it suffice to
#    constrain only $u$, the yaw column?).
#
#    *Hint:* the measurement depends on positions only through $p_F - p_{C_i}$; evaluate
#    `H_x @ N_first[:, :3] + H_f @ N_f[:, :3]` with the plain Jacobians.
# 4. Rerun section 4 with S-MSCKF's settings, `msckf_overrides={"init_sigma_velocity": 0.03,
#    "marginalize_third": False, "max_camera_states": 20}` and `gate_probability=0.95`: which part of the pose NEES
#    grows — position or attitude (`nees_position`, `nees_attitude`)? This library gates each feature on its whole
#    track whatever the pruning: compare `gating_mean_shrink(37, 0.95)` with S-MSCKF's 1-row gate,
#    `gating_mean_shrink(1, 0.95)` (`from evio_lib.msckf.update import gating_mean_shrink`).
#
#    *Hint:* pass `msckf_overrides=` and `gate_probability=0.95` to `run_vio_sim` and average `nees_position` and
#    `nees_attitude` over the runs.
#
# Solutions, with the code to run (checked by `tests/test_solutions.py`):
# [docs/solutions/12_observability_and_consistency.md](../docs/solutions/12_observability_and_consistency.md).
#
# ## What you have built so far, and what the thesis found
#
# In notebook 01 you started with a pinhole camera. Since then you have built, and checked against an
# independent truth at every step:
#
# * **geometry** (01-02): projection, distortion, the epipolar constraint and the essential matrix;
# * **events** (03-04): an event camera simulator, and frames made from its events: representations, classical
#   integration and a recurrent network that reconstructs intensity images;
# * **features** (05-08): classical detectors, a SuperPoint-style network trained from scratch on synthetic shapes
#   and homographic adaptation, and the benchmark that compares them (repeatability, homography correctness);
# * **the filter** (09-12): IMU kinematics and dead reckoning, the MSCKF's error state and covariance propagation,
#   triangulation and the nullspace-projected, gated update, and the observability constraint that keeps the
#   filter honest about what it cannot see.
#
# On simulated tracks with perfect data association the filter you built stays within centimetres of the truth (the
# RMSE printed in section 4) where the IMU alone drifts by metres within seconds (notebook 11, section 9).
#
# **What the thesis found** (§4.4-4.5, Table 6). On the *Boxes* recording (69.8 m travelled) the IMU alone drifted by
# kilometres without bias corrections (RMSE 5383 m) and 29 m with them; the MSCKF brought this to about 1 m RMSE on
# grayscale frames, with SIFT (1.11 m) and with the trained network (1.05 m) alike, and to under half a metre on event
# frames (0.437 m with SIFT, 0.457 m with the network; Table 6's "% error", the mean error over the distance, 0.447 %
# and 0.44 %): the event frames do not blur during the rapid motion of the recording's latter half (§4.5.1). On the
# *Camp Atterbury* flight (1076.82 m, sparse terrain seen from a fixed-wing UAV) it was the other way round:
# grayscale frames gave 8.96-20.01 m RMSE, event frames 22.77-34.12 m, because the sparse scene
# without rapid motion produced a low event rate and noisy event frames (§4.5.2, Chapter V). The thesis concludes
# (Chapter V) that the trained networks offered no significant advantage over SIFT inside the filter, although they
# repeated detections and estimated homographies best under illumination changes (HPatches illumination, Tables 2
# and 4; notebook 08): good benchmark numbers are not the same as good tracks.
#
# **Next: notebook 13** joins the two halves into the full pipeline: APS frames or frames reconstructed from events,
# feature tracks from the front end, tracks into this MSCKF, on a recording, with the metrics of the thesis's
# Table 6.
