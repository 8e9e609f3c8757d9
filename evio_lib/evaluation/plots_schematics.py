"""Schematic figures that open the lessons: a concept drawn before it is computed (boxes, arrows, labels).

One function per figure, each returning the matplotlib Figure:

- :func:`plot_event_pixel_schematic` (notebook 03): the DAVIS pixel (photoreceptor, differencing, comparators, thesis
  §2.2.1 Fig. 3) and the event generation model on one log-intensity curve (Fig. 4).
- :func:`plot_reconstruction_schematic` (notebook 04): windows of events -> voxel grid -> recurrent network
  (FireNet: encoder, ConvGRU cells whose state is carried from window to window, decoder) -> frame.
- :func:`plot_superpoint_schematic` (notebook 06): the shared VGG-style encoder down to 1/8 resolution and the
  detector and descriptor heads (thesis §3.2.4, Fig. 12).
- :func:`plot_homographic_adaptation_schematic` (notebook 07): an image, N random homographies, the detector on
  every view, the responses mapped back and averaged into labels (thesis §3.2.5.2); and the descriptor loss on a
  warped pair: corresponding and other cells, the two hinge terms and their margins (Eqs. 10-12).
- :func:`plot_msckf_schematic` (notebook 11): the MSCKF state vector (IMU state + N camera clones, thesis Eqs. 21,
  25-26) and the life of a feature track (observed, lost or pruned, triangulated, nullspace-projected update,
  clones marginalised; §3.3.6-3.3.7).
- :func:`plot_pipeline_schematic` (notebook 14): the pipeline's data flow from the sensors to a trajectory and its
  error metrics (Chapter IV §4.5).

The sizes written in the boxes are those of the library (`evio_lib.features.network`,
`evio_lib.events.reconstruction.nets`, `evio_lib.msckf.state`); nothing here is computed from data, except the
one-pixel curve of :func:`plot_event_pixel_schematic`, whose events follow the thesis's rule exactly, and the
panels of :func:`plot_homographic_adaptation_schematic`, computed on a made-up scene by the library's own
homographic adaptation (:func:`homographic_adaptation_schematic_data` returns them).
Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "plot_event_pixel_schematic",
    "plot_reconstruction_schematic",
    "plot_superpoint_schematic",
    "homographic_adaptation_schematic_data",
    "plot_homographic_adaptation_schematic",
    "plot_msckf_schematic",
    "plot_pipeline_schematic",
]

# one palette for every schematic: what a box holds, not which lesson it is from
_SENSOR = "#dbe9f6"  # sensor data, inputs
_PROCESS = "#fde9c9"  # a computation
_LEARNED = "#e3d7f0"  # a network layer with weights
_STATE = "#d9f0d3"  # a state or an output
_ON_COLOUR, _OFF_COLOUR = "tab:red", "tab:blue"


def _canvas(ax: "Axes", width: float, height: float) -> None:
    """Set ``ax`` up as a drawing board of ``width`` x ``height`` units, no axes, equal scale."""
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    ax.set_aspect("equal")
    ax.set_axis_off()


def _box(ax: "Axes", x: float, y: float, w: float, h: float, text: str, colour: str = _PROCESS,
         fontsize: float = 9.0, **text_options) -> tuple[float, float, float, float]:
    """Draw a rounded box with its lower-left corner at (x, y) and ``text`` centred in it; return (x, y, w, h)."""
    from matplotlib.patches import FancyBboxPatch

    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02,rounding_size=0.08", facecolor=colour,
                                edgecolor="0.25", linewidth=1.0))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=fontsize, **text_options)
    return x, y, w, h


def _arrow(ax: "Axes", start: Sequence[float], end: Sequence[float], text: str = "", *, colour: str = "0.2",
           fontsize: float = 8.0, text_offset: Sequence[float] = (0.0, 0.12), style: str = "-|>",
           connection: str = "arc3", linestyle: str = "-", **text_options) -> None:
    """Draw an arrow from ``start`` to ``end`` (data units), with an optional label near its middle."""
    ax.annotate("", xy=tuple(end), xytext=tuple(start),
                arrowprops=dict(arrowstyle=style, color=colour, lw=1.3, shrinkA=1, shrinkB=1,
                                connectionstyle=connection, linestyle=linestyle))
    if text:
        mid = (0.5 * (start[0] + end[0]) + text_offset[0], 0.5 * (start[1] + end[1]) + text_offset[1])
        options = dict(ha="center", va="bottom", fontsize=fontsize, color=colour)
        options.update(text_options)
        ax.text(*mid, text, **options)


def _right(box: tuple[float, float, float, float]) -> tuple[float, float]:
    x, y, w, h = box
    return x + w, y + h / 2


def _left(box: tuple[float, float, float, float]) -> tuple[float, float]:
    x, y, _, h = box
    return x, y + h / 2


def _top(box: tuple[float, float, float, float]) -> tuple[float, float]:
    x, y, w, h = box
    return x + w / 2, y + h


def _bottom(box: tuple[float, float, float, float]) -> tuple[float, float]:
    x, y, w, _ = box
    return x + w / 2, y


def _pixel_events(t: np.ndarray, log_intensity: np.ndarray, contrast: float
                  ) -> tuple[list[float], list[int], list[float]]:
    """Return (times, polarities, reference after each event) of an ideal pixel fed the sampled curve.

    The rule of thesis §2.2.1 with the reference r moved by C at every event: ON when L >= r + C, OFF when
    L <= r - C; crossing times by linear interpolation between samples.
    """
    reference = float(log_intensity[0])
    times, polarities, levels = [], [], []
    for k in range(1, t.size):
        l0, l1 = log_intensity[k - 1], log_intensity[k]
        while True:
            if l1 >= reference + contrast:
                sign = 1
            elif l1 <= reference - contrast:
                sign = -1
            else:
                break
            reference += sign * contrast
            times.append(float(t[k - 1] + (reference - l0) / (l1 - l0) * (t[k] - t[k - 1])))
            polarities.append(sign)
            levels.append(reference)
    return times, polarities, levels


def plot_event_pixel_schematic(contrast: float = 0.2) -> "Figure":
    """Return the DAVIS pixel as a block diagram (left) and its event generation model on one pixel (right).

    Left (thesis §2.2.1, Fig. 3): photoreceptor (log I) -> differencing amplifier (change since the last event) ->
    two comparators (+C, -C) -> ON / OFF events, and the reset that makes the current level the new reference.
    Right (Fig. 4): a log-intensity curve L(t), the reference levels r0 + k C, and the ON (up) and OFF (down)
    events emitted where L has moved by C from the last event's level; the events are computed by that rule.

    Args:
        contrast: the contrast threshold C (log units) of the right panel, > 0.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_event_pixel_schematic()
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    if not (np.isfinite(contrast) and contrast > 0):
        raise ValueError(f"contrast must be a positive number of log units; got {contrast!r}")
    fig, (ax, ax_curve) = plt.subplots(1, 2, figsize=(12.5, 4.2), gridspec_kw={"width_ratios": [1.35, 1.0]})

    # --- the pixel circuit as blocks -------------------------------------------------------------------------------
    _canvas(ax, 10.5, 5.4)
    ax.set_title("the DAVIS pixel (thesis §2.2.1, Fig. 3)", fontsize=10)
    light = _box(ax, 0.05, 2.05, 1.3, 0.9, "light\nintensity I", _SENSOR)
    photo = _box(ax, 1.95, 1.85, 1.9, 1.3, "photoreceptor\nV ∝ log I", _PROCESS)
    diff = _box(ax, 4.45, 1.85, 2.3, 1.3, "differencing\nΔL = log I − L_ref", _PROCESS)
    comp_on = _box(ax, 7.3, 3.2, 1.45, 1.0, "comparator\nΔL ≥ +C ?", _PROCESS)
    comp_off = _box(ax, 7.3, 0.8, 1.45, 1.0, "comparator\nΔL ≤ −C ?", _PROCESS)
    _box(ax, 9.15, 3.3, 1.3, 0.8, "ON event\np = +1", "#f7c9c4", color=_ON_COLOUR)
    _box(ax, 9.15, 0.9, 1.3, 0.8, "OFF event\np = −1", "#c9d9f2", color=_OFF_COLOUR)
    _arrow(ax, _right(light), _left(photo))
    _arrow(ax, _right(photo), _left(diff), "log I")
    _arrow(ax, _right(diff), _left(comp_on), connection="arc3,rad=0.15")
    _arrow(ax, _right(diff), _left(comp_off), connection="arc3,rad=-0.15")
    _arrow(ax, _right(comp_on), (9.15, 3.7), colour=_ON_COLOUR)
    _arrow(ax, _right(comp_off), (9.15, 1.3), colour=_OFF_COLOUR)
    # reset: after an event the reference becomes the current level
    _arrow(ax, (8.0, 0.8), (5.6, 1.85), "reset: L_ref ← L_ref ± C", connection="arc3,rad=-0.35",
           linestyle="--", text_offset=(0.1, -0.95))
    _arrow(ax, (8.0, 4.2), (5.6, 3.15), connection="arc3,rad=0.35", linestyle="--")
    ax.text(5.25, 5.1, "an event e = (t, x, y, p): asynchronous, per pixel, µs time stamps", ha="center",
            fontsize=8.5, style="italic")

    # --- one pixel's log intensity and its events -----------------------------------------------------------------
    t = np.linspace(0.0, 1.0, 2001)
    curve = 0.75 * np.sin(2 * np.pi * 1.1 * t) + 0.35 * t  # L(t): log units
    times, polarities, _ = _pixel_events(t, curve, contrast)
    r0 = float(curve[0])
    k_levels = np.arange(np.floor((curve.min() - r0) / contrast), np.ceil((curve.max() - r0) / contrast) + 1)
    for k in k_levels:
        ax_curve.axhline(r0 + k * contrast, color="0.75", lw=0.8, ls=":", zorder=0)
    ax_curve.plot(t, curve, color="k", lw=1.6)
    on = np.array([tk for tk, p in zip(times, polarities) if p > 0])
    off = np.array([tk for tk, p in zip(times, polarities) if p < 0])
    ax_curve.plot(on, np.interp(on, t, curve), "^", color=_ON_COLOUR, ms=7)
    ax_curve.plot(off, np.interp(off, t, curve), "v", color=_OFF_COLOUR, ms=7)
    base = curve.min() - 0.55
    ax_curve.vlines(on, base, base + 0.25, color=_ON_COLOUR, lw=1.5)
    ax_curve.vlines(off, base - 0.25, base, color=_OFF_COLOUR, lw=1.5)
    ax_curve.axhline(base, color="0.4", lw=0.8)
    ax_curve.text(0.01, base + 0.3, "event stream", fontsize=8, color="0.3")
    ax_curve.set_ylim(base - 0.4, curve.max() + 0.25)
    ax_curve.set_xlabel("time t [s]")
    ax_curve.set_ylabel("log intensity L = log I [log units]")
    ax_curve.set_title(f"event generation: one event per C = {contrast:g} of change (Fig. 4)", fontsize=10)
    ax_curve.legend(handles=[Line2D([], [], color="k", lw=1.6, label="log intensity L(t)"),
                             Line2D([], [], color="0.6", lw=0.8, ls=":", label="levels r0 + k C"),
                             Line2D([], [], color=_ON_COLOUR, marker="^", ls="", label=f"ON event ({on.size})"),
                             Line2D([], [], color=_OFF_COLOUR, marker="v", ls="", label=f"OFF event ({off.size})")],
                    fontsize=8, loc="upper right", framealpha=0.9)
    fig.tight_layout()
    return fig


