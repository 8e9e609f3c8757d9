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
# # 14 — The complete EVIO pipeline on APS frames
#
# Every piece of the course now exists on its own: frames from APS or from events (lesson 04), feature detectors
# (05-08), the Kalman filter and the MSCKF with its update and its consistency fixes (10-13). This lesson joins them
# into the pipeline of the thesis this course follows (Friedel 2020, "Event-based visual-inertial odometry using
# smart features", Chapter IV §4.5) and runs it on the camera's ordinary frames, the **APS frames** (the DAVIS's
# Active Pixel Sensor images, exposed like any camera's):
#
# 1. the **front-end** on real EuRoC and DAVIS frames and on simulated frames: tracks drawn, RANSAC's rejections
#    shown and checked against the true geometry; the two-point model and pyramidal Lucas-Kanade built from scratch;
# 2. the **whole pipeline** on the APS frames of the simulated `boxes_like` room (and the `aerial_like` flight):
#    SIFT, KLT (features followed by optical flow, built in section 1d) and IMU only, with the thesis's error
#    figures (3σ bounds, biases, trajectory, tracking statistics); then a real still start (EuRoC) with a static
#    initialisation and zero-velocity updates;
# 3. the **Table 6 analogue** of the thesis (its table of MSCKF results) for the rows without events.
#
# Lesson 15 feeds the same pipeline frames made from events and asks when they beat the APS frames.
#
# The code lives in `evio_lib.frontend` (the tracker) and `evio_lib.pipeline` (`load_dataset`, `PipelineConfig`,
# `run_pipeline`, `run_table`); the same runs are one command away: `python -m evio_lib run` and
# `python -m evio_lib table`. Every number below is from one run of one seed, on simulated data unless the cell loads
# a real recording, and unless a table says otherwise.

# %%
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")  # small images and matrices: one thread each is the fastest
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np
import torch
from IPython.display import Markdown, display

import evio_lib
from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_pipeline import (
    plot_bias_estimates,
    plot_error_comparison,
    plot_state_errors,
    plot_tracking_statistics,
    plot_tracks,
    plot_trajectory_topdown,
)
from evio_lib.features import create_detector
from evio_lib.frontend import camera_rotation_priors, create_tracker, match_mutual_ratio, stats_table
from evio_lib.frontend.two_point_ransac import two_point_ransac
from evio_lib.geometry.rotation import so3_log
from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline, run_pipelines
from evio_lib.pipeline.dataset import PRESET_DURATIONS
from evio_lib.pipeline.run import msckf_config_for

