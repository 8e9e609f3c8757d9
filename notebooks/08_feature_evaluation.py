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
# # 08 — Evaluating feature detectors: repeatability, homography estimation and the thesis's tables
#
# Lessons 05-07 built two families of front ends: classical detectors (Harris, FAST, SIFT, ORB, FAST-FREAK) and a
# SuperPoint-style network trained from scratch. Which one should a visual-inertial odometry system use? Looking at
# pictures of keypoints does not answer that. This lesson measures it the way the thesis the course follows does
# (Friedel 2020, *Event-based visual-inertial odometry using smart features*, §3.2.6, §4.3):
#
# 1. **repeatability** (Eqs. 15-16): does the detector fire on the same scene points in two views of the scene?
# 2. **homography estimation correctness** (Eq. 17): do detector *and* descriptor together recover the geometric
#    change between the views well enough that the image corners land within $\varepsilon$ pixels?
# 3. two descriptor metrics the thesis lists as future work: the **matching score** and the nearest-neighbour
#    **mean average precision**;
# 4. **qualitative matches** in the style of the thesis's Appendix B;
# 5. the **benchmark tables** in the form of Tables 2-5 for every available detector, plus a speed table.
#
# Repeatability, homography correctness and the matching score are first computed by hand on one image pair and
# checked against `evio_lib.features.evaluation.evaluate` (the NN mAP comes from the library); the tables then come
# from `evio_lib.features.evaluation.benchmark`.
#
# **The protocol, drawn** on a made-up scene before any of it is computed: (1) a pair of images related by a known
# homography $H$, so that every point of image 1 has a true place in image 2; (2) repeatability, the detector alone:
# image 1's keypoints carried into image 2 by $H$ count as repeated when a detection of image 2 lies within
# $\varepsilon$ pixels; (3) matching, detector and descriptor together: each point paired with the nearest descriptor
# of the other image, correct when it lands within $\varepsilon$ of the truth; (4) homography estimation: a
# homography $\hat H$ fitted to the matches by RANSAC (fits to random samples of four matches; the one most matches
# agree with wins, the matches that disagree are dropped), graded by where it puts image 1's four corners compared
# with $H$. The pair counts as correct when the mean corner distance is at most $\varepsilon$; in the drawing
# $\hat H$ is off by more than that.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_features import plot_evaluation_schematic

fig = plot_evaluation_schematic(eps=3.0)
plt.show()

# %% [markdown]
# **Data.** The thesis evaluated on HPatches (§3.2.3): 116 scenes, each a reference image and 5 others of the same
# planar scene under changed illumination (57 scenes) or viewpoint (59), with the true homography to the reference.
# HPatches and the thesis's aerial recordings do not come with the course; the library builds an
# HPatches-style benchmark instead (`heldout_pairs`): images of the held-out TEST split of the project's image pool
# (never seen in training), each paired with copies warped by random homographies (the *viewpoint* split) or
# changed only photometrically (the *illumination* split, $H = I$). The event-frame split pairs event frames of
# the simulator's aerial preset with warped copies, as the thesis built its set from a drone (UAV) flight (§3.2.3); but our frames are
# plain event-count images, where the thesis's were "reconstructed event images" made by a recurrent network (§3.2.3,
# §4.1), like the reconstructions of lesson 04 (section 6 says what that changes). Anyone with the
# real HPatches folder gets the official benchmark from the same code (`--dataset hpatches --hpatches-root DIR`).

# %%
import time

import cv2
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display
from scipy.stats import spearmanr

from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_features import (
    plot_heatmap_row,
    plot_homography_corners,
    plot_match_grid,
    plot_oracle_corner_errors,
    plot_repeated_points,
)
from evio_lib.events.array import event_count_image, events_between
from evio_lib.features.base import available_detectors, create_detector
from evio_lib.features.evaluation.benchmark import (
    VIEWPOINT_HOMOGRAPHY,
    BenchmarkSettings,
    diagnose_pairs,
    event_frame_pairs,
    format_table,
    heldout_pairs,
    measure_speed,
    run_benchmark,
)
from evio_lib.features.evaluation.evaluate import (
    corner_error,
    diagnose_matches,
    estimate_homography,
    homography_correctness,
    match_descriptors,
    matching_score,
    mean_average_precision,
    repeatability,
)
from evio_lib.features.evaluation.hpatches import resize_pair
from evio_lib.features.network import shipped_weights
from evio_lib.geometry.homography import warp_points
from evio_lib.sim.jobs import map_in_workers
from evio_lib.sim.presets import SimulationConfig, simulate_sequence

FAST = fast_mode()
rng = np.random.default_rng(8)
SEED = 0  # seed of the held-out image pool and of every random change in the benchmark

settings = BenchmarkSettings.thesis_hpatches()  # the thesis's settings (§3.2.6, last paragraph)
print(f"repeatability at {settings.repeatability_size[0]} x {settings.repeatability_size[1]}, best "
      f"{settings.repeatability_keypoints} points, NMS {settings.repeatability_nms}; homography at "
      f"{settings.homography_size[0]} x {settings.homography_size[1]}, best {settings.homography_keypoints} points, "
      f"NMS {settings.homography_nms}; eps = {', '.join(f'{e:g}' for e in settings.eps)} px")

# %% [markdown]
# ## 1. The benchmark pairs
#
# A benchmark sample is an `ImagePair`: image 1, image 2 and the homography $H$ that maps pixels of image 1 to
# pixels of image 2, $\tilde{\mathbf x}_2 \sim H \tilde{\mathbf x}_1$. For a planar scene (or a camera that only
# rotates) a homography describes the change of view exactly, so every metric below has a ground truth.

# %%
n_demo_images = 2 if FAST else 4
demo_pairs = heldout_pairs(SEED, n_images=n_demo_images, pairs_per_image=1)
view_pair = next(p for p in demo_pairs if p.split == "viewpoint")
illum_pair = next(p for p in demo_pairs if p.split == "illumination")
print(f"{len(demo_pairs)} pairs, image size {view_pair.image1.shape}")
print("viewpoint H =\n", view_pair.H.round(3))

fig = plot_heatmap_row([view_pair.image1, view_pair.image2, illum_pair.image1, illum_pair.image2],
                       ["viewpoint: image 1", "viewpoint: image 2 (warped)", "illumination: image 1",
                        "illumination: image 2 (H = I)"], cmaps="gray", panel_in=4.0)
plt.show()
assert np.allclose(illum_pair.H, np.eye(3))  # the illumination split changes only the photometry

# %% [markdown]
# ## 2. Repeatability (Eqs. 15-16)
#
# Detect $N_1$ points in image 1 and $N_2$ in image 2, keeping only points whose warp lands inside the other
# image (the shared view). A point $\mathbf x_i$ of image 1 is **repeated** when some detection of image 2 lies
# within $\varepsilon$ pixels of where $H$ sends it:
#
# $$\operatorname{Corr}(\mathbf x_i) = \Big(\min_{j} \lVert H\mathbf x_i - \mathbf x_j \rVert \le \varepsilon\Big),$$
#
# and symmetrically for the points $\mathbf x_j$ of image 2. Repeatability is the fraction of all points that are
# repeated:
#
# $$\mathrm{Rep} = \frac{\sum_i \operatorname{Corr}(\mathbf x_i) + \sum_j \operatorname{Corr}(\mathbf x_j)}{N_1 + N_2}.$$
#
# It measures the detector alone — descriptors play no part. The thesis evaluates it at 240 x 320 with the best
# 300 points and NMS radius 4. As in SuperPoint's evaluation code (whose numbers the thesis reports), both
# distances are measured in image 2's frame. Here it is by hand for SIFT on the viewpoint pair.

# %%
small = resize_pair(view_pair, settings.repeatability_size)  # 240 x 320, H updated: H' = S2 H S1^-1
rep_detector = create_detector("sift", max_keypoints=settings.repeatability_keypoints,
                               nms_radius=settings.repeatability_nms)
f1 = rep_detector.detect_and_describe(small.image1)
f2 = rep_detector.detect_and_describe(small.image2)
h, w = small.image2.shape