def plot_reconstruction_schematic(num_bins: int = 5, channels: int = 16) -> "Figure":
    """Return the learned reconstruction as a data flow, unrolled over two windows k - 1 and k.

    Each window of N_e = n H W events (thesis Eq. 87) becomes a voxel grid of ``num_bins`` time bins (B, H, W); the
    network (FireNet: a 3x3 convolution as encoder, two ConvGRU cells each followed by a residual block, a 1x1
    convolution and a sigmoid as decoder) turns it into a frame, and the ConvGRU state h_k is carried to the next
    window: that memory is how a sensor that only sees changes accumulates a whole image.

    Args:
        num_bins: B, the voxel grid's time bins (``evio_lib.events.representations.voxel_grid``; default 5).
        channels: the network's feature channels (FireNet default 16).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_reconstruction_schematic()
    >>> any("ConvGRU" in t.get_text() for t in fig.axes[0].texts)
    True
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    for name, value in (("num_bins", num_bins), ("channels", channels)):
        if not (isinstance(value, (int, np.integer)) and value >= 1):
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    fig, ax = plt.subplots(figsize=(12.5, 5.0))
    _canvas(ax, 15.0, 6.2)
    ax.set_title("learned reconstruction: events -> voxel grid -> recurrent network -> frame (unrolled over two "
                 "windows)", fontsize=10)
    # the event stream along the top, cut into windows
    ax.annotate("", xy=(14.8, 5.75), xytext=(0.2, 5.75), arrowprops=dict(arrowstyle="-|>", color="0.3", lw=1.2))
    ax.text(14.8, 5.9, "time t", ha="right", fontsize=8)
    rng = np.random.default_rng(0)
    for x0, x1, label in ((0.4, 2.4, "window k − 1"), (2.4, 3.4, "window k")):
        ax.add_patch(Rectangle((x0, 5.5), x1 - x0, 0.5, facecolor=_SENSOR, edgecolor="0.3"))
        ticks = rng.uniform(x0 + 0.05, x1 - 0.05, 18)
        ax.vlines(ticks, 5.55, 5.95, color=np.where(rng.random(18) < 0.5, _ON_COLOUR, _OFF_COLOUR), lw=0.8)
        ax.text(0.5 * (x0 + x1), 5.3, label, ha="center", va="top", fontsize=8)
    ax.text(3.6, 5.75, "each window: N_e = n H W events (Eq. 87);\nslow motion -> long window, fast -> short",
            va="center", fontsize=8)

    rows = {"k − 1": 3.3, "k": 0.6}
    gru_boxes = {}
    for k, y in rows.items():
        # voxel grid as a stack of B slices
        for b in range(num_bins):
            ax.add_patch(Rectangle((0.4 + 0.12 * b, y + 0.1 + 0.12 * b), 1.2, 1.0, facecolor=_SENSOR,
                                   edgecolor="0.3", lw=0.8))
        ax.text(1.1, y - 0.05, f"voxel grid\n{num_bins} x H x W", ha="center", va="top", fontsize=8)
        grid_right = (0.4 + 0.12 * (num_bins - 1) + 1.2, y + 0.85)
        enc = _box(ax, 2.8, y + 0.35, 2.1, 1.0, f"encoder\n3x3 conv, {num_bins} -> {channels} ch", _LEARNED)
        gru = _box(ax, 6.0, y + 0.35, 2.7, 1.0, "ConvGRU + residual\n(x2)  state h", _LEARNED)
        dec = _box(ax, 9.8, y + 0.35, 2.1, 1.0, "decoder\n1x1 conv + sigmoid", _LEARNED)
        out = _box(ax, 12.9, y + 0.25, 1.6, 1.2, f"frame\nÎ_{k.replace(' ', '')}", _STATE)
        _arrow(ax, grid_right, _left(enc))
        _arrow(ax, _right(enc), _left(gru))
        _arrow(ax, _right(gru), _left(dec))
        _arrow(ax, _right(dec), _left(out))
        gru_boxes[k] = gru
        ax.text(0.05, y + 0.85, k, ha="left", va="center", fontsize=9, fontweight="bold", rotation=90)
    # the windows feed their voxel grids
    _arrow(ax, (1.4, 5.5), (1.4, rows["k − 1"] + 1.65), colour="0.4")
    _arrow(ax, (2.9, 5.5), (1.9, rows["k"] + 1.65), colour="0.4", connection="arc3,rad=-0.1")
    # recurrent state carried between windows
    _arrow(ax, (7.35, 5.35), _top(gru_boxes["k − 1"]), "h_{k−2}", colour="tab:green", text_offset=(0.45, -0.1),
           linestyle="--")
    _arrow(ax, _bottom(gru_boxes["k − 1"]), _top(gru_boxes["k"]), "state h_{k−1} carried to window k",
           colour="tab:green", text_offset=(0.15, -0.15), ha="left", linestyle="--")
    _arrow(ax, _bottom(gru_boxes["k"]), (7.35, 0.05), "h_k -> window k + 1", colour="tab:green",
           text_offset=(0.15, -0.2), ha="left", linestyle="--")
    ax.text(9.0, 5.05, "same weights in every window; only the state h changes", fontsize=8, style="italic",
            color="0.25")
    fig.tight_layout()
    return fig


def plot_superpoint_schematic(encoder_channels: Sequence[int] = (64, 64, 64, 64, 128, 128, 128, 128),
                              head_channels: int = 256, descriptor_dim: int = 256, cell: int = 8) -> "Figure":
    """Return the SuperPoint-style network as blocks: the shared encoder and its detector and descriptor heads.

    Encoder (thesis §3.2.4, Fig. 12): eight 3x3 convolutions (depths ``encoder_channels``), a 2x2 max-pool after
    every two of the first six, so an H x W image becomes an H/8 x W/8 grid of cells. Detector head: 3x3 conv
    (``head_channels``), 1x1 conv to cell^2 + 1 = 65 logits per cell, softmax, drop the "no point" dustbin,
    depth-to-space to an H x W heatmap. Descriptor head: 3x3 conv, 1x1 conv to ``descriptor_dim``, bicubic
    upsampling and L2 normalisation. Defaults: `evio_lib.features.network` ("full" width).

    Args:
        encoder_channels: the eight encoder depths.
        head_channels: depth of each head's 3x3 convolution.
        descriptor_dim: descriptor length D.
        cell: the cell size (8: three 2x2 pools).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_superpoint_schematic()
    >>> any("65" in t.get_text() for t in fig.axes[0].texts)
    True
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    channels = [int(c) for c in encoder_channels]
    if len(channels) != 8 or min(channels) < 1:
        raise ValueError(f"encoder_channels must be 8 positive integers; got {encoder_channels!r}")
    fig, ax = plt.subplots(figsize=(13.0, 5.4))
    _canvas(ax, 17.4, 6.6)
    ax.set_title("SuperPoint-style network (thesis §3.2.4, Fig. 12): one shared encoder, two heads", fontsize=10)
    image = _box(ax, 0.1, 2.55, 1.3, 1.5, "image\nH x W x 1", _SENSOR)

    # encoder: four stages, drawn as slabs that shrink with the resolution
    x, centre, prev = 1.8, 3.3, _right(image)
    scales = ["H x W", "H/2 x W/2", "H/4 x W/4", "H/8 x W/8"]
    for stage in range(4):
        height = 2.6 / (1.45 ** stage)
        c1, c2 = channels[2 * stage], channels[2 * stage + 1]
        pooled = stage < 3
        slab = _box(ax, x, centre - height / 2, 1.25, height, f"2 x conv3x3\n{c1}, {c2}", _LEARNED,
                    fontsize=8)
        ax.text(x + 0.62, centre - height / 2 - 0.12, scales[stage], ha="center", va="top", fontsize=7.5)
        _arrow(ax, prev, _left(slab))
        prev = _right(slab)
        if pooled:
            ax.text(x + 1.42, centre + 0.15, "pool\n2x2", ha="center", va="bottom", fontsize=7, color="0.35")
        x += 1.65
    ax.add_patch(Polygon([[1.75, 5.35], [x - 0.35, 5.35]], closed=False, edgecolor="0.3", lw=1.0))
    ax.text(0.5 * (1.75 + x - 0.35), 5.45, f"shared encoder: H x W -> H/{cell} x W/{cell} x {channels[-1]}",
            ha="center", va="bottom", fontsize=9, fontweight="bold")
    split = (x - 0.05, centre)
    ax.plot([prev[0], split[0]], [centre, centre], color="0.2", lw=1.3)

    # detector head (top row) and descriptor head (bottom row)
    n_logits = cell * cell + 1
    row_specs = (
        ("detector head", 4.45, [(f"conv3x3\n{head_channels}", _LEARNED), (f"conv1x1\n{n_logits} ch", _LEARNED),
                                 (f"softmax over {n_logits},\ndrop dustbin", _PROCESS),
                                 (f"depth-to-space\n{cell * cell} ch -> {cell}x{cell}", _PROCESS),
                                 ("heatmap\nH x W", _STATE)]),
        ("descriptor head", 1.1, [(f"conv3x3\n{head_channels}", _LEARNED),
                                  (f"conv1x1\n{descriptor_dim} ch", _LEARNED),
                                  (f"bicubic upsampling\nx{cell}", _PROCESS), ("L2 normalise\n||d|| = 1", _PROCESS),
                                  (f"descriptors\nH x W x {descriptor_dim}", _STATE)]),
    )
    for name, y, boxes in row_specs:
        bx = split[0] + 0.45
        ax.text(bx, y + 1.15, name, fontsize=9, fontweight="bold")
        previous = None
        for k, (text, colour) in enumerate(boxes):
            box = _box(ax, bx, y, 1.5, 0.95, text, colour, fontsize=7.8)
            if previous is None:
                ax.plot([split[0], split[0]], [centre, y + 0.475], color="0.2", lw=1.3)
                _arrow(ax, (split[0], y + 0.475), _left(box))
            else:
                _arrow(ax, _right(previous), _left(box))
            previous = box
            bx += 1.7
    ax.text(split[0] + 0.5, 3.3, f"per cell of {cell}x{cell} px: {n_logits} logits (64 positions + 'no point')\n"
            f"and one {descriptor_dim}-D descriptor", fontsize=8, va="center", color="0.25", style="italic")
    fig.tight_layout()
    return fig


