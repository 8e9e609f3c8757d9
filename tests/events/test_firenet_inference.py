"""The fast CPU forward pass of FireNet (nets.FireNetInference) gives the eager network's images, state carried."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from evio_lib.events.array import make_events
from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.events.reconstruction.nets import E2VIDRecurrent, FireNet, FireNetInference
from evio_lib.events.reconstruction.precision import inference_network
from evio_lib.events.representations import count_windows, voxel_grid
from evio_lib.io.ecd import read_ecd_events


def _run(net, grids: list[np.ndarray], state=None) -> tuple[np.ndarray, list]:
    images = []
    with torch.inference_mode():
        for g in grids:
            image, state = net(torch.from_numpy(g)[None], state)
            images.append(image[0, 0].numpy().copy())
    return np.stack(images), state


def _real_grids(real_data_dir, fraction: float = 0.1) -> list[np.ndarray]:
    events = read_ecd_events(real_data_dir / "ecd_slider_depth_slice" / "slider_seg.txt", sensor_size=(240, 180))
    bounds = count_windows(events, int(round(fraction * 240 * 180)))
    return [voxel_grid(events[a:b], 240, 180, 5) for a, b in bounds]


def test_fast_forward_matches_eager_on_real_voxel_grids(real_data_dir):
    net = create_reconstructor("firenet").net
    grids = _real_grids(real_data_dir)
    assert len(grids) >= 10
    eager, eager_state = _run(net, grids)
    fast, fast_state = _run(FireNetInference(net), grids)
    assert fast.shape == eager.shape == (len(grids), 180, 240)
    assert np.abs(fast - eager).max() < 1e-3  # the brief's bound; measured: 1.2e-7
    for a, b in zip(fast_state, eager_state):
        assert torch.allclose(a, b, atol=1e-4)


def test_fast_forward_continues_an_eager_state_and_vice_versa(rng):
    torch.manual_seed(0)
    net = FireNet(num_bins=3, channels=8).eval()
    grids = [rng.normal(size=(3, 20, 30)).astype(np.float32) * (rng.random((3, 20, 30)) < 0.3) for _ in range(6)]
    eager, _ = _run(net, grids)
    _, state = _run(net, grids[:3])
    fast_tail, state = _run(FireNetInference(net), grids[3:5], state)     # eager state -> fast pass
    eager_tail, _ = _run(net, grids[5:], state)                         # fast (channels-last) state -> eager net
    assert np.abs(fast_tail - eager[3:5]).max() < 1e-5
    assert np.abs(eager_tail - eager[5:]).max() < 1e-5


def test_reconstructor_uses_the_fast_pass_and_leaves_the_firenet_alone():
    rec = create_reconstructor("firenet", 40, 30, precision="float32")  # the default "auto" is int8 on x86 CPUs
    assert isinstance(rec.forward, FireNetInference)
    assert isinstance(rec.net, FireNet)
    keys = set(FireNet().state_dict())
    assert set(rec.net.state_dict()) == keys                            # shipped weights still load into FireNet
    rng = np.random.default_rng(1)
    n = 400
    window = make_events(np.sort(rng.uniform(0, 1, n)), rng.integers(0, 40, n), rng.integers(0, 30, n),
                         rng.choice([-1, 1], n))
    image = rec.reconstruct(window)
    with torch.inference_mode():
        eager, _ = rec.net(torch.from_numpy(voxel_grid(window, 40, 30, rec.num_bins))[None])
    assert image.shape == (30, 40) and image.dtype == np.float32
    assert np.abs(image - eager[0, 0].numpy()).max() < 1e-5


def test_other_networks_run_as_they_are():
    net = E2VIDRecurrent(base_channels=4)
    assert inference_network(net) is net
