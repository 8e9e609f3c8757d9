"""Tests of the "distill" stage: the loss against a direct computation, a student learning a teacher, resume, errors."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from evio_lib.features.network import SuperPointNet, load_checkpoint, save_checkpoint
from evio_lib.features.training import train as tr
from evio_lib.features.training.distill import distillation_loss, teacher_forward

TINY = {"encoder_channels": [8, 8, 8, 8, 16, 16, 16, 16], "head_channels": 16, "descriptor_dim": 16}


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tests/features/conftest.py


@pytest.fixture
def teacher_file(tmp_path):
    """A small seeded network standing in for the trained teacher."""
    return save_checkpoint(SuperPointNet(**TINY, seed=11).eval(), tmp_path / "teacher.pt")


def tiny_distill(tmp_path, teacher, **changes) -> tr.TrainConfig:
    values = {"name": "tiny_distill", "stage": "distill", "model": TINY, "labels_from": str(teacher),
              "image_size": (32, 48), "batch_size": 2, "n_train_images": 4, "n_val_images": 2, "device": "cpu",
              "val_every": 1000, "checkpoint_every": 1000, "max_steps": 2, "checkpoint_dir": str(tmp_path / "runs")}
    values.update(changes)
    return tr.load_config(values)


def test_loss_equals_a_direct_computation():
    rng = np.random.default_rng(0)
    s_logits, t_logits = rng.normal(size=(2, 2, 65, 3, 4))
    s_desc, t_desc = rng.normal(size=(2, 2, 16, 3, 4))
    student = {"logits": torch.tensor(s_logits), "descriptors": torch.tensor(s_desc)}
    teacher = {"logits": torch.tensor(t_logits), "descriptors": torch.tensor(t_desc)}
    total, parts = distillation_loss(student, teacher, lambda_loss=0.5)

    def log_softmax(x):  # over the 65 channels
        x = x - x.max(axis=1, keepdims=True)
        return x - np.log(np.exp(x).sum(axis=1, keepdims=True))

    lp_s, lp_t = log_softmax(s_logits), log_softmax(t_logits)
    kl = (np.exp(lp_t) * (lp_t - lp_s)).sum(axis=1).mean()
    cos = (s_desc * t_desc).sum(axis=1) / (np.linalg.norm(s_desc, axis=1) * np.linalg.norm(t_desc, axis=1))
    assert float(parts["detector"]) == pytest.approx(kl, rel=1e-5)
    assert float(parts["descriptor"]) == pytest.approx((1 - cos).mean(), rel=1e-5)
    assert float(total) == pytest.approx(kl + 0.5 * (1 - cos).mean(), rel=1e-5)
    assert float(parts["detector"]) > 0  # KL of different distributions
    # the descriptor term ignores the length of the descriptors, only their direction counts
    scaled = {"logits": teacher["logits"], "descriptors": 3.0 * teacher["descriptors"]}
    assert float(distillation_loss(scaled, teacher)[0]) == pytest.approx(0.0, abs=1e-6)


def test_loss_refuses_mismatched_outputs():
    out = {"logits": torch.zeros(1, 65, 2, 2), "descriptors": torch.zeros(1, 8, 2, 2)}
    with pytest.raises(ValueError, match="logits differ in shape"):
        distillation_loss({**out, "logits": torch.zeros(1, 65, 2, 3)}, out)
    with pytest.raises(ValueError, match="descriptors differ in shape"):
        distillation_loss({**out, "descriptors": torch.zeros(1, 16, 2, 2)}, out)
    with pytest.raises(ValueError, match="'logits' and 'descriptors'"):
        distillation_loss({"logits": out["logits"]}, out)


def test_teacher_forward_refuses_missing_and_detector_only_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="teacher checkpoint .*nothing.pt not found"):
        teacher_forward(tmp_path / "nothing.pt")
    path = save_checkpoint(SuperPointNet(**TINY, detector_only=True, seed=0), tmp_path / "detector.pt")
    with pytest.raises(ValueError, match="detector-only"):
        teacher_forward(path)


def test_student_learns_the_teacher_and_resumes_bit_identically(tmp_path, teacher_file):
    common = dict(n_train_images=8, batch_size=4, val_every=10, checkpoint_every=5, lr=3e-3)
    result = tr.train(tiny_distill(tmp_path / "a", teacher_file, max_steps=40, **common), progress=False)
    first, last = result.validation[0], result.validation[-1]
    assert result.steps == 40 and last["step"] == 40
    # the student's outputs move towards the teacher's on the held-out images
    assert last["loss"] < 0.5 * first["loss"], (first, last)
    assert last["detector"] < first["detector"] and last["descriptor"] < first["descriptor"]
    # an interrupted run resumed from last.pt equals the uninterrupted one
    part = tr.train(tiny_distill(tmp_path / "b", teacher_file, max_steps=15, **common), progress=False)
    resumed = tr.train(tiny_distill(tmp_path / "b", teacher_file, max_steps=40, **common), progress=False,
                       resume=True)
    assert part.steps == 15 and resumed.resumed_from == 15 and resumed.train_loss == result.train_loss
    a, b = load_checkpoint(result.last_path), load_checkpoint(resumed.last_path)
    assert all(torch.equal(v, b["state_dict"][k]) for k, v in a["state_dict"].items())


def test_a_teacher_equal_to_the_student_gives_perfect_agreement(tmp_path):
    """Validation precision and recall compare the student's keypoints with the teacher's: 1 when they are one net."""
    net = SuperPointNet(**TINY, seed=3)
    with torch.no_grad():  # a detector that fires: raise the logits of pixel channel 27 above the dustbin
        net.detector_head[1].bias[27] += 6.0
    path = save_checkpoint(net.eval(), tmp_path / "same.pt")
    config = tiny_distill(tmp_path, path, model=dict(TINY, seed=3), seed=3, max_steps=1, lr=1e-12)
    model = tr.build_training_model(config)
    model.load_state_dict(net.state_dict())
    _, val = tr._datasets(config, progress=False)
    metrics = tr._validate(model, val, config, torch.device("cpu"))
    assert metrics["detector"] == pytest.approx(0.0, abs=1e-5) and metrics["descriptor"] == pytest.approx(0.0, abs=1e-5)
    assert metrics["precision"] == metrics["recall"] == 1.0


def test_unusable_teachers_are_refused_before_anything_is_written(tmp_path):
    config = tiny_distill(tmp_path, tmp_path / "absent.pt")
    with pytest.raises(FileNotFoundError, match=r"labels_from \(the teacher\) checkpoint .*absent.pt not found"):
        tr.train(config, progress=False)
    detector_only = save_checkpoint(SuperPointNet(**TINY, detector_only=True, seed=0), tmp_path / "det.pt")
    with pytest.raises(ValueError, match="detector-only"):
        tr.train(tiny_distill(tmp_path, detector_only), progress=False)
    wide = save_checkpoint(SuperPointNet(**dict(TINY, descriptor_dim=32), seed=0), tmp_path / "wide.pt")
    with pytest.raises(ValueError, match=r"32-D descriptors and the student 16-D; set the config's model "
                                         r"descriptor_dim to 32"):
        tr.train(tiny_distill(tmp_path, wide), progress=False)
    assert not (tmp_path / "runs").exists()  # no run folder left behind
    with pytest.raises(ValueError, match="select_on must be 'loss' for stage 'distill'"):
        tiny_distill(tmp_path, wide, select_on="desc_nn_accuracy")


def test_resume_refuses_a_changed_teacher(tmp_path):
    teacher = save_checkpoint(SuperPointNet(**TINY, seed=11).eval(), tmp_path / "teacher.pt")
    tr.train(tiny_distill(tmp_path, teacher, max_steps=1, checkpoint_every=1), progress=False)
    save_checkpoint(SuperPointNet(**TINY, seed=12).eval(), teacher)  # another network under the same name
    with pytest.raises(ValueError, match="cannot resume .*a different teacher"):
        tr.train(tiny_distill(tmp_path, teacher, max_steps=2, checkpoint_every=1), progress=False, resume=True)


def test_teacher_forward_reloads_a_rewritten_file(tmp_path):
    path = save_checkpoint(SuperPointNet(**TINY, seed=1).eval(), tmp_path / "t.pt")
    x = torch.rand(1, 1, 16, 16, generator=torch.Generator().manual_seed(0))
    before = teacher_forward(path)(x)["logits"]
    save_checkpoint(SuperPointNet(**TINY, seed=2).eval(), path)
    after = teacher_forward(path)(x)["logits"]
    assert not torch.equal(before, after)


def test_references_to_checkpoints_resolve_shipped_weights_for_every_stage(tmp_path):
    """init_from / labels_from may name shipped weights; a variant config of the same name wins over them."""
    path = tr._existing_checkpoint("pretrained_detdesc_round1_gpu", str(tmp_path), "init_from")
    assert path.name == "pretrained_detdesc_round1_gpu.pt" and path.is_file()
    shipped_name = "pretrained_detdesc_round1_gpu"
    config = tr.load_config({"name": "p", "stage": "detdesc", "model": "full", "init_from": shipped_name,
                             "labels_from": shipped_name, "checkpoint_dir": str(tmp_path)})
    assert tr.variant_dependencies("distilled_narrow") == ["distilled_narrow"]
    model = tr.build_training_model(config)  # "pre-trained" from the shipped weights
    shipped = load_checkpoint(path)["state_dict"]
    assert torch.equal(model.state_dict()["encoder.0.conv.weight"], shipped["encoder.0.conv.weight"])
    # distilled_narrow is both a config and shipped weights: the name means the variant's own run
    with pytest.raises(FileNotFoundError, match="train variant 'distilled_narrow' first"):
        tr._existing_checkpoint("distilled_narrow", str(tmp_path), "init_from")
    with pytest.raises(FileNotFoundError, match=r"init_from checkpoint .*nothing.pt not found \(expected a "):
        tr._existing_checkpoint(str(tmp_path / "nothing.pt"), str(tmp_path), "init_from")


def test_the_shipped_teacher_is_named_by_its_weights():
    config = tr.load_config("distilled_narrow")
    assert config.stage == "distill" and config.model == "narrow"
    assert tr._teacher_path(config).name == "pretrained_detdesc_round1_gpu.pt"
    assert tr.variant_dependencies("distilled_narrow") == ["distilled_narrow"]


def test_the_shipped_distilled_network_follows_its_teacher():
    """The shipped half-width network: a quarter of the teacher's multiply-adds, and outputs close to the teacher's
    on held-out validation images (cell descriptors, keypoints within 1 px)."""
    from evio_lib.features.network import count_parameters, load_model
    from evio_lib.features.training.datasets import image_pool

    student, teacher = load_model("distilled_narrow"), load_model("pretrained_detdesc_round1_gpu")
    assert student.config["encoder_channels"] == [c // 2 for c in teacher.config["encoder_channels"]]
    assert count_parameters(student) < 0.3 * count_parameters(teacher)
    images = torch.from_numpy(np.stack(image_pool("val", seed=0, size=(120, 160), n_images=4, render_zoom=4.0)))[:, None]
    with torch.no_grad():
        s, t = student(images), teacher(images)
        parts = distillation_loss(s, t)[1]
        untrained = distillation_loss(SuperPointNet.from_config("narrow", seed=0).eval()(images), t)[1]
    # on these 4 images: detector KL 0.175, descriptor cosine distance 0.101 (untrained: 3.10 and 0.98); on the 64
    # validation images of the training run 0.150 and 0.100
    assert float(parts["detector"]) < 0.25 < float(untrained["detector"])
    assert float(parts["descriptor"]) < 0.2 < float(untrained["descriptor"])
