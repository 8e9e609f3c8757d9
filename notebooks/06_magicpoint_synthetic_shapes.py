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
# # 06 — MagicPoint: a corner detector learned from Synthetic Shapes
#
# Lesson 05 built corner detectors by hand. The thesis (Friedel 2020, §3.2) instead *learns* a detector and a
# descriptor with one convolutional network, SuperPoint (DeTone, Malisiewicz and Rabinovich, 2018). Learning needs
# labels, and no large data set of photographs says where its "interest points" are. SuperPoint's trick is to start
# where the answer is unambiguous: **Synthetic Shapes**, simple rendered geometry whose corners and junctions are
# known exactly. A detector trained only on them is called **MagicPoint**; lesson 07 uses it to label real images
# (homographic adaptation) and trains the full network on them.
#
# This lesson:
#
# 1. looks at the Synthetic Shapes generator and its labels;
# 2. builds the network of thesis Fig. 12 and explains its 65-channel "cell + dustbin" output and depth-to-space;
# 3. writes the detector loss (Eq. 9) in a few lines and checks it against `evio_lib.features.training.losses`;
# 4. trains MagicPoint for a short while with `evio_lib.features.training.train` and plots the loss curve;
# 5. measures precision and recall (Eqs. 13-14) of its detections on held-out synthetic images.

# %% [markdown]
# The network of this lesson and the next, before any code: one shared encoder shrinks the image to an
# H/8 x W/8 grid of cells; the detector head gives each cell 65 scores (64 pixel positions and a "no point"
# dustbin), the descriptor head one 256-D descriptor. Section 2 builds exactly this.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_schematics import plot_superpoint_schematic

fig = plot_superpoint_schematic()
plt.show()

# %%
import tempfile

import matplotlib.pyplot as plt
import numpy as np
import torch
import torch.nn.functional as F
from IPython.display import Markdown, display

from evio_lib.course import fast_mode
from evio_lib.evaluation.plots_features import (
    plot_cell_probabilities,
    plot_detections,
    plot_labelled_images,
    plot_training_curve,
)
from evio_lib.features.network import (
    SuperPointDetector,
    build_model,
    count_parameters,
    load_checkpoint,
    logits_to_heatmap,
    resolve_weights,
    shipped_weights,
)
from evio_lib.features.training import train as training
from evio_lib.features.training.losses import detector_loss, keypoint_map_to_labels
from evio_lib.features.training.metrics import keypoints_to_map, precision_recall
from evio_lib.features.training.shapes import (
    SHAPE_COUNTS,
    SHAPE_KINDS,
    UNLABELLED_KINDS,
    SyntheticShapes,
    generate_shape_image,
)

FAST = fast_mode()
rng = np.random.default_rng(6)
_ = torch.manual_seed(0)  # nothing below draws from torch's global generator; this only guards against surprises

# %% [markdown]
# ## 1. Synthetic Shapes
#
# The generator draws one kind of shape per image over a smooth random background: checkerboards, cubes,
# ellipses, lines, polygons (one or several), stars, stripes and pure noise. Their keypoints are the corners and
# junctions of the drawn geometry — exact, sub-pixel, without any detector involved. Ellipses and noise carry
# **no** keypoints on purpose: the network must learn that blobs and texture noise are not corners.
#
# The thesis's proportions (§3.2.1): 66 000 images, 10 000 of every kind except ellipses (3 000), stripes (2 000)
# and noise (1 000); one and several polygons count as two kinds here, as in SuperPoint, which makes the total add
# up. The images are generated on the fly from a seed, so the "data set" takes no disk space.

# %%
print({kind: SHAPE_COUNTS[kind] for kind in SHAPE_KINDS}, "total", sum(SHAPE_COUNTS.values()))
assert sum(SHAPE_COUNTS.values()) == 66_000 and (SHAPE_COUNTS["ellipses"], SHAPE_COUNTS["stripes"],
                                                 SHAPE_COUNTS["gaussian_noise"]) == (3_000, 2_000, 1_000)
