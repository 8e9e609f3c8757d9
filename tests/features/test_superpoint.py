"""Tests of evio_lib.features.network: network shapes and size, post-processing against slow references,
BN folding, fast inference paths, checkpoints and the detector wrapper."""
from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
from scipy.special import softmax

from evio_lib.features import network as sp
from evio_lib.features.network.detector import _register_shipped_variants
from evio_lib.features.network.inference import _bf16_native
from evio_lib.features.network.postprocessing import _nms_torch
from evio_lib.features import base as features_base
from evio_lib.features.base import Features, create_detector, nms_keypoints
from evio_lib.features.network import model as sp_model  # where WEIGHTS_DIR is read


# ---------------------------------------------------------------------------------------------- helpers
@functools.lru_cache(maxsize=None)
def _model(config: str = "full", detector_only: bool = False) -> sp.SuperPointNet:
    """A seeded model whose BN layers carry non-trivial statistics (a few train-mode passes on real-looking images)."""
    net = sp.build_model(config, seed=3, detector_only=detector_only)
    images = torch.from_numpy(np.stack(sp.calibration_images((48, 64), count=4, seed=1)))[:, None]
    net.train()
    with torch.no_grad():
        for bn in (m for m in net.modules() if isinstance(m, torch.nn.BatchNorm2d)):
            bn.momentum = 1.0  # running stats = the statistics of the last batch
            g = torch.Generator().manual_seed(bn.num_features)
            bn.weight.uniform_(0.5, 1.5, generator=g)
            bn.bias.uniform_(-0.2, 0.2, generator=g)
        net(images)
    return net.eval()


def _greedy_nms_reference(scores: np.ndarray, radius: int) -> np.ndarray:
    """Slow greedy box NMS: visit positive pixels by descending score, keep unless a kept one is within the box."""
    kept = np.zeros_like(scores)
    ys, xs = np.nonzero(scores > 0)
    for i in np.argsort(-scores[ys, xs], kind="stable"):
        y, x = ys[i], xs[i]
        if not kept[max(0, y - radius) : y + radius + 1, max(0, x - radius) : x + radius + 1].any():
            kept[y, x] = scores[y, x]
    return kept


def _heatmap_reference(logits: np.ndarray) -> np.ndarray:
    """Slow depth-to-space: a loop over cells and channels of softmax probabilities."""
    _, hc, wc = logits.shape
    prob = softmax(logits.astype(np.float64), axis=0)
    heat = np.zeros((8 * hc, 8 * wc))
    for h in range(hc):
        for w in range(wc):
            for k in range(64):
                heat[8 * h + k // 8, 8 * w + k % 8] = prob[k, h, w]
    return heat


# ---------------------------------------------------------------------------------------------- network
@pytest.mark.parametrize("height,width", [(8, 8), (24, 32), (48, 40), (56, 72)])
def test_output_shapes(height: int, width: int) -> None:
    net = _model()
    with torch.inference_mode():
        out = net(torch.rand(2, 1, height, width, generator=torch.Generator().manual_seed(0)))
    assert out["logits"].shape == (2, 65, height // 8, width // 8)
    assert out["descriptors"].shape == (2, 256, height // 8, width // 8)
    assert out["logits"].dtype == torch.float32


def test_detector_only_and_narrow_shapes() -> None:
    magic = _model("full", detector_only=True)
    with torch.inference_mode():
        out = magic(torch.zeros(1, 1, 16, 24))
    assert set(out) == {"logits"} and out["logits"].shape == (1, 65, 2, 3)
    assert magic.descriptor_dim == 0
    narrow = _model("narrow")
    with torch.inference_mode():
        out = narrow(torch.zeros(1, 1, 16, 24))
    assert out["descriptors"].shape == (1, 256, 2, 3)


def _expected_parameters(enc: list[int], head: int, dim: int | None) -> int:
    """Closed-form count: 3x3 convs without bias + BN (gamma, beta); final 1x1 convs with bias."""
    total, c_in = 0, 1
    for c in enc:
        total += 9 * c_in * c + 2 * c
        c_in = c
    total += 9 * c_in * head + 2 * head + head * 65 + 65  # detector head
    if dim is not None:
        total += 9 * c_in * head + 2 * head + head * dim + dim  # descriptor head
    return total


def test_parameter_count_full_and_variants() -> None:
    full = sp.build_model("full")
    assert sp.count_parameters(full) == _expected_parameters([64] * 4 + [128] * 4, 256, 256) == 1_302_145
    magic = sp.build_model("full", detector_only=True)
    assert sp.count_parameters(magic) == _expected_parameters([64] * 4 + [128] * 4, 256, None)
    narrow = sp.build_model("narrow")
    assert sp.count_parameters(narrow) == _expected_parameters([32] * 4 + [64] * 4, 128, 256)
    assert sp.count_parameters(narrow) < sp.count_parameters(full) / 3
    # layer structure of the thesis: 8 encoder convs + 2 per head, max-pools after convs 2, 4, 6
    convs = [m for m in full.modules() if isinstance(m, torch.nn.Conv2d)]
    assert [c.kernel_size for c in convs] == [(3, 3)] * 9 + [(1, 1), (3, 3), (1, 1)]
    assert sum(isinstance(m, torch.nn.MaxPool2d) for m in full.modules()) == 3
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in full.modules()) == 10


def test_seeded_init_is_deterministic_and_leaves_global_rng_alone() -> None:
    torch.manual_seed(123)
    before = torch.rand(1)
    torch.manual_seed(123)
    a = sp.build_model("narrow", seed=7)
    after = torch.rand(1)
    b = sp.build_model("narrow", seed=7)
    assert torch.equal(before, after)
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))