def inside(points: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Whether (x, y) lies on the pixel area [-0.5, W - 0.5) x [-0.5, H - 0.5)."""
    return (points[:, 0] >= -0.5) & (points[:, 0] < shape[1] - 0.5) & (points[:, 1] >= -0.5) & (points[:, 1] < shape[0] - 0.5)


warped1 = warp_points(small.H, f1.keypoints.astype(np.float64))  # H x_i (image 2 frame)
back2 = warp_points(np.linalg.inv(small.H), f2.keypoints.astype(np.float64))  # H^-1 x_j (image 1 frame)
a = warped1[inside(warped1, small.image2.shape)]  # the N1 points of image 1 in the shared view
b = f2.keypoints[inside(back2, small.image1.shape)].astype(np.float64)  # the N2 points of image 2 in the shared view
dist = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)  # (N1, N2) pixel distances in image 2
eps = np.array(settings.eps)
corr1 = dist.min(axis=1)[:, None] <= eps  # Eq. 15 for the points of image 1
corr2 = dist.min(axis=0)[:, None] <= eps  # ... and for the points of image 2
rep_hand = (corr1.sum(axis=0) + corr2.sum(axis=0)) / (len(a) + len(b))  # Eq. 16

rep_lib = repeatability(f1.keypoints, f2.keypoints, small.H, small.image1.shape, small.image2.shape, eps)
print(f"N1 = {len(a)}, N2 = {len(b)} in the shared view")
print("by hand :", rep_hand.round(3), "\nlibrary :", np.round(rep_lib, 3))
assert np.allclose(rep_hand, rep_lib)

# %% [markdown]
# The figure shows image 2 with the detections of image 1 carried over by $H$: green where a detection of image 2
# lies within $\varepsilon = 3$ px (repeated), red where none does.

# %%
fig = plot_repeated_points(small.image2, a, b, corr1[:, 1], eps=3,  # column 1 of corr1: eps = 3
                           title=f"SIFT repeatability on one viewpoint pair: {rep_lib[1]:.2f} at eps = 3 px")
plt.show()

# %% [markdown]
# ## 3. Homography estimation correctness (Eq. 17)
#
# Now detector and descriptor work together, at 480 x 640 with the best 1000 points and NMS 8 (§3.2.6):
#
# 1. match descriptors by **mutual nearest neighbour** (L2 for float descriptors, Hamming for binary ones);
# 2. fit $\hat H$ to the matches with `cv2.findHomography` and RANSAC;
# 3. warp the four image corners $\mathbf c_j$ with both $\hat H$ and the true $H$ and average their distances.
#
# A pair counts as correct when that mean corner error is at most $\varepsilon$, and the score of a data set of
# $N$ pairs is
#
# $$\mathrm{Corr}_H = \frac{1}{N}\sum_{i=1}^{N}\Big(\frac14\sum_{j=1}^{4}\lVert \hat{\mathbf c}'_{ij} -
# \mathbf c'_{ij}\rVert \le \varepsilon\Big).$$
#
# (Eq. 17 of the thesis writes the threshold inside the corner sum; SuperPoint's code, which the thesis used,
# thresholds the mean, as here.)

# %%
large = resize_pair(view_pair, settings.homography_size)
hom_detector = create_detector("sift", max_keypoints=settings.homography_keypoints, nms_radius=settings.homography_nms)
g1 = hom_detector.detect_and_describe(large.image1)
g2 = hom_detector.detect_and_describe(large.image2)
matches = match_descriptors(g1.descriptors, g2.descriptors, binary=g1.binary, mutual=True)
H_est, inliers = estimate_homography(g1.keypoints, g2.keypoints, matches)

hh, ww = large.image1.shape
corners = np.array([[0.0, 0.0], [ww - 1.0, 0.0], [0.0, hh - 1.0], [ww - 1.0, hh - 1.0]])
c_true = warp_points(large.H, corners)  # c'_j = H c_j
c_est = warp_points(H_est, corners)  # c^'_j = H_est c_j
error_hand = np.linalg.norm(c_est - c_true, axis=1).mean()  # 1/4 sum_j ||c^'_j - c'_j||
correct_hand = error_hand <= eps

print(f"{len(g1.keypoints)} / {len(g2.keypoints)} keypoints, {len(matches)} mutual matches, {inliers.sum()} RANSAC inliers")
print(f"mean corner error: by hand {error_hand:.3f} px, library {corner_error(H_est, large.H, large.image1.shape):.3f} px")
print("correct at eps = 1, 3, 5:", correct_hand)
assert np.isclose(error_hand, corner_error(H_est, large.H, large.image1.shape))
assert (correct_hand == homography_correctness(H_est, large.H, large.image1.shape, eps)).all()
assert np.any((c_true < 0) | (c_true > [ww - 1.0, hh - 1.0]))  # image 1's corners land outside image 2 (a zoom)

# %%
fig = plot_homography_corners(large.image2, c_true, c_est)  # its title: the mean corner error, as error_hand
plt.show()

# %% [markdown]
# The corners of image 1 fall outside image 2 here, because image 2 shows a zoomed-in patch of image 1. That is
# why Eq. 17 looks at the corners: they sit where an error in $\hat H$'s perspective part shows most, so a
# homography that only fits the matched points in the middle of the image is not rewarded.
#
# ## 4. Descriptor metrics: matching score and mean average precision
#
# Homography correctness hides how good the descriptor is behind RANSAC, which tolerates many wrong matches. Two
# metrics look at the matches directly (DeTone et al. 2018, §7.2; the thesis lists them as future work):
#
# * **matching score**: match every point in the shared view to its nearest-neighbour descriptor (no
#   cross-check); the fraction of those matches that land within $\varepsilon$ of the truth, averaged over both
#   directions;
# * **NN mAP**: rank those matches by descriptor distance and take the area under the precision-recall curve
#   (precision: the share of the matches kept so far that are correct; recall: the share of all correct matches
#   kept so far; the curve walks down the ranking) — it rewards descriptors whose distances put correct matches first.
#
# A few lines reproduce the matching score for direction 1 → 2 and 2 → 1.

# %%
k1 = g1.keypoints.astype(np.float64)
k2 = g2.keypoints.astype(np.float64)
d = np.linalg.norm(g1.descriptors[:, None, :] - g2.descriptors[None, :, :], axis=2)  # (N1, N2) L2 distances
w1 = warp_points(large.H, k1)
q1 = inside(w1, large.image2.shape)  # queries of direction 1 -> 2
ms12 = (np.linalg.norm(w1[q1] - k2[d[q1].argmin(axis=1)], axis=1)[:, None] <= eps).mean(axis=0)
q2 = inside(warp_points(np.linalg.inv(large.H), k2), large.image1.shape)  # queries of direction 2 -> 1
ms21 = (np.linalg.norm(k2[q2] - w1[d[:, q2].argmin(axis=0)], axis=1)[:, None] <= eps).mean(axis=0)
ms_hand = (ms12 + ms21) / 2

shape1, shape2 = large.image1.shape, large.image2.shape
ms_lib = matching_score(g1.keypoints, g2.keypoints, g1.descriptors, g2.descriptors, large.H, shape1, shape2, eps)
map_lib = mean_average_precision(g1.keypoints, g2.keypoints, g1.descriptors, g2.descriptors, large.H, shape1, shape2, eps)
print("matching score by hand:", ms_hand.round(3), " library:", np.round(ms_lib, 3))
print("NN mAP (library):      ", np.round(map_lib, 3))
assert np.allclose(ms_hand, ms_lib, atol=1e-6)

# %% [markdown]
# ## 5. Qualitative matches (thesis Appendix B)
#
# The thesis shows matches of each method side by side. Below are the mutual nearest-neighbour matches of SIFT,
# ORB and FAST-FREAK on a viewpoint pair and on an illumination pair, at the homography-task settings; a match is
# green when the true $H$ puts it within 3 px of its partner, red otherwise. At most 150 matches are drawn per
# panel (a random, seeded subset) to keep the picture readable; the counts in the titles are over all matches.


# %%
def mutual_matches(pair, name: str):
    """Return keypoints 1 and 2, the mutual-NN matches (M, 2) and whether each lies within 3 px of the truth."""
    det = create_detector(name, max_keypoints=settings.homography_keypoints, nms_radius=settings.homography_nms)
    fa, fb = det.detect_and_describe(pair.image1), det.detect_and_describe(pair.image2)
    m = match_descriptors(fa.descriptors, fb.descriptors, binary=fa.binary, mutual=True)
    pa, pb = fa.keypoints[m[:, 0]].astype(np.float64), fb.keypoints[m[:, 1]].astype(np.float64)
    good = np.linalg.norm(warp_points(pair.H, pa) - pb, axis=1) <= 3.0  # ||H x_1 - x_2|| <= 3 px
    return fa.keypoints, fb.keypoints, m, good


big = {"viewpoint": resize_pair(view_pair, settings.homography_size),
       "illumination": resize_pair(illum_pair, settings.homography_size)}
matched = {split: {name: mutual_matches(pair, name) for name in ("sift", "orb", "fast_freak")}
           for split, pair in big.items()}  # split -> detector -> (keypoints1, keypoints2, matches, correct)
fig = plot_match_grid({split: (pair.image1, pair.image2) for split, pair in big.items()}, matched, rng, max_drawn=150)
plt.show()
qualitative = {(split, name): (int(m[3].sum()), len(m[3])) for split, ms in matched.items() for name, m in ms.items()}
for (split, name), (good, total) in qualitative.items():
    print(f"{split:12s} {name:10s}: {good:4d} correct of {total:4d} mutual matches")
    assert 0 <= good <= total
view = {name: qualitative[("viewpoint", name)] for name in ("sift", "orb", "fast_freak")}
assert all(view["sift"][0] > v[0] and view["sift"][0] / view["sift"][1] > v[0] / v[1] for n, v in view.items() if n != "sift")
assert all(view["sift"][1] > v[1] for n, v in view.items() if n != "sift")  # and the most mutual matches
assert all(qualitative[("illumination", n)][1] < view[n][1] for n in view)  # fewer mutual matches under illumination

# %% [markdown]
# Pure nearest-neighbour matching always produces some wrong matches (red); RANSAC has to reject them. On the
# viewpoint pair SIFT's gradient-histogram descriptor gives the most matches and the largest fraction of correct
# ones; the binary descriptors (ORB, FREAK, compared by Hamming distance) give fewer, as in the thesis's
# Appendix B. On the illumination pair every correct match is a horizontal line (H = I): the geometry is trivial,
# and all the difficulty lies in detecting the same points under a different tone curve, shading and exposure and
# in describing them alike. The counts printed under the figure show how few mutual matches survive such a change:
# fewer than on the viewpoint pair for every method.
#
# ## 6. The event-frame split
#
# The thesis's second data set was made of 786 "reconstructed event images" from its UAV flight, each paired with a
# copy warped by a random homography "limited to small changes in rotation and translation" (§3.2.3); the images came
# from the recurrent reconstruction network of §4.1 (the kind of network lesson 04 trains). We build the pairs the
# same way but from a simpler image: the simulator's aerial preset, whose events of short windows we only **count**
# per pixel (**event-count images**, lesson 03), scaled to [0, 1], then warped by `event_frame_pairs`. A count image
# is a sparse edge map: most of its pixels saw no event (printed below), where a reconstruction fills in intensity
# everywhere, so do not expect this split to reproduce the thesis's Tables 3 and 5 (lesson 04's
# `create_reconstructor` would give the closer analogue). The thesis evaluated these at 240 x 320 with the best 100
# points (repeatability) and 1000 points (homography), NMS 4 throughout: `BenchmarkSettings.thesis_event_frames()`.
# Our event frames are 180 x 240 (the DAVIS240C's size), so the benchmark scales them up by 4/3 to 240 x 320, which
# softens their one-pixel edges a little.

# %%
n_frames = 2 if FAST else 8
window = 0.04  # s of events per frame
sequence = simulate_sequence(SimulationConfig(preset="aerial_like", duration=window * n_frames + 0.01, seed=3,
                                              with_frames=False))
width, height = sequence.camera.width, sequence.camera.height
frames = []
for k in range(n_frames):
    counts = event_count_image(events_between(sequence.events, k * window, (k + 1) * window), width, height)
    scale = max(np.percentile(counts, 99), 1.0)  # a few hot pixels should not darken the whole frame
    frames.append(np.clip(counts / scale, 0.0, 1.0).astype(np.float32))
event_pairs = event_frame_pairs(frames, SEED, pairs_per_frame=1)
print(f"{len(sequence.events)} events simulated -> {len(frames)} frames of {height} x {width}, "
      f"{len(event_pairs)} pairs")
empty_fraction = float(np.mean([f == 0 for f in frames]))
print(f"pixels without any event: {empty_fraction:.0%} (a count image is a sparse edge map)")
assert empty_fraction > 0.5

fig = plot_heatmap_row([event_pairs[0].image1, event_pairs[0].image2, frames[-1]],
                       ["event frame", "warped copy (image 2)", "another frame"], cmaps="gray", panel_in=4.3,
                       colorbar_labels={2: "events per pixel / 99th percentile, clipped at 1 (all three panels)"})
plt.show()
assert all(f.min() >= 0 and f.max() <= 1 and f.max() > 0 for f in frames)

# %% [markdown]
# ## 7. The benchmark: Tables 2-5
#
# `run_benchmark(detector, pairs, settings)` repeats sections 2 and 3 for every pair and averages per split. The
# rows are the classical detectors and the library's trained networks, one row per weights file in
# `evio_lib/weights/`.
#
# The full benchmark (58 held-out images x 5 pairs x 2 splits = 580 pairs, like HPatches) runs from the command
# line:
#
# ```
# python -m evio_lib features-benchmark --out DIR
# python -m evio_lib features-benchmark --dataset events --event-frames FRAMES.npy --out DIR
# ```
#
# This lesson runs a subset; the cell below prints how many pairs and which detectors. The network rows are:
# `pretrained_detdesc_round1_gpu` (one round of homographic adaptation, trained with more steps and data),
# `pretrained_detdesc_round2_cpu` (two rounds of a shorter training, the chain notebook 07 runs),
# `distilled_narrow`, a network with half the channels (about a quarter of the multiply-adds) trained to give the
# outputs of `pretrained_detdesc_round1_gpu` (knowledge distillation: a small network taught by a larger one; not in
# the thesis), and `photos_detdesc`, `pretrained_detdesc_round1_gpu` trained further on natural photographs with a
# loss that asks its points to follow the image (lesson 07, section 4). Their speed is in section 8. Each runs as the
# thesis's detector does, once on the image itself (`scales=(1.0,)`); section 11 runs the library's default, the
# same network on an image pyramid. With so few pairs a single pair moves a homography score by a step the cell
# prints; read the tables as trends, not as final results.

# %%
classical = [n for n in available_detectors() if n != "superpoint" and not n.startswith("superpoint")]
classical = ["harris", "fast", "sift"] if FAST else [n for n in classical if n in
                                                     ("harris", "shi_tomasi", "fast", "sift", "orb", "fast_freak")]
cnn = [(w, {"weights": w, "scales": (1.0,)}) for w in shipped_weights()]  # one row per file in evio_lib/weights/
if cnn:
    print("network rows:", [w for w, _ in cnn])
else:
    print("no trained network weights in evio_lib/weights/: the tables below have no network rows "
          "(notebook 07 trains them)")
print("classical rows:", classical)

n_images, per_image = (2, 1) if FAST else (8, 2)
bench_pairs = heldout_pairs(SEED, n_images=n_images, pairs_per_image=per_image)
n_view = sum(p.split == "viewpoint" for p in bench_pairs)
print(f"held-out benchmark: {len(bench_pairs)} pairs ({n_view} viewpoint, {len(bench_pairs) - n_view} illumination) "
      f"of {n_images} images; {len(event_pairs)} event-frame pairs; one pair moves a homography score by "
      f"1/{n_view} = {1 / n_view:.3f}")
assert len(bench_pairs) == 4 if FAST else 25 <= len(bench_pairs) <= 32

# %%
event_settings = BenchmarkSettings.thesis_event_frames()
calls = []  # two benchmark runs per detector: the held-out pairs, then the event-frame pairs
for name in classical + [w for w, _ in cnn]:
    options = dict(cnn).get(name) if name not in classical else None
    detector = "superpoint" if options else name
    calls += [dict(detector=detector, pairs=bench_pairs, settings=settings, name=name, detector_options=options),
              dict(detector=detector, pairs=event_pairs, settings=event_settings, name=name, detector_options=options)]
start = time.perf_counter()
results = map_in_workers(run_benchmark, calls, jobs=1 if FAST else None)
rows, event_rows = results[0::2], results[1::2]
print(f"benchmark of {len(rows)} detectors on {len(bench_pairs) + len(event_pairs)} pairs: "
      f"{time.perf_counter() - start:.1f} s")

# %% [markdown]
# **Table 2 — repeatability, HPatches-style held-out pairs** (240 x 320, best 300 points, NMS 4):

# %%
display(Markdown(format_table(rows, "repeatability")))

# %% [markdown]
# **Table 3 — repeatability, event frames** (240 x 320, best 100 points, NMS 4):

# %%
display(Markdown(format_table(event_rows, "repeatability")))

# %% [markdown]
# **Table 4 — homography estimation correctness, held-out pairs** (480 x 640, best 1000 points, NMS 8,
# mutual nearest neighbours + RANSAC):

# %%
display(Markdown(format_table(rows, "homography")))

# %% [markdown]
# **Table 5 — homography estimation correctness, event frames** (240 x 320, best 1000 points, NMS 4):

# %%
display(Markdown(format_table(event_rows, "homography")))

# %% [markdown]
# The descriptor metrics of section 4 on the same detections (held-out pairs):

# %%
display(Markdown("**Matching score**\n\n" + format_table(rows, "matching_score")))
display(Markdown("**Nearest-neighbour mAP**\n\n" + format_table(rows, "mAP")))

# %% [markdown]
# Two properties hold by construction and make a quick sanity check of the whole run: every metric is a fraction
# in [0, 1], and both repeatability and homography correctness can only grow with $\varepsilon$ (a point within
# 1 px is also within 3 px).

# %%
for row in rows + event_rows:
    for metric in ("repeatability", "homography"):
        for split, values in row[metric].items():
            v = np.array([values[e] for e in settings.eps])
            assert np.all((0 <= v) & (v <= 1)) and np.all(np.diff(v) >= 0), (row["detector"], metric, split, v)
print("all metrics in [0, 1] and non-decreasing in eps")

# %% [markdown]
# ## 8. Speed
#
# A VIO front end has to keep up with the camera. `measure_speed` times `detect_and_describe` (detection and
# description together, one image at a time, after warm-up calls) at the DAVIS resolution 180 x 240 and at the
# thesis's evaluation size 240 x 320. Compare each row with the camera: a front end that detects in every image of a
# 20 Hz camera needs 20 frames/s, one that detects only in key frames and tracks in between needs fewer. The numbers
# depend on the machine and on what else runs on it: on a busy machine single timings scatter widely, so compare the
# classical rows with the network rows rather than the networks with one another.

# %%
timing_images = [p.image1 for p in bench_pairs[: 2 if FAST else 4]]
for row in rows:
    name = row["detector"]
    options = dict(cnn).get(name) if name not in classical else None
    detector = "superpoint" if options else name
    row["speed"] = {}
    for shape in ((180, 240), (240, 320)):
        row["speed"][f"{shape[0]}x{shape[1]}"] = measure_speed(detector, timing_images, shape,
                                                               n_frames=5 if FAST else 20, detector_options=options)
display(Markdown(format_table(rows, "speed")))

# %% [markdown]
# ## 9. How do the numbers compare with the thesis?
#
# The thesis's classical rows (Tables 2 and 4, HPatches) are printed next to ours below. Keep three differences in
# mind before comparing:
#
# * **different images**: HPatches has real photographs of real planar scenes taken with real cameras; our pairs
#   are synthetic warps of held-out images, so there is no parallax, no motion blur and no change of camera
#   between the two images of a pair. Our viewpoint homographies (`VIEWPOINT_HOMOGRAPHY`) also zoom in by about
#   1.5x (section 10 measures it);
# * **illumination**: HPatches' illumination scenes contain real light changes; ours are a model of them (tone
#   curve, shading, exposure, noise; `illumination_change`). Harsher or milder settings move every row;
# * **few pairs**: this lesson runs a small subset of the 580-pair benchmark.
#
# What to look for is the *ranking*, not the third decimal. In the thesis's Table 2 Harris is the most repeatable
# detector on the viewpoint scenes at $\varepsilon = 3, 5$ (0.758 / 0.868, §4.3) and SIFT's blob centres the least
# repeatable of the classical rows (0.486 / 0.685), yet in Table 4 SIFT's descriptor makes it the best classical
# method for viewpoint homographies (0.464 / 0.769 / 0.831), and ORB is the weakest (0.061 / 0.386 / 0.536). The
# thesis's trained networks mainly win on the **illumination** split, where a detector and descriptor learned under
# photometric augmentation cope better with a changed tone curve. The cells below print the thesis's classical rows
# next to ours and say which of these rankings our tables keep.
#
# The event-frame split is easier than the held-out pairs (rotations of at most 10°, a zoom of about 1.1 instead of
# about 1.5, no perspective, no added noise), so its homography scores are close to 1 for most methods, as in the
# thesis's Table 5 at $\varepsilon = 3, 5$.

# %%
thesis = {  # Table 2 (repeatability, HPatches) and Table 4 (homography estimation, HPatches); eps = 1, 3, 5
    ("repeatability", "fast"): ([0.294, 0.630, 0.786], [0.363, 0.574, 0.716]),
    ("repeatability", "harris"): ([0.312, 0.758, 0.868], [0.372, 0.627, 0.752]),
    ("repeatability", "sift"): ([0.260, 0.486, 0.685], [0.278, 0.434, 0.595]),
    ("homography", "fast_freak"): ([0.288, 0.590, 0.712], [0.551, 0.758, 0.789]),
    ("homography", "orb"): ([0.061, 0.386, 0.536], [0.232, 0.530, 0.593]),
    ("homography", "sift"): ([0.464, 0.769, 0.831], [0.540, 0.779, 0.825]),
}
by_name = {row["detector"]: row for row in rows}
lines = ["| metric | detector | split | thesis ε = 1 / 3 / 5 | this run ε = 1 / 3 / 5 |", "|---|---|---|---|---|"]
for (metric, name), (view, illum) in thesis.items():
    if name not in by_name:
        continue
    for split, ref in (("viewpoint", view), ("illumination", illum)):
        ours = [by_name[name][metric][split][e] for e in settings.eps]
        lines.append(f"| {metric} | {name} | {split} | {' / '.join(f'{v:.3f}' for v in ref)} | "
                     f"{' / '.join(f'{v:.3f}' for v in ours)} |")
display(Markdown("\n".join(lines)))

# %% [markdown]
# The best row of each split at $\varepsilon = 3$, and which of the thesis's rankings our tables keep:

# %%
for metric, split in (("repeatability", "viewpoint"), ("repeatability", "illumination"),
                      ("homography", "viewpoint"), ("homography", "illumination")):
    best = max(rows, key=lambda r: r[metric][split][3.0])
    print(f"best {metric:13s} on {split:12s} at eps = 3: {best['detector']} ({best[metric][split][3.0]:.3f})")
assert all(thesis[("repeatability", "harris")][0][k] > thesis[("repeatability", n)][0][k]  # the quoted ranking
           for n in ("fast", "sift") for k in (1, 2))
assert all(thesis[("homography", "sift")][0][k] > thesis[("homography", n)][0][k] > thesis[("homography", "orb")][0][k]
           for n in ("fast_freak",) for k in range(3))
sift_view = [by_name["sift"]["homography"]["viewpoint"][e] for e in settings.eps]
print("SIFT viewpoint homography, this run:", np.round(sift_view, 3), " thesis:", thesis[("homography", "sift")][0])
if not FAST:  # 16 viewpoint pairs: SIFT scores below its thesis row at every eps
    assert all(ours < ref for ours, ref in zip(sift_view, thesis[("homography", "sift")][0]))
if "sift" in by_name and "orb" in by_name:
    assert by_name["sift"]["homography"]["viewpoint"][3.0] >= by_name["orb"]["homography"]["viewpoint"][3.0]
event_hom = [next(iter(row["homography"].values())) for row in event_rows]  # the event split's scores per detector
print("event-frame homography correctness at eps = 3 / 5:", [(row["detector"], h[3.0], h[5.0])
                                                              for row, h in zip(event_rows, event_hom)])
assert np.mean([min(h[3.0], h[5.0]) >= 0.85 for h in event_hom]) > 0.5  # close to 1 for most methods


def ranked(metric: str, split: str, names: list[str]) -> list[str]:
    """The detectors ``names`` from best to worst in ``metric`` on ``split`` at eps = 3."""
    return sorted(names, key=lambda n: -by_name[n][metric][split][3.0])


def listed(metric: str, split: str, names: list[str]) -> str:
    return ", ".join(f"{n} {by_name[n][metric][split][3.0]:.3f}" for n in ranked(metric, split, names))


def ordinal(k: int) -> str:
    return f"{k}{'st' if k == 1 else 'nd' if k == 2 else 'rd' if k == 3 else 'th'}"


rep_order = ranked("repeatability", "viewpoint", classical)
hom_order = ranked("homography", "viewpoint", classical)
harris_first = rep_order[0] == "harris"
sift_last = rep_order[-1] == "sift"
below = all(o < r for o, r in zip(sift_view, thesis[("homography", "sift")][0]))
text = (f"**Repeatability (Table 2).** On our viewpoint split at ε = 3 the classical detectors rank: "
        f"{listed('repeatability', 'viewpoint', classical)}. ")
if harris_first and sift_last:
    text += "That is the thesis's order at its ends: Harris first, SIFT last. "
else:
    text += (f"This does **not** keep the thesis's order: Harris, its most repeatable detector, comes "
             f"{ordinal(rep_order.index('harris') + 1)} of {len(rep_order)} here, and SIFT, its least repeatable "
             f"classical row, comes {ordinal(rep_order.index('sift') + 1)}. Our viewpoint pairs differ from "
             f"HPatches, and from lesson 05's milder homographies, above all by their zoom of about "
             f"{np.median([np.sqrt(abs(np.linalg.det(p.H[:2, :2]))) for p in bench_pairs if p.split == 'viewpoint']):.1f}x, "
             f"and SIFT is the only one of these detectors that searches over scale; whether that is what reorders "
             f"them, this lesson does not measure. ")
text += (f"\n\n**Homography estimation (Table 4).** On the viewpoint split at ε = 3: "
         f"{listed('homography', 'viewpoint', classical)}. SIFT is "
         f"{'the best classical method, as in the thesis' if hom_order[0] == 'sift' else 'not the best classical method here'}")
if "orb" in by_name:
    text += f"; ORB, the thesis's weakest, scores {by_name['orb']['homography']['viewpoint'][3.0]:.3f}"
text += (f". SIFT's own scores, {' / '.join(f'{v:.3f}' for v in sift_view)} at ε = 1 / 3 / 5, are "
         + ("below its thesis row (0.464 / 0.769 / 0.831) at every ε: by this measure our viewpoint split is harder "
            "than HPatches for SIFT." if below else "beside its thesis row of 0.464 / 0.769 / 0.831."))
display(Markdown(text))

# %% [markdown]
# The claims about the trained networks, on the illumination split and on the event frames:

# %%
if cnn:
    best = {}
    for metric in ("repeatability", "homography"):
        best[metric] = {kind: max(by_name[n][metric]["illumination"][3.0] for n in names)
                        for kind, names in (("cnn", [w for w, _ in cnn]), ("classical", classical))}
        print(f"illumination {metric} at eps = 3: best network {best[metric]['cnn']:.3f}, "
              f"best classical {best[metric]['classical']:.3f}")
    best_hom1 = {kind: max(by_name[n]["homography"]["illumination"][1.0] for n in names)
                 for kind, names in (("cnn", [w for w, _ in cnn]), ("classical", classical))}
    assert best["repeatability"]["cnn"] > best["repeatability"]["classical"]  # the thesis's claim holds here
    assert best["homography"]["cnn"] <= best["homography"]["classical"]  # ... but not for homographies
    assert by_name["harris"]["homography"]["illumination"][3.0] == best["homography"]["classical"]  # Harris: the best
    event_rep = {row["detector"]: row["repeatability"]["event"][3.0] if "event" in row["repeatability"]
                 else next(iter(row["repeatability"].values()))[3.0] for row in event_rows}
    print("event-frame repeatability at eps = 3:", {n: round(v, 3) for n, v in event_rep.items()})
    assert all(event_rep[w] < event_rep["harris"] for w, _ in cnn)  # Harris leads, as in the thesis
    for w in ("pretrained_detdesc_round1_gpu", "distilled_narrow"):  # near SIFT and FAST, clearly below Harris
        if w in event_rep:
            assert all(abs(event_rep[w] - event_rep[n]) < 0.1 for n in ("sift", "fast")), w
            assert event_rep[w] < event_rep["harris"] - 0.1, w
    assert "pretrained_detdesc_round2_cpu" not in event_rep or \
        event_rep["pretrained_detdesc_round2_cpu"] < 0.5 * event_rep["harris"]  # less than half of Harris
    thesis_table3 = {"Harris": 0.885, "Pre-trained DetDesc (Round 2)": 0.839}  # the thesis's best network, eps = 3
    networks = ", ".join(f"`{w}` {event_rep[w]:.3f}" for w in sorted(event_rep, key=lambda n: -event_rep[n])
                         if w in dict(cnn))
    display(Markdown(
        f"**The illumination claim, checked.** On the illumination split at ε = 3 the best network repeats "
        f"{best['repeatability']['cnn']:.3f} of the points, the best classical detector "
        f"{best['repeatability']['classical']:.3f}: the thesis's claim holds for repeatability. At ε = 3 it does "
        f"not carry over "
        f"to homography estimation: the best network estimates no more of the illumination homographies correctly "
        f"({best['homography']['cnn']:.3f}) than Harris, the best classical method here "
        f"({best['homography']['classical']:.3f}); at the strict ε = 1 the best network scores "
        f"{best_hom1['cnn']:.3f} against the best classical method's {best_hom1['classical']:.3f}"
        + (" (Table 4): the networks' gain in repeatability shows in homographies only at 1 px. "
           if best_hom1["cnn"] > best_hom1["classical"] else ". ")
        + f"Repeating the same points is not enough; the descriptors must also "
        f"match them and the points must sit accurately enough for RANSAC, which section 10 looks at on the "
        f"viewpoint split (exercise 6 on the illumination split).\n\n"
        f"**The event frames** (Table 3) tell a different story from the thesis's. There, Harris was also the most "
        f"repeatable at ε = 3 ({thesis_table3['Harris']}), and its best network came close "
        f"({thesis_table3['Pre-trained DetDesc (Round 2)']}). Here Harris repeats {event_rep['harris']:.3f} and the "
        f"networks fall behind: {networks}, against SIFT's {event_rep['sift']:.3f} and FAST's "
        f"{event_rep['fast']:.3f}. None of these networks saw an event frame in training (the thesis's Events "
        f"variants, trained with event frames among their images, gained nothing from it either, §4.3), and our "
        f"event frames are thin count images, mostly empty (section 6), far from the photographs the networks "
        f"learned on, while the thesis's were reconstructed intensity images."))

# %% [markdown]
# ## 10. Why do the networks lose the viewpoint split? Matching, selection or localisation
#
# On the viewpoint split SIFT estimates homographies correctly more often than the project's networks do on average
# (Table 4 above), and never less often than any one of them. Three different failures give the same wrong
# $\hat H$:
#
# * **matching**: too few correct matches among the mutual nearest neighbours, so RANSAC has little to fit;
# * **selection**: enough correct matches, but RANSAC settles on a fit that keeps some wrong ones or drops right ones;
# * **localisation**: each keypoint sits a little off the true point. A homography fitted to them is extrapolated
#   to image 1's corners, far outside the zoomed-in patch that the matches cover, and an error of 1 px at the
#   keypoints becomes several px at the corners.
#
# `diagnose_matches` separates them. It counts the correct matches (error $e_k = \lVert H\mathbf x_{1,k} -
# \mathbf x_{2,k}\rVert \le 3$ px), averages their error $e_k$ (the **localisation error**), and fits an
# **oracle** homography to all the correct matches and nothing else, by least squares: what a perfect outlier
# rejection would fit. Where RANSAC fails and the oracle succeeds, selection was the trouble; where the oracle fails
# too, the correct matches themselves do not pin the corners down. If the keypoints' errors were independent, least
# squares would average them, and the oracle's corner error would shrink as (localisation error) /
# $\sqrt{\text{number of correct matches}}$ times a factor for the extrapolation to the corners. First the oracle by
# hand on one pair, with that factor measured there by adding independent Gaussian errors of the same size to the
# true positions of the same points; then every detector on a set of viewpoint pairs.

# %%
# row name -> (detector name, its options); diagnose_pairs creates each at the homography task's settings
diag_detectors = {"sift": ("sift", None)} | ({} if FAST else {"harris": ("harris", None)})
diag_detectors |= {w: ("superpoint", options) for w, options in cnn}

# the oracle by hand on the pair of section 3, with SIFT's matches from there
err_k = np.linalg.norm(warp_points(large.H, g1.keypoints[matches[:, 0]]) - g2.keypoints[matches[:, 1]], axis=1)
good = err_k <= 3.0
H_oracle, _ = cv2.findHomography(g1.keypoints[matches[good, 0]], g2.keypoints[matches[good, 1]], 0)  # least squares
diag = diagnose_matches(g1.keypoints, g2.keypoints, g1.descriptors, g2.descriptors, large.H, large.image1.shape)
print(f"by hand: {good.sum()} correct of {len(matches)}, localisation error {err_k[good].mean():.3f} px, "
      f"oracle corner error {corner_error(H_oracle, large.H, large.image1.shape):.3f} px")
print("library:", diag)
assert diag.n_correct == good.sum() and np.isclose(diag.localisation_error, err_k[good].mean())
assert np.isclose(diag.corner_error_oracle, corner_error(H_oracle, large.H, large.image1.shape), atol=1e-3)

# the same fit with independent Gaussian errors of the same mean length on the same points: the extrapolation alone
sigma_axis = err_k[good].mean() / np.sqrt(np.pi / 2)  # per-axis sigma whose mean error length is the measured one
points1 = g1.keypoints[matches[good, 0]].astype(np.float64)
true2 = warp_points(large.H, points1)  # where the correct matches should be in image 2
sim_rng = np.random.default_rng(SEED)
simulated = [corner_error(cv2.findHomography(points1, true2 + sim_rng.normal(0.0, sigma_axis, true2.shape), 0)[0],
                          large.H, large.image1.shape) for _ in range(200)]
per_point = err_k[good].mean() / np.sqrt(good.sum())  # localisation error / sqrt(n)
independent_factor, measured_factor = np.median(simulated) / per_point, diag.corner_error_oracle / per_point
print(f"oracle corner error / (localisation error / sqrt(n)) on this pair: {measured_factor:.1f} measured, "
      f"{independent_factor:.1f} with independent errors of the same size (median of {len(simulated)} draws)")
assert independent_factor > 3  # the extrapolation to the corners alone multiplies the error

# %%
diag_pairs = heldout_pairs(SEED, n_images=3 if FAST else 12, pairs_per_image=2, splits=("viewpoint",))
# diagnose_pairs runs diagnose_matches on every pair; one row per pair, columns: the fields of MatchDiagnosis
calls = [dict(detector=detector, pairs=diag_pairs, settings=settings, detector_options=options)
         for detector, options in diag_detectors.values()]
diagnoses = dict(zip(diag_detectors, map_in_workers(diagnose_pairs, calls, jobs=1 if FAST else None)))

lines = ["| detector | correct matches | localisation error (px) | RANSAC correct, ε = 3 | oracle correct, ε = 3 |",
         "|---|---|---|---|---|"]
for name, d in diagnoses.items():
    lines.append(f"| {name} | {d[:, 1].mean():.1f} | {np.nanmean(d[:, 2]):.2f} | {(d[:, 3] <= 3).mean():.2f} | "
                 f"{(d[:, 4] <= 3).mean():.2f} |")
display(Markdown(f"{len(diag_pairs)} viewpoint pairs (held-out images, 480 x 640, best 1000 points, NMS 8)\n\n"
                 + "\n".join(lines)))

fig = plot_oracle_corner_errors({name: (d[:, 1], d[:, 4]) for name, d in diagnoses.items()}, eps=3.0)
plt.show()
print("in the scatter: errors are clipped at 1000 px, so the top edge holds every pair whose oracle fit is off by "
      "that much or more, and the pairs with fewer than 4 correct matches (no homography); a pair with none sits at "
      "x = 1")

# %% [markdown]
# The checks behind the reading of the table: each network's localisation error against SIFT's, how often the
# oracle misses 3 px, and the oracle's corner error against (localisation error) / $\sqrt n$:

# %%
sift_error = np.nanmean(diagnoses["sift"][:, 2])
for w, _ in cnn:
    d = diagnoses[w]
    ratio = np.nanmean(d[:, 2]) / sift_error
    print(f"{w}: localisation error {np.nanmean(d[:, 2]):.2f} px vs SIFT {sift_error:.2f} px ({ratio:.1f}x); "
          f"at least 4 correct matches on {np.mean(d[:, 1] >= 4):.0%} of the pairs; the oracle misses 3 px on "
          f"{np.mean(~(d[:, 4] <= 3)):.0%}")
    assert 1.15 < ratio < 2.05  # SIFT's correct matches are the better localised
    assert np.mean(d[:, 1]) < np.mean(diagnoses["sift"][:, 1])  # and more numerous
    assert np.mean(d[:, 1] >= 4) > 0.5  # enough correct matches for a homography on most pairs
oracle_misses = {w: np.mean(~(diagnoses[w][:, 4] <= 3)) for w, _ in cnn}
assert np.mean(list(oracle_misses.values())) >= 0.25  # even the oracle misses on many of the networks' pairs
excess = {}
for name, d in diagnoses.items():  # oracle corner error against what independent errors would leave
    fitted = d[:, 1] >= 4
    excess[name] = np.median(d[fitted, 4] / (d[fitted, 2] / np.sqrt(d[fitted, 1])))
    print(f"{name}: oracle corner error / (localisation error / sqrt(correct matches)), median over "
          f"{fitted.sum()} pairs: {excess[name]:.1f}")
    assert excess[name] > 3, name  # far above 1: extrapolating to the corners multiplies the error
sift_view3 = by_name["sift"]["homography"]["viewpoint"][3.0]
cnn_view3 = [by_name[w]["homography"]["viewpoint"][3.0] for w, _ in cnn]
assert sift_view3 >= max(cnn_view3) and sift_view3 > np.mean(cnn_view3)  # section 10's opening sentence
zoom = [np.sqrt(abs(np.linalg.det(p.H[:2, :2]))) for p in diag_pairs]  # linear scale of each viewpoint homography
print(f"zoom of the viewpoint pairs: median {np.median(zoom):.2f}x (patch ratio {VIEWPOINT_HOMOGRAPHY['patch_ratio']})")
assert 1.3 < np.median(zoom) < 1.8 and VIEWPOINT_HOMOGRAPHY["patch_ratio"] == 0.65
pooled = np.vstack(list(diagnoses.values()))
fitted = (pooled[:, 1] >= 4) & np.isfinite(pooled[:, 4])
rho = spearmanr(pooled[fitted, 1], pooled[fitted, 4]).statistic  # correct matches against the oracle's error
print(f"rank correlation of correct matches and oracle corner error over {fitted.sum()} pairs: {rho:.2f}")

# %% [markdown]
# Read the table from left to right (every number below is from the cells above):

# %%
nets = [w for w, _ in cnn]
def span(values, f="{:.2f}"):
    low, high = f.format(min(values)), f.format(max(values))
    return low if low == high else f"{low} to {high}"



col = lambda name, k: diagnoses[name][:, k]
ransac = {n: np.mean(col(n, 3) <= 3) for n in diagnoses}
oracle = {n: np.mean(col(n, 4) <= 3) for n in diagnoses}
median_oracle = {n: np.median(col(n, 4)) for n in diagnoses}
text = (
    f"* **Matching.** The networks find at least four correct matches (enough for a homography) on "
    f"{span([np.mean(col(w, 1) >= 4) for w in nets], '{:.0%}')} of the pairs, but fewer than SIFT: "
    f"{span([np.mean(col(w, 1)) for w in nets], '{:.0f}')} per pair on average against SIFT's "
    f"{np.mean(col('sift', 1)):.0f}.\n"
    f"* **Localisation.** Their correct matches sit {span([np.nanmean(col(w, 2)) / sift_error for w in nets], '{:.1f}')} "
    f"times as far from the truth as SIFT's ({span([np.nanmean(col(w, 2)) for w in nets])} px against "
    f"{sift_error:.2f} px). SIFT fits each keypoint to a sub-pixel extremum of its scale space, so a zoomed copy of "
    f"a blob is found at the same scene point; a detector that works at one scale fires a little inside or outside "
    f"a corner depending on the zoom (about {np.median(zoom):.1f}x here)"
    + (f"; Harris, a corner detector too, has {np.nanmean(col('harris', 2)):.2f} px" if "harris" in diagnoses
       else "") + ".\n"
    f"* **Selection.** The oracle estimates {span([oracle[w] for w in nets])} of the network pairs correctly at 3 px, "
    f"RANSAC {span([ransac[w] for w in nets])} (SIFT: oracle {oracle['sift']:.2f}, RANSAC {ransac['sift']:.2f})"
    + (": for the networks, which matches are kept matters" if all(oracle[w] > ransac[w] for w in nets) else "")
    + f". Yet even the oracle misses 3 px on "
    f"{span([1 - oracle[w] for w in nets], '{:.0%}')} of the network pairs (SIFT {1 - oracle['sift']:.0%}).\n"
    f"* **More matches help, slowly.** Over all pairs, a pair with more correct matches tends to have "
    + ("a smaller" if rho < 0 else "no smaller")
    + f" oracle corner error (rank correlation {rho:.2f}; the scatter above). The oracle's error is "
    f"{span([excess[w] for w in nets], '{:.0f}')} times (localisation error) / √n for the networks and "
    f"{excess['sift']:.0f} times for SIFT. Independent errors of the same size on section 3's pair give "
    f"{independent_factor:.0f} times ({measured_factor:.1f} measured there): "
    + ("the extrapolation to the far corners alone multiplies the error by a factor of that order, so these "
       "factors are no "
       "sign of errors that depend on each other. " if independent_factor >= 0.5 * min(excess.values())
       else "more than the extrapolation alone explains: the keypoints' errors do not average out as independent ones "
         "would. ")
    + f"With a factor of that size, the networks' larger localisation error over "
    f"fewer correct matches is enough to put many of their pairs past 3 px even with the oracle. The median oracle "
    f"corner error is {median_oracle['sift']:.1f} px for SIFT against "
    f"{span([median_oracle[w] for w in nets], '{:.1f}')} px for the networks.\n\n"
    "Better localisation under a change of scale, more correct matches and a sharper outlier rejection would each "
    "help the networks. Section 11 gives the network the freedom SIFT has, a choice of scale; section 13 says why "
    "the localisation matters for the filter as well.")
display(Markdown(text))

# %% [markdown]
# ## 11. One network, several scales: an image pyramid
#
# SIFT finds each blob at the scale where it responds most, so a zoomed copy of the blob is found and described at
# the zoomed scale. The network has one receptive field in pixels: after a 1.5x zoom its 8 x 8 cells and its
# descriptor see a different neighbourhood of the same point. It can be given SIFT's freedom without any training:
# run it on resized copies of the image, an **image pyramid**, and pool what every level finds.
#
# ```
#   image 1                           image 2 = image 1 zoomed by z = 1.5
#   level 1.41  ##############         level 1.41  ##############
#   level 1.19  ############           level 1.19  ############
#   level 1.00  ##########  ---+       level 1.00  ##########
#   level 0.84  ########       |       level 0.84  ########
#   level 0.71  #######        +--->   level 0.71  #######     a corner of image 1's level 1 has the same
#   level 0.59  ######                 level 0.59  ######      size in pixels at image 2's level 1 / z = 0.67
#   level 0.50  #####                  level 0.50  #####       (0.71 is the nearest level)
# ```
#
# A corner seen at level $s$ of image 1 looks the same size at level $s/z$ of image 2. With levels a factor
# $2^{1/4}$ apart, some level of image 2 lies within a factor $2^{1/8} \approx 1.09$ of $s/z$ whenever $s/z$ falls
# inside image 2's range, so the pair has descriptors computed at nearly the same scale. Each level keeps its own
# NMS in its own pixels; a level's keypoint $(x_s, y_s)$ maps back to the image as
# $x = (x_s + \tfrac12)\,W/W_s - \tfrac12$ (and likewise $y$), and the best 1000 points of all levels by probability
# are kept. Levels above 1 are enlarged copies: the network's cells then cover less of the scene, which also places
# its points more finely.
#
# `create_detector("superpoint")` does this by default (`scales="auto"`): levels $2^{-k/4}$ down to a shorter side
# of 240 px plus two enlarged ones on top, and a single level for images too small to shrink once without falling
# under 240 px, such as the 180 x 240 event frames the pipeline uses. The cell prints the levels and what they cost.

# %%
from evio_lib.features.network import DEFAULT_WEIGHTS, pyramid_scales

levels = pyramid_scales(settings.homography_size)
cost = sum(s * s for s in levels)  # pixels of all levels over those of the image
print(f"levels of a {settings.homography_size[0]} x {settings.homography_size[1]} image: {np.round(levels, 2)}: "
      f"{cost:.1f} times the pixels of the image")
print("levels of a 180 x 240 event frame:", pyramid_scales((180, 240)))
assert levels[-1] * min(settings.homography_size) >= 240 and pyramid_scales((180, 240)) == (1.0,)

# %% [markdown]
# The diagnosis of section 10 again, on the same viewpoint pairs, for the weights `create_detector("superpoint")`
# loads (the table names them) once on the image (their row of section 10) and on their pyramid, with SIFT's row of
# section 10 beside them:

# %%
pyramid = diagnose_pairs("superpoint", diag_pairs, settings)  # default weights, scales="auto"
cpu_seconds = {}
for label, scales in (("pyramid", "auto"), ("one level", (1.0,))):
    timed = create_detector("superpoint", max_keypoints=1000, nms_radius=8, scales=scales)
    timed.detect_and_describe(large.image1)  # warm-up
    start = time.process_time()
    timed.detect_and_describe(large.image1)
    cpu_seconds[label] = time.process_time() - start
print(f"CPU time of one {large.image1.shape[0]} x {large.image1.shape[1]} detection: "
      f"pyramid {cpu_seconds['pyramid']:.2f} s, one level {cpu_seconds['one level']:.2f} s")
compared = {"sift": diagnoses["sift"], f"{DEFAULT_WEIGHTS}, one level": diagnoses[DEFAULT_WEIGHTS],
            f"{DEFAULT_WEIGHTS}, pyramid": pyramid}
lines = ["| detector | correct matches | localisation error (px) | RANSAC correct, ε = 1 | RANSAC correct, ε = 3 |",
         "|---|---|---|---|---|"]
for name, d in compared.items():
    lines.append(f"| {name} | {d[:, 1].mean():.1f} | {np.nanmean(d[:, 2]):.2f} | {(d[:, 3] <= 1).mean():.2f} | "
                 f"{(d[:, 3] <= 3).mean():.2f} |")
display(Markdown(f"{len(diag_pairs)} viewpoint pairs (held-out images, 480 x 640, best 1000 points, NMS 8)\n\n"
                 + "\n".join(lines)))

fig, ax = plt.subplots(figsize=(6.5, 3.0))
for k, eps_k in enumerate((1.0, 3.0)):
    ax.bar(np.arange(3) + 0.38 * k, [(d[:, 3] <= eps_k).mean() for d in compared.values()], width=0.36,
           label=f"ε = {eps_k:g} px")
ax.set_xticks(np.arange(3) + 0.19, ["SIFT", "network, one level", "network, pyramid"])
ax.set_ylabel("RANSAC homography correct")
ax.set_ylim(0, 1)
ax.legend()
ax.set_title("Viewpoint pairs: the same network with and without a pyramid")
plt.show()

one = diagnoses[DEFAULT_WEIGHTS]
assert pyramid[:, 1].mean() > one[:, 1].mean()  # more correct matches than at one level
assert (pyramid[:, 3] <= 3).mean() > (one[:, 3] <= 3).mean()  # more homographies within 3 px (the summary)
assert np.nanmean(pyramid[:, 2]) < np.nanmean(one[:, 2])  # and better placed matches

# %% [markdown]
# What the pyramid changes (every number from the table above):

# %%
sift_d = diagnoses["sift"]
ransac3 = {name: (d[:, 3] <= 3).mean() for name, d in compared.items()}
text = (
    f"* **Matching.** The pyramid gives {pyramid[:, 1].mean():.0f} correct matches per pair against "
    f"{one[:, 1].mean():.0f} for the same network on the image alone, {pyramid[:, 1].mean() / one[:, 1].mean():.1f} "
    f"times as many (SIFT {sift_d[:, 1].mean():.0f}).\n"
    f"* **Localisation.** Their error is {np.nanmean(pyramid[:, 2]):.2f} px against {np.nanmean(one[:, 2]):.2f} px "
    f"at one level and SIFT's {np.nanmean(sift_d[:, 2]):.2f} px"
    + (": still SIFT's points sit closer to the truth." if np.nanmean(pyramid[:, 2]) > np.nanmean(sift_d[:, 2])
       else ".") + "\n"
    f"* **Homographies.** RANSAC estimates {ransac3[f'{DEFAULT_WEIGHTS}, pyramid']:.2f} of the pairs within 3 px "
    f"with the pyramid, {ransac3[f'{DEFAULT_WEIGHTS}, one level']:.2f} without it, SIFT {ransac3['sift']:.2f}.\n"
    f"* **Cost.** The network runs on {cost:.1f} times the pixels: one 480 x 640 image took "
    f"{cpu_seconds['pyramid']:.2f} s of CPU with the pyramid and {cpu_seconds['one level']:.2f} s at one level "
    f"(the line above the table). The 180 x 240 frames of the pipeline keep one level and their speed.")
display(Markdown(text))

# %% [markdown]
# ## 12. Natural photographs
#
# The held-out pool mixes photographs with renders of the simulated scenes and procedural textures; HPatches, the
# thesis's benchmark, is all photographs of real scenes. `photo_pairs` builds the same viewpoint and illumination
# pairs from natural photographs: the test split of a photograph folder (each photograph assigned to train,
# validation or test by a hash of its name; the networks never trained on the test photographs), centre-cropped to
# 3:4 and resized to 480 x 640. The folder is not part of the course: `default_photo_folder()` finds one beside the
# checkout or through `$EVIO_PHOTOS`, and the section is skipped without it.
#
# Two networks against SIFT, both on the pyramid of section 11: `pretrained_detdesc_round1_gpu`, trained on the
# project's pool, and `photos_detdesc`, the same network trained further on the training photographs (lesson 07,
# section 4), which is what `create_detector("superpoint")` loads (the cell prints its name).

# %%
from evio_lib.features.evaluation.benchmark import photo_pairs
from evio_lib.sim.photos import default_photo_folder, list_photos

photo_folder = default_photo_folder()
photo_rows = []
if photo_folder is None:
    print("no photograph folder found (../shared/data/photos or $EVIO_PHOTOS): this section is skipped")
else:
    n_photos = 2 if FAST else 8
    real_pairs = photo_pairs(photo_folder, "test", SEED, n_images=n_photos, pairs_per_image=1)
    n_real_view = sum(p.split == "viewpoint" for p in real_pairs)
    n_test = len(list_photos(photo_folder, "test"))  # the whole test split
    print(f"{len(real_pairs)} pairs ({n_real_view} viewpoint) of {n_photos} test photographs, 480 x 640; "
          f"create_detector('superpoint') loads {DEFAULT_WEIGHTS}; one pair moves a score by 1/{n_real_view}")
    photo_calls = [dict(detector="sift", pairs=real_pairs, settings=settings, name="sift")]
    photo_calls += [dict(detector="superpoint", pairs=real_pairs, settings=settings, name=f"{w}, pyramid",
                         detector_options={"weights": w}) for w in ("pretrained_detdesc_round1_gpu", "photos_detdesc")
                    if w in shipped_weights()]
    start = time.perf_counter()
    photo_rows = map_in_workers(run_benchmark, photo_calls, jobs=1 if FAST else None)
    print(f"benchmark of {len(photo_rows)} detectors: {time.perf_counter() - start:.1f} s")
    display(Markdown("**Homography estimation correctness, test photographs** (480 x 640, best 1000 points, NMS 8)"
                     "\n\n" + format_table(photo_rows, "homography")))
for row in photo_rows:
    for split, values in row["homography"].items():
        v = np.array([values[e] for e in settings.eps])
        assert np.all((0 <= v) & (v <= 1)) and np.all(np.diff(v) >= 0), (row["detector"], split, v)

# %% [markdown]
# What the table says (the sentences are computed from it):

# %%
if photo_rows:
    he3 = {row["detector"]: row["homography"]["viewpoint"][3.0] for row in photo_rows}
    il1 = {row["detector"]: row["homography"]["illumination"][1.0] for row in photo_rows}
    best3 = max(he3.values())

    def label(name: str) -> str:
        """a row's name as the table prints it"""
        return "SIFT" if name == "sift" else f"`{name}`"

    def listed(items: list[str]) -> str:
        """'a', 'a and b', 'a, b and c'"""
        return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]

    leaders = [label(name) for name, v in he3.items() if v == best3]
    behind = [f"{label(name)} {v:.3f}" for name, v in he3.items() if v < best3]
    nets = [row for row in photo_rows if row["detector"] != "sift"]
    cells = [[row["homography"][split][e] for split in ("viewpoint", "illumination") for e in settings.eps]
             for row in nets]
    differ = sum(a != b for a, b in zip(*cells)) if len(cells) == 2 else 0
    same = len(cells) == 2 and differ == 0
    display(Markdown(
        "On these viewpoint pairs at ε = 3 " + ("the best row is " if len(leaders) == 1 else "the best rows are ")
        + listed(leaders) + f" ({best3:.3f})" + (f"; then {listed(behind)}" if behind else "")
        + ". On the illumination pairs at ε = 1: "
        + listed([f"{label(name)} {v:.3f}" for name, v in il1.items()]) + ". "
        + ("The two networks score alike in every column of the table. " if same else
           "The fine-tuned network and the one it started from differ in " f"{differ} of the table's six columns. ")
        + f"With {n_real_view} pairs per split one pair is a step of {1 / n_real_view:.3f}: the whole test split "
        f"({n_test} photographs, 5 pairs of each per split) is a command away, "
        "`python -m evio_lib features-benchmark --dataset photos --out DIR`, and its numbers are in "
        "docs/results/features.md."))