examples = {kind: generate_shape_image(kind, (120, 160), rng) for kind in SHAPE_KINDS}  # kind -> (image, keypoints)
assert all(len(examples[kind][1]) == 0 for kind in UNLABELLED_KINDS)  # blobs and noise: nothing to detect
fig = plot_labelled_images([im for im, _ in examples.values()], [kp for _, kp in examples.values()],
                           [f"{kind} ({len(kp)} keypoints)" for kind, (_, kp) in examples.items()], ncols=5)
plt.show()

# %% [markdown]
# For training, each image is also **augmented** (thesis §3.2.5): photometric changes (noise, brightness, contrast,
# shading, motion blur) and a random homography that warps the image, its keypoints and a *valid mask* of the
# pixels that still show the image. The training set returns `(image, keypoint_map, valid_mask)` tensors.

# %%
shapes = SyntheticShapes(8, seed=0, shape=(120, 160))  # train split: augmented
samples = [shapes[i] for i in range(4)]  # (image, keypoint_map, valid_mask) tensors
fig = plot_labelled_images([im[0].numpy() for im, _, _ in samples],
                           [np.argwhere(kmap.numpy())[:, ::-1] for _, kmap, _ in samples],  # (row, col) -> (x, y)
                           [f"{shapes.kind_of(i)} (augmented)" for i in range(4)],
                           masks=[valid.numpy() for _, _, valid in samples], ncols=4, panel_in=4.0)
plt.show()
image, keypoint_map, valid = samples[-1]
print("image", tuple(image.shape), image.dtype, "| keypoint map", tuple(keypoint_map.shape), "| valid mask",
      tuple(valid.shape))

# %% [markdown]
# ## 2. The network (thesis Fig. 12)
#
# A VGG-style **encoder** of eight 3x3 convolutions (depths 64-64-64-64-128-128-128-128) with a 2x2 max-pool after
# every second one of the first six shrinks an $H \times W$ image to an $H/8 \times W/8$ grid of **cells**. Two heads
# sit on the shared encoder: the **detector head** (3x3x256, then 1x1x65) and the **descriptor head** (3x3x256, then
# 1x1x256). Every 3x3 convolution is followed by batch normalisation (each channel rescaled to zero mean and unit
# variance over the batch, then by a learned scale and offset) and ReLU. For inference the library folds each batch
# normalisation into the convolution before it (`inference="fused"`: the same outputs, fewer operations). MagicPoint
# is the same network without the descriptor head. The hooks below print the shape after every block for a 120 x 160
# image.

# %%
net = build_model("full", seed=0).eval()
shapes_seen = []
hooks = [module.register_forward_hook(lambda m, i, o, name=name: shapes_seen.append((name, tuple(o.shape))))
         for name, module in net.named_modules() if name.count(".") == 1]  # the blocks of the encoder and heads
with torch.no_grad():
    out = net(torch.zeros(1, 1, 120, 160))
for hook in hooks:
    hook.remove()
for name, shape in shapes_seen:
    print(f"{name:20s} -> {shape}")
n_params = count_parameters(net)
print(f"parameters: {n_params:,} (MagicPoint without the descriptor head: "
      f"{count_parameters(build_model('full', detector_only=True)):,})")
assert tuple(out["logits"].shape) == (1, 65, 15, 20) and tuple(out["descriptors"].shape) == (1, 256, 15, 20)

# %% [markdown]
# ### The 65 channels: 64 pixels of a cell and a "dustbin"
#
# Each cell covers 8 x 8 = 64 pixels. The detector head outputs 65 numbers per cell: one logit (an unnormalised
# score) for each of the 64
# pixels and one for "no keypoint in this cell" (the **dustbin**). A softmax over the 65 turns them into
# probabilities; dropping the dustbin leaves 64 probabilities, and **depth-to-space** (pixel shuffle) puts channel
# $k$ of cell $(h, w)$ back at pixel $(8h + \lfloor k/8 \rfloor,\; 8w + k \bmod 8)$:
#
# $$P(8h + r, 8w + c) = \frac{e^{x_{hw}(8r + c)}}{\sum_{k=0}^{64} e^{x_{hw}(k)}}, \qquad r, c \in \{0..7\}.$$
#
# The network therefore never upsamples with learned layers: it predicts, per cell, *which* pixel (if any) is the
# corner. The picture shows one cell whose logit is large for pixel (row 2, col 5), and the reshaping done by hand
# agrees with `logits_to_heatmap`.