def test_network_bad_input() -> None:
    net = _model()
    with pytest.raises(ValueError, match=r"x must be a \(B, 1, H, W\)"):
        net(torch.zeros(1, 3, 16, 16))
    with pytest.raises(ValueError, match="multiples of 8"):
        net(torch.zeros(1, 1, 20, 16))
    with pytest.raises(ValueError, match="floating"):
        net(torch.zeros(1, 1, 16, 16, dtype=torch.uint8))
    with pytest.raises(ValueError, match="encoder_channels must be 8"):
        sp.SuperPointNet(encoder_channels=(64, 64))
    with pytest.raises(ValueError, match="config must be"):
        sp.SuperPointNet.from_config("huge")
    with pytest.raises(ValueError, match="unknown keys"):
        sp.SuperPointNet.from_config({"depth": 3})


def test_pad_to_cells_replicates_edges() -> None:
    x = torch.arange(6.0).reshape(1, 1, 2, 3)
    padded = sp.pad_to_cells(x)
    assert padded.shape == (1, 1, 8, 8)
    assert torch.equal(padded[..., :2, :3], x)
    assert torch.equal(padded[0, 0, 7, :3], x[0, 0, 1])  # bottom rows repeat the last row
    assert torch.equal(padded[0, 0, :2, 7], x[0, 0, :, 2])  # right columns repeat the last column


# ---------------------------------------------------------------------------------------------- post-processing
def test_heatmap_matches_loop_reference(rng: np.random.Generator) -> None:
    logits = rng.normal(0.0, 3.0, (65, 2, 3)).astype(np.float32)
    heat = sp.logits_to_heatmap(torch.from_numpy(logits))
    assert heat.shape == (1, 16, 24)
    np.testing.assert_allclose(heat[0].numpy(), _heatmap_reference(logits), atol=1e-6)
    # probabilities of a cell + its dustbin sum to one
    cell_sums = heat[0].reshape(2, 8, 3, 8).sum(axis=(1, 3)).numpy()
    dustbin = softmax(logits.astype(np.float64), axis=0)[64]
    np.testing.assert_allclose(cell_sums + dustbin, 1.0, atol=1e-5)