# %% [markdown]
# ## 13. From features to the filter
#
# The rest of the course builds the back end, the MSCKF, which turns feature tracks and IMU samples into a trajectory.
# The benchmarks above grade detectors on pairs of images; the filter asks for something slightly different:
#
# * **tracks**, not pairs: the same scene point found again in several consecutive images (a track needs at least
#   three observations to be used), so the front end matches each image to the previous one and keeps the track ids;
# * **parallax**: a point seen from nearly the same place has an unknown depth, so long tracks over a moving camera are
#   worth more than many short ones (notebook 12 triangulates them);
# * **accuracy in pixels**: every observation enters the filter with an assumed noise $\sigma$ per axis (the line
#   below prints it, and the mean distance $\sigma\sqrt{\pi/2}$ at which independent Gaussian errors of that
#   $\sigma$ put a point from the truth). The localisation errors of section 10 are of that order; the filter
#   treats them as independent from point to point, and notebook 12 shows what a wrong noise model does;
# * **undistorted, normalised coordinates** $(X/Z, Y/Z)$ rather than pixels, each with its own noise covariance;
# * **few outliers**: mutual nearest neighbours and RANSAC in the front end, a chi-square gate in the filter as the
#   last line of defence (notebook 12 builds it);
# * **speed**: the front end runs once per image, at the camera's rate (section 8).
#
# Between two images the filter does not need the camera at all: it integrates the IMU. Notebook 09 starts there.