cv2.setNumThreads(1)
torch.set_num_threads(1)
FAST = fast_mode()
D_APS = 5.0 if FAST else 20.0  # seconds of each preset for the APS-frame runs
TABLE_DURATION, TABLE_SEEDS = (3.0, (0,)) if FAST else (6.0, (0, 1))
JOBS = 1 if FAST else None  # worker processes for the side-by-side runs (None: one per core)
EUROC = Path(evio_lib.__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "euroc_V1_01_easy_micro"
HAVE_EUROC = (EUROC / "mav0").is_dir()  # real data is optional: its cells skip without it
print(f"APS runs over the first {D_APS:g} s of each preset; EuRoC slice found: {HAVE_EUROC}")

# %% [markdown]
# The pipeline as a data flow. Follow the arrows: APS frames are used as they are, events become frames through
# windows and a reconstruction (lesson 04; this lesson runs the APS branch, lesson 15 the event branch); the IMU feeds
# the filter and, dashed, gives the tracker its rotation prior; the ground truth scores the trajectory (it also gives
# a moving start its initial state, section 2, not drawn). The number in brackets is the lesson that teaches each box.

# %%
from evio_lib.evaluation.plots_schematics import plot_pipeline_schematic

fig = plot_pipeline_schematic()
plt.show()

# %% [markdown]
# ## 1. The front-end
#
# The tracker, `evio_lib.frontend`. The thesis's front-end (§3.3.5, "Image Processing Front-End") is one paragraph:
# SIFT or the CNN, at most N features per image spread over a 4 x 5 grid, and two-point RANSAC against outliers; how
# features are matched from frame to frame it does not say. Here:
#
# - **detect** features in each frame (SIFT by default, any detector of `evio_lib.features` by name) and undistort
#   them with the calibration (§3.3.5; the undistortion is §4.5's);
# - **match** each tracked feature to the detections near where the gyroscope says it went (the camera's rotation
#   between the frames, integrated from the IMU), mutual nearest neighbours of the descriptors. This gyro-guided
#   matching is this project's choice (msckf_vio predicts its KLT features, tracked by optical flow as in section
#   1d, the same way), not the thesis's;
# - reject outliers with **two-point RANSAC** (the thesis cites its reference [73]; the library follows Troiani et
#   al. 2014 and msckf_vio): once the gyro has removed the rotation, a correct match $f_1 \to f_2$ only constrains
#   the translation direction $t$ through the epipolar constraint $f_2^T [t]_\times R f_1 = 0$, so two matches fix a
#   hypothesis (section 1c builds it);
# - keep the features spread: a 4 x 5 grid with at most N/20 features per cell (§3.3.5; N = 60, §4.5), new
#   detections only where a cell has room.
#
# `PipelineConfig().frontend_config()` is the front-end the pipeline runs; the same object drives the tracker here.
#
# ### 1a. Real frames: EuRoC V1_01_easy
#
# A slice of the EuRoC MAV recording (752 x 480 grayscale at 20 Hz, real IMU), read with
# `evio_lib.io.euroc.read_euroc`, when the course's shared data folder is present.

# %%
frontend_config = PipelineConfig().frontend_config()
print(f"front-end: {frontend_config.method} tracker, detector {frontend_config.detector}, at most "
      f"{frontend_config.max_features} features on a {frontend_config.grid_rows} x {frontend_config.grid_cols} grid, "
      f"two-point RANSAC threshold {frontend_config.ransac_threshold_px:g} px")
assert (frontend_config.max_features, frontend_config.grid_rows, frontend_config.grid_cols) == (60, 4, 5)
assert frontend_config.ransac_threshold_px == 1.5
if HAVE_EUROC:
    from evio_lib.io.euroc import read_euroc

    euroc = read_euroc(EUROC)
    k = slice(40, 48)  # eight consecutive frames
    euroc_images, euroc_times = euroc.frames[k], euroc.frame_times[k]
    rotations = camera_rotation_priors(euroc.imu.t, euroc.imu.gyro, euroc_times, euroc.R_CtoI)
    assert euroc_images[0].shape == (480, 752) and abs(np.median(np.diff(euroc.frame_times)) - 0.05) < 1e-3  # 20 Hz
    euroc_tracks = create_tracker(euroc.camera, frontend_config).track(euroc_images, euroc_times, rotations)
    euroc_stats = stats_table(euroc_tracks)
    plot_tracks(euroc_images[-1], euroc_tracks, title=f"EuRoC V1_01_easy: tracks over {len(euroc_images)} frames "
                f"({euroc_times[-1] - euroc_times[0]:.2f} s)")
    plt.show()
    first, final = euroc_tracks[0], euroc_tracks[-1]
    kept = np.isin(final.ids, first.ids)  # tracks alive from the first frame to the last
    drift_px = np.linalg.norm(final.pixels[kept] - first.pixels[np.searchsorted(first.ids, final.ids[kept])], axis=1)
    print(f"{len(euroc.frames)} frames of {euroc_images.shape[2]} x {euroc_images.shape[1]} px in the slice, "
          f"{1 / np.median(np.diff(euroc.frame_times)):.0f} Hz; tracked per frame (after the first): "
          f"{euroc_stats['tracked'][1:].mean():.1f} of {euroc_stats['total'][1:].mean():.1f}; "
          f"{kept.sum()} tracks span all 8 frames, median motion {np.median(drift_px):.2f} px; "
          f"RANSAC degenerate in {euroc_stats['ransac_degenerate'][1:].sum()} of {len(euroc_tracks) - 1} frame pairs")
    assert euroc_stats["tracked"][1:].mean() > 40
    assert kept.sum() > 0.5 * len(final) and np.median(drift_px) < 2.0
    assert euroc_stats["ransac_degenerate"][1:].sum() >= 5
    display(Markdown(
        f"At the start of V1_01_easy the drone still sits on the floor: {kept.sum()} of the {len(final)} features of "
        f"the last frame were tracked through all eight frames, and they moved a median {np.median(drift_px):.2f} px. "
        f"With no translation there is no epipolar geometry to test, and two-point RANSAC says so: in "
        f"{euroc_stats['ransac_degenerate'][1:].sum()} of the {len(euroc_tracks) - 1} frame pairs it finds the "
        f"translation **unobservable** "
        f"(degenerate) and falls back to checking each match's displacement after the gyro's rotation is removed. "
        f"This is the situation of a filter's static start; parallax, and with it depth, only comes once the camera "
        f"moves."))
else:
    print(f"EuRoC slice not found at {EUROC}: skipping the real-frame part (section 1b runs the front-end on "
          f"simulated frames)")

# %% [markdown]
# **Real DAVIS240C frames: ECD `slider_depth`.** The same sensor as the simulated one (240 x 180), on a linear
# slider: the camera translates without rotating, so the tracker runs without a gyro prior (the slice has no IMU).
# `read_ecd_frames` reads the frames and calibration of an ECD folder without its events.

# %%
SLIDER = EUROC.parent / "ecd_slider_depth_slice"
if (SLIDER / "images.txt").is_file():
    from evio_lib.io.ecd import read_ecd_frames

    slider = read_ecd_frames(SLIDER)
    k = slice(40, 48)
    slider_tracks = create_tracker(slider.camera, frontend_config).track(slider.frames[k], slider.frame_times[k])
    slider_stats = stats_table(slider_tracks)
    plot_tracks(slider.frames[k][-1], slider_tracks, title="ECD slider_depth (real APS frames): tracks over 8 frames")
    plt.show()
    first, final = slider_tracks[0], slider_tracks[-1]
    kept = np.isin(final.ids, first.ids)
    slide_px = np.linalg.norm(final.pixels[kept] - first.pixels[np.searchsorted(first.ids, final.ids[kept])], axis=1)
    slider_ratio = slider_stats["tracked"][1:].mean() / slider_stats["total"][1:].mean()
    print(f"{slider.frames.shape[2]} x {slider.frames.shape[1]} px frames; "
          f"tracked per frame {slider_stats['tracked'][1:].mean():.1f} of {slider_stats['total'][1:].mean():.1f} "
          f"({100 * slider_ratio:.0f} %); {kept.sum()} tracks span all 8 frames, median motion "
          f"{np.median(slide_px):.1f} px")
    assert slider.frames.shape[1:] == (180, 240) and slider_ratio > 0.6 and np.median(slide_px) > 5
    display(Markdown(
        f"On real DAVIS frames SIFT continues {100 * slider_ratio:.0f} % of its features from one frame to the next "
        f"while the scene slides by {np.median(slide_px):.1f} px (median over the eight frames); keep this share in "
        f"mind for the simulated room below."))
else:
    slider_ratio = None
    print(f"ECD slider_depth slice not found at {SLIDER}: skipped")

# %% [markdown]
# ### 1b. Simulated frames: the `boxes_like` room
#
# The course's simulated DAVIS240C in a textured room, hand-held motion that starts gently and ends violently (its
# size, length and the frames' spacing are printed below). `load_dataset` simulates the first `D_APS` seconds of it.
# The tracker runs over eight frames from t = 3 s:

# %%
data = load_dataset("boxes_like", duration=D_APS)
seq = data.sequence
print(data.sequence.name, f"{len(seq.frame_times)} APS frames over {seq.frame_times[-1]:.1f} s "
      f"({1 / np.median(np.diff(seq.frame_times)):.0f} Hz), IMU at {1 / np.median(np.diff(seq.imu.t)):.0f} Hz;",
      *data.notes, sep="\n  ")
k = slice(72, 80)
box_images, box_times = seq.frames[k], seq.frame_times[k]
box_rotations = camera_rotation_priors(seq.imu.t, seq.imu.gyro, box_times, seq.R_CtoI)
box_tracks = create_tracker(seq.camera, frontend_config).track(box_images, box_times, box_rotations)
box_stats = stats_table(box_tracks)
frame_gap_ms = 1e3 * float(np.median(np.diff(box_times)))  # the frames' spacing
plot_tracks(box_images[-1], box_tracks,
            title=f"boxes_like (APS frames): tracks over {len(box_images)} frames from t = {box_times[0]:.1f} s")
plt.show()
print(f"{seq.camera.width} x {seq.camera.height} px; the preset's motion lasts {PRESET_DURATIONS['boxes_like']:g} s; "
      f"these frames start at t = {box_times[0]:.2f} s, {frame_gap_ms:.1f} ms apart")
print(f"per frame after the first: {box_stats['detected'][1:].mean():.0f} detections, "
      f"{box_stats['tracked'][1:].mean():.1f} tracked, {box_stats['new'][1:].mean():.1f} new, "
      f"{box_stats['rejected_ransac'][1:].mean():.1f} rejected by RANSAC")
assert (seq.camera.width, seq.camera.height) == (240, 180) and abs(box_times[0] - 3.0) < 0.05
assert np.all(np.abs(np.diff(box_times) - 0.04) < 0.005)  # frames about 40 ms apart
assert box_stats["total"][1:].min() >= 50  # the grid is refilled to about N = 60 features
assert 0.2 < box_stats["tracked"][1:].mean() / box_stats["total"][1:].mean() < 0.9
assert 0 < box_stats["rejected_ransac"][1:].mean() < box_stats["tracked"][1:].mean() / 3
assert PipelineConfig().match_ratio is None and frontend_config.ratio is None  # no ratio test in the pipeline
display(Markdown(
    f"The grid refills every frame to {box_stats['total'][1:].min()}-{box_stats['total'][1:].max()} features "
    f"(N = {frontend_config.max_features}), but only {box_stats['tracked'][1:].mean():.1f} of them on average "
    f"continue from the previous frame; the rest are new detections filling cells that lost theirs. In this "
    f"repetitive, low-resolution room many SIFT descriptors have a near twin: the pipeline matches without Lowe's "
    f"ratio test (which keeps a match only when its descriptor distance is below, say, 0.8 times that of the "
    f"second-best candidate; `PipelineConfig.match_ratio` says why it is off), and two-point RANSAC then rejects the "
    f"candidate matches that do not fit the gyro's rotation and one translation: "
    f"{box_stats['rejected_ransac'][1:].mean():.1f} per frame here. Every track that ends is a loss: the MSCKF uses "
    f"a track only once it has at least three observations (`min_track_length` of the filter's `MsckfConfig`, "
    f"lesson 12; asserted in section 2), and gains most from long tracks."))

# %% [markdown]
# **Two-point RANSAC by hand.** Match *every* SIFT detection of the last two frames (no search window, only Lowe's
# ratio test at 0.8, so some wrong matches get through) and let two-point RANSAC, given the gyro's rotation, decide.
# The simulator knows the true relative pose, so each decision can be checked against the true epipolar geometry
# $E = [t]_\times R$: the Sampson distance of a match, in pixels,
# $d = \frac{|f_2^T E f_1|}{\sqrt{(Ef_1)_1^2 + (Ef_1)_2^2 + (E^Tf_2)_1^2 + (E^Tf_2)_2^2}}\, f$.

# %%
sift = create_detector("sift")
prev, curr = sift.detect_and_describe(box_images[-2]), sift.detect_and_describe(box_images[-1])
pairs = match_mutual_ratio(prev.descriptors, curr.descriptors, ratio=0.8)  # (M, 2) indices [prev, curr]
f1 = seq.camera.unproject(prev.keypoints[pairs[:, 0]].astype(float))  # undistorted normalised (x, y)
f2 = seq.camera.unproject(curr.keypoints[pairs[:, 1]].astype(float))
ransac = two_point_ransac(f1, f2, box_rotations[-1], focal_px=seq.camera.fx, rng=0)

# the true relative pose from the ground truth (camera poses): R = R_C2toG^T R_C1toG, t = R_C2toG^T (p_C1 - p_C2)
pose1, pose2 = seq.groundtruth.interpolate(box_times[-2:-1]), seq.groundtruth.interpolate(box_times[-1:])
R_true = pose2.R_BtoG[0].T @ pose1.R_BtoG[0]
t_true = pose2.R_BtoG[0].T @ (pose1.p_BinG[0] - pose2.p_BinG[0])
f1h, f2h = np.c_[f1, np.ones(len(f1))], np.c_[f2, np.ones(len(f2))]
Ef1 = np.cross(t_true, f1h @ R_true.T)  # E f1 = t x (R f1)
Etf2 = -np.cross(t_true, f2h) @ R_true  # E^T f2 = R^T [t]x^T f2 = -R^T (t x f2)
sampson_px = np.abs(np.sum(f2h * Ef1, axis=1)) / np.sqrt(Ef1[:, 0] ** 2 + Ef1[:, 1] ** 2 + Etf2[:, 0] ** 2
                                                        + Etf2[:, 1] ** 2) * seq.camera.fx
inlier_px = np.median(sampson_px[ransac.inliers])
kept_ok = np.mean(sampson_px[ransac.inliers] < 1.5)  # 1.5 px: RANSAC's own inlier threshold
rejected_off = np.mean(sampson_px[~ransac.inliers] > 1.5)
print(f"{len(prev)} and {len(curr)} detections, {len(pairs)} matches; RANSAC keeps {ransac.inliers.sum()}, rejects "
      f"{ransac.num_rejected} (degenerate: {ransac.degenerate}); the camera moved "
      f"{100 * np.linalg.norm(t_true):.1f} cm")
print(f"distance to the TRUE epipolar geometry: kept matches median {inlier_px:.2f} px, {100 * kept_ok:.0f} % under "
      f"1.5 px; rejected matches: {100 * rejected_off:.0f} % over 1.5 px, "
      f"median {np.median(sampson_px[~ransac.inliers]):.1f} px")
pixel_pairs = np.stack([prev.keypoints[pairs[:, 0]], curr.keypoints[pairs[:, 1]]], axis=1).astype(float)
plot_tracks(box_images[-1], {i: pixel_pairs[i] for i in np.flatnonzero(ransac.inliers)},
            rejected=pixel_pairs[~ransac.inliers], track_label="kept by RANSAC",
            title="one frame pair: matches kept (green) and rejected (red)")
plt.show()
print(f"median displacement of the kept matches after the rotation is removed: "
      f"{np.median(ransac.residuals_px[ransac.inliers]):.2f} px")
assert ransac.num_rejected >= 3
assert inlier_px < 0.5 and kept_ok > 0.9 and rejected_off > 0.7
assert 0.002 < np.linalg.norm(t_true) < 0.03
assert ransac.degenerate and np.median(ransac.residuals_px[ransac.inliers]) < 3 * 1.5
display(Markdown(
    f"RANSAC never saw the true pose, only the gyro's rotation and the matches, yet {100 * kept_ok:.0f} % of the "
    f"matches it keeps agree with the true geometry to better than its 1.5 px threshold (median {inlier_px:.2f} px), "
    f"while {100 * rejected_off:.0f} % of those it rejects are off by more: wrong correspondences between "
    f"similar-looking places of the room. (The red segments join each rejected candidate to the feature it claimed "
    f"to continue.) But between two frames {frame_gap_ms:.0f} ms apart the camera moved only "
    f"{100 * np.linalg.norm(t_true):.1f} cm, "
    f"and RANSAC called the translation unobservable (`degenerate: True`): it classified the matches by their "
    f"displacement after the rotation was removed, and never used its two-point model."))

# %% [markdown]
# ### 1c. The two-point model, with translation
#
# To see the model at work, take two frames ten apart (frames 60 and 70, their times printed below), where the
# camera moved several centimetres. With the rotation $R = R_{C_1\to C_2}$ known from the gyroscope, rotate each
# previous bearing into the current camera, $g_1 = R f_1$ (scaled so that its third entry is 1). What is left
# between $g_1$ and $f_2$ is a pure translation, and the epipolar constraint becomes **linear in t**:
#
# $$ f_2^T [t]_\times g_1 = t \cdot (g_1 \times f_2) = c^T t = 0, \qquad c = g_1 \times f_2 . $$
#
# Each match gives one such plane through the origin; $t$ has no observable scale, so two matches fix it:
# $t \propto c_1 \times c_2$. RANSAC draws pairs, scores each hypothesis by the distance of every $f_2$ to its
# epipolar line $l = t \times g_1$ (in pixels), keeps the best-supported one and refits $t$ on its inliers by least
# squares ($\min |C t|$ with $|t| = 1$: the last right singular vector of the stacked $c^T$). The gyro's rotation
# here is corrected by the simulator's true gyro bias (the filter learns it within seconds, section 2): left in, the
# bias alone would turn the view between the two frames by the angle printed below, several pixels.

# %%
i, j = 60, 70  # ten frames apart
t_i, t_j = seq.frame_times[i], seq.frame_times[j]
b_g_true = seq.groundtruth_imu.interpolate(seq.imu.t).bias_gyro
R_gyro = camera_rotation_priors(seq.imu.t, seq.imu.gyro - b_g_true, [t_i, t_j], seq.R_CtoI)[1]  # R_C1toC2
first, second = sift.detect_and_describe(seq.frames[i]), sift.detect_and_describe(seq.frames[j])
pairs_ij = match_mutual_ratio(first.descriptors, second.descriptors, ratio=0.8)
x1 = seq.camera.unproject(first.keypoints[pairs_ij[:, 0]].astype(float))
x2 = seq.camera.unproject(second.keypoints[pairs_ij[:, 1]].astype(float))
f2 = np.c_[x2, np.ones(len(x2))]
g1 = np.c_[x1, np.ones(len(x1))] @ R_gyro.T
g1 /= g1[:, 2:]  # g1 = R f1, the rotation removed
c = np.cross(g1, f2)  # one linear constraint c_k . t = 0 per match
bias_turn = np.linalg.norm(b_g_true[np.searchsorted(seq.imu.t, t_i)]) * (t_j - t_i)  # rad, the bias over the gap
print(f"frames {i} and {j}: t = {t_i:.2f} s and {t_j:.2f} s, {t_j - t_i:.2f} s apart; the true gyro bias, "
      f"{np.linalg.norm(b_g_true[np.searchsorted(seq.imu.t, t_i)]):.3f} rad/s, would turn the view by "
      f"{np.degrees(bias_turn):.1f} deg, {bias_turn * seq.camera.fx:.1f} px at the image centre")


def epipolar_distance_px(t):
    """Distance of each f2 to its epipolar line l = t x g1, in pixels."""
    lines = np.cross(t, g1)
    return np.abs(np.sum(f2 * lines, axis=1)) / np.linalg.norm(lines[:, :2], axis=1) * seq.camera.fx


rng = np.random.default_rng(0)
our_inliers = np.zeros(len(c), dtype=bool)
for _ in range(200):
    p, q = rng.choice(len(c), size=2, replace=False)
    t_pair = np.cross(c[p], c[q])  # orthogonal to both constraints: the hypothesis of two matches
    assert abs(c[p] @ t_pair) < 1e-12 and abs(c[q] @ t_pair) < 1e-12
    inliers = epipolar_distance_px(t_pair / np.linalg.norm(t_pair)) < 1.5
    our_inliers = inliers if inliers.sum() > our_inliers.sum() else our_inliers
t_ours = np.linalg.svd(c[our_inliers])[2][-1]  # least squares on the inliers: min |C t|, |t| = 1

# %% [markdown]
# The from-scratch direction against the truth (from the simulator's poses) and against `two_point_ransac`:

# %%
pose_i, pose_j = seq.groundtruth.interpolate([t_i]), seq.groundtruth.interpolate([t_j])
t_true_ij = pose_j.R_BtoG[0].T @ (pose_i.p_BinG[0] - pose_j.p_BinG[0])  # p_C1inC2, from the ground truth
library = two_point_ransac(x1, x2, R_gyro, focal_px=seq.camera.fx, rng=0)


def angle_deg(a, b):
    """Angle between two directions, sign ignored (t has neither scale nor sign)."""
    return np.degrees(np.arccos(min(1.0, abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b))))