def plot_msckf_schematic(num_clones: int = 5) -> "Figure":
    """Return the MSCKF's state vector (top) and the life of one feature track through the filter (bottom).

    Top (thesis Eqs. 21, 25-26): the IMU state [q_GtoI, b_g, v_IinG, b_a, p_IinG] (15 error states: 3 each) and N
    camera clones (q_GtoC, p_CinG) of the sliding window (6 error states each): 15 + 6N in all, the order of
    `evio_lib.msckf.state`. Bottom (§3.3.6-3.3.7): a feature observed in several clones; when its track is lost (or
    its clones are about to be pruned from a full window) it is triangulated, its residual is projected onto the
    left nullspace of H_f (the feature's position drops out), the EKF updates every state, and the oldest clones
    are marginalised (their rows and columns of P removed).

    Args:
        num_clones: camera clones drawn in the window, >= 3.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_msckf_schematic()
    >>> any("b_g" in t.get_text() for t in fig.axes[0].texts)
    True
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    if not (isinstance(num_clones, (int, np.integer)) and num_clones >= 3):
        raise ValueError(f"num_clones must be an integer >= 3; got {num_clones!r}")
    fig, (ax_state, ax_track) = plt.subplots(2, 1, figsize=(12.5, 7.4), gridspec_kw={"height_ratios": [1.0, 1.55]})

    # --- the state vector --------------------------------------------------------------------------------------
    _canvas(ax_state, 16.0, 3.6)
    ax_state.set_title("the MSCKF state: IMU state + a sliding window of camera clones (error state 15 + 6N)",
                       fontsize=10)
    x = 0.2
    imu_parts = [("q_GtoI", "attitude"), ("b_g", "gyro bias"), ("v_IinG", "velocity"), ("b_a", "accel bias"),
                 ("p_IinG", "position")]
    for name, meaning in imu_parts:
        ax_state.add_patch(Rectangle((x, 1.4), 1.25, 1.0, facecolor=_STATE, edgecolor="0.25"))
        ax_state.text(x + 0.625, 2.05, name, ha="center", va="center", fontsize=9)
        ax_state.text(x + 0.625, 1.65, f"{meaning}\n(3)", ha="center", va="center", fontsize=7)
        x += 1.25
    ax_state.annotate("", xy=(0.2, 2.7), xytext=(x, 2.7), arrowprops=dict(arrowstyle="<->", color="0.3"))
    ax_state.text(0.5 * (0.2 + x), 2.8, "IMU state X_IMU (Eq. 21): 15 error states", ha="center", va="bottom",
                  fontsize=9)
    x += 0.25
    clone_start = x
    shown = [1, 2, "…", "N"]
    for label in shown:
        if label == "…":
            ax_state.text(x + 0.35, 1.9, "…", ha="center", va="center", fontsize=14)
            x += 0.7
            continue
        ax_state.add_patch(Rectangle((x, 1.4), 1.1, 1.0, facecolor=_SENSOR, edgecolor="0.25"))
        ax_state.add_patch(Rectangle((x + 1.1, 1.4), 1.1, 1.0, facecolor=_SENSOR, edgecolor="0.25"))
        ax_state.text(x + 0.55, 2.05, f"q_GtoC{label}", ha="center", va="center", fontsize=8.5)
        ax_state.text(x + 1.65, 2.05, f"p_C{label}inG", ha="center", va="center", fontsize=8.5)
        ax_state.text(x + 0.55, 1.65, "(3)", ha="center", va="center", fontsize=7)
        ax_state.text(x + 1.65, 1.65, "(3)", ha="center", va="center", fontsize=7)
        x += 2.35
    ax_state.annotate("", xy=(clone_start, 2.7), xytext=(x - 0.15, 2.7),
                      arrowprops=dict(arrowstyle="<->", color="0.3"))
    ax_state.text(0.5 * (clone_start + x), 2.8, "N camera clones (Eq. 25): 6 error states each", ha="center",
                  va="bottom", fontsize=9)
    ax_state.text(0.2, 0.75, "a new image -> clone the current camera pose (augmentation, Eqs. 27-30);  "
                  "the IMU propagates X_IMU and P between images (Eqs. 33-40);  covariance P: (15 + 6N) x (15 + 6N)",
                  fontsize=8, color="0.25")

    # --- the life of a feature track ---------------------------------------------------------------------------
    _canvas(ax_track, 16.0, 5.8)
    ax_track.set_title("the life of a feature track", fontsize=10)
    # the window of clones, observing a landmark
    landmark = (2.6, 5.15)
    ax_track.plot(*landmark, marker="*", ms=15, color="goldenrod")
    ax_track.text(landmark[0] + 0.25, landmark[1], "feature p_f (unknown)", va="center", fontsize=8)
    cams = []
    for i in range(num_clones):
        cx = 0.5 + i * 4.4 / (num_clones - 1)
        observed = 0 < i < num_clones - 1 or num_clones == 3
        ax_track.add_patch(Rectangle((cx - 0.25, 2.9), 0.5, 0.45, facecolor=_SENSOR, edgecolor="0.25"))
        ax_track.text(cx, 2.75, f"C{i + 1}", ha="center", va="top", fontsize=8)
        if observed:
            ax_track.plot([cx, landmark[0]], [3.35, landmark[1]], color="goldenrod", lw=1.0, ls="--")
        cams.append((cx, observed))
    ax_track.text(2.7, 2.25, "1. observed in several clones\n(a track: one image point per clone)",
                  ha="center", va="top", fontsize=8.5)
    ax_track.annotate("", xy=(5.2, 2.55), xytext=(0.2, 2.55), arrowprops=dict(arrowstyle="-|>", color="0.4"))

    steps = [
        (6.0, 3.6, "2. track lost\n(not seen in the new image)\nor clones pruned (window full)", _PROCESS),
        (9.45, 3.6, "3. triangulate p_f\nfrom the clone poses\n(inverse depth, Gauss-Newton)", _PROCESS),
        (12.9, 3.6, "4. residual r = z − h(x)\nJacobians H_x, H_f", _PROCESS),
        (12.9, 0.6, "5. nullspace projection\nr_o = Aᵀ r,  Aᵀ H_f = 0:\np_f drops out of the update", _PROCESS),
        (9.45, 0.6, "6. EKF update of IMU state\nand all clones (x, P)", _STATE),
        (6.0, 0.6, "7. window full: oldest clones\nmarginalised (their rows and\ncolumns of P dropped)", _STATE),
    ]
    boxes = [_box(ax_track, x0, y0, 2.95, 1.6, text, colour, fontsize=8.3) for x0, y0, text, colour in steps]
    _arrow(ax_track, (5.2, 3.1), _left(boxes[0]))
    for a, b in zip(boxes[:2], boxes[1:3]):
        _arrow(ax_track, _right(a), _left(b))
    _arrow(ax_track, _bottom(boxes[2]), _top(boxes[3]))
    for a, b in zip(boxes[3:5], boxes[4:6]):
        _arrow(ax_track, _left(a), _right(b))
    ax_track.text(0.2, 0.9, "a feature enters the filter only\nonce, when its track ends: its\n"
                  "position is never in the state", fontsize=8, style="italic", color="0.25", va="center")
    fig.tight_layout()
    return fig


def plot_pipeline_schematic() -> "Figure":
    """Return the EVIO pipeline's data flow: sensors -> frames -> features + tracker -> MSCKF -> trajectory + metrics.

    Events become frames by windows of N_e = n H W events and a reconstruction (lesson 04), or the APS frames are
    used directly; features (classical or CNN, lessons 05-08) are tracked from frame to frame (KLT or descriptor
    matching, two-point RANSAC with the gyroscope's rotation: lesson 14); the MSCKF (the IMU in lesson 09, the Kalman
    filter in 10, the MSCKF in 11-13) propagates with the IMU
    and updates with finished tracks; the trajectory is scored against the ground truth (lesson 14; thesis Chapter
    IV §4.5).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_pipeline_schematic()
    >>> any("MSCKF" in t.get_text() for t in fig.axes[0].texts)
    True
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(13.0, 4.8))
    _canvas(ax, 16.5, 6.0)
    ax.set_title("the EVIO pipeline: data flow (thesis Chapter IV §4.5); the lesson that teaches each box in "
                 "brackets", fontsize=10)
    events = _box(ax, 0.1, 4.3, 2.2, 1.0, "events (t, x, y, p)\n(03)", _SENSOR)
    aps = _box(ax, 0.1, 2.7, 2.2, 1.0, "APS frames\n(03)", _SENSOR)
    imu = _box(ax, 0.1, 1.1, 2.2, 1.0, "IMU: gyro ω, accel a\n(09)", _SENSOR)
    truth = _box(ax, 0.1, 0.0, 2.2, 0.8, "ground truth", _SENSOR, fontsize=8.5)
    recon = _box(ax, 3.0, 4.2, 2.6, 1.2, "windows N_e = n H W\n-> reconstruction\n(04)", _PROCESS, fontsize=8.5)
    frames = _box(ax, 6.3, 3.2, 2.0, 1.4, "frames\n(APS or\nfrom events)", _STATE)
    front = _box(ax, 9.0, 3.0, 2.9, 1.8, "features (05-08)\n+ tracker: KLT / matching,\ntwo-point RANSAC (14)",
                 _PROCESS, fontsize=8.5)
    msckf = _box(ax, 9.0, 0.6, 2.9, 1.6, "MSCKF (10-13)\npropagate with the IMU,\nupdate with tracks", _PROCESS,
                 fontsize=8.5)
    trajectory = _box(ax, 12.8, 0.7, 1.6, 1.4, "trajectory\n(TUM file)", _STATE, fontsize=8.5)
    metrics = _box(ax, 14.8, 0.7, 1.6, 1.4, "metrics\nATE, RMSE\n(14)", _STATE, fontsize=8.5)
    _arrow(ax, _right(events), _left(recon))
    _arrow(ax, _right(recon), (6.3, 4.2), connection="arc3,rad=-0.15")
    _arrow(ax, _right(aps), (6.3, 3.6), "or", connection="arc3,rad=0.1")
    _arrow(ax, _right(frames), _left(front))
    _arrow(ax, _bottom(front), _top(msckf), "feature tracks\n(undistorted, normalised)", text_offset=(1.15, -0.3))
    _arrow(ax, _right(imu), _left(msckf), "ω, a at 200-1000 Hz")
    _arrow(ax, (2.3, 1.85), (10.0, 3.0), "gyro rotation prior", connection="arc3,rad=0.12",
           colour="0.45", linestyle="--", text_offset=(1.6, 0.1))
    _arrow(ax, _right(msckf), _left(trajectory))
    _arrow(ax, _right(trajectory), _left(metrics))
    _arrow(ax, _right(truth), (15.6, 0.7), "", connection="arc3,rad=0.08", colour="0.45")
    ax.text(8.0, 0.18, "compared with the ground truth", fontsize=8, color="0.35")
    fig.tight_layout()
    return fig