# %%
from evio_lib.msckf.config import MsckfConfig

filter_config = MsckfConfig()
sigma = filter_config.pixel_noise_px
print(f"a track is used after >= {filter_config.min_track_length} observations; assumed noise sigma = {sigma:g} px "
      f"per axis at f = {filter_config.focal_length_px:g} px (mean error length {sigma * np.sqrt(np.pi / 2):.2f} px)")
assert filter_config.min_track_length == 3 and filter_config.pixel_noise_px == 1.0

# %% [markdown]
# ## Summary
#
# * **Repeatability** (Eqs. 15-16) asks whether the detector finds the same scene points again: carry each point
#   into the other image with the true $H$ and count those with a detection within $\varepsilon$, over both images.
#   It ignores descriptors.
# * **Homography estimation correctness** (Eq. 17) tests the whole chain — detector, descriptor, mutual
#   nearest-neighbour matching, RANSAC — through the mean distance of the four warped image corners.
# * **Matching score** and **NN mAP** look at the descriptor matches before RANSAC hides the wrong ones.
# * Repeatability, homography correctness and the matching score were computed by hand on one pair and agree with
#   `evio_lib.features.evaluation.evaluate`.
# * `evio_lib.features.evaluation.benchmark` turns these into tables shaped like the thesis's Tables 2-5 (held-out
#   viewpoint/illumination pairs and simulated event frames), plus a speed table; the full 580-pair run is
#   `python -m evio_lib features-benchmark --out DIR`.
# * Our tables keep some of the thesis's rankings and not others (section 9 says which); compare rankings, not
#   decimals, and only on data alike.
# * `diagnose_matches` separates matching, selection and localisation with an oracle homography. On the viewpoint
#   split the networks, run once on the image, have fewer correct matches than SIFT, each further from the truth
#   under the zoom of these pairs, and RANSAC loses some of the pairs the oracle would fit.
# * On the illumination split, at $\varepsilon = 3$, the best network repeats more of its points than any classical
#   detector but estimates no more homographies correctly than the best classical method; on the event-count frames
#   Harris leads every network.
# * The network sees one scale; SIFT chooses one per point. Run on an image pyramid whose levels each keep their own
#   points and descriptors (`scales="auto"`, what `create_detector("superpoint")` does at 480 x 640), the same
#   network finds many more correct matches on the viewpoint pairs, places them a little better and gets more
#   homographies right (section 11), at several times the cost; the small frames of the pipeline stay at one level.
# * Section 12 runs the benchmark on test photographs that no network saw in training (the fine-tuned network
#   trained on other photographs of the same folder): a handful of pairs, read as a sample; the whole test split
#   is one command.
#
# ## Exercises
#
# 1. Compute repeatability with the second term of Eq. 16 measured in image 1's frame ($H^{-1}\mathbf x_j$ against
#    $\mathbf x_i$), as the thesis writes it. On which pairs does it differ from the library's value, and why does
#    a zoom make the difference?
#
#    *Hint:* compute $H^{-1}x_j$ and measure its distance to the $x_i$ in image 1; compare the two versions on an
#    illumination pair ($H = I$) and on a zoomed viewpoint pair.
# 2. Replace mutual nearest-neighbour matching by Lowe's ratio test (keep a match when the best distance is below
#    0.8 times the second best) and rerun the homography table for SIFT and ORB. Which metric changes most?
#
#    *Hint:* sort each row of the descriptor distance matrix and keep a match when best < 0.8 x second best; feed the
#    matches to `estimate_homography`.
# 3. Run `illumination_pairs` with `strength=0.5` and `strength=1.5`. How quickly do the classical detectors
#    degrade, and which one degrades least?
#
#    *Hint:* `illumination_pairs(images, seed, strength=...)`; repeatability with $H = I$ needs no warping.
# 4. Time SIFT at 480 x 640 and compare with 240 x 320. Is the cost proportional to the number of pixels?
#
#    *Hint:* `measure_speed('sift', images, (480, 640))['ms']` against `(240, 320)` gives wall-clock times; on a
#    busy machine take the best of a few calls in CPU time (`time.process_time()` around `detect_and_describe`).
# 5. On the full benchmark from the command line, do the library's trained networks reach SIFT's homography
#    correctness at $\varepsilon = 3$ on the viewpoint split? Do they beat every classical method on the
#    illumination split?
#
#    *Hint:* `python -m evio_lib features-benchmark --out DIR` (it runs for a long while; its tables are shaped like
#    section 7's).
# 6. Run the diagnosis of section 10 on illumination pairs. Where the networks fail there, is it matching,
#    selection or localisation?
#
#    *Hint:* `heldout_pairs(SEED, n_images=..., pairs_per_image=2, splits=("illumination",))` and `diagnose_pairs`
#    as in section 10; compare the correct matches, the localisation error, and the oracle's correctness with
#    RANSAC's, pair by pair.
#
# 7. Which levels of the pyramid matter? Run section 11's diagnosis with the levels 1 to 0.5 alone, without the two
#    enlarged ones. Do the enlarged levels bring more correct matches, better placed ones, or both?
#
#    *Hint:* `pyramid_scales(settings.homography_size, levels_above=0)` gives the levels;
#    `diagnose_pairs("superpoint", diag_pairs, settings, detector_options={"scales": levels})` the diagnosis.
#
# Worked solutions, with the code to run:
# [docs/solutions/08_feature_evaluation.md](../docs/solutions/08_feature_evaluation.md).