print(f"{len(pairs_ij)} matches; the camera moved {100 * np.linalg.norm(t_true_ij):.1f} cm\n"
      f"from scratch: {our_inliers.sum()} inliers, t {angle_deg(t_ours, t_true_ij):.1f} deg from the true direction\n"
      f"library: {library.inliers.sum()} inliers (degenerate: {library.degenerate}), t "
      f"{angle_deg(library.t_dir, t_true_ij):.1f} deg from the truth, {angle_deg(library.t_dir, t_ours):.1f} deg from "
      f"ours; the same decision on {100 * np.mean(our_inliers == library.inliers):.0f} % of the matches")
sideways_deg = 90 - angle_deg(t_true_ij, np.array([0.0, 0.0, 1.0]))  # the true translation's angle to the image plane
print(f"the true translation is {sideways_deg:.0f} deg out of the image plane (0: purely sideways)")
to_pixels = lambda xy: seq.camera.project(np.c_[xy, np.ones(len(xy))])  # noqa: E731  normalised -> pixels
derotated = np.stack([to_pixels(g1[:, :2]), to_pixels(x2)], axis=1)
plot_tracks(seq.frames[j], {k: derotated[k] for k in np.flatnonzero(library.inliers)},
            rejected=derotated[~library.inliers], track_label="inliers, rotation removed",
            title=f"frames {t_j - t_i:.2f} s apart: motion left after removing the gyro's rotation")
plt.show()
assert not library.degenerate and np.linalg.norm(t_true_ij) > 0.05
assert angle_deg(library.t_dir, t_true_ij) < 5 and angle_deg(t_ours, t_true_ij) < 5
assert angle_deg(library.t_dir, t_ours) < 1 and np.mean(our_inliers == library.inliers) > 0.9
display(Markdown(
    f"Two matches per hypothesis and 200 draws: from the matches and the gyro alone, the from-scratch RANSAC found a "
    f"translation direction {angle_deg(t_ours, t_true_ij):.1f}° from the true one and `two_point_ransac` one "
    f"{angle_deg(library.t_dir, t_true_ij):.1f}° from it; the two agree to {angle_deg(library.t_dir, t_ours):.2f}° "
    f"and on {100 * np.mean(our_inliers == library.inliers):.0f} % of the decisions. (The library scores with the "
    f"Sampson distance, which also counts the error of $f_1$, and ranks hypotheses by MSAC's truncated cost "
    f"$\\sum_k \\min(d_k, 1.5\\,\\text{{px}})^2$, Torr & Zisserman 2000, instead of the inlier count.) In the "
    f"figure, each green segment joins a previous feature, its rotation removed, to its match: what remains is the "
    f"translation's parallax, segments along lines through the epipole (here far outside the image, since the "
    f"camera moved mostly sideways: {sideways_deg:.0f}° out of the image plane), longer for nearer points. In the "
    f"consecutive pair of section 1b the kept "
    f"matches moved a median {np.median(ransac.residuals_px[ransac.inliers]):.2f} px after the rotation was removed, "
    f"under the {3 * frontend_config.ransac_threshold_px:g} px below which `two_point_ransac` does not trust a "
    f"segment's direction (3 times its threshold: an end point off by the threshold then turns the segment by "
    f"1/3 rad, {np.degrees(1 / 3):.0f}°, or more); too few "
    f"longer ones agreed, hence the degenerate case there."))