# %%
logits = torch.zeros(1, 65, 2, 3)  # a 2 x 3 grid of cells = a 16 x 24 image
logits[0, 8 * 2 + 5, 0, 1] = 6.0  # cell (0, 1): pixel row 2, col 5 -> image pixel (2, 13)
logits[0, 64, 1, :] = 6.0  # bottom row of cells: confident "no keypoint"
prob = torch.softmax(logits, dim=1)[:, :64]  # softmax over 65, drop the dustbin
by_hand = prob.reshape(1, 8, 8, 2, 3).permute(0, 3, 1, 4, 2).reshape(1, 16, 24)  # (h, r, w, c) -> (8h + r, 8w + c)
heat = logits_to_heatmap(logits)
assert torch.allclose(by_hand, heat) and torch.allclose(F.pixel_shuffle(prob, 8)[:, 0], heat)
print("argmax pixel (row, col):", divmod(int(heat[0].argmax()), 24))

fig = plot_cell_probabilities(torch.softmax(logits, dim=1)[0, :, 0, 1].numpy(), heat[0].numpy(), cell_name="(0, 1)")
plt.show()

# %% [markdown]
# ## 3. The detector loss (Eq. 9)
#
# The label of a cell is the index $y_{hw} \in \{0..64\}$ of its keypoint pixel, or 64 when it has none (when a
# cell holds several keypoints, one is picked at random). The loss is the softmax cross-entropy averaged over the
# $H_c W_c$ cells:
#
# $$L_p(\mathcal{X}, \mathcal{Y}) = \frac{1}{H_c W_c} \sum_{h, w} -\log
# \frac{e^{x_{hw}(y_{hw})}}{\sum_{k=0}^{64} e^{x_{hw}(k)}}.$$
#
# A few lines of torch (space-to-depth of the keypoint map, the inverse of depth-to-space, `F.pixel_unshuffle`;
# label = argmax with the dustbin winning empty cells)
# reproduce `losses.detector_loss` on a map with at most one keypoint per cell, where no random choice is needed.

# %%
gen = torch.Generator().manual_seed(0)
x = torch.randn(2, 65, 4, 5, generator=gen)  # logits of 2 images of 32 x 40 pixels
kmap = torch.zeros(2, 32, 40)
cells = torch.randperm(40, generator=gen)[:15]  # 15 cells (of 2 x 4 x 5) get one keypoint each
for c in cells.tolist():
    b, h, w = c // 20, (c % 20) // 5, c % 5
    r, col = torch.randint(0, 8, (2,), generator=gen).tolist()
    kmap[b, 8 * h + r, 8 * w + col] = 1.0

unshuffled = F.pixel_unshuffle(kmap[:, None], 8)  # (B, 64, Hc, Wc): channel 8r + c = pixel (r, c) of the cell
labels = torch.cat([unshuffled, torch.full_like(unshuffled[:, :1], 0.5)], 1).argmax(1)  # dustbin if empty
loss_by_hand = -torch.log_softmax(x, dim=1).gather(1, labels[:, None]).mean()  # Eq. 9
loss_library = detector_loss(x, kmap, generator=0)
print(f"by hand {loss_by_hand:.6f}   library {loss_library:.6f}   uniform guess log(65) = {np.log(65):.6f}")
assert torch.allclose(loss_by_hand, loss_library)
assert torch.equal(labels, keypoint_map_to_labels(kmap, 0))