@pytest.mark.parametrize("radius", [1, 2, 4])
def test_nms_matches_greedy_reference_and_base_nms(rng: np.random.Generator, radius: int) -> None:
    scores = rng.random((3, 30, 41)).astype(np.float32)
    scores[scores < 0.6] = 0.0  # sparse candidates, distinct values
    out = sp.nms_heatmap(torch.from_numpy(scores), radius).numpy()
    for i in range(3):
        reference = _greedy_nms_reference(scores[i], radius)
        np.testing.assert_array_equal(out[i], reference)
        ys, xs = np.nonzero(scores[i])
        keep = nms_keypoints(np.column_stack([xs, ys]), scores[i][ys, xs], radius, scores[i].shape)
        expected = np.zeros_like(scores[i])
        expected[ys[keep], xs[keep]] = scores[i][ys[keep], xs[keep]]
        np.testing.assert_array_equal(out[i], expected)  # same as the shared NMS of base.py


def test_nms_dense_map_and_radius_zero(rng: np.random.Generator) -> None:
    scores = rng.random((25, 25)).astype(np.float32)  # every pixel a candidate: long suppression chains
    out = sp.nms_heatmap(torch.from_numpy(scores), 3).numpy()
    np.testing.assert_array_equal(out, _greedy_nms_reference(scores, 3))
    # the max-pool version used on GPUs gives the same result (run here on the CPU)
    pooled = _nms_torch(torch.from_numpy(scores)[None, None], 3)[0, 0].numpy()
    np.testing.assert_array_equal(pooled, out)
    assert torch.equal(sp.nms_heatmap(torch.from_numpy(scores), 0), torch.from_numpy(scores))
    with pytest.raises(ValueError, match="radius must be an integer >= 0"):
        sp.nms_heatmap(torch.from_numpy(scores), -1)
    with pytest.raises(ValueError, match="scores must be a torch tensor"):
        sp.nms_heatmap(scores, 2)


def _postprocess_reference(logits: np.ndarray, threshold: float, radius: int, border: int, top_k: int):
    """Slow post-processing: loop heatmap, threshold, border, greedy loop NMS, sort, top-k."""
    heat = _heatmap_reference(logits)
    heat[heat < threshold] = 0.0
    heat[:border] = heat[-border:] = 0.0
    heat[:, :border] = heat[:, -border:] = 0.0
    kept = _greedy_nms_reference(heat, radius)
    ys, xs = np.nonzero(kept)
    order = np.argsort(-kept[ys, xs], kind="stable")[:top_k]
    return np.column_stack([xs[order], ys[order]]).astype(np.float32), kept[ys[order], xs[order]]


def test_postprocess_matches_slow_reference(rng: np.random.Generator) -> None:
    logits = rng.normal(0.0, 2.0, (2, 65, 3, 4)).astype(np.float32)
    logits[:, 64] += 1.0
    descriptors = torch.from_numpy(rng.normal(size=(2, 16, 3, 4)).astype(np.float32))
    records = sp.postprocess(
        torch.from_numpy(logits), descriptors, threshold=0.02, nms_radius=2, border=3, max_keypoints=7
    )
    assert len(records) == 2
    for i, rec in enumerate(records):
        kp, sc = _postprocess_reference(logits[i], 0.02, 2, 3, 7)
        assert isinstance(rec, Features) and not rec.binary
        np.testing.assert_array_equal(rec.keypoints, kp)
        np.testing.assert_allclose(rec.scores, sc, rtol=1e-5)
        assert rec.descriptors.shape == (len(kp), 16)
        np.testing.assert_allclose(np.linalg.norm(rec.descriptors, axis=1), 1.0, atol=1e-5)