# %% [markdown]
# ### 1d. Optical flow: pyramidal Lucas-Kanade
#
# The other front-end of section 2, KLT (what msckf_vio and OpenVINS run), does not detect again in each frame: it
# **follows** a patch. Brightness constancy says a point keeps its intensity as it moves by $d$:
# $I_1(x + d) = I_0(x)$. Linearised around the current guess, $I_1(x + d + \Delta) \approx I_1(x + d) +
# \nabla I^T \Delta$, and summed in the least-squares sense over a window $W$ (15 x 15 px here), the step $\Delta$
# solves the 2 x 2 **normal equations**
#
# $$ \underbrace{\sum_{x \in W} \begin{bmatrix} I_x^2 & I_x I_y \\ I_x I_y & I_y^2 \end{bmatrix}}_{G\ \text{(structure
# tensor)}} \Delta = \sum_{x \in W} \nabla I \, \big(I_0(x) - I_1(x + d)\big), $$
#
# iterated ($d \leftarrow d + \Delta$) until the step is below 0.01 px. $G$ must be well conditioned: both of its
# eigenvalues large, a corner (Shi-Tomasi's criterion); on an edge one eigenvalue is near zero and the flow along the
# edge is unknown (the aperture problem). The linearisation only holds within a pixel or two of the answer, so
# motions larger than the window need a **pyramid**: solve on images halved 3 times, and carry $2d$ down to the next
# finer level as its starting guess. From scratch, on one corner of the room, against OpenCV's
# `cv2.calcOpticalFlowPyrLK` with the library's settings (`evio_lib.frontend.klt`):

# %%
from scipy.ndimage import map_coordinates


def sample(image, xy):
    """Bilinear interpolation of image at (K, 2) positions (x, y)."""
    return map_coordinates(image, [xy[:, 1], xy[:, 0]], order=1, mode="nearest")


def lucas_kanade(I0, I1, point, d, half=7, iterations=30, epsilon=0.01):
    """One level: the displacement d (2,) of the window around point from I0 to I1, and its structure tensor."""
    dy, dx = np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1), indexing="ij")
    window = point + np.c_[dx.ravel(), dy.ravel()]
    grad_y, grad_x = np.gradient(I0)
    Ix, Iy, template = sample(grad_x, window), sample(grad_y, window), sample(I0, window)
    G = np.array([[Ix @ Ix, Ix @ Iy], [Ix @ Iy, Iy @ Iy]])  # the structure tensor
    for _ in range(iterations):
        residual = template - sample(I1, window + d)  # I0(x) - I1(x + d)
        step = np.linalg.solve(G, [Ix @ residual, Iy @ residual])  # G Δ = Σ ∇I (I0(x) - I1(x + d))
        d = d + step
        if np.linalg.norm(step) < epsilon:
            break
    return d, G


def pyramidal_lucas_kanade(I0, I1, point, levels=3):
    """Coarse to fine: each level starts from twice the displacement found on the level above."""
    pyramid = [(I0, I1)]
    for _ in range(levels):
        pyramid.append(tuple(cv2.pyrDown(image) for image in pyramid[-1]))
    d = np.zeros(2)
    for level in range(levels, -1, -1):
        d, _ = lucas_kanade(*pyramid[level], point / 2 ** level, d)
        d = 2 * d if level else d
    return d


# %% [markdown]
# One corner of the room, at least 40 px from the border, followed to the next frame and to the fourth frame on,
# with one level and with the pyramid, against OpenCV:

# %%
frame0 = seq.frames[72]
corners = cv2.goodFeaturesToTrack(frame0, maxCorners=50, qualityLevel=0.01, minDistance=10)[:, 0]
corner = corners[np.all((corners > 40) & (corners < [200, 140]), axis=1)][0].astype(float)  # 40 px from the border
criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, frontend_config.klt_max_iterations,
            frontend_config.klt_epsilon)
flow = {}
for k in (73, 76):  # the next frame, and 4 frames on
    single, G = lucas_kanade(frame0.astype(float), seq.frames[k].astype(float), corner, np.zeros(2))
    pyramid = pyramidal_lucas_kanade(frame0.astype(float), seq.frames[k].astype(float), corner,
                                     levels=frontend_config.klt_levels)
    opencv = {levels: cv2.calcOpticalFlowPyrLK(frame0, seq.frames[k], corner.astype(np.float32).reshape(1, 1, 2), None,
                                               winSize=(frontend_config.klt_window,) * 2, maxLevel=levels,
                                               criteria=criteria)[0].reshape(2) - corner
              for levels in (0, frontend_config.klt_levels)}
    flow[k] = single, pyramid, opencv
    print(f"frame {k}: one level {single.round(2)} px (OpenCV one level {opencv[0].round(2)}); pyramid "
          f"{pyramid.round(2)} px (OpenCV, {frontend_config.klt_levels} levels: "
          f"{opencv[frontend_config.klt_levels].round(2)})")
print(f"structure tensor eigenvalues at the corner: {np.linalg.eigvalsh(G).round(0)}; the library's window "
      f"{frontend_config.klt_window} x {frontend_config.klt_window} px, {frontend_config.klt_levels} pyramid levels, "
      f"iterations until the step is below {frontend_config.klt_epsilon:g} px")
assert (frontend_config.klt_window, frontend_config.klt_levels) == (15, 3)
assert np.abs(flow[73][0] - flow[73][2][0]).max() < 0.05 and np.abs(flow[73][1] - flow[73][2][3]).max() < 0.05
assert 3 < np.linalg.norm(flow[73][1]) < 7  # about 5 px to the next frame
assert np.linalg.norm(flow[76][1]) > 2 * 7 and np.abs(flow[76][1] - flow[76][2][3]).max() < 0.05
assert np.linalg.norm(flow[76][0] - flow[76][1]) > 3 and np.linalg.norm(flow[76][2][0] - flow[76][1]) > 3
assert np.linalg.eigvalsh(G)[0] > 0.2 * np.linalg.eigvalsh(G)[1]
off = lambda a, b: float(np.abs(a - b).max())  # noqa: E731  largest difference of two displacements, px
low, high = np.linalg.eigvalsh(G)
display(Markdown(
    f"To the next frame the corner moved {np.linalg.norm(flow[73][1]):.1f} px: one level is enough, and the few lines "
    f"above agree with OpenCV to {off(flow[73][0], flow[73][2][0]):.3f} px (one level) and "
    f"{off(flow[73][1], flow[73][2][3]):.3f} px (pyramid). {76 - 72} frames on it has moved "
    f"{np.linalg.norm(flow[76][1]):.1f} px, more than twice the window's half-width (7 px): one level then converges "
    f"to a wrong place ({np.linalg.norm(flow[76][0] - flow[76][1]):.1f} px from the pyramid's answer; OpenCV's one "
    f"level {np.linalg.norm(flow[76][2][0] - flow[76][1]):.1f} px), while the pyramid again agrees with OpenCV's three "
    f"levels to {off(flow[76][1], flow[76][2][3]):.3f} px. The eigenvalues of $G$, {low:.0f} and {high:.0f}, are of "
    f"the same order: a corner, as a KLT feature must be. The library adds what a tracker needs around this core: "
    f"the gyro's rotation as the starting guess $d$, a forward-backward check (track back, drop what does not return "
    f"within {frontend_config.klt_backward_check_px:g} px) and the same two-point RANSAC and grid as the descriptor "
    f"tracker."))

# %% [markdown]
# ## 2. The whole pipeline on APS frames
#
# `run_pipeline(data, config)` runs frames -> front-end -> MSCKF on the recording: each frame's tracks, undistorted,
# with their own 2 x 2 pixel covariance, go to `Msckf.process_image`; every IMU sample is propagated. The filter
# starts from the ground truth's pose and velocity at the first frame, and with both biases at **zero**. That is not
# the thesis's set-up: its biases "had to be estimated prior to evaluating the MSCKF" (Chapter IV's introduction) and
# were "manually estimated" for each recording "to minimize the impact of poor initial motion estimates" (§4.4; for
# Boxes $b_g$ = [0.049, 0.012, 0.002] rad/s and $b_a$ = [0.0275, -0.135, 0.14] m/s², without saying how). Its
# inertial frame is the initial IMU frame (§3.3.2). Starting at zero makes the filter learn the biases (below). Three
# configurations:
#
# - **IMU only** (`imu_only=True`): the same filter, no frames: dead reckoning;
# - **SIFT** with the thesis's descriptor tracker;
# - **KLT**: pyramidal Lucas-Kanade optical flow with FAST detections, what msckf_vio and OpenVINS run.
#
# `run_pipelines(data, configs)` runs `run_pipeline` for each of them, side by side in worker processes. A run is
# deterministic: it gives the same trajectory in a worker as alone; only its timings (the "x real time" of each
# summary: seconds of recording per second of computing) feel the neighbours.