# %% [markdown]
# ## 4. Training MagicPoint
#
# `evio_lib.features.training.train` runs each training step of the thesis from a config file
# (`evio_lib/features/configs/`, one per variant of thesis Table 1). `magicpoint` comes first: the detector alone, on
# Synthetic Shapes, with Adam (a gradient-descent optimiser that scales each weight's step by its recent gradients).
# The project's config trains the full network on augmented images for thousands of steps
# (`python -m evio_lib features-train magicpoint`). Here we override it with a short run of the **narrow** network
# (half the channels) on small, un-augmented images at a larger learning rate, so that a short run gets somewhere
# (exercise 2 turns the augmentation back on); the cell prints both settings. The trainer validates on held-out
# (un-augmented) images, keeps the best model by validation loss, and writes checkpoints it can resume from.

# %%
run_dir = tempfile.mkdtemp(prefix="evio06_")
if FAST:
    overrides = dict(model="narrow", image_size=(32, 48), batch_size=4, max_steps=8, val_every=4, n_val_images=4)
else:
    overrides = dict(model="narrow", image_size=(64, 88), batch_size=8, max_steps=500, val_every=100, n_val_images=48)
config = training.load_config("magicpoint", checkpoint_dir=run_dir, device="cpu", checkpoint_every=50, num_threads=1,
                              augment=False, lr=3e-3, **overrides)
project_config = training.load_config("magicpoint")
print(f"{'':12s} {'this run':>10s} {'project config':>15s}")
for field in ("model", "image_size", "batch_size", "max_steps", "lr", "augment"):
    print(f"{field:12s} {str(getattr(config, field)):>10s} {str(getattr(project_config, field)):>15s}")
assert (project_config.model, project_config.augment) == ("full", True) and project_config.max_steps >= 1000
result = training.train(config, progress=False)
print(f"{result.steps} steps in {result.seconds:.0f} s; best step {result.best_step}, validation loss "
      f"{result.best_metrics['loss']:.3f}")

# %% [markdown]
# Most cells of a Synthetic Shapes image hold no corner, so a network that ignores the image and only learns how
# often the dustbin is right already lowers the loss. If a share $e$ of the cells is empty, the best such constant
# answer (dustbin with probability $e$, the 64 pixels sharing the rest) costs
# $-e \log e - (1 - e) \log\frac{1 - e}{64}$ per cell. The cell measures $e$ on validation images of this run's size
# and compares.

# %%
losses = np.array(result.train_loss)
fig = plot_training_curve(losses, result.validation, ylabel="detector loss $L_p$",
                          reference=(np.log(65), "log 65 (uniform guess)"))
plt.show()
val_maps = SyntheticShapes(32, split="val", seed=0, shape=config.image_size)
cells = np.stack([F.max_pool2d(val_maps[i][1][None, None], 8)[0, 0].numpy() for i in range(len(val_maps))])
empty = float(np.mean(cells == 0))
constant_loss = -empty * np.log(empty) - (1 - empty) * np.log((1 - empty) / 64)
print(f"training loss: first step {losses[0]:.2f}, mean of the last 3 steps {losses[-3:].mean():.2f}; best "
      f"validation loss {result.best_metrics['loss']:.2f}")
print(f"empty cells: {empty:.1%}; the best constant answer costs {constant_loss:.2f}")
assert abs(losses[0] - np.log(65)) < 0.5  # starts near the uniform guess
assert losses[-3:].mean() < losses[:3].mean()  # the detector loss goes down

# %%
beats = result.best_metrics["loss"] < constant_loss
display(Markdown(
    f"The loss starts at {losses[0]:.2f}, near $\\log 65 \\approx 4.17$ (65 equally likely classes). With "
    f"{empty:.0%} of the cells empty, the constant answer would cost {constant_loss:.2f}; this run's best validation "
    f"loss is {result.best_metrics['loss']:.2f}, "
    + ("below it: the network has begun to place keypoints inside their cells, which is what the long runs refine."
       if beats else
       "not yet below it: the network has not yet learned even how often a cell is empty.")))

