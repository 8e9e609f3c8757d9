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
# # 07 — Homographic adaptation and training SuperPoint on real images
#
# Lesson 06 trained MagicPoint on Synthetic Shapes, where every corner is known. Real photographs come without
# such labels, and "where is an interest point?" has no ground truth there. SuperPoint, the network the thesis
# (Friedel 2020, §3.2.5) trains, answers it by **self-supervision** (the data label themselves): a detector labels
# real images, made more reliable by averaging its response over many random warps (**homographic adaptation**); a
# detector trained on those labels can label them again (the "rounds"); and the full network learns descriptors from
# **warped pairs** whose correspondence is known exactly because we made the warp.
#
# This lesson:
#
# 1. runs homographic adaptation and checks that the aggregated response is closer to equivariant than one view;
# 2. builds the cell correspondence matrix $S$ of a warped pair and checks the descriptor loss (Eqs. 10-12) by hand;
# 3. trains a MagicPoint and then the detector + descriptor network for a short while, and compares it with the
#    untrained network and with the project's trained network on test drawings whose corners we know;
# 4. shows the whole training chain of the thesis, its command, and how the project's configs differ from the thesis.
#
# The two ideas, before any code. Top: an image without labels is warped by $N$ random homographies (a homography
# maps the pixels of one view of a plane to another: rotation, zoom, shift and tilt); the detector runs on every
# view, each response is mapped back into the image's frame and the responses are averaged where the views saw the
# pixel; the maxima of that average are the labels. Bottom: for an image and its warp, a cell of the first image
# *corresponds* to the cells of the second whose centres lie within 8 px of its warped centre; the descriptor loss
# pulls their descriptors together (up to the margin $m_p$) and pushes every other pair apart (below $m_n$). The
# detector drawn here is a Harris response on a made-up scene, standing in for the network.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_schematics import plot_homographic_adaptation_schematic

fig = plot_homographic_adaptation_schematic()
plt.show()

# %%
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one thread: small images and short runs gain nothing from more
import json
import tempfile

import cv2
import numpy as np
import torch
from IPython.display import Markdown, display

torch.set_num_threads(1)
os.environ["EVIO_CACHE_DIR"] = tempfile.mkdtemp(prefix="evio07_labels_")  # exported labels: a temporary folder

from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_features import (
    plot_cell_correspondences,
    plot_detections,
    plot_heatmap_row,
    plot_matches,
    plot_training_curve,
)
from evio_lib.features.evaluation.evaluate import match_descriptors
from evio_lib.features.network import (
    DEFAULT_WEIGHTS,
    SuperPointDetector,
    inference_model,
    load_checkpoint,
    load_model,
    logits_to_heatmap,
    pad_to_cells,
    resolve_weights,
    shipped_weights,
)
from evio_lib.features.training import train as training
from evio_lib.features.training.adaptation import homographic_adaptation, heatmap_to_keypoints
from evio_lib.features.training.augment import HOMOGRAPHIC_ADAPTATION, HOMOGRAPHIC_PAIR, homographic_augment
from evio_lib.features.training.datasets import RealImages, image_pool
from evio_lib.features.training.losses import cell_centres, cell_correspondences, descriptor_cell_stats, descriptor_loss
from evio_lib.features.training.shapes import generate_shape_image
from evio_lib.geometry.homography import valid_mask, warp_image, warp_points

FAST = fast_mode()
rng = np.random.default_rng(7)
_ = torch.manual_seed(0)  # nothing below draws from torch's global generator; this only guards against surprises
run_root = tempfile.mkdtemp(prefix="evio07_runs_")

# %% [markdown]
# ## 1. Homographic adaptation
#
# ### The detector to adapt
#
# The thesis adapts MagicPoint, the detector of lesson 06. A MagicPoint trained for a few hundred steps, like the one
# of section 3, barely has peaks yet (section 3 measures it), so this section adapts the project's **trained network**:
# the same architecture as lesson 06, whose detector began as a MagicPoint trained on about 500 000 augmented
# Synthetic Shapes images and was then trained together with the descriptor on real images labelled by homographic
# adaptation (sections 3 and 4 show how). The cell prints what its weights file says about that training. The
# detector $f$ is its keypoint heatmap: image in, one probability per pixel out.

# %%
trained_name = "pretrained_detdesc_round1_gpu"  # evio_lib/weights/<name>.pt
trained_meta = load_checkpoint(resolve_weights(trained_name))["metadata"]
trained_config = trained_meta["config"]
print(f"trained network: {trained_meta['description']}: {trained_meta['step']} steps of "
      f"{trained_config['batch_size']} warped pairs at {trained_config['image_size'][0]} x "
      f"{trained_config['image_size'][1]}, learning rate {trained_config['lr']:g}, starting from a MagicPoint")
network = inference_model(load_model(trained_name).eval(), "fused")  # each batch norm merged into its convolution


def cnn_heatmaps(batch: np.ndarray) -> np.ndarray:
    """(B, H, W) float32 images -> (B, H, W) keypoint probabilities of the trained network."""
    height, width = batch.shape[1:]
    x = pad_to_cells(torch.from_numpy(np.ascontiguousarray(batch, np.float32))[:, None])
    with torch.inference_mode():
        return logits_to_heatmap(network(x)["logits"])[:, :height, :width].numpy()


def harris_heatmaps(batch: np.ndarray) -> np.ndarray:
    """(B, H, W) float32 images -> (B, H, W) positive Harris responses (lesson 05), one fixed scale."""
    return np.stack([np.maximum(cv2.cornerHarris(img, 3, 3, 0.04), 0.0) * 50.0 for img in batch])  # loop: images


# %% [markdown]
# ### One view versus the aggregate over $N$ warps
#
# Let $f$ be the detector and $\mathcal{H}_i$ random homographies ($\mathcal{H}_0 = I$, the identity). Homographic
# adaptation warps the image by each $\mathcal{H}_i$, runs the detector, maps each response back to the original
# frame and averages over the views that saw each pixel:
#
# $$F(I; f)(u) = \frac{\sum_{i} c_i(u)\, f(\mathcal{H}_i I)(\mathcal{H}_i u)}{\sum_i c_i(u)}, \qquad
# c_i(u) = 1 \text{ if } \mathcal{H}_i u \text{ lies inside view } i.$$
#
# A good detector should be **equivariant**: detecting on a warped image should give the warped detections,
# $f(\mathcal{H} I) = \mathcal{H} f(I)$. A CNN is at best equivariant to translations (one with SuperPoint's 8 x 8
# cell head, in principle, only to shifts by whole cells: exercise 6 measures it); rotations, scale changes and
# perspective change its response. Averaging over many random warps keeps what *every* view agrees on and damps
# what depends on the viewpoint; the maxima of the average are the labels exported for the next round (the thesis,
# §3.2.5.2, uses $N = 100$). We use an image of the validation pool (the project's real images: photographs, renders
# of simulated scenes, textures; never the held-out test split) and label it at SuperPoint's export threshold, 0.015.