def _schematic_drawing(shape: tuple[int, int] = (96, 128)) -> np.ndarray:
    """Return a made-up grayscale scene in [0, 1] with sharp corners (a square, a triangle, an L, a small grid)."""
    import cv2

    height, width = shape
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    image = (0.75 + 0.1 * xx / width - 0.05 * yy / height).astype(np.float32)  # a gentle background gradient
    scale = np.array([width / 128.0, height / 96.0])
    shapes = [
        ([[14, 14], [44, 14], [44, 42], [14, 42]], 0.15),  # square
        ([[62, 70], [96, 52], [90, 86]], 0.3),  # triangle
        ([[58, 12], [112, 12], [112, 22], [70, 22], [70, 40], [58, 40]], 0.1),  # an L
    ]
    for corners, value in shapes:
        cv2.fillPoly(image, [np.round(np.asarray(corners) * scale).astype(np.int32)], float(value))
    for row in range(2):  # a 2 x 3 checkerboard
        for col in range(3):
            if (row + col) % 2 == 0:
                x0, y0 = (16 + 10 * col) * scale[0], (58 + 10 * row) * scale[1]
                cv2.rectangle(image, (int(x0), int(y0)), (int(x0 + 10 * scale[0]) - 1, int(y0 + 10 * scale[1]) - 1),
                              0.05, -1)
    return cv2.GaussianBlur(image, (3, 3), 0.7)