def test_postprocess_crop_border_and_detector_only() -> None:
    logits = torch.full((1, 65, 2, 2), -5.0)
    logits[:, 64] = 5.0
    logits[0, 8 * 1 + 6, 1, 1] = 12.0  # pixel (x, y) = (14, 9): inside a 12 x 16 crop, but in its 4 px border
    logits[0, 8 * 2 + 2, 0, 1] = 12.0  # pixel (10, 2): in the border band (y < 4)
    logits[0, 8 * 5 + 5, 0, 0] = 12.0  # pixel (5, 5): valid
    rec = sp.postprocess(logits, None, image_shape=(12, 16), border=4)[0]
    assert rec.keypoints.tolist() == [[5.0, 5.0]]
    assert rec.descriptors.shape == (1, 0)
    rec = sp.postprocess(logits, None, border=0)[0]
    assert sorted(rec.keypoints.tolist()) == [[5.0, 5.0], [10.0, 2.0], [14.0, 9.0]]
    with pytest.raises(ValueError, match="exceeds"):
        sp.postprocess(logits, None, image_shape=(17, 16))
    with pytest.raises(ValueError, match=r"logits must have shape \(B, 65, Hc, Wc\)"):
        sp.postprocess(torch.zeros(1, 64, 2, 2))
    with pytest.raises(ValueError, match="descriptors must have shape"):
        sp.postprocess(logits, torch.zeros(1, 8, 3, 2))


def test_extract_keypoints_threshold_topk_sorted(rng: np.random.Generator) -> None:
    heat = torch.from_numpy(rng.random((40, 50)).astype(np.float32) * 0.1)
    kp, sc = sp.extract_keypoints(heat, threshold=0.05, nms_radius=1, border=2, max_keypoints=20)
    assert kp.shape == (20, 2) and sc.shape == (20,)
    assert bool((sc[:-1] >= sc[1:]).all()) and float(sc.min()) >= 0.05
    assert float(kp[:, 0].min()) >= 2 and float(kp[:, 0].max()) <= 47 and float(kp[:, 1].max()) <= 37
    np.testing.assert_array_equal(heat[kp[:, 1].long(), kp[:, 0].long()].numpy(), sc.numpy())
    with pytest.raises(ValueError, match="threshold must be a finite number"):
        sp.extract_keypoints(heat, threshold=-1.0)
    with pytest.raises(ValueError, match=r"heatmap must be a \(H, W\)"):
        sp.extract_keypoints(heat[None])


def test_refine_keypoints_finds_subpixel_blob_centres() -> None:
    # a sampled Gaussian blob centred off the pixel grid: the integer peak is up to 0.5 px off, the centroid closer
    ys, xs = np.mgrid[0:40, 0:50]
    errors_int, errors_refined = [], []
    for cx, cy in [(20.3, 14.8), (10.45, 30.25), (33.9, 20.0), (25.0, 25.0)]:
        heat = np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * 0.8**2)).astype(np.float32)
        kp, _ = sp.extract_keypoints(torch.from_numpy(heat), threshold=0.1, nms_radius=4, border=4)
        assert len(kp) == 1
        refined = sp.refine_keypoints(torch.from_numpy(heat), kp, radius=2)
        errors_int.append(np.hypot(*(kp[0].numpy() - [cx, cy])))
        errors_refined.append(np.hypot(*(refined[0].numpy() - [cx, cy])))
    assert max(errors_refined) < 0.08 and max(errors_int) > 0.4
    assert errors_refined[-1] < 1e-6  # a centred blob stays put


def test_refine_keypoints_edges_radius_zero_and_errors() -> None:
    heat = torch.zeros(6, 8)
    heat[0, 0], heat[0, 1], heat[5, 7] = 1.0, 1.0, 1.0
    kp = torch.tensor([[0.0, 0.0], [7.0, 5.0]])
    out = sp.refine_keypoints(heat, kp, radius=1)
    assert out.tolist() == [[0.5, 0.0], [7.0, 5.0]]  # nothing outside the image: points stay inside it
    assert sp.refine_keypoints(heat, kp, radius=0).tolist() == kp.tolist()
    assert sp.refine_keypoints(heat, torch.zeros(0, 2), radius=2).shape == (0, 2)
    with pytest.raises(ValueError, match="inside the"):
        sp.refine_keypoints(heat, torch.tensor([[8.0, 0.0]]))
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        sp.refine_keypoints(heat, torch.zeros(3))
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        sp.refine_keypoints(heat[None], kp)
    with pytest.raises(ValueError, match="radius"):
        sp.refine_keypoints(heat, kp, radius=-1)
    with pytest.raises(ValueError, match="subpixel_radius"):
        sp.SuperPointDetector(weights=None, allow_random=True, subpixel_radius=1.5)