# %%
image = image_pool("val", seed=0, size=(96, 128), n_images=2)[1]
n_warps = 30 if FAST else 60
single = cnn_heatmaps(image[None])[0]
adapted = homographic_adaptation(image, cnn_heatmaps, rng=1, n_homographies=n_warps)
labels, _ = heatmap_to_keypoints(adapted.heatmap, 0.015, nms_radius=4, border=4)
print(f"N = {n_warps} warps; pixels seen by at least half of them: {np.mean(adapted.counts >= n_warps // 2):.0%}")
print(f"largest probability: one view {single.max():.3f}, aggregate {adapted.heatmap.max():.3f}; "
      f"{len(labels)} labels above 0.015 (NMS 4 px)")

fig = plot_heatmap_row([image, single, adapted.heatmap, image],
                       ["image (validation pool)", "trained network: one view f(I)",
                        f"aggregate F(I) over N = {n_warps} warps", "labels: maxima of F(I) above 0.015"],
                       ["gray", "magma", "magma", "gray"], points={3: labels},
                       colorbar_labels={1: "keypoint probability", 2: "keypoint probability"}, shared=[(1, 2)])
plt.show()
assert adapted.heatmap.max() < single.max()  # a peak stays at full height only where every view agrees

# %% [markdown]
# ### Is the aggregate equivariant?
#
# Warp the image by a fixed homography $\mathcal{H}$ and compare, on the pixels that both images show, the
# detector on the warped image, $f(\mathcal{H} I)$, with the warped detection, $\mathcal{H} f(I)$: once for a
# single view and once for the aggregate $F$ (each with its own, independent random warps). We measure the mean
# absolute difference relative to the mean response, and the correlation; Harris (lesson 05) on one view is the
# yardstick of a hand-made detector.