# %% [markdown]
# ## 5. Detections, precision and recall (Eqs. 13-14)
#
# With a binary map of detections $y_\text{pred}$ (after the 1/65 threshold and non-maximum suppression, NMS: only
# the strongest point within a radius survives) and of labels $y_\text{true}$,
#
# $$p = \frac{\sum y_\text{true}\, y_\text{pred}}{\sum y_\text{pred}}, \qquad
# r = \frac{\sum y_\text{true}\, y_\text{pred}}{\sum y_\text{true}},$$
#
# and their relaxed versions count a detection as correct when a label lies within 1 pixel. We evaluate on the
# **test** split of the generator (images never seen in training or validation), un-augmented.

# %%
test_shapes = SyntheticShapes(6 if FAST else 64, split="test", seed=0, shape=config.image_size)


def evaluate(detector, data):
    """Return precision/recall (exact and 1 px) and the detections of a detector on a SyntheticShapes split."""
    preds, trues, detections = [], [], []
    for i in range(len(data)):
        image, keypoint_map, _ = data[i]
        features = detector.detect_and_describe(image[0].numpy())
        preds.append(keypoints_to_map(features.keypoints, keypoint_map.shape))
        trues.append(keypoint_map.numpy())
        detections.append(features.keypoints)
    exact = precision_recall(np.stack(preds), np.stack(trues))
    within = precision_recall(np.stack(preds), np.stack(trues), tolerance=1)
    return exact, within, detections


trained = SuperPointDetector(weights=result.best_path, inference="fused", nms_radius=4, border=2)
untrained = SuperPointDetector(weights=None, allow_random=True, model_config="narrow", inference="fused", border=2)
rows, scores = {}, {}
for name, detector in (("untrained", untrained), ("MagicPoint (this run)", trained)):
    exact, within, detections = evaluate(detector, test_shapes)
    rows[name] = detections
    scores[name] = within
    print(f"{name:24s} precision {exact[0]:.3f}  recall {exact[1]:.3f}   within 1 px: precision {within[0]:.3f}  "
          f"recall {within[1]:.3f}")
    assert 0.0 <= min(exact + within) and max(exact + within) <= 1.0
    assert within[0] >= exact[0] and within[1] >= exact[1]  # the 1 px tolerance only adds hits

labels_stack = np.stack([test_shapes[i][1].numpy() for i in range(len(test_shapes))])
chance = precision_recall(np.ones_like(labels_stack), labels_stack, tolerance=1)[0]  # a detection on every pixel
flat = untrained.heatmap(test_shapes[0][0][0].numpy()) * 65  # probabilities in units of 1/65
offsets = np.concatenate(rows["untrained"]).astype(int) % 8  # position of each detection inside its 8 x 8 cell
grid_share = max(np.bincount(offsets[:, 0], minlength=8).max(), np.bincount(offsets[:, 1], minlength=8).max())
print(f"untrained heatmap: {flat.min():.2f}/65 to {flat.max():.2f}/65; "
      f"{grid_share / len(offsets):.0%} of its detections share one column or row inside their cell")
print(f"chance: a detection on every pixel would be within 1 px of a label with precision {chance:.3f}")
assert 0.8 < flat.min() and flat.max() < 1.2  # nearly uniform
assert grid_share > 0.5 * len(offsets)  # a regular grid, not the image's structure
assert scores["untrained"][0] < 1.5 * chance  # about chance
assert scores["MagicPoint (this run)"][0] > 2 * scores["untrained"][0]  # training: more detections on corners
assert scores["MagicPoint (this run)"][1] < 0.8  # but corners are still missed

# %%
shown = range(4)  # the first four test images
test_images = [test_shapes[i][0][0].numpy() for i in shown]
test_labels = [np.argwhere(test_shapes[i][1].numpy())[:, ::-1] for i in shown]  # (row, col) -> (x, y)
fig = plot_detections(test_images, test_labels, rows, titles=[test_shapes.kind_of(i) for i in shown])
plt.show()