@pytest.mark.parametrize("mode", ["bilinear", "bicubic"])
def test_sample_descriptors_at_cell_centres_and_between(rng: np.random.Generator, mode: str) -> None:
    dmap = torch.from_numpy(rng.normal(size=(32, 3, 4)).astype(np.float32))
    unit = torch.nn.functional.normalize(dmap, dim=0)
    centres = torch.tensor([[8 * w + 3.5, 8 * h + 3.5] for h in range(3) for w in range(4)])
    out = sp.sample_descriptors(dmap, centres, mode)
    np.testing.assert_allclose(out.numpy(), unit.reshape(32, -1).T.numpy(), atol=1e-5)  # interpolants pass nodes
    if mode == "bilinear":  # midway between cells (1, 1) and (1, 2): normalised mean of the two unit vectors
        mid = sp.sample_descriptors(dmap, torch.tensor([[15.5, 11.5]]), mode)[0]
        expected = torch.nn.functional.normalize(unit[:, 1, 1] + unit[:, 1, 2], dim=0)
        np.testing.assert_allclose(mid.numpy(), expected.numpy(), atol=1e-5)
    anywhere = sp.sample_descriptors(dmap, torch.from_numpy(rng.uniform(0, 24, (50, 2)).astype(np.float32)), mode)
    np.testing.assert_allclose(anywhere.norm(dim=1).numpy(), 1.0, atol=1e-5)
    assert sp.sample_descriptors(dmap, torch.zeros(0, 2), mode).shape == (0, 32)
    with pytest.raises(ValueError, match="interpolation must be"):
        sp.sample_descriptors(dmap, centres, "nearest")


# ---------------------------------------------------------------------------------------------- fusion and fast paths
def test_fused_matches_unfused_eval_model(rng: np.random.Generator) -> None:
    net = _model()
    fused = net.fuse_for_inference()
    assert fused.config["batch_norm"] is False and fused.inference_only
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fused.modules())
    x = torch.from_numpy(rng.random((2, 1, 40, 56)).astype(np.float32))
    with torch.inference_mode():
        a, b = net(x), fused(x)
    for key in ("logits", "descriptors"):
        assert a[key].abs().max() > 1e-2  # non-trivial outputs
        torch.testing.assert_close(b[key], a[key], atol=1e-4, rtol=1e-4)
    with pytest.raises(RuntimeError, match="inference copy"):
        fused.train()
    assert net.config["batch_norm"] is True  # the original is untouched


def _keypoint_agreement(a: Features, b: Features, tol: float = 1.0) -> tuple[float, float]:
    """Return (fraction of b's keypoints within tol px of one of a's, median cosine of their descriptors)."""
    d = np.linalg.norm(b.keypoints[:, None] - a.keypoints[None], axis=2)
    nearest = d.argmin(axis=1)
    close = d[np.arange(len(b)), nearest] <= tol
    cos = np.sum(a.descriptors[nearest[close]] * b.descriptors[close], axis=1)
    return float(close.mean()), float(np.median(cos))


