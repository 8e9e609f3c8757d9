"""Published FireNet / FireNet+ weights (event_cnn_minimal / EVREAL layout) load into the project's FireNet and give
the images the published equations give; other layouts are refused in one line."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn
from torch.nn import functional as F

from evio_lib.events.array import make_events
from evio_lib.events.reconstruct import reconstructor_by_name_or_file
from evio_lib.events.representations import voxel_grid
from evio_lib.io.checkpoint import CheckpointError


class _PublishedGRU(nn.Module):
    """The published ConvGRU, written from its equations: three separate convolutions over [x, h]."""

    def __init__(self, c: int) -> None:
        super().__init__()
        self.reset_gate = nn.Conv2d(2 * c, c, 3, padding=1)
        self.update_gate = nn.Conv2d(2 * c, c, 3, padding=1)
        self.out_gate = nn.Conv2d(2 * c, c, 3, padding=1)

    def forward(self, x, h):
        h = torch.zeros_like(x) if h is None else h
        stacked = torch.cat([x, h], 1)
        update, reset = torch.sigmoid(self.update_gate(stacked)), torch.sigmoid(self.reset_gate(stacked))
        out = torch.tanh(self.out_gate(torch.cat([x, h * reset], 1)))
        return h * (1 - update) + out * update


class _Layer(nn.Module):
    def __init__(self, i: int, o: int, k: int, relu: bool = True) -> None:
        super().__init__()
        self.conv2d, self.relu = nn.Conv2d(i, o, k, padding=k // 2), relu

    def forward(self, x):
        y = self.conv2d(x)
        return F.relu(y) if self.relu else y


class _Residual(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.conv1, self.conv2 = nn.Conv2d(c, c, 3, padding=1), nn.Conv2d(c, c, 3, padding=1)

    def forward(self, x):
        return F.relu(x + self.conv2(F.relu(self.conv1(x))))


class _PublishedFireNet(nn.Module):
    def __init__(self, bins: int = 5, c: int = 16) -> None:
        super().__init__()
        self.head, self.G1, self.R1 = _Layer(bins, c, 3), _PublishedGRU(c), _Residual(c)
        self.G2, self.R2, self.pred = _PublishedGRU(c), _Residual(c), _Layer(c, 1, 1, relu=False)

    def forward(self, x, state):
        h1 = self.G1(self.head(x), state[0])
        h2 = self.G2(self.R1(h1), state[1])
        return self.pred(self.R2(h2)), [h1, h2]


def _published(tmp_path, wrap):
    torch.manual_seed(3)
    net = _PublishedFireNet()
    with torch.no_grad():
        net.pred.conv2d.bias.fill_(0.5)          # images around mid-grey, so the clip to [0, 1] rarely acts
        net.pred.conv2d.weight.mul_(20.0)
    path = tmp_path / "firenet_published.pth"
    torch.save(wrap(net.state_dict()), path)
    return net, path


@pytest.mark.parametrize("wrap", [lambda s: s, lambda s: {"state_dict": s, "epoch": 10},
                                  lambda s: {"state_dict": {f"module.{k}": v for k, v in s.items()}}])
def test_published_weights_give_the_published_images(tmp_path, wrap):
    net, path = _published(tmp_path, wrap)
    rec = reconstructor_by_name_or_file(str(path), 40, 30)
    assert rec.precision == "float32" and rec.net.output == "clamp" and rec.num_bins == 5
    rng = np.random.default_rng(0)
    state = [None, None]
    for k in range(3):
        n = 2000
        events = make_events(np.sort(rng.uniform(k, k + 1, n)), rng.integers(0, 40, n), rng.integers(0, 30, n),
                             rng.choice([-1, 1], n))
        image = rec.reconstruct(events)
        with torch.no_grad():
            expected, state = net(torch.from_numpy(voxel_grid(events, 40, 30, 5))[None], state)
        expected = expected.clamp(0, 1)[0, 0].numpy()
        assert 0.5 < float(np.mean((expected > 0) & (expected < 1))) and np.ptp(expected) > 0.05
        np.testing.assert_allclose(image, expected, atol=1e-5)
    with pytest.raises(ValueError, match="int8 runs a FireNet that ends in a sigmoid"):
        reconstructor_by_name_or_file(str(path), 40, 30, precision="int8")


def test_other_layouts_are_refused_in_one_line(tmp_path):
    e2vid = tmp_path / "E2VID_lightweight.pth.tar"
    torch.save({"state_dict": {"unetrecurrent.head.conv2d.weight": torch.zeros(32, 5, 5, 5)}}, e2vid)
    with pytest.raises(CheckpointError, match="published E2VID weights .* not the project's E2VID-style network"):
        reconstructor_by_name_or_file(str(e2vid), 40, 30)
    other = tmp_path / "other.pth"
    torch.save({"state_dict": {"conv.weight": torch.zeros(1)}}, other)
    with pytest.raises(CheckpointError) as error:
        reconstructor_by_name_or_file(str(other), 40, 30)
    assert "\n" not in str(error.value) and str(other) in str(error.value)
    _, path = _published(tmp_path, lambda s: {k: v for k, v in s.items() if k != "R1.conv1.bias"})
    with pytest.raises(CheckpointError, match="without R1.conv1.bias"):
        reconstructor_by_name_or_file(str(path), 40, 30)


class _Config:                                    # stands for event_cnn_minimal's pickled ConfigParser object
    def __init__(self) -> None:
        self.name = "firenet"


def test_a_published_file_with_pickled_objects_says_how_to_load_it(tmp_path):
    path = tmp_path / "firenet_1000.pth.tar"
    torch.save({"state_dict": {"head.conv2d.weight": torch.zeros(16, 5, 3, 3)}, "config": _Config()}, path)
    with pytest.raises(CheckpointError, match=r"checkpoint\['state_dict'\] is saved alone") as error:
        reconstructor_by_name_or_file(str(path), 40, 30)
    assert "\n" not in str(error.value)