# %%
(p_untrained, r_untrained), (p_run, r_run) = scores["untrained"], scores["MagicPoint (this run)"]
ratio = p_run / p_untrained
display(Markdown(
    f"The untrained network does not look at the image at all: its heatmap is nearly flat (from "
    f"{flat.min():.2f}/65 to {flat.max():.2f}/65), so which pixel of a cell wins is decided by small, fixed "
    f"differences of its random filters, and NMS turns them into the **regular grid** of the top row: "
    f"{grid_share / len(offsets):.0%} of its detections share one column or row inside their 8 x 8 cell. Its "
    f"precision within 1 px, {p_untrained:.3f}, is at the level of chance, a detector that fires on every pixel "
    f"({chance:.3f}). After {result.steps} steps the detections are {ratio:.{0 if ratio >= 10 else 1}f} times as "
    f"precise "
    f"({p_run:.3f}), and the recall rose from {r_untrained:.3f} to {r_run:.3f}: {1 - r_run:.0%} of the corners are "
    f"still missed."))

# %% [markdown]
# ### A longer-trained network on the same test
#
# The project comes with networks trained much longer (`evio_lib/weights/`). The one used here has the full width;
# its detector began as a MagicPoint trained on about 500 000 **augmented** Synthetic Shapes images at 120 x 160
# (noise, blur, brightness changes, warps), and was then trained further, together with the descriptor, on labels of
# real images (photographs, renders, textures) made by homographic adaptation (lesson 07): corners of real images,
# not of drawings. The cell prints what its weights file says about that second training. Two tests: the clean test
# images above, the distribution this short run was trained on, and the same images augmented, closer to what a
# detector meant for real frames meets.

# %%
available = shipped_weights()
longer_name = "pretrained_detdesc_round1_gpu"  # evio_lib/weights/<name>.pt
assert longer_name in available, f"no weights {longer_name} in evio_lib/weights"
meta = load_checkpoint(resolve_weights(longer_name))["metadata"]
height, width = meta["config"]["image_size"]
print(f"longer-trained network: {meta['description']}, {meta['step']} steps of {meta['config']['batch_size']} warped "
      f"pairs of real images at {height} x {width}, after MagicPoint")
longer = SuperPointDetector(weights=longer_name, inference="fused", border=2)
augmented_test = SyntheticShapes(len(test_shapes), split="test", seed=0, shape=config.image_size, augment=True)
table = {}
run, ship = "MagicPoint (this run)", "longer-trained network"
for name, detector in ((run, trained), (ship, longer)):
    for split, data in (("clean", test_shapes), ("augmented", augmented_test)):
        table[name, split] = evaluate(detector, data)[1]  # (precision, recall) within 1 px
print(f"{'within 1 px':26s} {'clean: precision':>17s} {'recall':>7s} {'augmented: precision':>21s} {'recall':>7s}")
for name in (run, ship):
    (pc, rc), (pa, ra) = table[name, "clean"], table[name, "augmented"]
    print(f"{name:26s} {pc:17.3f} {rc:7.3f} {pa:21.3f} {ra:7.3f}")
assert table[ship, "clean"][1] > table[run, "clean"][1]  # clean: the longer-trained network finds more corners
assert table[run, "augmented"][0] < 0.5 * table[run, "clean"][0]  # augmented: the short run loses most precision
assert table[ship, "augmented"][0] < table[ship, "clean"][0]  # the longer-trained network loses precision too
assert table[ship, "augmented"][0] > table[run, "augmented"][0]  # and it is ahead of the short run there

# %%
(pc_run, rc_run), (pa_run, ra_run) = table[run, "clean"], table[run, "augmented"]
(pc_ship, rc_ship), (pa_ship, ra_ship) = table[ship, "clean"], table[ship, "augmented"]
clean_precision = (f"and also places more of its detections within 1 px of a label ({pc_ship:.3f} against "
                   f"{pc_run:.3f})" if pc_ship > pc_run else
                   f"but places fewer of its detections within 1 px of a label ({pc_ship:.3f} against the short "
                   f"run's {pc_run:.3f}): the short run was trained on exactly this distribution, un-augmented "
                   f"shapes at this image size, while the longer training saw augmented drawings at 120 x 160 "
                   f"and then the corners of real images")
