"""Recurrent networks that turn event voxel grids into intensity images (PyTorch).

Two architectures, both fully convolutional (any image size) and recurrent (a hidden state carried from window to window,
which is what lets an event camera, which only sees changes, accumulate a whole image):

- :class:`FireNet` (Scheerlinck et al., WACV 2020), the small default: a 3x3 head, two ConvGRU cells each followed by a
  residual block, and a 1x1 prediction layer. 16 channels give 37 777 parameters.
- :class:`E2VIDRecurrent` (Rebecq et al., TPAMI 2019), the large option: a UNet whose three encoder stages are strided
  convolutions followed by ConvLSTM cells, two residual blocks at the bottom, and decoders that upsample and add the skip
  connections. 32 base channels give 10 710 401 (10.7 M).

ConvGRU (Ballas et al. 2016), for input x and hidden state h:
    z = sigmoid(W_z * [x, h]),  r = sigmoid(W_r * [x, h]),  h~ = tanh(W_h * [x, r . h]),  h' = (1 - z) . h + z . h~
ConvLSTM (Shi et al. 2015): [i, f, o, g] = W * [x, h];  c' = sigmoid(f) . c + sigmoid(i) . tanh(g);  h' = sigmoid(o) . tanh(c')

Both networks output an image in [0, 1] (a sigmoid on the last layer) and return their new state; ``state=None`` starts
from zeros. A FireNet built with ``output="clamp"`` instead clips its last layer to [0, 1]: the published FireNet+
(Stoffregen et al. 2020; EVREAL) ends in a plain 1 x 1 convolution, and its weights load into that form
(:mod:`evio_lib.events.reconstruction.published`).
"""
from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F


#: what a FireNet's last layer becomes: "sigmoid" (trained here) or "clamp" (published FireNet+ weights)
FIRENET_OUTPUTS = ("sigmoid", "clamp")

__all__ = ["FIRENET_OUTPUTS", "AutocastForward", "ConvGRUCell", "ConvLSTMCell", "FireNet", "FireNetInference",
           "E2VIDRecurrent", "build_network", "count_parameters"]


class ConvGRUCell(nn.Module):
    """A convolutional GRU cell: ``forward(x, h) -> h'`` (equations in the module docstring)."""

    def __init__(self, in_channels: int, hidden_channels: int, kernel_size: int = 3) -> None:
        super().__init__()
        self.hidden_channels = hidden_channels
        pad = kernel_size // 2
        self.gates = nn.Conv2d(in_channels + hidden_channels, 2 * hidden_channels, kernel_size, padding=pad)
        self.candidate = nn.Conv2d(in_channels + hidden_channels, hidden_channels, kernel_size, padding=pad)

    def forward(self, x: torch.Tensor, h: torch.Tensor | None) -> torch.Tensor:
        if h is None:
            h = x.new_zeros(x.shape[0], self.hidden_channels, x.shape[2], x.shape[3])
        z, r = torch.sigmoid(self.gates(torch.cat([x, h], dim=1))).chunk(2, dim=1)   # update and reset gates
        h_tilde = torch.tanh(self.candidate(torch.cat([x, r * h], dim=1)))
        return (1 - z) * h + z * h_tilde                                              # h' = (1 - z) h + z h~