@pytest.mark.parametrize("mode", ["fused", "bf16", "int8"])
def test_fast_paths_stay_close_to_fp32(mode: str) -> None:
    net = _model()
    image = sp.calibration_images((48, 64), count=1, seed=11)[0]  # not one of the calibration images
    fast = sp.inference_model(net, mode, calibration=sp.calibration_images((48, 64), count=2, seed=1))
    x = torch.from_numpy(image)[None, None]
    with torch.inference_mode():
        ref, out = net(x), fast(x)
    # int8 on a CPU without 8-bit dot products (AVX2 only) runs FBGEMM with 7-bit activations (reduce_range):
    # twice the quantisation step, measured 0.13-0.15 relative error on an AVX2 EPYC against under 0.12 with oneDNN
    seven_bit = mode == "int8" and getattr(fast, "engine", None) == "x86"
    for key in ("logits", "descriptors"):
        rel = float((out[key] - ref[key]).norm() / ref[key].norm())
        assert rel < {"fused": 1e-5, "bf16": 0.06, "int8": 0.2 if seven_bit else 0.12}[mode], (key, rel)
    kw = dict(threshold=0.0, nms_radius=2, border=4, max_keypoints=30)
    a = sp.postprocess(ref["logits"], ref["descriptors"], **kw)[0]
    b = sp.postprocess(out["logits"], out["descriptors"], **kw)[0]
    frac, cos = _keypoint_agreement(a, b)
    assert frac >= {"fused": 1.0, "bf16": 0.85, "int8": 0.7 if seven_bit else 0.8}[mode], frac
    assert cos > 0.99, cos


def test_inference_model_bad_mode() -> None:
    with pytest.raises(ValueError, match="mode must be one of"):
        sp.inference_model(_model(), "fp8")
    with pytest.raises(ValueError, match="must be a SuperPointNet"):
        sp.inference_model(torch.nn.Conv2d(1, 1, 1))


# ---------------------------------------------------------------------------------------------- checkpoints
def test_checkpoint_round_trip(tmp_path, rng: np.random.Generator) -> None:
    net = _model("narrow")
    metadata = {"stage": "DetDesc", "epoch": 3}
    path = sp.save_checkpoint(net, tmp_path / "sub" / "model.pt", metadata, optimizer={"lr": 1e-3})
    raw = torch.load(path, weights_only=True)  # plain data only
    assert raw["model_config"] == net.config and raw["metadata"] == {"stage": "DetDesc", "epoch": 3}
    assert raw["optimizer"] == {"lr": 1e-3}
    loaded = sp.load_model(path)
    assert not loaded.training and loaded.config == net.config
    x = torch.from_numpy(rng.random((1, 1, 24, 32)).astype(np.float32))
    with torch.inference_mode():
        a, b = net(x), loaded(x)
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ValueError, match="reserved keys"):
        sp.save_checkpoint(net, tmp_path / "x.pt", state_dict={})