# %%
configs = {
    "IMU only": PipelineConfig(imu_only=True),
    "SIFT": PipelineConfig(features="sift"),
    "KLT + FAST": PipelineConfig(tracker="klt", features="fast"),
}
results = run_pipelines(data, configs, jobs=JOBS)
for result in results.values():
    print(result.summary())
rmse = {name: r.metrics["rmse_m"] for name, r in results.items()}
imu_halves = results["IMU only"].metrics["rmse_first_half_m"], results["IMU only"].metrics["rmse_second_half_m"]
print(f"IMU only: RMSE {imu_halves[0]:.2f} m over the first half, {imu_halves[1]:.2f} m over the second")
halves = {name: (r.metrics["rmse_first_half_m"], r.metrics["rmse_second_half_m"]) for name, r in results.items()}
assert rmse["SIFT"] < rmse["IMU only"] / 3 and rmse["KLT + FAST"] < rmse["IMU only"] / 3
assert imu_halves[1] > 3 * imu_halves[0]
assert all(halves["IMU only"][1] / halves[name][1] > halves["IMU only"][0] / halves[name][0]
           for name in ("SIFT", "KLT + FAST"))  # the gap to dead reckoning grows
assert all(r.metrics["percent_of_distance"] < 20 for name, r in results.items() if name != "IMU only")
assert msckf_config_for(configs["SIFT"], data).min_track_length == 3  # a track is used from 3 observations (1b)
display(Markdown(
    f"Both visual front-ends beat dead reckoning by a wide margin: the RMSE (the root-mean-square of the position "
    f"error over the run) of IMU only is {rmse['IMU only'] / rmse['SIFT']:.0f} times SIFT's and "
    f"{rmse['IMU only'] / rmse['KLT + FAST']:.0f} times KLT's. The gap grows with the length of the run: IMU-only's "
    f"error over the second half is {imu_halves[1] / imu_halves[0]:.0f} times that over the first (under a gyro bias "
    f"the tilt error grows linearly, the misread gravity integrates twice: the position error grows like $t^3$, "
    f"for which this ratio would be $\\sqrt{{2^7 - 1}}$ = {np.sqrt(2 ** 7 - 1):.1f}). "
    f"SIFT's error is {results['SIFT'].metrics['percent_of_distance']:.2f} % of the distance travelled and KLT's "
    f"{results['KLT + FAST'].metrics['percent_of_distance']:.2f} % over these first {D_APS:g} s of gentle motion. "
    f"The thesis's unit, **% of distance**, is the mean position error divided by the distance travelled; it "
    f"flatters long runs and punishes short ones, so compare it only between runs over the same stretch."))

# %% [markdown]
# **ATE, the absolute trajectory error.** The RMSE above compares the estimate with the ground truth in the world frame
# the filter was started in. When the start is not the truth's (a static start: yaw and position are unobservable,
# section 2c) or to compare with other systems, the estimate is first moved rigidly onto the truth and only then
# measured: the rotation $R$ and translation $t$ minimising $\sum_k |p^{gt}_k - (R\,p^{est}_k + t)|^2$ have a closed
# form (Horn 1987, Umeyama 1991). With the centred points $a_k = p^{est}_k - \bar p^{est}$, $b_k = p^{gt}_k -
# \bar p^{gt}$ and the SVD $\frac1N \sum_k b_k a_k^T = U D V^T$:
#
# $$ R = U \operatorname{diag}(1, 1, \det U \det V)\, V^T, \qquad t = \bar p^{gt} - R\,\bar p^{est}, \qquad
# \mathrm{ATE} = \sqrt{\tfrac1N \sum_k |p^{gt}_k - (R\,p^{est}_k + t)|^2} $$
#
# (the diag(1, 1, ±1) keeps $R$ a rotation, not a reflection). For the SIFT run, from scratch and from the library:

# %%
from evio_lib.evaluation.trajectory_metrics import absolute_trajectory_error

p_est, p_gt = results["SIFT"].p_IinG, results["SIFT"].truth["p_IinG"]
a, b = p_est - p_est.mean(axis=0), p_gt - p_gt.mean(axis=0)
U, _, Vt = np.linalg.svd(b.T @ a / len(a))  # (1/N) sum b_k a_k^T = U D V^T
R_align = U @ np.diag([1.0, 1.0, np.linalg.det(U) * np.linalg.det(Vt)]) @ Vt
t_align = p_gt.mean(axis=0) - R_align @ p_est.mean(axis=0)
p_aligned = p_est @ R_align.T + t_align
ate_ours = np.sqrt(np.mean(np.sum((p_gt - p_aligned) ** 2, axis=1)))
turn_deg = np.degrees(np.arccos((np.trace(R_align) - 1) / 2))
print(f"ATE from scratch {ate_ours:.4f} m, library {results['SIFT'].metrics['ate_se3_m']:.4f} m; RMSE without "
      f"alignment {rmse['SIFT']:.4f} m; the alignment turns by {turn_deg:.1f} deg and shifts by "
      f"{100 * np.linalg.norm(t_align):.1f} cm")
assert abs(ate_ours - results["SIFT"].metrics["ate_se3_m"]) < 1e-9
assert abs(ate_ours - absolute_trajectory_error(p_est, p_gt, yaw_only=False)) < 1e-9
assert all(r.metrics["ate_se3_m"] <= r.metrics["rmse_m"] for r in results.values())
print(f"from scratch against the library: {abs(ate_ours - results['SIFT'].metrics['ate_se3_m']):.1e} m apart")

# %% [markdown]
# The few lines agree with `evio_lib.evaluation.trajectory_metrics.absolute_trajectory_error` (and with the
# `ate_se3_m` of the run's metrics) to the rounding of floating point (the last line printed above). The ATE is never
# larger than the unaligned RMSE, since the identity is one of the transforms the alignment may choose. It measures
# the trajectory's shape, not where it lies: the alignment may turn the whole estimate (by the angle printed) to fit
# it better, and on a short path a large turn costs little, so quote it beside the RMSE, not instead of it. For VIO,
# whose roll and pitch are observable from gravity, the field's convention is the 4-DoF alignment (yaw and
# translation only; `ate_4dof_m`, `yaw_only=True`); `evo_ape` (the absolute-pose-error command of the `evo`
# trajectory-evaluation tool) computes the same numbers from the trajectories that `python -m evio_lib run --out`
# writes in the TUM text format, one pose per line (a test checks it).
#
# The error figures of the thesis (Figs. 23-32): truth minus estimate per axis inside the filter's own ±3σ, for the
# SIFT run. The filter's state error is $[\delta\theta, \delta b_g, \delta v, \delta b_a, \delta p]$ (its σ's are
# `result.sigma`, 15 columns in that order); the attitude error is the small angle of
# $R_{G\to I}^{true} R_{G\to I}^{est\,T} \approx I - [\delta\theta]_\times$ (JPL), in the IMU frame. Which of its
# components is the yaw (heading) error? The one about the IMU axis that points along gravity: in this room the
# IMU's $y$ axis stays close to the vertical (its largest angle to it is printed below the figures), so "about $y_I$"
# is yaw, and the other two are tilt (roll and pitch), which gravity makes observable.

# %%
sift_run = results["SIFT"]
t = sift_run.t - sift_run.t[0]
truth = sift_run.truth
position_error = truth["p_IinG"] - sift_run.p_IinG
velocity_error = truth["v_IinG"] - sift_run.v_IinG
# δθ = log(R_ItoG_est^T R_ItoG_true): the rotation taking the estimate to the truth, in I
attitude_error_deg = np.degrees([so3_log(est.T @ true) for est, true in zip(sift_run.R_ItoG, truth["R_ItoG"])])
sigma = sift_run.sigma
plot_state_errors(t, position_error, sigma[:, 12:15], quantity="position", unit="m", title="SIFT: position")
vertical_deg = np.degrees(np.arccos(np.abs(truth["R_ItoG"][:, 2, :])))  # angle of x_I, y_I, z_I to the vertical
plot_state_errors(t, attitude_error_deg, np.degrees(sigma[:, 0:3]), quantity="", unit="deg",
                  axis_labels=("about $x_I$ (tilt)", "about $y_I$ (yaw)", "about $z_I$ (tilt)"),
                  title="SIFT: orientation error δθ in the IMU frame")
plot_state_errors(t, velocity_error, sigma[:, 6:9], quantity="velocity", unit="m/s", title="SIFT: velocity")
plt.show()
bands = {"position": (position_error, sigma[:, 12:15]), "orientation": (attitude_error_deg, np.degrees(sigma[:, 0:3])),
         "velocity": (velocity_error, sigma[:, 6:9])}
inside = {name: np.mean(np.abs(e) <= 3 * s) for name, (e, s) in bands.items()}  # share of samples inside ±3σ
print("share of samples inside ±3σ:", {k: round(float(v), 3) for k, v in inside.items()})
print(f"position σ (x, y, z): {sigma[0, 12:15].round(4)} m at the first frame, "
      f"{sigma[-1, 12:15].round(4)} m at the last")