class ConvLSTMCell(nn.Module):
    """A convolutional LSTM cell: ``forward(x, (h, c)) -> (h', c')``."""

    def __init__(self, in_channels: int, hidden_channels: int, kernel_size: int = 3) -> None:
        super().__init__()
        self.hidden_channels = hidden_channels
        self.gates = nn.Conv2d(in_channels + hidden_channels, 4 * hidden_channels, kernel_size, padding=kernel_size // 2)

    def forward(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        if state is None:
            zeros = x.new_zeros(x.shape[0], self.hidden_channels, x.shape[2], x.shape[3])
            state = (zeros, zeros)
        h, c = state
        i, f, o, g = self.gates(torch.cat([x, h], dim=1)).chunk(4, dim=1)
        c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)                   # c' = f c + i g
        return torch.sigmoid(o) * torch.tanh(c), c                                    # h' = o tanh(c')


class _ResidualBlock(nn.Module):
    """Two 3x3 convolutions with a skip connection: y = relu(x + conv(relu(conv(x))))."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.conv2(F.relu(self.conv1(x))))


class FireNet(nn.Module):
    """The small recurrent reconstructor: ``forward(voxels (N, B, H, W), state) -> (image (N, 1, H, W), state)``."""

    def __init__(self, num_bins: int = 5, channels: int = 16, output: str = "sigmoid") -> None:
        super().__init__()
        if output not in FIRENET_OUTPUTS:
            raise ValueError(f"output must be one of {FIRENET_OUTPUTS}; got {output!r}")
        self.num_bins = num_bins
        self.output = output
        self.head = nn.Conv2d(num_bins, channels, 3, padding=1)
        self.gru1 = ConvGRUCell(channels, channels)
        self.res1 = _ResidualBlock(channels)
        self.gru2 = ConvGRUCell(channels, channels)
        self.res2 = _ResidualBlock(channels)
        self.pred = nn.Conv2d(channels, 1, 1)

    def forward(self, voxels: torch.Tensor, state: list | None = None) -> tuple[torch.Tensor, list]:
        h1, h2 = state if state is not None else (None, None)
        x = F.relu(self.head(voxels))
        h1 = self.gru1(x, h1)
        x = self.res1(h1)
        h2 = self.gru2(x, h2)
        x = self.res2(h2)
        return _image(self.pred(x), self.output), [h1, h2]


def _image(a: torch.Tensor, output: str) -> torch.Tensor:
    """Return the image of the last layer's output ``a``: sigmoid(a) (the project's networks) or a clipped to [0, 1]."""
    return torch.sigmoid(a) if output == "sigmoid" else a.clamp(0.0, 1.0)


def _tanh_(a: torch.Tensor) -> torch.Tensor:
    """Return tanh(a) = 2 sigmoid(2 a) - 1, computed in place (torch's CPU tanh is much slower than its sigmoid:
    docs/results/speed.md#small-costs-behind-the-codes-choices)."""
    return torch.sigmoid_(a.mul_(2)).mul_(2).sub_(1)


class FireNetInference(nn.Module):
    """A faster CPU forward pass of a :class:`FireNet` (inference only): same equations, same state, outputs within ~1e-6.

    Built from a FireNet, whose weights it copies once (rebuild it after changing the FireNet's weights); the FireNet
    itself is left untouched. Three changes, each measured in bench/bench_reconstruction.py:

    - channels-last tensors (oneDNN's convolutions run without reordering to their blocked layout),
    - the ConvGRU's convolutions over the concatenation [x, h] split into one over x (gates and candidate together,
      16 -> 48 channels) and two over h and r . h: no concatenated copies (the same multiply-adds),
    - tanh as 2 sigmoid(2a) - 1 and the other pointwise steps in place; h' = h + z (h~ - h).

    ``forward(voxels (N, B, H, W), state) -> (image (N, 1, H, W), state)`` like FireNet; a state of either is accepted.
    """

    def __init__(self, net: FireNet) -> None:
        super().__init__()
        last = torch.channels_last

        def weights(conv: nn.Conv2d, rows: slice = slice(None), cols: slice = slice(None)) -> torch.Tensor:
            return conv.weight.detach()[rows, cols].clone().contiguous(memory_format=last)

        self.num_bins = net.num_bins
        self.output = net.output
        self.head_w, self.head_b = weights(net.head), net.head.bias.detach().clone()
        self.pred_w, self.pred_b = weights(net.pred), net.pred.bias.detach().clone()
        self.res = [(weights(r.conv1), r.conv1.bias.detach().clone(), weights(r.conv2), r.conv2.bias.detach().clone())
                    for r in (net.res1, net.res2)]
        self.grus = []
        for cell in (net.gru1, net.gru2):
            c_in = cell.gates.in_channels - cell.hidden_channels
            x_part, h_part = slice(0, c_in), slice(c_in, None)
            w_x = torch.cat([weights(cell.gates, cols=x_part), weights(cell.candidate, cols=x_part)])
            b_x = torch.cat([cell.gates.bias.detach(), cell.candidate.bias.detach()])
            self.grus.append((cell.hidden_channels, w_x.contiguous(memory_format=last), b_x,
                              weights(cell.gates, cols=h_part), weights(cell.candidate, cols=h_part)))

    @staticmethod
    def _gru(params: tuple, x: torch.Tensor, h: torch.Tensor | None) -> torch.Tensor:
        c, w_x, b_x, w_h, w_rh = params
        from_x = F.conv2d(x, w_x, b_x, padding=w_x.shape[-1] // 2)              # [z, r, h~] parts from x (+ biases)
        if h is None:                                                          # h = 0: h' = z h~
            return torch.sigmoid(from_x[:, :c]).mul_(_tanh_(from_x[:, 2 * c:]))
        zr = torch.sigmoid_(from_x[:, :2 * c].add_(F.conv2d(h, w_h, None, padding=w_h.shape[-1] // 2)))
        z, r = zr[:, :c], zr[:, c:]
        h_tilde = _tanh_(from_x[:, 2 * c:].add_(F.conv2d(r * h, w_rh, None, padding=w_rh.shape[-1] // 2)))
        return torch.addcmul(h, z, h_tilde.sub_(h))                             # h' = h + z (h~ - h)

    @staticmethod
    def _residual(params: tuple, x: torch.Tensor) -> torch.Tensor:
        w1, b1, w2, b2 = params
        y = F.conv2d(F.conv2d(x, w1, b1, padding=1).relu_(), w2, b2, padding=1)
        return y.add_(x).relu_()

    def forward(self, voxels: torch.Tensor, state: list | None = None) -> tuple[torch.Tensor, list]:
        h1, h2 = state if state is not None else (None, None)
        last = torch.channels_last
        h1 = h1.contiguous(memory_format=last) if h1 is not None else None
        h2 = h2.contiguous(memory_format=last) if h2 is not None else None
        x = F.conv2d(voxels.contiguous(memory_format=last), self.head_w, self.head_b, padding=1).relu_()
        h1 = self._gru(self.grus[0], x, h1)
        x = self._residual(self.res[0], h1)
        h2 = self._gru(self.grus[1], x, h2)
        x = self._residual(self.res[1], h2)
        return _image(F.conv2d(x, self.pred_w, self.pred_b), self.output), [h1, h2]


class AutocastForward(nn.Module):
    """``net``'s forward pass under ``torch.autocast`` in bfloat16; images returned as float32, state carried in bfloat16.

    Convolutions run in bfloat16 (8 bits of mantissa), which oneDNN computes natively on CPUs with AVX512-BF16, faster
    than float32. The images differ slightly from float32's, at nearly the same SSIM (both measured in
    docs/results/reconstruction.md#speed, ``bench/bench_reconstruction.py`` and ``bench/reconstruction_quality.py
    --precision``). CPUs without native bfloat16 emulate it, slowly.
    """

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net
        self.device_type = next(net.parameters()).device.type

    def forward(self, voxels: torch.Tensor, state: list | None = None) -> tuple[torch.Tensor, list]:
        with torch.autocast(self.device_type, dtype=torch.bfloat16):
            image, state = self.net(voxels, state)
        return image.float(), state


class E2VIDRecurrent(nn.Module):
    """The large recurrent UNet: ``forward(voxels (N, B, H, W), state) -> (image (N, 1, H, W), state)``.

    Input sizes are padded to a multiple of 8 internally (three stride-2 stages) and cropped back.
    """

    def __init__(self, num_bins: int = 5, base_channels: int = 32, num_encoders: int = 3) -> None:
        super().__init__()
        self.num_bins = num_bins
        self.num_encoders = num_encoders
        ch = [base_channels * 2 ** i for i in range(num_encoders + 1)]            # 32, 64, 128, 256
        self.head = nn.Conv2d(num_bins, ch[0], 5, padding=2)
        self.down = nn.ModuleList(nn.Conv2d(ch[i], ch[i + 1], 5, stride=2, padding=2) for i in range(num_encoders))
        self.lstm = nn.ModuleList(ConvLSTMCell(ch[i + 1], ch[i + 1]) for i in range(num_encoders))
        self.res = nn.Sequential(_ResidualBlock(ch[-1]), _ResidualBlock(ch[-1]))
        self.up = nn.ModuleList(nn.Conv2d(ch[i + 1], ch[i], 5, padding=2) for i in reversed(range(num_encoders)))
        self.pred = nn.Conv2d(ch[0], 1, 1)

    def forward(self, voxels: torch.Tensor, state: list | None = None) -> tuple[torch.Tensor, list]:
        height, width = voxels.shape[-2:]
        multiple = 2 ** self.num_encoders
        pad_h, pad_w = (-height) % multiple, (-width) % multiple
        x = F.pad(voxels, (0, pad_w, 0, pad_h))
        state = state if state is not None else [None] * self.num_encoders
        x = F.relu(self.head(x))
        skips, new_state = [x], []
        for down, lstm, s in zip(self.down, self.lstm, state):
            x = F.relu(down(x))
            h, c = lstm(x, s)
            new_state.append((h, c))
            x = h
            skips.append(x)
        x = self.res(x)
        for up, skip in zip(self.up, reversed(skips[:-1])):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = F.relu(up(x)) + skip                                                # upsample, convolve, add skip
        image = torch.sigmoid(self.pred(x))
        return image[..., :height, :width], new_state


def build_network(architecture: str, num_bins: int = 5, **options) -> nn.Module:
    """Return a new network: ``firenet`` (default small) or ``e2vid`` (large), with ``options`` for its constructor."""
    if architecture == "firenet":
        return FireNet(num_bins=num_bins, **options)
    if architecture == "e2vid":
        return E2VIDRecurrent(num_bins=num_bins, **options)
    raise ValueError(f"architecture must be 'firenet' or 'e2vid'; got {architecture!r}")


def count_parameters(net: nn.Module) -> int:
    """Return the number of trainable parameters of ``net``.

    >>> count_parameters(FireNet())
    37777
    """
    return sum(p.numel() for p in net.parameters() if p.requires_grad)