def test_checkpoint_errors(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="not found"):
        sp.load_checkpoint(tmp_path / "missing.pt")
    torch.save({"weights": 1}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a SuperPoint checkpoint"):
        sp.load_checkpoint(tmp_path / "other.pt")
    bad = {"model_config": sp.build_model("narrow").config, "state_dict": sp.build_model("full").state_dict()}
    torch.save(bad, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="does not match its model_config"):
        sp.load_model(tmp_path / "bad.pt")


def test_missing_shipped_weights_message(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(sp_model, "WEIGHTS_DIR", tmp_path)
    with pytest.raises(FileNotFoundError, match="no_such_model.pt") as info:
        sp.SuperPointDetector(weights="no_such_model")
    assert sp.TRAINING_COMMAND in str(info.value) and "allow_random=True" in str(info.value)
    with pytest.raises(FileNotFoundError, match="weights file not found"):
        sp.resolve_weights(tmp_path / "nothing.pt")
    with pytest.raises(ValueError, match="allow_random=True"):
        sp.SuperPointDetector(weights=None)


def test_shipped_name_resolves_and_registers(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(sp_model, "WEIGHTS_DIR", tmp_path)
    # a registry of its own: the made-up variant must not outlive the test (other tests list every detector)
    monkeypatch.setattr(features_base, "_REGISTERED", dict(features_base._REGISTERED))
    sp.save_checkpoint(_model("narrow"), tmp_path / "test_variant_xyz.pt")
    assert sp.shipped_weights() == ["test_variant_xyz"]
    assert sp.resolve_weights("test_variant_xyz") == tmp_path / "test_variant_xyz.pt"
    _register_shipped_variants()
    det = create_detector("test_variant_xyz", inference="fused", max_keypoints=10)
    assert isinstance(det, sp.SuperPointDetector) and det.weights_path == tmp_path / "test_variant_xyz.pt"
    assert det.model.config == _model("narrow").config


# ---------------------------------------------------------------------------------------------- detector
def test_detector_any_size_uint8_equals_float(rng: np.random.Generator) -> None:
    det = create_detector("superpoint", weights=None, allow_random=True, inference="fused", max_keypoints=40,
                          nms_radius=3, threshold=0.0, subpixel_radius=0)
    image = (sp.calibration_images((45, 61), count=1, seed=2)[0] * 255).round().astype(np.uint8)
    a = det.detect_and_describe(image)
    b = det.detect_and_describe(image.astype(np.float32) / 255.0)
    assert isinstance(a, Features) and len(a) == 40
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    assert a.descriptors.shape == (40, 256) and a.descriptors.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(a.descriptors, axis=1), 1.0, atol=1e-5)
    assert (a.keypoints[:, 0] >= 4).all() and (a.keypoints[:, 0] <= 61 - 5).all()
    assert (a.keypoints[:, 1] >= 4).all() and (a.keypoints[:, 1] <= 45 - 5).all()
    d = np.abs(a.keypoints[:, None] - a.keypoints[None]).max(axis=2) + 100 * np.eye(40)
    assert d.min() > 3  # NMS radius 3
    heat = det.heatmap(image)
    assert heat.shape == (45, 61) and heat.dtype == np.float32
    np.testing.assert_allclose(a.scores, heat[a.keypoints[:, 1].astype(int), a.keypoints[:, 0].astype(int)], rtol=1e-5)
    # the default detector refines the same peaks: same scores, points within the 5 x 5 window, heat centroids
    refined = create_detector("superpoint", weights=None, allow_random=True, inference="fused", max_keypoints=40,
                              nms_radius=3, threshold=0.0).detect_and_describe(image)
    np.testing.assert_array_equal(refined.scores, a.scores)
    assert np.abs(refined.keypoints - a.keypoints).max() <= 2.0 and not np.array_equal(refined.keypoints, a.keypoints)
    padded = np.pad(heat, 2)
    for (x, y), (xr, yr) in zip(a.keypoints.astype(int), refined.keypoints):  # loop reference of the centroid
        window = padded[y : y + 5, x : x + 5].astype(np.float64)
        offsets = np.arange(-2, 3)
        assert xr == pytest.approx(x + (window * offsets[None, :]).sum() / window.sum(), abs=1e-4)
        assert yr == pytest.approx(y + (window * offsets[:, None]).sum() / window.sum(), abs=1e-4)


def test_detector_auto_and_int8_modes() -> None:
    auto = sp.SuperPointDetector(weights=None, allow_random=True, model_config="narrow")
    assert auto.inference == ("bf16" if _bf16_native() else "int8")  # the fast path of this CPU
    det = sp.SuperPointDetector(weights=None, allow_random=True, model_config="narrow", max_keypoints=5,
                                inference="int8", calibration=sp.calibration_images((32, 32), count=1))
    assert det.inference == "int8" and det.descriptor_dim == 256
    f = det.detect_and_describe(np.zeros((30, 30), np.uint8))
    assert f.descriptors.shape[1] == 256 and len(f) <= 5
    with pytest.raises(ValueError, match="unknown option"):
        sp.SuperPointDetector(weights=None, allow_random=True, inference="fused", colour=True)
    with pytest.raises(ValueError, match="inference must be one of"):
        sp.SuperPointDetector(weights=None, allow_random=True, inference="fast")
    with pytest.raises(ValueError, match="grayscale image"):
        det = sp.SuperPointDetector(weights=None, allow_random=True, inference="fused")
        det.detect_and_describe(np.zeros((8, 8, 3)))
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA is not available"):
            sp.SuperPointDetector(weights=None, allow_random=True, device="cuda")
