"""Tests of evio_lib.features.training.losses: hand-made cases with known values, a loop reference, masks, randomness,
gradients."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import log_softmax

from evio_lib.features.network import build_model
from evio_lib.features.training import losses
from evio_lib.geometry.homography import warp_points


def _one_label_map(rng: np.random.Generator, hc: int, wc: int, p_empty: float = 0.3) -> tuple[torch.Tensor, np.ndarray]:
    """Return a (1, 8hc, 8wc) keypoint map with at most one label per cell and the (hc, wc) true cell labels."""
    kmap = np.zeros((8 * hc, 8 * wc), np.float32)
    labels = np.full((hc, wc), 64)
    for h in range(hc):
        for w in range(wc):
            if rng.random() > p_empty:
                k = int(rng.integers(64))
                labels[h, w] = k
                kmap[8 * h + k // 8, 8 * w + k % 8] = 1.0
    return torch.from_numpy(kmap)[None], labels


# ---------------------------------------------------------------------------------------------- labels
def test_labels_single_keypoint_per_cell(rng: np.random.Generator) -> None:
    kmap, labels = _one_label_map(rng, 3, 5)
    out = losses.keypoint_map_to_labels(kmap, generator=0)
    assert out.shape == (1, 3, 5) and out.dtype == torch.int64
    np.testing.assert_array_equal(out[0].numpy(), labels)


def test_random_label_choice_covers_all_pixels_and_is_seeded() -> None:
    kmap = torch.zeros(1, 8, 8)
    pixels = [(0, 0), (3, 5), (7, 7)]  # (row, col) -> labels 0, 29, 63
    for r, c in pixels:
        kmap[0, r, c] = 1.0
    gen = torch.Generator().manual_seed(0)
    picks = [int(losses.keypoint_map_to_labels(kmap, gen)[0, 0, 0]) for _ in range(300)]
    counts = {k: picks.count(k) for k in set(picks)}
    assert set(counts) == {0, 29, 63}  # only labelled pixels, all of them
    assert all(70 <= n <= 130 for n in counts.values()), counts  # ~uniform (100 each; 6 sigma ~ 49)
    a = losses.keypoint_map_to_labels(kmap.repeat(4, 1, 1), 5)
    b = losses.keypoint_map_to_labels(kmap.repeat(4, 1, 1), torch.Generator().manual_seed(5))
    assert torch.equal(a, b)  # a seed and a generator with that seed agree
    with pytest.raises(ValueError, match="generator must be a torch.Generator or an int seed"):
        losses.keypoint_map_to_labels(kmap, None)


def test_cell_valid_mask_and_centres() -> None:
    mask = torch.ones(2, 16, 16)
    mask[1, 15, 0] = 0.0
    cells = losses.cell_valid_mask(mask)
    assert cells.shape == (2, 2, 2)
    assert cells[0].all() and cells[1].tolist() == [[True, True], [False, True]]
    assert losses.cell_centres((1, 2)).tolist() == [[3.5, 3.5], [11.5, 3.5]]
    with pytest.raises(ValueError, match="multiples of 8"):
        losses.cell_valid_mask(torch.ones(1, 10, 16))


# ---------------------------------------------------------------------------------------------- detector loss
def test_detector_loss_perfect_and_uniform_logits(rng: np.random.Generator) -> None:
    kmap, labels = _one_label_map(rng, 4, 6)
    perfect = torch.full((1, 65, 4, 6), -15.0)
    perfect.scatter_(1, torch.from_numpy(labels)[None, None], 15.0)  # +15 at the true class
    assert float(losses.detector_loss(perfect, kmap, generator=0)) < 1e-10
    uniform = torch.zeros(1, 65, 4, 6)
    assert float(losses.detector_loss(uniform, kmap, generator=0)) == pytest.approx(math.log(65), rel=1e-6)


def test_detector_loss_matches_numpy_reference(rng: np.random.Generator) -> None:
    kmap, labels = _one_label_map(rng, 3, 4)
    logits = rng.normal(0, 2, (1, 65, 3, 4)).astype(np.float32)
    expected = -np.mean(np.take_along_axis(log_softmax(logits[0].astype(np.float64), axis=0), labels[None], 0))  # Eq. 9
    got = losses.detector_loss(torch.from_numpy(logits), kmap, generator=0)
    assert float(got) == pytest.approx(expected, rel=1e-5)


def test_detector_loss_ignores_invalid_cells(rng: np.random.Generator) -> None:
    kmap, labels = _one_label_map(rng, 2, 2)
    logits = torch.full((1, 65, 2, 2), -15.0)
    logits.scatter_(1, torch.from_numpy(labels)[None, None], 15.0)
    logits[0, :, 1, 1] = torch.from_numpy(rng.normal(0, 5, 65).astype(np.float32))  # wrong cell (1, 1) ...
    mask = torch.ones(1, 16, 16)
    mask[0, 12, 12] = 0.0  # ... that is not fully valid
    assert float(losses.detector_loss(logits, kmap, generator=0, valid_mask=mask)) < 1e-10
    assert float(losses.detector_loss(logits, kmap, generator=0)) > 0.1
    assert float(losses.detector_loss(logits, kmap, generator=0, valid_mask=torch.zeros(1, 16, 16))) == 0.0


def test_detector_loss_bad_input() -> None:
    with pytest.raises(ValueError, match=r"logits must be a \(B, 65, Hc, Wc\)"):
        losses.detector_loss(torch.zeros(1, 64, 2, 2), torch.zeros(1, 16, 16), generator=0)
    with pytest.raises(ValueError, match="keypoint_map must have shape"):
        losses.detector_loss(torch.zeros(1, 65, 2, 2), torch.zeros(1, 16, 24), generator=0)
    with pytest.raises(ValueError, match="valid_mask must have shape"):
        losses.detector_loss(
            torch.zeros(1, 65, 2, 2), torch.zeros(1, 16, 16), generator=0, valid_mask=torch.ones(1, 8, 8)
        )


# ---------------------------------------------------------------------------------------------- correspondences
def test_correspondences_match_loop_with_warp_points(rng: np.random.Generator) -> None:
    theta = 0.2
    H = np.array([
        [1.05 * np.cos(theta), -np.sin(theta), 6.0],
        [np.sin(theta), 0.95 * np.cos(theta), -3.0],
        [1e-4, -2e-4, 1.0],
    ])
    s = losses.cell_correspondences(torch.from_numpy(H)[None], (3, 4), (4, 5)).numpy()[0]
    assert s.shape == (12, 20)
    centres1 = [(8 * w + 3.5, 8 * h + 3.5) for h in range(3) for w in range(4)]
    centres2 = [(8 * w + 3.5, 8 * h + 3.5) for h in range(4) for w in range(5)]
    warped = warp_points(H, centres1)  # independent homography code
    expected = np.array([[float(np.hypot(*(warped[i] - np.array(c))) < 8.0) for c in centres2] for i in range(12)])
    np.testing.assert_array_equal(s, expected)
    assert expected.sum() > 6  # the case is not trivially empty
    s_neg = losses.cell_correspondences(-2.0 * H, (3, 4), (4, 5)).numpy()[0]  # same homography, other scale
    np.testing.assert_array_equal(s_neg, s)


def test_correspondences_translation_by_one_cell() -> None:
    H = np.array([[1.0, 0, 8.0], [0, 1.0, 0], [0, 0, 1.0]])  # image 2 = image 1 shifted 8 px right
    s = losses.cell_correspondences(H, (1, 3))[0]
    assert s.tolist() == [[0, 1, 0], [0, 0, 1], [0, 0, 0]]
    with pytest.raises(ValueError, match="radius must be a positive"):
        losses.cell_correspondences(H, (1, 3), radius=0.0)


# ---------------------------------------------------------------------------------------------- descriptor loss
def _one_hot_descriptors(dim: int, hc: int, wc: int) -> torch.Tensor:
    """(1, dim, hc, wc) map whose cells hold distinct basis vectors e_0 .. e_{hc wc - 1}."""
    d = torch.zeros(1, dim, hc * wc)
    d[0, torch.arange(hc * wc), torch.arange(hc * wc)] = 1.0
    return d.reshape(1, dim, hc, wc)


def test_descriptor_loss_zero_when_positives_align_and_negatives_far() -> None:
    d = _one_hot_descriptors(8, 2, 3) * 3.0  # raw scale does not matter: descriptors are normalised
    assert float(losses.descriptor_loss(d, d.clone(), np.eye(3))) == 0.0
    # image 2 shifted one cell to the right: cell (h, w) of image 1 is cell (h, w + 1) of image 2
    H = np.array([[1.0, 0, 8.0], [0, 1.0, 0], [0, 0, 1.0]])
    d2 = torch.zeros_like(d)
    d2[..., 1:] = d[..., :-1]
    d2[..., 0] = torch.tensor([0.0, 0, 0, 0, 0, 0, 1.0, 0])[:, None]  # unseen column: an unused direction
    assert float(losses.descriptor_loss(d, d2, H)) == 0.0


def test_descriptor_loss_known_values() -> None:
    d = torch.ones(1, 4, 2, 2)  # every descriptor the same unit vector: d^T d' = 1 for every pair
    # identity: 4 positives with loss 0, 12 negatives with 1 - 0.2 = 0.8 -> mean over 16 pairs
    assert float(losses.descriptor_loss(d, d.clone(), np.eye(3))) == pytest.approx(12 * 0.8 / 16)
    d1 = _one_hot_descriptors(4, 2, 2)  # orthogonal descriptors: positives cost lambda_d * 1, negatives 0
    for lam in (1.0, 250.0):
        got = losses.descriptor_loss(d1, d1.roll(1, dims=3), np.eye(3), lambda_d=lam)
        # d'(h, w) = d(h, w - 1): the 4 positive pairs (h, w)-(h, w) have d^T d' = 0 and cost lam each; the 4
        # negative pairs (h, w)-(h, w + 1) have d^T d' = 1 and cost 1 - 0.2 = 0.8; the other 8 pairs cost 0
        assert float(got) == pytest.approx((4 * lam + 4 * 0.8) / 16)
    # margins are parameters
    assert float(losses.descriptor_loss(d, d.clone(), np.eye(3), negative_margin=1.0)) == 0.0


def test_descriptor_loss_masks(rng: np.random.Generator) -> None:
    d = torch.from_numpy(rng.normal(size=(1, 16, 2, 3)).astype(np.float32))
    d2 = torch.from_numpy(rng.normal(size=(1, 16, 2, 3)).astype(np.float32))
    mask2 = torch.ones(1, 16, 24)
    mask2[0, :, 8:] = 0.0  # only the first column of cells of image 2 is valid
    got = losses.descriptor_loss(d, d2, np.eye(3), valid_mask_warped=mask2)
    expected = losses.descriptor_loss(d, d2[..., :1], np.eye(3))  # same pairs: image 2 cropped to column 0
    assert float(got) == pytest.approx(float(expected), rel=1e-6)
    mask1 = torch.ones(1, 16, 24)
    mask1[0, 8:, :] = 0.0  # only row 0 of image 1
    got = losses.descriptor_loss(d, d2, np.eye(3), valid_mask=mask1)
    expected = losses.descriptor_loss(d[:, :, :1], d2, np.eye(3))
    assert float(got) == pytest.approx(float(expected), rel=1e-6)


def test_descriptor_loss_bad_input() -> None:
    d = torch.zeros(1, 4, 2, 2)
    with pytest.raises(ValueError, match="descriptors_warped must have shape"):
        losses.descriptor_loss(d, torch.zeros(1, 5, 2, 2), np.eye(3))
    with pytest.raises(ValueError, match=r"homographies must have shape \(B, 3, 3\)"):
        losses.descriptor_loss(d, d, np.eye(2))
    with pytest.raises(ValueError, match="lambda_d must be >= 0"):
        losses.descriptor_loss(d, d, np.eye(3), lambda_d=-1.0)
    with pytest.raises(ValueError, match="finite"):
        losses.descriptor_loss(d, d, np.full((3, 3), np.nan))


def test_descriptor_cell_stats_match_a_loop_over_cells(rng: np.random.Generator) -> None:
    d1 = torch.from_numpy(rng.normal(size=(2, 8, 3, 4)).astype(np.float32))
    d2 = d1 + 0.8 * torch.from_numpy(rng.normal(size=(2, 8, 3, 4)).astype(np.float32))  # noisy copies
    H = np.array([[1.0, 0, 8.0], [0, 1.0, 0], [0, 0, 1.0]])  # one cell to the right
    mask2 = torch.ones(2, 24, 32)
    mask2[1, :8] = 0.0  # first cell row of image 2 invalid in the second pair
    got = losses.descriptor_cell_stats(d1, d2.roll(1, dims=3), H, valid_mask_warped=mask2)
    s = losses.cell_correspondences(H, (3, 4))[0].numpy() > 0  # (12, 12), same for both pairs
    pos, neg, hits, total = [], [], 0, 0
    for b in range(2):  # the reference: explicit loops over image pairs and cells
        a = d1[b].flatten(1).numpy()
        c = d2.roll(1, dims=3)[b].flatten(1).numpy()
        a, c = a / np.linalg.norm(a, axis=0), c / np.linalg.norm(c, axis=0)
        valid2 = np.ones(12, bool) if b == 0 else np.arange(12) >= 4
        for i in range(12):
            dots = a[:, i] @ c
            for j in range(12):
                if valid2[j]:
                    (pos if s[i, j] else neg).append(dots[j])
            if (s[i] & valid2).any():
                total += 1
                hits += bool(s[i, np.flatnonzero(valid2)[np.argmax(dots[valid2])]])
    assert got.positive_dot == pytest.approx(np.mean(pos), abs=1e-5)
    assert got.negative_dot == pytest.approx(np.mean(neg), abs=1e-5)
    assert got.nn_accuracy == pytest.approx(hits / total)
    assert 0.0 < got.nn_accuracy < 1.0  # the noise makes some cells miss: the check is not vacuous


def test_descriptor_cell_stats_no_correspondence_is_nan() -> None:
    d = _one_hot_descriptors(4, 1, 2)
    far = np.array([[1.0, 0, 100.0], [0, 1.0, 0], [0, 0, 1.0]])  # everything leaves image 2
    stats = losses.descriptor_cell_stats(d, d.clone(), far)
    assert math.isnan(stats.positive_dot) and math.isnan(stats.nn_accuracy)
    assert stats.negative_dot == pytest.approx(0.5)  # (1 + 0 + 0 + 1) / 4 over the four non-corresponding pairs


# ---------------------------------------------------------------------------------------------- total loss
def test_total_loss_combines_terms_and_gradients_flow(rng: np.random.Generator) -> None:
    net = build_model("narrow", seed=1).train()
    x = torch.from_numpy(rng.random((4, 1, 32, 40)).astype(np.float32))
    out = net(x)
    o1 = {k: v[:2] for k, v in out.items()}
    o2 = {k: v[2:] for k, v in out.items()}
    kmap = (torch.from_numpy(rng.random((2, 32, 40))) > 0.97).float()
    kmap2 = (torch.from_numpy(rng.random((2, 32, 40))) > 0.97).float()
    H = np.stack([np.eye(3), [[1.0, 0, 4.0], [0, 1.0, -2.0], [0, 0, 1.0]]])
    mask2 = torch.ones(2, 32, 40)
    mask2[1, :, :8] = 0.0
    terms = losses.superpoint_loss(o1, o2, kmap, kmap2, H, generator=3, valid_mask_warped=mask2, lambda_loss=0.5)
    assert isinstance(terms, losses.LossTerms)
    g = torch.Generator().manual_seed(3)
    det = losses.detector_loss(o1["logits"], kmap, generator=g)
    det2 = losses.detector_loss(o2["logits"], kmap2, generator=g, valid_mask=mask2)
    desc = losses.descriptor_loss(o1["descriptors"], o2["descriptors"], H, valid_mask_warped=mask2)
    torch.testing.assert_close(terms.total, det + det2 + 0.5 * desc)  # Eq. 8
    torch.testing.assert_close(terms.descriptor, desc)
    terms.total.backward()
    grads = [p.grad for p in net.parameters()]
    assert all(gr is not None and torch.isfinite(gr).all() for gr in grads)
    assert all(float(gr.abs().sum()) > 0 for gr in grads)  # every layer, both heads, gets a gradient


def test_total_loss_detector_only_and_bad_outputs(rng: np.random.Generator) -> None:
    logits = torch.zeros(1, 65, 2, 2, requires_grad=True)
    kmap = torch.zeros(1, 16, 16)
    terms = losses.superpoint_loss({"logits": logits}, {"logits": logits}, kmap, kmap, np.eye(3), generator=0)
    assert float(terms.descriptor) == 0.0
    assert float(terms.total.detach()) == pytest.approx(2 * math.log(65), rel=1e-6)
    with pytest.raises(ValueError, match="outputs must be the network's output dict"):
        losses.superpoint_loss(logits, {"logits": logits}, kmap, kmap, np.eye(3), generator=0)
    with pytest.raises(ValueError, match="lambda_loss must be"):
        out = {"logits": logits}
        losses.superpoint_loss(out, out, kmap, kmap, np.eye(3), generator=0, lambda_loss=-1)