# %%
H = HOMOGRAPHIC_ADAPTATION.replace(perspective_amplitude_x=0.1, perspective_amplitude_y=0.1).sample(image.shape, 5)
warped = warp_image(image, H)
adapted_warped = homographic_adaptation(warped, cnn_heatmaps, rng=2, n_homographies=n_warps)
shared = valid_mask(image.shape, H, erode=8) & (adapted_warped.counts >= max(1, n_warps // 4))  # pixels both see


def compare(on_warped: np.ndarray, warped_response: np.ndarray) -> tuple[float, float]:
    """Return (mean |a - b| / mean b, correlation) of two responses on the shared pixels."""
    a, b = on_warped[shared], warped_response[shared]
    return float(np.abs(a - b).mean() / b.mean()), float(np.corrcoef(a, b)[0, 1])


err_single, corr_single = compare(cnn_heatmaps(warped[None])[0], warp_image(single, H))
err_agg, corr_agg = compare(adapted_warped.heatmap, warp_image(adapted.heatmap, H))
err_harris, corr_harris = compare(harris_heatmaps(warped[None])[0], warp_image(harris_heatmaps(image[None])[0], H))
print(f"network, one view      : relative difference {err_single:.2f}, correlation {corr_single:.2f}")
print(f"network, aggregate of {n_warps}: relative difference {err_agg:.2f}, correlation {corr_agg:.2f}")
print(f"Harris, one view       : relative difference {err_harris:.2f}, correlation {corr_harris:.2f}  "
      f"({shared.mean():.0%} of the pixels shared)")

warped_aggregate = warp_image(adapted.heatmap, H)
difference = np.abs(adapted_warped.heatmap - warped_aggregate) * shared
fig = plot_heatmap_row([adapted_warped.heatmap, warped_aggregate, difference],
                       ["F(H I): aggregate of the warped image", "H F(I): warped aggregate", "|difference| (shared)"],
                       colorbar_labels={0: "keypoint probability", 1: "keypoint probability",
                                        2: "|difference| of probabilities"}, shared=[(0, 1, 2)])
plt.show()
assert err_agg < err_single and corr_agg > corr_single  # averaging over warps: closer to equivariant
assert err_single > 0.5 and corr_single < 0.8  # the CNN on one view: clearly not equivariant
assert corr_harris > 0.9  # Harris on one view: nearly equivariant already

# %%
display(Markdown(
    f"Averaging over warps makes the network's response closer to equivariant: the relative difference falls from "
    f"{err_single:.2f} on one view to {err_agg:.2f} for the aggregate of N = {n_warps}, and the correlation rises "
    f"from {corr_single:.2f} to {corr_agg:.2f}. Harris, a formula on image gradients that a rotation leaves "
    f"unchanged, is close already on one view (relative difference {err_harris:.2f}, correlation "
    f"{corr_harris:.2f}); a learned detector is equivariant only as far as its training made it. The two "
    f"aggregates use different random warps, so their difference never reaches zero; exercise 1 follows it as N "
    f"grows."))

# %% [markdown]
# ## 2. The descriptor loss on a warped pair (Eqs. 10-12)
#
# The descriptor head outputs one descriptor $d_{hw}$ per 8x8 cell. For an image and its warp by a known
# $\mathcal{H}$, cell $(h, w)$ of the first image and cell $(h', w')$ of the second **correspond** when the warped
# centre of the first lands within 8 px of the centre of the second:
#
# $$s_{hw,h'w'} = \begin{cases} 1 & \lVert \mathcal{H} p_{hw} - p'_{h'w'} \rVert < 8 \\ 0 & \text{otherwise}
# \end{cases}, \qquad p_{hw} = (8w + 3.5,\; 8h + 3.5).$$
#
# The loss pulls corresponding descriptors together and pushes all others apart, with hinge margins
# $m_p = 1$, $m_n = 0.2$ on unit descriptors:
#
# $$l_d(d, d', s) = \lambda_d\, s \max(0, m_p - d^\top d') + (1 - s) \max(0, d^\top d' - m_n),$$
#
# averaged over all pairs of cells. $\lambda_d$ balances the few positives of a cell (about $\pi$: the cell
# centres within 8 px of a point) against its $H_c W_c - 3$ negatives, so the right value depends on the grid:
# SuperPoint's 250 suits 240 x 320 images (1 200 cells); on 120 x 160 crops (300 cells) the same 250 lets the positives
# win, and in the project's training runs every descriptor drifted towards every other (they **collapsed**). The
# configs use $250 \cdot 300 / 1200 = 62.5$
# (Exercise 4 tries 250; `losses.py` explains why the thesis's $\lambda_d = 0.05$, $\lambda = 10^4$ belong to
# a differently normalised loss). A training pair from the real-image pool:

# %%
pair_images = image_pool("train", seed=0, size=(48, 64), n_images=4)
pair = RealImages(pair_images, split="train", seed=3, pairs=True, augment=False)[2]
H_pair = pair.homography.double().numpy()
grid = (48 // 8, 64 // 8)
S = cell_correspondences(H_pair, grid)[0]  # (48, 48): rows = cells of image 1, columns = cells of image 2
print("S", tuple(S.shape), "| positives per cell of image 1:", np.bincount(S.sum(1).int().numpy()))

# the same S by hand: warp the centres, measure the distances
centres = cell_centres(grid).double().numpy()
dist = np.linalg.norm(warp_points(H_pair, centres)[:, None, :] - centres[None, :, :], axis=2)
S_hand = (dist < 8.0).astype(np.float32)
assert np.array_equal(S_hand, S.numpy())
warped_centres = warp_points(H_pair, centres)
well_inside = np.all((warped_centres >= 8) & (warped_centres <= np.array([64, 48]) - 8), axis=1)
print(f"cells whose warped centre lies 8 px inside image 2: {S_hand.sum(1)[well_inside].mean():.2f} positives each "
      f"(pi = {np.pi:.2f})")
assert abs(S_hand.sum(1)[well_inside].mean() - np.pi) < 0.5  # about pi positives per cell away from the border

fig = plot_cell_correspondences(pair.image[0], pair.warped_image[0], centres, S.numpy())
plt.show()
rows, cols = np.nonzero(S.numpy())  # the corresponding cell pairs (i of image 1, j of image 2)

# %% [markdown]
# Now the loss by hand. Random descriptors (a seeded torch generator), L2-normalised; we write out a few terms of
# Eq. 12 and then the mean over all $48 \times 48$ pairs, and compare with `losses.descriptor_loss`.

# %%
gen = torch.Generator().manual_seed(0)
D1 = torch.randn(1, 16, *grid, generator=gen)
D2 = torch.randn(1, 16, *grid, generator=gen)
D2[0, :, 2, 3] = D1[0, :, 2, 2] + 0.3 * torch.randn(16, generator=gen)  # make one pair similar
d1 = D1[0].flatten(1).T.numpy().astype(np.float64)  # (48, 16), row-major cells
d2 = D2[0].flatten(1).T.numpy().astype(np.float64)
d1 /= np.linalg.norm(d1, axis=1, keepdims=True)  # unit descriptors
d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
m_p, m_n, lambda_d = 1.0, 0.2, 62.5  # the configs' value at 120 x 160


def l_d(i: int, j: int) -> float:
    """Eq. 12 for cell i of image 1 and cell j of image 2."""
    dot, s = d1[i] @ d2[j], S_hand[i, j]
    return lambda_d * s * max(0.0, m_p - dot) + (1 - s) * max(0.0, dot - m_n)


i_pos, j_pos = rows[len(rows) // 2], cols[len(rows) // 2]
for i, j in ((i_pos, j_pos), (2 * 8 + 2, 2 * 8 + 3), (0, 47)):
    print(f"cells {i:2d} -> {j:2d}: s = {S_hand[i, j]:.0f}, d.d' = {d1[i] @ d2[j]:+.3f}, l_d = {l_d(i, j):.4f}")
dots = d1 @ d2.T
loss_hand = np.mean(lambda_d * S_hand * np.maximum(0, m_p - dots) + (1 - S_hand) * np.maximum(0, dots - m_n))
loss_lib = float(descriptor_loss(D1, D2, H_pair, lambda_d=lambda_d))
print(f"mean over all pairs: by hand {loss_hand:.6f}, library {loss_lib:.6f}")
assert abs(loss_hand - loss_lib) < 1e-5 * max(1.0, loss_hand)
assert abs(np.mean([l_d(i, j) for i in range(48) for j in range(48)]) - loss_hand) < 1e-9  # term by term (small)
positive_part = np.mean(lambda_d * S_hand * np.maximum(0, m_p - dots))
print(f"positive pairs: {positive_part / loss_hand:.0%} of the loss, "
      f"{np.mean(lambda_d * np.maximum(0, m_p - dots[S_hand > 0])):.1f} each on average")
assert positive_part > 0.9 * loss_hand and abs(np.mean(lambda_d * np.maximum(0, m_p - dots[S_hand > 0])) - 62.5) < 10

# %% [markdown]
# Positive pairs dominate the loss at first (the line above): random descriptors have $d^\top d' \approx 0$, so each
# costs about $\lambda_d m_p = 62.5$, while a negative only costs when its dot product exceeds $m_n$.
#
# ## 3. A short detector + descriptor training run
#
# ### A MagicPoint to start from
#
# The detector + descriptor step (**DetDesc** in the thesis) needs a detector that labels the real images
# (`labels_from`) and, in the thesis's "pre-trained" variant, whose weights it starts from (`init_from`). As in
# lesson 06 we train a narrow MagicPoint (half the channels) on Synthetic Shapes for a short while, and then look at
# what homographic adaptation makes of it on section 1's image.

# %%
if FAST:
    mp_overrides = dict(image_size=(32, 48), batch_size=4, max_steps=100, val_every=50, n_val_images=4)
else:
    mp_overrides = dict(image_size=(64, 88), batch_size=8, max_steps=200, val_every=100, n_val_images=16)
mp_config = training.load_config("magicpoint", model="narrow", checkpoint_dir=run_root, device="cpu",
                                 checkpoint_every=50, num_threads=1, augment=False, lr=3e-3, **mp_overrides)
mp_result = training.train(mp_config, progress=False)
print(f"MagicPoint: {mp_result.steps} steps of {mp_config.batch_size} images at {mp_config.image_size[0]} x "
      f"{mp_config.image_size[1]} in {mp_result.seconds:.0f} s")
magicpoint = inference_model(load_model(mp_result.best_path).eval(), "fused")


def magicpoint_heatmaps(batch: np.ndarray) -> np.ndarray:
    """(B, H, W) float32 images -> (B, H, W) keypoint probabilities of this run's MagicPoint."""
    height, width = batch.shape[1:]
    x = pad_to_cells(torch.from_numpy(np.ascontiguousarray(batch, np.float32))[:, None])
    with torch.inference_mode():
        return logits_to_heatmap(magicpoint(x)["logits"])[:, :height, :width].numpy()


mp_single = magicpoint_heatmaps(image[None])[0]
mp_adapted = homographic_adaptation(image, magicpoint_heatmaps, rng=1, n_homographies=n_warps)
mp_labels = {threshold: len(heatmap_to_keypoints(mp_adapted.heatmap, threshold, nms_radius=4, border=4)[0])
             for threshold in (0.015, 0.005)}
print(f"on section 1's image: largest probability of one view {mp_single.max() * 65:.2f}/65, of the aggregate "
      f"{mp_adapted.heatmap.max() * 65:.2f}/65; labels at 0.015: {mp_labels[0.015]}, at 0.005: {mp_labels[0.005]} "
      f"(the trained network: {len(labels)} at 0.015)")
assert mp_labels[0.005] >= mp_labels[0.015]

# %%
display(Markdown(
    f"An untrained network answers about 1/65 everywhere. After {mp_result.steps} steps this MagicPoint's largest "
    f"probability on section 1's image is {mp_single.max() * 65:.2f}/65 on one view and "
    f"{mp_adapted.heatmap.max() * 65:.2f}/65 in the aggregate: weak peaks. SuperPoint's export threshold, 0.015 "
    f"(about 1/65), leaves {mp_labels[0.015]} labels on this image where the trained network gets {len(labels)}; "
    f"0.005, the threshold of the run below, leaves {mp_labels[0.005]}. A briefly trained labeller needs a lower "
    f"threshold; the project's configs export at 0.002 and keep the strongest points (section 4)."))

# %% [markdown]
# ### The detector + descriptor run
#
# `train` with a `detdesc` config runs the whole step: it builds the real-image pool, **exports labels** by
# homographic adaptation with the model named in `labels_from` (here our MagicPoint, at the lower threshold), builds
# warped pairs, and minimises Eq. 8, $L = L_p(X, Y) + L_p(X', Y') + \lambda L_d(D, D', S)$ (X, Y: the detector's
# logits and labels of an image; X', Y': those of its warp; D, D': the two descriptor maps; S: their cell
# correspondences; λ: the descriptor loss's weight), with Adam (a gradient-descent optimiser that scales each
# weight's step by its recent gradients). `init_from` starts from the MagicPoint weights, the thesis's
# "pre-trained" variant, at the learning rate the thesis uses for every training of the full network, $10^{-4}$
# (§3.2.5.4): small steps, so that the detector keeps what MagicPoint learned while the descriptor head starts from
# scratch. The project's longer configs use $10^{-3}$ instead (section 4): over their few thousand steps $10^{-4}$
# taught the descriptor too slowly. A larger rate trains the descriptor faster but can pull the detector away from
# what MagicPoint learned; exercise 4 measures that trade. With only a handful of validation pairs, this short run
# keeps the checkpoint with the lowest validation loss (`select_on="loss"`). The cell prints the settings that
# differ from the project's config.

# %%
if FAST:
    dd_overrides = dict(image_size=(32, 48), max_steps=30, val_every=10, n_train_images=8, n_val_images=2,
                        n_homographies=4)
else:
    dd_overrides = dict(image_size=(64, 88), max_steps=600, val_every=150, n_train_images=48, n_val_images=8,
                        n_homographies=20)
dd_config = training.load_config(
    "detdesc_round1", model="narrow", labels_from=str(mp_result.best_path), init_from=str(mp_result.best_path),
    batch_size=2, lr=1e-4, label_threshold=0.005, num_threads=1, checkpoint_dir=run_root, device="cpu",
    checkpoint_every=100, select_on="loss", **dd_overrides)
project_config = training.load_config("detdesc_round1")
discussed = ("model", "image_size", "n_train_images", "n_homographies", "label_threshold", "max_steps", "lr",
             "lambda_d", "select_on")
print(f"{'':16s} {'this run':>12s} {'project config':>15s}")
for field in discussed:
    print(f"{field:16s} {str(getattr(dd_config, field)):>12s} {str(getattr(project_config, field)):>15s}")
dd_result = training.train(dd_config, progress=False)
print(f"{dd_result.steps} steps in {dd_result.seconds:.0f} s (label export included); best step {dd_result.best_step}")

# %%
losses = np.array(dd_result.train_loss)
fig = plot_training_curve(losses, dd_result.validation, ylabel="total loss (Eq. 8)", log_scale=True)
plt.show()
head = max(1, len(losses) // 10)
print(f"mean training loss: first {head} steps {losses[:head].mean():.2f}, "
      f"last {head} steps {losses[-head:].mean():.2f}")
assert np.isfinite(losses).all() and losses[-head:].mean() < losses[:head].mean()  # the loss goes down

# %% [markdown]
# A falling loss does not prove that the descriptors are useful. The validation also records three direct checks on
# the validation pairs (`losses.descriptor_cell_stats`): the mean cosine $d^\top d'$ of corresponding cells (it
# should approach 1), that of all other pairs (it should fall below $m_n$), and **retrieval**: the share of cells
# whose most similar cell in the warped image is one of its correspondences. A loss can keep falling while the
# descriptors **collapse**: every descriptor close to every other, corresponding or not, so that the cosine of
# corresponding cells looks fine, the cosine of all others is high too, and retrieval stays low (exercise 4 provokes
# it). The project's DetDesc configs therefore keep `best.pt` at the highest retrieval
# (`select_on="desc_nn_accuracy"`), not at the lowest loss; this short run, with too few validation pairs to rank
# retrieval reliably, keeps the lowest loss.

# %%
print(f"{'step':>5s} {'loss':>7s} {'cos(corresponding)':>19s} {'cos(others)':>12s} {'retrieval':>10s}")
for v in dd_result.validation:
    print(f"{v['step']:5d} {v['loss']:7.3f} {v['desc_positive_dot']:19.3f} {v['desc_negative_dot']:12.3f} "
          f"{v['desc_nn_accuracy']:10.1%}")
assert all(0.0 <= v["desc_nn_accuracy"] <= 1.0 for v in dd_result.validation)
first_v, last_v = dd_result.validation[0], dd_result.validation[-1]
best_row = next(v for v in dd_result.validation if v["step"] == dd_result.best_step)
assert best_row["loss"] <= min(v["loss"] for v in dd_result.validation) + 1e-6  # best.pt: the lowest val loss
cells_per_image = dd_config.image_size[0] * dd_config.image_size[1] // 64
chance_retrieval = np.pi / cells_per_image  # about pi corresponding cells among all


def moved(before: float, after: float) -> str:
    return "rose" if after > before else "fell" if after < before else "stayed"


display(Markdown(
    f"From the first validation (step {first_v['step']}) to the last (step {last_v['step']}) the loss "
    f"{moved(first_v['loss'], last_v['loss'])} from {first_v['loss']:.3f} to {last_v['loss']:.3f}, "
    f"cos(others) {moved(first_v['desc_negative_dot'], last_v['desc_negative_dot'])} from "
    f"{first_v['desc_negative_dot']:.3f} to {last_v['desc_negative_dot']:.3f} "
    f"({'still above' if last_v['desc_negative_dot'] > 0.2 else 'below'} $m_n$ = 0.2), and retrieval "
    f"{moved(first_v['desc_nn_accuracy'], last_v['desc_nn_accuracy'])} from {first_v['desc_nn_accuracy']:.1%} to "
    f"{last_v['desc_nn_accuracy']:.1%}, against {chance_retrieval:.0%} for a random pick among the "
    f"{cells_per_image} cells of a validation image."))

# %% [markdown]
# ### Does the short run beat the untrained network?
#
# Test images whose corners we know: eight drawings of the Synthetic Shapes generator (polygons, checkerboards,
# cubes) with their own seed, none of them seen in training, each warped by a known $\mathcal{H}$ (milder than the
# training warps: small rotation and perspective). On an image with $N$ true corners every network keeps its best
# $2N$ points. We ask two questions, and sum the answers over the eight images:
#
# * **detector**: what share of the keypoints lies within 2 px of a true corner, and what share of the corners has
#   a keypoint within 2 px?
# * **descriptor**: match each image with its warp by **mutual nearest neighbours** (a match is kept only when each
#   descriptor is the other's nearest); how many matches are correct,
#   i.e. $\lVert \mathcal{H} x_1 - x_2 \rVert \le 3$ px?
#
# The baseline is the untrained network (random weights), whose nearly flat heatmap puts its points on a regular grid
# (lesson 06); the project's trained network of section 1 shows where long training gets.

# %%
mild = HOMOGRAPHIC_PAIR.replace(max_angle=0.3, scaling_amplitude=0.1, perspective_amplitude_x=0.1,
                                perspective_amplitude_y=0.1)
test_rng = np.random.default_rng(7)
test_set = []  # (image, true corners (N, 2), warped pair with its homography)
for k in range(8):
    drawing, corners = generate_shape_image(("multiple_polygons", "checkerboard", "polygon", "cube")[k % 4],
                                            (120, 160), test_rng)
    drawing = drawing.astype(np.float32)
    test_set.append((drawing, corners, homographic_augment(drawing, corners, np.random.default_rng(100 + k), mild)))


def match_pair(detector: SuperPointDetector, image: np.ndarray, corners: np.ndarray, pair) -> tuple:
    """Return keypoints of both images, mutual-NN matches (M, 2), their correctness (M,) at 3 px, on-corner flags."""
    f1 = detector.detect_and_describe(image)
    f2 = detector.detect_and_describe(pair.image)
    matches = match_descriptors(f1.descriptors, f2.descriptors, mutual=True)
    err = np.linalg.norm(warp_points(pair.homography, f1.keypoints[matches[:, 0]]) - f2.keypoints[matches[:, 1]],
                         axis=1) if len(matches) else np.zeros(0)
    on_corner = np.linalg.norm(f1.keypoints[:, None] - corners[None], axis=2).min(axis=1) <= 2.0
    return f1.keypoints, f2.keypoints, matches, err <= 3.0, on_corner


networks = {"untrained": dict(weights=None, allow_random=True, model_config="narrow"),
            "short run": dict(weights=dd_result.best_path),
            "trained network": dict(weights=trained_name)}
outcomes, totals, all_results = {}, {}, {}
for name, weights in networks.items():
    results = [match_pair(SuperPointDetector(**weights, inference="fused", max_keypoints=2 * len(corners)),
                          image, corners, pair) for image, corners, pair in test_set]  # loop: test images
    outcomes[name], all_results[name] = results[0], results  # the first image's matches are drawn below
    on_corner = np.concatenate([r[4] for r in results])
    correct = np.concatenate([r[3] for r in results])
    found = np.concatenate([np.linalg.norm(c[:, None] - r[0][None], axis=2).min(axis=1) <= 2.0
                            for (_, c, _), r in zip(test_set, results)])  # true corners with a keypoint within 2 px
    totals[name] = dict(on_corner=on_corner.mean(), found=found.mean(), correct=int(correct.sum()),
                        matches=len(correct))
    print(f"{name:16s} keypoints on a corner {on_corner.mean():4.0%}, corners found {found.mean():4.0%} | "
          f"correct matches at 3 px {correct.sum():3d} of {len(correct):3d} mutual matches (8 images)")
fig = plot_detections([t[0] for t in test_set[:4]], [t[1] for t in test_set[:4]],
                      {name: [r[0] for r in results_of] for name, results_of in all_results.items()})
plt.show()
drawn_image, _, drawn_pair = test_set[0]
fig = plot_matches(drawn_image, drawn_pair.image, {name: outcome[:4] for name, outcome in outcomes.items()})
plt.show()
short, untrained, trained = totals["short run"], totals["untrained"], totals["trained network"]
assert short["on_corner"] > 2 * untrained["on_corner"] and short["found"] > 2 * untrained["found"]  # it learned
assert trained["on_corner"] > 2 * short["on_corner"] and trained["correct"] > short["correct"]  # far from done

# %%
drawn = {name: (int(outcome[3].sum()), len(outcome[3])) for name, outcome in outcomes.items()}
share = {name: t["correct"] / max(t["matches"], 1) for name, t in totals.items()}
display(Markdown(
    f"The short run's detector started from MagicPoint's weights and learned from its labels: "
    f"{short['on_corner']:.0%} of its keypoints sit within 2 px of a corner against the untrained grid's "
    f"{untrained['on_corner']:.0%} ({short['on_corner'] / untrained['on_corner']:.1f} times the share), and it finds "
    f"{short['found']:.0%} of the corners against {untrained['found']:.0%}. That is a start, not a detector: most of "
    f"its keypoints are still elsewhere, where the trained network puts {trained['on_corner']:.0%} of its keypoints "
    f"on a corner and finds {trained['found']:.0%} of them.\n\n"
    f"Its descriptors have barely begun: summed over the eight pairs, {short['correct']} of its {short['matches']} "
    f"mutual matches are correct ({share['short run']:.0%}), against {untrained['correct']} of "
    f"{untrained['matches']} ({share['untrained']:.0%}) for random filters, which are a surprisingly strong "
    f"baseline on a mild warp, and {trained['correct']} of {trained['matches']} ({share['trained network']:.0%}) "
    f"for the trained network. The pair drawn above is only the first of the eight: there the counts are "
    + ", ".join(f"{name} {c} of {m}" for name, (c, m) in drawn.items()) + ". "
    f"This run trained {dd_result.steps} steps on {dd_config.n_train_images} small images; the thesis trained 15 "
    f"epochs over 82 783 MS-COCO images."))

# %% [markdown]
# ## 4. The full chain
#
# The thesis (§3.2.5, Fig. 13) compared several training processes; each is a config file. The model it took into the
# filter (the MSCKF, which the later lessons build) on the strength of its Tables 2-5 (§4.5), **pre-trained DetDesc
# (Round 2)**, needs MagicPoint, its labels, DetDesc (Round 1), that model's labels, and finally DetDesc (Round 2)
# started from Round 1's weights:

# %%
chain = training.variant_dependencies("pretrained_detdesc_round2")
print(" -> ".join(chain))
for name in chain:
    cfg = training.load_config(name)
    print(f"  {name:28s} labels from {cfg.labels_from or 'Synthetic Shapes':16s} starts from "
          f"{cfg.init_from or 'random weights'}")
print("\ncommand: python -m evio_lib features-train pretrained_detdesc_round2 --chain")
assert training.load_config("pretrained_detdesc_round2").init_from == "detdesc_round1"
assert chain == ["magicpoint", "detdesc_round1", "pretrained_detdesc_round2"]

# %% [markdown]
# Every variant of thesis Table 1 (from scratch or pre-trained, detector only or detector + descriptor, with and
# without event frames) has a config (`python -m evio_lib features-train --list` lists every config):

# %%
table1 = [name for name in training.available_configs() if training.load_config(name).stage != "distill"]
for name in table1:
    print(f"{name:36s} {training.load_config(name).description}")

# %% [markdown]
# What the thesis trained and what the project's configs do (each config keeps the thesis's values under
# `"thesis"`; the thesis's in brackets):

# %%
print(f"{'variant':28s} {'size (thesis)':>17s} {'batch':>8s} {'length (thesis)':>24s} {'lr':>15s} {'N warps':>9s}")
for name in chain:
    raw = json.loads((training.CONFIG_DIR / f"{name}.json").read_text())
    thesis = raw.get("thesis", {})
    size = f"{raw['image_size'][0]}x{raw['image_size'][1]} ({thesis.get('image_size', ['?', '?'])[0]}x" \
           f"{thesis.get('image_size', ['?', '?'])[1]})"
    length = f"{raw['max_steps']} steps ({thesis.get('epochs', '?')} epochs)"
    lr = f"{raw['lr']:g} ({thesis.get('lr', '?')})"
    warps = f"{raw['n_homographies']} ({thesis.get('n_homographies', '-')})" if name != "magicpoint" else "-"
    print(f"{name:28s} {size:>17s} {raw['batch_size']:>3d} ({thesis.get('batch_size', '?')}) {length:>24s} "
          f"{lr:>15s} {warps:>9s}")
    assert raw["max_steps"] >= 1000 and 15 <= thesis["epochs"] <= 50  # thousands of steps; thesis 15-50 epochs
    assert raw["image_size"] == ([96, 128] if name == "magicpoint" else [120, 160])
    assert name == "magicpoint" or (raw["n_homographies"], thesis["n_homographies"]) == (50, 100)
    assert name == "magicpoint" or (raw["lr"], thesis["lr"]) == (1e-3, 1e-4)

# %% [markdown]
# The thesis trained Synthetic Shapes for 50 epochs at 120 x 160 and its MS-COCO steps (82 783 images at 240 x 320) for
# 15-20 epochs each (§3.2.5; 15 for the two steps printed above, 20 for the detector-only variants). Nothing is
# downloaded here and the configs are sized for a small CPU: they train on the project's own image pool (scikit-image
# photographs, renders of simulated scenes, aerial views, textures) at 120 x 160 (MagicPoint at 96 x 128), for the
# thousands of steps printed above, with 50 instead of 100 adaptation warps, and at a learning rate of $10^{-3}$ where
# the thesis used $10^{-4}$ for the full network (section 3 says why). The descriptor loss keeps its form; its positive
# weight $\lambda_d$ is scaled to the number of cells (section 2), and the total weight $\lambda$ differs because this
# loss is a mean over valid cell pairs (`losses.py`).
#
# ### How many labels?
#
# The export threshold decides how many maxima of the aggregate become labels. SuperPoint's 0.015 suits a converged
# MagicPoint; a briefly trained one responds weakly, and the same threshold leaves it few labels to teach the next
# round (section 3 counted them). The configs export at 0.002 and keep the strongest 150 points per image
# (`label_max_keypoints`; labels come strongest first, so this is a top-k); `export_labels` prints the label counts
# and warns when the median falls below `MIN_LABEL_DENSITY` points per 1 000 pixels. `render_zoom` draws the
# rendered training scenes 4x larger before the random crop, so 120 x 160 training crops also show the content scale
# of lesson 08's benchmark, whose views are 480 x 640.

# %%
for name in chain[1:]:
    cfg = training.load_config(name)
    print(f"{name:28s} label threshold {cfg.label_threshold:g} (SuperPoint 0.015), best {cfg.label_max_keypoints} "
          f"per image, render zoom {cfg.render_zoom:g}")
    minimum = training.MIN_LABEL_DENSITY * cfg.image_size[0] * cfg.image_size[1] / 1000
    assert cfg.label_max_keypoints > minimum  # the cap never pushes labels below the warning level

# %% [markdown]
# ### Training on natural photographs
#
# The thesis's real-image steps train on MS-COCO photographs. A config can mix a folder of natural photographs
# into its training images (`"photos"`: a folder, or `"auto"` for one beside the checkout or in `$EVIO_PHOTOS`;
# photographs then make 60 % of the training images, the pool the rest). Each photograph belongs to the training,
# validation or test split by a hash of its name, and only the training ones are labelled and trained on.
#
# That is how the network `photos_detdesc` was made (config `photos_detdesc_reprojection10`). Section 1's network
# labelled the training photographs by homographic adaptation; then it was trained further on warped pairs of random
# crops of them, pairs that zoom more than the thesis's, with one more term in the loss, the **reprojection loss**
# $\lambda_r L_r$. The detector loss only says in which pixel of a cell a label lies; $L_r$ asks the points to follow
# the image when it moves by a fraction of a cell. In image 1 each cell's most probable pixel, where the detector
# would keep it (probability at least 1/65, no stronger heat within 4 px), is refined to the heat centroid of the
# 5 x 5 window around it, a sub-pixel point $c_1$; $\mathcal H$ carries it to $q = \mathcal H c_1$ in image 2, where
# the nearest such refined point $c_2$ should land: $L_r$ is the mean of $\min(\lVert c_2 - q \rVert, 3\,\text{px})$,
# weighted by each cell's keypoint probability, computed from image 1 to image 2 and back and averaged.
#
# The cell prints the recipe the weights file records and, where a photograph folder is found, labels the first
# training photograph the way the run labelled its crops (section 1's network, the config's warps, threshold and
# cap), here on the whole photograph resized to the training size.

# %%
from evio_lib.features.evaluation.photos import fit_photo
from evio_lib.sim.photos import default_photo_folder, list_photos, load_photo

photo_meta = load_checkpoint(resolve_weights("photos_detdesc"))["metadata"]
photo_cfg = photo_meta["config"]
print(f"photos_detdesc (config {photo_cfg['name']}): {photo_meta['step']} steps from {photo_cfg['init_from']}, "
      f"labels by {photo_cfg['labels_from']} "
      f"over {photo_cfg['n_homographies']} warps (threshold {photo_cfg['label_threshold']:g}, best "
      f"{photo_cfg['label_max_keypoints']}), {photo_cfg['image_size'][0]} x {photo_cfg['image_size'][1]} crops, "
      f"batch {photo_cfg['batch_size']}, lr {photo_cfg['lr']:g}, "
      f"reprojection weight {photo_cfg['lambda_reprojection']:g}")
assert photo_cfg["labels_from"] == trained_name and photo_cfg["lambda_reprojection"] > 0

photo_folder = default_photo_folder()
if photo_folder is None:
    print("no photograph folder found (../shared/data/photos or $EVIO_PHOTOS): no photograph to label")
else:
    counts = {split: len(list_photos(photo_folder, split)) for split in ("train", "val", "test")}
    print(f"photographs per split: {counts}")
    photo = fit_photo(load_photo(list_photos(photo_folder, "train")[0]), tuple(photo_cfg["image_size"]))
    photo_adapted = homographic_adaptation(photo, cnn_heatmaps, rng=3, n_homographies=photo_cfg["n_homographies"])
    photo_labels, _ = heatmap_to_keypoints(photo_adapted.heatmap, photo_cfg["label_threshold"], nms_radius=4,
                                           border=4, max_keypoints=photo_cfg["label_max_keypoints"])
    print(f"{len(photo_labels)} labels on the first training photograph")
    fig = plot_heatmap_row([photo, photo_adapted.heatmap, photo],
                           ["training photograph", f"aggregate over {photo_cfg['n_homographies']} warps",
                            "its labels (the run labelled random crops)"],
                           ["gray", "magma", "gray"], points={2: photo_labels},
                           colorbar_labels={1: "keypoint probability"})
    plt.show()
    assert 0 < len(photo_labels) <= photo_cfg["label_max_keypoints"]

# %% [markdown]
# ### The project's trained networks
#
# Four trained networks come with the project (`evio_lib/weights/`); lesson 08 evaluates them. Two follow the
# thesis's chain: `pretrained_detdesc_round2_cpu` from the steps printed above (its line below gives the step of the
# checkpoint that was kept), and section 1's network, the thesis's pre-trained Round 1 step (a DetDesc run started
# from MagicPoint's weights, where the chain above starts `detdesc_round1` from random weights), trained on a GPU
# with the settings its line prints below. The third, `distilled_narrow`, has half the channels and learned to give
# the outputs of section 1's network: per 8 x 8 cell the same softmax over the 65 channels and descriptors pointing
# the same way (**knowledge distillation**: a small network trained to copy a larger one;
# `evio_lib/features/training/distill.py`). The fourth, `photos_detdesc`, is section 1's network trained further on
# natural photographs with the reprojection loss (the subsection above;
# `evio_lib/features/training/reprojection.py`); it is the one `create_detector("superpoint")` loads (the cell
# prints the name).
# The cell prints what each weights file says about its training and checks that none of them collapsed
# (section 3): it measures the two cosines and the retrieval of each on validation pairs. None of them was trained
# on these images, though every checkpoint was chosen on validation images: the distilled network's by its loss,
# `photos_detdesc`'s by its homography scores on validation photographs (lesson 08 defines them), the others by their
# retrieval.

# %%
val_cfg = training.load_config("pretrained_detdesc_round2")
val_pairs = RealImages(image_pool("val", seed=0, size=val_cfg.image_size, n_images=4 if FAST else 16,
                                  render_zoom=val_cfg.render_zoom),
                       split="val", seed=0, pairs=True, augment=False, pair_homographic=val_cfg.pair_homographic())
items = [val_pairs[k] for k in range(len(val_pairs))]  # each pair drawn once, shared by the networks


def is_superpoint(name: str) -> bool:
    """True if a weights file holds a SuperPoint network (evio_lib/weights also holds other models)."""
    try:
        load_checkpoint(resolve_weights(name))
    except ValueError:
        return False
    return True


def training_summary(name: str) -> str:
    """What a weights file's metadata says about its training, in one line."""
    meta = load_checkpoint(resolve_weights(name))["metadata"]
    cfg = meta["config"]
    what = (f"copies {cfg['labels_from']}" if cfg["stage"] == "distill" else
            f"{cfg['name']}, labels by {cfg['n_homographies']} warps")
    return (f"{cfg['model']} network, {what}; {meta['step']} steps of {cfg['batch_size']} at "
            f"{cfg['image_size'][0]}x{cfg['image_size'][1]}, lr {cfg['lr']:g}")


names = [name for name in sorted(shipped_weights()) if is_superpoint(name)]  # evio_lib/weights/*.pt
assert names, "no trained SuperPoint weights in evio_lib/weights"
chance = 3 / (val_cfg.image_size[0] * val_cfg.image_size[1] / 64)  # ~3 corresponding cells among all
print(f"{len(items)} validation pairs; chance retrieval about {chance:.0%}; "
      f"create_detector('superpoint') loads {DEFAULT_WEIGHTS}")
for name in names:  # loop over the trained networks
    net = load_model(resolve_weights(name)).eval()
    with torch.no_grad():
        stats = [descriptor_cell_stats(net(item.image[None])["descriptors"],
                                       net(item.warped_image[None])["descriptors"], item.homography[None],
                                       valid_mask=item.valid_mask[None], valid_mask_warped=item.warped_valid_mask[None])
                 for item in items]
    pos, neg, nn = np.nanmean(np.array(stats, dtype=float), axis=0)  # DescriptorStats: positive, negative, retrieval
    print(f"{name:30s} {training_summary(name)}\n{'':30s} cos(corresponding) {pos:.2f}  cos(others) {neg:.2f}  "
          f"retrieval {nn:.0%}")
    assert neg < 0.2 < pos and nn > 0.2  # not collapsed: others below m_n, and retrieval far above chance

# %% [markdown]
# ## Summary
#
# * Real images have no interest-point labels. **Homographic adaptation** makes them: run a detector on $N$
#   random warps of the image, map the responses back and average them. The aggregate is closer to equivariant
#   than one view (section 1 measured how much), so its maxima are repeatable labels.
# * Training alternates **label export** and **training rounds**; each round's model labels the images for the
#   next (thesis §3.2.5).
# * The full network learns descriptors from **warped pairs**: $\mathcal{H}$ gives the cell correspondences
#   $S$ (Eq. 10), and a hinge loss (Eqs. 11-12) pulls corresponding cells together and pushes the rest apart;
#   a few lines of NumPy reproduce the library's loss.
# * `evio_lib.features.training.train` runs any step from a config (labels, pairs, Eq. 8, validation, checkpoints);
#   the thesis's best chain is `python -m evio_lib features-train pretrained_detdesc_round2 --chain`.
# * A short pre-trained run at the thesis's small learning rate moves some of the detector's points onto corners
#   (section 3 counted them); its descriptors, and most of its keypoints, need far longer training, as the project's
#   trained network shows on the same test.
# * A falling loss does not prove useful descriptors: they can collapse (every descriptor alike), so the DetDesc
#   configs keep the checkpoint with the best retrieval. A briefly trained detector responds weakly, so the label
#   export uses a low threshold and keeps the strongest points (`label_threshold`, `label_max_keypoints`).
#
# ## Exercises
#
# 1. Plot the relative difference of section 1 against the number of warps $N$ (1, 5, 20, 60, 100). How fast does it
#    fall, and where is the point of diminishing returns for the label export?
#
#    *Hint:* wrap section 1's equivariance comparison in a function of $N$ (`homographic_adaptation` with
#    `n_homographies=N` on `image` and on `warped`, then `compare`).
# 2. Aggregate with the maximum instead of the mean in `homographic_adaptation`. Are the labels more or less
#    repeatable?
#
#    *Hint:* `homographic_adaptation(..., aggregation='max')` (the default is `'mean'`); take labels as in section 1
#    from the image and its warp, count them, then keep the strongest 50 of each (`max_keypoints=50`) so that both
#    aggregations are compared on as many points, and compute their `repeatability` at 1 and 3 px
#    (`evio_lib.features.evaluation.evaluate`).
# 3. Compute $S$ for a homography that scales by 2. How many positives does a cell of image 1 get, and what does
#    that mean for $\lambda_d$?
#
#    *Hint:* `cell_correspondences(np.diag([2.0, 2.0, 1.0]), (15, 20))` (the cell grid of a 120 x 160 image): count
#    the positives per row (cells of image 1) and per column.
# 4. Train the descriptor run of section 3 with `lambda_d=250` and with `lambda_d=6`. Follow the two cosines and the
#    retrieval in `dd_result.validation`: which setting collapses the descriptors, and which one stops pulling
#    corresponding cells together? Then train it with `lr=1e-3`: what happens to the share of keypoints on corners
#    and to the correct matches of section 3?
#
#    *Hint:* pass `lambda_d=` or `lr=` to the `detdesc_round1` config of section 3, print `desc_positive_dot`,
#    `desc_negative_dot` and `desc_nn_accuracy` of each validation, and score `best_path` with `match_pair`.
# 5. Run the matching of section 3 with the strong training warp (`HOMOGRAPHIC_PAIR`, rotations up to 90 degrees).
#    Which network suffers more, the trained or the untrained one?
#
#    *Hint:* replace `mild` by `HOMOGRAPHIC_PAIR` in `homographic_augment` and compare the correct matches of both
#    networks with the mild ones.
# 6. Shift a validation-pool image by 0.5, 1, 2.5 and 8 px (a homography that only translates) and detect with the
#    trained network and with Harris on both images. Which shifts does each detector follow exactly, and why would a
#    1.5x zoom hurt every single-scale detector?
#
#    *Hint:* `H = np.eye(3); H[0, 2] = dx`, `warp_image(image, H)`, then `repeatability(k1, k2, H, shape, shape,
#    eps=1)` and `localisation_error(k1, k2, H, shape, shape, eps=3)` from `evio_lib.features.evaluation.evaluate`.
#
# Worked solutions, with the code to run:
# [docs/solutions/07_homographic_adaptation_and_superpoint_training.md](../docs/solutions/07_homographic_adaptation_and_superpoint_training.md).