print(f"largest angle of y_I to the vertical: {vertical_deg[:, 1].max():.1f} deg")
assert min(inside.values()) > 0.7 and max(inside.values()) < 0.997  # fewer than a consistent filter keeps
assert np.all(sigma[-1, 12:15] > sigma[0, 12:15])
assert vertical_deg[:, 1].max() < 12 and vertical_deg[:, [0, 2]].min() > 75
assert sigma[-1, 1] > max(sigma[-1, 0], sigma[-1, 2])  # the yaw band ends the widest
shares = ", ".join(f"{name} {100 * share:.1f} %" for name, share in inside.items())
display(Markdown(
    f"Inside the ±3σ band over this run: {shares} of the error samples, fewer than the 99.7 % that a consistent "
    f"filter keeps of a Gaussian error: over this run the filter is overconfident, the kind of inconsistency lesson 13 "
    f"measures with the NEES. Yaw and the absolute position are unobservable (lesson 13): the filter only learns the "
    f"motion relative to where it started, so the position band ends the run wider than it began, on every axis "
    f"(σ grows from {1e3 * sigma[0, 12:15].max():.1f} mm to {1e3 * sigma[-1, 12:15].min():.0f}-"
    f"{1e3 * sigma[-1, 12:15].max():.0f} mm); it "
    f"narrows only where an update ties the current pose to the poses of earlier frames, whose own uncertainty is the "
    f"floor. The yaw band (about $y_I$) ends the run the widest of the three attitude bands "
    f"({np.degrees(sigma[-1, 1]):.2f}° against {np.degrees(sigma[-1, 0]):.2f}° and "
    f"{np.degrees(sigma[-1, 2]):.2f}°): "
    f"nothing measures the heading, while gravity bounds the tilt."))

# %% [markdown]
# The IMU biases start at zero; the simulator knows the true ones, drawn black dashed (the thesis's bias figures,
# Appendix C, Figs. 49-58, show the estimates alone: its recordings have no true biases):

# %%
plot_bias_estimates(t, sift_run.b_g, sigma[:, 3:6], truth["b_g"], kind="gyro", title="SIFT: gyroscope bias")
plot_bias_estimates(t, sift_run.b_a, sigma[:, 9:12], truth["b_a"], kind="accel", title="SIFT: accelerometer bias")
plt.show()
gyro_bias_error = np.linalg.norm(truth["b_g"] - sift_run.b_g, axis=1)
halved = t[np.argmax(gyro_bias_error < 0.5 * gyro_bias_error[0])]  # first time under half the start's error
tenth = np.flatnonzero(gyro_bias_error < 0.1 * gyro_bias_error[0])
learned_in = f"under half of that after {halved:.1f} s" + (f", under a tenth after {t[tenth[0]]:.1f} s" if tenth.size
                                                           else "")
print(f"|b_g true - estimate|: {gyro_bias_error[0]:.4f} rad/s at the start ({learned_in}), "
      f"{gyro_bias_error[-1]:.4f} rad/s at the end")
accel_band_end = 3 * sigma[-1, 9:12]
print(f"accelerometer bias ±3σ at the end (x_I, y_I, z_I): {accel_band_end.round(3)} m/s^2")
assert gyro_bias_error[-1] < 0.5 * gyro_bias_error[0]
assert accel_band_end[1] < min(accel_band_end[0], accel_band_end[2])  # along the vertical y_I: the narrowest
display(Markdown(
    f"The gyroscope bias is learned within seconds (its error starts at {1e3 * gyro_bias_error[0]:.1f} mrad/s, is "
    f"{learned_in} and ends at {1e3 * gyro_bias_error[-1]:.1f} mrad/s): every tracked feature constrains the "
    f"rotation between views. The "
    f"accelerometer bias is learned unevenly: its ±3σ band ends the narrowest along the vertical $y_I$ "
    f"({accel_band_end[1]:.3f} m/s² against {accel_band_end[0]:.3f} and {accel_band_end[2]:.3f}), where a bias "
    f"changes the measured size of gravity, which no tilt can mimic; across the vertical a bias looks like a small "
    f"tilt, and the two are told apart only as the device rotates relative to gravity."))

# %% [markdown]
# The trajectory from above and the front-end's health over the run:

# %%
plot_trajectory_topdown({name: r.p_IinG for name, r in results.items() if name != "IMU only"},
                        truth["p_IinG"], title=f"boxes_like, first {D_APS:g} s (IMU only leaves the picture)")
plt.show()
for name in ("SIFT", "KLT + FAST"):
    r = results[name]
    plot_tracking_statistics(r.tracking, track_lengths=r.track_lengths, title=f"{name}: front-end statistics")
plt.show()
track_length = {name: float(np.mean(results[name].track_lengths)) for name in ("SIFT", "KLT + FAST")}
print("mean track length [frames]:", {k: round(v, 1) for k, v in track_length.items()})
assert track_length["KLT + FAST"] > 3 * track_length["SIFT"]
longest = {name: int(np.max(results[name].track_lengths)) for name in track_length}
display(Markdown(
    f"The two front-ends differ most in how long they keep a feature: optical flow follows a patch from frame to frame "
    f"and keeps it for {track_length['KLT + FAST']:.1f} frames on average (its longest track: "
    f"{longest['KLT + FAST']} frames), while SIFT's tracks last {track_length['SIFT']:.1f} frames (its longest: "
    f"{longest['SIFT']}); the histograms' log axes show both ends. Long tracks give the MSCKF more views per feature "
    f"and therefore more parallax per update."))

# %% [markdown]
# Why are SIFT's tracks shorter? A descriptor tracker can only continue a feature that the detector finds *again*
# in the next frame. `evio_lib.frontend.redetection` measures exactly that: it carries every keypoint of one frame
# into the next with optical flow and asks whether the detector fired within 2 px of it, and whether the guided
# nearest descriptor is that very point. SIFT against the project's CNN (`create_detector("superpoint")`, the
# network of the table's CNN rows below; the cell prints its name), on a few consecutive frame pairs, with up to 1000
# points per frame rather than the pipeline's 60 so that each rate rests on many points:

# %%
from evio_lib.frontend.redetection import redetection

pair_starts = range(72, 72 + (4 if FAST else 12), 2)
redetect = {}
print(f"the CNN: create_detector('superpoint') loads the network {create_detector('superpoint').weights_path.stem}")
for name in ("sift", "superpoint"):
    detector = create_detector(name, max_keypoints=1000, nms_radius=4)
    found = [redetection(detector, seq.frames[k], seq.frames[k + 1]) for k in pair_starts]
    redetect[name] = (np.mean([r.rate for r in found]), np.mean([r.match_rate for r in found]))
    print(f"{name:>10}: re-detected within 2 px {redetect[name][0]:.2f}, guided match correct {redetect[name][1]:.2f}")
assert 0.5 < redetect["sift"][0] < 0.9 and redetect["superpoint"][0] < 1.2 * redetect["sift"][0]
assert redetect["sift"][1] > 0.9 and redetect["superpoint"][1] > 0.8  # mostly the right point when found again
box_ratio = box_stats["tracked"][1:].mean() / box_stats["total"][1:].mean()  # continued share, section 1b
print(f"share of features continued from the previous frame: simulated room {box_ratio:.2f}"
      + ("" if slider_ratio is None else f", real slider {slider_ratio:.2f}"))
assert slider_ratio is None or abs(slider_ratio - box_ratio) < 0.15  # about the same on real and simulated frames
display(Markdown(
    f"SIFT fires again at {100 * redetect['sift'][0]:.0f} % of its points, not at all of them: the rest move to other "
    f"places of the texture, and their tracks must end however good the matching is, for when the point *is* found "
    f"again the guided nearest descriptor picks it {100 * redetect['sift'][1]:.0f} % of the time. So a track is lost "
    f"to a missed detection, not to a wrong match. The CNN, trained for repeatable points, re-detects "
    f"{100 * redetect['superpoint'][0]:.0f} % of its points on these frames, "
    f"{redetect['superpoint'][0] / redetect['sift'][0]:.2f} times SIFT's rate, and its guided match picks the point "
    f"{100 * redetect['superpoint'][1]:.0f} % of the time: the thesis's argument for a learned detector, more "
    f"repeatable points, "
    + ("does not show here." if redetect["superpoint"][0] < 1.1 * redetect["sift"][0] else "shows only weakly here.")
    + ("" if slider_ratio is None else
       f" On the real slider frames of section 1a SIFT continued {100 * slider_ratio:.0f} % of its features from "
       f"frame to frame, in the simulated room {100 * box_ratio:.0f} %: for this front-end the simulated frames "
       f"behave much like real ones.")))

# %% [markdown]
# A tracker can also keep looking for a point it missed: `PipelineConfig(max_track_gap=2)` (`run --max-track-gap 2`) keeps a
# lost track for two frames, predicts where its point went with the gyro's rotation and continues the track, with
# its id, when its last descriptor is matched again; the filter keeps such a track open meanwhile. It is off by
# default (`PipelineConfig`'s docstring says what it gave on whole recordings); exercise 3 tries it here.
#
# ### 2b. The sparse aerial scene
#
# The second preset, `aerial_like`, flies fast over sparse terrain seen from above (the thesis's aerial sequence).
# The same three configurations over the same number of seconds:

# %%
data_aerial = load_dataset("aerial_like", duration=D_APS)
aerial_results = run_pipelines(data_aerial, configs, jobs=JOBS)
for result in aerial_results.values():
    print(result.summary())