display(Markdown(
    f"On the clean test images the longer-trained network finds more of the corners (recall {rc_ship:.3f} against "
    f"{rc_run:.3f}) {clean_precision}. On the augmented images both lose precision: the short run, which never saw "
    f"noise or blur, falls from {pc_run:.3f} to {pa_run:.3f}, the longer-trained network from {pc_ship:.3f} to "
    f"{pa_ship:.3f}, and there it is ahead ({pa_ship:.3f} against {pa_run:.3f}, recall {ra_ship:.3f} against "
    f"{ra_run:.3f})."))

# %% [markdown]
# ## Summary
#
# * Synthetic Shapes gives exact keypoint labels for free: corners and junctions of rendered geometry, with blobs
#   and noise as negatives, generated on the fly from a seed in the thesis's proportions.
# * The SuperPoint network is a shared VGG-style encoder to 1/8 resolution plus two heads. The detector head
#   classifies each 8 x 8 cell into 64 pixel positions or a "no keypoint" dustbin; softmax, dropping the dustbin
#   and depth-to-space give a full-resolution keypoint probability map.
# * The detector loss (Eq. 9) is a 65-way cross-entropy per cell; a few lines of torch reproduce the library's.
# * `evio_lib.features.training.train` trains any variant of thesis Table 1 from its config, with validation, best-model
#   selection, checkpoints and exact resume. MagicPoint is the first step; precision and recall (Eqs. 13-14) on
#   held-out images track its progress.
# * A short run already puts its detections on corners far more often than chance (section 5 measured how much);
#   a longer-trained network finds more of the corners and keeps more of its precision on augmented images.
#
# ## Exercises
#
# 1. Train with `model="full"` for the same number of steps. How do time per step and the validation loss compare
#    with the narrow network?
#
#    *Hint:* keep every other override of the short run, change only `model`; `result.seconds / result.steps` is the
#    time per step.
# 2. The short run switched the augmentation off (`augment=False`; the project's config has `augment=True`). Train
#    with `augment=True` for the same number of steps and again for four times as many. Does the validation loss
#    (un-augmented images) get better or worse, and how do precision and recall on `augmented_test` change?
#
#    *Hint:* train with `augment=True`, then score both runs on `test_shapes` and on `augmented_test` with `evaluate`.
# 3. Change the NMS radius and the 1/65 threshold of the detector and plot precision against recall. Which
#    setting would you pick for a VIO front end that needs ~100 well-spread points?
#
#    *Hint:* compute each heatmap once (`detector.heatmap`, a NumPy array) and sweep
#    `extract_keypoints(torch.from_numpy(heat), threshold=..., nms_radius=..., border=2)`
#    (`evio_lib.features.network`; border 2 as in this lesson, the default is 4).
# 4. Remove the ellipses and noise from the schedule (`counts=` of `SyntheticShapes`) and train again. Does the
#    detector start firing on blobs? (Look at the `ellipses` test images.)
#
#    *Hint:* pass `counts=` without `ellipses` and `gaussian_noise` to `SyntheticShapes`; the trainer builds its data
#    sets inside `train`, so wrap the class it imports.
# 5. Interrupt a training run (`max_steps=20`), resume it with `training.train(config, resume=True)` to 40 steps
#    and check that the weights equal those of an uninterrupted 40-step run.
#
#    *Hint:* train 20 steps into one folder, then `training.train(config_40, resume=True)` there and compare
#    `last.pt`'s `state_dict` with an uninterrupted 40-step run (`torch.equal`).
#
# Worked solutions, with the code to run:
# [docs/solutions/06_magicpoint_synthetic_shapes.md](../docs/solutions/06_magicpoint_synthetic_shapes.md).
