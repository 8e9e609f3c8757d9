"""Event-to-image reconstruction: one interface for the classical integrators and the learned recurrent networks.

``create_reconstructor(name, width, height, **options)`` returns an object with ``reset()`` and
``reconstruct(window) -> (H, W) float32 image in [0, 1]``, fed one event window after another (state carried):

- ``direct``: direct integration of log intensity, L^(x) += C p for every event, with an optional leak
  (``cutoff_hz``); the simplest baseline.
- ``high_pass``: the per-event high-pass filter of Scheerlinck et al. (ACCV 2018). Between events every pixel decays,
  and each event first decays its pixel once more and then adds its contrast:
      L^(t_k) = exp(-alpha (t_k - t_prev) - beta) L^(t_prev) + C p_k,   alpha = 2 pi f_c.
  Defaults are those of the authors' reference ROS implementation as we read it: f_c = 0.06 Hz (alpha = 0.377 rad/s)
  and a per-event decay beta = 0.06. ``direct`` is the same filter with alpha = beta = 0.
  The filter is linear, so a window is applied in closed form, vectorised with ``np.bincount``: at the window's end T,
      L^(T) = exp(-alpha (T - T_prev) - beta n_x) L^(T_prev) + sum_k C p_k exp(-alpha (T - t_k) - beta m_k),
  where n_x counts the window's events at pixel x and m_k the events at event k's pixel after it.
  The image returned is the intensity exp(L^), stretched between its 1st and 99th percentiles: linear intensity, like
  the learned networks' output and the simulator's truth (up to the unknown brightness of each pixel at the start).
- ``firenet`` (the default, shipped weights) and any other shipped checkpoint by name, or ``learned`` with
  ``checkpoint=PATH``: a recurrent network (:mod:`evio_lib.events.reconstruction.nets`) fed E2VID's voxel grid
  (B = 5 bins) of each window.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.events.representations import check_sensor_pixels, voxel_grid
from evio_lib.events.reconstruction.precision import PRECISIONS  # torch-free: the commands' --help stays light

__all__ = ["PRECISIONS", "Reconstructor", "LogIntegrator", "LearnedReconstructor", "available_reconstructors",
           "create_reconstructor", "reconstructor_by_name_or_file", "shipped_checkpoint", "reconstruct_windows",
           "reconstruct_at_times"]

# PRECISIONS: a network's arithmetic (``precision=`` of the learned reconstructors; the classical ones have none to
# choose). ``auto`` (the default): int8 for a FireNet on a CPU that runs PyTorch's x86 int8 convolutions and Numba's
# kernels, else float32 (:func:`evio_lib.events.reconstruction.precision.resolve_precision`). A reconstructor's
# ``precision`` says which it chose.

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
#: Shipped learned reconstructors: name -> checkpoint file in evio_lib/weights/.
_SHIPPED = {"firenet": "reconstruction_firenet.pt"}


class Reconstructor(ABC):
    """Turns consecutive event windows into images; ``reset()`` between sequences."""

    name: str = ""

    def __init__(self, width: int, height: int) -> None:
        w, h = int(width), int(height)
        if w <= 0 or h <= 0 or w != width or h != height:
            raise ValueError(f"width and height must be positive integers (the sensor size); got {width}x{height}")
        check_sensor_pixels(w, h, f"the sensor size {w}x{h}")  # before any H x W array: 1e10 px would be 40 GB each
        self.width, self.height = w, h

    @abstractmethod
    def reset(self) -> None:
        """Forget everything seen so far (a new sequence starts)."""

    @abstractmethod
    def _reconstruct(self, window: np.ndarray, t_end: float) -> np.ndarray:
        """Return the (H, W) float32 image in [0, 1] after ``window``."""

    def reconstruct(self, window: np.ndarray, t_end: float | None = None) -> np.ndarray:
        """Return the (H, W) float32 image in [0, 1] after feeding ``window`` (events sorted by time).

        Args:
            window: (N,) event array on the width x height sensor; may be empty.
            t_end: the time the image is for [s] (default: the window's last event; must not precede it).
        """
        if not isinstance(window, np.ndarray) or window.dtype != EVENT_DTYPE or window.ndim != 1:
            got = f"dtype {window.dtype}" if isinstance(window, np.ndarray) else type(window).__name__
            raise ValueError(f"window must be a 1-D event array of dtype EVENT_DTYPE; got {got}")
        if window.size and (int(window["x"].max()) >= self.width or int(window["y"].max()) >= self.height):
            raise ValueError(f"window has events outside the {self.width}x{self.height} sensor this reconstructor was "
                             f"made for (max x {int(window['x'].max())}, max y {int(window['y'].max())})")
        if t_end is None:
            t_end = float(window["t"][-1]) if window.size else None
        elif window.size and t_end < window["t"][-1]:
            raise ValueError(f"t_end must not precede the window's last event ({window['t'][-1]!r}); got {t_end!r}")
        return self._reconstruct(window, t_end)


def _stretch(values: np.ndarray, low: float = 1.0, high: float = 99.0) -> np.ndarray:
    """Return ``values`` mapped linearly so that its ``low``/``high`` percentiles become 0/1, clipped to [0, 1]."""
    lo, hi = np.percentile(values, [low, high])
    if hi - lo < 1e-9:
        return np.full(values.shape, 0.5, np.float32)
    return np.clip((values - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)


class LogIntegrator(Reconstructor):
    """Direct integration (``cutoff_hz = per_event_decay = 0``) or Scheerlinck's high-pass filter (module docstring)."""

    def __init__(self, width: int, height: int, contrast: float = 0.2, cutoff_hz: float = 0.0,
                 per_event_decay: float = 0.0, name: str = "direct") -> None:
        super().__init__(width, height)
        for label, value in (("contrast", contrast), ("cutoff_hz", cutoff_hz), ("per_event_decay", per_event_decay)):
            if not np.isfinite(value) or value < 0 or (label == "contrast" and value == 0):
                raise ValueError(f"{label} must be a finite number {'> 0' if label == 'contrast' else '>= 0'}; "
                                 f"got {value!r}")
        self.contrast = float(contrast)
        self.alpha = 2 * np.pi * float(cutoff_hz)           # alpha = 2 pi f_c [rad/s]
        self.beta = float(per_event_decay)
        self.name = name
        self.reset()

    def reset(self) -> None:
        self.log_state = np.zeros(self.height * self.width)
        self.t_state: float | None = None

    def _reconstruct(self, window: np.ndarray, t_end: float | None) -> np.ndarray:
        if t_end is None:                                    # nothing happened and no time given: the state stands
            return self._image()
        if self.t_state is None:
            self.t_state = float(window["t"][0]) if window.size else t_end
        n_pixels = self.height * self.width
        pix = window["y"].astype(np.int64) * self.width + window["x"].astype(np.int64)
        n_at_pixel = np.bincount(pix, minlength=n_pixels)
        # decay of the old state: exp(-alpha (T - T_prev) - beta n_x)
        self.log_state *= np.exp(-self.alpha * (t_end - self.t_state) - self.beta * n_at_pixel)
        if window.size:
            # m_k: events at event k's pixel after it (rank within its pixel, counted from the end)
            order = np.argsort(pix, kind="stable")
            sorted_pix = pix[order]
            group_start = np.searchsorted(sorted_pix, sorted_pix, side="left")
            rank = np.arange(pix.size) - group_start
            later = np.empty(pix.size, np.int64)
            later[order] = n_at_pixel[sorted_pix] - 1 - rank
            weight = self.contrast * window["p"] * np.exp(-self.alpha * (t_end - window["t"]) - self.beta * later)
            self.log_state += np.bincount(pix, weights=weight, minlength=n_pixels)
        self.t_state = t_end
        return self._image()

    def _image(self) -> np.ndarray:
        """Return exp(L^) stretched to [0, 1] (linear intensity), as (H, W) float32."""
        log_state = self.log_state - self.log_state.max() if self.log_state.size else self.log_state  # no overflow
        return _stretch(np.exp(log_state)).reshape(self.height, self.width)


class LearnedReconstructor(Reconstructor):
    """A recurrent network from a checkpoint of :func:`evio_lib.events.reconstruction.training.train_reconstructor`."""

    def __init__(self, width: int, height: int, checkpoint: str | Path, device: str | None = None,
                 name: str = "learned", threads: int | None = None, precision: str = "auto") -> None:
        super().__init__(width, height)
        import torch

        from evio_lib.events.reconstruction.nets import build_network
        from evio_lib.events.reconstruction.precision import inference_network, resolve_precision

        _check_precision(precision)  # before the checkpoint loads and the thread count changes

        from evio_lib.io.checkpoint import CheckpointError, load_state, read_checkpoint

        path = Path(checkpoint)
        # a missing (CheckpointNotFoundError, also a FileNotFoundError), empty, truncated, foreign or SuperPoint file
        # is a one-line CheckpointError (a ValueError) naming it
        try:
            ckpt = read_checkpoint(path, "reconstructor", map_location="cpu", weights_only=True)
        except CheckpointError as error:            # published FireNet weights are not a reconstruct-train checkpoint
            ckpt = _published_checkpoint(path, error)
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        if threads is not None:
            torch.set_num_threads(int(threads))
        try:
            self.num_bins = int(ckpt["num_bins"])
            self.net = build_network(ckpt["architecture"], self.num_bins, **dict(ckpt.get("network_options") or {}))
        except (ValueError, TypeError) as exc:
            raise CheckpointError(f"{path}: its architecture {ckpt.get('architecture')!r}, num_bins "
                                  f"{ckpt.get('num_bins')!r} and network_options {ckpt.get('network_options')!r} "
                                  f"describe no network ({exc})") from None
        load_state(self.net, ckpt["state_dict"], path,
                   f"its state_dict does not fit the {ckpt['architecture']} network its settings describe")
        self.net.to(self.device).eval()
        # the forward pass used: FireNetInference on CPU (same outputs within ~1e-6, faster: docs/archive.md, "float32
        # FireNet forward-pass variants"), else the net; precision="bfloat16": the net under autocast (faster on CPUs
        # with native bfloat16, images slightly off float32's: docs/results/reconstruction.md#speed); "int8": FireNet
        # with int8 convolutions (quantized.FireNetInt8; the checkpoint's stored calibration, else one calibration per
        # process: docs/results/reconstruction.md#int8-and-float32); "auto": int8 where it runs (resolve_precision),
        # else float32
        precision = resolve_precision(self.net, precision)
        self.forward = inference_network(self.net, precision, ckpt.get("int8_ranges"))
        self.precision = precision  # what "auto" chose
        self.checkpoint = path
        self.name = name
        self.training_steps = int(ckpt.get("step", 0))
        self.reset()

    def reset(self) -> None:
        self.state = None
        self.last_image = np.full((self.height, self.width), 0.5, np.float32)

    def _reconstruct(self, window: np.ndarray, t_end: float | None) -> np.ndarray:
        import torch

        if window.size == 0:                                  # no events: nothing changed, the last image stands
            return self.last_image.copy()
        voxels = voxel_grid(window, self.width, self.height, self.num_bins)
        with torch.inference_mode():
            image, self.state = self.forward(torch.from_numpy(voxels)[None].to(self.device), self.state)
        self.last_image = image[0, 0].float().cpu().numpy()
        return self.last_image.copy()


def _published_checkpoint(path: Path, error: Exception) -> dict:
    """Return published FireNet weights in ``path`` as a checkpoint dict
    (:mod:`evio_lib.events.reconstruction.published`), or raise ``error`` (why it is no reconstruct-train checkpoint)
    when the file holds no published layout."""
    import torch

    from evio_lib.events.reconstruction.published import is_published_layout, published_firenet_checkpoint

    if not path.is_file():
        raise error
    import warnings

    try:
        with warnings.catch_warnings():                 # "Detected pickle protocol 4": the error below says more
            warnings.simplefilter("ignore")
            raw = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:                                   # unreadable: the reconstruct-train reader's message says why
        if "Python objects" in str(error):               # e.g. event_cnn_minimal's files pickle their config object
            from evio_lib.io.checkpoint import CheckpointError

            raise CheckpointError(f"{error}; published FireNet weights saved with such objects load once their "
                                  f"checkpoint['state_dict'] is saved alone (torch.save) by the code that wrote "
                                  f"them") from None
        raise error from None
    if is_published_layout(raw) is None:
        raise error
    return published_firenet_checkpoint(raw, path)


def shipped_checkpoint(name: str) -> Path:
    """Return the path of the shipped checkpoint ``name`` (see :func:`available_reconstructors`)."""
    if name not in _SHIPPED:
        raise ValueError(f"no shipped reconstructor named {name!r}; shipped: {sorted(_SHIPPED)}")
    return WEIGHTS_DIR / _SHIPPED[name]


def available_reconstructors() -> list[str]:
    """Return the names :func:`create_reconstructor` accepts without a checkpoint path.

    >>> available_reconstructors()[:2]
    ['direct', 'high_pass']
    """
    return ["direct", "high_pass"] + [name for name, f in _SHIPPED.items() if (WEIGHTS_DIR / f).is_file()]


def create_reconstructor(name: str = "firenet", width: int = 240, height: int = 180, **options) -> Reconstructor:
    """Return a reconstructor by name for a width x height sensor (DAVIS240C by default).

    Names: ``direct`` (options: contrast, cutoff_hz), ``high_pass`` (contrast, cutoff_hz = 0.06, per_event_decay = 0.06),
    ``firenet`` (the shipped network; options: device, threads, precision = one of :data:`PRECISIONS`), ``learned``
    with ``checkpoint=PATH`` (any checkpoint, e.g. an ``e2vid`` run of ``reconstruct-train``; the same options).
    ``precision`` is checked for every name; ``direct`` and ``high_pass`` compute in float64 whatever it says.

    >>> r = create_reconstructor("direct", 4, 3)
    >>> r.reconstruct(np.zeros(0, EVENT_DTYPE), t_end=0.1).shape
    (3, 4)
    """
    if name in ("direct", "high_pass"):  # no network: nothing to compute in another precision
        _check_precision(options.pop("precision", PRECISIONS[0]))
    if name == "direct":
        return LogIntegrator(width, height, name="direct", **options)
    if name == "high_pass":
        values = {"cutoff_hz": 0.06, "per_event_decay": 0.06, **options}
        return LogIntegrator(width, height, name="high_pass", **values)
    if name == "learned":
        if "checkpoint" not in options:
            raise ValueError("create_reconstructor('learned') needs checkpoint=PATH (a reconstruct-train checkpoint)")
        return LearnedReconstructor(width, height, **options)
    if name in _SHIPPED:
        path = shipped_checkpoint(name)
        if not path.is_file():
            raise FileNotFoundError(f"the shipped weights of {name!r} are missing ({path}); reinstall evio or train them "
                                    f"with `python -m evio_lib reconstruct-train`")
        return LearnedReconstructor(width, height, checkpoint=path, name=name, **options)
    if name == "e2vid":
        raise ValueError("no e2vid weights are shipped (10.7 M parameters need a GPU to train); train them with "
                         "`python -m evio_lib reconstruct-train --architecture e2vid --out DIR`, then use "
                         "create_reconstructor('learned', checkpoint='DIR/best.pt')")
    raise ValueError(f"unknown reconstructor {name!r}; choose one of {available_reconstructors() + ['learned']}")


def _check_precision(precision: str) -> None:
    """Raise ValueError unless ``precision`` is one of :data:`PRECISIONS`."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")


def reconstructor_by_name_or_file(method: str, width: int, height: int, what: str = "method",
                                  precision: str | None = None, threads: int | None = None) -> Reconstructor:
    """Return the reconstructor named ``method`` (:func:`available_reconstructors`), else the one in the
    reconstruct-train checkpoint file ``method``; ``what`` names the setting in the error for anything else.
    ``precision`` (one of :data:`PRECISIONS`) applies to networks; the classical methods ignore it. ``threads``: a
    network's torch threads (None: torch's default); the classical methods have none."""
    options = {} if precision is None else {"precision": precision}
    if threads is not None and method not in ("direct", "high_pass"):
        options["threads"] = threads
    if method in available_reconstructors():
        return create_reconstructor(method, width, height, **options)
    if method.endswith(".pt") or Path(method).is_file():
        return create_reconstructor("learned", width, height, checkpoint=method, **options)
    raise ValueError(f"{what} must be one of {available_reconstructors()} or a checkpoint file; got {method!r}")


def reconstruct_windows(reconstructor: Reconstructor, events: np.ndarray, bounds: np.ndarray,
                        reset: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Return (frames (K, H, W) float32, times (K,)): one image per window ``events[start:stop]`` of ``bounds``.

    The image's time is its window's last event.
    """
    bounds = np.asarray(bounds, dtype=np.int64).reshape(-1, 2)
    if reset:
        reconstructor.reset()
    frames = np.empty((len(bounds), reconstructor.height, reconstructor.width), np.float32)
    times = np.empty(len(bounds))
    for k, (a, b) in enumerate(bounds):
        if b <= a:
            raise ValueError(f"window {k} is empty ({a}:{b}); use reconstruct_at_times for time-based windows")
        frames[k] = reconstructor.reconstruct(events[a:b])
        times[k] = events["t"][b - 1]
    return frames, times


def reconstruct_at_times(reconstructor: Reconstructor, events: np.ndarray, times: np.ndarray,
                         max_window_events: int | None = None, reset: bool = True) -> np.ndarray:
    """Return (K, H, W) float32 frames: frame k reconstructed from all events up to ``times[k]`` (the EVREAL protocol).

    Events between consecutive times are fed as one window, split into windows of at most ``max_window_events``
    (the shipped network was trained on windows of 0.05-1 H W events and on windows of equal duration).
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if times.size and (np.any(~np.isfinite(times)) or np.any(np.diff(times) < 0)):
        raise ValueError("times must be finite and sorted in increasing order")
    if reset:
        reconstructor.reset()
    ends = np.searchsorted(events["t"], times, side="right")
    frames = np.empty((times.size, reconstructor.height, reconstructor.width), np.float32)
    start = 0
    for k, (stop, t) in enumerate(zip(ends, times)):
        chunk = events[start:stop]
        step = max_window_events or max(chunk.size, 1)
        pieces = [chunk[i:i + step] for i in range(0, chunk.size, step)] or [chunk]
        for piece in pieces:
            image = reconstructor.reconstruct(piece, t_end=float(t) if piece is pieces[-1] else None)
        frames[k] = image
        start = stop
    return frames