plot_error_comparison({name: r.t - r.t[0] for name, r in aerial_results.items()},
                      {name: np.linalg.norm(r.truth["p_IinG"] - r.p_IinG, axis=1)
                       for name, r in aerial_results.items()},
                      log=True, title=f"aerial_like, first {D_APS:g} s: position error")
plt.show()
aerial_rmse = {name: r.metrics["rmse_m"] for name, r in aerial_results.items()}
distance = {"boxes_like": results["SIFT"].metrics["distance_m"],
            "aerial_like": aerial_results["SIFT"].metrics["distance_m"]}
print(f"distance travelled: {distance['boxes_like']:.1f} m in the room, {distance['aerial_like']:.0f} m in the air")
assert all(aerial_rmse[name] < aerial_rmse["IMU only"] / 2 for name in ("SIFT", "KLT + FAST"))
assert all(aerial_results[name].metrics["percent_of_distance"] < 5 for name in ("SIFT", "KLT + FAST"))
assert distance["aerial_like"] > 10 * distance["boxes_like"]
assert all(aerial_rmse[name] > rmse[name] for name in configs)
display(Markdown(
    f"Over sparse terrain both visual front-ends still beat dead reckoning: IMU only's RMSE is "
    f"{aerial_rmse['IMU only'] / aerial_rmse['SIFT']:.1f} times SIFT's and "
    f"{aerial_rmse['IMU only'] / aerial_rmse['KLT + FAST']:.1f} times KLT's, and their errors are "
    f"{aerial_results['SIFT'].metrics['percent_of_distance']:.2f} % and "
    f"{aerial_results['KLT + FAST'].metrics['percent_of_distance']:.2f} % of the distance flown. The flight covers "
    f"{distance['aerial_like'] / distance['boxes_like']:.0f} times the room's distance in the same time, and every "
    f"configuration's error in metres is larger than in the room: compare configurations within one scene, not "
    f"metres across scenes."))

# %% [markdown]
# ### 2c. Standing still: static start and zero-velocity updates
#
# Both presets start in motion, so the runs above start from the ground truth. A real recording often starts with
# the platform on the ground: the EuRoC slice is the first seconds of V1_01 (its length is printed below), the MAV
# still on the floor with its rotors spinning. Two things go wrong there if the filter is not told:
#
# - **Initialisation.** With `init="auto"` (the default) the pipeline tests the first second of IMU: if it is still
#   (the 50 ms means of gyro and accelerometer barely change, and |a| is about g), it starts as OpenVINS does: roll
#   and pitch from the direction of gravity, the gyro bias as the mean gyro reading, velocity zero. Yaw and position
#   cannot be seen from a still IMU; they are copied from the ground truth when there is one, so the errors need no
#   alignment. A moving start (the presets) keeps the ground-truth initialisation.
# - **No parallax.** Every camera clone sits at the same place, so no feature can be triangulated and the visual
#   update rejects them all, while the IMU's noise keeps integrating into velocity and position.
#
# The fix is a **zero-velocity update** (ZUPT). A frame counts as still when the tracks moved less than half a pixel
# since the previous frame (the median), the IMU is still over the last 0.25 s, and the filter's speed is under
# 0.1 m/s. The images are needed: the IMU alone cannot tell standing still from moving at a constant velocity. On a
# still frame the filter gets, instead of a visual update, the measurement
#
# $$ v_{I}^{G} = 0, \qquad \bar\omega_m = b_g + n_g, \qquad \bar a_m = -R_{G\to I}\, g^G + b_a + n_a $$
#
# over the IMU samples since the last frame (bars are means). With the JPL attitude error
# $R_{G\to I} \approx (I - [\delta\theta]_\times)\hat R_{G\to I}$ the accelerometer row's Jacobian is
# $H_\theta = -[\hat R_{G\to I} g^G]_\times$ and $H_{b_a} = I$; it has no column for position and
# $H_\theta$ is zero along gravity, so yaw and position stay unobservable as they should (lesson 13). No camera pose is
# cloned on a still frame. `evio_lib.msckf.zero_velocity` holds the test and the measurement, and
# `tests/msckf/test_zero_velocity.py` checks the Jacobian against finite differences. The same run with and
# without it (`PipelineConfig(zupt=False)`, `python -m evio_lib run --no-zupt`):

# %%
from evio_lib.msckf.zero_velocity import ZeroVelocityConfig

still_test = ZeroVelocityConfig()  # the thresholds named above: 0.5 px of median track motion, 0.25 s, 0.1 m/s
assert (still_test.max_disparity_px, still_test.imu_window, still_test.max_velocity) == (0.5, 0.25, 0.1)
print(f"still: median track motion under {still_test.max_disparity_px:g} px, IMU still over the last "
      f"{still_test.imu_window:g} s, filter speed under {still_test.max_velocity:g} m/s")
D_STILL = 2.0 if FAST else None  # seconds of the EuRoC slice (None: all of it)
if HAVE_EUROC:
    euroc_data = load_dataset(EUROC)
    slice_s = euroc_data.sequence.frame_times[-1] - euroc_data.sequence.frame_times[0]
    print(f"the EuRoC slice: {slice_s:.1f} s; the runs below use "
          + (f"its first {D_STILL:g} s" if D_STILL else "all of it"))
    still_runs = {label: run_pipeline(euroc_data, PipelineConfig(tracker="klt", features="fast", zupt=zupt,
                                                                 max_duration=D_STILL))
                  for label, zupt in (("with zero-velocity updates", True), ("without", False))}
    for result in still_runs.values():
        print(result.summary())
    plot_error_comparison({label: r.t - r.t[0] for label, r in still_runs.items()},
                          {label: np.linalg.norm(r.truth["p_IinG"] - r.p_IinG, axis=1)
                           for label, r in still_runs.items()},
                          log=True, title="EuRoC V1_01, the MAV on the ground: position error")
    plt.show()
    held, free = still_runs.values()
    drawn = {label: float(np.sqrt(np.mean(np.sum((r.truth["p_IinG"] - r.p_IinG) ** 2, axis=1)))) for label, r
             in still_runs.items()}  # the RMSE of the error the figure draws, before any alignment
    print(f"still frames: {held.metrics['zupt_frames']} of {held.metrics['frames']}; "
          f"ATE {held.metrics['ate_se3_m']:.4f} m "
          f"with the updates, {free.metrics['ate_se3_m']:.4f} m without; ground-truth path "
          f"{held.metrics['distance_m']:.3f} m")
    assert held.metrics["init"] == "static" and free.metrics["init"] == "static"
    assert held.metrics["zupt_frames"] >= 0.8 * held.metrics["frames"]
    assert held.metrics["ate_se3_m"] < 0.02 and free.metrics["ate_se3_m"] > 5 * held.metrics["ate_se3_m"]
    assert held.metrics["distance_m"] < 0.02 and np.isnan(held.metrics["percent_of_distance"])
    display(Markdown(
        f"Both runs start statically. With the zero-velocity updates {held.metrics['zupt_frames']} of the "
        f"{held.metrics['frames']} frames are declared still and the error stays at "
        f"{1e3 * held.metrics['ate_se3_m']:.1f} mm (ATE; the figure draws the error before alignment, whose RMSE is "
        f"{1e3 * drawn['with zero-velocity updates']:.1f} mm); without them the same filter drifts to "
        f"{1e3 * free.metrics['ate_se3_m']:.0f} mm, {free.metrics['ate_se3_m'] / held.metrics['ate_se3_m']:.0f} times "
        f"further (before alignment: {1e3 * drawn['without']:.0f} mm RMSE, "
        f"{1e3 * np.linalg.norm(free.truth['p_IinG'][-1] - free.p_IinG[-1]):.0f} mm at the end), "
        f"while the MAV does not move. The ground truth's path is {1e3 * held.metrics['distance_m']:.0f} mm "
        f"here (the MAV vibrating on the floor), so no % of distance is reported: divided by almost nothing it would "
        f"only measure noise."))
else:
    print(f"EuRoC slice not found at {EUROC}: skipping the still-start comparison")

# %% [markdown]
# ## 3. The Table 6 analogue
#
# The thesis's Table 6 lists the MSCKF's error for each configuration. `run_table` runs every (preset, row, seed) job
# through joblib (each job is a pure function, `table_job`, so joblib's Dask or Ray backend, libraries that spread
# Python jobs over many machines, could spread a sweep over a cluster unchanged); `aggregate` takes the mean and
# spread over seeds and `format_table6` prints the thesis's columns. Here: short runs of the rows without events.
# The "bias correction" row starts the biases at the simulator's true values; the thesis's row of that name used the
# biases it had "manually estimated" (§4.4, method not given) and propagated the IMU alone with them.

# %%
from evio_lib.pipeline.table import aggregate, format_table6, run_table, table_rows
from evio_lib.sim.jobs import default_jobs  # one worker per core (EVIO_JOBS overrides)

rows = table_rows(["imu", "imu_bias", "sift_aps", "klt_aps"])
records = run_table(presets=("boxes_like",), seeds=TABLE_SEEDS, rows=rows,
                    durations={"boxes_like": TABLE_DURATION}, jobs=JOBS or default_jobs(), progress=False)