def _similarity_homography(shape: tuple[int, int], angle_deg: float, scale: float, shift: Sequence[float] = (0, 0),
                           perspective: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """Return a homography that rotates by ``angle_deg`` and scales about the image centre, shifts and tilts."""
    height, width = shape
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    a = np.deg2rad(angle_deg)
    to_centre = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    rotate = np.array([[scale * np.cos(a), -scale * np.sin(a), 0.0], [scale * np.sin(a), scale * np.cos(a), 0.0],
                       [perspective[0] / width, perspective[1] / height, 1.0]])
    back = np.array([[1.0, 0.0, cx + shift[0]], [0.0, 1.0, cy + shift[1]], [0.0, 0.0, 1.0]])
    H = back @ rotate @ to_centre
    return H / H[2, 2]


def _harris_response(batch: np.ndarray) -> np.ndarray:
    """(B, H, W) images -> (B, H, W) positive Harris responses: the stand-in detector f of the schematic."""
    import cv2

    return np.stack([np.maximum(cv2.cornerHarris(np.ascontiguousarray(img, np.float32), 5, 3, 0.04), 0.0)
                     for img in batch])  # loop: a few images


def homographic_adaptation_schematic_data(n_homographies: int = 16, seed: int = 0) -> dict[str, np.ndarray]:
    """Return the numbers drawn by :func:`plot_homographic_adaptation_schematic` (all computed, nothing typed).

    Keys: ``image`` (96, 128) made-up scene; ``homographies`` (N, 3, 3), [0] the identity, [1:4] the three views
    drawn; ``views``, ``responses``, ``back`` (3, 96, 128): the drawn views H_i I, the detector on them and the
    response mapped back to the image's frame (NaN where view i did not see the pixel); ``heatmap``, ``counts``:
    the aggregate over all N views by :func:`evio_lib.features.training.adaptation.homographic_adaptation`;
    ``labels`` (K, 2): its maxima (above a tenth of its peak, NMS 4 px); ``scale``: the peak of f on the image,
    by which every response is divided; ``pair_homography``, ``cell`` (row, col), ``positives`` (P, 2) (row, col)
    cells of image 2 within 8 px of the warped centre (Eq. 10) and ``warped_centre`` (2,) for the descriptor panel.

    >>> data = homographic_adaptation_schematic_data(n_homographies=4)
    >>> data["heatmap"].shape, data["homographies"].shape, bool(np.allclose(data["homographies"][0], np.eye(3)))
    ((96, 128), (4, 3, 3), True)
    """
    import cv2

    from evio_lib.features.training.adaptation import heatmap_to_keypoints, homographic_adaptation
    from evio_lib.features.training.augment import HOMOGRAPHIC_ADAPTATION
    from evio_lib.geometry.homography import valid_mask, warp_image, warp_points

    if isinstance(n_homographies, bool) or not isinstance(n_homographies, (int, np.integer)) or n_homographies < 4:
        raise ValueError(f"n_homographies must be an integer >= 4 (the identity and the three views drawn); "
                         f"got {n_homographies!r}")
    image = _schematic_drawing()
    shape = image.shape
    drawn = [_similarity_homography(shape, 25.0, 0.9, (4, -3), (0.25, 0.0)),
             _similarity_homography(shape, -30.0, 1.15, (-5, 4), (0.0, 0.3)),
             _similarity_homography(shape, 8.0, 0.8, (6, 5), (-0.3, 0.15))]
    rng = np.random.default_rng(seed)
    others = [_similarity_homography(shape, rng.uniform(-35, 35), rng.uniform(0.8, 1.2), rng.uniform(-6, 6, 2),
                                     rng.uniform(-0.3, 0.3, 2)) for _ in range(n_homographies - 4)]
    homographies = np.stack([np.eye(3)] + drawn + others)
    scale = float(_harris_response(image[None])[0].max())

    def detector(batch: np.ndarray) -> np.ndarray:
        return _harris_response(batch) / scale

    margin = 5  # the detector's 5 x 5 window answers to a view's border up to 5 px inside it: left out (c_i = 0)
    result = homographic_adaptation(image, detector, rng=seed, homographies=homographies,
                                    config=HOMOGRAPHIC_ADAPTATION.replace(valid_border_margin=margin))
    views = np.stack([warp_image(image, H) for H in drawn])
    responses = detector(views)
    back = []
    for H, response in zip(drawn, responses):  # the library's mapping back, for the three views drawn
        seen = warp_image(valid_mask(shape, H, erode=margin).astype(np.float32), np.linalg.inv(H),
                          interpolation=cv2.INTER_NEAREST) > 0.5
        mapped = cv2.warpPerspective(response, np.linalg.inv(H), (shape[1], shape[0]), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REPLICATE)
        back.append(np.where(seen, mapped, np.nan))
    labels, _ = heatmap_to_keypoints(result.heatmap, 0.1 * float(result.heatmap.max()), nms_radius=4, border=4)

    pair_homography = _similarity_homography(shape, 12.0, 1.1, (5, -2), (0.15, 0.1))
    cell = (5, 6)  # (row, col) of the cell of image 1 whose correspondences are drawn
    centre = np.array([[8 * cell[1] + 3.5, 8 * cell[0] + 3.5]])
    warped_centre = warp_points(pair_homography, centre)[0]
    rows, cols = np.mgrid[0:shape[0] // 8, 0:shape[1] // 8]
    centres = np.stack([8 * cols.ravel() + 3.5, 8 * rows.ravel() + 3.5], axis=1)
    near = np.linalg.norm(centres - warped_centre, axis=1) < 8.0  # Eq. 10: s = 1 within 8 px
    positives = np.stack([rows.ravel()[near], cols.ravel()[near]], axis=1)
    return dict(image=image, homographies=homographies, views=views, responses=responses, back=np.stack(back),
                heatmap=result.heatmap, counts=result.counts, labels=labels, scale=np.float64(scale),
                pair_homography=pair_homography, cell=np.array(cell), positives=positives,
                warped_centre=warped_centre)


def plot_homographic_adaptation_schematic(n_homographies: int = 16, margins: tuple[float, float] = (1.0, 0.2),
                                          lambda_d: float = 62.5) -> "Figure":
    """Return homographic adaptation (top) and the descriptor loss on a warped pair (bottom), drawn on a made-up scene.

    Top (thesis §3.2.5.2): an image without labels, N random homographies H_i (three views drawn), the detector f on
    each view, each response mapped back by H_i⁻¹ (only where the view saw the pixel, c_i = 1), and the mean over the
    views that saw each pixel: the aggregate, whose maxima become the labels. The detector drawn is a Harris
    response (a stand-in for MagicPoint), every response divided by its peak on the image, on one colour range.
    Bottom (Eqs. 10-12): one cell of image 1, its centre warped by the pair's H into image 2, the cells of image 2
    whose centres lie within 8 px (s = 1: corresponding) and all others (s = 0); and the two hinge terms of the
    descriptor loss against the cosine d·d′ of two unit descriptors, with the margins m_p and m_n.

    Args:
        n_homographies: N, the views averaged (the identity and the three drawn among them), >= 4.
        margins: (m_p, m_n), the positive and negative margins of the hinge (SuperPoint: 1 and 0.2).
        lambda_d: the weight of the positive term (the configs' 62.5 at 120 x 160); the curve is drawn divided by it.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_homographic_adaptation_schematic(n_homographies=4)
    >>> any("H_i" in t.get_text() for t in fig.texts)
    True
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, ConnectionPatch, Rectangle

    m_p, m_n = (float(m) for m in margins)
    if not (np.isfinite(m_p) and np.isfinite(m_n) and -1.0 <= m_n < m_p):
        raise ValueError(f"margins must be (m_p, m_n) with -1 <= m_n < m_p; got {margins!r}")
    if not (np.isfinite(lambda_d) and lambda_d > 0):
        raise ValueError(f"lambda_d must be a positive number; got {lambda_d!r}")
    data = homographic_adaptation_schematic_data(n_homographies)
    image = data["image"]
    height, width = image.shape
    fig_w, fig_h = 13.6, 9.4
    fig = plt.figure(figsize=(fig_w, fig_h))

    def axes_at(left: float, bottom: float, w: float, h: float) -> "Axes":  # inches -> figure fraction
        return fig.add_axes((left / fig_w, bottom / fig_h, w / fig_w, h / fig_h))

    def image_axes(left: float, bottom: float, w: float) -> "Axes":
        ax = axes_at(left, bottom, w, w * height / width)
        ax.set_xticks([])
        ax.set_yticks([])
        return ax

    def link(ax_a: "Axes", ax_b: "Axes", text: str = "", ya: float = 0.5, yb: float = 0.5, **text_options) -> None:
        arrow = ConnectionPatch((1.02, ya), (-0.02, yb), "axes fraction", "axes fraction", axesA=ax_a, axesB=ax_b,
                                arrowstyle="-|>", color="0.2", lw=1.2, mutation_scale=12)
        fig.add_artist(arrow)
        if text:
            x_a, y_a = fig.transFigure.inverted().transform(ax_a.transAxes.transform((1.02, ya)))
            x_b, y_b = fig.transFigure.inverted().transform(ax_b.transAxes.transform((-0.02, yb)))
            options = dict(ha="center", va="bottom", fontsize=8, color="0.2")
            options.update(text_options)
            fig.text(0.5 * (x_a + x_b), 0.5 * (y_a + y_b) + 0.008, text, **options)

    cmap = plt.get_cmap("magma").with_extremes(bad="0.85")  # grey: pixels a view did not see
    response_range = dict(vmin=0.0, vmax=1.0, cmap=cmap)

    # --- top: homographic adaptation ---------------------------------------------------------------------------
    fig.text(0.5, 0.985, f"homographic adaptation (thesis §3.2.5.2): a label from N = {n_homographies} random warps "
             "of an image without labels", ha="center", va="top", fontsize=11)
    big, small, top_base = 2.0, 1.4, 4.55
    small_h = small * height / width
    ax_image = image_axes(0.25, top_base + 1.05, big)
    ax_image.imshow(image, cmap="gray", vmin=0, vmax=1)
    ax_image.set_title("image I (no labels)", fontsize=9)
    grid_left = 0.25 + big + 0.75
    column_titles = ["view H_i I", "detector f(H_i I)", "back in I's frame\nH_i⁻¹ f(H_i I)"]
    grid_axes = []
    for i in range(3):
        bottom = top_base + 2 * (small_h + 0.32) - i * (small_h + 0.32)
        row = []
        for j, (panel, kind) in enumerate(((data["views"][i], "gray"), (data["responses"][i], "response"),
                                           (data["back"][i], "response"))):
            ax = image_axes(grid_left + j * (small + 0.45), bottom, small)
            if kind == "gray":
                ax.imshow(panel, cmap="gray", vmin=0, vmax=1)
            else:
                shown = ax.imshow(panel, **response_range)
            if i == 0:
                ax.set_title(column_titles[j], fontsize=8.5)
            row.append(ax)
        for a, b in zip(row[:-1], row[1:]):
            link(a, b)
        grid_axes.append(row)
    for i, row in enumerate(grid_axes):
        link(ax_image, row[0], f"H_{i + 1}", yb=0.5, ya=0.85 - 0.35 * i, fontsize=9)
    fig.text((0.25 + big / 2) / fig_w, (top_base + 0.95) / fig_h, "warp by N random\nhomographies H_i",
             ha="center", va="top", fontsize=8.5)
    fig.text((grid_left + 1.5 * small + 0.45) / fig_w, (top_base - 0.18) / fig_h,
             f"… and {n_homographies - 4} more random views, plus the image itself (H_0 = identity); grey: pixels "
             "the view did not see (c_i = 0)", ha="center", va="top", fontsize=8, color="0.3")
    agg_left = grid_left + 3 * small + 2 * 0.45 + 0.7
    ax_agg = image_axes(agg_left, top_base + 1.05, big)
    heat = np.where(data["counts"] > 0, data["heatmap"], np.nan)
    shown = ax_agg.imshow(heat, **response_range)
    ax_agg.set_title("aggregate F(I): mean over\nthe views that saw each pixel", fontsize=9)
    for row in grid_axes:
        link(row[-1], ax_agg, yb=0.5)
    colour_axes = axes_at(agg_left, top_base + 0.55, big, 0.12)
    bar = fig.colorbar(shown, cax=colour_axes, orientation="horizontal")
    bar.set_label("detector response (÷ its peak on I)", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    ax_labels = image_axes(agg_left + big + 0.65, top_base + 1.05, big)
    ax_labels.imshow(image, cmap="gray", vmin=0, vmax=1)
    labels = data["labels"]
    ax_labels.scatter(labels[:, 0], labels[:, 1], s=40, facecolors="none", edgecolors="red", linewidths=1.3)
    ax_labels.set_title(f"labels: the {len(labels)} maxima of F(I)", fontsize=9)
    link(ax_agg, ax_labels, "threshold\n+ NMS")

    # --- bottom: the descriptor loss on a warped pair ------------------------------------------------------------
    fig.text(0.5, 3.9 / fig_h, "the descriptor loss on a warped pair (Eqs. 10-12): one descriptor per 8 x 8 cell",
             ha="center", va="bottom", fontsize=11)
    pair_w, pair_base = 3.3, 0.75
    ax_1 = image_axes(0.25, pair_base, pair_w)
    ax_2 = image_axes(0.25 + pair_w + 0.9, pair_base, pair_w)
    from evio_lib.geometry.homography import warp_image

    warped = warp_image(image, data["pair_homography"])
    r, c = (int(v) for v in data["cell"])
    for ax, shown_image, title in ((ax_1, image, "image 1: cell (h, w), centre p_hw"),
                                   (ax_2, warped, "image 2 = image 1 warped by H")):
        ax.imshow(shown_image, cmap="gray", vmin=0, vmax=1)
        for x in np.arange(8, width, 8) - 0.5:
            ax.axvline(x, color="tab:blue", lw=0.4, alpha=0.6)
        for y in np.arange(8, height, 8) - 0.5:
            ax.axhline(y, color="tab:blue", lw=0.4, alpha=0.6)
        ax.set_title(title, fontsize=9)
    ax_1.add_patch(Rectangle((8 * c - 0.5, 8 * r - 0.5), 8, 8, facecolor="gold", alpha=0.6, edgecolor="k"))
    ax_1.plot(8 * c + 3.5, 8 * r + 3.5, "k+", ms=8)
    for pr, pc in data["positives"]:
        ax_2.add_patch(Rectangle((8 * pc - 0.5, 8 * pr - 0.5), 8, 8, facecolor="lime", alpha=0.55, edgecolor="k",
                                 lw=0.6))
    wx, wy = data["warped_centre"]
    ax_2.add_patch(Circle((wx, wy), 8.0, fill=False, edgecolor="gold", lw=1.5))
    ax_2.plot(wx, wy, "k+", ms=8)
    fig.add_artist(ConnectionPatch((8 * c + 3.5, 8 * r + 3.5), (wx, wy), "data", "data", axesA=ax_1, axesB=ax_2,
                                   arrowstyle="-|>", color="gold", lw=1.4, mutation_scale=12))
    ax_2.text(0.02, -0.04, f"green: the {len(data['positives'])} cells whose centre lies within 8 px of H p_hw "
              "\n(s = 1, corresponding); every other cell: s = 0", transform=ax_2.transAxes, ha="left", va="top",
              fontsize=8)
    ax_1.text(0.5, -0.04, "every cell of image 1 is paired with every cell of image 2", transform=ax_1.transAxes,
              ha="center", va="top", fontsize=8)
    ax_hinge = axes_at(0.25 + 2 * pair_w + 2.3, pair_base + 0.05, 3.7, 2.45)
    cosine = np.linspace(-1.0, 1.0, 401)
    ax_hinge.plot(cosine, np.maximum(0.0, m_p - cosine), color="tab:green", lw=2,
                  label="s = 1: λ_d max(0, m_p − d·d′), drawn ÷ λ_d")
    ax_hinge.plot(cosine, np.maximum(0.0, cosine - m_n), color="tab:red", lw=2,
                  label="s = 0: max(0, d·d′ − m_n)")
    ax_hinge.axvline(m_p, color="tab:green", ls=":", lw=1)
    ax_hinge.axvline(m_n, color="tab:red", ls=":", lw=1)
    ax_hinge.text(m_p, 1.3, f"m_p = {m_p:g} ", ha="right", va="bottom", fontsize=8, color="tab:green")
    ax_hinge.text(m_n, 0.55, f"m_n = {m_n:g} ", ha="right", va="bottom", fontsize=8, color="tab:red")
    ax_hinge.set_ylim(0, 2.05)
    ax_hinge.set_xlim(-1, 1)
    ax_hinge.set_xlabel("d·d′: cosine of the two cells' unit descriptors")
    ax_hinge.set_ylabel(f"loss of one cell pair\n(positive term ÷ λ_d = {lambda_d:g})")
    ax_hinge.set_title("hinge terms: pull corresponding cells to d·d′ ≥ m_p,\npush the others below m_n",
                       fontsize=9)
    ax_hinge.legend(fontsize=7.5, loc="upper right")
    return fig