table = {row["row"]: row for row in aggregate(records)}
display(Markdown(f"boxes_like, first {TABLE_DURATION:g} s, seeds {list(TABLE_SEEDS)}:\n\n" +
                 format_table6(list(table.values()))))
assert all(row["failed"] == 0 for row in table.values())
assert max(table["sift_aps"]["rmse_m"], table["klt_aps"]["rmse_m"]) < table["imu"]["rmse_m"] / 2
assert table["imu_bias"]["rmse_m"] < table["imu"]["rmse_m"] / 5
assert table["imu_bias"]["rmse_m"] < table["sift_aps"]["rmse_m"]
assert all(table[key]["rmse_second_half_m"] > table[key]["rmse_first_half_m"] for key in ("imu", "imu_bias"))
display(Markdown(
    f"Over {TABLE_DURATION:g} s, part of Table 6's structure appears: uncorrected dead reckoning's RMSE is "
    f"{table['imu']['rmse_m'] / table['sift_aps']['rmse_m']:.0f} times SIFT's and "
    f"{table['imu']['rmse_m'] / table['klt_aps']['rmse_m']:.0f} times KLT's, and starting the biases at their true "
    f"values shrinks the IMU-only error {table['imu']['rmse_m'] / table['imu_bias']['rmse_m']:.0f} times. Over these "
    f"short runs that bias-corrected dead reckoning even beats SIFT ({table['imu_bias']['rmse_m']:.3f} against "
    f"{table['sift_aps']['rmse_m']:.3f} m): with *exactly* known biases (which only a simulator offers; the thesis's "
    f"recordings had no true biases to check its hand estimates against) the IMU's error grows from noise and bias "
    f"drift alone, slowly at first, while a visual error starts at once from the tracks' noise. Dead reckoning's "
    f"error still grows without bound: its second-half RMSE is the larger in both IMU rows."))

# %% [markdown]
# Whether the visual rows overtake it over the whole recordings is what the full sweep measures: every row, both
# presets, the whole room and flight, three seeds (`python -m evio_lib table`, hours of computing;
# docs/results/pipeline.md has every row, the IMU rows among them). Its APS rows, as the project recorded them (the
# data line printed below gives the lengths and seeds and the command of the SIFT and CNN rows; the KLT row comes
# from an earlier sweep of the same recordings), beside the thesis's grayscale rows on its real recordings
# (boxes_6dof, 69.8 m, and the Camp Atterbury flight, 1 077 m):

# %%
import json

sweep = json.loads((Path(evio_lib.__file__).resolve().parents[1] / "docs" / "results" / "data" / "table6.json")
                   .read_text(encoding="utf-8"))
values = sweep["values"]
THESIS_GRAYSCALE = {"sift_aps": ("SIFT", 0.989, 0.645), "cnn_aps": ("DetDesc (Round 2), the thesis's CNN", 0.996, 1.09)}


def sweep_cell(preset, row):
    """mean ± std over the seeds, or the number of diverged seeds, of one row of the recorded sweep."""
    key = f"{preset}.{row}"
    if f"{key}.mean" in values:
        return f"{values[key + '.mean']:.2f} ± {values[key + '.std']:.2f}"
    return f"{values[key + '.diverged']} of {values[key + '.seeds']} seeds diverged"


lines = ["| configuration | boxes_like, 60 s [% of distance] | aerial_like, 40 s | "
         "thesis, boxes_6dof / Camp Atterbury |", "|---|---|---|---|"]
for row, label in (("sift_aps", "SIFT, APS frames"), ("cnn_aps", "CNN, APS frames"),
                   ("klt_aps", "KLT + FAST, APS frames")):
    thesis = THESIS_GRAYSCALE.get(row)
    lines.append(f"| {label} | {sweep_cell('boxes_like', row)} | {sweep_cell('aerial_like', row)} | "
                 + (f"{thesis[1]} / {thesis[2]} % ({thesis[0]})" if thesis else "-") + " |")
display(Markdown("\n".join(lines)))
print(f"the full sweep's numbers: {sweep['data']}\ncommand: {sweep['command']}\nat commit {sweep['commit']}")
assert values["boxes_like.sift_aps.mean"] < 1.0 and values["boxes_like.klt_aps.mean"] < 1.0
assert values["boxes_like.cnn_aps.std"] > max(values["boxes_like.sift_aps.std"], values["boxes_like.klt_aps.std"])
flight_cnn = sweep_cell("aerial_like", "cnn_aps")  # "mean ± std", or how many seeds diverged
if "aerial_like.cnn_aps.mean" in values:
    largest = values["aerial_like.cnn_aps.mean"] > max(values["aerial_like.sift_aps.mean"],
                                                       values["aerial_like.klt_aps.mean"])
    flight_cnn = f"it reaches {flight_cnn} %, " + ("the largest mean of the three" if largest else
                                                   "within the other rows' means")
display(Markdown(
    f"Over the whole recordings SIFT and KLT stay under 1 % of the distance in the room "
    f"({values['boxes_like.sift_aps.mean']:.2f} and {values['boxes_like.klt_aps.mean']:.2f} %), as the thesis's "
    f"SIFT row on its real Boxes recording does ({THESIS_GRAYSCALE['sift_aps'][1]} %); its CNN reached "
    f"{THESIS_GRAYSCALE['cnn_aps'][1]} % there, ours {values['boxes_like.cnn_aps.mean']:.2f} % in the room. In the "
    f"room the CNN's row is the least steady of the three on these simulated frames "
    f"({sweep_cell('boxes_like', 'cnn_aps')} %); over the flight {flight_cnn}."))

# %% [markdown]
# The thesis's numbers come from other sensors, scenes and durations: read them for orientation, not as a
# like-for-like comparison. One run of one configuration, with its output folder (the trajectory in the TUM format,
# per-frame states, figures): `python -m evio_lib run boxes_like --duration 10 --out runs/boxes`.
#
# ## Summary
#
# - The front-end detects, matches inside the gyro-predicted window, rejects outliers with two-point RANSAC and keeps
#   features spread on a grid; on a still camera RANSAC correctly reports the translation unobservable.
# - With the rotation known from the gyro, the epipolar constraint is linear in the translation: two matches give a
#   hypothesis $t \propto c_1 \times c_2$, and RANSAC over such pairs recovers the direction of the camera's motion.
# - Lucas-Kanade solves a 2 x 2 system with the window's structure tensor, iterated; the pyramid extends it to
#   motions larger than the window.
# - ATE: align the estimate rigidly onto the truth (Umeyama's closed form with one SVD), then take the RMSE.
# - `run_pipeline(load_dataset(...), PipelineConfig(...))` is the whole chain; `result.summary()`, the figures of
#   `evio_lib.evaluation.plots_pipeline` and `python -m evio_lib run` give the thesis's outputs.
# - The MSCKF with either visual front-end beats IMU-only with unknown biases by a wide margin, in the textured room
#   and over sparse terrain, and learns the gyroscope bias within seconds; KLT keeps its features far longer than
#   SIFT, whose tracks end where the detector does not fire again.
# - A still start needs two things the moving presets do not: a static initialisation (attitude and gyro bias from
#   the still IMU) and zero-velocity updates while the platform stands still, detected from the tracks and the IMU.
#
# ## Exercises
#
# 1. Run section 2's SIFT with `PipelineConfig(match_ratio=0.8)`, the front-end's stand-alone default. What happens
#    to the track length and to the error? Why would a ratio test cost correct matches in a repetitive room?
#
#    *Hint:* compare `np.mean(result.track_lengths)` and `rmse_m` of both runs; in a room of repeated textures, how
#    close is the second-best match?
# 2. Raise `pixel_noise_px` to 3 and lower it to 0.3. How do the 3σ bands and the share of errors inside them change?
#
#    *Hint:* `pixel_noise_px` is the noise the filter assumes, not the noise of the tracks; compare
#    `result.sigma[:, 12:15]` and the share of errors inside ±3σ.
# 3. Run SIFT with `PipelineConfig(features="sift", max_track_gap=2)` over section 2's stretch. How much longer do its
#    tracks get, and does the error follow?
#
#    *Hint:* `np.mean(result.track_lengths)` and `result.metrics["rmse_m"]` beside section 2's SIFT run, and the
#    `rmse_first_half_m` / `rmse_second_half_m` of both.
# 4. Call `evio_lib.msckf.zero_velocity.imu_still_test` on the first 0.25 s of the EuRoC IMU (`euroc_data.sequence.imu`,
#    with the static start's attitude and gyro bias), then on the same samples plus a constant 1 m/s^2 along $y_I$
#    (horizontal here: this MAV's IMU has its $x$ axis up, so along $x$ the push would add to |a|). Which of its
#    figures changes, and why would testing |a| against g alone have missed it?
#
#    *Hint:* `static_initialization` on the first second gives the attitude and gyro bias; the test's fourth figure
#    compares the mean accelerometer with $-R_{GtoI}g + b_a$ as a vector; $\sqrt{9.81^2 + 1^2} \approx 9.86$.
#
# Solutions, with the code to run (checked by `tests/test_solutions.py`):
# [docs/solutions/14_evio_pipeline.md](../docs/solutions/14_evio_pipeline.md).
